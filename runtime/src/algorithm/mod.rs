//! The solvers, one module per problem (Pinocchio's `algorithm/`), and the machinery they
//! share: block Newton with backtracking, and blockwise linear solves with a condition check.
//!
//! Every solver reads the model and writes `Data`; on success it commits its result
//! (`data.x`, `data.xdot` or `data.xddot`), on error it leaves that result untouched.

pub mod fk_robust;
pub mod forward_dynamics;
pub mod forward_kinematics;
pub mod inverse_dynamics;
pub mod inverse_kinematics;
pub mod projection;

pub use forward_dynamics::forward_dynamics;
pub use forward_kinematics::{forward_acceleration, forward_kinematics, forward_velocity};
pub use inverse_dynamics::{inverse_dynamics, inverse_dynamics_dense};
pub use inverse_kinematics::{inverse_acceleration, inverse_kinematics, inverse_velocity};
pub use projection::{project_position, project_velocity};

use nalgebra::SMatrix;

use crate::data::{BlockState, Data, Workspace};
use crate::error::SolverError;
use crate::kernels::{Dynamics, IkBlock, Kernels};
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

/// Which algorithm a dynamics solve used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DynamicsMethod {
    /// Inverse dynamics by block elimination: one transposed solve per inverse-kinematics
    /// block `G_kk`, then the small reduced system in `U` (order `N - M`).
    BlockElimination,
    /// Inverse dynamics by a dense LU of the N × N matrix `[S | Gᵀ]`.
    DenseLu,
    /// Forward dynamics by the Schur complement `G M⁻¹ Gᵀ` on the block-diagonal `M`.
    SchurComplement,
}

/// What a successful dynamics solve ([`inverse_dynamics()`], [`forward_dynamics()`]) reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicsReport {
    /// The algorithm used.
    pub method: DynamicsMethod,
    /// Conditioning of the small blocks.
    ///
    /// - Inverse dynamics: the largest 1-norm condition estimate of the inverse-kinematics
    ///   blocks `G_kk` (block elimination). When a block was singular and the solve fell back
    ///   to the dense LU, the estimate of that block (`inf` for a zero pivot).
    /// - Forward dynamics: `max l_ii² / min l_ii²` over the Cholesky pivots of all blocks of
    ///   `M`, a lower bound of the 2-norm condition number of `M` (exact for a diagonal `M`).
    pub cond_blocks: f64,
    /// The estimated 1-norm condition number of the main system: the reduced `U` system
    /// (block elimination), `[S | Gᵀ]` (dense LU) or `S_c = G M⁻¹ Gᵀ` (forward dynamics).
    /// Above `SolverOptions::cond_max` the solve fails with `Singular` instead.
    pub cond: f64,
    /// The residual of the solved equations at the result. Inverse dynamics:
    /// `max |M Ẍ - psi - Q - S U + Gᵀ lambda|` (forces). Forward dynamics:
    /// `max |G Ẍ - gamma_stab|` (the acceleration constraint, with Baumgarte's terms).
    pub residual: f64,
}

/// Baumgarte's constraint stabilisation in forward dynamics: the acceleration constraint
/// `G Ẍ = gamma` becomes `G Ẍ = gamma - 2 alpha G Ẋ - beta² f(X)`, so that the constraint
/// error `e = f(X)` obeys `ë + 2 alpha ė + beta² e = 0` instead of `ë = 0`.
///
/// `alpha = beta = 0` ([`Baumgarte::NONE`], the default) is the plain index-1 system. With
/// `alpha = beta = ω` the error decays critically damped with time constant `1/ω`; an explicit
/// integrator then needs `ω h` well inside its stability region (RK4 and DOPRI5: about 2.8 and
/// 3.3 on the negative real axis). See [`Baumgarte::DEFAULT`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Baumgarte {
    /// Damping gain `alpha` (1/s).
    pub alpha: f64,
    /// Stiffness gain `beta` (1/s).
    pub beta: f64,
}

impl Baumgarte {
    /// No stabilisation.
    pub const NONE: Self = Self {
        alpha: 0.0,
        beta: 0.0,
    };

    /// `alpha = beta = 10 /s`: critically damped, time constant 0.1 s.
    ///
    /// Why 10, measured on the paper's round trip (`TraekP` over 2 s, feed-forward `U` from
    /// inverse dynamics; `runtime/tests/dynamics.rs`), sweeping `ω` over 1, 2, 5, 10, 20, 50,
    /// 100 /s:
    ///
    /// - the drift comes from integration error, and the violation settles near
    ///   (local error rate) / ω²: at `ω = 10` the largest `|f|` is about 100 times smaller than
    ///   without stabilisation for RK4 (`dt` 1e-2 and 1e-3) and DOPRI5 (rtol 1e-4 to 1e-8);
    /// - but the stabilised system gains a double eigenvalue `-ω` that the integrator must
    ///   resolve: with RK4 at `dt = 1e-2` the violation is smallest at `ω` = 5 to 10 and grows
    ///   again beyond (3e-7 at 50 /s, worse than 1.1e-8 at 10 /s); DOPRI5's error control
    ///   shortens its steps, costing +40 % right-hand-side evaluations at `ω = 10` (rtol 1e-6),
    ///   +110 % at 20 and +330 % at 50.
    pub const DEFAULT: Self = Self {
        alpha: 10.0,
        beta: 10.0,
    };

    /// Critically damped gains `alpha = beta = omega`.
    pub const fn critical(omega: f64) -> Self {
        Self {
            alpha: omega,
            beta: omega,
        }
    }
}

impl Default for Baumgarte {
    fn default() -> Self {
        Self::NONE
    }
}

/// Checks that `Dynamics::mass_blocks` lists every coordinate exactly once, in range, with no
/// empty block (after this the dynamics solvers index with them without any bounds failure).
pub(crate) fn check_mass_blocks<const N: usize>(blocks: &[&[usize]]) -> Result<(), SolverError> {
    let mut seen = [false; N];
    let mut count = 0;
    let bad = |found| SolverError::Dimension {
        what: "Dynamics::mass_blocks (each coordinate exactly once)",
        expected: N,
        found,
    };
    for blk in blocks {
        if blk.is_empty() {
            return Err(bad(count));
        }
        for &j in blk.iter() {
            match seen.get_mut(j) {
                Some(s) if !*s => {
                    *s = true;
                    count += 1;
                }
                _ => return Err(bad(count + 1)),
            }
        }
    }
    if count != N {
        return Err(bad(count));
    }
    Ok(())
}

/// `out = M v` with the block-diagonal `M` (blocks checked by [`check_mass_blocks`]).
pub(crate) fn mass_times<const N: usize>(
    mass: &SMatrix<f64, N, N>,
    blocks: &[&[usize]],
    v: &[f64; N],
    out: &mut [f64; N],
) {
    for blk in blocks {
        for &r in blk.iter() {
            let mut s = 0.0;
            for &c in blk.iter() {
                s += mass.data.0[c][r] * v[c];
            }
            out[r] = s;
        }
    }
}

/// Evaluates `G`, `gamma`, `M` and `psi` at `data.x`, `data.xdot` (finite, checked by the
/// caller) with the fused `Dynamics::dynamics_terms` kernel into `data.g`, `data.gamma`,
/// `data.mass`, `data.psi`, after checking the mass blocks; returns the blocks.
pub(crate) fn dynamics_terms<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<&'static [&'static [usize]], SolverError> {
    let k = model.kernels();
    let blocks = k.mass_blocks();
    check_mass_blocks::<N>(blocks)?;
    k.dynamics_terms(
        &data.x,
        &data.xdot,
        &mut data.g.data.0,
        &mut data.gamma,
        &mut data.mass.data.0,
        &mut data.psi,
    );
    check_finite("G (Jacobian kernel output)", data.g.as_slice())?;
    check_finite("gamma (kernel output)", &data.gamma)?;
    check_finite("M (mass kernel output)", data.mass.as_slice())?;
    check_finite("psi (kernel output)", &data.psi)?;
    Ok(blocks)
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

/// What a `NonFinite` from a factorisation of `G`'s blocks names.
const G_SOURCE: &str = "G (Jacobian kernel output)";

/// Maps a factorisation error to the solver's; `source` names the matrix's origin for
/// `NonFinite`.
pub(crate) fn lu_error(
    e: LuError,
    what: &'static str,
    block: Option<usize>,
    k: usize,
    source: &'static str,
) -> SolverError {
    match e {
        // A zero pivot (LU), or a non-positive pivot of a Gram matrix that must be positive
        // definite when the mechanism is regular (Cholesky of G Gᵀ or G M⁻¹ Gᵀ).
        LuError::Singular { .. } | LuError::NotPositiveDefinite { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block,
        },
        LuError::NonFinite => SolverError::NonFinite { what: source },
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
    for (c, &j) in cols.iter().take(k).enumerate() {
        let gcol = &g.data.0[j];
        for (r, &i) in rows.iter().take(k).enumerate() {
            a[r + c * k] = gcol[i];
        }
    }
    factor_lu(
        a,
        k,
        &mut piv[..k],
        work.as_flattened_mut(),
        cond_max,
        what,
        block,
        G_SOURCE,
    )
}

/// Factors the column-major `k × k` matrix `a` in place (LU with partial pivoting) and
/// estimates its 1-norm condition number; `Singular` if the estimate exceeds `cond_max`,
/// `NonFinite { what: source }` for a NaN or infinite entry. `piv.len() == k`,
/// `work.len() >= 2 k`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn factor_lu(
    a: &mut [f64],
    k: usize,
    piv: &mut [usize],
    work: &mut [f64],
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
    source: &'static str,
) -> Result<f64, SolverError> {
    let err = |e| lu_error(e, what, block, k, source);
    let anorm = linalg::norm1(a, k).map_err(err)?;
    if !anorm.is_finite() {
        return Err(SolverError::NonFinite { what: source });
    }
    linalg::lu_factor(a, k, piv).map_err(err)?;
    let cond = linalg::cond1_estimate(a, k, piv, anorm, work).map_err(err)?;
    check_cond(cond, cond_max, what, block)
}

/// Cholesky-factors the symmetric column-major `k × k` matrix `a` in place (both triangles
/// given: the 1-norm is taken over the whole matrix) and estimates its 1-norm condition number.
/// A non-positive pivot is `Singular` (the Gram matrices factored this way are positive
/// definite exactly when the mechanism is regular), as is an estimate above `cond_max`.
pub(crate) fn factor_spd(
    a: &mut [f64],
    k: usize,
    work: &mut [f64],
    cond_max: f64,
    what: &'static str,
    source: &'static str,
) -> Result<f64, SolverError> {
    let err = |e| lu_error(e, what, None, k, source);
    let anorm = linalg::norm1(a, k).map_err(err)?;
    if !anorm.is_finite() {
        return Err(SolverError::NonFinite { what: source });
    }
    linalg::cholesky_factor(a, k).map_err(err)?;
    let cond = linalg::cholesky_cond1_estimate(a, k, anorm, work).map_err(err)?;
    check_cond(cond, cond_max, what, None)
}

fn check_cond(
    cond: f64,
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<f64, SolverError> {
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
        .map_err(|e| lu_error(e, what, block, k, G_SOURCE))
}

/// Solves the transpose of the factored block in place (`b` has the block's order).
pub(crate) fn solve_block_transpose<const M: usize>(
    lu: &[[f64; M]; M],
    piv: &[usize; M],
    b: &mut [f64],
    what: &'static str,
    block: Option<usize>,
) -> Result<(), SolverError> {
    let k = b.len().min(M);
    linalg::lu_solve_transpose(&lu.as_flattened()[..k * k], k, &piv[..k], b)
        .map_err(|e| lu_error(e, what, block, k, G_SOURCE))
}

/// `out = G v`.
pub(crate) fn mat_vec<const N: usize, const M: usize>(
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

pub(crate) fn max_abs(v: &[f64]) -> f64 {
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
        ..
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
