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
pub mod fk_robust;
pub mod forward_dynamics;
pub mod forward_kinematics;
mod generated;
pub(crate) mod input;
pub mod inverse_dynamics;
pub mod inverse_kinematics;
pub(crate) mod newton;
pub mod path;
pub mod projection;
pub(crate) mod reach;
pub(crate) mod reduced;
mod report;
pub(crate) mod terms;

pub use baumgarte::Baumgarte;
pub use forward_dynamics::forward_dynamics_schur;
pub use forward_kinematics::{forward_acceleration, forward_kinematics, forward_velocity};
pub use inverse_dynamics::{inverse_dynamics, inverse_dynamics_dense, inverse_dynamics_full};
pub use inverse_kinematics::{
    KinematicsReport, inverse_acceleration, inverse_kinematics, inverse_kinematics_full,
    inverse_velocity,
};
pub use projection::{project_position, project_velocity};
pub use report::{DynamicsMethod, DynamicsReport, SolveReport};

/// Forward dynamics (see [`forward_dynamics::forward_dynamics`]): `M Ẍ = psi + Q + S U - Gᵀ
/// lambda`, `G Ẍ = gamma`. A robot without constraints (`M = 0`: a serial arm or a tree, no
/// loop) solves `M Ẍ = F` by the Cholesky factor of `M` here (the Schur complement with an
/// empty `S_c`); `cond_blocks` is then the factor's pivot ratio `max l_ii² / min l_ii²` and
/// `cond` the 1-norm estimate of `M`'s condition number, `residual` 0 (no constraint).
pub fn forward_dynamics<K: crate::tasks::ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &crate::Model<K, N, M>,
    data: &mut crate::Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
) -> Result<DynamicsReport, crate::SolverError> {
    if M == 0 {
        unconstrained(model, data, u, q_forces)
    } else {
        forward_dynamics::forward_dynamics(model, data, u, q_forces, baumgarte)
    }
}

/// `M Ẍ = psi + Q + S U` (no constraint): see [`forward_dynamics()`].
fn unconstrained<K: crate::tasks::ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &crate::Model<K, N, M>,
    data: &mut crate::Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, crate::SolverError> {
    const WHAT: &str = "the mass matrix M";
    const SOURCE: &str = "M or psi (kernel output)";
    let s = model.structure();
    input::check_input("u", u, s.actuated.len())?;
    input::check_finite("data.x", &data.x)?;
    input::check_finite("data.xdot", &data.xdot)?;
    if let Some(q) = q_forces {
        input::check_finite("q_forces", q)?;
    }
    terms::evaluate_terms(model, data);
    input::check_finite(SOURCE, data.mass.as_slice())?;
    input::check_finite(SOURCE, &data.psi)?;
    let scratch = &mut data.ws.dynamics;
    let force = &mut scratch.v;
    for (j, fj) in force.iter_mut().enumerate() {
        *fj = data.psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    for (i, (&j, &ua)) in s.actuated.iter().zip(u).enumerate() {
        force[j] += crate::kernels::gear_ratio(s.gear, i) * ua;
    }
    let l = scratch.lu_n.as_flattened_mut();
    l.copy_from_slice(data.mass.as_slice());
    let cond = crate::factor::factor_spd(
        l,
        N,
        scratch.work_n.as_flattened_mut(),
        model.options.cond_max,
        crate::factor::CondMode::Report,
        WHAT,
        SOURCE,
    )?;
    crate::linalg::cholesky_solve(l, N, force)
        .map_err(|e| crate::factor::lu_error(e, WHAT, None, N, SOURCE))?;
    input::check_finite("Xddot", force)?;
    let (lo, hi) = (0..N)
        .map(|i| l[i + i * N] * l[i + i * N])
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        });
    data.xddot = *force;
    data.u = [0.0; N];
    data.u[..u.len()].copy_from_slice(u);
    Ok(DynamicsReport {
        method: DynamicsMethod::SchurComplement,
        cond_blocks: if N == 0 { 1.0 } else { hi / lo },
        cond,
        residual: 0.0,
    })
}
