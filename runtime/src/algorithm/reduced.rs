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

use crate::factor::{BMAX, FdFactors, FkFactors, WMAX};
use crate::linalg;
use crate::model::Model;
use crate::plan::{invert_block, mass_times};
use crate::tasks::{EquationsOfMotion, Robot};

/// The largest condition number of a block `K_b` for which forward kinematics eliminates onto
/// the outputs: the elimination's rounding grows with it (Newton corrects a slightly inexact
/// step; the dense LU takes over beyond).
pub(crate) const K_COND_MAX: f64 = 1e4;

/// Forward dynamics eliminates onto the outputs while every inverse-kinematics block `K_b` has a
/// 1-norm condition number (exact: the blocks are inverted explicitly) of at most this. Near a
/// serial singularity (a leg's inverse kinematics, which forward dynamics does not care about)
/// `Rᵀ M R` becomes ill-conditioned like `cond(K_b)²` while `S_c` stays regular (the stress walk
/// towards one: `cond(K_b)` 595 gave `cond(Rᵀ M R)` 4.7e3 against 70 for `S_c`), so beyond it
/// the Schur complement runs. At the 6-UPS's regular poses the blocks stay below 3, the
/// five-bar's below 12.
pub(crate) const FD_K_COND_MAX: f64 = 1e2;

/// Past this pivot ratio of `Rᵀ M R`'s Cholesky factor (`(max l_ii / min l_ii)²`, a lower
/// bound of its 2-norm condition number, free with the factor), or past `cond_max / 100` if
/// that is lower, the Hager/Higham estimate is computed too and decides against
/// `SolverOptions::cond_max`; below it the estimate is not needed (the ratio is all the
/// report gives).
const FD_COND_CHECK: f64 = 1e6;

/// The pivot ratio of `Rᵀ M R` up to which its Cholesky factor is trusted without the condition
/// estimate (see `FD_COND_CHECK`).
pub(crate) fn fd_cond_check(cond_max: f64) -> f64 {
    FD_COND_CHECK.min(1e-2 * cond_max)
}

/// The inputs of [`forward_dynamics`], evaluated by the caller at the state.
pub(crate) struct Terms<'a, const N: usize, const M: usize> {
    pub g: &'a SMatrix<f64, M, N>,
    pub mass: &'a SMatrix<f64, N, N>,
    /// `Dynamics::mass_blocks`, checked.
    pub mass_blocks: &'a [&'a [usize]],
    /// `F = psi + Q + S U`.
    pub force: &'a [f64; N],
    /// The right-hand side of the acceleration constraint (with Baumgarte's terms).
    pub gamma: &'a [f64],
}

/// What [`forward_dynamics`] reports: the conditioning it read off its factors.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Conditioning {
    /// The largest 1-norm condition number of the blocks `K_b` (exact).
    pub blocks: f64,
    /// The condition of `Rᵀ M R`: the Cholesky pivot ratio `(max l_ii / min l_ii)²`, or the
    /// Hager/Higham 1-norm estimate when that ratio passed `FD_COND_CHECK`.
    pub reduced: f64,
}

/// Forward dynamics by elimination onto the outputs: solves `M Ẍ + Gᵀ lambda = F`,
/// `G Ẍ = gamma` into `xddot`, `lambda`, for inverse-kinematics blocks of any order up to
/// `linalg::INVERT_MAX` (16) and up to 16 outputs, by
///
/// 1. the explicit inverse of every inverse-kinematics block `K_b` (with its exact condition
///    number), `R` and `r0` (see the [module](self) documentation), kept as `Rᵀ`: one row of
///    length N per output;
/// 2. `(Rᵀ M R) z̈ = Rᵀ (F - M r0)` (the constraint forces drop out: `G R = 0`), its entries
///    as dot products of `(M R)ᵀ` and `Rᵀ` rows, by Cholesky, and `Ẍ = R z̈ + r0`. `M` only
///    has to be positive definite on the motions `R`, so massless frames (a serial arm's tool
///    pose) need no other path;
/// 3. `lambda` from the rows of `y`: `K_bᵀ lambda_b = (F - M Ẍ)` on the block's columns.
///
/// The checks cost nothing on the regular path: the blocks' condition numbers come with their
/// inverses and the Cholesky pivots with the factor; only a pivot ratio past `FD_COND_CHECK`
/// runs the condition estimate. Returns `None` (nothing written that the caller reads) when
/// there are no outputs or more than 16, a block is larger than 16 × 16, singular or worse
/// conditioned than [`FD_K_COND_MAX`] (near a serial singularity: the Schur complement then
/// solves, and decides `Singular` on the constraints' rank), or `Rᵀ M R` is not positive
/// definite or its estimate exceeds `cond_max`.
pub(crate) fn forward_dynamics<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    t: &Terms<'_, N, M>,
    cond_max: f64,
    fac: &mut FdFactors<M>,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Option<Conditioning> {
    // `R` has `N - M` columns (the degrees of freedom), padded to a compile-time width; only
    // the width this robot needs is compiled.
    match N - M {
        0 => None,
        1..=4 => fd_width::<K, N, M, 4>(model, t, cond_max, fac, xddot, lambda),
        5..=8 => fd_width::<K, N, M, 8>(model, t, cond_max, fac, xddot, lambda),
        9..=16 => fd_width::<K, N, M, 16>(model, t, cond_max, fac, xddot, lambda),
        _ => None,
    }
}

/// [`forward_dynamics`] with `R` padded to `W >= N - M` columns, and the blocks of the robot's
/// uniform order `B` (1 to 4) inverted at that compile-time order, else (`B = 0`) at theirs.
fn fd_width<K: EquationsOfMotion<N, M>, const N: usize, const M: usize, const W: usize>(
    model: &Model<K, N, M>,
    t: &Terms<'_, N, M>,
    cond_max: f64,
    fac: &mut FdFactors<M>,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Option<Conditioning> {
    let ik = model.structure().ik_blocks;
    by_ik_order!(K, ik, B => fd_blocks::<K, N, M, W, B>(model, t, cond_max, fac, xddot, lambda),
        _ => fd_blocks::<K, N, M, W, 0>(model, t, cond_max, fac, xddot, lambda))
}

/// Inverts block `blk` of `G` into `out` (its `k²` packed entries) and returns its exact 1-norm
/// condition number, at the compile-time order `B` or, with `B = 0`, at its own (up to
/// `linalg::INVERT_MAX`).
#[inline(always)]
fn invert_ik_block<const N: usize, const M: usize, const B: usize>(
    g: &SMatrix<f64, M, N>,
    blk: &crate::kernels::IkBlock,
    out: &mut [f64],
) -> Option<f64> {
    if B > 0 {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let (inv, anorm, inv_norm) = invert_block::<N, M, B>(g, rows, cols).ok()?;
        out.copy_from_slice(inv.as_flattened());
        return Some(anorm * inv_norm);
    }
    let k = blk.rows.len();
    for (c, &j) in blk.cols.iter().enumerate() {
        let col = &g.data.0[j];
        for (a, &i) in out[c * k..c * k + k].iter_mut().zip(blk.rows) {
            *a = col[i];
        }
    }
    let anorm = linalg::norm1(out, k).ok()?;
    let inv_norm = linalg::invert_small(out, k).ok()?;
    Some(anorm * inv_norm)
}

/// `out[cols] = sign K_b⁻¹ src[rows]`, with `inv` the column-major `K_b⁻¹` (order
/// `rows.len() <= linalg::INVERT_MAX`, one axpy per column); nothing is written when `src` is
/// zero on the block's rows (an output that does not move the block's rows).
#[inline(always)]
fn apply_inverse<const N: usize>(
    inv: &[f64],
    rows: &[usize],
    cols: &[usize],
    src: &[f64],
    sign: f64,
    out: &mut [f64; N],
) {
    let k = rows.len();
    if rows.iter().all(|&i| src[i] == 0.0) {
        return;
    }
    let mut w = [0.0; linalg::INVERT_MAX];
    for (col, &i) in inv.chunks_exact(k).zip(rows) {
        let vc = src[i];
        for (wi, &a) in w.iter_mut().zip(col) {
            *wi += a * vc;
        }
    }
    for (&wi, &j) in w.iter().zip(cols) {
        out[j] = sign * wi;
    }
}

/// [`fd_width`] with blocks of order `B` (`0`: each at its own order).
fn fd_blocks<
    K: EquationsOfMotion<N, M>,
    const N: usize,
    const M: usize,
    const W: usize,
    const B: usize,
>(
    model: &Model<K, N, M>,
    t: &Terms<'_, N, M>,
    cond_max: f64,
    fac: &mut FdFactors<M>,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Option<Conditioning> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let p = z.len();
    if p == 0 || p > W {
        return None;
    }
    let g = &t.g.data.0;
    let inv_all = fac.inv.as_flattened_mut();

    // 1. K_b⁻¹, Rᵀ (row c: -K_b⁻¹ G[R_b, z_c] on the blocks' columns, 1 on output c) and r0
    //    (K_b⁻¹ gamma_b).
    let mut rt = [[0.0; N]; W];
    let mut r0 = [0.0; N];
    let mut worst = 0.0_f64;
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        if k > linalg::INVERT_MAX {
            return None;
        }
        let inv = inv_all.get_mut(off..off + k * k)?;
        let cond = invert_ik_block::<N, M, B>(t.g, blk, inv)?;
        if cond.is_nan() || cond > FD_K_COND_MAX.min(cond_max) {
            return None;
        }
        worst = worst.max(cond);
        let (rows, cols) = (blk.rows, blk.cols);
        for (row, &zj) in rt.iter_mut().zip(z) {
            apply_inverse(inv, rows, cols, &g[zj], -1.0, row);
        }
        apply_inverse(inv, rows, cols, t.gamma, 1.0, &mut r0);
        off += k * k;
    }
    for (row, &zj) in rt.iter_mut().zip(z) {
        row[zj] = 1.0;
    }

    // 2. (M R)ᵀ and F - M r0, one mass block at a time, then Rᵀ M R and Rᵀ (F - M r0) as dot
    //    products of rows of length N.
    let mut mrt = [[0.0; N]; W];
    let mut fr = *t.force;
    for blk in t.mass_blocks {
        if let [j] = **blk {
            let m = t.mass.data.0[j][j];
            for (mrow, row) in mrt.iter_mut().zip(&rt).take(p) {
                mrow[j] = m * row[j];
            }
            fr[j] -= m * r0[j];
            continue;
        }
        for &jr in blk.iter() {
            let mut mr0 = 0.0;
            for &jc in blk.iter() {
                let m = t.mass.data.0[jc][jr];
                mr0 += m * r0[jc];
                for (mrow, row) in mrt.iter_mut().zip(&rt).take(p) {
                    mrow[jr] += m * row[jc];
                }
            }
            fr[jr] -= mr0;
        }
    }
    let mut a = [[0.0; W]; W]; // [column][row], lower triangle
    let mut rhs = [0.0; W];
    for c in 0..p {
        rhs[c] = linalg::dot4(&rt[c], &fr);
        for rr in c..p {
            a[c][rr] = linalg::dot4(&mrt[c], &rt[rr]);
        }
    }

    // 3. Cholesky of Rᵀ M R (order p, in the fixed arrays).
    for j in 0..p {
        let (left, right) = a.split_at_mut(j);
        let col = &mut right[0];
        for lp in left.iter() {
            let ljp = lp[j];
            for (c, &l) in col.iter_mut().zip(lp).skip(j) {
                *c -= l * ljp;
            }
        }
        let d = col[j];
        if d.is_nan() || d <= 0.0 || !d.is_finite() {
            return None;
        }
        let ljj = d.sqrt();
        col[j] = ljj;
        let inv = 1.0 / ljj;
        for c in col.iter_mut().take(p).skip(j + 1) {
            *c *= inv;
        }
    }
    let (mut lmin, mut lmax) = (f64::INFINITY, 0.0_f64);
    for (j, col) in a.iter().enumerate().take(p) {
        lmin = lmin.min(col[j]);
        lmax = lmax.max(col[j]);
    }
    let mut cond = (lmax / lmin) * (lmax / lmin);
    // (A limit set below the check's threshold makes every solve estimate.)
    if cond.is_nan() || cond > fd_cond_check(cond_max) {
        cond = reduced_cond_estimate(&a, p, t, &rt)?;
        if cond.is_nan() || cond > cond_max {
            return None;
        }
    }
    // z̈: L y = rhs, Lᵀ z̈ = y.
    let mut zdd = rhs;
    for j in 0..p {
        let yj = zdd[j] / a[j][j];
        zdd[j] = yj;
        for (zi, &l) in zdd.iter_mut().zip(&a[j]).take(p).skip(j + 1) {
            *zi -= l * yj;
        }
    }
    for j in (0..p).rev() {
        let mut sj = zdd[j];
        for (&l, &zi) in a[j].iter().zip(&zdd).take(p).skip(j + 1) {
            sj -= l * zi;
        }
        zdd[j] = sj / a[j][j];
    }

    // Ẍ = R z̈ + r0, one axpy of length N per output.
    *xddot = r0;
    for (row, &zc) in rt.iter().zip(&zdd).take(p) {
        for (x, &rv) in xddot.iter_mut().zip(row) {
            *x += zc * rv;
        }
    }

    // 4. lambda: K_bᵀ lambda_b = (F - M Ẍ) on the block's columns.
    let mut res = [0.0; N];
    mass_times(t.mass, t.mass_blocks, xddot, &mut res);
    let mut off = 0;
    for blk in ik {
        let k = blk.rows.len();
        let inv = inv_all.get(off..off + k * k)?;
        // lambda_b = K_b⁻ᵀ v: entry c is column c of K_b⁻¹ dotted with v.
        for (col, &i) in inv.chunks_exact(k).zip(blk.rows) {
            let mut sum = 0.0;
            for (&a, &j) in col.iter().zip(blk.cols) {
                sum += a * (t.force[j] - res[j]);
            }
            lambda[i] = sum;
        }
        off += k * k;
    }
    Some(Conditioning {
        blocks: worst,
        reduced: cond,
    })
}

/// The Hager/Higham estimate of the 1-norm condition number of `Rᵀ M R` from its Cholesky
/// factor (the lower triangle of `l`, order `p`), its norm formed again from `Rᵀ` and `M`: run
/// only past `FD_COND_CHECK`.
fn reduced_cond_estimate<const N: usize, const M: usize, const W: usize>(
    l: &[[f64; W]; W],
    p: usize,
    t: &Terms<'_, N, M>,
    rt: &[[f64; N]; W],
) -> Option<f64> {
    // ‖Rᵀ M R‖₁ column by column: (Rᵀ M R) e_c = Rᵀ (M (R e_c)).
    let mut anorm = 0.0_f64;
    let mut mrc = [0.0; N];
    for row in rt.iter().take(p) {
        mass_times(t.mass, t.mass_blocks, row, &mut mrc);
        let s: f64 = rt.iter().take(p).map(|r| linalg::dot4(r, &mrc).abs()).sum();
        anorm = anorm.max(s);
    }
    let mut packed = [0.0; 256]; // W <= 16
    for c in 0..p {
        for rr in c..p {
            packed[rr + c * p] = l[c][rr];
        }
    }
    let mut work = [0.0; 32];
    linalg::cholesky_cond1_estimate(&packed[..p * p], p, anorm, &mut work[..2 * p]).ok()
}

/// The row width `W` for a robot with `N - M` degrees of freedom (the number of outputs `P` for
/// every generated robot): every loop over the outputs has this compile-time length, `P`
/// zero-padded to 8 (two AVX registers: the 6-UPS, the five-bar) or 16 (the two-stage
/// platform's 12 outputs); 0 beyond [`WMAX`]. Only the width a robot needs is compiled (a
/// `match` on this constant).
const fn fk_width(dof: usize) -> usize {
    match dof {
        1..=8 => 8,
        9..=WMAX => WMAX,
        _ => 0,
    }
}

/// `s` as rows of `W` entries (a trailing partial row dropped).
#[inline(always)]
fn rows_of<const W: usize>(s: &[f64]) -> &[[f64; W]] {
    s.as_chunks::<W>().0
}

#[inline(always)]
fn axpy_row<const W: usize>(y: &mut [f64; W], a: f64, x: &[f64; W]) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

#[inline(always)]
fn dot_row<const W: usize>(a: &[f64; W], b: &[f64; W]) -> f64 {
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
/// than one per block or more than [`WMAX`] or than the row width `fk_width(N - M)`), a `K_b`
/// is singular or worse conditioned than [`K_COND_MAX`] (the elimination's rounding grows with
/// it), `E` is singular, or the bound does not certify: the caller factors `J_p` densely.
pub(crate) fn fk_factor<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    fk: &mut FkFactors<M>,
    cond_max: f64,
) -> Option<f64> {
    match fk_width(N - M) {
        8 => fk_factor_width::<K, N, M, 8>(model, g, fk, cond_max),
        WMAX => fk_factor_width::<K, N, M, WMAX>(model, g, fk, cond_max),
        _ => None,
    }
}

/// [`fk_factor`] with rows of width `W`.
fn fk_factor_width<K: Robot<N, M>, const N: usize, const M: usize, const W: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    fk: &mut FkFactors<M>,
    cond_max: f64,
) -> Option<f64> {
    let ik = model.structure().ik_blocks;
    // Orders 2 and 3 only (a 1 x 1 or 4 x 4 block has no such factorisation here).
    by_ik_order!(K, ik, B => if B == 2 || B == 3 {
        fk_factor_fixed::<K, N, M, B, W>(model, g, fk, cond_max)
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

/// [`fk_factor`] for blocks of order `B` and rows of width `W`.
fn fk_factor_fixed<
    K: Robot<N, M>,
    const N: usize,
    const M: usize,
    const B: usize,
    const W: usize,
>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    fk: &mut FkFactors<M>,
    cond_max: f64,
) -> Option<f64> {
    let s = model.structure();
    let (ik, z) = (s.ik_blocks, s.outputs);
    let (nb, p) = (ik.len(), z.len());
    if p == 0 || p > W || W > WMAX || nb != p || nb > M || B > BMAX {
        return None;
    }
    let g = &g.data.0;
    let mut e = [[0.0; W]; W]; // column-major p × p in the first p² entries
    let e = e.as_flattened_mut();
    let (mut kinv_max, mut anorm) = (0.0_f64, 0.0_f64);
    let mut wl = [0.0; W]; // column sums of |W_L|
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
        let w: &mut [[f64; W]; B] = fk.w[b]
            .as_chunks_mut::<W>()
            .0
            .get_mut(..B)?
            .try_into()
            .ok()?;
        *w = [[0.0; W]; B];
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
    let einv: &mut [[f64; W]; W] = fk
        .einv
        .as_chunks_mut::<W>()
        .0
        .get_mut(..W)?
        .try_into()
        .ok()?;
    for (c, col) in einv.iter_mut().enumerate().take(p) {
        *col = [0.0; W];
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
    match fk_width(N - M) {
        8 => fk_solve_width::<K, N, M, 8>(model, fk, r, out),
        WMAX => fk_solve_width::<K, N, M, WMAX>(model, fk, r, out),
        _ => {}
    }
}

/// [`fk_solve`] with rows of width `W`.
fn fk_solve_width<K: Robot<N, M>, const N: usize, const M: usize, const W: usize>(
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
    let einv = rows_of::<W>(&fk.einv);
    let mut t = [[0.0; BMAX]; M];
    let mut dz = [0.0; W];
    for ((blk, tb), (ki, ei)) in ik
        .iter()
        .zip(t.iter_mut())
        .zip(fk.kinv.iter().zip(einv))
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
        for ((&tv, wr), &j) in tb.iter().zip(rows_of::<W>(w)).zip(lc).take(last) {
            out[j] = tv - dot_row(wr, &dz);
        }
    }
}

/// The exact 1-norm condition number of `J_p` (up to rounding) from the factors of
/// [`fk_factor`]. Column `i` of block `b` of `J_p⁻¹` is, with `t = K_b⁻¹ e_i` and `s` its last
/// entry: `s E⁻¹ e_b` on the outputs, `-s W_b',L E⁻¹ e_b` on every block `b'` and `t_L` added
/// on block `b`; so `V = W_L E⁻¹` (`P (B - 1)` rows of `P`: `V[b', k][b] = W_b',k E⁻¹ e_b`)
/// gives every column sum in `O(B)`.
pub(crate) fn fk_cond<const N: usize, const M: usize>(fk: &FkFactors<M>) -> f64 {
    match fk_width(N - M) {
        8 => fk_cond_width::<M, 8>(fk),
        WMAX => fk_cond_width::<M, WMAX>(fk),
        _ => f64::INFINITY,
    }
}

/// [`fk_cond`] with rows of width `W`: `V` by dot products of the rows of `W_L` with the
/// columns of `E⁻¹` for `W = 8`; beyond, by combinations of the rows of `E⁻¹` (transposed here:
/// axpys of width `W`, which vectorise, where the serial dot products of length 16 dominated:
/// the two-stage platform's forward velocity 5.4 -> 4.9 us). For the 6-UPS the transposition
/// measured slower than its 72 dot products of 8. Both sum in the same order.
fn fk_cond_width<const M: usize, const W: usize>(fk: &FkFactors<M>) -> f64 {
    let (nb, last) = (fk.nb, fk.bk.saturating_sub(1).min(BMAX - 1));
    if nb > W {
        return f64::INFINITY;
    }
    let einv = rows_of::<W>(&fk.einv);
    // Per column b of J_p⁻¹'s block b: the sum over the outputs and the other blocks
    // (`others`), and block b's own entries of V (`own`).
    let mut others = [0.0; W];
    for (col, o) in einv.iter().zip(others.iter_mut()).take(nb) {
        *o = col.iter().map(|v| v.abs()).sum::<f64>();
    }
    let mut own = [[0.0; BMAX]; W];
    if W <= 8 {
        for (b, (y, (oth, ob))) in einv
            .iter()
            .zip(others.iter_mut().zip(own.iter_mut()))
            .enumerate()
            .take(nb)
        {
            for (bp, w) in fk.w.iter().enumerate().take(nb) {
                for (k, wr) in rows_of::<W>(w).iter().enumerate().take(last) {
                    let v = dot_row(wr, y);
                    if bp == b {
                        ob[k] = v;
                    } else {
                        *oth += v.abs();
                    }
                }
            }
        }
    } else {
        let mut et = [[0.0; W]; W];
        for (b, col) in einv.iter().enumerate().take(nb) {
            for (er, &v) in et.iter_mut().zip(col) {
                er[b] = v;
            }
        }
        // Row (b', k) of V; its entry b' is block b''s own, the others add to `others`.
        for ((bp, w), ob) in fk.w.iter().enumerate().zip(own.iter_mut()).take(nb) {
            for (wr, o) in rows_of::<W>(w).iter().zip(ob.iter_mut()).take(last) {
                let mut v = [0.0; W];
                for (&a, er) in wr.iter().zip(&et).take(nb) {
                    axpy_row(&mut v, a, er);
                }
                *o = v[bp];
                v[bp] = 0.0;
                for (s, &x) in others.iter_mut().zip(&v) {
                    *s += x.abs();
                }
            }
        }
    }
    let mut inv_norm = 0.0_f64;
    for ((ki, ob), &oth) in fk.kinv.iter().zip(&own).zip(&others).take(nb) {
        for col in ki.iter().take(last + 1) {
            let s = col[last];
            let local: f64 = col[..last]
                .iter()
                .zip(ob)
                .map(|(&t, &v)| (t - s * v).abs())
                .sum();
            inv_norm = inv_norm.max(s.abs() * oth + local);
        }
    }
    let cond = fk.anorm * inv_norm;
    if cond.is_nan() { f64::INFINITY } else { cond }
}
