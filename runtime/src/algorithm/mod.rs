//! The solvers, one module per problem (Pinocchio's `algorithm/`), and the machinery they
//! share, one file each: block Newton with backtracking (`newton`), blockwise linear solves with
//! a condition check (`blockwise`), the dynamics terms (`terms`), input checks (`input`),
//! reports (`report`). This file holds only the module list, the re-exports and the
//! `by_order!` macros (see the crate docs for the layout).
//!
//! Every solver reads the model and writes `Data`; on success it commits its result
//! (`data.x`, `data.xdot` or `data.xddot`), on error it leaves that result untouched.

/// `$body` with the constant `$b` bound to `$order` when it is 1, 2, 3 or 4; `$other`
/// otherwise. With a constant `$order` (a robot's `IK_BLOCK_ORDER`, or `M`) only the arm taken
/// is compiled: rustc does not instantiate code under a `match` on a constant that cannot run.
macro_rules! by_order {
    ($order:expr, $b:ident => $body:expr, _ => $other:expr) => {
        match $order {
            1 => {
                const $b: usize = 1;
                $body
            }
            2 => {
                const $b: usize = 2;
                $body
            }
            3 => {
                const $b: usize = 3;
                $body
            }
            4 => {
                const $b: usize = 4;
                $body
            }
            _ => $other,
        }
    };
}

/// [`by_order!`] on the order of robot `$k`'s inverse-kinematics blocks: the order it declares
/// (`IK_BLOCK_ORDER`, a constant: one size compiled per robot), or the one `$ik` (its
/// `Structure::ik_blocks`) has when it declares none.
macro_rules! by_ik_order {
    ($k:ty, $ik:expr, $b:ident => $body:expr, _ => $other:expr) => {
        match <$k as $crate::tasks::Robot<N, M>>::IK_BLOCK_ORDER {
            $crate::kernels::IK_BLOCK_ORDER_UNDECLARED => by_order!(
                $crate::kernels::uniform_order($ik).unwrap_or(0),
                $b => $body,
                _ => $other
            ),
            _ => by_order!(
                <$k as $crate::tasks::Robot<N, M>>::IK_BLOCK_ORDER,
                $b => $body,
                _ => $other
            ),
        }
    };
}

mod baumgarte;
pub(crate) mod blockwise;
pub mod certify;
pub(crate) mod damping;
pub mod derivatives;
pub mod fk_robust;
pub mod forward_dynamics;
pub mod forward_kinematics;
mod generated;
pub mod id_derivatives;
pub(crate) mod input;
pub mod inverse_dynamics;
pub mod inverse_kinematics;
pub mod linearize;
pub(crate) mod newton;
pub mod path;
pub mod projection;
pub(crate) mod reach;
pub(crate) mod reduced;
mod report;
pub mod step;
pub mod step_projection;
pub(crate) mod terms;

pub use baumgarte::Baumgarte;
pub use derivatives::{
    DerivativesSolver, ForwardDynamicsDerivatives, forward_dynamics_derivatives,
    forward_dynamics_derivatives_with,
};
pub use forward_dynamics::{
    FdSolver, forward_dynamics, forward_dynamics_schur, forward_dynamics_with,
};
pub use forward_kinematics::{forward_acceleration, forward_kinematics, forward_velocity};
pub use id_derivatives::{
    IdDerivativesSolver, InverseDynamicsDerivatives, inverse_dynamics_derivatives,
    inverse_dynamics_derivatives_with,
};
pub use inverse_dynamics::{inverse_dynamics, inverse_dynamics_dense, inverse_dynamics_full};
pub use inverse_kinematics::{
    KinematicsReport, inverse_acceleration, inverse_kinematics, inverse_kinematics_full,
    inverse_velocity,
};
pub use linearize::{Coordinates, Linearization, linearize};
pub use projection::{project_position, project_velocity, state_residual};
pub use report::{DynamicsMethod, DynamicsReport, SolveReport};
pub use step::{
    StepDerivatives, rk4_step_derivatives, semi_implicit_euler_step,
    semi_implicit_euler_step_derivatives,
};
pub use step_projection::{StepProjection, project_step_derivatives};
