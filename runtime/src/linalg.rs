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
        for v in &mut a[cj + j + 1..cj + k] {
            *v /= d;
        }
        // Rank-one update of the trailing block.
        let (left, right) = a.split_at_mut(cj + k);
        let lcol = &left[cj + j + 1..cj + k];
        for col in right.chunks_exact_mut(k) {
            let ajc = col[j];
            if ajc != 0.0 {
                for (c, &l) in col[j + 1..].iter_mut().zip(lcol) {
                    *c -= l * ajc;
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
    for (j, col) in lu.chunks_exact(k.max(1)).enumerate().take(k) {
        let (head, tail) = b.split_at_mut(j + 1);
        let bj = head[j];
        if bj != 0.0 {
            for (bi, &lij) in tail.iter_mut().zip(&col[j + 1..]) {
                *bi -= lij * bj;
            }
        }
    }
    // U x = y.
    for (j, col) in lu.chunks_exact(k.max(1)).enumerate().take(k).rev() {
        let (head, tail) = b.split_at_mut(j);
        let bj = tail[0] / col[j];
        tail[0] = bj;
        if bj != 0.0 {
            for (bi, &uij) in head.iter_mut().zip(&col[..j]) {
                *bi -= uij * bj;
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
    for (j, col) in lu.chunks_exact(k.max(1)).enumerate().take(k) {
        let s = b[j] - dot4(&col[..j], &b[..j]);
        b[j] = s / col[j];
    }
    // Lᵀ z = w (unit upper triangular): z_j = w_j - Σ_{i>j} L_ij z_i.
    for (j, col) in lu.chunks_exact(k.max(1)).enumerate().take(k).rev() {
        b[j] -= dot4(&col[j + 1..], &b[j + 1..]);
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
        let col = &mut right[j..k];
        for lp in left.chunks_exact(k) {
            let lp = &lp[j..];
            let ljp = lp[0];
            if ljp != 0.0 {
                for (c, &l) in col.iter_mut().zip(lp) {
                    *c -= l * ljp;
                }
            }
        }
        let d = col[0];
        if d.is_nan() || d <= 0.0 {
            return Err(LuError::NotPositiveDefinite { column: j });
        }
        let ljj = d.sqrt();
        if !ljj.is_finite() {
            return Err(LuError::NonFinite);
        }
        col[0] = ljj;
        let inv = 1.0 / ljj;
        for v in &mut col[1..] {
            *v *= inv;
        }
    }
    Ok(())
}

/// `Σ a_i b_i` over the common length, with four partial sums (independent additions instead
/// of one dependency chain); the rounding differs from a left-to-right sum only in the order of
/// the additions.
#[inline]
pub(crate) fn dot4(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ac, ar) = a.as_chunks::<4>();
    let (bc, br) = b.as_chunks::<4>();
    let mut acc = [0.0; 4];
    for (x, y) in ac.iter().zip(bc) {
        for ((s, &xi), &yi) in acc.iter_mut().zip(x).zip(y) {
            *s += xi * yi;
        }
    }
    let mut tail = 0.0;
    for (&x, &y) in ar.iter().zip(br) {
        tail += x * y;
    }
    (acc[0] + acc[2]) + (acc[1] + acc[3]) + tail
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
    for (j, col) in l.chunks_exact(k.max(1)).enumerate().take(k) {
        let (head, tail) = b.split_at_mut(j + 1);
        let bj = head[j] / col[j];
        head[j] = bj;
        if bj != 0.0 {
            for (bi, &lij) in tail.iter_mut().zip(&col[j + 1..]) {
                *bi -= lij * bj;
            }
        }
    }
    Ok(())
}

/// Solves `Lᵀ x = y` in place (`b` holds `y`, becomes `x`) with the factor from
/// [`cholesky_factor`].
pub fn cholesky_backward(l: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    check_cholesky(l, k, b)?;
    for (j, col) in l.chunks_exact(k.max(1)).enumerate().take(k).rev() {
        let s = b[j] - dot4(&col[j + 1..], &b[j + 1..]);
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

/// Hager/Higham estimate of `‖B‖₁` (LAPACK `dlacon`) for a `k × k` operator `B` given by its
/// products: `apply(x)` sets `x := B x`, `apply_transpose(x)` sets `x := Bᵀ x`. A lower bound of
/// the true value (up to rounding), almost always within a factor 3; at most eleven products.
/// `work.len() >= 2 k`. `+inf` when it overflows.
pub fn norm1_estimate(
    k: usize,
    work: &mut [f64],
    apply: impl FnMut(&mut [f64]) -> Result<(), LuError>,
    apply_transpose: impl FnMut(&mut [f64]) -> Result<(), LuError>,
) -> Result<f64, LuError> {
    inverse_norm1_estimate(k, work, apply, apply_transpose)
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

/// The width of the solvers' small fixed-size buffers (rows over the outputs in forward
/// kinematics' elimination of robots with up to 8 outputs, the structured Schur solve's dense
/// rows), and the order up to which a Cholesky factor's condition is estimated rather than
/// bounded. Explicit inverses go further: [`INVERT_MAX`].
pub const SMALL: usize = 8;

/// Largest order that [`invert_small`] inverts explicitly: beyond [`SMALL`], Gauss–Jordan up to
/// 16 × 16 still costs about what an LU factorisation and a condition estimate cost (the
/// estimate alone is some ten triangular solves), and gives the exact condition number with no
/// estimate at all: a 3-RPS tripod's 9 × 9 or a hybrid machine's 14 × 14 inverse-kinematics
/// block.
pub const INVERT_MAX: usize = 16;

/// Inverts the column-major `k × k` matrix `a` in place (`k <= INVERT_MAX`) and returns `‖A⁻¹‖₁`;
/// with `‖A‖₁` from [`norm1`] (taken before) their product is the exact 1-norm condition number
/// up to rounding, not an estimate.
///
/// Orders 1 to 3 use the adjugate (`A⁻¹ = adj(A) / det A`, branch-free; for these orders its
/// normwise error is of the order of `cond(A) ε`, like that of a solve with the LU factors);
/// orders 4 to 16 Gauss–Jordan elimination with partial pivoting (forward error also of the
/// order of `cond(A) ε`).
///
/// Errors: [`LuError::Dimension`] for `k > INVERT_MAX` or a buffer of the wrong size,
/// [`LuError::NonFinite`] for NaN/inf in `a`, [`LuError::Singular`] when the determinant (or an
/// LU pivot) is exactly zero or the inverse overflows. The contents of `a` are unspecified after
/// an error.
pub fn invert_small(a: &mut [f64], k: usize) -> Result<f64, LuError> {
    check_square(a.len(), k)?;
    if a.iter().any(|v| !v.is_finite()) {
        return Err(LuError::NonFinite);
    }
    fn fixed<const K: usize>(a: &mut [f64]) -> Result<f64, LuError> {
        let m: &mut [[f64; K]; K] = a
            .as_chunks_mut::<K>()
            .0
            .try_into()
            .map_err(|_| LuError::Dimension)?;
        let src = *m;
        invert_fixed(&src, m)
    }
    match k {
        0 => Ok(0.0),
        1 => fixed::<1>(a),
        2 => fixed::<2>(a),
        3 => fixed::<3>(a),
        4 => fixed::<4>(a),
        5 => fixed::<5>(a),
        6 => fixed::<6>(a),
        7 => fixed::<7>(a),
        8 => fixed::<8>(a),
        9 => fixed::<9>(a),
        10 => fixed::<10>(a),
        11 => fixed::<11>(a),
        12 => fixed::<12>(a),
        13 => fixed::<13>(a),
        14 => fixed::<14>(a),
        15 => fixed::<15>(a),
        16 => fixed::<16>(a),
        _ => Err(LuError::Dimension),
    }
}

/// [`invert_small`] for a compile-time order `K <= INVERT_MAX` on arrays (`a[c][r]`, column-major,
/// finite: the callers check `‖A‖₁` first), fully unrolled: writes `A⁻¹` into `inv` and returns
/// `‖A⁻¹‖₁`. Errors: [`LuError::Singular`] (zero determinant or pivot, overflowing inverse),
/// [`LuError::NonFinite`] for a determinant that overflows (orders 2 and 3),
/// [`LuError::Dimension`] for `K > INVERT_MAX`.
#[inline]
pub fn invert_fixed<const K: usize>(
    a: &[[f64; K]; K],
    inv: &mut [[f64; K]; K],
) -> Result<f64, LuError> {
    let x = a.as_flattened();
    let out = inv.as_flattened_mut();
    match K {
        0 => return Ok(0.0),
        1 => {
            if x[0] == 0.0 {
                return Err(LuError::Singular { column: 0 });
            }
            out[0] = 1.0 / x[0];
        }
        2 => {
            let (a11, a21, a12, a22) = (x[0], x[1], x[2], x[3]);
            let det = a11 * a22 - a12 * a21;
            if !det.is_finite() {
                // Entries so large that the determinant overflows (a pose of 1e300): not a
                // singular matrix but one f64 cannot handle.
                return Err(LuError::NonFinite);
            }
            if det == 0.0 {
                return Err(LuError::Singular { column: 1 });
            }
            let r = 1.0 / det;
            out[0] = a22 * r;
            out[1] = -a21 * r;
            out[2] = -a12 * r;
            out[3] = a11 * r;
        }
        3 => {
            let (a11, a21, a31) = (x[0], x[1], x[2]);
            let (a12, a22, a32) = (x[3], x[4], x[5]);
            let (a13, a23, a33) = (x[6], x[7], x[8]);
            // Cofactors C_ij; (A⁻¹)_ij = C_ji / det.
            let c11 = a22 * a33 - a23 * a32;
            let c21 = a13 * a32 - a12 * a33;
            let c31 = a12 * a23 - a13 * a22;
            let det = a11 * c11 + a21 * c21 + a31 * c31;
            if !det.is_finite() {
                // Entries so large that the determinant overflows (a pose of 1e300): not a
                // singular matrix but one f64 cannot handle.
                return Err(LuError::NonFinite);
            }
            if det == 0.0 {
                return Err(LuError::Singular { column: 2 });
            }
            let c12 = a23 * a31 - a21 * a33;
            let c22 = a11 * a33 - a13 * a31;
            let c32 = a13 * a21 - a11 * a23;
            let c13 = a21 * a32 - a22 * a31;
            let c23 = a12 * a31 - a11 * a32;
            let c33 = a11 * a22 - a12 * a21;
            let r = 1.0 / det;
            out[0] = c11 * r;
            out[1] = c12 * r;
            out[2] = c13 * r;
            out[3] = c21 * r;
            out[4] = c22 * r;
            out[5] = c23 * r;
            out[6] = c31 * r;
            out[7] = c32 * r;
            out[8] = c33 * r;
        }
        4..=INVERT_MAX => gauss_jordan(a, inv)?,
        _ => return Err(LuError::Dimension),
    }
    let n = norm1_fixed(inv);
    if !n.is_finite() {
        // Overflow (or 0 * inf) in the inverse of a nearly singular matrix.
        return Err(LuError::Singular {
            column: K.saturating_sub(1),
        });
    }
    Ok(n)
}

/// `A⁻¹` by Gauss–Jordan elimination with partial pivoting, on the rows of `A` (contiguous
/// arrays, so each row operation is one vectorisable loop of length `K`); `K` small.
#[inline]
fn gauss_jordan<const K: usize>(a: &[[f64; K]; K], inv: &mut [[f64; K]; K]) -> Result<(), LuError> {
    // m: the rows of A; e: the rows of the identity, becoming the rows of A⁻¹.
    let mut m = [[0.0; K]; K];
    for (c, col) in a.iter().enumerate() {
        for (row, &v) in m.iter_mut().zip(col) {
            row[c] = v;
        }
    }
    let mut e = [[0.0; K]; K];
    for (i, row) in e.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for j in 0..K {
        let mut p = j;
        let mut best = m[j][j].abs();
        for (i, row) in m.iter().enumerate().skip(j + 1) {
            let v = row[j].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if best == 0.0 {
            return Err(LuError::Singular { column: j });
        }
        m.swap(j, p);
        e.swap(j, p);
        let d = 1.0 / m[j][j];
        for (x, y) in m[j].iter_mut().zip(e[j].iter_mut()) {
            *x *= d;
            *y *= d;
        }
        let (mj, ej) = (m[j], e[j]);
        for (i, (mi, ei)) in m.iter_mut().zip(e.iter_mut()).enumerate() {
            let f = mi[j];
            if i != j && f != 0.0 {
                for (x, &y) in mi.iter_mut().zip(&mj) {
                    *x -= f * y;
                }
                for (x, &y) in ei.iter_mut().zip(&ej) {
                    *x -= f * y;
                }
            }
        }
    }
    for (c, col) in inv.iter_mut().enumerate() {
        for (v, row) in col.iter_mut().zip(&e) {
            *v = row[c];
        }
    }
    Ok(())
}

/// The 1-norm (largest absolute column sum) of a column-major `K × K` array; NaN if it holds
/// NaN.
#[inline]
pub fn norm1_fixed<const K: usize>(a: &[[f64; K]; K]) -> f64 {
    let mut best = 0.0_f64;
    for col in a {
        let s: f64 = col.iter().map(|v| v.abs()).sum();
        if s > best || s.is_nan() {
            best = s;
        }
    }
    best
}

/// `b := A b` for the column-major `k × k` matrix `a` (`k <= INVERT_MAX`, as inverted by
/// [`invert_small`]); `b.len() == k`.
pub fn small_mul(a: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    small_product(a, k, b, false)
}

/// `b := Aᵀ b` for the column-major `k × k` matrix `a` (`k <= INVERT_MAX`); `b.len() == k`.
pub fn small_mul_transpose(a: &[f64], k: usize, b: &mut [f64]) -> Result<(), LuError> {
    small_product(a, k, b, true)
}

fn small_product(a: &[f64], k: usize, b: &mut [f64], transpose: bool) -> Result<(), LuError> {
    fn fixed<const K: usize>(a: &[f64], b: &mut [f64], transpose: bool) -> Result<(), LuError> {
        let m: &[[f64; K]; K] = a
            .as_chunks::<K>()
            .0
            .try_into()
            .map_err(|_| LuError::Dimension)?;
        let v: &mut [f64; K] = b.try_into().map_err(|_| LuError::Dimension)?;
        *v = if transpose {
            mul_transpose_fixed(m, v)
        } else {
            mul_fixed(m, v)
        };
        Ok(())
    }
    check_square(a.len(), k)?;
    match k {
        0 if b.is_empty() => Ok(()),
        1 => fixed::<1>(a, b, transpose),
        2 => fixed::<2>(a, b, transpose),
        3 => fixed::<3>(a, b, transpose),
        4 => fixed::<4>(a, b, transpose),
        5 => fixed::<5>(a, b, transpose),
        6 => fixed::<6>(a, b, transpose),
        7 => fixed::<7>(a, b, transpose),
        8 => fixed::<8>(a, b, transpose),
        9 => fixed::<9>(a, b, transpose),
        10 => fixed::<10>(a, b, transpose),
        11 => fixed::<11>(a, b, transpose),
        12 => fixed::<12>(a, b, transpose),
        13 => fixed::<13>(a, b, transpose),
        14 => fixed::<14>(a, b, transpose),
        15 => fixed::<15>(a, b, transpose),
        16 => fixed::<16>(a, b, transpose),
        _ => Err(LuError::Dimension),
    }
}

/// `A v` for a column-major `K × K` array.
#[inline]
pub fn mul_fixed<const K: usize>(a: &[[f64; K]; K], v: &[f64; K]) -> [f64; K] {
    let mut t = [0.0; K];
    for (col, &vj) in a.iter().zip(v) {
        for (ti, &aij) in t.iter_mut().zip(col) {
            *ti += aij * vj;
        }
    }
    t
}

/// `Aᵀ v` for a column-major `K × K` array.
#[inline]
pub fn mul_transpose_fixed<const K: usize>(a: &[[f64; K]; K], v: &[f64; K]) -> [f64; K] {
    let mut t = [0.0; K];
    for (ti, col) in t.iter_mut().zip(a) {
        let mut s = 0.0;
        for (&aij, &vi) in col.iter().zip(v) {
            s += aij * vi;
        }
        *ti = s;
    }
    t
}

/// A rigorous upper bound of `‖A⁻¹‖₁` from the LU factors of `A` ([`lu_factor`]), in two
/// triangular solves (`O(k²)`, about a fifth of [`cond1_estimate`]):
/// `‖A⁻¹‖₁ <= ‖U⁻¹‖₁ ‖L⁻¹‖₁ <= ‖M(U)⁻¹‖₁ ‖M(L)⁻¹‖₁`, where `M(T)` is the comparison matrix of
/// the triangular `T` (`|t_ii|` on the diagonal, `-|t_ij|` off it), whose inverse is
/// non-negative and dominates `|T⁻¹|` entrywise (Higham, *Accuracy and Stability of Numerical
/// Algorithms*, 8.2), so each norm is the largest entry of one solve with `M(T)ᵀ` and the ones
/// vector. Pessimistic (by factors of 10 to 100 on the 18 × 18 `J_p` of the 6-UPS), but never
/// below the true value except by rounding: meant to certify that a matrix is well-conditioned
/// without running the estimator. `work.len() >= k`. `+inf` on overflow.
pub fn lu_inverse_norm1_bound(
    lu: &[f64],
    k: usize,
    piv: &[usize],
    work: &mut [f64],
) -> Result<f64, LuError> {
    check_square(lu.len(), k)?;
    if piv.len() != k || work.len() < k {
        return Err(LuError::Dimension);
    }
    let y = &mut work[..k];
    // M(U)ᵀ y = e (lower triangular, forward): y_j = (1 + Σ_{i<j} |u_ij| y_i) / |u_jj|.
    let mut nu = 0.0_f64;
    for j in 0..k {
        let col = &lu[j * k..j * k + k];
        let mut s = 1.0;
        for (&uij, &yi) in col[..j].iter().zip(y[..j].iter()) {
            s += uij.abs() * yi;
        }
        let v = s / col[j].abs();
        y[j] = v;
        nu = nu.max(v);
    }
    // M(L)ᵀ z = e (unit upper triangular, backward): z_j = 1 + Σ_{i>j} |l_ij| z_i.
    let mut nl = 0.0_f64;
    for j in (0..k).rev() {
        let col = &lu[j * k..j * k + k];
        let mut s = 1.0;
        for (&lij, &zi) in col[j + 1..].iter().zip(y[j + 1..].iter()) {
            s += lij.abs() * zi;
        }
        y[j] = s;
        nl = nl.max(s);
    }
    let b = nu * nl;
    Ok(if b.is_nan() { f64::INFINITY } else { b })
}

/// A rigorous upper bound of `‖A⁻¹‖₁` for a symmetric positive definite `A = L Lᵀ` from its
/// Cholesky factor ([`cholesky_factor`]), in two triangular solves:
/// `‖A⁻¹‖₁ <= ‖L⁻ᵀ‖₁ ‖L⁻¹‖₁ = ‖L⁻¹‖_∞ ‖L⁻¹‖₁`, each bounded through the comparison matrix
/// `M(L)` as in [`lu_inverse_norm1_bound`] (the largest entries of `M(L)⁻¹ e` and
/// `M(L)⁻ᵀ e`). On the Gram matrices of the 6-UPS it is 5 to 15 times the true value.
/// `work.len() >= k`. `+inf` on overflow.
pub fn cholesky_inverse_norm1_bound(l: &[f64], k: usize, work: &mut [f64]) -> Result<f64, LuError> {
    check_square(l.len(), k)?;
    if work.len() < k {
        return Err(LuError::Dimension);
    }
    let y = &mut work[..k];
    // M(L) y = e, column oriented (forward): ‖L⁻¹‖_∞ <= max y.
    y.fill(1.0);
    let mut ninf = 0.0_f64;
    for j in 0..k {
        let col = &l[j * k..j * k + k];
        let yj = y[j] / col[j];
        y[j] = yj;
        ninf = ninf.max(yj);
        for (yi, &lij) in y[j + 1..].iter_mut().zip(col[j + 1..].iter()) {
            *yi += lij.abs() * yj;
        }
    }
    // M(L)ᵀ z = e (backward): ‖L⁻¹‖₁ <= max z.
    let mut n1 = 0.0_f64;
    for j in (0..k).rev() {
        let col = &l[j * k..j * k + k];
        let mut s = 1.0;
        for (&lij, &zi) in col[j + 1..].iter().zip(y[j + 1..].iter()) {
            s += lij.abs() * zi;
        }
        let zj = s / col[j];
        y[j] = zj;
        n1 = n1.max(zj);
    }
    let b = ninf * n1;
    Ok(if b.is_nan() { f64::INFINITY } else { b })
}

/// Householder reflector (LAPACK `dlarfg`): on entry `x` is a vector `[alpha, x_tail]`; on
/// return `x[0]` holds `beta = ∓‖x‖` and `x[1..]` the tail of `v` (`v[0] = 1` implied) with
/// `(I - tau v vᵀ) x_in = beta e_1`. Returns `tau` (0 when `x_tail` is zero: no reflection).
pub fn householder(x: &mut [f64]) -> f64 {
    let Some((alpha, tail)) = x.split_first_mut() else {
        return 0.0;
    };
    // The norm with scaling, so that neither tiny nor huge entries under- or overflow.
    let scale = tail.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if scale == 0.0 {
        return 0.0;
    }
    let scale = scale.max(alpha.abs());
    let ss: f64 = tail.iter().map(|v| (v / scale) * (v / scale)).sum::<f64>()
        + (*alpha / scale) * (*alpha / scale);
    let norm = scale * ss.sqrt();
    let beta = if *alpha >= 0.0 { -norm } else { norm };
    let tau = (beta - *alpha) / beta;
    let inv = 1.0 / (*alpha - beta);
    for v in tail.iter_mut() {
        *v *= inv;
    }
    *alpha = beta;
    tau
}

/// Applies `I - tau v vᵀ` (`v = [1, v_tail]`, as [`householder`] leaves it) to `y` in place,
/// `y.len() == v_tail.len() + 1`.
#[inline]
pub fn apply_householder(v_tail: &[f64], tau: f64, y: &mut [f64]) {
    if tau == 0.0 {
        return;
    }
    let Some((y0, ytail)) = y.split_first_mut() else {
        return;
    };
    let w = tau * (*y0 + dot4(v_tail, ytail));
    *y0 -= w;
    for (yi, &vi) in ytail.iter_mut().zip(v_tail) {
        *yi -= w * vi;
    }
}

/// Householder QR with column pivoting (LAPACK `dgeqp3`'s choice, norms recomputed) of the
/// column-major `rows × cols` matrix `a`, in place: `A P = Q R`, `R` on and above the diagonal,
/// the reflectors' tails below it (`tau[k]` their factors, `Q = H_0 H_1 … H_{r-1}`), `perm[k]`
/// the original index of column `k` of `A P`. Stops at the numerical rank `r`: the first step
/// whose largest remaining column norm is at most `rel_tol · |r_00|` (so `|r_kk|`, which
/// decreases with `k`, is above it for every `k < r`); columns `r..` are left as reduced so far
/// (their rows `r..` below the tolerance, rows `..r` are `R_12`). Returns `r`. `norms` is work
/// space of length `cols`.
///
/// Errors: `Dimension` for wrong buffer lengths, `NonFinite` for NaN/inf in `a`.
pub fn qr_col_piv(
    a: &mut [f64],
    rows: usize,
    cols: usize,
    tau: &mut [f64],
    perm: &mut [usize],
    norms: &mut [f64],
    rel_tol: f64,
) -> Result<usize, LuError> {
    if a.len() != rows * cols || tau.len() < cols || perm.len() < cols || norms.len() < cols {
        return Err(LuError::Dimension);
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(LuError::NonFinite);
    }
    for (j, p) in perm.iter_mut().enumerate().take(cols) {
        *p = j;
    }
    let mut r00 = 0.0_f64;
    let steps = rows.min(cols);
    for k in 0..steps {
        // The largest remaining column (rows k..).
        let (mut best, mut pmax) = (k, -1.0_f64);
        for j in k..cols {
            let col = &a[j * rows + k..(j + 1) * rows];
            let s = col.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            let nrm = if s == 0.0 {
                0.0
            } else {
                s * col.iter().map(|v| (v / s) * (v / s)).sum::<f64>().sqrt()
            };
            norms[j] = nrm;
            if nrm > pmax {
                pmax = nrm;
                best = j;
            }
        }
        if k == 0 {
            r00 = pmax;
        }
        if pmax <= rel_tol * r00 || pmax == 0.0 {
            return Ok(k);
        }
        if best != k {
            for i in 0..rows {
                a.swap(i + k * rows, i + best * rows);
            }
            perm.swap(k, best);
        }
        let (left, right) = a.split_at_mut((k + 1) * rows);
        let colk = &mut left[k * rows + k..];
        let t = householder(colk);
        tau[k] = t;
        let v = &colk[1..];
        for c in right.chunks_exact_mut(rows) {
            apply_householder(v, t, &mut c[k..]);
        }
    }
    Ok(steps)
}

/// Applies `Qᵀ = H_{r-1} … H_0` (`transpose`) or `Q = H_0 … H_{r-1}` of the first `r`
/// reflectors that [`qr_col_piv`] (or [`qr_col_piv`] without pivoting) left in the column-major
/// `rows × _` matrix `qr` to the vector `y` (length `rows`).
pub fn apply_q(qr: &[f64], rows: usize, tau: &[f64], r: usize, y: &mut [f64], transpose: bool) {
    let one = |k: usize, y: &mut [f64]| {
        let v = &qr[k * rows + k + 1..(k + 1) * rows];
        apply_householder(v, tau[k], &mut y[k..rows]);
    };
    if transpose {
        for k in 0..r {
            one(k, y);
        }
    } else {
        for k in (0..r).rev() {
            one(k, y);
        }
    }
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
    fn small_inverse_is_exact_and_solves_like_lu() {
        let mut rng = XorShift(0x5A11_0001);
        for k in 0..=INVERT_MAX {
            for trial in 0..200 {
                let mut a = random(k, &mut rng);
                if trial % 5 == 0 && k > 1 {
                    // Ill-conditioned: a nearly dependent last column.
                    let c0 = a.column(0).clone_owned();
                    a.set_column(k - 1, &(c0 * 2.0 + a.column(k - 1) * 1e-6));
                }
                let mut inv: Vec<f64> = a.as_slice().to_vec();
                let anorm = norm1(&inv, k).unwrap();
                let inv_norm = invert_small(&mut inv, k).unwrap();
                if k == 0 {
                    assert_eq!(inv_norm, 0.0);
                    continue;
                }
                let exact = exact_cond1(&a);
                let cond = anorm * inv_norm;
                assert!(
                    (cond - exact).abs() <= 1e-12 * exact * exact.max(10.0),
                    "k={k}: cond {cond:e}, exact {exact:e}"
                );
                let im = DMatrix::from_column_slice(k, k, &inv);
                let id = &a * &im - DMatrix::identity(k, k);
                assert!(
                    id.amax() <= 1e-14 * exact,
                    "k={k}: A A⁻¹ - I = {:e}",
                    id.amax()
                );

                let b: Vec<f64> = (0..k).map(|_| rng.next()).collect();
                let mut x = b.clone();
                small_mul(&inv, k, &mut x).unwrap();
                let mut xt = b.clone();
                small_mul_transpose(&inv, k, &mut xt).unwrap();
                let bv = nalgebra::DVector::from_vec(b.clone());
                let xr = a.clone().lu().solve(&bv).unwrap();
                let xtr = a.transpose().lu().solve(&bv).unwrap();
                for i in 0..k {
                    let tol = 1e-14 * exact * xr.amax().max(1.0);
                    assert!((x[i] - xr[i]).abs() <= tol, "k={k} x[{i}]");
                    let tol = 1e-14 * exact * xtr.amax().max(1.0);
                    assert!((xt[i] - xtr[i]).abs() <= tol, "k={k} xt[{i}]");
                }
            }
        }
    }

    #[test]
    fn small_inverse_errors() {
        let mut z = [0.0; 9];
        assert_eq!(
            invert_small(&mut z, 3),
            Err(LuError::Singular { column: 2 })
        );
        let mut z = [1.0, 2.0, 2.0, 4.0];
        assert_eq!(
            invert_small(&mut z, 2),
            Err(LuError::Singular { column: 1 })
        );
        let mut z = [0.0; 16];
        assert!(matches!(
            invert_small(&mut z, 4),
            Err(LuError::Singular { .. })
        ));
        let mut n = [1.0, f64::NAN, 0.0, 1.0];
        assert_eq!(invert_small(&mut n, 2), Err(LuError::NonFinite));
        let mut big = [0.0; 289];
        assert_eq!(invert_small(&mut big, 17), Err(LuError::Dimension));
        // A tiny determinant whose inverse overflows: singular, not inf.
        let mut tiny = [1e-200, 0.0, 0.0, 1e-200];
        assert_eq!(
            invert_small(&mut tiny, 2),
            Err(LuError::Singular { column: 1 })
        );
        assert_eq!(
            small_mul(&[1.0; 4], 2, &mut [1.0; 3]),
            Err(LuError::Dimension)
        );
    }

    #[test]
    fn inverse_norm_bounds_are_upper_bounds() {
        let mut rng = XorShift(0xB0B0_0001);
        for k in 1..=18 {
            for trial in 0..20 {
                let mut a = random(k, &mut rng);
                if trial % 4 == 0 && k > 1 {
                    let c0 = a.column(0).clone_owned();
                    a.set_column(k - 1, &(c0 * 3.0 + a.column(k - 1) * 1e-7));
                }
                let inv_exact = exact_cond1(&a) / {
                    let n: f64 = a
                        .column_iter()
                        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
                        .fold(0.0, f64::max);
                    n
                };
                let mut lu: Vec<f64> = a.as_slice().to_vec();
                let mut piv = vec![0; k];
                lu_factor(&mut lu, k, &mut piv).unwrap();
                let mut work = vec![0.0; k];
                let b = lu_inverse_norm1_bound(&lu, k, &piv, &mut work).unwrap();
                assert!(
                    b >= inv_exact * (1.0 - 1e-6),
                    "k={k}: LU bound {b:e} < {inv_exact:e}"
                );

                let spd = a.transpose() * &a + DMatrix::identity(k, k) * 0.1;
                let spd_inv = spd.clone().try_inverse().unwrap();
                let inv_exact: f64 = spd_inv
                    .column_iter()
                    .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
                    .fold(0.0, f64::max);
                let mut l: Vec<f64> = spd.as_slice().to_vec();
                cholesky_factor(&mut l, k).unwrap();
                let b = cholesky_inverse_norm1_bound(&l, k, &mut work).unwrap();
                assert!(
                    b >= inv_exact * (1.0 - 1e-6),
                    "k={k}: Cholesky bound {b:e} < {inv_exact:e}"
                );
            }
        }
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
