//! rbss-runtime: the kernel trait generated robots implement, and the solvers built on it.
//!
//! ```ignore
//! let model = Model::new(robot);            // robot: K: Kernels<N, M>
//! let mut data = Data::new(&model);         // x at the home assembly; no allocation
//! let rep = inverse_kinematics(&model, &mut data, &pose)?;   // writes data.x
//! inverse_velocity(&model, &mut data, &pose_dot)?;           // writes data.xdot
//! inverse_acceleration(&model, &mut data, &pose_ddot)?;      // writes data.xddot
//! let rep = forward_kinematics(&model, &mut data, &q)?;      // writes data.x
//! forward_velocity(&model, &mut data, &qdot)?;
//! forward_acceleration(&model, &mut data, &qddot)?;
//! ```
//!
//! Every solver is allocation-free and panic-free, and fails with a typed [`SolverError`]
//! rather than a NaN.

pub mod algorithm;
pub mod data;
pub mod error;
pub mod kernels;
pub mod linalg;
pub mod model;

pub use algorithm::{
    SolveReport, forward_acceleration, forward_kinematics, forward_velocity, inverse_acceleration,
    inverse_kinematics, inverse_velocity,
};
pub use data::Data;
pub use error::{SolverError, StructureError};
pub use kernels::{Dynamics, IkBlock, Kernels, Structure};
pub use model::{Model, SolverOptions};
