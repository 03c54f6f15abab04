//! The derivatives of inverse dynamics: `∂U/∂X`, `∂U/∂Ẋ`, `∂U/∂Ẍ` and `∂lambda/∂X`,
//! `∂lambda/∂Ẋ`, `∂lambda/∂Ẍ` at one motion.
//!
//! Inverse dynamics solves `M Ẍ - psi - Q - S U + Gᵀ lambda = 0` for `U` and `lambda`
//! (`S`: the gear ratios on the actuated coordinates; see
//! [`inverse_dynamics`](super::inverse_dynamics)). With the residual
//! `r = M Ẍ - psi + Gᵀ lambda`, whose derivatives `∂r/∂X` (at fixed `Ẍ`, `lambda`) and `∂r/∂Ẋ`
//! the generated kernel `dynamics_derivatives` writes, a perturbation `(dX, dẊ, dẌ)` at fixed
//! `Q` moves the solution by
//!
//! ```text
//! [S | Gᵀ] [dU_S; dmu] = ∂r/∂X dX + ∂r/∂Ẋ dẊ + M dẌ,     dU = dU_S / gear,  dlambda = -dmu
//! ```
//!
//! the matrix inverse dynamics solves with, here with `3 N` right-hand sides (`∂r/∂X`,
//! `∂r/∂Ẋ`, `M`). It is solved in inverse dynamics' structure: every inverse-kinematics block
//! `K_b = G[rows_b, cols_b]` inverted explicitly (its exact 1-norm condition number against
//! `SolverOptions::cond_max`), then the reduced system `A` of order `N - M` in the actuators'
//! forces (`A[o, a] = G[:, o]ᵀ K_b⁻ᵀ e_a`) factored once by LU with partial pivoting, its
//! condition estimated (Hager/Higham) against `cond_max`: past it, `Singular` (a parallel
//! singularity). As in inverse dynamics, a block past `cond_max` (a serial singularity of one
//! leg, not one of the problem) or a structure without the elimination falls back to the dense
//! LU of `[S | Gᵀ]`, which decides `Singular`. The derivatives hold at any `X`, `Ẋ`, `Ẍ` where
//! `[S | Gᵀ]` is regular (on the constraint manifold or not), as inverse dynamics does.

use nalgebra::SMatrix;

use super::input::all_finite;
use super::inverse_dynamics::inverse_dynamics;
use super::report::{DynamicsMethod, DynamicsReport};
use crate::data::Data;
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::{Derivatives, InverseDynamics};

const WHAT_REDUCED: &str = "reduced inverse-dynamics system A (U)";
const WHAT_DENSE: &str = "[S | Gᵀ]";
const WHAT_KERNEL: &str = "inverse_dynamics_derivatives";

/// Which solve [`inverse_dynamics_derivatives_with`] uses for the right-hand sides.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdDerivativesSolver {
    /// The block elimination, the dense LU when it declines (what
    /// [`inverse_dynamics_derivatives`] does).
    Auto,
    /// The dense LU of `[S | Gᵀ]` alone: the reference the elimination is tested against.
    DenseLu,
}

/// The derivatives of inverse dynamics at one motion and the buffers that compute them:
/// [`InverseDynamicsDerivatives::new`] allocates once, [`inverse_dynamics_derivatives`] never.
#[derive(Debug, Clone)]
pub struct InverseDynamicsDerivatives<const N: usize, const M: usize> {
    /// `∂U/∂X` (N × N): row `a` for the control force `u[a]` (in `data.u`'s units, that is
    /// divided by the gear ratio) of `Structure::actuated[a]`; the rows from
    /// `Structure::actuated.len()` on stay zero.
    pub du_dx: SMatrix<f64, N, N>,
    /// `∂U/∂Ẋ` (N × N), rows as in `du_dx`.
    pub du_dxdot: SMatrix<f64, N, N>,
    /// `∂U/∂Ẍ` (N × N), rows as in `du_dx`.
    pub du_dxddot: SMatrix<f64, N, N>,
    /// `∂lambda/∂X` (M × N).
    pub dlambda_dx: SMatrix<f64, M, N>,
    /// `∂lambda/∂Ẋ` (M × N).
    pub dlambda_dxdot: SMatrix<f64, M, N>,
    /// `∂lambda/∂Ẍ` (M × N).
    pub dlambda_dxddot: SMatrix<f64, M, N>,
    /// `∂r/∂X` of the residual `r = M Ẍ - psi + Gᵀ lambda` at the solution (N × N), as the
    /// generated kernel wrote it.
    pub dr_dx: SMatrix<f64, N, N>,
    /// `∂r/∂Ẋ = -∂psi/∂Ẋ` (N × N).
    pub dr_dxdot: SMatrix<f64, N, N>,
    /// The path that solved: [`DynamicsMethod::BlockElimination`] or
    /// [`DynamicsMethod::DenseLu`].
    pub method: DynamicsMethod,
    /// `BlockElimination`: the largest exact 1-norm condition number of the blocks `K_b`;
    /// `DenseLu`: infinity (no blocks).
    pub cond_blocks: f64,
    /// The Hager/Higham estimate of the 1-norm condition number of the reduced system `A`
    /// (`BlockElimination`) or of `[S | Gᵀ]` (`DenseLu`).
    pub cond: f64,
    /// The kernel's `∂c/∂X`, `∂c/∂Ẋ` of the acceleration constraint (not needed here).
    dc_dx: SMatrix<f64, M, N>,
    dc_dxdot: SMatrix<f64, M, N>,
    /// `K_b⁻¹` of every block, column-major, packed in block order.
    inv: Vec<f64>,
    /// `w_a = K_b⁻ᵀ e_a` per actuator: M entries each (on its block's rows, packed).
    w: Vec<f64>,
    /// The block of every actuator.
    owner: Vec<usize>,
    /// LU factors of `A` (`(N - M)²`) or of `[S | Gᵀ]` (`N²`), column-major, and pivots.
    lu: Vec<f64>,
    piv: Vec<usize>,
    work: Vec<f64>,
    /// The right-hand sides (`3 N` of length N): in the block elimination as rows (N rows of
    /// length `3 N`), in the dense LU column-major, overwritten by `[dU_S; dmu]`.
    rhs: Vec<f64>,
    /// `mu⁰`, then `mu`, as rows (M rows of length `3 N`).
    mu: Vec<f64>,
    /// The reduced right-hand sides, then `U_S`, as rows (`N - M` rows of length `3 N`).
    red: Vec<f64>,
}

impl<const N: usize, const M: usize> InverseDynamicsDerivatives<N, M> {
    /// Zeroed derivatives and the solves' buffers (the only allocation).
    pub fn new() -> Self {
        Self {
            du_dx: SMatrix::zeros(),
            du_dxdot: SMatrix::zeros(),
            du_dxddot: SMatrix::zeros(),
            dlambda_dx: SMatrix::zeros(),
            dlambda_dxdot: SMatrix::zeros(),
            dlambda_dxddot: SMatrix::zeros(),
            dr_dx: SMatrix::zeros(),
            dr_dxdot: SMatrix::zeros(),
            method: DynamicsMethod::BlockElimination,
            cond_blocks: f64::NAN,
            cond: f64::NAN,
            dc_dx: SMatrix::zeros(),
            dc_dxdot: SMatrix::zeros(),
            inv: vec![0.0; M * linalg::INVERT_MAX],
            w: vec![0.0; N * M],
            owner: vec![0; N],
            lu: vec![0.0; N * N],
            piv: vec![0; N],
            work: vec![0.0; 2 * N],
            rhs: vec![0.0; 3 * N * N],
            mu: vec![0.0; 3 * N * M],
            red: vec![0.0; 3 * N * N],
        }
    }
}

impl<const N: usize, const M: usize> Default for InverseDynamicsDerivatives<N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Inverse dynamics at `data.x`, `data.xdot`, `data.xddot` with the applied forces `q_forces`
/// (held fixed), then its derivatives with respect to `X`, `Ẋ` and `Ẍ` into `out` (see the
/// [module](self) documentation). Writes what [`inverse_dynamics`] writes (`data.u`,
/// `data.lambda`, ...) and returns its report.
///
/// Errors: those of [`inverse_dynamics`]; `NonFinite` when the derivative kernel's outputs or
/// the derivatives are not finite; `Singular` when the reduced system `A` (`what`:
/// `"reduced inverse-dynamics system A (U)"`) or, after the fallback, `[S | Gᵀ]` is exactly
/// singular or its condition estimate exceeds `SolverOptions::cond_max`.
pub fn inverse_dynamics_derivatives<
    K: Derivatives<N, M> + InverseDynamics<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut InverseDynamicsDerivatives<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    inverse_dynamics_derivatives_with(model, data, out, q_forces, IdDerivativesSolver::Auto)
}

/// [`inverse_dynamics_derivatives`] with the solve `solver`; the same outputs and errors.
pub fn inverse_dynamics_derivatives_with<
    K: Derivatives<N, M> + InverseDynamics<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut InverseDynamicsDerivatives<N, M>,
    q_forces: Option<&[f64; N]>,
    solver: IdDerivativesSolver,
) -> Result<DynamicsReport, SolverError> {
    let report = inverse_dynamics(model, data, q_forces)?;
    // The kernel writes only the structural non-zeros; its constraint part is not read.
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
    if !all_finite(out.dr_dx.as_slice()) || !all_finite(out.dr_dxdot.as_slice()) {
        return Err(SolverError::NonFinite {
            what: "dynamics_derivatives",
        });
    }
    let blocks = match solver {
        IdDerivativesSolver::Auto => block_factor(model, data, out)?,
        IdDerivativesSolver::DenseLu => None,
    };
    match blocks {
        Some(cond_blocks) => {
            out.method = DynamicsMethod::BlockElimination;
            out.cond_blocks = cond_blocks;
            block_solve_all(model, data, out);
        }
        None => {
            out.method = DynamicsMethod::DenseLu;
            out.cond_blocks = f64::INFINITY;
            dense_solve_all(model, data, out)?;
        }
    }
    let finite = all_finite(out.du_dx.as_slice())
        && all_finite(out.du_dxdot.as_slice())
        && all_finite(out.du_dxddot.as_slice())
        && all_finite(out.dlambda_dx.as_slice())
        && all_finite(out.dlambda_dxdot.as_slice())
        && all_finite(out.dlambda_dxddot.as_slice());
    if !finite {
        return Err(SolverError::NonFinite { what: WHAT_KERNEL });
    }
    Ok(report)
}

/// The blocks' inverses, the vectors `w_a` and the LU factors of the reduced system `A` into
/// `out`: `Ok(Some(largest cond(K_b)))`, `Ok(None)` when the elimination declines (no outputs,
/// `#outputs != #actuated`, a block past `cond_max` or larger than `linalg::INVERT_MAX`), and
/// `Singular` when `A` is.
fn block_factor<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut InverseDynamicsDerivatives<N, M>,
) -> Result<Option<f64>, SolverError> {
    let s = model.structure();
    let n = s.actuated.len();
    if M == 0 || s.outputs.len() != n || n == 0 {
        return Ok(None);
    }
    let cond_max = model.options.cond_max;
    let g = &data.g.data.0;
    let mut worst = 0.0_f64;
    let mut off = 0;
    for (bk, blk) in s.ik_blocks.iter().enumerate() {
        let k = blk.rows.len();
        let Some(inv) = out.inv.get_mut(off..off + k * k) else {
            return Ok(None);
        };
        if k > linalg::INVERT_MAX || blk.cols.len() != k {
            return Ok(None);
        }
        for (c, &j) in blk.cols.iter().enumerate() {
            for (a, &i) in inv[c * k..c * k + k].iter_mut().zip(blk.rows) {
                *a = g[j][i];
            }
        }
        let Ok(anorm) = linalg::norm1(inv, k) else {
            return Ok(None);
        };
        let Ok(inorm) = linalg::invert_small(inv, k) else {
            return Ok(None);
        };
        let cond = anorm * inorm;
        if cond.is_nan() || cond > cond_max {
            return Ok(None);
        }
        worst = worst.max(cond);
        // w_a = K⁻ᵀ e_c = row c of K⁻¹, for the actuator a at position c of the block.
        for (c, &j) in blk.cols.iter().enumerate() {
            let a = model.actuator_of[j];
            if a >= n {
                continue;
            }
            out.owner[a] = bk;
            let wa = &mut out.w[a * M..a * M + k];
            for (r, wr) in wa.iter_mut().enumerate() {
                *wr = inv[r * k + c];
            }
        }
        off += k * k;
    }
    // A[o, a] = Σ_{i in rows of a's block} G[i, o] w_a[i], column-major.
    let a_mat = &mut out.lu[..n * n];
    for (r, &o) in s.outputs.iter().enumerate() {
        let go = &g[o];
        for a in 0..n {
            let rows = s.ik_blocks[out.owner[a]].rows;
            let wa = &out.w[a * M..a * M + rows.len()];
            a_mat[r + a * n] = rows.iter().zip(wa).map(|(&i, &wi)| go[i] * wi).sum();
        }
    }
    out.cond = factor(
        a_mat,
        n,
        &mut out.piv[..n],
        &mut out.work[..2 * n],
        cond_max,
        WHAT_REDUCED,
    )?;
    Ok(Some(worst))
}

/// LU factors of the column-major `k × k` matrix `a` in place and its condition estimate,
/// `Singular` (`what`) past `cond_max`.
fn factor(
    a: &mut [f64],
    k: usize,
    piv: &mut [usize],
    work: &mut [f64],
    cond_max: f64,
    what: &'static str,
) -> Result<f64, SolverError> {
    let err = |e: LuError| match e {
        LuError::Singular { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block: None,
        },
        _ => SolverError::NonFinite { what: WHAT_KERNEL },
    };
    let anorm = linalg::norm1(a, k).map_err(err)?;
    linalg::lu_factor(a, k, piv).map_err(err)?;
    let cond = linalg::cond1_estimate(a, k, piv, anorm, work).map_err(err)?;
    if cond.is_nan() || cond > cond_max {
        return Err(SolverError::Singular {
            cond,
            what,
            block: None,
        });
    }
    Ok(cond)
}

/// `dst += a src` over two rows of equal length.
#[inline(always)]
fn axpy(dst: &mut [f64], a: f64, src: &[f64]) {
    for (d, &v) in dst.iter_mut().zip(src) {
        *d += a * v;
    }
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

/// Every right-hand side by the block elimination's factors in `out` (see [`block_factor`]),
/// all at once: the right-hand sides laid out as rows (row `i`: component `i` of all `3 N` of
/// them), so that every step is an axpy along rows of length `3 N`. Per right-hand side `b`:
/// `mu⁰_k = K_k⁻ᵀ b[cols_k]`, `A U_S = G_oᵀ mu⁰ - b_o`, `mu = mu⁰ - Σ_a w_a U_S,a`.
fn block_solve_all<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut InverseDynamicsDerivatives<N, M>,
) {
    let s = model.structure();
    let n = s.actuated.len();
    let g = &data.g.data.0;
    let w3 = 3 * N;
    let InverseDynamicsDerivatives {
        du_dx,
        du_dxdot,
        du_dxddot,
        dlambda_dx,
        dlambda_dxdot,
        dlambda_dxddot,
        dr_dx,
        dr_dxdot,
        inv,
        w,
        owner,
        lu,
        piv,
        rhs,
        mu,
        red,
        ..
    } = out;
    // B as rows: [∂r/∂X, ∂r/∂Ẋ, M].
    let (lu, piv) = (&lu[..n * n], &piv[..n]);
    for (j, ((cx, cv), cm)) in dr_dx
        .data
        .0
        .iter()
        .zip(&dr_dxdot.data.0)
        .zip(&data.mass.data.0)
        .enumerate()
    {
        for (i, ((&vx, &vv), &vm)) in cx.iter().zip(cv).zip(cm).enumerate() {
            rhs[i * w3 + j] = vx;
            rhs[i * w3 + N + j] = vv;
            rhs[i * w3 + 2 * N + j] = vm;
        }
    }
    // mu⁰ block by block: mu⁰[rows_k[a]] = Σ_c K⁻¹(c, a) b[cols_k[c]].
    let mut off = 0;
    for blk in s.ik_blocks {
        let k = blk.rows.len();
        let kinv = &inv[off..off + k * k];
        off += k * k;
        for (a, &i) in blk.rows.iter().enumerate() {
            let row = &mut mu[i * w3..(i + 1) * w3];
            row.fill(0.0);
            for (&j, &v) in blk.cols.iter().zip(&kinv[a * k..a * k + k]) {
                if v != 0.0 {
                    axpy(row, v, &rhs[j * w3..(j + 1) * w3]);
                }
            }
        }
    }
    // The reduced right-hand sides G_oᵀ mu⁰ - b_o.
    let red = &mut red[..n * w3];
    for (r, &o) in s.outputs.iter().enumerate() {
        let row = &mut red[r * w3..(r + 1) * w3];
        for (d, &b) in row.iter_mut().zip(&rhs[o * w3..(o + 1) * w3]) {
            *d = -b;
        }
        for (i, &gi) in g[o].iter().enumerate() {
            if gi != 0.0 {
                axpy(row, gi, &mu[i * w3..(i + 1) * w3]);
            }
        }
    }
    // A U_S = red by the LU factors (P A = L U), row operations.
    for (j, &p) in piv.iter().enumerate() {
        if p != j {
            for c in 0..w3 {
                red.swap(j * w3 + c, p * w3 + c);
            }
        }
    }
    for j in 0..n {
        for i in j + 1..n {
            let l = lu[j * n + i];
            if l != 0.0 {
                let (ri, rj) = two_rows(red, w3, i, j);
                axpy(ri, -l, rj);
            }
        }
    }
    for j in (0..n).rev() {
        let d = 1.0 / lu[j * n + j];
        red[j * w3..(j + 1) * w3].iter_mut().for_each(|v| *v *= d);
        for i in 0..j {
            let u = lu[j * n + i];
            if u != 0.0 {
                let (ri, rj) = two_rows(red, w3, i, j);
                axpy(ri, -u, rj);
            }
        }
    }
    // mu = mu⁰ - Σ_a w_a U_S,a, on the rows of a's block.
    for a in 0..n {
        let rows = s.ik_blocks[owner[a]].rows;
        let fa = &red[a * w3..(a + 1) * w3];
        for (&i, &wi) in rows.iter().zip(&w[a * M..a * M + rows.len()]) {
            axpy(&mut mu[i * w3..(i + 1) * w3], -wi, fa);
        }
    }
    // Back to the column-major outputs.
    for a in 0..n {
        let inv_gear = 1.0 / gear_ratio(s.gear, a);
        let fa = &red[a * w3..(a + 1) * w3];
        for j in 0..N {
            du_dx[(a, j)] = fa[j] * inv_gear;
            du_dxdot[(a, j)] = fa[N + j] * inv_gear;
            du_dxddot[(a, j)] = fa[2 * N + j] * inv_gear;
        }
    }
    for i in 0..M {
        let mi = &mu[i * w3..(i + 1) * w3];
        for j in 0..N {
            dlambda_dx[(i, j)] = -mi[j];
            dlambda_dxdot[(i, j)] = -mi[N + j];
            dlambda_dxddot[(i, j)] = -mi[2 * N + j];
        }
    }
}

/// Every right-hand side by the dense LU of `[S | Gᵀ]`, which decides `Singular`.
fn dense_solve_all<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut InverseDynamicsDerivatives<N, M>,
) -> Result<(), SolverError> {
    let s = model.structure();
    let n = s.actuated.len();
    if n + M != N {
        // Unreachable for a structure accepted by Model::try_new.
        return Err(SolverError::Dimension {
            what: "actuated coordinates (N - M)",
            expected: N.saturating_sub(M),
            found: n,
        });
    }
    // Columns 0..n: S (unit vectors on the actuated coordinates); then Gᵀ.
    let a = &mut out.lu[..N * N];
    a.fill(0.0);
    for (col, &j) in a.chunks_exact_mut(N.max(1)).zip(s.actuated) {
        col[j] = 1.0;
    }
    for (i, col) in a.chunks_exact_mut(N.max(1)).skip(n).enumerate() {
        for (aj, gcol) in col.iter_mut().zip(data.g.data.0.iter()) {
            *aj = gcol[i];
        }
    }
    out.cond = factor(
        a,
        N,
        &mut out.piv[..N],
        &mut out.work[..2 * N],
        model.options.cond_max,
        WHAT_DENSE,
    )?;
    // The right-hand sides [∂r/∂X, ∂r/∂Ẋ, M], column-major.
    let nn = N * N;
    out.rhs[..nn].copy_from_slice(out.dr_dx.as_slice());
    out.rhs[nn..2 * nn].copy_from_slice(out.dr_dxdot.as_slice());
    out.rhs[2 * nn..].copy_from_slice(data.mass.as_slice());
    let InverseDynamicsDerivatives {
        du_dx,
        du_dxdot,
        du_dxddot,
        dlambda_dx,
        dlambda_dxdot,
        dlambda_dxddot,
        lu,
        piv,
        rhs,
        ..
    } = out;
    for (col, b) in rhs.chunks_exact_mut(N.max(1)).enumerate() {
        let _ = linalg::lu_solve(&lu[..N * N], N, &piv[..N], b);
        let (du, dl, j) = match col / N {
            0 => (&mut *du_dx, &mut *dlambda_dx, col),
            1 => (&mut *du_dxdot, &mut *dlambda_dxdot, col - N),
            _ => (&mut *du_dxddot, &mut *dlambda_dxddot, col - 2 * N),
        };
        for (a, &ua) in b[..n].iter().enumerate() {
            du[(a, j)] = ua / gear_ratio(s.gear, a);
        }
        for (l, &m) in dl.column_mut(j).iter_mut().zip(&b[n..]) {
            *l = -m;
        }
    }
    Ok(())
}
