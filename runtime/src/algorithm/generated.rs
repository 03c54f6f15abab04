//! The kinematic solves the generator emitted for the robot, taken before the general paths of
//! this module's parent: inverse kinematics' block solves
//! ([`Kernels::ik_block_solve`](crate::Kernels::ik_block_solve)) and forward kinematics'
//! elimination onto the outputs
//! ([`Kernels::forward_rates_solve`](crate::Kernels::forward_rates_solve)), one function per
//! kind of block over the structural non-zeros of `G`, with constant indices.
//!
//! Each returns `None` where the generated code declines (a pivot its threshold test refuses, a
//! singular block, a robot without it), where the condition number passes its threshold
//! (`SolverOptions::cond_max` for a block or an exact condition number; half of it for forward
//! kinematics' upper bound, as the runtime's own elimination certifies), or where a result is not finite: the general path
//! then runs from the start and gives the answer or the typed error (`Singular` with its
//! condition number, `NonFinite` naming the kernel output) as before. A block's condition
//! number from the generated code is exact up to order 3 and, beyond, read off the
//! elimination's pivots (`‖K‖₁ max_c 1 / |u_cc|`; the Hager/Higham estimate where that passes
//! 1e3);
//! forward kinematics' elimination gives the exact `cond₁(J_p)` where it is reported (the rates,
//! the Newton step that can converge) and its rigorous upper bound, free with the solve, where
//! it only decides `Singular` (the Newton steps before).

use super::blockwise::Level;
use super::input::all_finite;
use super::report::SolveReport;
use crate::data::Data;
use crate::model::Model;
use crate::tasks::Robot;

/// The blockwise rate solve `G_r v_r = base - G_o v_o` (`base = gamma` at the acceleration
/// level, else zero) at `data.g` as it is, by the generated block solves; commits `data.xdot`
/// or `data.xddot` and reports the worst block condition and the largest residual of a block's
/// rows.
pub(crate) fn ik_rates<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    rates: &[f64],
    level: Level,
) -> Option<SolveReport> {
    let s = model.structure();
    let k = model.kernels();
    let Data {
        g,
        gamma,
        ws,
        xdot,
        xddot,
        ..
    } = data;
    let v = &mut ws.x;
    *v = [0.0; N];
    for (&j, &r) in s.outputs.iter().zip(rates) {
        v[j] = r;
    }
    let base = match level {
        Level::Velocity => &[0.0; M],
        Level::Acceleration => &*gamma,
    };
    let (mut cond, mut residual) = (0.0_f64, 0.0_f64);
    for b in 0..s.ik_blocks.len() {
        let [c, r] = k.ik_block_solve(b, &g.data.0, base, true, v)?;
        // A NaN declines too.
        if c.is_nan() || c > model.options.cond_max {
            return None;
        }
        cond = cond.max(c);
        residual = residual.max(r);
    }
    if !(residual.is_finite() && all_finite(v)) {
        return None;
    }
    match level {
        Level::Velocity => *xdot = *v,
        Level::Acceleration => *xddot = *v,
    }
    Some(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}

/// A Newton step of inverse-kinematics block `block`, `G_b step = -f_b`, by the generated
/// block solve: `step` in the order of the block's columns (written through `scratch`, whose
/// entries in those columns it overwrites), and the block's condition number.
#[allow(clippy::too_many_arguments)]
pub(crate) fn ik_newton_step<K: Robot<N, M>, const N: usize, const M: usize>(
    kernels: &K,
    block: usize,
    cols: &[usize],
    g: &[[f64; M]; N],
    f: &[f64; M],
    scratch: &mut [f64; N],
    step: &mut [f64],
    cond_max: f64,
) -> Option<f64> {
    let [c, _] = kernels.ik_block_solve(block, g, f, false, scratch)?;
    if c.is_nan() || c > cond_max {
        return None;
    }
    for (s, &j) in step.iter_mut().zip(cols) {
        *s = -scratch[j];
    }
    Some(c)
}

/// `J_p v_p = base - J_q v_q` at `data.g` as it is by the generated elimination, `v =
/// data.ws.x` with its actuated entries given (`base = gamma` if `with_gamma`, else zero):
/// writes the passive entries of `v` and returns `(c, max |G v - base|)`: `c` the elimination's
/// upper bound of `cond₁(J_p)` when it certifies `J_p` (at most `cond_max / 2`) and the options
/// do not ask for the exact value (`SolverOptions::exact_cond`), else the exact value (solved
/// again when the bound did not certify). On `None` the passive entries of `v` are zero again,
/// as the general path needs.
pub(crate) fn fk_rates<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    with_gamma: bool,
) -> Option<(f64, f64)> {
    let Data { g, gamma, ws, .. } = data;
    let base = if with_gamma { &*gamma } else { &[0.0; M] };
    let v = &mut ws.x;
    let o = model.options;
    let mut solve = |exact| {
        model
            .kernels()
            .forward_rates_solve(&g.data.0, base, true, exact, v)
            .filter(|[_, res]| res.is_finite() && all_finite(v))
    };
    let mut exact = o.exact_cond;
    let mut r = solve(exact);
    if !exact && r.is_some_and(|[c, _]| c > fk_cond_limit(false, o.cond_max)) {
        // The bound does not certify J_p: decide on the exact value.
        exact = true;
        r = solve(exact);
    }
    match r {
        Some([c, res]) if c <= fk_cond_limit(exact, o.cond_max) => Some((c, res)),
        _ => {
            for &j in model.structure().passive {
                v[j] = 0.0;
            }
            None
        }
    }
}

/// The largest condition number of `J_p` the generated elimination's result is taken with: the
/// exact value up to `cond_max`, its upper bound up to `cond_max / 2` (as the runtime's own
/// elimination certifies).
fn fk_cond_limit(exact: bool, cond_max: f64) -> f64 {
    if exact { cond_max } else { 0.5 * cond_max }
}

/// A Newton step of forward kinematics, `J_p step = -f`, by the generated elimination: `step`
/// in the order of the passive columns (written through `scratch`, whose entries it
/// overwrites), the condition number of `J_p` (exact if `exact` and at most `cond_max`, else
/// the elimination's upper bound when it is at most `cond_max / 2`), and whether the
/// elimination's factors were kept in `store` for chord steps
/// (`Kernels::forward_rates_keep`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fk_newton_step<K: Robot<N, M>, const N: usize, const M: usize>(
    kernels: &K,
    passive: &[usize],
    g: &[[f64; M]; N],
    f: &[f64; M],
    scratch: &mut [f64; N],
    step: &mut [f64],
    cond_max: f64,
    exact: bool,
    store: &mut [f64],
) -> Option<(f64, bool)> {
    let minus_f: [f64; M] = core::array::from_fn(|i| -f[i]);
    // The actuated columns of `g` are not the Newton kernel's: `x_q = 0` leaves them unread.
    let ([c, _], kept) = kernels.forward_rates_keep(g, &minus_f, exact, scratch, store)?;
    if c.is_nan() || c > fk_cond_limit(exact, cond_max) {
        return None;
    }
    for (s, &j) in step.iter_mut().zip(passive) {
        *s = scratch[j];
    }
    Some((c, kept))
}
