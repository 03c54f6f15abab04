//! Forward dynamics by the Schur complement `S_c = G M⁻¹ Gᵀ` on the block-diagonal mass matrix:
//! the path near a serial singularity and [`forward_dynamics_schur`](super::forward_dynamics_schur)
//! (steps 1 to 5 of the [module](super) documentation), with `S_c` solved by its structure
//! (Woodbury) when a bound certifies it, else by a dense Cholesky.

use nalgebra::SMatrix;

use crate::algorithm::input::check_finite;
use crate::error::SolverError;
use crate::factor::{CondMode, factor_spd, lu_error};
use crate::linalg::dot4 as dot;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::EquationsOfMotion;

const WHAT_SC: &str = "S_c = G M⁻¹ Gᵀ";

const SC_SOURCE: &str = "G or M (kernel output)";

/// The largest condition number of a block `D_k` for which forward dynamics solves with `S_c`
/// by its structure (the Woodbury formula, see `woodbury`), whose rounding error grows with it;
/// beyond, the dense Cholesky of `S_c`. At the 6-UPS's regular poses the blocks stay below 100.
const D_COND_MAX: f64 = 1e4;

/// The buffers of the Schur complement, in `data.ws` (`factors.lu`, `factors.work` and
/// `dynamics`).
pub(super) struct Scratch<'a, const N: usize, const M: usize> {
    /// `S_c` (M × M) when it is factored densely.
    pub sc: &'a mut [[f64; M]; M],
    /// The condition estimator's work space; `work[0]` the Woodbury solve's scratch.
    pub work: &'a mut [[f64; M]; 2],
    /// The Cholesky factors of the blocks of `M`, packed.
    pub lu_n: &'a mut [[f64; N]; N],
    /// `Z = L⁻¹ Gᵀ`, as its N rows of length M.
    pub z: &'a mut [[f64; N]; M],
    /// `E = D⁻¹ W` of the structured solve.
    pub wood: &'a mut [[f64; M]; linalg::SMALL],
}

/// Forward dynamics by the Schur complement `S_c = G M⁻¹ Gᵀ` on the block-diagonal `M`
/// (`blocks`, checked; steps 1 to 5 of the [module](super) documentation): `force` is `F` on
/// entry and `Ẍ` on return, `lambda` the multipliers; `scratch` is work space; `exact` asks for
/// the exact condition number of `S_c` after a structured solve (else its bound). Returns
/// `(cond_blocks, cond)` for the report.
#[allow(clippy::too_many_arguments)]
pub(super) fn solve<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    blocks: &[&[usize]],
    g: &SMatrix<f64, M, N>,
    mass: &SMatrix<f64, N, N>,
    gamma_stab: &[f64],
    ws: Scratch<'_, N, M>,
    force: &mut [f64; N],
    scratch: &mut [f64; N],
    lambda: &mut [f64; M],
    exact: bool,
) -> Result<(f64, f64), SolverError> {
    let Scratch {
        sc,
        work,
        lu_n,
        z,
        wood,
    } = ws;
    let s = model.structure();
    // 1. Cholesky of every block of M, packed one after the other in ws.dynamics.lu_n; for the 1 × 1
    //    blocks also 1 / l_jj in inv_l (1 for the coordinates of larger blocks).
    let factors = lu_n.as_flattened_mut();
    let mut inv_l = [1.0; N];
    let (mut pmin, mut pmax) = (f64::INFINITY, 0.0_f64);
    let mut off = 0;
    for (b, blk) in blocks.iter().enumerate() {
        let kb = blk.len();
        // Σ kb² <= (Σ kb)² = N² (blocks checked).
        let l = &mut factors[off..off + kb * kb];
        if let ([l0], &[j]) = (&mut *l, *blk) {
            // 1 × 1 (finite: checked by dynamics_terms).
            let m = mass.data.0[j][j];
            if m.is_nan() || m <= 0.0 {
                return Err(SolverError::NotPositiveDefinite {
                    what: "mass block",
                    block: Some(b),
                    column: 0,
                });
            }
            *l0 = m.sqrt();
            inv_l[j] = 1.0 / *l0;
            let p = m;
            pmin = pmin.min(p);
            pmax = pmax.max(p);
            off += 1;
            continue;
        }
        for (c, &jc) in blk.iter().enumerate() {
            for (r, &jr) in blk.iter().enumerate() {
                l[r + c * kb] = mass.data.0[jc][jr];
            }
        }
        linalg::cholesky_factor(l, kb).map_err(|e| match e {
            LuError::NotPositiveDefinite { column } => SolverError::NotPositiveDefinite {
                what: "mass block",
                block: Some(b),
                column,
            },
            _ => SolverError::NonFinite {
                what: "M (mass kernel output)",
            },
        })?;
        for i in 0..kb {
            let p = l[i + i * kb] * l[i + i * kb];
            pmin = pmin.min(p);
            pmax = pmax.max(p);
        }
        off += kb * kb;
    }
    let cond_blocks = if pmin > 0.0 {
        pmax / pmin
    } else {
        f64::INFINITY
    };
    let cond_max = model.options.cond_max;

    // 2. Z = L⁻¹ Gᵀ (N × M), kept as its N rows z_j (length M): for a 1 × 1 block of M,
    //    z_j = G[:, j] / l_jj; for a larger block b, the forward substitution with L_b across
    //    the block's columns of G. And z_F = L⁻¹ F.
    let (zr, _) = z.as_flattened_mut().as_chunks_mut::<M>();
    for ((zj, gj), &il) in zr.iter_mut().zip(&g.data.0).zip(&inv_l) {
        for (a, &b) in zj.iter_mut().zip(gj) {
            *a = b * il;
        }
    }
    let mut off = 0;
    for blk in blocks.iter() {
        let kb = blk.len();
        let l = &factors[off..off + kb * kb];
        off += kb * kb;
        if kb == 1 {
            continue;
        }
        for (r, &jr) in blk.iter().enumerate() {
            let Some(mut zj) = g.data.0.get(jr).copied() else {
                continue; // unreachable: blocks checked
            };
            for (p, &jp) in blk[..r].iter().enumerate() {
                let lrp = l[r + p * kb];
                if let Some(zp) = zr.get(jp) {
                    for (a, &b) in zj.iter_mut().zip(zp) {
                        *a -= lrp * b;
                    }
                }
            }
            let inv = 1.0 / l[r + r * kb];
            for a in zj.iter_mut() {
                *a *= inv;
            }
            if let Some(dst) = zr.get_mut(jr) {
                *dst = zj;
            }
        }
    }
    apply_blocks(factors, blocks, &inv_l, force, scratch, Pass::Forward);
    // (An overflow in Z shows up in S_c, which factor_spd checks.)
    check_finite("L⁻¹ F", force)?;
    let (zr, _) = z.as_flattened().as_chunks::<M>();

    // The rows of Z are sparse: z_j of a mass block whose coordinates all belong to one
    // inverse-kinematics block k is zero outside the constraint rows of k (so is a column of
    // G, `Model::ik_block_of`). support[j] = k for those, usize::MAX ("all rows") otherwise
    // (for the 6-UPS: the 18 leg coordinates are sparse, the 6 outputs dense).
    let mut support = [usize::MAX; N];
    for blk in blocks.iter() {
        let first = blk.first().map_or(usize::MAX, |&j| model.ik_block_of[j]);
        if blk.iter().all(|&j| model.ik_block_of[j] == first) {
            for &j in blk.iter() {
                support[j] = first;
            }
        }
    }
    let rows_of =
        |j: usize| -> Option<&'static [usize]> { s.ik_blocks.get(support[j]).map(|ik| ik.rows) };

    // 3. The right-hand side Zᵀ z_F - gamma_stab.
    lambda.fill(0.0);
    for (j, (zj, &fj)) in zr.iter().zip(force.iter()).enumerate() {
        match rows_of(j) {
            Some(rows) => {
                for &i in rows {
                    lambda[i] += zj[i] * fj;
                }
            }
            None => {
                for (l, &zi) in lambda.iter_mut().zip(zj) {
                    *l += zi * fj;
                }
            }
        }
    }
    for (l, &gs) in lambda.iter_mut().zip(gamma_stab.iter()) {
        *l -= gs;
    }

    // 4. lambda = S_c⁻¹ (Zᵀ z_F - gamma_stab): by the structure of S_c when its bound certifies
    //    it, else by the dense Cholesky of S_c.
    let structured = woodbury(
        model,
        zr,
        &support,
        lambda,
        wood,
        &mut work[0],
        cond_max,
        exact,
    );
    let cond = match structured {
        Some(bound) => bound,
        None => {
            // S_c = Zᵀ Z = Σ_j z_j z_jᵀ (lower triangle, then mirrored): a k × k update for a
            // sparse row, M × M for a dense one.
            let sc = sc.as_flattened_mut();
            sc.fill(0.0);
            for (j, zj) in zr.iter().enumerate() {
                match rows_of(j) {
                    Some(rows) => {
                        for (a, &ra) in rows.iter().enumerate() {
                            for &rb in &rows[..=a] {
                                let (r, c) = (ra.max(rb), ra.min(rb));
                                sc[r + c * M] += zj[ra] * zj[rb];
                            }
                        }
                    }
                    None => {
                        for (c, &zc) in zj.iter().enumerate() {
                            if zc != 0.0 {
                                let col = &mut sc[c * M + c..c * M + M];
                                for (sv, &zrc) in col.iter_mut().zip(&zj[c..]) {
                                    *sv += zrc * zc;
                                }
                            }
                        }
                    }
                }
            }
            for c in 0..M {
                for r in c + 1..M {
                    sc[c + r * M] = sc[r + c * M];
                }
            }
            let cond = factor_spd(
                sc,
                M,
                work.as_flattened_mut(),
                cond_max,
                CondMode::Report,
                WHAT_SC,
                SC_SOURCE,
            )?;
            linalg::cholesky_solve(sc, M, lambda)
                .map_err(|e| lu_error(e, WHAT_SC, None, M, SC_SOURCE))?;
            cond
        }
    };
    check_finite("lambda", lambda)?;

    // 5. Ẍ = L⁻ᵀ (z_F - Z lambda), in ws.dynamics.v (z_j · lambda over z_j's rows).
    for (j, (zj, fj)) in zr.iter().zip(force.iter_mut()).enumerate() {
        *fj -= match rows_of(j) {
            Some(rows) => rows.iter().map(|&i| zj[i] * lambda[i]).sum::<f64>(),
            None => dot(zj, lambda),
        };
    }
    apply_blocks(factors, blocks, &inv_l, force, scratch, Pass::Backward);
    Ok((cond_blocks, cond))
}

/// Solves `S_c lambda = rhs` (in place in `lambda`) through the structure of
/// `S_c = Zᵀ Z = D + W Wᵀ`: `D = Σ` over the sparse rows `z_j` (`support[j]` an
/// inverse-kinematics block) is block diagonal with the blocks `D_k` on the rows of block `k`,
/// and `W` (M × w) has the dense rows as columns (the outputs, `w = 6` for the 6-UPS). By the
/// Sherman–Morrison–Woodbury identity
///
/// ```text
/// S_c⁻¹ = D⁻¹ - E C⁻¹ Eᵀ,   E = D⁻¹ W,   C = I + Wᵀ D⁻¹ W   (w × w)
/// ```
///
/// so a solve costs the small inverses `D_k⁻¹`, `C⁻¹` (explicit, order at most 4 and
/// `linalg::SMALL`) and a few products with `W` and `E`, instead of the Cholesky factorisation
/// of the dense M × M `S_c` and a condition estimate.
///
/// Returns the exact 1-norm condition number of `S_c` if `exact` (formed column by column from
/// the same structure: `O(M² w)`), else a rigorous upper bound of it; or `None` (nothing
/// solved; the caller factors `S_c` densely) when the structure does not apply (blocks of
/// different orders or of order above 4, `w` above `linalg::SMALL`, no dense rows), a `D_k` is
/// singular or worse conditioned than
/// `cond_max`, or the bound exceeds `cond_max / 2` (`S_c` is not certified: the dense path's
/// estimate decides). The bound: `‖S_c‖₁ <= max_i (Σ_l |D_li| + Σ_a |W_ia| ‖w_a‖₁)`, and, since
/// `S_c ⪰ D` and both terms of `S_c⁻¹` are positive semidefinite,
/// `‖S_c⁻¹‖₁ <= min(√M ‖D⁻¹‖₂, ‖D⁻¹‖₁ + ‖E‖₁ ‖C⁻¹‖₁ ‖E‖_∞)` with `‖D⁻¹‖₂ <= max_k ‖D_k⁻¹‖₁`.
/// On the 6-UPS it is 5 to 6 times the exact condition number (about 12). The blocks `D_k` must
/// also have condition numbers at most `D_COND_MAX`: the formula's rounding error grows with
/// them, while that of the dense Cholesky grows only with the condition number of `S_c`.
#[allow(clippy::too_many_arguments)]
fn woodbury<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    zr: &[[f64; M]],
    support: &[usize; N],
    lambda: &mut [f64; M],
    e: &mut [[f64; M]; linalg::SMALL],
    y: &mut [f64; M],
    cond_max: f64,
    exact: bool,
) -> Option<f64> {
    let ik = model.structure().ik_blocks;
    by_ik_order!(K, ik, B =>
        woodbury_fixed::<K, N, M, B>(model, zr, support, lambda, e, y, cond_max, exact),
        _ => None)
}

/// [`woodbury`] for inverse-kinematics blocks all of order `B`.
#[allow(clippy::too_many_arguments)]
fn woodbury_fixed<K: EquationsOfMotion<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    zr: &[[f64; M]],
    support: &[usize; N],
    lambda: &mut [f64; M],
    e: &mut [[f64; M]; linalg::SMALL],
    y: &mut [f64; M],
    cond_max: f64,
    exact: bool,
) -> Option<f64> {
    let ik = model.structure().ik_blocks;
    // The dense rows: the columns of W.
    let mut dense = [0_usize; linalg::SMALL];
    let mut w = 0;
    for (j, &k) in support.iter().enumerate() {
        if k == usize::MAX {
            *dense.get_mut(w)? = j;
            w += 1;
        }
    }
    if w == 0 {
        return None;
    }
    let mut wcols = [[0.0; M]; linalg::SMALL];
    for (wc, &j) in wcols.iter_mut().zip(&dense[..w]) {
        *wc = *zr.get(j)?;
    }
    let wcols = &wcols[..w];

    // D_k⁻¹ (at most M blocks), and ‖S_c‖₁'s D part per row.
    let mut rows = [[0_usize; B]; M];
    let mut dinv = [[[0.0; B]; B]; M];
    let nb = ik.len();
    if nb > M {
        return None;
    }
    for (r, blk) in rows.iter_mut().zip(ik) {
        *r = blk.rows.try_into().ok()?;
    }
    let mut d = [[[0.0; B]; B]; M];
    for (zj, &k) in zr.iter().zip(support) {
        let (Some(dk), Some(rk)) = (d.get_mut(k), rows.get(k)) else {
            continue; // dense
        };
        let zk: [f64; B] = core::array::from_fn(|i| zj[rk[i]]);
        for (dc, &zc) in dk.iter_mut().zip(&zk) {
            for (v, &zr_) in dc.iter_mut().zip(&zk) {
                *v += zr_ * zc;
            }
        }
    }
    let mut colsum = [0.0; M];
    let mut inv_d = 0.0_f64;
    for ((dk, rk), di) in d.iter().zip(&rows).zip(dinv.iter_mut()).take(nb) {
        for (dc, &rc) in dk.iter().zip(rk) {
            colsum[rc] = dc.iter().map(|v| v.abs()).sum();
        }
        let anorm = linalg::norm1_fixed(dk);
        let inv = linalg::invert_fixed(dk, di).ok()?;
        let cond = anorm * inv;
        if cond.is_nan() || cond > D_COND_MAX.min(cond_max) {
            return None;
        }
        inv_d = inv_d.max(inv);
    }
    let apply_dinv = |v: &[f64; M], out: &mut [f64; M]| {
        for (di, rk) in dinv.iter().zip(&rows).take(nb) {
            let vk: [f64; B] = core::array::from_fn(|i| v[rk[i]]);
            let t = linalg::mul_fixed(di, &vk);
            for (&tr, &rr) in t.iter().zip(rk) {
                out[rr] = tr;
            }
        }
    };

    // E = D⁻¹ W, column a in e[a]; C = I + Wᵀ E.
    for (ea, wa) in e.iter_mut().zip(wcols) {
        apply_dinv(wa, ea);
    }
    let mut c = [0.0; linalg::SMALL * linalg::SMALL];
    let c = &mut c[..w * w];
    // (Symmetric: Wᵀ D⁻¹ W; one triangle computed, mirrored.)
    for (a, wa) in wcols.iter().enumerate() {
        for (b, eb) in e.iter().enumerate().take(w).skip(a) {
            let v = dot(wa, eb);
            c[a + b * w] = v;
            c[b + a * w] = v;
        }
        c[a + a * w] += 1.0;
    }
    let inv_c = linalg::invert_small(c, w).ok()?;

    // The bound on the condition number.
    let mut wnorm = [0.0; linalg::SMALL];
    for (n, wa) in wnorm.iter_mut().zip(wcols) {
        *n = wa.iter().map(|x| x.abs()).sum();
    }
    let mut norm_s = colsum;
    for (wa, &wn) in wcols.iter().zip(&wnorm) {
        for (t, &x) in norm_s.iter_mut().zip(wa) {
            *t += x.abs() * wn;
        }
    }
    let norm_s = norm_s.iter().fold(0.0_f64, |m, &x| m.max(x));
    let mut e1 = 0.0_f64;
    let mut einf = [0.0; M];
    for ea in e.iter().take(w) {
        e1 = e1.max(ea.iter().map(|x| x.abs()).sum());
        for (r, &x) in einf.iter_mut().zip(ea) {
            *r += x.abs();
        }
    }
    let einf = einf.iter().fold(0.0_f64, |m, &x| m.max(x));
    let inv_s = ((M as f64).sqrt() * inv_d).min(inv_d + e1 * inv_c * einf);
    let bound = norm_s * inv_s;
    if bound.is_nan() || bound > 0.5 * cond_max {
        return None;
    }

    // lambda = D⁻¹ r - E C⁻¹ Wᵀ D⁻¹ r.
    apply_dinv(lambda, y);
    let mut t = [0.0; linalg::SMALL];
    for (ta, wa) in t.iter_mut().zip(wcols) {
        *ta = dot(wa, y);
    }
    let mut u = [0.0; linalg::SMALL];
    for (b, &tb) in t.iter().enumerate().take(w) {
        for (a, ua) in u.iter_mut().enumerate().take(w) {
            *ua += c[a + b * w] * tb;
        }
    }
    *lambda = *y;
    for (ea, &ua) in e.iter().zip(&u).take(w) {
        for (l, &x) in lambda.iter_mut().zip(ea) {
            *l -= x * ua;
        }
    }
    if !exact {
        return Some(bound);
    }

    // The exact condition number ‖S_c‖₁ ‖S_c⁻¹‖₁ for the report, column by column:
    // S_c e_i = D e_i + W (row i of W), S_c⁻¹ e_i = D⁻¹ e_i - G (row i of E), G = E C⁻¹.
    let mut gm = [[0.0; M]; linalg::SMALL];
    for (a, ga) in gm.iter_mut().enumerate().take(w) {
        for (b, eb) in e.iter().enumerate().take(w) {
            axpy(ga, eb, c[b + a * w]);
        }
    }
    let (mut norm, mut norm_inv) = (0.0_f64, 0.0_f64);
    for ((rk, dk), di) in rows.iter().zip(&d).zip(&dinv).take(nb) {
        for (pos, &i) in rk.iter().enumerate() {
            let mut sc = [0.0; M];
            let mut si = [0.0; M];
            for ((wa, ea), ga) in wcols.iter().zip(e.iter()).zip(&gm) {
                axpy(&mut sc, wa, wa[i]);
                axpy(&mut si, ga, -ea[i]);
            }
            for ((&r, &dv), &dvi) in rk.iter().zip(&dk[pos]).zip(&di[pos]) {
                sc[r] += dv;
                si[r] += dvi;
            }
            norm = norm.max(sc.iter().map(|x| x.abs()).sum());
            norm_inv = norm_inv.max(si.iter().map(|x| x.abs()).sum());
        }
    }
    let cond = norm * norm_inv;
    if cond.is_nan() {
        return Some(bound);
    }
    // Rounding could put it a hair above the bound; the bound is the certified value.
    Some(cond.min(bound))
}

/// `y += a x` over arrays of a compile-time length (one vectorised loop).
#[inline(always)]
fn axpy<const L: usize>(y: &mut [f64; L], x: &[f64; L], a: f64) {
    for i in 0..L {
        y[i] += a * x[i];
    }
}

#[derive(Clone, Copy)]
enum Pass {
    /// `v := L⁻¹ v`.
    Forward,
    /// `v := L⁻ᵀ v`.
    Backward,
}

/// Applies `L⁻¹` or `L⁻ᵀ` of the block-diagonal Cholesky factor packed in `factors` to `v`
/// (blocks checked; factors finite and with a positive diagonal, so the triangular solves
/// cannot fail): the 1 × 1 blocks by one vectorised product with `inv_l` (their `1 / l_jj`, and
/// 1 for the coordinates of larger blocks), then the larger blocks.
fn apply_blocks<const N: usize>(
    factors: &[f64],
    blocks: &[&[usize]],
    inv_l: &[f64; N],
    v: &mut [f64; N],
    scratch: &mut [f64; N],
    pass: Pass,
) {
    for (x, &il) in v.iter_mut().zip(inv_l) {
        *x *= il;
    }
    let mut off = 0;
    for blk in blocks {
        let kb = blk.len();
        let l = &factors[off..off + kb * kb];
        off += kb * kb;
        if kb == 1 {
            continue;
        }
        let t = &mut scratch[..kb];
        for (ti, &j) in t.iter_mut().zip(blk.iter()) {
            *ti = v[j];
        }
        if t.iter().all(|&x| x == 0.0) {
            continue;
        }
        // Dimensions match by construction; an error cannot occur.
        let _ = match pass {
            Pass::Forward => linalg::cholesky_forward(l, kb, t),
            Pass::Backward => linalg::cholesky_backward(l, kb, t),
        };
        for (&ti, &j) in t.iter().zip(blk.iter()) {
            v[j] = ti;
        }
    }
}
