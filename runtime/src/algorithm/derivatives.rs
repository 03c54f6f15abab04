//! The derivatives of forward dynamics: `∂Ẍ/∂X`, `∂Ẍ/∂Ẋ`, `∂Ẍ/∂U` and `∂lambda/∂X`,
//! `∂lambda/∂Ẋ`, `∂lambda/∂U` at one state.
//!
//! Forward dynamics solves `M Ẍ + Gᵀ lambda = psi + Q + S U` and `G Ẍ = gamma` (see
//! `design.md`). With the inverse-dynamics residual `r = M Ẍ - psi + Gᵀ lambda` and the
//! acceleration constraint `c = G Ẍ - gamma`, whose derivatives the generated kernel
//! `dynamics_derivatives` writes (the chain rule through the generator's named intermediates),
//! the implicit function theorem gives, for a perturbation `(dX, dẊ, dU)` at fixed `Q`:
//!
//! ```text
//! [M  Gᵀ] [dẌ     ]     [∂r/∂X dX + ∂r/∂Ẋ dẊ - S dU]
//! [G  0 ] [dlambda] = - [∂c/∂X dX + ∂c/∂Ẋ dẊ        ]
//! ```
//!
//! one saddle-point system with `2 N + (N - M)` right-hand sides, the matrix forward dynamics
//! just solved with. It is solved in forward dynamics' structure (the elimination onto the
//! outputs' coordinates, `forward_dynamics/reduced.rs`): the inverse-kinematics blocks `K_b` of
//! `G` inverted explicitly, `R = [-G_y⁻¹ G_z; I]` kept as its rows `Rᵀ` (`P × N`), and the
//! `P × P` reduced mass matrix `H = Rᵀ M R` factored once by Cholesky; then for every
//! right-hand side `(a, b)` of `M x + Gᵀ l = a`, `G x = b`:
//!
//! ```text
//! x0 = G_y⁻¹ b (block by block),  H z = Rᵀ (a - M x0),  x = x0 + R z,
//! l_b = K_b⁻ᵀ (a - M x)[C_b]       (the rows of block b)
//! ```
//!
//! (`G R = 0`, so the constraint forces drop out of the reduced equation.) The factors are
//! certified by the checks forward dynamics' elimination uses: every block's exact 1-norm
//! condition number at most `FD_K_COND_MAX` (and `cond_max`), the Cholesky pivots positive and
//! their ratio below forward dynamics' threshold (past it, the Hager/Higham estimate of
//! `cond(H)` against `cond_max`). When the elimination declines (no outputs, a block near a
//! serial singularity, `H` not certified) the saddle-point matrix is factored densely (LU with
//! partial pivoting of the `(N + M) × (N + M)` matrix, its condition estimated), which decides
//! `Singular`. [`ForwardDynamicsDerivatives::method`] says which path answered. The derivatives
//! are those of the unstabilised system (`Baumgarte::NONE`).

use nalgebra::SMatrix;

use super::baumgarte::Baumgarte;
use super::forward_dynamics::forward_dynamics;
use super::forward_dynamics::{FD_K_COND_MAX, fd_cond_check};
use super::input::all_finite;
use super::report::{DynamicsMethod, DynamicsReport};
use crate::data::Data;
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::plan::mass_times;
use crate::tasks::Derivatives;

/// The most outputs the structured solve takes (the order of `Rᵀ M R`), as forward dynamics'
/// elimination.
pub(crate) const P_MAX: usize = 16;

/// `(Rᵀ, the blocks' K_b⁻¹, (max ‖K_b‖₁, max ‖K_b⁻¹‖₁))` of the elimination.
pub(crate) type ReducedParts<'a> = (&'a [f64], &'a [f64], (f64, f64));

/// The elimination's factors (see [`ForwardDynamicsDerivatives::reduced_factors`]).
pub(crate) struct ReducedFactors<'a> {
    pub rt: &'a [f64],
    pub mrt: &'a [f64],
    pub chol: &'a [f64],
    pub inv: &'a [f64],
}

/// The derivatives of forward dynamics at one state and the buffers that compute them:
/// [`ForwardDynamicsDerivatives::new`] allocates once, [`forward_dynamics_derivatives`] never.
#[derive(Debug, Clone)]
pub struct ForwardDynamicsDerivatives<const N: usize, const M: usize> {
    /// `∂Ẍ/∂X` (N × N).
    pub dxddot_dx: SMatrix<f64, N, N>,
    /// `∂Ẍ/∂Ẋ` (N × N).
    pub dxddot_dxdot: SMatrix<f64, N, N>,
    /// `∂Ẍ/∂U` (N × N): column `a` for the control force `u[a]` on `Structure::actuated[a]`;
    /// the columns from `Structure::actuated.len()` on stay zero.
    pub dxddot_du: SMatrix<f64, N, N>,
    /// `∂lambda/∂X` (M × N).
    pub dlambda_dx: SMatrix<f64, M, N>,
    /// `∂lambda/∂Ẋ` (M × N).
    pub dlambda_dxdot: SMatrix<f64, M, N>,
    /// `∂lambda/∂U` (M × N), columns as in `dxddot_du`.
    pub dlambda_du: SMatrix<f64, M, N>,
    /// `∂r/∂X` of the residual `r = M Ẍ - psi + Gᵀ lambda` at the solution (N × N), as the
    /// generated kernel wrote it.
    pub dr_dx: SMatrix<f64, N, N>,
    /// `∂r/∂Ẋ = -∂psi/∂Ẋ` (N × N).
    pub dr_dxdot: SMatrix<f64, N, N>,
    /// `∂c/∂X` of `c = G Ẍ - gamma` at the solution (M × N).
    pub dc_dx: SMatrix<f64, M, N>,
    /// `∂c/∂Ẋ = -∂gamma/∂Ẋ` (M × N).
    pub dc_dxdot: SMatrix<f64, M, N>,
    /// The path that solved: [`DynamicsMethod::Reduced`] (the elimination onto the outputs) or
    /// [`DynamicsMethod::SaddlePoint`] (the dense LU).
    pub method: DynamicsMethod,
    /// `Reduced`: the largest exact 1-norm condition number of the blocks `K_b`;
    /// `SaddlePoint`: infinity (no blocks).
    pub cond_blocks: f64,
    /// `Reduced`: the condition of `Rᵀ M R` as forward dynamics reports it (the Cholesky pivot
    /// ratio `(max l_ii / min l_ii)²`, or the Hager/Higham estimate past the threshold);
    /// `SaddlePoint`: the Hager/Higham estimate of the 1-norm condition number of
    /// `[M Gᵀ; G 0]`.
    pub cond: f64,
    /// `Reduced`: the largest 1-norms of the blocks `K_b` and of their inverses (the exact
    /// 1-norm condition number of the block-diagonal `G_y` is their product).
    norms: (f64, f64),
    /// Baumgarte's terms were added to `dc_dx`, `dc_dxdot` (possibly off the kernel's
    /// structural non-zeros, which are all it writes): the next call clears them first.
    gains_added: bool,
    /// `K_b⁻¹` of every block, column-major, packed in block order.
    inv: Vec<f64>,
    /// `Rᵀ`: `P` rows of length N (row `c`: the motion of output `c`).
    rt: Vec<f64>,
    /// `(M R)ᵀ`, as `rt`.
    mrt: Vec<f64>,
    /// The Cholesky factor of `Rᵀ M R` (`P × P`, column-major, lower triangle).
    chol: Vec<f64>,
    /// The right-hand sides as rows (`2 N + (N - M)` long; see `reduced_solve_all`): `A`
    /// (N rows), `A - M X` (N), `B` then lambda (M), `X` (N), `Z` (`P_MAX`).
    wa: Vec<f64>,
    wr: Vec<f64>,
    wb: Vec<f64>,
    wx: Vec<f64>,
    /// `X0 = G_y⁻¹ B` (rows of the blocks' coordinates; the others are not written).
    wx0: Vec<f64>,
    wz: Vec<f64>,
    /// LU factors of `[M Gᵀ; G 0]`, column-major, `(N + M)²`.
    kkt: Vec<f64>,
    piv: Vec<usize>,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl<const N: usize, const M: usize> ForwardDynamicsDerivatives<N, M> {
    /// Zeroed derivatives and the saddle-point system's buffers (the only allocation).
    pub fn new() -> Self {
        let k = N + M;
        Self {
            dxddot_dx: SMatrix::zeros(),
            dxddot_dxdot: SMatrix::zeros(),
            dxddot_du: SMatrix::zeros(),
            dlambda_dx: SMatrix::zeros(),
            dlambda_dxdot: SMatrix::zeros(),
            dlambda_du: SMatrix::zeros(),
            dr_dx: SMatrix::zeros(),
            dr_dxdot: SMatrix::zeros(),
            dc_dx: SMatrix::zeros(),
            dc_dxdot: SMatrix::zeros(),
            method: DynamicsMethod::Reduced,
            cond_blocks: f64::NAN,
            cond: f64::NAN,
            norms: (f64::NAN, f64::NAN),
            gains_added: false,
            inv: vec![0.0; M * linalg::INVERT_MAX],
            rt: vec![0.0; P_MAX * N],
            mrt: vec![0.0; P_MAX * N],
            chol: vec![0.0; P_MAX * P_MAX],
            wa: vec![0.0; N * row_width(N, N)],
            wr: vec![0.0; N * row_width(N, N)],
            wb: vec![0.0; M * row_width(N, N)],
            wx: vec![0.0; N * row_width(N, N)],
            wx0: vec![0.0; N * row_width(N, N)],
            wz: vec![0.0; P_MAX * row_width(N, N)],
            kkt: vec![0.0; k * k],
            piv: vec![0; k],
            rhs: vec![0.0; k],
            work: vec![0.0; 2 * k],
        }
    }
}

impl<const N: usize, const M: usize> ForwardDynamicsDerivatives<N, M> {
    /// `∂Ẍ/∂(X, Ẋ, U)` as rows of the width `row_width(N, na)` (`na` control forces): row `i`
    /// holds `∂Ẍ_i/∂X` (N entries), `∂Ẍ_i/∂Ẋ` (N), `∂Ẍ_i/∂U` (na) and zeros; what the last
    /// successful call wrote, on either path.
    pub(crate) fn xddot_rows(&self) -> &[f64] {
        &self.wx
    }

    /// After the elimination (`method == Reduced`): `Rᵀ` (the tangent map onto the outputs,
    /// `P` rows of length N), the blocks' inverses `K_b⁻¹` (column-major, packed in block
    /// order) and the largest 1-norms of `K_b` and `K_b⁻¹`; `None` after the dense LU.
    pub(crate) fn reduced_parts(&self) -> Option<ReducedParts<'_>> {
        (self.method == DynamicsMethod::Reduced).then_some((&self.rt, &self.inv, self.norms))
    }

    /// After the elimination's factors (`method == Reduced`) with `p` outputs: `Rᵀ` and
    /// `(M R)ᵀ` (`p` rows of length N), the Cholesky factor of `Rᵀ M R` (`p × p`,
    /// column-major, lower triangle) and the blocks' `K_b⁻¹` (column-major, packed in block
    /// order); `None` after the dense LU.
    pub(crate) fn reduced_factors(&self, p: usize) -> Option<ReducedFactors<'_>> {
        (self.method == DynamicsMethod::Reduced && p <= P_MAX).then(|| ReducedFactors {
            rt: &self.rt[..p * N],
            mrt: &self.mrt[..p * N],
            chol: &self.chol[..p * p],
            inv: &self.inv,
        })
    }

    /// After the elimination: `∂Ẍ/∂(X, Ẋ, U) = X0 + R Z` split, as rows of the row width:
    /// `(X0, Z)` with `X0`'s rows those of the blocks' coordinates only (the others are zero
    /// and not written) and `Z` the `P` rows of the outputs; `None` after the dense LU.
    pub(crate) fn low_rank_rows(&self) -> Option<(&[f64], &[f64])> {
        (self.method == DynamicsMethod::Reduced).then_some((&self.wx0, &self.wz))
    }
}

impl<const N: usize, const M: usize> Default for ForwardDynamicsDerivatives<N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Forward dynamics at `data.x`, `data.xdot` with the control forces `u` and the generalised
/// forces `q_forces` (held fixed), then its derivatives with respect to `X`, `Ẋ` and `U` into
/// `out` (see the [module](self) documentation). Writes what [`forward_dynamics`] writes
/// (`data.xddot`, `data.lambda`, ...) and returns its report.
///
/// Errors: those of [`forward_dynamics`] (without stabilisation); `NonFinite` when the
/// derivative kernel's outputs are not finite; `Singular` (`what`: `"[M Gᵀ; G 0]"`) when the
/// saddle-point matrix is exactly singular or its condition estimate exceeds
/// `SolverOptions::cond_max` (a rank-deficient `G`: redundant constraints leave `lambda`, and
/// so its derivatives, not unique).
pub fn forward_dynamics_derivatives<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    forward_dynamics_derivatives_with(
        model,
        data,
        out,
        u,
        q_forces,
        Baumgarte::NONE,
        DerivativesSolver::Auto,
    )
}

/// Which solve [`forward_dynamics_derivatives_with`] uses for the right-hand sides.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DerivativesSolver {
    /// The elimination onto the outputs, the dense LU when it declines (what
    /// [`forward_dynamics_derivatives`] does).
    Auto,
    /// The dense LU of `[M Gᵀ; G 0]` alone: the reference the elimination is tested against.
    SaddlePointLu,
}

/// [`forward_dynamics_derivatives`] with Baumgarte's stabilisation `baumgarte` (the
/// derivatives of the stabilised system `G Ẍ = gamma - 2 alpha G Ẋ - beta² f`: `∂c/∂X` gains
/// `2 alpha ∂(G Ẋ)/∂X + beta² G = alpha ∂c/∂Ẋ + beta² G` with the unstabilised `∂c/∂Ẋ`
/// (`= 2 ∂(G Ẋ)/∂X`, see `linearize`), `∂c/∂Ẋ` gains `2 alpha G`; `dc_dx`, `dc_dxdot` hold
/// the stabilised ones) and the solve `solver`; the same outputs and errors.
pub fn forward_dynamics_derivatives_with<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
    solver: DerivativesSolver,
) -> Result<DynamicsReport, SolverError> {
    let (report, reduced) = prepare(model, data, out, u, q_forces, baumgarte, solver)?;
    solve_prepared(model, data, out, reduced, Outputs::All)?;
    Ok(report)
}

/// What [`solve_prepared`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Outputs {
    /// Every output of [`ForwardDynamicsDerivatives`].
    All,
    /// After the elimination, only the rows of `∂Ẍ/∂(X, Ẋ, U)` (`xddot_rows`,
    /// `low_rank_rows`): not `∂lambda`, not the column-major `dxddot_*` (the dense LU writes
    /// everything).
    XddotRows,
}

/// The right-hand sides of the last [`prepare`] solved: by the elimination when its factors
/// were certified (`reduced`), else by the dense LU (which decides `Singular`).
pub(crate) fn solve_prepared<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    reduced: bool,
    outputs: Outputs,
) -> Result<(), SolverError> {
    if reduced {
        reduced_solve_all(model, data, out, outputs)
    } else {
        saddle_solve_all(model, data, out)
    }
}

/// Everything of [`forward_dynamics_derivatives_with`] but the right-hand sides' solve:
/// forward dynamics, the kernel's `∂r`, `∂c` (with Baumgarte's terms) and, for
/// `DerivativesSolver::Auto`, the elimination's factors (`method`, `cond_blocks`, `cond` set
/// when certified). Returns forward dynamics' report and whether the elimination's factors
/// are certified (the right-hand sides then go through them, see [`solve_prepared`]).
pub(crate) fn prepare<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
    solver: DerivativesSolver,
) -> Result<(DynamicsReport, bool), SolverError> {
    let report = forward_dynamics(model, data, u, q_forces, baumgarte)?;
    let Baumgarte { alpha, beta } = baumgarte;
    // The kernel writes only the structural non-zeros: clear what the gains' terms of an
    // earlier call may have left elsewhere.
    if out.gains_added {
        out.dc_dx.as_mut_slice().fill(0.0);
        out.dc_dxdot.as_mut_slice().fill(0.0);
        out.gains_added = false;
    }
    model.kernels().dynamics_derivatives(
        &data.x,
        &data.xdot,
        &data.xddot,
        &data.lambda,
        &mut out.dr_dx.data.0,
        &mut out.dr_dxdot.data.0,
        &mut out.dc_dx.data.0,
        &mut out.dc_dxdot.data.0,
    );
    for v in [
        out.dr_dx.as_slice(),
        out.dr_dxdot.as_slice(),
        out.dc_dx.as_slice(),
        out.dc_dxdot.as_slice(),
    ] {
        if !all_finite(v) {
            return Err(SolverError::NonFinite {
                what: "dynamics_derivatives",
            });
        }
    }
    if alpha != 0.0 || beta != 0.0 {
        out.gains_added = true;
        let g = &data.g.data.0;
        let b2 = beta * beta;
        for ((cx, cv), gc) in out
            .dc_dx
            .data
            .0
            .iter_mut()
            .zip(out.dc_dxdot.data.0.iter_mut())
            .zip(g)
        {
            for ((x, v), &gi) in cx.iter_mut().zip(cv.iter_mut()).zip(gc) {
                *x += alpha * *v + b2 * gi;
                *v += 2.0 * alpha * gi;
            }
        }
    }
    let reduced = match solver {
        DerivativesSolver::Auto => reduced_factor(model, data, out),
        DerivativesSolver::SaddlePointLu => None,
    };
    if let Some((cond_blocks, cond)) = reduced {
        out.method = DynamicsMethod::Reduced;
        out.cond_blocks = cond_blocks;
        out.cond = cond;
    } else {
        out.method = DynamicsMethod::SaddlePoint;
        out.cond_blocks = f64::INFINITY;
    }
    Ok((report, reduced.is_some()))
}

/// The elimination's factors at `data` (see the [module](self) documentation) into `out`:
/// `(largest cond(K_b), cond(Rᵀ M R))`, or `None` when it declines.
fn reduced_factor<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
) -> Option<(f64, f64)> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let p = z.len();
    if M == 0 || p == 0 || p > P_MAX {
        return None;
    }
    let cond_max = model.options.cond_max;
    let g = &data.g.data.0;
    let rt = &mut out.rt[..p * N];
    rt.fill(0.0);
    for (row, &zj) in rt.chunks_exact_mut(N).zip(z) {
        row[zj] = 1.0;
    }
    // K_b⁻¹ (exact condition numbers) and the blocks' entries of Rᵀ: -K_b⁻¹ G[R_b, z_c].
    let mut worst = 0.0_f64;
    let mut norms = (0.0_f64, 0.0_f64);
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        let inv = out.inv.get_mut(off..off + k * k)?;
        for (c, &j) in blk.cols.iter().enumerate() {
            for (a, &i) in inv[c * k..c * k + k].iter_mut().zip(blk.rows) {
                *a = g[j][i];
            }
        }
        let anorm = linalg::norm1(inv, k).ok()?;
        let inorm = linalg::invert_small(inv, k).ok()?;
        let cond = anorm * inorm;
        if cond.is_nan() || cond > FD_K_COND_MAX.min(cond_max) {
            return None;
        }
        worst = worst.max(cond);
        norms = (norms.0.max(anorm), norms.1.max(inorm));
        for (row, &zj) in rt.chunks_exact_mut(N).zip(z) {
            let mut w = [0.0; linalg::INVERT_MAX];
            for (col, &i) in inv.chunks_exact(k).zip(blk.rows) {
                let v = g[zj][i];
                for (wi, &a) in w.iter_mut().zip(col) {
                    *wi += a * v;
                }
            }
            for (&wi, &j) in w.iter().zip(blk.cols) {
                row[j] = -wi;
            }
        }
        off += k * k;
    }
    // (M R)ᵀ and H = Rᵀ M R (lower triangle), then its Cholesky factor.
    let blocks = model.kernels().mass_blocks();
    let mrt = &mut out.mrt[..p * N];
    for (mrow, row) in mrt.chunks_exact_mut(N).zip(rt.chunks_exact(N)) {
        let (mrow, row): (&mut [f64; N], &[f64; N]) = (mrow.try_into().ok()?, row.try_into().ok()?);
        mass_times(&data.mass, blocks, row, mrow);
    }
    let h = &mut out.chol[..p * p];
    for c in 0..p {
        for r in c..p {
            h[c * p + r] = linalg::dot4(&mrt[c * N..(c + 1) * N], &rt[r * N..(r + 1) * N]);
        }
    }
    let mut anorm = 0.0_f64;
    for c in 0..p {
        let col: f64 = (0..p)
            .map(|r| if r >= c { h[c * p + r] } else { h[r * p + c] }.abs())
            .sum();
        anorm = anorm.max(col);
    }
    linalg::cholesky_factor(h, p).ok()?;
    let (mut lmin, mut lmax) = (f64::INFINITY, 0.0_f64);
    for j in 0..p {
        lmin = lmin.min(h[j * p + j]);
        lmax = lmax.max(h[j * p + j]);
    }
    let mut cond = (lmax / lmin) * (lmax / lmin);
    if cond.is_nan() || cond > fd_cond_check(cond_max) {
        let mut work = [0.0; 2 * P_MAX];
        cond = linalg::cholesky_cond1_estimate(h, p, anorm, &mut work[..2 * p]).ok()?;
        if cond.is_nan() || cond > cond_max {
            return None;
        }
    }
    out.norms = norms;
    Some((worst, cond))
}

/// Up to this many terms are summed into a row in registers at once (`Terms`).
const TERMS: usize = 64;

/// A sum `Σ a_t src[row_t]` of rows of a row-major matrix with rows of length `w`, added into a
/// row chunk by chunk: each chunk of 8 entries stays in registers over all the terms (one load
/// per term and entry instead of the load and store of an axpy per term).
pub(crate) struct Terms {
    coef: [f64; TERMS],
    /// The terms' row offsets `row_t w` into `src`.
    off: [usize; TERMS],
    n: usize,
    /// The next flush overwrites the row (`out = Σ ...`) rather than adding into it.
    assign: bool,
}

impl Terms {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            coef: [0.0; TERMS],
            off: [0; TERMS],
            n: 0,
            assign: false,
        }
    }

    /// The row the next terms go into is overwritten by their sum (no need to clear it first);
    /// holds until the next flush.
    #[inline(always)]
    pub(crate) fn assign(&mut self) {
        self.assign = true;
    }

    /// Adds the term `a src[row]` (nothing for `a == 0`), first flushing into `out` when full.
    #[inline(always)]
    pub(crate) fn push(&mut self, a: f64, row: usize, out: &mut [f64], src: &[f64], w: usize) {
        if a == 0.0 {
            return;
        }
        if self.n == TERMS {
            self.flush(out, src, w);
        }
        self.coef[self.n] = a;
        self.off[self.n] = row * w;
        self.n += 1;
    }

    /// `out += Σ a_t src[row_t]` (`out = ...` after [`Terms::assign`]), and no terms left.
    #[inline(always)]
    pub(crate) fn flush(&mut self, out: &mut [f64], src: &[f64], w: usize) {
        self.flush_base(out, None, src, w);
    }

    /// `out = base + Σ a_t src[row_t]` when every term is still pending (no flush since the
    /// first push: at most `TERMS` of them), else `out += ...` after copying `base` first.
    #[inline(always)]
    pub(crate) fn flush_from(&mut self, out: &mut [f64], base: &[f64], src: &[f64], w: usize) {
        self.flush_base(out, Some(base), src, w);
    }

    #[inline(always)]
    fn flush_base(&mut self, out: &mut [f64], base: Option<&[f64]>, src: &[f64], w: usize) {
        let n = self.n;
        let assign = self.assign;
        self.n = 0;
        self.assign = false;
        if n == 0 {
            if let Some(b) = base {
                out[..w].copy_from_slice(&b[..w]);
            } else if assign {
                out.iter_mut().for_each(|v| *v = 0.0);
            }
            return;
        }
        let (coef, offs) = (&self.coef[..n], &self.off[..n]);
        let out = &mut out[..w];
        // Chunks of 16 (8 registers of two lanes over the terms), then of 8, then single entries.
        let (wide, rest) = out.as_chunks_mut::<16>();
        for (q, acc) in wide.iter_mut().enumerate() {
            chunk(acc, assign, base, coef, offs, src, 16 * q);
        }
        let t0 = 16 * wide.len();
        let (narrow, tail) = rest.as_chunks_mut::<8>();
        for (q, acc) in narrow.iter_mut().enumerate() {
            chunk(acc, assign, base, coef, offs, src, t0 + 8 * q);
        }
        let t0 = t0 + 8 * narrow.len();
        for (e, o) in tail.iter_mut().enumerate() {
            let mut v = match base {
                Some(b) => b[t0 + e],
                None if assign => 0.0,
                None => *o,
            };
            for (&a, &off) in coef.iter().zip(offs) {
                v += a * src[off + t0 + e];
            }
            *o = v;
        }
    }
}

/// `acc (= base, 0 or itself) + Σ a_t src[off_t + at ..][..C]`, the chunk in registers over the
/// terms.
#[inline(always)]
fn chunk<const C: usize>(
    acc: &mut [f64; C],
    assign: bool,
    base: Option<&[f64]>,
    coef: &[f64],
    offs: &[usize],
    src: &[f64],
    at: usize,
) {
    let mut v = match base.and_then(|b| b.get(at..at + C)) {
        Some(b) => {
            let mut v = [0.0; C];
            v.copy_from_slice(b);
            v
        }
        None if assign => [0.0; C],
        None => *acc,
    };
    for (&a, &o) in coef.iter().zip(offs) {
        if let Some(x) = src.get(o + at..o + at + C) {
            for (vi, &xi) in v.iter_mut().zip(x) {
                *vi += a * xi;
            }
        }
    }
    *acc = v;
}

/// The length of the rows of right-hand sides: `2 N + na` rounded up to a multiple of 8.
pub(crate) const fn row_width(n: usize, na: usize) -> usize {
    (2 * n + na).div_ceil(8) * 8
}

/// Rows `i` and `j != i` of a row-major matrix with rows of length `w`: `(&mut row i, &row j)`.
#[inline(always)]
fn two_rows(m: &mut [f64], w: usize, i: usize, j: usize) -> (&mut [f64], &[f64]) {
    if i < j {
        let (lo, hi) = m.split_at_mut(j * w);
        (&mut lo[i * w..(i + 1) * w], &hi[..w])
    } else {
        let (lo, hi) = m.split_at_mut(i * w);
        (&mut hi[..w], &lo[j * w..(j + 1) * w])
    }
}

/// Every right-hand side by the elimination's factors in `out`, all at once: the right-hand
/// sides are laid out as rows (entry `(i, j)`: component `i` of right-hand side `j`, `j` over
/// the `2 N + (N - M)` of them), so that every step is a sum of axpys along the rows of
/// `K_b⁻¹`, `M`, `Rᵀ` and the Cholesky factor's entries, each over all right-hand sides.
fn reduced_solve_all<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    outputs: Outputs,
) -> Result<(), SolverError> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let p = z.len();
    let blocks = model.kernels().mass_blocks();
    let mass = &data.mass.data.0;
    let na = s.actuated.len();
    // Rows padded to whole chunks of 8 (the padding stays zero: no term reaches it but zeros).
    let w = row_width(N, na);
    let ForwardDynamicsDerivatives {
        dxddot_dx,
        dxddot_dxdot,
        dxddot_du,
        dlambda_dx,
        dlambda_dxdot,
        dlambda_du,
        dr_dx,
        dr_dxdot,
        dc_dx,
        dc_dxdot,
        inv,
        rt,
        chol,
        wa,
        wr,
        wb,
        wx,
        wx0,
        wz,
        ..
    } = out;
    let wx0 = &mut wx0[..N * w];
    let (wa, wr, wb, wx, wz) = (
        &mut wa[..N * w],
        &mut wr[..N * w],
        &mut wb[..M * w],
        &mut wx[..N * w],
        &mut wz[..p * w],
    );
    // A = -[∂r/∂X, ∂r/∂Ẋ, -S] and B = -[∂c/∂X, ∂c/∂Ẋ, 0], as rows.
    to_rows(&dr_dx.data.0, wa, w, 0, -1.0);
    to_rows(&dr_dxdot.data.0, wa, w, N, -1.0);
    for i in 0..N {
        wa[i * w + 2 * N..(i + 1) * w].fill(0.0);
    }
    for (a, &j) in s.actuated.iter().enumerate() {
        wa[j * w + 2 * N + a] = gear_ratio(s.gear, a);
    }
    to_rows(&dc_dx.data.0, wb, w, 0, -1.0);
    to_rows(&dc_dxdot.data.0, wb, w, N, -1.0);
    for i in 0..M {
        wb[i * w + 2 * N..(i + 1) * w].fill(0.0);
    }
    let mut t = Terms::new();
    // X0 = G_y⁻¹ B, block by block (zero on the outputs: their rows are not read).
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        let kinv = &inv[off..off + k * k];
        off += k * k;
        for (r, &jr) in blk.cols.iter().enumerate() {
            let xr = &mut wx0[jr * w..(jr + 1) * w];
            t.assign();
            for (c, &ic) in blk.rows.iter().enumerate() {
                t.push(kinv[c * k + r], ic, xr, wb, w);
            }
            t.flush(xr, wb, w);
        }
    }
    // W = A - M X0 into `wr` for the rows it changes (`in_wr`); `wa` holds the others.
    let mut in_wr = [false; N];
    for blk in blocks {
        let fits = blk.len() <= TERMS;
        for &r in blk.iter() {
            if !blk.iter().any(|&c| model.ik_block_of[c] < ik.len()) {
                break;
            }
            in_wr[r] = true;
            let row = &mut wr[r * w..(r + 1) * w];
            let base = &wa[r * w..(r + 1) * w];
            if !fits {
                row.copy_from_slice(base);
            }
            for &c in blk.iter() {
                if model.ik_block_of[c] < ik.len() {
                    t.push(-mass[c][r], c, row, wx0, w);
                }
            }
            if fits {
                t.flush_from(row, base, wx0, w);
            } else {
                t.flush(row, wx0, w);
            }
        }
    }
    // Z = H⁻¹ Rᵀ W.
    for (c, zrow) in wz.chunks_exact_mut(w).enumerate() {
        let rc = &rt[c * N..(c + 1) * N];
        t.assign();
        for (i, &rv) in rc.iter().enumerate() {
            if !in_wr[i] {
                t.push(rv, i, zrow, wa, w);
            }
        }
        t.flush(zrow, wa, w);
        for (i, &rv) in rc.iter().enumerate() {
            if in_wr[i] {
                t.push(rv, i, zrow, wr, w);
            }
        }
        t.flush(zrow, wr, w);
    }
    let h = &chol[..p * p];
    for j in 0..p {
        let d = 1.0 / h[j * p + j];
        wz[j * w..(j + 1) * w].iter_mut().for_each(|v| *v *= d);
        for i in j + 1..p {
            let (zi, zj) = two_rows(wz, w, i, j);
            for (a, &b) in zi.iter_mut().zip(zj) {
                *a -= h[j * p + i] * b;
            }
        }
    }
    for j in (0..p).rev() {
        for i in j + 1..p {
            let (zj, zi) = two_rows(wz, w, j, i);
            for (a, &b) in zj.iter_mut().zip(zi) {
                *a -= h[j * p + i] * b;
            }
        }
        let d = 1.0 / h[j * p + j];
        wz[j * w..(j + 1) * w].iter_mut().for_each(|v| *v *= d);
    }
    // X = X0 + R Z: Rᵀ read by columns (entry (c, i) at rt[c N + i]).
    for i in 0..N {
        let xr = &mut wx[i * w..(i + 1) * w];
        for c in 0..p {
            t.push(rt[c * N + i], c, xr, wz, w);
        }
        if model.ik_block_of[i] < ik.len() {
            t.flush_from(xr, &wx0[i * w..(i + 1) * w], wz, w);
        } else {
            t.assign(); // X0 is zero here
            t.flush(xr, wz, w);
        }
    }
    if outputs == Outputs::XddotRows {
        return if all_finite(wx) {
            Ok(())
        } else {
            Err(SolverError::NonFinite {
                what: "dynamics_derivatives",
            })
        };
    }
    // Lambda: K_bᵀ lambda_b = (A - M X)[C_b], into the rows of B.
    for blk in blocks {
        for &r in blk.iter() {
            if model.ik_block_of[r] >= ik.len() {
                continue; // an output: its equation is the reduced one
            }
            let row = &mut wr[r * w..(r + 1) * w];
            let base = &wa[r * w..(r + 1) * w];
            if blk.len() > TERMS {
                row.copy_from_slice(base);
                for &c in blk.iter() {
                    t.push(-mass[c][r], c, row, wx, w);
                }
                t.flush(row, wx, w);
            } else {
                for &c in blk.iter() {
                    t.push(-mass[c][r], c, row, wx, w);
                }
                t.flush_from(row, base, wx, w);
            }
        }
    }
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        let kinv = &inv[off..off + k * k];
        off += k * k;
        for (c, &ic) in blk.rows.iter().enumerate() {
            let lrow = &mut wb[ic * w..(ic + 1) * w];
            t.assign();
            for (r, &jr) in blk.cols.iter().enumerate() {
                t.push(kinv[c * k + r], jr, lrow, wr, w);
            }
            t.flush(lrow, wr, w);
        }
    }
    if !all_finite(wx) || !all_finite(wb) {
        return Err(SolverError::NonFinite {
            what: "dynamics_derivatives",
        });
    }
    // Back to the column-major outputs.
    from_rows(wx, w, 0, &mut dxddot_dx.data.0);
    from_rows(wx, w, N, &mut dxddot_dxdot.data.0);
    from_rows(wb, w, 0, &mut dlambda_dx.data.0);
    from_rows(wb, w, N, &mut dlambda_dxdot.data.0);
    for a in 0..na {
        for (i, v) in dxddot_du.data.0[a].iter_mut().enumerate() {
            *v = wx[i * w + 2 * N + a];
        }
        for (i, v) in dlambda_du.data.0[a].iter_mut().enumerate() {
            *v = wb[i * w + 2 * N + a];
        }
    }
    Ok(())
}

/// `rows[i w + at + j] = scale cols[j][i]`: a column-major matrix into rows, by 2 × 2 blocks
/// (two loads of a pair, two stores of a pair).
fn to_rows<const R: usize, const C: usize>(
    cols: &[[f64; R]; C],
    rows: &mut [f64],
    w: usize,
    at: usize,
    scale: f64,
) {
    let (pairs, last) = cols.as_chunks::<2>();
    for (jp, [c0, c1]) in pairs.iter().enumerate() {
        let j = at + 2 * jp;
        let (ip, ilast) = (R / 2, R % 2);
        for q in 0..ip {
            let i = 2 * q;
            let (a0, a1) = (c0[i], c0[i + 1]);
            let (b0, b1) = (c1[i], c1[i + 1]);
            if let Some(d) = rows.get_mut(i * w + j..i * w + j + 2) {
                d.copy_from_slice(&[scale * a0, scale * b0]);
            }
            if let Some(d) = rows.get_mut((i + 1) * w + j..(i + 1) * w + j + 2) {
                d.copy_from_slice(&[scale * a1, scale * b1]);
            }
        }
        if ilast == 1 {
            let i = R - 1;
            rows[i * w + j] = scale * c0[i];
            rows[i * w + j + 1] = scale * c1[i];
        }
    }
    if let [c] = last {
        let j = at + C - 1;
        for (i, &v) in c.iter().enumerate() {
            rows[i * w + j] = scale * v;
        }
    }
}

/// `cols[j][i] = rows[i w + at + j]`: the inverse of [`to_rows`] (without the scale), two rows
/// at a time (each column gets a pair of entries).
fn from_rows<const R: usize, const C: usize>(
    rows: &[f64],
    w: usize,
    at: usize,
    cols: &mut [[f64; R]; C],
) {
    let row = |i: usize| &rows[i * w + at..i * w + at + C];
    let mut i = 0;
    while i + 1 < R {
        let (r0, r1) = (row(i), row(i + 1));
        for (col, (&a, &b)) in cols.iter_mut().zip(r0.iter().zip(r1)) {
            if let Some(pair) = col.get_mut(i..i + 2) {
                pair.copy_from_slice(&[a, b]);
            }
        }
        i += 2;
    }
    if i < R {
        for (col, &a) in cols.iter_mut().zip(row(i)) {
            col[i] = a;
        }
    }
}

/// Every right-hand side by the dense LU of `[M Gᵀ; G 0]`, which decides `Singular`.
fn saddle_solve_all<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
) -> Result<(), SolverError> {
    let k = N + M;
    // [M Gᵀ; G 0], column-major.
    let kkt = &mut out.kkt;
    for j in 0..N {
        let col = &mut kkt[j * k..(j + 1) * k];
        col[..N].copy_from_slice(data.mass.column(j).as_slice());
        col[N..].copy_from_slice(data.g.column(j).as_slice());
    }
    for l in 0..M {
        let col = &mut kkt[(N + l) * k..(N + l + 1) * k];
        for (i, c) in col[..N].iter_mut().enumerate() {
            *c = data.g[(l, i)];
        }
        col[N..].fill(0.0);
    }
    let what = "[M Gᵀ; G 0]";
    let lu_error = |e: LuError| match e {
        LuError::Singular { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block: None,
        },
        _ => SolverError::NonFinite {
            what: "dynamics_derivatives",
        },
    };
    let anorm = linalg::norm1(kkt, k).map_err(lu_error)?;
    linalg::lu_factor(kkt, k, &mut out.piv).map_err(lu_error)?;
    out.cond = linalg::cond1_estimate(kkt, k, &out.piv, anorm, &mut out.work).map_err(lu_error)?;
    if out.cond.is_nan() || out.cond > model.options.cond_max {
        return Err(SolverError::Singular {
            cond: out.cond,
            what,
            block: None,
        });
    }
    let (kkt, piv, rhs) = (&out.kkt[..], &out.piv[..], &mut out.rhs[..]);
    let solve = |rhs: &mut [f64], dxddot: &mut [f64], dlambda: &mut [f64]| {
        linalg::lu_solve(kkt, k, piv, rhs).map_err(lu_error)?;
        dxddot.copy_from_slice(&rhs[..N]);
        dlambda.copy_from_slice(&rhs[N..]);
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(SolverError::NonFinite {
                what: "dynamics_derivatives",
            })
        }
    };
    for j in 0..N {
        for (r, &d) in rhs[..N].iter_mut().zip(out.dr_dx.column(j).iter()) {
            *r = -d;
        }
        for (r, &d) in rhs[N..].iter_mut().zip(out.dc_dx.column(j).iter()) {
            *r = -d;
        }
        solve(
            rhs,
            out.dxddot_dx.column_mut(j).as_mut_slice(),
            out.dlambda_dx.column_mut(j).as_mut_slice(),
        )?;
        for (r, &d) in rhs[..N].iter_mut().zip(out.dr_dxdot.column(j).iter()) {
            *r = -d;
        }
        for (r, &d) in rhs[N..].iter_mut().zip(out.dc_dxdot.column(j).iter()) {
            *r = -d;
        }
        solve(
            rhs,
            out.dxddot_dxdot.column_mut(j).as_mut_slice(),
            out.dlambda_dxdot.column_mut(j).as_mut_slice(),
        )?;
    }
    let s = model.structure();
    for (a, &j) in s.actuated.iter().enumerate() {
        rhs.fill(0.0);
        rhs[j] = gear_ratio(s.gear, a);
        solve(
            rhs,
            out.dxddot_du.column_mut(a).as_mut_slice(),
            out.dlambda_du.column_mut(a).as_mut_slice(),
        )?;
    }
    // The rows `xddot_rows` reads, as the elimination leaves them.
    let na = s.actuated.len();
    let w = row_width(N, na);
    for (i, row) in out.wx[..N * w].chunks_exact_mut(w).enumerate() {
        row.fill(0.0);
        for j in 0..N {
            row[j] = out.dxddot_dx[(i, j)];
            row[N + j] = out.dxddot_dxdot[(i, j)];
        }
        for a in 0..na {
            row[2 * N + a] = out.dxddot_du[(i, a)];
        }
    }
    Ok(())
}
