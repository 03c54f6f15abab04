//! Forward kinematics by Levenberg–Marquardt on `J_p`, for starts far from the solution, with
//! an explicit assembly-mode policy ([`forward_kinematics_lm`]).
//!
//! [`forward_kinematics`](crate::forward_kinematics()) is Newton with backtracking on `‖f‖₂`:
//! fast and exact from a warm start, but from a poor start a full Newton step can jump across
//! the workspace into another assembly mode (another solution `p` of the same `q`), or stall
//! where `J_p` is near singular on the way. Levenberg–Marquardt minimises `½ ‖f(q, p)‖²` with
//! steps `(JᵀJ + mu D) dp = -Jᵀ f` (`J = J_p`, `D = diag(JᵀJ)`, Marquardt's scaling), whose
//! damping `mu` shortens and turns the step towards steepest descent whenever the
//! linear model of `f` is poor (Nielsen's update of `mu` from the gain ratio), and which never
//! factors `J_p` itself on the way: `JᵀJ + mu D` is positive definite for `mu > 0`. Near the
//! solution `mu` falls geometrically and the steps become Newton's.
//!
//! **Mode policy.** A converged solution is a root of `f(q, ·)`, but not necessarily the one
//! the start was near. The report gives `max_change`, the largest `|p_j - p_j,start|` over the
//! passive coordinates (no wrapping of angles: `2 pi` away is "far" too). With
//! [`LmOptions::max_passive_change`] finite, a solution farther than that from the start is
//! rejected with [`FkRobustError::ModeChange`] and `data.x` is left as it was: the caller
//! learns that the start did not determine the assembly mode, instead of silently receiving
//! another one. With the default (`inf`) the change is only reported.

use crate::data::Data;
use crate::error::SolverError;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::ForwardKinematics;

use super::damping::Damping;

/// Settings of [`forward_kinematics_lm`]. The convergence test, `tol_f`, `tol_x` and
/// `cond_max` come from the model's [`SolverOptions`](crate::SolverOptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Initial damping relative to the largest diagonal entry of `JᵀJ`
    /// (`mu_0 = tau max_i (JᵀJ)_ii`). Small values start close to Gauss–Newton (Newton for the
    /// square `J_p`). Default `1e-3` (Madsen, Nielsen & Tingleff).
    pub tau: f64,
    /// Most iterations (accepted plus rejected steps). Default 200.
    pub max_iterations: usize,
    /// Trust-region cap on one step: `max |dp_j| <= max_step` (m or rad); a longer step is
    /// scaled down along its direction. Default `0.5`.
    pub max_step: f64,
    /// Newton phase: once `max |f| <= newton_residual`, try plain Newton steps (`J_p dp = -f`),
    /// keeping each only if it reduces `‖f‖₂` (else an LM step follows). Default `1e-3`.
    pub newton_residual: f64,
    /// The mode policy: reject a converged solution with a passive coordinate farther than this
    /// from the start (see the [module](self) documentation). Default `inf` (report only).
    pub max_passive_change: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            tau: 1e-3,
            max_iterations: 200,
            max_step: 0.5,
            newton_residual: 1e-3,
            max_passive_change: f64::INFINITY,
        }
    }
}

/// What a successful [`forward_kinematics_lm`] reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmReport {
    /// Iterations: LM steps tried (accepted or not) plus Newton steps, not counting the final
    /// (tiny) step that passed the convergence test, as `forward_kinematics` counts.
    pub iterations: usize,
    /// `f` + `J_p` evaluations (`constraints_jacobian_p`) plus `f`-only trial evaluations.
    pub evaluations: usize,
    /// `max |f|` at the returned solution.
    pub residual: f64,
    /// 1-norm condition estimate of `J_p` at the solution.
    pub cond: f64,
    /// `max_j |p_j - p_j,start|` over the passive coordinates.
    pub max_change: f64,
    /// The passive coordinate (index into `X`) that moved most.
    pub max_change_coordinate: usize,
}

/// Why [`forward_kinematics_lm`] failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FkRobustError {
    /// A solver error: `Dimension`/`NonFinite` for bad input, `NotConverged` (iteration limit,
    /// or a stationary point of `‖f‖²` that is not a root), `Singular` when `J_p` is singular
    /// at the converged point (a singularity of the mechanism, as in `forward_kinematics`),
    /// `SpuriousRoot` when the converged point fails the certificate (`certify_position`).
    Solver(SolverError),
    /// Converged, but farther from the start than `LmOptions::max_passive_change`: another
    /// assembly mode (or branch of a joint) than the start's, rejected by the mode policy.
    ModeChange {
        /// `max_j |p_j - p_j,start|` of the rejected solution.
        max_change: f64,
        /// The coordinate (index into `X`) that moved most.
        coordinate: usize,
        /// `max |f|` of the rejected solution.
        residual: f64,
    },
}

impl From<SolverError> for FkRobustError {
    fn from(e: SolverError) -> Self {
        FkRobustError::Solver(e)
    }
}

impl core::fmt::Display for FkRobustError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FkRobustError::Solver(e) => write!(f, "{e}"),
            FkRobustError::ModeChange {
                max_change,
                coordinate,
                residual,
            } => write!(
                f,
                "converged (max |f| = {residual:e}) to another assembly mode: coordinate \
                 {coordinate} moved {max_change} from the start"
            ),
        }
    }
}

impl std::error::Error for FkRobustError {}

const WHAT: &str = "J_p";

fn nonfinite(what: &'static str) -> SolverError {
    SolverError::NonFinite { what }
}

/// Gathers `J_p` (all rows, the passive columns of `g`) column-major into `a` (`M × M`).
fn gather<const N: usize, const M: usize>(g: &[[f64; M]; N], passive: &[usize], a: &mut [f64]) {
    for (c, &j) in passive.iter().enumerate().take(M) {
        a[c * M..(c + 1) * M].copy_from_slice(&g[j]);
    }
}

fn sum_sq(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// Solves `f(q, p) = 0` for the passive coordinates `p` by Levenberg–Marquardt from the start
/// `data.x` (its actuated entries replaced by `q`), as
/// [`forward_kinematics`](crate::forward_kinematics()) does by Newton. Writes `data.x` on
/// success, and `data.f` (`f` at the last iterate) in any case. Allocation-free.
///
/// Iteration: `J = J_p` at `p` (one fused `constraints_jacobian_p` call), `A = JᵀJ`,
/// `g = Jᵀ f`; the step solves `(A + mu diag(A)) dp = -g` by Cholesky and is capped at
/// `LmOptions::max_step`; the trial `p + dp` is accepted when `‖f‖²` decreases (gain ratio
/// `rho > 0`), and `mu` is updated by Nielsen's rule (`mu *= max(1/3, 1 - (2 rho - 1)³)` on
/// success, `mu *= nu, nu *= 2` on failure).
///
/// Convergence: the test of `forward_kinematics` — `max |f| <= tol_f` and the Newton step
/// `J_p dp = -f` (LU) has `max |dp| <= tol_x (1 + max |p|)`, which is applied. From
/// `max |f| <= LmOptions::newton_residual` on, the solver takes such Newton steps (quadratic convergence; LM again if
/// one fails to reduce `‖f‖`). Then the mode policy (see the [module](self) documentation).
///
/// Errors: see [`FkRobustError`]. A stationary point of `‖f‖²` that is not a root
/// (`max |Jᵀ f| <= 1e-14 max(1, ‖f‖²)`, or `mu > 1e16`: no step reduces `‖f‖`) ends the
/// search with `NotConverged` at once instead of spending the iteration limit.
pub fn forward_kinematics_lm<K: ForwardKinematics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q: &[f64],
    options: &LmOptions,
) -> Result<LmReport, FkRobustError> {
    let s = model.structure();
    let o = model.options;
    let kern = model.kernels();
    s.require_actuated("forward kinematics")?;
    if q.len() != s.actuated.len() {
        return Err(SolverError::Dimension {
            what: "q",
            expected: s.actuated.len(),
            found: q.len(),
        }
        .into());
    }
    if q.iter().any(|v| !v.is_finite()) {
        return Err(nonfinite("q").into());
    }
    let bad_option = |v: f64| !(v.is_finite() && v > 0.0);
    if bad_option(options.tau)
        || bad_option(options.max_step)
        || options.newton_residual.is_nan()
        || options.max_passive_change.is_nan()
        || options.max_passive_change <= 0.0
    {
        return Err(nonfinite("LmOptions (tau, max_step, max_passive_change > 0)").into());
    }
    let passive = s.passive;
    let mut x = data.x;
    for (&j, &v) in s.actuated.iter().zip(q) {
        x[j] = v;
    }
    if x.iter().any(|v| !v.is_finite()) {
        return Err(nonfinite("data.x (warm start)").into());
    }
    let start = x;

    // Buffers (stack; M × M matrices column-major in [[f64; M]; M]).
    let mut g = [[0.0; M]; N];
    let mut f = [0.0; M];
    let mut f_trial = [0.0; M];
    let mut jac = [[0.0; M]; M];
    let mut a = [[0.0; M]; M];
    let mut grad = [0.0; M];
    let mut step = [0.0; M];
    let mut piv = [0usize; M];
    let mut work = [[0.0; M]; 2];
    let mut x_trial;

    let mut evaluations = 0;
    let mut iterations = 0;
    let mut damping = Damping::new();
    let mut fresh = true; // f, J (hence A, grad) are current at x
    let mut newton_failed = false; // a Newton step from this x failed
    kern.constraints_jacobian_p(&x, &mut f, &mut g);
    evaluations += 1;
    let finish_err = |data: &mut Data<N, M>, f: &[f64; M], e: SolverError| {
        data.f = *f;
        Err(FkRobustError::Solver(e))
    };
    loop {
        if f.iter().any(|v| !v.is_finite()) {
            return finish_err(data, &f, nonfinite("f (constraint kernel output)"));
        }
        if fresh {
            gather(&g, passive, jac.as_flattened_mut());
            if jac.as_flattened().iter().any(|v| !v.is_finite()) {
                return finish_err(data, &f, nonfinite("J_p (Jacobian kernel output)"));
            }
            // A = JᵀJ, grad = Jᵀ f.
            for c in 0..M {
                for r in c..M {
                    let v: f64 = jac[r].iter().zip(&jac[c]).map(|(u, w)| u * w).sum();
                    a[c][r] = v;
                    a[r][c] = v;
                }
                grad[c] = jac[c].iter().zip(&f).map(|(u, w)| u * w).sum();
            }
            if damping.mu == 0.0 {
                let dmax = (0..M).fold(0.0_f64, |m, i| m.max(a[i][i]));
                damping.mu = options.tau * dmax.max(1e-12);
            }
            fresh = false;
        }
        let rmax = max_abs(&f);
        let norm2 = sum_sq(&f);

        // Newton phase near a root: the convergence test of forward_kinematics. Skipped at a
        // point where a Newton step already failed, and (away from the root) where J_p is too
        // ill-conditioned for it: the damped step handles that.
        if rmax <= options.newton_residual.max(o.tol_f) && !newton_failed {
            let lu = jac;
            let (cond, newton) = newton_step(&lu, &f, &mut piv, &mut work, &mut step);
            match newton {
                Some(()) if cond > o.cond_max && rmax > o.tol_f => newton_failed = true,
                Some(()) => {
                    if cond > o.cond_max {
                        return finish_err(
                            data,
                            &f,
                            SolverError::Singular {
                                cond,
                                what: WHAT,
                                block: None,
                            },
                        );
                    }
                    let dmax = max_abs(&step);
                    let pmax = passive.iter().fold(0.0_f64, |m, &j| m.max(x[j].abs()));
                    x_trial = x;
                    for (&j, &d) in passive.iter().zip(&step) {
                        x_trial[j] += d;
                    }
                    if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + pmax) {
                        // Converged: apply the last tiny step, measure the residual.
                        kern.constraints(&x_trial, &mut f);
                        evaluations += 1;
                        if f.iter().any(|v| !v.is_finite()) {
                            return finish_err(data, &f, nonfinite("f (constraint kernel output)"));
                        }
                        if let Err(e) = super::certify::certify_position(model, &x_trial) {
                            return finish_err(data, &f, e);
                        }
                        return finish(
                            data,
                            &x_trial,
                            &start,
                            &f,
                            passive,
                            options,
                            iterations,
                            evaluations,
                            cond,
                        );
                    }
                    if iterations >= options.max_iterations {
                        break;
                    }
                    iterations += 1;
                    kern.constraints_jacobian_p(&x_trial, &mut f_trial, &mut g);
                    evaluations += 1;
                    if sum_sq(&f_trial) < norm2 || max_abs(&f_trial) <= o.tol_f {
                        x = x_trial;
                        f = f_trial;
                        fresh = true;
                        newton_failed = false;
                        continue;
                    }
                    // Newton did not help: an LM step from x (f, J_p, A, grad are still x's;
                    // only the kernel buffer g holds the trial's columns, unread until the
                    // next evaluation overwrites them).
                    newton_failed = true;
                }
                None => {
                    newton_failed = true;
                    if rmax <= o.tol_f {
                        return finish_err(
                            data,
                            &f,
                            SolverError::Singular {
                                cond,
                                what: WHAT,
                                block: None,
                            },
                        );
                    }
                }
            }
        }

        if iterations >= options.max_iterations {
            break;
        }
        // Stationary point of ‖f‖² that is not a root, or no step reduces ‖f‖.
        if max_abs(&grad) <= 1e-14 * norm2.max(1.0) || damping.mu > 1e16 {
            break;
        }
        iterations += 1;

        // LM step: (A + mu diag(A)) step = -grad.
        let mut chol = a;
        for (c, col) in chol.iter_mut().enumerate() {
            col[c] += damping.mu * col[c].max(1e-12);
        }
        let ok = linalg::cholesky_factor(chol.as_flattened_mut(), M).is_ok();
        if !ok {
            damping.reject();
            continue;
        }
        for (st, gr) in step.iter_mut().zip(&grad) {
            *st = -gr;
        }
        if linalg::cholesky_solve(chol.as_flattened(), M, &mut step).is_err()
            || step.iter().any(|v| !v.is_finite())
        {
            damping.reject();
            continue;
        }
        let smax = max_abs(&step);
        if smax > options.max_step {
            let scale = options.max_step / smax;
            for st in step.iter_mut() {
                *st *= scale;
            }
        }
        x_trial = x;
        for (&j, &d) in passive.iter().zip(&step) {
            x_trial[j] += d;
        }
        kern.constraints(&x_trial, &mut f_trial);
        evaluations += 1;
        let new2 = sum_sq(&f_trial);
        // Predicted decrease of ½‖f‖²: ½ stepᵀ (mu D step - grad).
        let mut pred = 0.0;
        for c in 0..M {
            pred += step[c] * (damping.mu * a[c][c].max(1e-12) * step[c] - grad[c]);
        }
        pred *= 0.5;
        let actual = 0.5 * (norm2 - new2);
        let rho = if pred > 0.0 { actual / pred } else { -1.0 };
        if new2.is_finite() && rho > 0.0 {
            x = x_trial;
            newton_failed = false;
            kern.constraints_jacobian_p(&x, &mut f, &mut g);
            evaluations += 1;
            fresh = true;
            damping.accept(rho);
        } else {
            damping.reject();
        }
    }
    let residual = max_abs(&f);
    finish_err(
        data,
        &f,
        SolverError::NotConverged {
            iterations,
            residual,
        },
    )
}

/// The Newton step `J dp = -f` by LU, with the condition estimate of `J` (`inf` for an exact
/// zero pivot, in which case the step is `None`).
fn newton_step<const M: usize>(
    jac: &[[f64; M]; M],
    f: &[f64; M],
    piv: &mut [usize; M],
    work: &mut [[f64; M]; 2],
    step: &mut [f64; M],
) -> (f64, Option<()>) {
    let mut lu = *jac;
    let a = lu.as_flattened_mut();
    let Ok(anorm) = linalg::norm1(a, M) else {
        return (f64::INFINITY, None);
    };
    match linalg::lu_factor(a, M, piv) {
        Ok(()) => {}
        Err(LuError::Singular { .. }) | Err(_) => return (f64::INFINITY, None),
    }
    let cond =
        linalg::cond1_estimate(a, M, piv, anorm, work.as_flattened_mut()).unwrap_or(f64::INFINITY);
    for (s, v) in step.iter_mut().zip(f) {
        *s = -v;
    }
    if linalg::lu_solve(a, M, piv, step).is_err() || step.iter().any(|v| !v.is_finite()) {
        return (cond, None);
    }
    (cond, Some(()))
}

/// Applies the mode policy and commits the solution.
#[allow(clippy::too_many_arguments)]
fn finish<const N: usize, const M: usize>(
    data: &mut Data<N, M>,
    x: &[f64; N],
    start: &[f64; N],
    f: &[f64; M],
    passive: &[usize],
    options: &LmOptions,
    iterations: usize,
    evaluations: usize,
    cond: f64,
) -> Result<LmReport, FkRobustError> {
    let (mut max_change, mut coordinate) = (0.0_f64, passive.first().copied().unwrap_or(0));
    for &j in passive {
        let d = (x[j] - start[j]).abs();
        if d > max_change {
            max_change = d;
            coordinate = j;
        }
    }
    let residual = max_abs(f);
    data.f = *f;
    if max_change > options.max_passive_change {
        return Err(FkRobustError::ModeChange {
            max_change,
            coordinate,
            residual,
        });
    }
    data.x = *x;
    Ok(LmReport {
        iterations,
        evaluations,
        residual,
        cond,
        max_change,
        max_change_coordinate: coordinate,
    })
}
