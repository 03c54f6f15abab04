//! Small dense linear algebra without allocation: LU with partial pivoting and Cholesky, in
//! place on a column-major `k × k` slice, and 1-norm condition estimates from the factors.
//!
//! Storage is column-major with leading dimension `k`: entry `(i, j)` is `a[i + j * k]`,
//! as in LAPACK and nalgebra. The factorisation is `P A = L U` with `L` unit lower triangular
//! (stored below the diagonal) and `U` upper triangular (on and above it); `piv[j]` is the row
//! swapped with row `j` at step `j` (LAPACK's `ipiv`, 0-based). The Cholesky factorisation of a
//! symmetric positive definite matrix is `A = L Lᵀ`, `L` lower triangular with a positive
//! diagonal, written over the lower triangle (the strict upper triangle is neither read nor
//! written).
//!
//! Every function checks its buffer sizes and returns an error instead of panicking; none
//! returns NaN for finite input.

use core::fmt;

/// Why a factorisation or solve failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LuError {
    /// Column `column` had no non-zero pivot candidate: the matrix is exactly singular.
    Singular {
        /// The elimination step that found only zeros.
        column: usize,
    },
    /// The matrix contains NaN or infinity, or a pivot overflowed.
    NonFinite,
    /// A buffer is shorter or longer than `k` requires, or a pivot index is out of range.
    Dimension,
    /// Cholesky only: the pivot of column `column` was not positive, so the matrix is not
    /// (numerically) positive definite.
    NotPositiveDefinite {
        /// The elimination step whose pivot `a_jj - Σ l_jp²` was `<= 0`.
        column: usize,
    },
}

impl fmt::Display for LuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LuError::Singular { column } => {
                write!(f, "matrix is singular (zero pivot column {column})")
            }
            LuError::NonFinite => write!(f, "matrix has a non-finite entry or pivot"),
            LuError::Dimension => write!(f, "buffer sizes do not match the matrix order"),
            LuError::NotPositiveDefinite { column } => {
                write!(f, "matrix is not positive definite (pivot column {column})")
            }
        }
    }
}

impl std::error::Error for LuError {}

fn check_square(a_len: usize, k: usize) -> Result<(), LuError> {
    match k.checked_mul(k) {
        Some(kk) if kk == a_len => Ok(()),
        _ => Err(LuError::Dimension),
    }
}

/// The 1-norm (largest absolute column sum) of the column-major `k × k` matrix `a`.
/// Returns NaN only if `a` holds NaN; call it before [`lu_factor`], which overwrites `a`.
pub fn norm1(a: &[f64], k: usize) -> Result<f64, LuError> {
    check_square(a.len(), k)?;
    let mut best = 0.0_f64;
    if k == 0 {
        return Ok(best);
    }
    for col in a.chunks_exact(k) {
        let s: f64 = col.iter().map(|v| v.abs()).sum();
        if s > best || s.is_nan() {
            best = s;
        }
    }
    Ok(best)
}

/// Factors the column-major `k × k` matrix `a` in place as `P A = L U` (partial pivoting).
///
/// `piv` must have length `k`. Errors: [`LuError::NonFinite`] if `a` holds NaN/inf or a pivot
/// overflows, [`LuError::Singular`] if a column has no non-zero pivot. A tiny but non-zero pivot
/// is not an error here: use [`cond1_estimate`] to judge the conditioning.
pub fn lu_factor(a: &mut [f64], k: usize, piv: &mut [usize]) -> Result<(), LuError> {
    check_square(a.len(), k)?;
    if piv.len() != k {
        return Err(LuError::Dimension);
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(LuError::NonFinite);
    }
    for j in 0..k {
        let cj = j * k;
        // Pivot search in column j, rows j..k.
        let mut p = j;
        let mut best = a[cj + j].abs();
        for i in j + 1..k {
            let v = a[cj + i].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if !best.is_finite() {
            return Err(LuError::NonFinite);
        }
        if best == 0.0 {
            return Err(LuError::Singular { column: j });
        }
        piv[j] = p;
        if p != j {
            for c in 0..k {
                a.swap(c * k + j, c * k + p);
            }
        }
        let d = a[cj + j];
        for i in j + 1..k {
            a[cj + i] /= d;
        }
        // Rank-one update of the trailing block.
        let (left, right) = a.split_at_mut(cj + k);
        let lcol = &left[cj..cj + k];
        for col in right.chunks_exact_mut(k) {
            let ajc = col[j];
            if ajc != 0.0 {
                for i in j + 1..k {
                    col[i] -= lcol[i] * ajc;
                }
            }
        }
    }
    Ok(())
}

fn check_factors(lu: &[f64], k: usize, piv: &[usize], b: &[f64]) -> Result<(), LuError> {
    check_square(lu.len(), k)?;
    if piv.len() != k || b.len() != k || piv.iter().any(|&p| p >= k) {
        return Err(LuError::Dimension);
    }
    Ok(())
}

/// Solves `A x = b` in place (`b` becomes `x`) with the factors from [`lu_factor`].
pub fn lu_solve(lu: &[f64], k: usize, piv: &[usize], b: &mut [f64]) -> Result<(), LuError> {
    check_factors(lu, k, piv, b)?;
    for (j, &p) in piv.iter().enumerate() {
        b.swap(j, p);
    }
    // L y = P b (unit lower triangular), column oriented.
    for j in 0..k {
        let bj = b[j];
        if bj != 0.0 {
            let col = &lu[j * k..j * k + k];
            for i in j + 1..k {
                b[i] -= col[i] * bj;
            }
        }
    }
    // U x = y.
    for j in (0..k).rev() {
        let col = &lu[j * k..j * k + k];
        b[j] /= col[j];
        let bj = b[j];
        if bj != 0.0 {
            for i in 0..j {
                b[i] -= col[i] * bj;
            }
        }
    }
    Ok(())
}

/// Solves `Aᵀ x = b` in place with the factors from [`lu_factor`].
pub fn lu_solve_transpose(
    lu: &[f64],
    k: usize,
    piv: &[usize],
    b: &mut [f64],
) -> Result<(), LuError> {
    check_factors(lu, k, piv, b)?;
    // Uᵀ w = b (lower triangular): w_j = (b_j - Σ_{i<j} U_ij w_i) / U_jj.
    for j in 0..k {
        let col = &lu[j * k..j * k + k];
        let mut s = b[j];
        for i in 0..j {
            s -= col[i] * b[i];
        }
        b[j] = s / col[j];
    }
    // Lᵀ z = w (unit upper triangular): z_j = w_j - Σ_{i>j} L_ij z_i.
    for j in (0..k).rev() {
        let col = &lu[j * k..j * k + k];
        let mut s = b[j];
        for i in j + 1..k {
            s -= col[i] * b[i];
        }
        b[j] = s;
    }
    // x = Pᵀ z: undo the row swaps in reverse order.
    for (j, &p) in piv.iter().enumerate().rev() {
        b.swap(j, p);
    }
    Ok(())
}

/// Estimates the 1-norm condition number `‖A‖₁ ‖A⁻¹‖₁` from the LU factors of `A` and its
/// norm `anorm` (from [`norm1`], taken before factoring).
///
/// `‖A⁻¹‖₁` comes from Hager's estimator as refined by Higham (LAPACK `dlacon`): at most five
/// power-like steps, each one solve with `A` and one with `Aᵀ`, plus Higham's alternating test
/// vector; the result is a lower bound of the true value, almost always within a factor of 3.
/// Cost: about ten triangular solve pairs, `O(k²)`. `work` must hold at least `2 k` values.
///
/// Returns `+inf` when the estimate overflows, never NaN for factors of a finite matrix.
pub fn cond1_estimate(
    lu: &[f64],
    k: usize,
    piv: &[usize],
    anorm: f64,
    work: &mut [f64],
) -> Result<f64, LuError> {
    check_square(lu.len(), k)?;
    if piv.len() != k || work.len() < 2 * k {
        return Err(LuError::Dimension);
    }
    let inv = inverse_norm1_estimate(
        k,
        work,
        |b| lu_solve(lu, k, piv, b),
        |b| lu_solve_transpose(lu, k, piv, b),
    )?;
    Ok(condition(anorm, inv))
}

/// Factors the symmetric positive definite column-major `k × k` matrix `a` in place as
/// `A = L Lᵀ` (Cholesky), reading and writing only its lower triangle.
///
/// Errors: [`LuError::NonFinite`] if the lower triangle holds NaN/inf,
/// [`LuError::NotPositiveDefinite`] if a pivot is not positive. A tiny positive pivot is not an
/// error here: use [`cholesky_cond1_estimate`] to judge the conditioning.
pub fn cholesky_factor(a: &mut [f64], k: usize) -> Result<(), LuError> {
    check_square(a.len(), k)?;
    for j in 0..k {
        if a[j * k + j..(j + 1) * k].iter().any(|v| !v.is_finite()) {
            return Err(LuError::NonFinite);
        }
    }
    for j in 0..k {
        // Left-looking: column j of L from the columns 0..j.
        let (left, right) = a.split_at_mut(j * k);
        let col = &mut right[..k];
        for p in 0..j {
            let lp = &left[p * k..p * k + k];
            let ljp = lp[j];
            if ljp != 0.0 {
                for i in j..k {
                    col[i] -= lp[i] * ljp;
                }
            }
        }
        let d = col[j];
        if d.is_nan() || d <= 0.0 {
            return Err(LuError::NotPositiveDefinite { column: j });
        }
        let ljj = d.sqrt();
        if !ljj.is_finite() {
            return Err(LuError::NonFinite);
        }
        col[j] = ljj;
        for v in &mut col[j + 1..] {
            *v /= ljj;
        }
    }
    Ok(())
}

fn check_cholesky(l: &[f64], k: usize, b: &[f64]) -> Result<(), LuError> {
    check_square(l.len(), k)?;
    if b.len() != k {
        return Err(LuError::Dimension);
    }
    Ok(())
}

/// Solves `L y = b` in place (`b` becomes `y`) with the factor from [`cholesky_factor`].
pub fn cholesky_forward(l: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    check_cholesky(l, k, b)?;
    for j in 0..k {
        let col = &l[j * k..j * k + k];
        b[j] /= col[j];
        let bj = b[j];
        if bj != 0.0 {
            for i in j + 1..k {
                b[i] -= col[i] * bj;
            }
        }
    }
    Ok(())
}

/// Solves `Lᵀ x = y` in place (`b` holds `y`, becomes `x`) with the factor from
/// [`cholesky_factor`].
pub fn cholesky_backward(l: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    check_cholesky(l, k, b)?;
    for j in (0..k).rev() {
        let col = &l[j * k..j * k + k];
        let mut s = b[j];
        for i in j + 1..k {
            s -= col[i] * b[i];
        }
        b[j] = s / col[j];
    }
    Ok(())
}

/// Solves `A x = b` in place with the Cholesky factor `L` of `A` (forward, then backward).
pub fn cholesky_solve(l: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    cholesky_forward(l, k, b)?;
    cholesky_backward(l, k, b)
}

/// Estimates the 1-norm condition number of a symmetric positive definite `A` from its
/// Cholesky factor and its norm `anorm` (from [`norm1`], taken before factoring): the same
/// Hager/Higham estimator as [`cond1_estimate`], with `A⁻ᵀ = A⁻¹`. `work` must hold at least
/// `2 k` values. Returns `+inf` when the estimate overflows, never NaN for a finite factor.
pub fn cholesky_cond1_estimate(
    l: &[f64],
    k: usize,
    anorm: f64,
    work: &mut [f64],
) -> Result<f64, LuError> {
    check_square(l.len(), k)?;
    if work.len() < 2 * k {
        return Err(LuError::Dimension);
    }
    let inv = inverse_norm1_estimate(
        k,
        work,
        |b| cholesky_solve(l, k, b),
        |b| cholesky_solve(l, k, b),
    )?;
    Ok(condition(anorm, inv))
}

/// `anorm * inv`, with `+inf` for NaN (`0 * inf`).
fn condition(anorm: f64, inv: f64) -> f64 {
    let cond = anorm * inv;
    if cond.is_nan() { f64::INFINITY } else { cond }
}

/// Hager/Higham estimate of `‖A⁻¹‖₁` (LAPACK `dlacon`) from solves with `A` and `Aᵀ`;
/// `+inf` when it overflows. `work.len() >= 2 k` (checked by the callers).
fn inverse_norm1_estimate(
    k: usize,
    work: &mut [f64],
    mut solve: impl FnMut(&mut [f64]) -> Result<(), LuError>,
    mut solve_transpose: impl FnMut(&mut [f64]) -> Result<(), LuError>,
) -> Result<f64, LuError> {
    if k == 0 {
        return Ok(0.0);
    }
    if work.len() < 2 * k {
        return Err(LuError::Dimension);
    }
    let (x, rest) = work.split_at_mut(k);
    let z = &mut rest[..k];
    let kf = k as f64;

    // Hager: maximise ‖A⁻¹ x‖₁ over the unit 1-norm ball, starting from x = (1/k, …, 1/k).
    x.fill(1.0 / kf);
    let mut est = 0.0_f64;
    let mut jprev = 0;
    for iter in 0..5 {
        solve(x)?; // x := y = A⁻¹ x
        let ny: f64 = x.iter().map(|v| v.abs()).sum();
        if !ny.is_finite() {
            return Ok(f64::INFINITY);
        }
        if iter > 0 && ny <= est {
            break;
        }
        est = ny;
        for (zi, &yi) in z.iter_mut().zip(x.iter()) {
            *zi = if yi >= 0.0 { 1.0 } else { -1.0 };
        }
        solve_transpose(z)?; // z = A⁻ᵀ sign(y)
        let mut j = 0;
        let mut zmax = -1.0;
        for (i, &zi) in z.iter().enumerate() {
            if zi.abs() > zmax {
                zmax = zi.abs();
                j = i;
            }
        }
        if !zmax.is_finite() {
            return Ok(f64::INFINITY);
        }
        // zᵀx for the x that produced y: uniform on the first pass, e_jprev afterwards.
        let ztx = if iter == 0 {
            z.iter().sum::<f64>() / kf
        } else {
            z[jprev]
        };
        if zmax <= ztx {
            break;
        }
        x.fill(0.0);
        x[j] = 1.0;
        jprev = j;
    }
    // Higham's safeguard: x_i = (-1)^i (1 + i/(k-1)), estimate 2‖A⁻¹x‖₁ / (3k).
    for (i, xi) in x.iter_mut().enumerate() {
        let mag = if k > 1 {
            1.0 + i as f64 / (kf - 1.0)
        } else {
            1.0
        };
        *xi = if i % 2 == 0 { mag } else { -mag };
    }
    solve(x)?;
    let alt = 2.0 * x.iter().map(|v| v.abs()).sum::<f64>() / (3.0 * kf);
    Ok(if alt.is_finite() {
        est.max(alt)
    } else {
        f64::INFINITY
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    struct XorShift(u64);
    impl XorShift {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    fn random(k: usize, rng: &mut XorShift) -> DMatrix<f64> {
        DMatrix::from_fn(k, k, |_, _| rng.next())
    }

    fn exact_cond1(a: &DMatrix<f64>) -> f64 {
        let n1 = |m: &DMatrix<f64>| {
            m.column_iter()
                .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
                .fold(0.0, f64::max)
        };
        n1(a) * n1(&a.clone().try_inverse().unwrap())
    }

    #[test]
    fn solve_matches_nalgebra() {
        let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
        for k in 1..=20 {
            for _ in 0..10 {
                let a = random(k, &mut rng);
                let b: Vec<f64> = (0..k).map(|_| rng.next()).collect();
                let mut lu: Vec<f64> = a.as_slice().to_vec();
                let mut piv = vec![0; k];
                lu_factor(&mut lu, k, &mut piv).unwrap();

                let mut x = b.clone();
                lu_solve(&lu, k, &piv, &mut x).unwrap();
                let bv = nalgebra::DVector::from_vec(b.clone());
                let xr = a.clone().lu().solve(&bv).unwrap();
                let scale = xr.amax().max(1.0);
                for i in 0..k {
                    assert!((x[i] - xr[i]).abs() <= 1e-9 * scale, "k={k} x[{i}]");
                }

                let mut xt = b.clone();
                lu_solve_transpose(&lu, k, &piv, &mut xt).unwrap();
                let xtr = a.transpose().lu().solve(&bv).unwrap();
                let scale = xtr.amax().max(1.0);
                for i in 0..k {
                    assert!((xt[i] - xtr[i]).abs() <= 1e-9 * scale, "k={k} xt[{i}]");
                }
            }
        }
    }

    #[test]
    fn factors_reproduce_pa() {
        let mut rng = XorShift(12345);
        let k = 7;
        let a = random(k, &mut rng);
        let mut lu: Vec<f64> = a.as_slice().to_vec();
        let mut piv = vec![0; k];
        lu_factor(&mut lu, k, &mut piv).unwrap();
        let f = DMatrix::from_column_slice(k, k, &lu);
        let l = DMatrix::from_fn(k, k, |i, j| match i.cmp(&j) {
            core::cmp::Ordering::Greater => f[(i, j)],
            core::cmp::Ordering::Equal => 1.0,
            core::cmp::Ordering::Less => 0.0,
        });
        let u = DMatrix::from_fn(k, k, |i, j| if i <= j { f[(i, j)] } else { 0.0 });
        let mut pa = a.clone();
        for (j, &p) in piv.iter().enumerate() {
            pa.swap_rows(j, p);
        }
        assert!((l * u - pa).amax() < 1e-14);
    }

    #[test]
    fn cond_estimate_is_a_tight_lower_bound() {
        let mut rng = XorShift(42);
        let mut worst_ratio = 1.0_f64;
        for k in 1..=16 {
            for trial in 0..20 {
                let mut a = random(k, &mut rng);
                if trial % 4 == 0 && k > 1 {
                    // Make it ill-conditioned: nearly dependent last column.
                    let c0 = a.column(0).clone_owned();
                    a.set_column(k - 1, &(c0 * 3.0 + a.column(k - 1) * 1e-7));
                }
                let exact = exact_cond1(&a);
                let mut lu: Vec<f64> = a.as_slice().to_vec();
                let anorm = norm1(&lu, k).unwrap();
                let mut piv = vec![0; k];
                lu_factor(&mut lu, k, &mut piv).unwrap();
                let mut work = vec![0.0; 2 * k];
                let est = cond1_estimate(&lu, k, &piv, anorm, &mut work).unwrap();
                // A lower bound up to rounding, which grows like cond * eps.
                let slack = 1.0 + 1e-8 + 1e-14 * exact;
                assert!(est <= exact * slack, "k={k}: est {est:e} > exact {exact:e}");
                assert!(est >= exact / 10.0, "k={k}: est {est:e} << exact {exact:e}");
                worst_ratio = worst_ratio.max(exact / est);
            }
        }
        assert!(
            worst_ratio < 10.0,
            "worst underestimate ratio {worst_ratio}"
        );
    }

    #[test]
    fn singular_and_non_finite_are_errors() {
        let k = 3;
        // Rank 2: third column = first + second.
        let mut a = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 5.0, 7.0, 9.0];
        let mut piv = [0; 3];
        // Exactly singular in exact arithmetic; in floating point either a zero pivot or a
        // huge condition estimate, never NaN.
        let anorm = norm1(&a, k).unwrap();
        match lu_factor(&mut a, k, &mut piv) {
            Err(LuError::Singular { .. }) => {}
            Ok(()) => {
                let mut work = [0.0; 6];
                let c = cond1_estimate(&a, k, &piv, anorm, &mut work).unwrap();
                assert!(c > 1e15, "cond {c:e}");
            }
            Err(e) => panic!("unexpected {e}"),
        }

        let mut z = vec![0.0; 4];
        let mut piv2 = [0; 2];
        assert_eq!(
            lu_factor(&mut z, 2, &mut piv2),
            Err(LuError::Singular { column: 0 })
        );

        let mut n = vec![1.0, f64::NAN, 0.0, 1.0];
        assert_eq!(lu_factor(&mut n, 2, &mut piv2), Err(LuError::NonFinite));
        let mut inf = vec![1.0, 0.0, 0.0, f64::INFINITY];
        assert_eq!(lu_factor(&mut inf, 2, &mut piv2), Err(LuError::NonFinite));

        // Overflowing elimination: the second pivot becomes 1e308 + 1e308 = inf.
        let mut big = vec![1.0, -1.0, 1e308, 1e308];
        assert_eq!(lu_factor(&mut big, 2, &mut piv2), Err(LuError::NonFinite));

        assert_eq!(
            lu_factor(&mut [0.0; 3], 2, &mut piv2),
            Err(LuError::Dimension)
        );
        let mut b = [1.0, 2.0];
        assert_eq!(
            lu_solve(&[1.0, 0.0, 0.0, 1.0], 2, &[0, 7], &mut b),
            Err(LuError::Dimension)
        );
    }

    #[test]
    fn cholesky_solves_and_estimates_like_dense() {
        let mut rng = XorShift(0xC401_E5C1);
        for k in 1..=18 {
            for trial in 0..10 {
                // SPD: Bᵀ B + shift I; a small shift makes it ill-conditioned.
                let b = random(k, &mut rng);
                let shift = if trial % 3 == 0 { 1e-6 } else { 0.5 };
                let a = b.transpose() * &b + DMatrix::identity(k, k) * shift;
                let rhs: Vec<f64> = (0..k).map(|_| rng.next()).collect();
                let mut l: Vec<f64> = a.as_slice().to_vec();
                let anorm = norm1(&l, k).unwrap();
                cholesky_factor(&mut l, k).unwrap();
                let lm = DMatrix::from_fn(k, k, |i, j| if i >= j { l[i + j * k] } else { 0.0 });
                assert!((&lm * lm.transpose() - &a).amax() < 1e-12 * a.amax());

                let mut x = rhs.clone();
                cholesky_solve(&l, k, &mut x).unwrap();
                let xr = a
                    .clone()
                    .lu()
                    .solve(&nalgebra::DVector::from_vec(rhs.clone()))
                    .unwrap();
                let exact = exact_cond1(&a);
                let scale = xr.amax().max(1.0);
                for i in 0..k {
                    assert!(
                        (x[i] - xr[i]).abs() <= 1e-15 * exact * scale + 1e-12 * scale,
                        "k={k} x[{i}]"
                    );
                }
                let mut work = vec![0.0; 2 * k];
                let est = cholesky_cond1_estimate(&l, k, anorm, &mut work).unwrap();
                let slack = 1.0 + 1e-8 + 1e-14 * exact;
                assert!(est <= exact * slack, "k={k}: est {est:e} > exact {exact:e}");
                assert!(est >= exact / 10.0, "k={k}: est {est:e} << exact {exact:e}");
            }
        }
    }

    #[test]
    fn cholesky_rejects_indefinite_and_non_finite() {
        // Indefinite: eigenvalues 3 and -1.
        let mut a = [1.0, 2.0, 2.0, 1.0];
        assert_eq!(
            cholesky_factor(&mut a, 2),
            Err(LuError::NotPositiveDefinite { column: 1 })
        );
        let mut z = [0.0; 4];
        assert_eq!(
            cholesky_factor(&mut z, 2),
            Err(LuError::NotPositiveDefinite { column: 0 })
        );
        let mut n = [1.0, f64::NAN, f64::NAN, 1.0];
        assert_eq!(cholesky_factor(&mut n, 2), Err(LuError::NonFinite));
        // The strict upper triangle is never read.
        let mut u = [4.0, 2.0, f64::NAN, 5.0];
        cholesky_factor(&mut u, 2).unwrap();
        assert_eq!((u[0], u[1], u[3]), (2.0, 1.0, 2.0));
        assert!(u[2].is_nan());
        assert_eq!(cholesky_factor(&mut [0.0; 3], 2), Err(LuError::Dimension));
        let mut b = [1.0];
        assert_eq!(
            cholesky_solve(&[1.0, 0.0, 0.0, 1.0], 2, &mut b),
            Err(LuError::Dimension)
        );
    }

    #[test]
    fn order_zero_and_one() {
        let mut piv: [usize; 0] = [];
        lu_factor(&mut [], 0, &mut piv).unwrap();
        let mut work: [f64; 0] = [];
        assert_eq!(cond1_estimate(&[], 0, &piv, 0.0, &mut work), Ok(0.0));

        let mut a = [4.0];
        let mut p = [0];
        lu_factor(&mut a, 1, &mut p).unwrap();
        let mut b = [2.0];
        lu_solve(&a, 1, &p, &mut b).unwrap();
        assert_eq!(b, [0.5]);
        let mut w = [0.0; 2];
        assert_eq!(cond1_estimate(&a, 1, &p, 4.0, &mut w), Ok(1.0));
    }
}
