//! Inverse kinematics: given the output coordinates `o` (`Structure::outputs`, e.g. the
//! platform pose), find every other coordinate `r`.
//!
//! With the outputs fixed, the constraints split into independent square blocks
//! (`Structure::ik_blocks`, one per leg of a Stewart platform), each solved on its own:
//!
//! - Position: Newton per block with its rows and columns of `G` (from
//!   `Kernels::jacobian_ik`); one `constraints` and one `jacobian_ik` call per iteration serve
//!   all blocks, and a converged block stops updating.
//! - Velocity: `G_r ṙ = -G_o ȯ`, blockwise.
//! - Acceleration: `G_r r̈ = gamma(X, Ẋ) - G_o ö`, blockwise.

use super::{Blocks, SolveReport, check_finite, check_input, linear_solve, newton};
use crate::data::Data;
use crate::error::SolverError;
use crate::kernels::Kernels;
use crate::model::Model;

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
/// Errors: `Dimension`/`NonFinite` for bad outputs or warm start, `Singular` (condition estimate
/// and block index) when a block's Jacobian is near singular, e.g. a fully stretched leg, and
/// `NotConverged`, e.g. for an unreachable pose.
pub fn inverse_kinematics<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    check_input("outputs", outputs, s.outputs.len())?;
    data.ws.x = data.x;
    for (&j, &v) in s.outputs.iter().zip(outputs) {
        data.ws.x[j] = v;
    }
    check_finite("data.x (warm start)", &data.ws.x)?;
    let report = newton(model, data, Blocks::Ik(s.ik_blocks), K::jacobian_ik, WHAT)?;
    data.x = data.ws.x;
    Ok(report)
}

/// Solves `G_r ṙ = -G_o ȯ` block by block at `data.x`, given the output rates `ȯ`.
/// Writes `data.xdot` on success. Calls `Kernels::jacobian`.
pub fn inverse_velocity<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs_dot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    check_input("outputs_dot", outputs_dot, s.outputs.len())?;
    check_finite("data.x", &data.x)?;
    model.kernels().jacobian(&data.x, &mut data.g.data.0);
    data.ws.x = [0.0; N];
    for (&j, &v) in s.outputs.iter().zip(outputs_dot) {
        data.ws.x[j] = v;
    }
    let (cond, residual) = linear_solve(
        data,
        Blocks::Ik(s.ik_blocks),
        false,
        model.options.cond_max,
        WHAT,
    )?;
    data.xdot = data.ws.x;
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}

/// Solves `G_r r̈ = gamma(X, Ẋ) - G_o ö` block by block at `data.x`, `data.xdot` (from
/// [`inverse_velocity`]), given the output accelerations `ö`. Writes `data.xddot` on success
/// (and `data.gamma`, in any case). Calls `Kernels::jacobian` and `Kernels::gamma`.
pub fn inverse_acceleration<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs_ddot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    check_input("outputs_ddot", outputs_ddot, s.outputs.len())?;
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    let k = model.kernels();
    k.jacobian(&data.x, &mut data.g.data.0);
    k.gamma(&data.x, &data.xdot, &mut data.gamma);
    check_finite("gamma (kernel output)", &data.gamma)?;
    data.ws.x = [0.0; N];
    for (&j, &v) in s.outputs.iter().zip(outputs_ddot) {
        data.ws.x[j] = v;
    }
    let (cond, residual) = linear_solve(
        data,
        Blocks::Ik(s.ik_blocks),
        true,
        model.options.cond_max,
        WHAT,
    )?;
    data.xddot = data.ws.x;
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}
