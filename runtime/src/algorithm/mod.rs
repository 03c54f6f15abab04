//! The solvers, one module per problem (Pinocchio's `algorithm/`), and the machinery they
//! share: block Newton with backtracking, and blockwise linear solves with a condition check.
//!
//! Every solver reads the model and writes `Data`; on success it commits its result
//! (`data.x`, `data.xdot` or `data.xddot`), on error it leaves that result untouched.

pub mod forward_kinematics;
pub mod inverse_kinematics;

pub use forward_kinematics::{forward_acceleration, forward_kinematics, forward_velocity};
pub use inverse_kinematics::{inverse_acceleration, inverse_kinematics, inverse_velocity};

use nalgebra::SMatrix;

use crate::data::{BlockState, Data, Workspace};
use crate::error::SolverError;
use crate::kernels::{IkBlock, Kernels};
use crate::linalg::{self, LuError};
use crate::model::Model;

/// What a successful solve reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    /// Newton steps taken (inverse kinematics: by the slowest block); `0` for the velocity and
    /// acceleration solves, which are direct.
    pub iterations: usize,
    /// Kernel evaluations. Newton solves: `constraints` + Jacobian pairs, line-search trials
    /// included, so `evaluations - iterations - 1` steps were shortened by backtracking (one
    /// more `constraints` call, not counted, measures the final residual). Direct solves: `1`.
    pub evaluations: usize,
    /// The residual at the returned solution: `max |f(X)|` for the position solvers,
    /// `max |G Ẋ|` for velocity, `max |G Ẍ - gamma|` for acceleration.
    pub residual: f64,
    /// The largest estimated 1-norm condition number among the matrices factored at the
    /// returned solution (`J_p`, or the worst inverse-kinematics block).
    pub cond: f64,
}

/// A set of independent square subsystems `(rows, cols)` of `G`.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Blocks<'a> {
    /// The inverse-kinematics blocks of the structure.
    Ik(&'static [IkBlock]),
    /// One system (forward kinematics: all rows, the passive columns).
    Single {
        rows: &'a [usize],
        cols: &'static [usize],
    },
}

impl Blocks<'_> {
    fn len(&self) -> usize {
        match self {
            Blocks::Ik(b) => b.len(),
            Blocks::Single { .. } => 1,
        }
    }

    /// `(rows, cols, block index for errors)`; `b < self.len()`.
    fn get(&self, b: usize) -> (&[usize], &[usize], Option<usize>) {
        match self {
            Blocks::Ik(blocks) => match blocks.get(b) {
                Some(blk) => (blk.rows, blk.cols, Some(b)),
                None => (&[], &[], Some(b)),
            },
            Blocks::Single { rows, cols } => (rows, cols, None),
        }
    }
}

/// Cap on `SolverOptions::max_step_halvings`: a step of `2^-60` is below rounding anyway.
const MAX_HALVINGS: u32 = 60;

/// Which Jacobian kernel a Newton solve calls.
pub(crate) type JacobianKernel<K, const N: usize, const M: usize> =
    fn(&K, &[f64; N], &mut [[f64; M]; N]);

fn lu_error(e: LuError, what: &'static str, block: Option<usize>, k: usize) -> SolverError {
    match e {
        LuError::Singular { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block,
        },
        LuError::NonFinite => SolverError::NonFinite {
            what: "G (Jacobian kernel output)",
        },
        // Unreachable: Model::try_new bounds every block by M, the workspace's order.
        LuError::Dimension => SolverError::Dimension {
            what: "LU workspace",
            expected: k * k,
            found: 0,
        },
    }
}

/// Gathers `G[rows, cols]` into the LU workspace, factors it and estimates its condition
/// number; `Singular` if the estimate exceeds `cond_max`.
#[allow(clippy::too_many_arguments)]
fn factor_block<const N: usize, const M: usize>(
    g: &SMatrix<f64, M, N>,
    rows: &[usize],
    cols: &[usize],
    lu: &mut [[f64; M]; M],
    piv: &mut [usize; M],
    work: &mut [[f64; M]; 2],
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<f64, SolverError> {
    let k = rows.len().min(cols.len()).min(M);
    let a = &mut lu.as_flattened_mut()[..k * k];
    let piv = &mut piv[..k];
    for (c, &j) in cols.iter().take(k).enumerate() {
        let gcol = &g.data.0[j];
        for (r, &i) in rows.iter().take(k).enumerate() {
            a[r + c * k] = gcol[i];
        }
    }
    let err = |e| lu_error(e, what, block, k);
    let anorm = linalg::norm1(a, k).map_err(err)?;
    if !anorm.is_finite() {
        return Err(SolverError::NonFinite {
            what: "G (Jacobian kernel output)",
        });
    }
    linalg::lu_factor(a, k, piv).map_err(err)?;
    let cond = linalg::cond1_estimate(a, k, piv, anorm, work.as_flattened_mut()).map_err(err)?;
    if cond > cond_max || cond.is_nan() {
        return Err(SolverError::Singular { cond, what, block });
    }
    Ok(cond)
}

/// Solves the factored block in place (`b` has the block's order).
fn solve_block<const M: usize>(
    lu: &[[f64; M]; M],
    piv: &[usize; M],
    b: &mut [f64],
    what: &'static str,
    block: Option<usize>,
) -> Result<(), SolverError> {
    let k = b.len().min(M);
    linalg::lu_solve(&lu.as_flattened()[..k * k], k, &piv[..k], b)
        .map_err(|e| lu_error(e, what, block, k))
}

/// `out = G v`.
fn mat_vec<const N: usize, const M: usize>(
    g: &SMatrix<f64, M, N>,
    v: &[f64; N],
    out: &mut [f64; M],
) {
    out.fill(0.0);
    for (col, &vj) in g.data.0.iter().zip(v) {
        if vj != 0.0 {
            for (o, &gij) in out.iter_mut().zip(col) {
                *o += gij * vj;
            }
        }
    }
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

pub(crate) fn check_input(
    what: &'static str,
    v: &[f64],
    expected: usize,
) -> Result<(), SolverError> {
    if v.len() != expected {
        return Err(SolverError::Dimension {
            what,
            expected,
            found: v.len(),
        });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(SolverError::NonFinite { what });
    }
    Ok(())
}

pub(crate) fn check_finite(what: &'static str, v: &[f64]) -> Result<(), SolverError> {
    if v.iter().any(|x| !x.is_finite()) {
        return Err(SolverError::NonFinite { what });
    }
    Ok(())
}

/// Newton's method on independent blocks, from the iterate `data.ws.x` (set by the caller,
/// finite). Each evaluation calls `constraints` and `jacobian` once for all blocks; each
/// unconverged block then either tests its trial step (backtracking) or takes a Newton step.
/// Converged blocks stop updating; the step that passes the convergence test is applied, and
/// one more `constraints` call measures the returned residual. On success `data.ws.x` is the
/// solution, `data.f` is `f` there, and `data.g` is the Jacobian one (tiny) step before it.
pub(crate) fn newton<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    jacobian: JacobianKernel<K, N, M>,
    what: &'static str,
) -> Result<SolveReport, SolverError> {
    let o = model.options;
    let kern = model.kernels();
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        x_base,
        dx,
        rhs,
        lu,
        piv,
        work,
        blocks: states,
    } = ws;
    let nb = blocks.len().min(M);
    let states = &mut states[..nb];
    states.fill(BlockState::default());
    let mut evaluations = 0;
    loop {
        kern.constraints(x, f);
        jacobian(kern, x, &mut g.data.0);
        evaluations += 1;
        let mut done = true;
        for (b, st) in states.iter_mut().enumerate() {
            if st.converged {
                continue;
            }
            let (rows, cols, block) = blocks.get(b);
            let (mut rmax, mut r2) = (0.0_f64, 0.0_f64);
            for &i in rows {
                let v = f[i];
                if !v.is_finite() {
                    return Err(SolverError::NonFinite {
                        what: "f (constraint kernel output)",
                    });
                }
                rmax = rmax.max(v.abs());
                r2 += v * v;
            }
            let rnorm = r2.sqrt();
            if st.trial {
                let accept = rmax <= o.tol_f
                    || rnorm <= (1.0 - 1e-4 * st.alpha) * st.norm_base
                    || st.halvings >= o.max_step_halvings.min(MAX_HALVINGS);
                if !accept {
                    st.alpha *= 0.5;
                    st.halvings += 1;
                    for &j in cols {
                        x[j] = x_base[j] + st.alpha * dx[j];
                    }
                    done = false;
                    continue;
                }
                st.trial = false;
            }

            // Newton step at x: G_b dx = -f_b.
            let cond = factor_block(g, rows, cols, lu, piv, work, o.cond_max, what, block)?;
            let k = rows.len().min(M);
            let step = &mut rhs[..k];
            for (s, &i) in step.iter_mut().zip(rows) {
                *s = -f[i];
            }
            solve_block(lu, piv, step, what, block)?;
            let (mut dmax, mut xmax) = (0.0_f64, 0.0_f64);
            for (&d, &j) in step.iter().zip(cols) {
                if !d.is_finite() {
                    return Err(SolverError::NonFinite {
                        what: "Newton step",
                    });
                }
                dmax = dmax.max(d.abs());
                xmax = xmax.max(x[j].abs());
                dx[j] = d;
            }
            if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + xmax) {
                // Converged; the last, tiny step is still applied: it costs nothing and
                // Newton's quadratic convergence makes the solution far more accurate.
                st.converged = true;
                st.cond = cond;
                for &j in cols {
                    x[j] += dx[j];
                }
                continue;
            }
            if st.steps >= o.max_iterations {
                return Err(SolverError::NotConverged {
                    iterations: st.steps,
                    residual: max_abs(f),
                });
            }
            st.steps += 1;
            st.trial = true;
            st.alpha = 1.0;
            st.halvings = 0;
            st.norm_base = rnorm;
            for &j in cols {
                x_base[j] = x[j];
                x[j] += dx[j];
            }
            done = false;
        }
        if done {
            break;
        }
    }
    // The residual at the returned point, after the final steps.
    kern.constraints(x, f);
    check_finite("f (constraint kernel output)", f)?;
    let mut rep = SolveReport {
        iterations: 0,
        evaluations,
        residual: 0.0,
        cond: 0.0,
    };
    for (b, st) in states.iter().enumerate() {
        let (rows, _, _) = blocks.get(b);
        for &i in rows {
            rep.residual = rep.residual.max(f[i].abs());
        }
        rep.iterations = rep.iterations.max(st.steps);
        rep.cond = rep.cond.max(st.cond);
    }
    Ok(rep)
}

/// Blockwise direct solve of `G v = base` (`base = gamma` if `with_gamma`, else zero) for the
/// blocks' columns of `v = data.ws.x`, whose other entries (the given rates) are set by the
/// caller and whose block entries are zero on entry. Uses `data.g` as it is (the caller runs
/// `Kernels::jacobian`). Returns `(worst cond, max |G v - base|)`.
pub(crate) fn linear_solve<const N: usize, const M: usize>(
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    with_gamma: bool,
    cond_max: f64,
    what: &'static str,
) -> Result<(f64, f64), SolverError> {
    let Data { g, gamma, ws, .. } = data;
    let Workspace {
        x: v,
        dx,
        rhs,
        lu,
        piv,
        work,
        ..
    } = ws;
    // rhs = base - G v, over all rows, before any block writes v.
    mat_vec(g, v, rhs);
    for (r, &gam) in rhs.iter_mut().zip(gamma.iter()) {
        let base = if with_gamma { gam } else { 0.0 };
        *r = base - *r;
    }
    check_finite("right-hand side (G or gamma)", rhs)?;
    let mut worst = 0.0_f64;
    for b in 0..blocks.len() {
        let (rows, cols, block) = blocks.get(b);
        let cond = factor_block(g, rows, cols, lu, piv, work, cond_max, what, block)?;
        worst = worst.max(cond);
        let k = rows.len().min(M).min(N);
        let sol = &mut dx[..k];
        for (s, &i) in sol.iter_mut().zip(rows) {
            *s = rhs[i];
        }
        solve_block(lu, piv, sol, what, block)?;
        check_finite("solution", sol)?;
        for (&s, &j) in sol.iter().zip(cols) {
            v[j] = s;
        }
    }
    mat_vec(g, v, rhs);
    let mut residual = 0.0_f64;
    for (&gv, &gam) in rhs.iter().zip(gamma.iter()) {
        let base = if with_gamma { gam } else { 0.0 };
        residual = residual.max((gv - base).abs());
    }
    Ok((worst, residual))
}
