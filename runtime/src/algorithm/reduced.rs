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
//! 6-UPS) instead of the `M × M` Schur complement `S_c = G M⁻¹ Gᵀ` (18 × 18): that path is
//! [`forward_dynamics::reduced`](super::forward_dynamics). This module holds forward kinematics'
//! elimination, the same with `J_p` ([`fk_factor`]).

use nalgebra::SMatrix;

use crate::factor::{BMAX, FkFactors, WMAX};
use crate::linalg;
use crate::model::Model;
use crate::tasks::Robot;

/// The largest condition number of a block `K_b` for which forward kinematics eliminates onto
/// the outputs: the elimination's rounding grows with it (Newton corrects a slightly inexact
/// step; the dense LU takes over beyond).
pub(crate) const K_COND_MAX: f64 = 1e4;

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
/// of an order other than 2 and 3, not exactly one actuated column per block, an actuated
/// output, outputs other than one per block or more than [`WMAX`] or than the row width
/// `fk_width(N - M)`), a `K_b` is singular or worse conditioned than [`K_COND_MAX`] (the elimination's rounding grows with
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
    // The outputs are columns of `J_p`: none may be actuated.
    if z.iter()
        .any(|&j| model.actuator_of.get(j) != Some(&usize::MAX))
    {
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
