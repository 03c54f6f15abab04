//! Inverse kinematics: given the output coordinates `o` (`Structure::outputs`, e.g. the
//! platform pose), find every other coordinate `r`.
//!
//! With the outputs fixed, the constraints split into independent square blocks
//! (`Structure::ik_blocks`, one per leg of a Stewart platform), each solved on its own:
//!
//! - Position: Newton per block with its rows and columns of `G`; one call of the fused
//!   `Kernels::constraints_jacobian_ik` per iteration serves all blocks, and a converged block
//!   stops updating. Blocks of order up to 4 (3 × 3 legs of a Stewart platform) are inverted
//!   explicitly, with their exact condition number; larger ones (a tripod's 9 × 9, a serial
//!   arm's 6 × 6) are solved by the code the generator emitted for them
//!   ([`Kernels::ik_block_solve`](crate::Kernels::ik_block_solve), their condition read off
//!   the pivots, the Hager/Higham estimate where that passes 1e3), or by the runtime's LU where
//!   that declines.
//! - Velocity: `G_r ṙ = -G_o ȯ`, blockwise.
//! - Acceleration: `G_r r̈ = gamma(X, Ẋ) - G_o ö`, blockwise.
//!
//! The rates take the generated block solves first, for blocks of every order, and the
//! runtime's block factors where those decline.

use super::blockwise::{Blocks, Level, factor_blocks, linear_solve};
use super::generated;
use super::input::{check_finite, check_input};
use super::newton::newton;
use super::report::SolveReport;
use crate::data::Data;
use crate::error::SolverError;
use crate::model::Model;
use crate::tasks::{Acceleration, InverseKinematics, Jacobian, Robot, Velocity};

const WHAT: &str = "IK block G_r";

/// Solves `f(X) = 0` for every non-output coordinate, given the outputs `outputs`
/// (`Structure::outputs` order). Writes `data.x` on success.
///
/// Newton on each block, starting from the current `data.x` (warm start; call
/// [`Data::set_home`] first for a cold start from the model's home assembly). Per block the
/// convergence test is `max |f_b| <= tol_f` and `max |dx_b| <= tol_x (1 + max |x_b|)`, with
/// backtracking on `‖f_b‖₂` (see [`SolverOptions`](crate::SolverOptions)). The report gives the
/// most Newton steps of any block, the largest block residual and the worst block condition
/// estimate at the solution.
///
/// Errors: `Dimension`/`NonFinite` for bad outputs or warm start; `Unreachable` (the block and
/// its least residual) for a pose out of a leg's reach: after Newton failed, a least-squares
/// search on each block from the same start (Levenberg–Marquardt) finds a minimum of `‖f_b‖`
/// that is not a root; otherwise `Singular` (condition estimate and block index) when a
/// block's Jacobian is near singular at a reachable pose, e.g. a fully stretched leg, and
/// `NotConverged`; `SpuriousRoot` when the solution fails the certificate
/// ([`certify_position`](crate::certify_position): a mirror root of a loop written with fewer
/// components). To keep the start's working modes over a long way, use
/// [`inverse_kinematics_path`](crate::inverse_kinematics_path).
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn inverse_kinematics<K: InverseKinematics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_outputs("inverse kinematics")?;
    check_input("outputs", outputs, s.outputs.len())?;
    data.ws.x = data.x;
    for (&j, &v) in s.outputs.iter().zip(outputs) {
        data.ws.x[j] = v;
    }
    check_finite("data.x (warm start)", &data.ws.x)?;
    let start = data.ws.x;
    match newton(
        model,
        data,
        Blocks::Ik(s.ik_blocks),
        K::constraints_jacobian_ik,
        WHAT,
    ) {
        Ok(report) => {
            super::certify::certify_position(model, &data.ws.x)?;
            data.x = data.ws.x;
            Ok(report)
        }
        Err(e @ (SolverError::NotConverged { .. } | SolverError::Singular { .. })) => {
            Err(super::reach::unreachable_block(model, data, &start).unwrap_or(e))
        }
        Err(e) => Err(e),
    }
}

/// Solves `G_r ṙ = -G_o ȯ` block by block at `data.x`, given the output rates `ȯ`.
/// Writes `data.xdot` on success. Calls `Kernels::jacobian`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn inverse_velocity<K: Velocity<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs_dot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_outputs("inverse velocity")?;
    check_input("outputs_dot", outputs_dot, s.outputs.len())?;
    check_finite("data.x", &data.x)?;
    model.kernels().jacobian(&data.x, &mut data.g.data.0);
    if let Some(r) = generated::ik_rates(model, data, outputs_dot, Level::Velocity) {
        return Ok(r);
    }
    let cond =
        factor_blocks::<K, N, M>(data, Blocks::Ik(s.ik_blocks), model.options.cond_max, WHAT)?;
    solve_rates(model, data, outputs_dot, Level::Velocity, cond)
}

/// Solves `G_r r̈ = gamma(X, Ẋ) - G_o ö` block by block at `data.x`, `data.xdot` (from
/// [`inverse_velocity`]), given the output accelerations `ö`. Writes `data.xddot` on success
/// (and `data.gamma`, in any case). Calls `Kernels::jacobian` and `Kernels::gamma`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn inverse_acceleration<K: Acceleration<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs_ddot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_outputs("inverse acceleration")?;
    check_input("outputs_ddot", outputs_ddot, s.outputs.len())?;
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    let k = model.kernels();
    k.jacobian(&data.x, &mut data.g.data.0);
    k.gamma(&data.x, &data.xdot, &mut data.gamma);
    if let Some(r) = generated::ik_rates(model, data, outputs_ddot, Level::Acceleration) {
        return Ok(r);
    }
    check_finite("gamma (kernel output)", &data.gamma)?;
    let cond =
        factor_blocks::<K, N, M>(data, Blocks::Ik(s.ik_blocks), model.options.cond_max, WHAT)?;
    solve_rates(model, data, outputs_ddot, Level::Acceleration, cond)
}

/// The reports of [`inverse_kinematics_full`]: one per level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicsReport {
    /// Newton on the position (as [`inverse_kinematics`] reports it).
    pub position: SolveReport,
    /// The velocity solve (as [`inverse_velocity`] reports it).
    pub velocity: SolveReport,
    /// The acceleration solve (as [`inverse_acceleration`] reports it).
    pub acceleration: SolveReport,
}

/// [`inverse_kinematics`], [`inverse_velocity`] and [`inverse_acceleration`] in one call, with
/// the same results up to rounding: `data.x`, `data.xdot` and `data.xddot` for the output pose,
/// rates and accelerations, Newton warm-started from `data.x`.
///
/// Cheaper than the three calls: after Newton it evaluates `Kernels::jacobian` once at the
/// solution and factors the inverse-kinematics blocks once, for both the velocity and the
/// acceleration (the separate calls evaluate the Jacobian and factor the blocks in each), and
/// then `Kernels::gamma`.
///
/// All three inputs are checked before anything is written. Errors: those of the three calls;
/// the levels before the failing one stay committed (as after the separate calls), the failing
/// one and those after it are left untouched.
pub fn inverse_kinematics_full<
    K: InverseKinematics<N, M> + Velocity<N, M> + Acceleration<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
    outputs_dot: &[f64],
    outputs_ddot: &[f64],
) -> Result<KinematicsReport, SolverError> {
    model.structure().require_outputs("inverse kinematics")?;
    check_input(
        "outputs_ddot",
        outputs_ddot,
        model.structure().outputs.len(),
    )?;
    let (position, velocity, factored) = position_and_velocity(model, data, outputs, outputs_dot)?;
    let k = model.kernels();
    k.gamma(&data.x, &data.xdot, &mut data.gamma);
    let (acceleration, _) = acceleration_after(model, data, outputs_ddot, &velocity, factored)?;
    Ok(KinematicsReport {
        position,
        velocity,
        acceleration,
    })
}

/// The first two levels of [`inverse_kinematics_full`] (both inputs checked first): Newton,
/// `Kernels::jacobian` at the solution and the velocity, by the generated block solves or else
/// with the block factors, which are then left in the workspace for the acceleration (the
/// third value: whether they are).
pub(crate) fn position_and_velocity<
    K: InverseKinematics<N, M> + Jacobian<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
    outputs_dot: &[f64],
) -> Result<(SolveReport, SolveReport, bool), SolverError> {
    let s = model.structure();
    check_input("outputs_dot", outputs_dot, s.outputs.len())?;
    let position = inverse_kinematics(model, data, outputs)?;
    model.kernels().jacobian(&data.x, &mut data.g.data.0);
    if let Some(velocity) = generated::ik_rates(model, data, outputs_dot, Level::Velocity) {
        return Ok((position, velocity, false));
    }
    let cond =
        factor_blocks::<K, N, M>(data, Blocks::Ik(s.ik_blocks), model.options.cond_max, WHAT)?;
    let velocity = solve_rates(model, data, outputs_dot, Level::Velocity, cond)?;
    Ok((position, velocity, true))
}

/// The acceleration level after [`position_and_velocity`] (`velocity` its report, `factored`
/// whether it left the block factors), `data.gamma` evaluated: the generated block solves, or
/// else the block factors (made now if the velocity did not leave them) and [`solve_rates`].
/// Returns the report and the condition number of the block factors in the workspace, if any.
pub(crate) fn acceleration_after<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs_ddot: &[f64],
    velocity: &SolveReport,
    factored: bool,
) -> Result<(SolveReport, Option<f64>), SolverError> {
    if let Some(r) = generated::ik_rates(model, data, outputs_ddot, Level::Acceleration) {
        return Ok((r, factored.then_some(velocity.cond)));
    }
    check_finite("gamma (kernel output)", &data.gamma)?;
    let cond = if factored {
        velocity.cond
    } else {
        let ik = Blocks::Ik(model.structure().ik_blocks);
        factor_blocks::<K, N, M>(data, ik, model.options.cond_max, WHAT)?
    };
    let r = solve_rates(model, data, outputs_ddot, Level::Acceleration, cond)?;
    Ok((r, Some(cond)))
}

/// The blockwise rate solve with the block factors already in the workspace (`cond` their
/// worst condition number) and `data.g` at `data.x`; commits `data.xdot` or `data.xddot`.
pub(crate) fn solve_rates<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    rates: &[f64],
    level: Level,
    cond: f64,
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    data.ws.x = [0.0; N];
    for (&j, &v) in s.outputs.iter().zip(rates) {
        data.ws.x[j] = v;
    }
    let with_gamma = level == Level::Acceleration;
    let residual = linear_solve::<K, N, M>(data, Blocks::Ik(s.ik_blocks), with_gamma, WHAT)?;
    match level {
        Level::Velocity => data.xdot = data.ws.x,
        Level::Acceleration => data.xddot = data.ws.x,
    }
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}
