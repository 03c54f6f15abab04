//! Why inverse kinematics failed: is the pose out of reach, and of which leg?
//!
//! Newton on an IK block ([`inverse_kinematics`](crate::inverse_kinematics())) fails in two
//! ways at a pose that a leg cannot reach: it wanders without converging (`NotConverged`), or,
//! just past the workspace boundary, it approaches the leg's stretched (or folded) posture,
//! where the block's Jacobian is singular (`Singular`). Neither says that the pose is
//! unreachable. After such a failure, [`unreachable_block`] minimises each block's
//! `½ ‖f_b‖²` over the block's coordinates by Levenberg–Marquardt from 32 starts (Newton's,
//! the home assembly, and 30 spread over the block's coordinates by a Weyl sequence): a block
//! whose searches all end at a stationary point with `max |f_b|` well above `tol_f` cannot close
//! at this pose — the
//! pose is out of that leg's reach (the least residual is a distance, e.g. in metres for a
//! position loop). Each search is local, so this is evidence, not proof; one start that closes
//! the block or stays inconclusive makes the answer "did not converge" (Newton's own error), never
//! "out of reach".

use crate::data::Data;
use crate::error::SolverError;
use crate::linalg;
use crate::model::Model;
use crate::tasks::InverseKinematics;

use super::damping::Damping;

/// Most Levenberg–Marquardt iterations per block. Far out of reach the least-squares problem has
/// a large residual and LM converges linearly (a UR5 1.2 m out of reach: the gradient halves
/// about every 50 iterations), so the limit is generous; it costs only on this failure path.
const MAX_ITERATIONS: usize = 2000;
/// Stationary: `max |∇ ½‖f_b‖²| <= STATIONARY · sqrt(max diag JᵀJ) · ‖f_b‖`, the gradient
/// small against the scale of the problem (then the least residual is exact to rounding).
const STATIONARY: f64 = 1e-10;
/// The same test, looser, at the iteration limit: a search that crawls linearly (large
/// residual) is stationary to this (MINPACK's kind of `gtol`), its least residual good to
/// about 1e-7 relative.
const STATIONARY_AT_LIMIT: f64 = 1e-6;
/// The longest step per coordinate (m or rad), as `LmOptions::max_step` of forward kinematics.
const MAX_STEP: f64 = 0.5;
/// A block whose least `max |f_b|` exceeds this multiple of `tol_f` is unreachable.
const UNREACHABLE_FACTOR: f64 = 1e3;

/// The outcome of the least-squares search on one block.
enum Search {
    /// `max |f_b| <= tol_f`: the block closes (Newton failed for another reason).
    Closes,
    /// A stationary point of `‖f_b‖²` with this `max |f_b|`.
    Stationary(f64),
    /// Neither within the iteration limit, or a non-finite value.
    Inconclusive,
}

/// After Newton failed on the IK blocks from `start` (every coordinate, outputs set), the
/// unreachable block (every one of [`STARTS`] searches ends at a stationary point that is not a
/// root) with the largest least residual, as
/// `SolverError::Unreachable { block, residual }`; `None` if every block's search closes the
/// block or is inconclusive (then Newton's own error stands). Allocation-free; writes only
/// `data.f` and `data.g` (kernel buffers).
pub(crate) fn unreachable_block<K: InverseKinematics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    start: &[f64; N],
) -> Option<SolverError> {
    let s = model.structure();
    let tol_f = model.options.tol_f;
    // A least-squares search is local: one start's minimum with a positive residual may be a
    // local one (the UR5's tool-axis loops have local minima centimetres from closing at poses
    // it reaches in another branch). The block is unreachable only when the search from every
    // start ends at a stationary point with a positive residual; the least of those residuals is
    // reported. The starts: the caller's, the home assembly, and the caller's with the block's
    // coordinates moved by a Weyl sequence over [-pi, pi] (rad or m), one irrational rate per
    // coordinate: spread over the block's configuration space, and deterministic.
    let mut home = *start;
    for (j, &h) in s.home.iter().enumerate().take(N) {
        if !s.outputs.contains(&j) {
            home[j] = h;
        }
    }
    let mut worst: Option<(usize, f64)> = None;
    for (b, blk) in s.ik_blocks.iter().enumerate() {
        if blk.rows.len() != blk.cols.len() || blk.rows.len() > M {
            return None;
        }
        let mut least = f64::INFINITY;
        for k in 0..STARTS {
            let from = match k {
                0 => *start,
                1 => home,
                _ => {
                    let mut x = *start;
                    for (i, &j) in blk.cols.iter().enumerate() {
                        // frac(k sqrt(p_i)) with p_i the i-th prime: equidistributed in [0, 1).
                        let rate = PRIMES[i % PRIMES.len()].sqrt();
                        let u = (k as f64 * rate).fract();
                        x[j] = start[j] + std::f64::consts::PI * (2.0 * u - 1.0);
                    }
                    x
                }
            };
            match least_squares(model, data, &from, blk.rows, blk.cols) {
                Search::Stationary(r) if r > UNREACHABLE_FACTOR * tol_f => least = least.min(r),
                _ => {
                    least = f64::NAN;
                    break;
                }
            }
        }
        if least.is_finite() && worst.is_none_or(|(_, w)| least > w) {
            worst = Some((b, least));
        }
    }
    worst.map(|(block, residual)| SolverError::Unreachable { block, residual })
}

/// How many starts the least-squares search tries per block (see [`unreachable_block`]): the
/// caller's, home, and `STARTS - 2` spread over the block's coordinates. Each costs at most
/// `MAX_ITERATIONS` iterations, on the failure path only.
const STARTS: usize = 32;
/// The rates of the Weyl sequence of starts: square roots of primes.
const PRIMES: [f64; 16] = [
    2.0, 3.0, 5.0, 7.0, 11.0, 13.0, 17.0, 19.0, 23.0, 29.0, 31.0, 37.0, 41.0, 43.0, 47.0, 53.0,
];

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// Levenberg–Marquardt (Marquardt's scaling, Nielsen's damping update) on `½ ‖f_rows‖²` over
/// the coordinates `cols`, from `start`.
fn least_squares<K: InverseKinematics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    start: &[f64; N],
    rows: &[usize],
    cols: &[usize],
) -> Search {
    let k = rows.len();
    let kern = model.kernels();
    let tol_f = model.options.tol_f;
    let mut x = *start;
    let mut fb = [0.0; M];
    let mut jac = [[0.0; M]; M];
    let mut a = [[0.0; M]; M];
    let mut chol = [[0.0; M]; M];
    let mut grad = [0.0; M];
    let mut step = [0.0; M];
    // k × k matrices column-major in the first k * k entries.
    let (fb, jac, a, chol, grad, step) = (
        &mut fb[..k],
        &mut jac.as_flattened_mut()[..k * k],
        &mut a.as_flattened_mut()[..k * k],
        &mut chol.as_flattened_mut()[..k * k],
        &mut grad[..k],
        &mut step[..k],
    );
    // f_b and J_b (column-major k × k) at x; false on a non-finite value.
    let eval = |data: &mut Data<N, M>, x: &[f64; N], fb: &mut [f64], jac: &mut [f64]| {
        kern.constraints_jacobian_ik(x, &mut data.f, &mut data.g.data.0);
        for (v, &r) in fb.iter_mut().zip(rows) {
            *v = data.f[r];
        }
        for (c, &j) in cols.iter().enumerate() {
            for (i, &r) in rows.iter().enumerate() {
                jac[c * k + i] = data.g.data.0[j][r];
            }
        }
        fb.iter().chain(jac.iter()).all(|v| v.is_finite())
    };
    if !eval(data, &x, fb, jac) {
        return Search::Inconclusive;
    }
    let mut damping = Damping::new();
    let mut fresh = true;
    for _ in 0..MAX_ITERATIONS {
        let norm2: f64 = fb.iter().map(|v| v * v).sum();
        if max_abs(fb) <= tol_f {
            return Search::Closes;
        }
        if fresh {
            for c in 0..k {
                for r in c..k {
                    let v: f64 = (0..k).map(|i| jac[r * k + i] * jac[c * k + i]).sum();
                    a[c * k + r] = v;
                    a[r * k + c] = v;
                }
                grad[c] = (0..k).map(|i| jac[c * k + i] * fb[i]).sum();
            }
            if damping.mu == 0.0 {
                let dmax = (0..k).fold(0.0_f64, |m, i| m.max(a[i * k + i]));
                damping.mu = 1e-3 * dmax.max(1e-12);
            }
            fresh = false;
        }
        // Stationary: the gradient of ½‖f_b‖² vanishes to rounding, or no step reduces ‖f_b‖.
        let gmax = max_abs(grad);
        let dmax = (0..k).fold(0.0_f64, |m, i| m.max(a[i * k + i]));
        if gmax <= STATIONARY * dmax.sqrt().max(1.0) * norm2.sqrt() || damping.mu > 1e16 {
            return Search::Stationary(max_abs(fb));
        }
        // Marquardt's scaling, floored at 1e-2 of the largest diagonal: a coordinate the block
        // hardly moves (a UR5's wrist roll far out of reach: diagonal 4.5e-13 against 2.1) would
        // otherwise get almost no damping, take the whole trust-region step, and leave LM
        // stalled with a large gradient (measured: 500 iterations at mu ~ 1e7, gradient 0.79).
        chol.copy_from_slice(a);
        for c in 0..k {
            chol[c * k + c] += damping.mu * a[c * k + c].max(1e-2 * dmax).max(1e-12);
        }
        let solved = linalg::cholesky_factor(chol, k).is_ok() && {
            for (st, g) in step.iter_mut().zip(grad.iter()) {
                *st = -g;
            }
            linalg::cholesky_solve(chol, k, step).is_ok() && step.iter().all(|v| v.is_finite())
        };
        if !solved {
            damping.reject();
            continue;
        }
        // Trust region: at most MAX_STEP per coordinate (m or rad), along the LM direction.
        let smax = max_abs(step);
        if smax > MAX_STEP {
            for st in step.iter_mut() {
                *st *= MAX_STEP / smax;
            }
        }
        let mut trial = x;
        for (&j, &d) in cols.iter().zip(step.iter()) {
            trial[j] += d;
        }
        kern.constraints(&trial, &mut data.f);
        let new2: f64 = rows.iter().map(|&r| data.f[r] * data.f[r]).sum();
        // Predicted decrease of ½‖f‖² by the linear model: -gradᵀ step - ½ stepᵀ A step.
        let mut pred = 0.0;
        for c in 0..k {
            let a_step: f64 = (0..k).map(|r| a[c * k + r] * step[r]).sum();
            pred -= step[c] * (grad[c] + 0.5 * a_step);
        }
        let rho = if pred > 0.0 {
            0.5 * (norm2 - new2) / pred
        } else {
            -1.0
        };
        if new2.is_finite() && rho > 0.0 {
            x = trial;
            if !eval(data, &x, fb, jac) {
                return Search::Inconclusive;
            }
            fresh = true;
            damping.accept(rho);
        } else {
            damping.reject();
        }
    }
    let norm2: f64 = fb.iter().map(|v| v * v).sum();
    if fresh {
        for (c, g) in grad.iter_mut().enumerate() {
            *g = (0..k).map(|i| jac[c * k + i] * fb[i]).sum();
        }
    }
    let dmax = (0..k).fold(0.0_f64, |m, i| m.max(a[i * k + i]));
    if max_abs(grad) <= STATIONARY_AT_LIMIT * dmax.sqrt().max(1.0) * norm2.sqrt() {
        return Search::Stationary(max_abs(fb));
    }
    Search::Inconclusive
}
