//! Forward dynamics by elimination onto the outputs' coordinates (see
//! [`algorithm::reduced`](crate::algorithm::reduced) for the elimination): with the
//! inverse-kinematics blocks `K_b` of `G` inverted explicitly, `Ẍ = R z̈ + r0`, and only the
//! `P × P` symmetric positive definite reduced mass matrix `Rᵀ M R` (6 × 6 for the 6-UPS) is
//! factored instead of the `M × M` Schur complement `S_c = G M⁻¹ Gᵀ` (18 × 18).

use nalgebra::SMatrix;

use crate::factor::FdFactors;
use crate::linalg;
use crate::model::Model;
use crate::plan::{invert_block, mass_times};
use crate::tasks::EquationsOfMotion;

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
