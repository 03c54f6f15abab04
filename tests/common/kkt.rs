//! An independent reference for constrained forward dynamics: the dense saddle-point system
//!
//! ```text
//! [ M  Gᵀ ] [ Ẍ      ]   [ F     ]
//! [ G  0  ] [ lambda ] = [ gamma ]
//! ```
//!
//! from the kernels' `M`, `G`, `F = psi + S U` and `gamma` (taken as exact data), solved in
//! double-double arithmetic (about 106 bits: every sum and product compensated with
//! `two_sum`/`fma`, Dekker and Knuth) by an LU factorisation with partial pivoting, then rounded
//! to f64. It shares no code with the runtime: no Schur complement, no factor of `M`, no
//! structure. With the saddle-point matrix's condition number `kappa`, the reference's own
//! error is about `kappa * 1e-32` relative, far below the f64 rounding it is compared with
//! (the f64 rounding of the exact solution itself, half an ulp, is what is left).

/// A double-double number `hi + lo`, `|lo| <= ulp(hi) / 2`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dd {
    pub hi: f64,
    pub lo: f64,
}

/// `a + b` exactly, as `s + e` (Knuth's two-sum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// `a + b` exactly when `|a| >= |b|` (Dekker's fast two-sum).
fn fast_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

/// `a * b` exactly, as `p + e` (the fused multiply-add gives the error).
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

impl Dd {
    pub const ZERO: Dd = Dd { hi: 0.0, lo: 0.0 };

    pub fn from_f64(x: f64) -> Dd {
        Dd { hi: x, lo: 0.0 }
    }

    /// The nearest f64.
    pub fn to_f64(self) -> f64 {
        self.hi + self.lo
    }

    pub fn abs(self) -> Dd {
        if self.hi < 0.0 { self.neg() } else { self }
    }

    pub fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }

    pub fn add(self, b: Dd) -> Dd {
        let (s, e) = two_sum(self.hi, b.hi);
        let (t, f) = two_sum(self.lo, b.lo);
        let (s, e) = fast_two_sum(s, e + t);
        let (hi, lo) = fast_two_sum(s, e + f);
        Dd { hi, lo }
    }

    pub fn sub(self, b: Dd) -> Dd {
        self.add(b.neg())
    }

    pub fn mul(self, b: Dd) -> Dd {
        let (p, e) = two_prod(self.hi, b.hi);
        let e = e + (self.hi * b.lo + self.lo * b.hi);
        let (hi, lo) = fast_two_sum(p, e);
        Dd { hi, lo }
    }

    pub fn div(self, b: Dd) -> Dd {
        // Long division: q1 = a / b in f64, then the remainder's quotient, twice.
        let q1 = self.hi / b.hi;
        let r = self.sub(b.mul(Dd::from_f64(q1)));
        let q2 = r.hi / b.hi;
        let r = r.sub(b.mul(Dd::from_f64(q2)));
        let q3 = r.hi / b.hi;
        let (hi, lo) = fast_two_sum(q1, q2);
        Dd { hi, lo }.add(Dd::from_f64(q3))
    }
}

/// Solves the square system `a x = b` (`a` row-major, `n × n`) in double-double by LU with
/// partial pivoting; `None` when a pivot is exactly zero (a singular matrix).
pub fn lu_solve_dd(a: &[Vec<f64>], b: &[f64]) -> Option<Vec<Dd>> {
    let n = b.len();
    assert!(
        a.len() == n && a.iter().all(|r| r.len() == n),
        "lu_solve_dd: a is not n × n"
    );
    let mut a: Vec<Vec<Dd>> = a
        .iter()
        .map(|r| r.iter().map(|&v| Dd::from_f64(v)).collect())
        .collect();
    let mut b: Vec<Dd> = b.iter().map(|&v| Dd::from_f64(v)).collect();
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| a[i][k].abs().to_f64().total_cmp(&a[j][k].abs().to_f64()))
            .unwrap();
        if a[p][k].hi == 0.0 {
            return None;
        }
        a.swap(k, p);
        b.swap(k, p);
        for i in k + 1..n {
            let l = a[i][k].div(a[k][k]);
            if l.hi == 0.0 {
                continue;
            }
            let pivot_row = a[k].clone();
            for (aij, &akj) in a[i][k + 1..n].iter_mut().zip(&pivot_row[k + 1..n]) {
                *aij = aij.sub(l.mul(akj));
            }
            b[i] = b[i].sub(l.mul(b[k]));
        }
    }
    let mut x = vec![Dd::ZERO; n];
    for i in (0..n).rev() {
        let mut s = b[i];
        for j in i + 1..n {
            s = s.sub(a[i][j].mul(x[j]));
        }
        x[i] = s.div(a[i][i]);
    }
    Some(x)
}

/// The saddle-point matrix `[M Gᵀ; G 0]` (row-major, `(n + m)²`) from `mass` (`n × n`,
/// row-major) and `g` (`m × n`, row-major).
pub fn kkt_matrix(mass: &[Vec<f64>], g: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (n, m) = (mass.len(), g.len());
    let mut k = vec![vec![0.0; n + m]; n + m];
    for i in 0..n {
        k[i][..n].copy_from_slice(&mass[i]);
    }
    for (c, row) in g.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            k[n + c][j] = v;
            k[j][n + c] = v;
        }
    }
    k
}

/// The reference forward dynamics: `(Ẍ, lambda)` of `M Ẍ + Gᵀ lambda = force`,
/// `G Ẍ = gamma` (dense, row-major `mass` and `g`), solved in double-double and rounded to f64;
/// `None` for a singular saddle-point matrix.
pub fn forward_dynamics_dd(
    mass: &[Vec<f64>],
    g: &[Vec<f64>],
    force: &[f64],
    gamma: &[f64],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = mass.len();
    let rhs: Vec<f64> = force.iter().chain(gamma).copied().collect();
    let x = lu_solve_dd(&kkt_matrix(mass, g), &rhs)?;
    let x: Vec<f64> = x.iter().map(|v| v.to_f64()).collect();
    Some((x[..n].to_vec(), x[n..].to_vec()))
}

/// [`forward_dynamics_dd`] on the kernels' layout: `mass` as `[[f64; N]; N]` (symmetric),
/// `g` column-major `[[f64; M]; N]` (`g[j][c] = ∂f_c/∂X_j`).
pub fn forward_dynamics_dd_kernels<const N: usize, const M: usize>(
    mass: &[[f64; N]; N],
    g: &[[f64; M]; N],
    force: &[f64; N],
    gamma: &[f64; M],
) -> Option<([f64; N], [f64; M])> {
    let mass: Vec<Vec<f64>> = (0..N)
        .map(|i| (0..N).map(|j| mass[j][i]).collect())
        .collect();
    let g: Vec<Vec<f64>> = (0..M).map(|c| (0..N).map(|j| g[j][c]).collect()).collect();
    let (xddot, lambda) = forward_dynamics_dd(&mass, &g, force, gamma)?;
    Some((xddot.try_into().unwrap(), lambda.try_into().unwrap()))
}

/// The 1-norm condition number of the square matrix `a` (row-major), from its inverse computed
/// in double-double (column by column): what the reference's and the solvers' rounding scale
/// with. `None` when singular.
pub fn cond1(a: &[Vec<f64>]) -> Option<f64> {
    let n = a.len();
    let norm1 = |cols: &dyn Fn(usize) -> Vec<f64>| {
        (0..n)
            .map(|j| cols(j).iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0_f64, f64::max)
    };
    let na = norm1(&|j| (0..n).map(|i| a[i][j]).collect());
    let mut inv_cols = Vec::with_capacity(n);
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        let x = lu_solve_dd(a, &e)?;
        inv_cols.push(x.iter().map(|v| v.to_f64()).collect::<Vec<f64>>());
    }
    let ninv = norm1(&|j| inv_cols[j].clone());
    Some(na * ninv)
}
