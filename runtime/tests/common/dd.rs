//! Double-double arithmetic (a value is `hi + lo`, |lo| <= ulp(hi) / 2, about 106 bits) and a
//! dense LU with partial pivoting in it: the independent reference of the forward-dynamics
//! stress tests. The error-free transformations are Knuth's two-sum and the fused
//! multiply-add two-product; the operations are the "sloppy" ones of Bailey's QD library
//! (relative error a few 2⁻¹⁰⁶ per operation), ample for a reference 10¹⁵ times more
//! accurate than the f64 solve it checks at the conditioning of the tests.

#![allow(dead_code)]

use core::ops::{Add, Div, Mul, Neg, Sub};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dd {
    pub hi: f64,
    pub lo: f64,
}

#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

#[inline]
fn quick_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

#[inline]
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

impl Dd {
    pub const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };
    pub fn from(x: f64) -> Dd {
        Dd { hi: x, lo: 0.0 }
    }
    pub fn abs(self) -> Dd {
        if self.hi < 0.0 { -self } else { self }
    }
    pub fn to_f64(self) -> f64 {
        self.hi + self.lo
    }
}

impl Add for Dd {
    type Output = Dd;
    fn add(self, b: Dd) -> Dd {
        let (s, e) = two_sum(self.hi, b.hi);
        let (t, f) = two_sum(self.lo, b.lo);
        let (s, e) = quick_two_sum(s, e + t);
        let (hi, lo) = quick_two_sum(s, e + f);
        Dd { hi, lo }
    }
}

impl Neg for Dd {
    type Output = Dd;
    fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }
}

impl Sub for Dd {
    type Output = Dd;
    fn sub(self, b: Dd) -> Dd {
        self + (-b)
    }
}

impl Mul for Dd {
    type Output = Dd;
    fn mul(self, b: Dd) -> Dd {
        let (p, e) = two_prod(self.hi, b.hi);
        let e = e + (self.hi * b.lo + self.lo * b.hi);
        let (hi, lo) = quick_two_sum(p, e);
        Dd { hi, lo }
    }
}

impl Div for Dd {
    type Output = Dd;
    fn div(self, b: Dd) -> Dd {
        // Long division: q1 = a / b, r = a - q1 b, q2 = r / b, r -= q2 b, q3 = r / b.
        let q1 = self.hi / b.hi;
        let r = self - b * Dd::from(q1);
        let q2 = r.hi / b.hi;
        let r = r - b * Dd::from(q2);
        let q3 = r.hi / b.hi;
        let (hi, lo) = quick_two_sum(q1, q2);
        Dd { hi, lo } + Dd::from(q3)
    }
}

/// Solves the dense `k × k` system `a x = b` (row-major `a[i][j]`) in double-double by LU with
/// partial pivoting; `None` for an exactly zero pivot.
pub fn solve(mut a: Vec<Vec<Dd>>, mut b: Vec<Dd>) -> Option<Vec<Dd>> {
    let k = b.len();
    for c in 0..k {
        let p =
            (c..k).max_by(|&i, &j| a[i][c].abs().to_f64().total_cmp(&a[j][c].abs().to_f64()))?;
        if a[p][c].hi == 0.0 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..k {
            let f = a[r][c] / a[c][c];
            if f.hi == 0.0 {
                continue;
            }
            let pivot_row = a[c].clone();
            for (arj, &v) in a[r][c..k].iter_mut().zip(&pivot_row[c..k]) {
                *arj = *arj - f * v;
            }
            let v = b[c];
            b[r] = b[r] - f * v;
        }
    }
    let mut x = vec![Dd::ZERO; k];
    for r in (0..k).rev() {
        let mut s = b[r];
        for j in r + 1..k {
            s = s - a[r][j] * x[j];
        }
        x[r] = s / a[r][r];
    }
    Some(x)
}

/// The saddle-point system `[M Gᵀ; G 0] [x; l] = [f; gamma]` in double-double for f64 data
/// (`mass[c][r]`, `g[c][r]` column-major as the kernels write them), with only the constraint
/// rows `rows` of `G` (all of them for a regular problem; an independent subset for redundant
/// constraints). Returns `(x, l)` rounded to f64 (`l` has `rows.len()` entries) and the
/// normwise condition number of `x` as a function of the data,
/// `‖(K⁻¹)[x, :]‖∞ (‖K‖∞ ‖z‖∞ + ‖b‖∞) / ‖x‖∞`, from the double-double inverse.
pub fn saddle_point<const N: usize, const M: usize>(
    mass: &[[f64; N]; N],
    g: &[[f64; M]; N],
    f: &[f64; N],
    gamma: &[f64; M],
    rows: &[usize],
) -> Option<(Vec<f64>, Vec<f64>, f64)> {
    let m = rows.len();
    let k = N + m;
    let mut a = vec![vec![Dd::ZERO; k]; k];
    for r in 0..N {
        for c in 0..N {
            a[r][c] = Dd::from(mass[c][r]);
        }
    }
    for (ii, &i) in rows.iter().enumerate() {
        for c in 0..N {
            a[N + ii][c] = Dd::from(g[c][i]);
            a[c][N + ii] = Dd::from(g[c][i]);
        }
    }
    let mut b = vec![Dd::ZERO; k];
    for r in 0..N {
        b[r] = Dd::from(f[r]);
    }
    for (ii, &i) in rows.iter().enumerate() {
        b[N + ii] = Dd::from(gamma[i]);
    }
    let z = solve(a.clone(), b.clone())?;
    // (K⁻¹)[x, :] row sums, column by column of the inverse.
    let mut inv_rows = vec![0.0_f64; N];
    for c in 0..k {
        let mut e = vec![Dd::ZERO; k];
        e[c] = Dd::from(1.0);
        let col = solve(a.clone(), e)?;
        for r in 0..N {
            inv_rows[r] += col[r].abs().to_f64();
        }
    }
    let inf = |v: &[f64]| v.iter().fold(0.0_f64, |m, &x| m.max(x.abs()));
    let knorm = a
        .iter()
        .map(|row| row.iter().map(|v| v.hi.abs()).sum::<f64>())
        .fold(0.0_f64, f64::max);
    let zf: Vec<f64> = z.iter().map(|v| v.to_f64()).collect();
    let bf: Vec<f64> = b.iter().map(|v| v.to_f64()).collect();
    let x = zf[..N].to_vec();
    let l = zf[N..].to_vec();
    let kappa = inf(&inv_rows) * (knorm * inf(&zf) + inf(&bf)) / inf(&x);
    Some((x, l, kappa))
}
