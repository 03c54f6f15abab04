//! The state-space linearisation of forward dynamics on the constraint manifold, in the robot's
//! independent coordinates `y` (the outputs, or the actuated coordinates: the caller picks):
//!
//! ```text
//! d/dt [y; ẏ] ≈ A [dy; dẏ] + B dU,   A = [0 I; ∂ÿ/∂y ∂ÿ/∂ẏ],   B = [0; ∂ÿ/∂U]
//! ```
//!
//! The other coordinates `c` follow from the constraints: `f(X) = 0` with `X[y] = y` fixes
//! `X(y)`, and `G Ẋ = 0` fixes `Ẋ = T ẏ` with the tangent map
//!
//! ```text
//! T = ∂X/∂y:   T[y, :] = I,   G_c T[c, :] = -G_y        (G_c = G[:, c], M × M)
//! ```
//!
//! (`R = [I; -J_p⁻¹ J_q]`-style). Differentiating `G(X) Ẋ = 0` along `y` at fixed `ẏ` gives
//! `∂Ẋ/∂y`: zero on `y`, `G_c ∂Ẋ_c/∂y_k = -∂(G Ẋ)/∂X T_k` on the rest, where
//! `∂(G Ẋ)/∂X = ½ ∂c/∂Ẋ`: the acceleration constraint's `gamma = -Ġ Ẋ` is the quadratic form
//! of the symmetric second derivatives of `f`, so `∂gamma/∂Ẋ = -2 ∂(G Ẋ)/∂X` and the kernel's
//! `∂c/∂Ẋ = -∂gamma/∂Ẋ` holds it. Then, with forward dynamics' derivatives
//! ([`forward_dynamics_derivatives`](crate::forward_dynamics_derivatives)) at the state,
//!
//! ```text
//! ∂ÿ/∂ẏ = (∂Ẍ/∂Ẋ T)[y, :],   ∂ÿ/∂y = (∂Ẍ/∂X T + ∂Ẍ/∂Ẋ ∂Ẋ/∂y)[y, :],   ∂ÿ/∂U = ∂Ẍ/∂U[y, :]
//! ```
//!
//! The state must be on the manifold (`f(X) = 0`, `G Ẋ = 0`: what the position and velocity
//! solves return); the linearisation is that of the dynamics restricted to it.

use nalgebra::SMatrix;

use super::baumgarte::Baumgarte;
use super::derivatives::{
    DerivativesSolver, ForwardDynamicsDerivatives, Outputs, P_MAX, prepare, row_width,
    solve_prepared,
};
use super::input::all_finite;
use super::report::DynamicsReport;
use crate::data::Data;
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::Derivatives;

/// Which coordinates are the independent ones `y`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coordinates {
    /// `Structure::outputs` (the platform's pose): the other coordinates from the inverse
    /// kinematics' blocks.
    Outputs,
    /// `Structure::actuated`: the passive coordinates from `J_p` (fully actuated robots only).
    Actuated,
}

/// The linearisation at one state and the buffers that compute it: [`Linearization::new`]
/// allocates once, [`linearize`] never. Matrices are stored in fixed `N × N` arrays of which
/// the top-left block is used (`d` independent coordinates, `na` control forces).
#[derive(Debug, Clone)]
pub struct Linearization<const N: usize, const M: usize> {
    /// The independent coordinates of the last call.
    pub coordinates: Coordinates,
    /// Their number `d`.
    pub d: usize,
    /// The number of control forces `na` (columns of `∂ÿ/∂U`).
    pub na: usize,
    /// The coordinates' indices into `X` (first `d` entries).
    pub index: [usize; N],
    /// The tangent map `T = ∂X/∂y` (N × d).
    pub tangent: SMatrix<f64, N, N>,
    /// `∂Ẋ/∂y` at fixed `ẏ` (N × d).
    pub dxdot_dy: SMatrix<f64, N, N>,
    /// `∂ÿ/∂y` (d × d).
    pub dyddot_dy: SMatrix<f64, N, N>,
    /// `∂ÿ/∂ẏ` (d × d).
    pub dyddot_dydot: SMatrix<f64, N, N>,
    /// `∂ÿ/∂U` (d × na).
    pub dyddot_du: SMatrix<f64, N, N>,
    /// The 1-norm condition number of `G_c`: exact (the product of the largest 1-norms of the
    /// inverse-kinematics blocks and of their inverses) when `G_c` is the block-diagonal `G_y`
    /// of forward dynamics' elimination (the outputs' coordinates, the derivatives solved by
    /// it), else the Hager/Higham estimate from its LU.
    pub cond: f64,
    /// Forward dynamics' derivatives at the state: the kernel's `dr_dx`, `dr_dxdot`, `dc_dx`,
    /// `dc_dxdot`, `method`, `cond_blocks` and `cond` always; `dxddot_*` and `dlambda_*` only
    /// with [`Linearization::full_derivatives`] or off the fast path (see there), else they
    /// hold what an earlier call left.
    pub derivatives: ForwardDynamicsDerivatives<N, M>,
    /// Solve for the full derivatives `∂Ẍ/∂(X, Ẋ, U)` and `∂lambda/∂(X, Ẋ, U)` into
    /// `derivatives` as well (`false` from [`Linearization::new`]). Without it, in the outputs'
    /// coordinates and on forward dynamics' elimination (its blocks covering the constraints),
    /// only the `2 d + na` directions on the manifold are solved for, and only for the
    /// outputs' rows (`ÿ = Z`, the reduced unknowns): the same `A`, `B` at a fraction of the
    /// cost.
    pub full_derivatives: bool,
    lu: Vec<f64>,
    piv: Vec<usize>,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl<const N: usize, const M: usize> Linearization<N, M> {
    /// Zeroed matrices and the buffers (the only allocation).
    pub fn new() -> Self {
        Self {
            coordinates: Coordinates::Outputs,
            d: 0,
            na: 0,
            index: [0; N],
            tangent: SMatrix::zeros(),
            dxdot_dy: SMatrix::zeros(),
            dyddot_dy: SMatrix::zeros(),
            dyddot_dydot: SMatrix::zeros(),
            dyddot_du: SMatrix::zeros(),
            cond: f64::NAN,
            derivatives: ForwardDynamicsDerivatives::new(),
            full_derivatives: false,
            lu: vec![0.0; M * M],
            piv: vec![0; M],
            rhs: vec![0.0; M],
            work: vec![0.0; 2 * M],
        }
    }

    /// `A` (2d × 2d) and `B` (2d × na), row-major, into `a` and `b`.
    ///
    /// Errors: `Dimension` when `a` is not `(2d)²` long or `b` not `2d na`.
    pub fn state_space(&self, a: &mut [f64], b: &mut [f64]) -> Result<(), SolverError> {
        let (d, na) = (self.d, self.na);
        let w = 2 * d;
        for (what, s, n) in [("A", &*a, w * w), ("B", &*b, w * na)] {
            if s.len() != n {
                return Err(SolverError::Dimension {
                    what,
                    expected: n,
                    found: s.len(),
                });
            }
        }
        a.fill(0.0);
        b.fill(0.0);
        for i in 0..d {
            a[i * w + d + i] = 1.0;
            for k in 0..d {
                a[(d + i) * w + k] = self.dyddot_dy[(i, k)];
                a[(d + i) * w + d + k] = self.dyddot_dydot[(i, k)];
            }
            for c in 0..na {
                b[(d + i) * na + c] = self.dyddot_du[(i, c)];
            }
        }
        Ok(())
    }
}

impl<const N: usize, const M: usize> Default for Linearization<N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Forward dynamics and its derivatives at `data.x`, `data.xdot` (on the constraint manifold)
/// with the control forces `u` and the applied forces `q_forces` (held fixed), then the
/// linearisation in the coordinates `coordinates` into `out` (see the [module](self)
/// documentation). Writes what [`forward_dynamics_derivatives`](crate::forward_dynamics_derivatives) writes and returns its report.
///
/// Errors: those of [`forward_dynamics_derivatives`](crate::forward_dynamics_derivatives); `Underactuated` for
/// `Coordinates::Actuated` on a robot that is not fully actuated, `MissingOutputs` (as the
/// solvers that need outputs) for `Coordinates::Outputs` on a robot without them, `Dimension`
/// when the other coordinates are not `M` many; `Singular` (`what`: `"G_c"`) when `G`
/// restricted to the other coordinates is singular or its condition estimate exceeds
/// `SolverOptions::cond_max`: at a singularity of the chosen coordinates (for the actuated
/// ones, a parallel singularity) they do not parametrise the manifold.
pub fn linearize<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut Linearization<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    coordinates: Coordinates,
) -> Result<DynamicsReport, SolverError> {
    let s = model.structure();
    let idx = match coordinates {
        Coordinates::Outputs => {
            s.require_outputs("linearize")?;
            s.outputs
        }
        Coordinates::Actuated => {
            s.require_actuated("linearize")?;
            s.actuated
        }
    };
    let d = idx.len();
    if d + M != N {
        return Err(SolverError::Dimension {
            what: "independent coordinates",
            expected: N - M,
            found: d,
        });
    }
    out.coordinates = coordinates;
    out.d = d;
    out.na = s.actuated.len();
    out.index = [0; N];
    out.index[..d].copy_from_slice(idx);
    let ik = s.ik_blocks;
    let blocks_cover = ik.iter().map(|b| b.rows.len()).sum::<usize>() == M;
    let (report, reduced) = prepare(
        model,
        data,
        &mut out.derivatives,
        u,
        q_forces,
        Baumgarte::NONE,
        DerivativesSolver::Auto,
    )?;
    let outputs_path = coordinates == Coordinates::Outputs && blocks_cover;
    if reduced && outputs_path && !out.full_derivatives && d <= P_MAX {
        if d <= 8 {
            reduced_outputs::<K, N, M, 8>(model, out)?;
        } else {
            reduced_outputs::<K, N, M, 16>(model, out)?;
        }
        return finite_result(out).map(|()| report);
    }
    solve_prepared(model, data, &mut out.derivatives, reduced, Outputs::All)?;
    if reduced && outputs_path {
        tangent_reduced(model, out)?;
    } else {
        tangent_lu(model, data, out, idx)?;
    }
    // The rows of y of ∂Ẍ/∂X T + ∂Ẍ/∂Ẋ ∂Ẋ/∂y, ∂Ẍ/∂Ẋ T and ∂Ẍ/∂U, from the derivatives'
    // rows.
    let na = out.na;
    let w = row_width(N, na);
    let rows = out.derivatives.xddot_rows();
    out.dyddot_dy.as_mut_slice().fill(0.0);
    out.dyddot_dydot.as_mut_slice().fill(0.0);
    out.dyddot_du.as_mut_slice().fill(0.0);
    for (i, &jy) in idx.iter().enumerate() {
        let row = &rows[jy * w..(jy + 1) * w];
        let (rx, rv) = (&row[..N], &row[N..2 * N]);
        for k in 0..d {
            let (tk, dk) = (&out.tangent.data.0[k], &out.dxdot_dy.data.0[k]);
            out.dyddot_dy[(i, k)] = linalg::dot4(rx, tk) + linalg::dot4(rv, dk);
            out.dyddot_dydot[(i, k)] = linalg::dot4(rv, tk);
        }
        for c in 0..na {
            out.dyddot_du[(i, c)] = row[2 * N + c];
        }
    }
    finite_result(out).map(|()| report)
}

/// `NonFinite` unless the columns in use (the rest stays zero) are finite.
fn finite_result<const N: usize, const M: usize>(
    out: &Linearization<N, M>,
) -> Result<(), SolverError> {
    let (d, na) = (out.d, out.na);
    let all = [
        &out.tangent.as_slice()[..N * d],
        &out.dxdot_dy.as_slice()[..N * d],
        &out.dyddot_dy.as_slice()[..N * d],
        &out.dyddot_dydot.as_slice()[..N * d],
        &out.dyddot_du.as_slice()[..N * na],
    ];
    if all.iter().all(|v| all_finite(v)) {
        Ok(())
    } else {
        Err(SolverError::NonFinite { what: "linearize" })
    }
}

/// The tangent map `T = R` (`Rᵀ`'s rows, in the outputs' order) and `∂Ẋ/∂y` from the
/// elimination's factors: `G_c` is the block-diagonal `G_y` (its blocks `K_b` inverted and their
/// norms known, so its 1-norm condition number is exact). Writes the first `d` columns whole.
fn tangent_reduced<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    out: &mut Linearization<N, M>,
) -> Result<(), SolverError> {
    let what = "G_c";
    let (d, ik) = (out.d, model.structure().ik_blocks);
    let Some((rt, inv, (knorm, kinv_norm))) = out.derivatives.reduced_parts() else {
        return Err(SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block: None,
        });
    };
    out.cond = knorm * kinv_norm;
    if out.cond.is_nan() || out.cond > model.options.cond_max {
        return Err(SolverError::Singular {
            cond: out.cond,
            what,
            block: None,
        });
    }
    let dc_dxdot = &out.derivatives.dc_dxdot.data.0;
    for (k, (tk, dk)) in out
        .tangent
        .data
        .0
        .iter_mut()
        .zip(out.dxdot_dy.data.0.iter_mut())
        .take(d)
        .enumerate()
    {
        tk.copy_from_slice(&rt[k * N..(k + 1) * N]);
        // G_c ∂Ẋ_c/∂y_k = -½ ∂c/∂Ẋ T_k, block by block (zero on the outputs).
        let mut rhs = [0.0; M];
        for (col, &t) in dc_dxdot.iter().zip(tk.iter()) {
            if t != 0.0 {
                for (r, &v) in rhs.iter_mut().zip(col) {
                    *r -= 0.5 * v * t;
                }
            }
        }
        dk.fill(0.0);
        let mut off = 0;
        for blk in ik {
            let kb = blk.rows.len();
            let kinv = &inv[off..off + kb * kb];
            off += kb * kb;
            for (r, &jr) in blk.cols.iter().enumerate() {
                let mut v = 0.0;
                for (c, &ic) in blk.rows.iter().enumerate() {
                    v += kinv[c * kb + r] * rhs[ic];
                }
                dk[jr] = v;
            }
        }
    }
    Ok(())
}

/// `∂ÿ/∂y`, `∂ÿ/∂ẏ`, `∂ÿ/∂U` in the outputs' coordinates from the elimination's factors alone
/// (`W` lanes, at least `d`; the tangent map and `∂Ẋ/∂y` as [`tangent_reduced`] writes them):
/// `ÿ` is the reduced unknown `Z` (`R`'s rows on the outputs are the identity, `X0` is zero
/// there), so for a direction `(dX, dẊ, dU)` with the right-hand side `(a, b)` (`derivatives`'
/// module documentation)
///
/// ```text
/// dÿ = H⁻¹ Rᵀ (a - M X0) = H⁻¹ Q [a; b],   Q = [Rᵀ  -(M R)ᵀ G_y⁻¹]      (P × (N + M))
/// ```
///
/// and `Q [a; b] = -(Q ∂(r, c)/∂X) dX - (Q ∂(r, c)/∂Ẋ) dẊ + Rᵀ S dU`. The projections
/// `Q ∂(r, c)/∂X`, `Q ∂(r, c)/∂Ẋ` skip the kernel's zeros; then only the `2 d + na` directions
/// on the manifold (`(T_k, ∂Ẋ/∂y_k)`, `(0, T_k)`, `e_a`) are taken, and `H⁻¹` applied to them
/// (formed from the Cholesky factor, `d` solves).
fn reduced_outputs<K: Derivatives<N, M>, const N: usize, const M: usize, const W: usize>(
    model: &Model<K, N, M>,
    out: &mut Linearization<N, M>,
) -> Result<(), SolverError> {
    let s = model.structure();
    let d = out.d;
    let ik = s.ik_blocks;
    let what = "G_c";
    let Some((_, _, (knorm, kinv_norm))) = out.derivatives.reduced_parts() else {
        return Err(SolverError::NonFinite { what: "linearize" });
    };
    out.cond = knorm * kinv_norm;
    if out.cond.is_nan() || out.cond > model.options.cond_max {
        return Err(SolverError::Singular {
            cond: out.cond,
            what,
            block: None,
        });
    }
    let fd = &out.derivatives;
    let Some(f) = fd.reduced_factors(d) else {
        return Err(SolverError::NonFinite { what: "linearize" });
    };
    // T by rows (lanes over the outputs: T[j, k] = Rᵀ[k, j]); Q by columns, lanes over the
    // outputs: Rᵀ's columns (= T's rows), then -(M R)ᵀ G_y⁻¹'s.
    let mut qr = [[0.0; W]; N];
    for (c, row) in f.rt.chunks_exact(N).enumerate() {
        for (q, &v) in qr.iter_mut().zip(row) {
            q[c] = v;
        }
    }
    let mut qc = [[0.0; W]; M];
    // ∂Ẋ/∂y by rows: G_y ∂Ẋ_c/∂y = -½ ∂c/∂Ẋ T, block by block (zero on the outputs).
    let mut gt = [[0.0; W]; M];
    for (col, t) in fd.dc_dxdot.data.0.iter().zip(&qr) {
        for (&v, g) in col.iter().zip(gt.iter_mut()) {
            if v != 0.0 {
                for (gv, &tv) in g.iter_mut().zip(t) {
                    *gv -= 0.5 * v * tv;
                }
            }
        }
    }
    let mut dy = [[0.0; W]; N];
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        let kinv = &f.inv[off..off + k * k];
        off += k * k;
        for (ci, &ic) in blk.rows.iter().enumerate() {
            let (q, g) = (&mut qc[ic], &gt[ic]);
            for (r, &jr) in blk.cols.iter().enumerate() {
                let a = kinv[ci * k + r];
                for (qv, mrow) in q.iter_mut().zip(f.mrt.chunks_exact(N)) {
                    *qv -= a * mrow[jr];
                }
                for (dv, &gv) in dy[jr].iter_mut().zip(g) {
                    *dv += a * gv;
                }
            }
        }
    }
    for (k, (tk, dk)) in out
        .tangent
        .data
        .0
        .iter_mut()
        .zip(out.dxdot_dy.data.0.iter_mut())
        .take(d)
        .enumerate()
    {
        tk.copy_from_slice(&f.rt[k * N..(k + 1) * N]);
        for (v, dj) in dk.iter_mut().zip(&dy) {
            *v = dj[k];
        }
    }
    let mut px = [[0.0; W]; N];
    let mut pv = [[0.0; W]; N];
    project(&fd.dr_dx.data.0, &fd.dc_dx.data.0, &qr, &qc, &mut px);
    project(&fd.dr_dxdot.data.0, &fd.dc_dxdot.data.0, &qr, &qc, &mut pv);
    // H⁻¹ by columns (symmetric: also its rows).
    let mut hinv = [[0.0; W]; W];
    for (c, col) in hinv.iter_mut().enumerate().take(d) {
        col[c] = 1.0;
        cholesky_solve(f.chol, d, col);
    }
    // dÿ = H⁻¹ e for every direction's e (lanes over the outputs).
    let apply = |e: &[f64; W], z: &mut [f64]| {
        let mut acc = [0.0; W];
        for (h, &ec) in hinv.iter().zip(e).take(d) {
            for (a, &hv) in acc.iter_mut().zip(h) {
                *a += hv * ec;
            }
        }
        z.copy_from_slice(&acc[..d]);
    };
    for k in 0..d {
        let (mut ey, mut ev) = ([0.0; W], [0.0; W]);
        for ((t, dj), (x, p)) in qr.iter().zip(&dy).zip(px.iter().zip(&pv)) {
            let (t, dv) = (t[k], dj[k]);
            for ((y, v), (&x, &p)) in ey.iter_mut().zip(ev.iter_mut()).zip(x.iter().zip(p)) {
                *y -= x * t + p * dv;
                *v -= p * t;
            }
        }
        apply(&ey, &mut out.dyddot_dy.data.0[k][..d]);
        apply(&ev, &mut out.dyddot_dydot.data.0[k][..d]);
    }
    for (a, &j) in s.actuated.iter().enumerate() {
        let g = gear_ratio(s.gear, a);
        let mut e = qr[j];
        e.iter_mut().for_each(|v| *v *= g);
        apply(&e, &mut out.dyddot_du.data.0[a][..d]);
    }
    Ok(())
}

/// `out[j] = Σ_i dr[j][i] qr[i] + Σ_i dc[j][i] qc[i]` over the non-zero entries of column `j`.
fn project<const N: usize, const M: usize, const W: usize>(
    dr: &[[f64; N]; N],
    dc: &[[f64; M]; N],
    qr: &[[f64; W]; N],
    qc: &[[f64; W]; M],
    out: &mut [[f64; W]; N],
) {
    for ((o, rcol), ccol) in out.iter_mut().zip(dr).zip(dc) {
        let mut acc = [0.0; W];
        sparse_axpys(&mut acc, rcol, qr);
        sparse_axpys(&mut acc, ccol, qc);
        *o = acc;
    }
}

/// `acc += Σ_i col[i] q[i]` over the non-zero `col[i]`: a mask of them per 64 entries (no
/// branch per entry), then its set bits.
#[inline(always)]
fn sparse_axpys<const W: usize>(acc: &mut [f64; W], col: &[f64], q: &[[f64; W]]) {
    for (c64, q64) in col.chunks(64).zip(q.chunks(64)) {
        let mut mask = 0_u64;
        for (k, &v) in c64.iter().enumerate() {
            mask |= u64::from(v != 0.0) << k;
        }
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if let (Some(&v), Some(qv)) = (c64.get(i), q64.get(i)) {
                for (a, &x) in acc.iter_mut().zip(qv) {
                    *a += v * x;
                }
            }
        }
    }
}

/// `H z = e` in place by the Cholesky factor `L` of `H` (`p × p`, column-major, lower).
fn cholesky_solve<const W: usize>(l: &[f64], p: usize, e: &mut [f64; W]) {
    for j in 0..p {
        e[j] *= 1.0 / l[j * p + j];
        for i in j + 1..p {
            e[i] -= l[j * p + i] * e[j];
        }
    }
    for j in (0..p).rev() {
        for i in j + 1..p {
            e[j] -= l[j * p + i] * e[i];
        }
        e[j] *= 1.0 / l[j * p + j];
    }
}

/// The tangent map `T` and `∂Ẋ/∂y` by the LU of `G_c` (the coordinates `idx` independent),
/// with its condition estimate in `out.cond`.
fn tangent_lu<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &mut Linearization<N, M>,
    idx: &[usize],
) -> Result<(), SolverError> {
    // The other coordinates, ascending.
    let mut is_y = [false; N];
    for &j in idx {
        is_y[j] = true;
    }
    let mut comp = [0usize; M];
    for (slot, j) in comp.iter_mut().zip((0..N).filter(|&j| !is_y[j])) {
        *slot = j;
    }
    // G_c, column-major, by LU with its condition estimate.
    let g = data.g();
    for (c, &j) in comp.iter().enumerate() {
        for i in 0..M {
            out.lu[c * M + i] = g[(i, j)];
        }
    }
    let what = "G_c";
    let lu_error = |e: LuError| match e {
        LuError::Singular { .. } | LuError::NotPositiveDefinite { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block: None,
        },
        _ => SolverError::NonFinite { what },
    };
    let anorm = linalg::norm1(&out.lu, M).map_err(lu_error)?;
    linalg::lu_factor(&mut out.lu, M, &mut out.piv).map_err(lu_error)?;
    out.cond =
        linalg::cond1_estimate(&out.lu, M, &out.piv, anorm, &mut out.work).map_err(lu_error)?;
    if out.cond.is_nan() || out.cond > model.options.cond_max {
        return Err(SolverError::Singular {
            cond: out.cond,
            what,
            block: None,
        });
    }
    // T and ∂Ẋ/∂y, column by column.
    let dc_dxdot = &out.derivatives.dc_dxdot;
    out.tangent.as_mut_slice().fill(0.0);
    out.dxdot_dy.as_mut_slice().fill(0.0);
    for (k, &jy) in idx.iter().enumerate() {
        for i in 0..M {
            out.rhs[i] = -g[(i, jy)];
        }
        linalg::lu_solve(&out.lu, M, &out.piv, &mut out.rhs).map_err(lu_error)?;
        out.tangent[(jy, k)] = 1.0;
        for (&j, &v) in comp.iter().zip(out.rhs.iter()) {
            out.tangent[(j, k)] = v;
        }
        // G_c ∂Ẋ_c/∂y_k = -½ ∂c/∂Ẋ T_k.
        for i in 0..M {
            let mut sum = 0.0;
            for j in 0..N {
                sum += dc_dxdot[(i, j)] * out.tangent[(j, k)];
            }
            out.rhs[i] = -0.5 * sum;
        }
        linalg::lu_solve(&out.lu, M, &out.piv, &mut out.rhs).map_err(lu_error)?;
        for (&j, &v) in comp.iter().zip(out.rhs.iter()) {
            out.dxdot_dy[(j, k)] = v;
        }
    }
    Ok(())
}
