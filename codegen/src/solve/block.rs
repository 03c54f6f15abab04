//! One inverse-kinematics block `K = G[rows, cols]` on the tape: factored once, then solved
//! with as many right-hand sides as the solve needs, `K x = b` and `Kᵀ y = v`.
//!
//! Orders 1 to 3: the explicit inverse by the adjugate (branch-free, as the runtime's
//! `linalg::invert_fixed`), with the exact 1-norm condition number. Larger orders (a serial
//! arm's 6 × 6, a tripod's coupled 9 × 9): Gaussian elimination over the block's structural
//! non-zeros in a pivot order chosen by the generator (partial pivoting at the reference
//! state), checked at run time by the threshold test `|pivot| >= TAU max |column|`: where
//! another order would be needed the solve declines and the runtime's general path runs. Their
//! condition number comes from the factors' pivots (`‖K‖₁ max_c 1 / |u_cc|`), and from the
//! Hager/Higham estimate (four solves with the factors) only where that passes `SCREEN`.

use quote::{format_ident, quote};

use super::tape::{Tape, V};

/// Threshold partial pivoting: a pivot may be this much smaller than the largest entry of its
/// column (growth at most `(1 + 1/TAU)` per step); below it the solve declines.
pub const TAU: f64 = 0.1;

/// Blocks beyond order 3: below this condition number by their pivots (`‖K‖₁ max_c 1 /
/// |u_cc|`) the pivots' value is the block's condition number; above it, the Hager/Higham
/// estimate (four more solves). The runtime's thresholds are far above (`cond_max = 1e7`, the
/// elimination's 1e4), so a block the pivots underestimate by less than a factor of 10 is
/// decided as before; `tests/generated_kinematics.rs` measures the factor at random states.
pub const SCREEN: f64 = 1e3;

/// A factored block.
pub enum Factor {
    /// `inv[i][j] = (K⁻¹)_{ij}`: column `i` of the block, row `j`.
    Inverse(Vec<Vec<V>>),
    /// Elimination: row `piv[c]` is the pivot of step `c`; `l[r][c]` the multiplier of row `r`
    /// at step `c`; `u[c][c2]` the pivot row's entries (`c2 >= c`); `rp[c] = 1 / u[c][c]`.
    Lu {
        piv: Vec<usize>,
        l: Vec<Vec<V>>,
        u: Vec<Vec<V>>,
        rp: Vec<V>,
    },
}

/// Statements that return `None` from the emitted function when `cond` (an expression in
/// temporaries) does not hold; NaN fails it.
pub fn require(tape: &mut Tape, cond: proc_macro2::TokenStream) {
    tape.stmt(quote!(if !(#cond) { return None; }));
}

/// Factors `k[j][i]` (row `j`, column `i`, square); returns the factor and the block's 1-norm
/// condition number as a temporary. `None` when the block is structurally singular.
pub fn factor(tape: &mut Tape, k: &[Vec<V>], id: usize) -> Option<(Factor, V)> {
    let (f, norm_k, norm_inv) = factor_norms(tape, k, id)?;
    let cond = tape.mul(norm_k, norm_inv);
    Some((f, cond))
}

/// [`factor`], with `‖K‖₁` and `‖K⁻¹‖₁` (exact up to order 3, the estimate beyond) apart.
pub fn factor_norms(tape: &mut Tape, k: &[Vec<V>], id: usize) -> Option<(Factor, V, V)> {
    let n = k.len();
    let col = |i: usize| -> Vec<V> { (0..n).map(|j| k[j][i]).collect() };
    let cols: Vec<Vec<V>> = (0..n).map(col).collect();
    let norm_k = {
        let sums: Vec<V> = cols.iter().map(|c| tape.sum_abs(c)).collect();
        tape.max(&sums)
    };
    if n <= 3 {
        let inv = adjugate(tape, k)?;
        // ‖K⁻¹‖₁: the largest column sum, a column of K⁻¹ being one row j of inv.
        let sums: Vec<V> = (0..n)
            .map(|j| {
                let c: Vec<V> = (0..n).map(|i| inv[i][j]).collect();
                tape.sum_abs(&c)
            })
            .collect();
        let norm_inv = tape.max(&sums);
        return Some((Factor::Inverse(inv), norm_k, norm_inv));
    }
    let f = eliminate(tape, k)?;
    // From the factors themselves: `max_c 1 / |u_cc|` (the last pivot's is a lower bound of
    // `‖K⁻¹‖`: `1 / u_nn` is an entry of the permuted `K⁻¹`); the Hager/Higham estimate only
    // where the condition number it gives passes `SCREEN`.
    let Factor::Lu { rp, .. } = &f else {
        unreachable!("eliminate returns LU factors")
    };
    let pivots = tape.max_abs(rp);
    let screen = tape.mul(norm_k, pivots);
    let (ts, lim) = (
        Tape::tok(screen),
        proc_macro2::Literal::f64_suffixed(SCREEN),
    );
    let est = tape.branch(quote!(!(#ts <= #lim)), pivots, |t| {
        estimate_inverse_norm(t, &f, n, id)
    });
    Some((f, norm_k, est))
}

fn adjugate(tape: &mut Tape, k: &[Vec<V>]) -> Option<Vec<Vec<V>>> {
    let n = k.len();
    // cof[r][c]: the cofactor of entry (r, c).
    let cof: Vec<Vec<V>> = match n {
        1 => vec![vec![V::One]],
        2 => vec![
            vec![k[1][1], tape.neg(k[1][0])],
            vec![tape.neg(k[0][1]), k[0][0]],
        ],
        _ => (0..3)
            .map(|r| {
                (0..3)
                    .map(|c| {
                        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
                        let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
                        // The cyclic order carries the sign (-1)^(r+c).
                        tape.sum(&[(1.0, k[r1][c1], k[r2][c2]), (-1.0, k[r1][c2], k[r2][c1])])
                    })
                    .collect()
            })
            .collect(),
    };
    let terms: Vec<(f64, V, V)> = (0..n).map(|c| (1.0, k[0][c], cof[0][c])).collect();
    let det = tape.sum(&terms);
    if det.is_zero() {
        return None;
    }
    let td = Tape::tok(det);
    require(tape, quote!(f64::abs(#td) > 0.0 && f64::is_finite(#td)));
    let r = tape.recip(det);
    // (K⁻¹)_{ij} = cof_{ji} / det.
    Some(
        (0..n)
            .map(|i| (0..n).map(|j| tape.mul(cof[j][i], r)).collect())
            .collect(),
    )
}

/// Gaussian elimination of `k[j][i]` (row `j`, column `i`) over its structural non-zeros, the
/// pivot of each column the largest at the reference state, checked at run time by the
/// threshold test (`TAU`); `None` when the matrix is structurally singular.
pub fn eliminate(tape: &mut Tape, k: &[Vec<V>]) -> Option<Factor> {
    let n = k.len();
    let mut a: Vec<Vec<V>> = k.to_vec();
    let mut done = vec![false; n];
    let mut piv = Vec::with_capacity(n);
    let mut l = vec![vec![V::Zero; n]; n];
    let mut u = vec![vec![V::Zero; n]; n];
    let mut rp = Vec::with_capacity(n);
    for c in 0..n {
        let cands: Vec<usize> = (0..n).filter(|&r| !done[r] && !a[r][c].is_zero()).collect();
        let &p = cands.iter().max_by(|&&x, &&y| {
            tape.val(a[x][c])
                .abs()
                .total_cmp(&tape.val(a[y][c]).abs())
                .then(y.cmp(&x))
        })?;
        let others: Vec<usize> = cands.iter().copied().filter(|&r| r != p).collect();
        let tp = Tape::tok(a[p][c]);
        if others.is_empty() {
            require(tape, quote!(f64::abs(#tp) > 0.0));
        } else {
            let col: Vec<V> = others.iter().map(|&r| a[r][c]).collect();
            let cmax = Tape::tok(tape.max_abs(&col));
            require(
                tape,
                quote!(f64::abs(#tp) > 0.0 && f64::abs(#tp) >= #TAU * #cmax),
            );
        }
        done[p] = true;
        piv.push(p);
        let r_p = tape.recip(a[p][c]);
        rp.push(r_p);
        for c2 in c..n {
            u[c][c2] = a[p][c2];
        }
        let prow = a[p].clone();
        for &r in &others {
            let m = tape.mul(a[r][c], r_p);
            l[r][c] = m;
            for (v, &pv) in a[r].iter_mut().zip(&prow).skip(c + 1) {
                *v = tape.sum(&[(1.0, *v, V::One), (-1.0, m, pv)]);
            }
        }
    }
    Some(Factor::Lu { piv, l, u, rp })
}

/// `x = K⁻¹ b` (`b` by row, `x` by column).
pub fn solve(tape: &mut Tape, f: &Factor, b: &[V]) -> Vec<V> {
    match f {
        Factor::Inverse(inv) => inv
            .iter()
            .map(|row| {
                let t: Vec<(f64, V, V)> = row.iter().zip(b).map(|(&a, &bj)| (1.0, a, bj)).collect();
                tape.sum(&t)
            })
            .collect(),
        Factor::Lu { piv, l, u, rp } => {
            let n = b.len();
            let mut b = b.to_vec();
            for (c, &p) in piv.iter().enumerate() {
                for r in 0..n {
                    if !l[r][c].is_zero() {
                        b[r] = tape.sum(&[(1.0, b[r], V::One), (-1.0, l[r][c], b[p])]);
                    }
                }
            }
            let mut x = vec![V::Zero; n];
            for c in (0..n).rev() {
                let mut t = vec![(1.0, b[piv[c]], V::One)];
                t.extend((c + 1..n).map(|c2| (-1.0, u[c][c2], x[c2])));
                let s = tape.sum(&t);
                x[c] = tape.mul(s, rp[c]);
            }
            x
        }
    }
}

/// `y = K⁻ᵀ v` (`v` by column, `y` by row).
pub fn solve_t(tape: &mut Tape, f: &Factor, v: &[V]) -> Vec<V> {
    match f {
        Factor::Inverse(inv) => (0..v.len())
            .map(|j| {
                let t: Vec<(f64, V, V)> = inv
                    .iter()
                    .zip(v)
                    .map(|(row, &vi)| (1.0, row[j], vi))
                    .collect();
                tape.sum(&t)
            })
            .collect(),
        Factor::Lu { piv, l, u, rp } => {
            let n = v.len();
            // Uᵀ w = v, then y = Eᵀ w (E: the elimination's row operations).
            let mut w = vec![V::Zero; n];
            for c2 in 0..n {
                let mut t = vec![(1.0, v[c2], V::One)];
                t.extend((0..c2).map(|c| (-1.0, u[c][c2], w[c])));
                let s = tape.sum(&t);
                w[c2] = tape.mul(s, rp[c2]);
            }
            let mut y = vec![V::Zero; n];
            for c in 0..n {
                y[piv[c]] = w[c];
            }
            for c in (0..n).rev() {
                let mut t = vec![(1.0, y[piv[c]], V::One)];
                t.extend((0..n).map(|r| (-1.0, l[r][c], y[r])));
                y[piv[c]] = tape.sum(&t);
            }
            y
        }
    }
}

/// The Hager/Higham estimate of `‖K⁻¹‖₁` (one iteration, with Higham's alternating-sign
/// vector), in straight-line code: the argmax of the second step picks its unit vector by
/// value, not by branch.
fn estimate_inverse_norm(tape: &mut Tape, f: &Factor, n: usize, id: usize) -> V {
    let inv_n = tape.constant(1.0 / n as f64);
    let x = solve(tape, f, &vec![inv_n; n]);
    let est1 = tape.sum_abs(&x);
    let xi: Vec<V> = x
        .iter()
        .map(|&xc| {
            let t = Tape::tok(xc);
            tape.push(quote!(if #t >= 0.0 { 1.0 } else { -1.0 }), 1.0)
        })
        .collect();
    let z = solve_t(tape, f, &xi);
    let zs: Vec<_> = z.iter().map(|&v| Tape::tok(v)).collect();
    let (arr, jb) = (format_ident!("zabs{}", id), format_ident!("jmax{}", id));
    tape.stmt(quote! {
        let #arr = [#(f64::abs(#zs)),*];
        let mut #jb = 0usize;
        for (i, &v) in #arr.iter().enumerate() {
            if v > #arr[#jb] {
                #jb = i;
            }
        }
    });
    let e: Vec<V> = (0..n)
        .map(|j| tape.push(quote!(if #jb == #j { 1.0 } else { 0.0 }), 0.0))
        .collect();
    let x2 = solve(tape, f, &e);
    let est2 = tape.sum_abs(&x2);
    let alt_b: Vec<V> = (0..n)
        .map(|j| {
            let s = if j % 2 == 0 { 1.0 } else { -1.0 };
            tape.constant(s * (1.0 + j as f64 / (n - 1) as f64))
        })
        .collect();
    let x3 = solve(tape, f, &alt_b);
    let s3 = tape.sum_abs(&x3);
    let scale = tape.constant(2.0 / (3.0 * n as f64));
    let alt = tape.mul(s3, scale);
    tape.max(&[est1, est2, alt])
}

impl Factor {
    /// The temporaries the factor holds, each once, in a fixed order: what a second function
    /// needs to solve with it (stored by the first, read back by the second).
    pub fn values(&self) -> Vec<V> {
        let mut out: Vec<V> = Vec::new();
        let mut add = |v: V| {
            if matches!(v, V::T(_)) && !out.contains(&v) {
                out.push(v);
            }
        };
        match self {
            Factor::Inverse(inv) => inv.iter().flatten().copied().for_each(&mut add),
            Factor::Lu { l, u, rp, .. } => {
                l.iter().flatten().copied().for_each(&mut add);
                u.iter().flatten().copied().for_each(&mut add);
                rp.iter().copied().for_each(&mut add);
            }
        }
        out
    }

    /// The same factor with every temporary replaced by `f` of it.
    pub fn map(&self, f: &dyn Fn(V) -> V) -> Factor {
        let m = |vs: &Vec<Vec<V>>| -> Vec<Vec<V>> {
            vs.iter()
                .map(|r| r.iter().map(|&v| f(v)).collect())
                .collect()
        };
        match self {
            Factor::Inverse(inv) => Factor::Inverse(m(inv)),
            Factor::Lu { piv, l, u, rp } => Factor::Lu {
                piv: piv.clone(),
                l: m(l),
                u: m(u),
                rp: rp.iter().map(|&v| f(v)).collect(),
            },
        }
    }
}
