//! rbss-runtime: the kernel trait generated robots implement, and the solvers built on it.
//!
//! ```ignore
//! let model = Model::new(robot);            // robot: K: Kernels<N, M>, or a scene's crate (see `tasks`)
//! let mut data = Data::new(&model);         // x at the home assembly; no allocation
//! let rep = inverse_kinematics(&model, &mut data, &pose)?;   // writes data.x
//! inverse_velocity(&model, &mut data, &pose_dot)?;           // writes data.xdot
//! inverse_acceleration(&model, &mut data, &pose_ddot)?;      // writes data.xddot
//! // The three at once (one Jacobian and one factorisation of the blocks for both rates):
//! let reps = inverse_kinematics_full(&model, &mut data, &pose, &pose_dot, &pose_ddot)?;
//! let rep = forward_kinematics(&model, &mut data, &q)?;      // writes data.x
//! forward_velocity(&model, &mut data, &qdot)?;
//! forward_acceleration(&model, &mut data, &qddot)?;
//!
//! // Dynamics (K: Dynamics<N, M>): data.x, data.xdot, data.xddot from the solvers above.
//! let rep = inverse_dynamics(&model, &mut data, None)?;      // writes data.u, data.lambda
//! let u = data.u;                                           // U: the first N - M entries
//! // One feed-forward sample: IK, velocity, acceleration and inverse dynamics at once.
//! let (kin, dyn_rep) = inverse_dynamics_full(&model, &mut data, &pose, &pose_dot, &pose_ddot, None)?;
//! let rep = forward_dynamics(&model, &mut data, &u[..N - M], None, Baumgarte::NONE)?; // data.xddot
//!
//! // Simulation (integrate): RK4, DOPRI5 or DOP853, with a stabilisation of the constraints.
//! let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
//! let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &xdot0, options)?;
//! let stats = sim.run(&model, &mut data, t_end, &mut control, |_| {})?;
//! ```
//!
//! Every solver is allocation-free and panic-free, and fails with a typed [`SolverError`]
//! rather than a NaN.
//!
//! # Layout
//!
//! The modules form layers: each imports only from its own layer or lower ones, with no import
//! cycle (`runtime/tests/layers.rs` checks the sources), from the bottom:
//!
//! 1. [`linalg`] (dense LU, Cholesky, explicit small inverses, condition estimates) and
//!    [`error`] (the typed errors).
//! 2. [`kernels`] and [`tasks`]: the traits generated robots implement, their [`Structure`]
//!    and [`IkBlock`]s.
//! 3. `plan`: the structure as the solvers use it, fixed when the robot was generated: the
//!    mass blocks' check and product, the gathering and inversion of a block of `G`, `G v`.
//! 4. `factor`: the factorizations with their condition checks (`factor_lu`, `factor_spd`,
//!    `solve_factored`, `check_cond`, the slots of the blockwise factors) and the storage of the
//!    eliminations onto the outputs.
//! 5. [`model`] ([`Model`]: kernels, structure, options and the row lists computed once, with
//!    `G`'s structured products), then [`data`] ([`Data`]: every buffer, the solvers' scratch
//!    space grouped by who uses it).
//! 6. [`algorithm`]: one file per solver — `inverse_kinematics`, `forward_kinematics`,
//!    `inverse_dynamics`, `forward_dynamics/` (`mod.rs` the entry and the choice of path,
//!    `reduced.rs` the elimination onto the outputs, `schur.rs` the Schur complement,
//!    `saddle.rs` the saddle-point LU), `projection`, `certify` (certificates and assembly
//!    modes), `path` (continuation), `fk_robust` (Levenberg–Marquardt), `reach` — and what they
//!    share: `newton` (block Newton with backtracking), `blockwise` (blockwise linear solves),
//!    `reduced` (forward kinematics' elimination onto the outputs), `generated` (calls of the
//!    generated solves), `terms` (the dynamics terms and their checks), `input` (input checks),
//!    `damping`, `report` ([`SolveReport`], [`DynamicsReport`]) and `baumgarte`
//!    ([`Baumgarte`]). `algorithm/mod.rs` holds the module list, the re-exports and the
//!    `by_order!` macros.
//! 7. [`integrate`]: the simulator on top of forward dynamics — `options` (methods, settings,
//!    statistics, errors), `tableau` (the Dormand–Prince 5(4) and 8(5,3) tableaux, checked
//!    against their order conditions) and `simulator` (RK4, the adaptive steps, the
//!    stabilisations).

pub mod algorithm;
pub mod data;
pub mod error;
pub(crate) mod factor;
pub mod integrate;
pub mod kernels;
pub mod linalg;
pub mod model;
pub(crate) mod plan;
pub mod tasks;

pub use algorithm::certify::{
    CERTIFY_FACTOR, ModeSignature, Parts, certify_position, mode_signature,
};
pub use algorithm::fk_robust::{FkRobustError, LmOptions, LmReport, forward_kinematics_lm};
pub use algorithm::path::{
    PathOptions, PathReport, forward_kinematics_path, inverse_kinematics_path,
};
pub use algorithm::{
    Baumgarte, DerivativesSolver, DynamicsMethod, DynamicsReport, FdSolver,
    ForwardDynamicsDerivatives, KinematicsReport, SolveReport, forward_acceleration,
    forward_dynamics, forward_dynamics_derivatives, forward_dynamics_derivatives_with,
    forward_dynamics_schur, forward_dynamics_with, forward_kinematics, forward_velocity,
    inverse_acceleration, inverse_dynamics, inverse_dynamics_dense, inverse_dynamics_full,
    inverse_kinematics, inverse_kinematics_full, inverse_velocity, project_position,
    project_velocity, state_residual,
};
pub use algorithm::{
    Coordinates, Linearization, StepDerivatives, StepProjection, linearize,
    project_step_derivatives, rk4_step_derivatives, semi_implicit_euler_step,
    semi_implicit_euler_step_derivatives,
};
pub use algorithm::{
    IdDerivativesSolver, InverseDynamicsDerivatives, inverse_dynamics_derivatives,
    inverse_dynamics_derivatives_with,
};
pub use data::Data;
pub use error::{ModePart, SolverError, StructureError};
pub use integrate::{
    IntegrateError, IntegrateOptions, IntegrateStats, Method, Simulator, Stabilization, StepControl,
};
pub use kernels::{
    Dynamics, DynamicsDerivatives, IK_BLOCK_ORDER_UNDECLARED, IkBlock, Kernels, SolveConditioning,
    Structure, gear_ratio,
};
pub use model::{Model, SolverOptions};
