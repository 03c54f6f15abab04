//! Forward kinematics: given the actuated coordinates `q`, find the others `p`
//! (paper eqs. 9-17).
//!
//! - Position: Newton on all M equations `f(q, p) = 0` with `J_p = ∂f/∂p` (the passive
//!   columns of `G`, written with `f` by the fused `Kernels::constraints_jacobian_p`),
//!   warm-started from `data.x`. Each step solves with `J_p` by elimination onto the outputs:
//!   by the code the generator emitted for the robot
//!   ([`Kernels::forward_rates_solve`](crate::Kernels::forward_rates_solve): one function per
//!   kind of leg over the structural non-zeros of `G`, the reduced system of the outputs by its
//!   explicit inverse), or where that declines by the runtime's own (`reduced::fk_factor`:
//!   every leg's passive columns completed to an invertible 3 × 3 block by their cross
//!   product), each when its rigorous bound certifies `J_p`; otherwise, near a singularity, by
//!   the dense LU.
//! - Velocity and acceleration solve with `J_p` the same way.
//! - Velocity (eq. 12): `J_p ṗ = -J_q q̇`.
//! - Acceleration (eq. 15): `J_p p̈ = gamma(X, Ẋ) - J_q q̈`, with `gamma = -(dG/dt) Ẋ`.

use super::blockwise::{Blocks, factor_blocks, linear_solve};
use super::generated;
use super::input::{check_finite, check_input};
use super::newton::newton;
use super::reduced;
use super::report::SolveReport;
use crate::data::Data;
use crate::error::SolverError;
use crate::factor::check_cond;
use crate::model::{Model, mat_vec_structured};
use crate::plan::mat_vec;
use crate::tasks::{Acceleration, ForwardKinematics, Robot, Velocity};

const WHAT: &str = "J_p";

/// Solves `f(q, p) = 0` for the passive coordinates `p`, given the actuated `q`
/// (`Structure::actuated` order). Writes `data.x` (q and p) on success.
///
/// Newton on all M equations, starting from the current `data.x` (warm start; call
/// [`Data::set_home`] first for a cold start), each step solving `J_p dp = -f` by elimination
/// onto the outputs or, when that does not certify `J_p` (near a singularity), by LU. Converged
/// when `max |f| <= tol_f` and `max |dp| <= tol_x (1 + max |p|)` (defaults `1e-12`, `1e-12`,
/// at most 50 steps: [`SolverOptions`](crate::SolverOptions)). When a full step does not
/// decrease `‖f‖₂`, it is halved (backtracking).
///
/// The report's `cond` is exact after the elimination (the 1-norm of `J_p⁻¹` formed from its
/// factors), the Hager/Higham estimate after the LU. The steps before the residual is within
/// `tol_f` decide `Singular` by the generated elimination's rigorous upper bound, free with the
/// solve; the step that can converge computes the exact value.
///
/// Certified: the loop components the model leaves out of `f` are checked at the solution
/// ([`certify_position`](crate::certify_position)), and a mirror root is `SpuriousRoot`, not
/// returned. The assembly mode is that of the root Newton reaches from the start; to keep the
/// start's mode over a long way, use [`forward_kinematics_path`](crate::forward_kinematics_path).
///
/// Errors: `Dimension`/`NonFinite` for a bad `q` or warm start, `Singular` (with the condition
/// estimate of `J_p`) near a singularity of the mechanism, `NotConverged`, `SpuriousRoot`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn forward_kinematics<K: ForwardKinematics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_actuated("forward kinematics")?;
    check_input("q", q, s.actuated.len())?;
    data.ws.x = data.x;
    for (&j, &v) in s.actuated.iter().zip(q) {
        data.ws.x[j] = v;
    }
    check_finite("data.x (warm start)", &data.ws.x)?;
    let blocks = Blocks::Single {
        rows: &model.all_rows,
        cols: s.passive,
    };
    let report = newton(model, data, blocks, K::constraints_jacobian_p, WHAT)?;
    super::certify::certify_position(model, &data.ws.x)?;
    data.x = data.ws.x;
    Ok(report)
}

/// Solves `J_p ṗ = -J_q q̇` (paper eq. 12) at `data.x`, given the actuated rates `q̇`.
/// Writes `data.xdot` on success. Calls `Kernels::jacobian`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn forward_velocity<K: Velocity<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    qdot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_actuated("forward velocity")?;
    check_input("qdot", qdot, s.actuated.len())?;
    check_finite("data.x", &data.x)?;
    model.kernels().jacobian(&data.x, &mut data.g.data.0);
    data.ws.x = [0.0; N];
    for (&j, &v) in s.actuated.iter().zip(qdot) {
        data.ws.x[j] = v;
    }
    let (cond, residual) = rates(model, data, false)?;
    data.xdot = data.ws.x;
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}

/// Solves `J_p p̈ = gamma(X, Ẋ) - J_q q̈` (paper eq. 15) at `data.x`, `data.xdot` (from
/// [`forward_velocity`]), given the actuated accelerations `q̈`. Writes `data.xddot` on success
/// (and `data.gamma`, in any case). Calls `Kernels::jacobian` and `Kernels::gamma`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn forward_acceleration<K: Acceleration<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    qddot: &[f64],
) -> Result<SolveReport, SolverError> {
    let s = model.structure();
    s.require_actuated("forward acceleration")?;
    check_input("qddot", qddot, s.actuated.len())?;
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    let k = model.kernels();
    k.jacobian(&data.x, &mut data.g.data.0);
    k.gamma(&data.x, &data.xdot, &mut data.gamma);
    check_finite("gamma (kernel output)", &data.gamma)?;
    data.ws.x = [0.0; N];
    for (&j, &v) in s.actuated.iter().zip(qddot) {
        data.ws.x[j] = v;
    }
    let (cond, residual) = rates(model, data, true)?;
    data.xddot = data.ws.x;
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}

/// Solves `J_p v_p = base - J_q v_q` for the passive entries of `v = data.ws.x` (the actuated
/// ones set by the caller, the passive ones zero), `base = gamma` if `with_gamma`, else zero,
/// at `data.g` as it is: by elimination onto the outputs, the generated one
/// (`Kernels::forward_rates_solve`) or the runtime's (`reduced::fk_factor`), the same as a Newton
/// step of [`forward_kinematics`], each with the exact condition number, when it certifies
/// `J_p`, else by the dense LU with the Hager/Higham estimate. Returns `(cond, max |G v - base|)`.
fn rates<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    with_gamma: bool,
) -> Result<(f64, f64), SolverError> {
    if let Some(r) = generated::fk_rates(model, data, with_gamma) {
        return Ok(r);
    }
    let cond_max = model.options.cond_max;
    if reduced::fk_factor(model, &data.g, &mut data.ws.fk, cond_max).is_some() {
        let cond = check_cond(reduced::fk_cond::<N, M>(&data.ws.fk), cond_max, WHAT, None)?;
        let Data { g, gamma, ws, .. } = data;
        let mut rhs = [0.0; M];
        mat_vec(g, &ws.x, &mut rhs);
        for (r, &gam) in rhs.iter_mut().zip(gamma.iter()) {
            *r = if with_gamma { gam } else { 0.0 } - *r;
        }
        check_finite("right-hand side (G or gamma)", &rhs)?;
        reduced::fk_solve(model, &ws.fk, &rhs, &mut ws.x);
        check_finite("solution", &ws.x)?;
        let mut gv = [0.0; M];
        mat_vec_structured(model, g, &ws.x, &mut gv);
        let residual = gv.iter().zip(gamma.iter()).fold(0.0_f64, |m, (&a, &b)| {
            m.max((a - if with_gamma { b } else { 0.0 }).abs())
        });
        return Ok((cond, residual));
    }
    let blocks = Blocks::Single {
        rows: &model.all_rows,
        cols: model.structure().passive,
    };
    let cond = factor_blocks::<K, N, M>(data, blocks, cond_max, WHAT)?;
    let residual = linear_solve::<K, N, M>(data, blocks, with_gamma, WHAT)?;
    Ok((cond, residual))
}
