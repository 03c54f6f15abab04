//! Time integration of the equations of motion `M Ẍ = psi + S U - Gᵀ lambda`,
//! `G Ẍ = gamma` (paper eq. 32), with the control forces `U(t, X, Ẋ)` from a callback.
//!
//! ```ignore
//! let options = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
//! let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &xdot0, options)?; // projects x0, xdot0
//! let mut control = |t: f64, x: &[f64; N], xdot: &[f64; N], u: &mut [f64]| {
//!     // may run inverse dynamics on its own Data
//!     u.fill(0.0);
//!     Ok(())
//! };
//! let stats = sim.run(&model, &mut data, 2.0, &mut control, |s| println!("{} {:?}", s.t(), s.x()))?;
//! ```
//!
//! Integrators ([`Method`]): classic fixed-step Runge–Kutta 4 (the paper's), and the adaptive
//! Dormand–Prince pairs 5(4) and 8(5,3) with embedded error control (Hairer, Nørsett & Wanner,
//! *Solving ODEs I*, II.4-5 and II.10, codes `DOPRI5` and `DOP853`: local extrapolation, FSAL,
//! a PI or standard step-size controller, automatic initial step; `embedded.rs`).
//!
//! The ODE is of index 1: integrating `Ẍ` lets `f(X)` and `G Ẋ` drift by the integration
//! error. [`Stabilization`] chooses what to do about it: nothing, Baumgarte's feedback in the
//! acceleration constraint, projection onto the manifold after each step, or integrating only
//! the independent coordinates `q` (coordinate partitioning) and recovering the others by
//! forward kinematics.
//!
//! The simulator keeps the state as `[f64; N]` arrays and its stages in fixed buffers: after
//! construction, a step allocates nothing (unless the control callback does).
//!
//! The files: `options.rs` (the settings, statistics and errors), `tableau.rs` (the
//! Runge–Kutta tableaux, checked against their order conditions), `simulator.rs` (the
//! simulator: RK4, the adaptive pairs' steps, the stabilisations).

mod options;
mod simulator;
mod tableau;

pub use options::{
    IntegrateError, IntegrateOptions, IntegrateStats, Method, Stabilization, StepControl, Time,
};
pub use simulator::Simulator;
