//! Elimination onto the outputs' coordinates: the structure every generated robot has.
//!
//! The coordinates split into the outputs `z` (the platform's pose, `Structure::outputs`, `P`
//! of them) and the rest `y`, which the inverse-kinematics blocks partition: block `b` has the
//! constraint rows `R_b` and the columns `C_b`, and its rows involve only its columns and the
//! outputs. So `G = [G_y | G_z]` with `G_y` block diagonal (the blocks `K_b = G[R_b, C_b]`, 3 × 3
//! per leg of a Stewart platform), and away from a serial singularity (a singular `K_b`) every
//! motion that satisfies the acceleration constraint `G Ẍ = gamma` is
//!
//! ```text
//! Ẍ = R z̈ + r0,   R = [-G_y⁻¹ G_z ; I],   r0 = [G_y⁻¹ gamma ; 0]
//! ```
//!
//! with `G_y⁻¹ G_z` formed block by block (`W_b = K_b⁻¹ G[R_b, z]`). Forward dynamics then needs
//! only the `P × P` symmetric positive definite reduced mass matrix `Rᵀ M R` (6 × 6 for the
//! 6-UPS) instead of the `M × M` Schur complement `S_c = G M⁻¹ Gᵀ` (18 × 18). Forward kinematics
//! eliminates the same way with `J_p` ([`fk_factor`]).

use nalgebra::SMatrix;

use super::invert_block;
use crate::linalg::{self, SMALL};
use crate::model::Model;
use crate::tasks::{EquationsOfMotion, Robot};

/// The largest condition number of a block `K_b` for which forward kinematics eliminates onto
/// the outputs: the elimination's rounding grows with it (Newton corrects a slightly inexact
/// step; the dense LU takes over beyond).
pub(crate) const K_COND_MAX: f64 = 1e4;

/// The same for forward dynamics, tighter: near a serial singularity (a leg's inverse
/// kinematics, which forward dynamics does not care about) `Rᵀ M R` becomes ill-conditioned
/// like `cond(K_b)²` while `S_c` stays regular (the stress walk towards one: `cond(K_b)` 595
/// gave `cond(Rᵀ M R)` 4.7e3 against 70 for `S_c`), so beyond 100 the Schur complement runs.
/// At the 6-UPS's regular poses the blocks stay below 3, the five-bar's below 12.
pub(crate) const FD_K_COND_MAX: f64 = 1e2;

/// The inputs of [`forward_dynamics`], evaluated by the caller at the state.
pub(crate) struct Terms<'a, const N: usize, const M: usize> {
    pub g: &'a SMatrix<f64, M, N>,
    pub mass: &'a SMatrix<f64, N, N>,
    /// `Dynamics::mass_blocks`, checked.
    pub mass_blocks: &'a [&'a [usize]],
    /// `‖M⁻¹‖₁` or an upper bound of it (from the Cholesky factors of the mass blocks).
    pub minv_norm: f64,
    /// `F = psi + Q + S U`.
    pub force: &'a [f64; N],
    /// The right-hand side of the acceleration constraint (with Baumgarte's terms).
    pub gamma: &'a [f64],
}

/// Forward dynamics by elimination onto the outputs: solves `M Ẍ + Gᵀ lambda = F`,
/// `G Ẍ = gamma` into `xddot`, `lambda`, by
///
/// 1. `K_b⁻¹` of every inverse-kinematics block (explicit, exact condition numbers), `R` and
///    `r0` (see the [module](self) documentation);
/// 2. `(Rᵀ M R) z̈ = Rᵀ (F - M r0)` (the constraint forces drop out: `G R = 0`), by the explicit
///    inverse of the `P × P` matrix (`P <= linalg::SMALL`), and `Ẍ = R z̈ + r0`;
/// 3. `lambda` from the rows of `y`: `G_yᵀ lambda = (F - M Ẍ)_y`, one transposed product
///    with `K_b⁻¹` per block.
///
/// Returns the exact 1-norm condition number of `Rᵀ M R`, or `None` (nothing written that the
/// caller reads) when the structure does not apply (blocks of different orders or above 4 × 4,
/// no outputs or more than `linalg::SMALL`), a block is singular or has a condition number above
/// [`FD_K_COND_MAX`], or `S_c` is not certified: the decision on `Singular` belongs to the Schur
/// complement `S_c = G M⁻¹ Gᵀ` (the constraints' rank), which this path never forms. It is certified by the rigorous bound
///
/// ```text
/// cond₁(S_c) <= ‖G‖₁ ‖G‖_∞ ‖M⁻¹‖₁ · ‖G_y⁻¹‖₁ ‖G_y⁻¹‖_∞ √(N - P) ‖M‖₁ <= cond_max / 2,
/// ```
///
/// from `S_c⁻¹ = G_y⁻ᵀ Q_yy G_y⁻¹` with `Q = M - M R (Rᵀ M R)⁻¹ Rᵀ M`, which lies between 0
/// and `M` (Loewner order: `M^½ (I - projector) M^½`), so `‖Q_yy‖₁ <= √(N - P) ‖Q_yy‖₂ <=
/// √(N - P) ‖M‖₁`. On the 6-UPS near home it is about 1e4 (`cond_max / 2` = 5e6).
pub(crate) fn forward_dynamics<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    t: &Terms<'_, N, M>,
    cond_max: f64,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Option<f64> {
    let ik = model.structure().ik_blocks;
    by_ik_order!(K, ik, B => fd_fixed::<K, N, M, B>(model, t, cond_max, xddot, lambda), _ => None)
}

/// `‖A‖_∞` (largest absolute row sum) of a column-major `B × B` array.
#[inline]
fn norm_inf_fixed<const B: usize>(a: &[[f64; B]; B]) -> f64 {
    let mut rows = [0.0; B];
    for col in a {
        for (r, &v) in rows.iter_mut().zip(col) {
            *r += v.abs();
        }
    }
    rows.iter().fold(0.0, |m: f64, &v| m.max(v))
}

/// [`forward_dynamics`] for inverse-kinematics blocks all of order `B`.
fn fd_fixed<K: EquationsOfMotion<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    t: &Terms<'_, N, M>,
    cond_max: f64,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Option<f64> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let p = z.len();
    if p == 0 || p > SMALL || ik.len() > M {
        return None;
    }
    let g = &t.g.data.0;

    // 1. K_b⁻¹, the rows of R (-W_b for the blocks' columns, unit rows for the outputs) and r0.
    let mut kinv = [[[0.0; B]; B]; M];
    let (mut kinv_1, mut kinv_inf) = (0.0_f64, 0.0_f64);
    let mut r = [[0.0; SMALL]; N];
    let mut r0 = [0.0; N];
    for (blk, ki) in ik.iter().zip(kinv.iter_mut()) {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let (inv, anorm, inv_norm) = invert_block::<N, M, B>(t.g, rows, cols).ok()?;
        let cond = anorm * inv_norm;
        if cond.is_nan() || cond > FD_K_COND_MAX.min(cond_max) {
            return None;
        }
        kinv_1 = kinv_1.max(inv_norm);
        kinv_inf = kinv_inf.max(norm_inf_fixed(&inv));
        for (pi, &zj) in z.iter().enumerate() {
            let gz: [f64; B] = core::array::from_fn(|i| g[zj][rows[i]]);
            let w = linalg::mul_fixed(&inv, &gz);
            for (&wi, &j) in w.iter().zip(cols) {
                r[j][pi] = -wi;
            }
        }
        let gb: [f64; B] = core::array::from_fn(|i| t.gamma.get(rows[i]).copied().unwrap_or(0.0));
        let sol = linalg::mul_fixed(&inv, &gb);
        for (&v, &j) in sol.iter().zip(cols) {
            r0[j] = v;
        }
        *ki = inv;
    }
    // The outputs belong to no block: their rows of R and entries of r0 are still zero.
    for (pi, &zj) in z.iter().enumerate() {
        *r.get_mut(zj)?.get_mut(pi)? = 1.0;
    }

    // The certificate of S_c (see `forward_dynamics`). ‖G‖₁ and ‖G‖_∞ over the structure:
    // a block's column is zero outside the block's rows, an output's column is dense.
    let (mut g1, mut grows) = (0.0_f64, [0.0; M]);
    for (col, &b) in g.iter().zip(&model.ik_block_of) {
        let mut c = 0.0;
        match ik.get(b) {
            Some(blk) => {
                for &i in blk.rows {
                    let v = col[i].abs();
                    c += v;
                    grows[i] += v;
                }
            }
            None => {
                for (rs, &v) in grows.iter_mut().zip(col) {
                    c += v.abs();
                    *rs += v.abs();
                }
            }
        }
        g1 = g1.max(c);
    }
    let ginf = grows.iter().fold(0.0_f64, |m, &v| m.max(v));
    let mut m1 = 0.0_f64;
    for blk in t.mass_blocks {
        for &jc in blk.iter() {
            let col = &t.mass.data.0[jc];
            m1 = m1.max(blk.iter().map(|&jr| col[jr].abs()).sum());
        }
    }
    let ny = (N - p) as f64;
    let bound = g1 * ginf * t.minv_norm * kinv_1 * kinv_inf * ny.sqrt() * m1;
    // (A NaN bound does not certify.)
    if bound.is_nan() || bound > 0.5 * cond_max {
        return None;
    }

    // 2. Rᵀ M R and Rᵀ (F - M r0), one mass block at a time, on rows of the fixed width
    //    `linalg::SMALL` (the entries beyond P stay zero).
    let mut mr = [[0.0; SMALL]; SMALL]; // [column][row], lower triangle
    let mut rhs = [0.0; SMALL];
    for blk in t.mass_blocks {
        for &jr in blk.iter() {
            // (M R)_jr and (M r0)_jr over the block's columns.
            let (mrow, mr0) = match **blk {
                [j] => {
                    let m = t.mass.data.0[j][j];
                    (r[j].map(|v| m * v), m * r0[j])
                }
                _ => {
                    let mut mrow = [0.0; SMALL];
                    let mut mr0 = 0.0;
                    for &jc in blk.iter() {
                        let m = t.mass.data.0[jc][jr];
                        mr0 += m * r0[jc];
                        axpy_row(&mut mrow, m, &r[jc]);
                    }
                    (mrow, mr0)
                }
            };
            let rj = &r[jr];
            axpy_row(&mut rhs, t.force[jr] - mr0, rj);
            // The lower triangle (fixed bounds: unrolled).
            for c in 0..SMALL {
                for rr in c..SMALL {
                    mr[c][rr] += mrow[c] * rj[rr];
                }
            }
        }
    }
    let mut a = [0.0; SMALL * SMALL];
    for c in 0..p {
        for rr in c..p {
            a[rr + c * p] = mr[c][rr];
            a[c + rr * p] = mr[c][rr];
        }
    }
    let a = &mut a[..p * p];
    let anorm = linalg::norm1(a, p).ok()?;
    let inv_norm = linalg::invert_small(a, p).ok()?;
    let cond = anorm * inv_norm;
    if cond.is_nan() || cond > cond_max {
        return None;
    }
    let mut zdd = [0.0; SMALL];
    for c in 0..p {
        let col = &a[c * p..c * p + p];
        for (zi, &v) in zdd.iter_mut().zip(col) {
            *zi += v * rhs[c];
        }
    }

    // Ẍ = R z̈ + r0.
    for ((xd, rj), &r0j) in xddot.iter_mut().zip(&r).zip(&r0) {
        *xd = r0j + rj[..p].iter().zip(&zdd).map(|(a, b)| a * b).sum::<f64>();
    }

    // 3. lambda: K_bᵀ lambda_b = (F - M Ẍ) on the block's columns.
    let mut res = [0.0; N];
    super::mass_times(t.mass, t.mass_blocks, xddot, &mut res);
    for (rv, &fv) in res.iter_mut().zip(t.force) {
        *rv = fv - *rv;
    }
    for (blk, ki) in ik.iter().zip(&kinv) {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let v: [f64; B] = core::array::from_fn(|i| res[cols[i]]);
        let l = linalg::mul_transpose_fixed(ki, &v);
        for (&lv, &i) in l.iter().zip(rows) {
            lambda[i] = lv;
        }
    }
    Some(cond)
}

/// The largest inverse-kinematics block [`FkFactors`] handles.
const BMAX: usize = 3;

/// A row over the outputs, zero-padded to `linalg::SMALL` entries: every loop over the outputs
/// has a compile-time length (two AVX registers) whatever `P`.
type Row = [f64; SMALL];

/// The factors of `J_p` (forward kinematics) by elimination onto the outputs.
///
/// The rows `R_b` of block `b` involve its `l_b` passive columns `L_b` (the block's columns
/// without its actuated one: the two joint angles of a Stewart leg) and the outputs `z`:
/// `A_b dl_b + G[R_b, z] dz = r_b` with `A_b = J_p[R_b, L_b]`. Completing `A_b` by a column
/// `n_b` orthogonal to it (the cross product of its two columns for a 3 × 2 block) gives an
/// invertible `K_b = [A_b | n_b]`; with `W_b = K_b⁻¹ G[R_b, z]` and `t_b = K_b⁻¹ r_b`, the
/// block's equations are `dl_b = t_b,L - W_b,L dz` and the last row `W_b,n dz = t_b,n`. Stacked
/// over the blocks the last rows are the `P × P` system `E dz = s` (the robot's inverse
/// Jacobian up to row scaling: 6 × 6 for the 6-UPS, one row per leg). A solve with `J_p`
/// (18 × 18) then costs one 3 × 3 product per leg and one product with the explicit `E⁻¹`.
///
/// This needs blocks with exactly one actuated column each (`l_b = B - 1`), of order 2 or 3:
/// Stewart platforms, hexapods, deltas, five-bars. Other structures take the dense path.
#[derive(Debug, Clone)]
pub(crate) struct FkFactors<const M: usize> {
    /// Blocks factored (`Structure::ik_blocks.len()`, also `P`) and their order `B`.
    nb: usize,
    bk: usize,
    /// Per block: its passive columns.
    lcols: [[usize; BMAX]; M],
    /// Per block: `K_b⁻¹` (`[column][row]`).
    kinv: [[[f64; BMAX]; BMAX]; M],
    /// Per block: `W_b = K_b⁻¹ G[R_b, z]`, `[row][output]`; row `B - 1` is the block's row of `E`.
    w: [[Row; BMAX]; M],
    /// `E⁻¹`, by columns.
    einv: [Row; SMALL],
    /// `‖J_p‖₁`.
    anorm: f64,
}

impl<const M: usize> FkFactors<M> {
    pub(crate) fn new() -> Self {
        Self {
            nb: 0,
            bk: 0,
            lcols: [[0; BMAX]; M],
            kinv: [[[0.0; BMAX]; BMAX]; M],
            w: [[[0.0; SMALL]; BMAX]; M],
            einv: [[0.0; SMALL]; SMALL],
            anorm: 0.0,
        }
    }
}

#[inline(always)]
fn axpy_row(y: &mut Row, a: f64, x: &Row) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

#[inline(always)]
fn dot_row(a: &Row, b: &Row) -> f64 {
    let mut s = 0.0;
    for (&ai, &bi) in a.iter().zip(b) {
        s += ai * bi;
    }
    s
}

/// Factors `J_p` (the passive columns of `g`) by elimination onto the outputs into `fk` and
/// returns a rigorous upper bound of its 1-norm condition number,
///
/// ```text
/// ‖J_p⁻¹‖₁ <= max_b ‖K_b⁻¹‖₁ (1 + (1 + ‖W_L‖₁) ‖E⁻¹‖₁)
/// ```
///
/// (`W_L` the rows of all `W_b` but the last), when it is at most `cond_max / 2`: the matrix is
/// certified, and the dense path's estimate (a lower bound of the true value) would not have
/// called it singular. `None` when the structure does not apply (blocks of different orders or
/// of an order other than 2 and 3, not exactly one actuated column per block, outputs other
/// than one per block or more than `linalg::SMALL`), a `K_b` is singular or worse conditioned
/// than [`K_COND_MAX`] (the elimination's rounding grows with it), `E` is singular, or the
/// bound does not certify: the caller factors `J_p` densely.
pub(crate) fn fk_factor<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    fk: &mut FkFactors<M>,
    cond_max: f64,
) -> Option<f64> {
    let ik = model.structure().ik_blocks;
    // Orders 2 and 3 only (a 1 x 1 or 4 x 4 block has no such factorisation here).
    by_ik_order!(K, ik, B => if B == 2 || B == 3 {
        fk_factor_fixed::<K, N, M, B>(model, g, fk, cond_max)
    } else {
        None
    }, _ => None)
}

/// `n` orthogonal to the `B - 1` columns of `a` (their cross product for `B = 3`, the
/// perpendicular for `B = 2`), scaled to the length of the first column.
#[inline(always)]
fn complement<const B: usize>(a: &[[f64; B]; B]) -> Option<[f64; B]> {
    let mut n = [0.0; B];
    match B {
        2 => (n[0], n[1]) = (-a[0][1], a[0][0]),
        3 => {
            let (u, v) = (&a[0], &a[1]);
            (n[0], n[1], n[2]) = (
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            );
        }
        _ => return None,
    }
    let nn = n.iter().map(|x| x * x).sum::<f64>().sqrt();
    let scale = a[0].iter().map(|x| x * x).sum::<f64>().sqrt() / nn;
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    Some(n.map(|x| x * scale))
}

/// [`fk_factor`] for blocks of order `B`.
fn fk_factor_fixed<K: Robot<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    fk: &mut FkFactors<M>,
    cond_max: f64,
) -> Option<f64> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let (nb, p) = (ik.len(), z.len());
    if p == 0 || p > SMALL || nb != p || nb > M || B > BMAX {
        return None;
    }
    let g = &g.data.0;
    let mut e = [0.0; SMALL * SMALL]; // column-major p × p
    let (mut kinv_max, mut anorm) = (0.0_f64, 0.0_f64);
    let mut wl = [0.0; SMALL]; // column sums of |W_L|
    for (b, blk) in ik.iter().enumerate() {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let lcols = &mut fk.lcols[b];
        let mut l = 0;
        for &j in blk.cols {
            if model.actuator_of.get(j) == Some(&usize::MAX) {
                *lcols.get_mut(l)? = j;
                l += 1;
            }
        }
        if l + 1 != B {
            return None;
        }
        let mut k = [[0.0; B]; B];
        for (kc, &j) in k.iter_mut().zip(&lcols[..l]) {
            let gc = &g[j];
            *kc = core::array::from_fn(|r| gc[rows[r]]);
            anorm = anorm.max(kc.iter().map(|v| v.abs()).sum());
        }
        k[B - 1] = complement(&k)?;
        let knorm = linalg::norm1_fixed(&k);
        let mut inv = [[0.0; B]; B];
        let inv_norm = linalg::invert_fixed(&k, &mut inv).ok()?;
        let cond = knorm * inv_norm;
        if cond.is_nan() || cond > K_COND_MAX.min(cond_max) {
            return None;
        }
        kinv_max = kinv_max.max(inv_norm);
        let w = &mut fk.w[b];
        *w = [[0.0; SMALL]; BMAX];
        for (pi, &zj) in z.iter().enumerate() {
            let gc = &g[zj];
            let gz: [f64; B] = core::array::from_fn(|r| gc[rows[r]]);
            let wz = linalg::mul_fixed(&inv, &gz);
            for (wr, &v) in w.iter_mut().zip(&wz) {
                wr[pi] = v;
            }
            e[b + pi * p] = wz[B - 1];
        }
        for wr in &w[..l] {
            for (c, &v) in wl.iter_mut().zip(wr) {
                *c += v.abs();
            }
        }
        for (dst, src) in fk.kinv[b].iter_mut().zip(&inv) {
            dst[..B].copy_from_slice(src);
        }
    }
    // ‖J_p‖₁: the outputs' columns are dense, the blocks' passive columns were summed above.
    for &zj in z {
        anorm = anorm.max(g[zj].iter().map(|v| v.abs()).sum());
    }
    let e = &mut e[..p * p];
    let enorm = linalg::norm1(e, p).ok()?;
    let einv_norm = linalg::invert_small(e, p).ok()?;
    for (c, col) in fk.einv.iter_mut().enumerate().take(p) {
        *col = [0.0; SMALL];
        col[..p].copy_from_slice(&e[c * p..c * p + p]);
    }
    fk.nb = nb;
    fk.bk = B;
    fk.anorm = anorm;
    let wl_norm = wl.iter().fold(0.0_f64, |m, &v| m.max(v));
    let bound = anorm * kinv_max * (1.0 + (1.0 + wl_norm) * einv_norm);
    if bound.is_nan() || bound > 0.5 * cond_max || !(enorm * einv_norm).is_finite() {
        return None;
    }
    Some(bound)
}

/// `K_b⁻¹ v` over the block's order.
#[inline(always)]
fn kinv_mul(ki: &[[f64; BMAX]; BMAX], v: &[f64; BMAX]) -> [f64; BMAX] {
    let mut out = [0.0; BMAX];
    for (col, &vc) in ki.iter().zip(v) {
        for (o, &a) in out.iter_mut().zip(col) {
            *o += a * vc;
        }
    }
    out
}

/// Solves `J_p d = r` with the factors of [`fk_factor`]: `r` by constraint row, `d` written
/// into the passive coordinates of `out` (indexed by coordinate; the others untouched).
pub(crate) fn fk_solve<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    fk: &FkFactors<M>,
    r: &[f64; M],
    out: &mut [f64; N],
) {
    let s = model.structure();
    let (ik, z, last) = (
        s.ik_blocks,
        s.outputs,
        fk.bk.saturating_sub(1).min(BMAX - 1),
    );
    let mut t = [[0.0; BMAX]; M];
    let mut dz = [0.0; SMALL];
    for ((blk, tb), (ki, ei)) in ik
        .iter()
        .zip(t.iter_mut())
        .zip(fk.kinv.iter().zip(&fk.einv))
        .take(fk.nb)
    {
        let mut rb = [0.0; BMAX];
        for (v, &i) in rb.iter_mut().zip(blk.rows) {
            *v = r[i];
        }
        *tb = kinv_mul(ki, &rb);
        axpy_row(&mut dz, tb[last], ei);
    }
    for (&zj, &d) in z.iter().zip(&dz) {
        out[zj] = d;
    }
    for ((tb, w), lc) in t.iter().zip(&fk.w).zip(&fk.lcols).take(fk.nb) {
        for ((&tv, wr), &j) in tb.iter().zip(w).zip(lc).take(last) {
            out[j] = tv - dot_row(wr, &dz);
        }
    }
}

/// The exact 1-norm condition number of `J_p` (up to rounding) from the factors of
/// [`fk_factor`]. Column `i` of block `b` of `J_p⁻¹` is, with `t = K_b⁻¹ e_i` and `s` its last
/// entry: `s E⁻¹ e_b` on the outputs, `-s W_b',L E⁻¹ e_b` on every block `b'` and `t_L` added
/// on block `b`; so `V[b][b'] = W_b',L E⁻¹ e_b` (`P² (B - 1)` dot products) gives every column
/// sum in `O(B)`.
pub(crate) fn fk_cond<const M: usize>(fk: &FkFactors<M>) -> f64 {
    let (nb, last) = (fk.nb, fk.bk.saturating_sub(1).min(BMAX - 1));
    let mut inv_norm = 0.0_f64;
    for (b, (ki, y)) in fk.kinv.iter().zip(&fk.einv).enumerate().take(nb) {
        // Σ over the other blocks and the outputs, and this block's V.
        let mut others = y.iter().map(|v| v.abs()).sum::<f64>();
        let mut own = [0.0; BMAX];
        for (bp, w) in fk.w.iter().enumerate().take(nb) {
            for (k, wr) in w.iter().enumerate().take(last) {
                let v = dot_row(wr, y);
                if bp == b {
                    own[k] = v;
                } else {
                    others += v.abs();
                }
            }
        }
        for col in ki.iter().take(last + 1) {
            let s = col[last];
            let local: f64 = col[..last]
                .iter()
                .zip(&own)
                .map(|(&t, &v)| (t - s * v).abs())
                .sum();
            inv_norm = inv_norm.max(s.abs() * others + local);
        }
    }
    let cond = fk.anorm * inv_norm;
    if cond.is_nan() { f64::INFINITY } else { cond }
}
