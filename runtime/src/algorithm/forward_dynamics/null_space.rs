//! Forward dynamics by the null-space method: the saddle-point system
//!
//! ```text
//! [ M  Gᵀ ] [ Ẍ      ]   [ F          ]
//! [ G  0  ] [ lambda ] = [ gamma_stab ]
//! ```
//!
//! solved without forming `G M⁻¹ Gᵀ` (which squares the conditioning of `M` into that of the
//! multipliers' system) and without a factor of `M` (massless coordinates are fine):
//!
//! 0. the coordinates scaled by `S = diag(s_j)`, `s_j = 1 / sqrt(M_jj)` (the kinetic-energy
//!    metric: `S M S` has a unit diagonal), for a massless coordinate ten times the largest
//!    scaled column of `G` over the size of its own column (its acceleration follows from the
//!    constraints; a large weight keeps it out of the null-space basis); everything below is on
//!    `S M S`, `G S`, `S F`, and `Ẍ = S x̃`. Without it an orthonormal null-space basis mixes a
//!    light coordinate (a rod's spin) with heavy ones, and the projected mass matrix inherits
//!    the whole spread of `M`'s eigenvalues;
//! 1. a rank-revealing QR with column pivoting of `Gᵀ`: `Gᵀ P = Q R`, `Q = [Q₁ Q₂]`
//!    orthogonal (`Q₁`: N × r, `Q₂`: N × (N - r), an orthonormal basis of `null(G)`), `r` the
//!    numerical rank of `G` (`RANK_TOL`);
//! 2. with `Ẍ = Q y`: the constraint rows `R₁₁ᵀ y₁ = (Pᵀ gamma_stab)[..r]` (forward
//!    substitution); the rows of a redundant constraint are dependent on those and are met
//!    with them when `gamma_stab` is consistent (the residual is checked by the caller);
//! 3. the projected mass matrix `H = Q₂ᵀ M Q₂` (positive definite exactly when the problem is
//!    well posed) solved with a Cholesky factor of its Jacobi-scaled form `D H D`,
//!    `D = diag(H)^(-1/2)`: `H y₂ = Q₂ᵀ (F - M Q₁ y₁)`;
//! 4. the multipliers from `Q₁ᵀ (F - M Ẍ) = R₁ Pᵀ lambda`, `R₁ = [R₁₁ R₁₂]` (r × m): by back
//!    substitution when `r = m`, else the minimum-norm solution through a QR of `R₁ᵀ`.
//!
//! `Singular` is decided on the scaled `H` alone: its Cholesky fails, or its 1-norm condition
//! estimate exceeds `cond_max`. A rank-deficient `G` is not singular: its dependent rows are
//! redundant constraints (the accelerations are unique, the multipliers are not, and the
//! minimum-norm ones are returned). The Jacobi scaling makes the decision independent of the
//! units and of a diagonal spread of `M` (a thin rod's spin, 1e-6 kg m², beside a 10 kg
//! body): Cholesky's error is governed by the scaled matrix's condition number (van der Sluis).
//!
//! The factors stay in [`NullSpaceBuffers`]; [`solve`] can be called again on them with other
//! right-hand sides (iterative refinement). The buffers are allocated at the first call and
//! reused (no allocation afterwards).

use crate::error::SolverError;
use crate::factor::{Factored, NullSpaceBuffers};
use crate::linalg::{self, LuError};

/// `G`'s numerical rank: the columns of `Gᵀ P` whose remaining norm is at most this times the
/// largest one are dependent (a redundant constraint). Rounding in a dependent row leaves a
/// few `ε |G|`; a constraint that is independent only by 1e-12 relative cannot be told from a
/// redundant one in `f64` anyway.
pub(crate) const RANK_TOL: f64 = 1e-12;

const WHAT_H: &str = "projected mass matrix Q₂ᵀ M Q₂ (null-space method)";

fn non_finite(what: &'static str) -> impl Fn(LuError) -> SolverError {
    move |_| SolverError::NonFinite { what }
}

/// Factors `G` and the projected mass matrix for [`solve`]. `Singular` when the scaled `H` is
/// not positive definite or its condition estimate exceeds `cond_max`.
pub(crate) fn factor<const N: usize, const M: usize>(
    mass: &nalgebra::SMatrix<f64, N, N>,
    g: &nalgebra::SMatrix<f64, M, N>,
    cond_max: f64,
    buf: &mut NullSpaceBuffers,
) -> Result<Factored, SolverError> {
    buf.qr.resize(N * M, 0.0);
    buf.tau.resize(M, 0.0);
    buf.perm.resize(M, 0);
    buf.b.resize(N * N, 0.0);
    buf.h.resize(N * N, 0.0);
    buf.d.resize(N, 0.0);
    buf.scale.resize(N, 0.0);
    buf.z.resize(M * M, 0.0);
    buf.ztau.resize(M, 0.0);
    buf.work.resize(2 * N + 2 * M, 0.0);
    let NullSpaceBuffers {
        qr,
        tau,
        perm,
        b,
        h,
        d,
        scale,
        z,
        ztau,
        work,
        rank,
    } = buf;
    // S: 1 / sqrt(M_jj), and for massless coordinates 10 times the largest scaled column of G.
    let col_max = |j: usize| g.data.0[j].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut target = 0.0_f64;
    for (j, sj) in scale.iter_mut().enumerate() {
        let mjj = mass.data.0[j][j];
        *sj = if mjj > 0.0 { 1.0 / mjj.sqrt() } else { 0.0 };
        target = target.max(*sj * col_max(j));
    }
    for (j, sj) in scale.iter_mut().enumerate() {
        if *sj == 0.0 || !sj.is_finite() {
            let c = col_max(j);
            *sj = if c > 0.0 && target > 0.0 {
                10.0 * target / c
            } else {
                1.0
            };
        }
    }
    // (S G)ᵀ: column j is row j of G (g.data.0[i][j] = G(j, i)), scaled.
    for j in 0..M {
        for i in 0..N {
            qr[i + j * N] = g.data.0[i][j] * scale[i];
        }
    }
    let r = linalg::qr_col_piv(qr, N, M, tau, perm, work, RANK_TOL)
        .map_err(non_finite("G (Jacobian kernel output)"))?;
    *rank = r;
    let cond_g = if r == 0 {
        1.0
    } else {
        qr[0].abs() / qr[(r - 1) + (r - 1) * N].abs()
    };

    // B = Qᵀ M Q = H_{r-1} … H_0 M H_0 … H_{r-1}: each reflector from the left (on the columns)
    // and from the right (on the rows; B symmetric, so on the columns again after the left).
    for c in 0..N {
        for (r, (bv, &mv)) in b[c * N..(c + 1) * N]
            .iter_mut()
            .zip(&mass.data.0[c])
            .enumerate()
        {
            *bv = scale[r] * mv * scale[c];
        }
    }
    if b.iter().any(|v| !v.is_finite()) {
        return Err(SolverError::NonFinite {
            what: "M (mass kernel output)",
        });
    }
    for k in 0..r {
        let v = &qr[k * N + k + 1..(k + 1) * N];
        let t = tau[k];
        for col in b.chunks_exact_mut(N) {
            linalg::apply_householder(v, t, &mut col[k..]);
        }
        // From the right: row i of B H_k = (H_k row i)ᵀ; gather each row.
        let row = &mut work[..N];
        for i in 0..N {
            for (c, rv) in row.iter_mut().enumerate() {
                *rv = b[i + c * N];
            }
            linalg::apply_householder(v, t, &mut row[k..]);
            for (c, &rv) in row.iter().enumerate().skip(k) {
                b[i + c * N] = rv;
            }
        }
    }

    // H = B[r.., r..], scaled by D = diag(H)^(-1/2), factored.
    let nh = N - r;
    let h = &mut h[..nh * nh];
    for (i, di) in d.iter_mut().enumerate().take(nh) {
        let hii = b[(r + i) + (r + i) * N];
        if hii.is_nan() || hii <= 0.0 {
            return Err(SolverError::Singular {
                cond: f64::INFINITY,
                what: WHAT_H,
                block: None,
            });
        }
        *di = 1.0 / hii.sqrt();
    }
    for c in 0..nh {
        for rr in 0..nh {
            h[rr + c * nh] = b[(r + rr) + (r + c) * N] * d[rr] * d[c];
        }
    }
    let cond_h = if nh == 0 {
        1.0
    } else {
        let anorm = linalg::norm1(h, nh).map_err(non_finite("M (mass kernel output)"))?;
        linalg::cholesky_factor(h, nh).map_err(|e| match e {
            LuError::NonFinite => SolverError::NonFinite {
                what: "M (mass kernel output)",
            },
            _ => SolverError::Singular {
                cond: f64::INFINITY,
                what: WHAT_H,
                block: None,
            },
        })?;
        linalg::cholesky_cond1_estimate(h, nh, anorm, &mut work[..2 * nh])
            .map_err(non_finite("M (mass kernel output)"))?
    };
    if cond_h.is_nan() || cond_h > cond_max {
        return Err(SolverError::Singular {
            cond: cond_h,
            what: WHAT_H,
            block: None,
        });
    }

    // Redundant constraints: the QR of R₁ᵀ (M × r) for the minimum-norm multipliers.
    if r < M {
        let z = &mut z[..M * r];
        for i in 0..r {
            for j in 0..M {
                // R₁ᵀ(j, i) = R(i, j), zero below the diagonal.
                z[j + i * M] = if j < i { 0.0 } else { qr[i + j * N] };
            }
        }
        for k in 0..r {
            let (left, right) = z.split_at_mut((k + 1) * M);
            let colk = &mut left[k * M + k..];
            let t = linalg::householder(colk);
            ztau[k] = t;
            let v = &colk[1..];
            for c in right.chunks_exact_mut(M) {
                linalg::apply_householder(v, t, &mut c[k..]);
            }
        }
    }
    Ok(Factored {
        rank: r,
        cond_g,
        cond_h,
    })
}

/// Solves the saddle-point system with the factors of [`factor`] for the right-hand side
/// `(force, gamma)`: `Ẍ` into `xddot`, the (minimum-norm, when `G` has dependent rows)
/// multipliers into `lambda`.
pub(crate) fn solve<const N: usize, const M: usize>(
    buf: &mut NullSpaceBuffers,
    force: &[f64; N],
    gamma: &[f64; M],
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) {
    let NullSpaceBuffers {
        qr,
        tau,
        perm,
        b,
        h,
        d,
        scale,
        z,
        ztau,
        rank,
        ..
    } = buf;
    let r = *rank;
    let nh = N - r;
    // y₁: R₁₁ᵀ y₁ = (Pᵀ gamma)[..r], forward substitution (R₁₁ᵀ lower triangular).
    let mut y = [0.0; N];
    for k in 0..r {
        let col = &qr[k * N..k * N + k];
        let s = gamma[perm[k]] - linalg::dot4(col, &y[..k]);
        y[k] = s / qr[k + k * N];
    }
    // t = Qᵀ S F.
    let mut t = *force;
    for (tj, &sj) in t.iter_mut().zip(scale.iter()) {
        *tj *= sj;
    }
    linalg::apply_q(qr, N, tau, r, &mut t, true);
    // y₂ = H⁻¹ (t₂ - B₂₁ y₁), with H = D⁻¹ (L Lᵀ) D⁻¹.
    let mut rhs = [0.0; N];
    for i in 0..nh {
        let mut s = t[r + i];
        for (c, &yc) in y.iter().enumerate().take(r) {
            s -= b[(r + i) + c * N] * yc;
        }
        rhs[i] = s * d[i];
    }
    if nh > 0 {
        // Dimensions match by construction; the factor is positive definite (checked).
        let _ = linalg::cholesky_solve(&h[..nh * nh], nh, &mut rhs[..nh]);
    }
    for i in 0..nh {
        y[r + i] = rhs[i] * d[i];
    }
    // s = t₁ - B₁₁ y₁ - B₁₂ y₂ = Q₁ᵀ (F - M Ẍ).
    let mut s = [0.0; M];
    for (i, si) in s.iter_mut().enumerate().take(r) {
        let mut v = t[i];
        for (c, &yc) in y.iter().enumerate() {
            v -= b[i + c * N] * yc;
        }
        *si = v;
    }
    // mu = Pᵀ lambda from R₁ mu = s.
    let mut mu = [0.0; M];
    if r == M {
        for k in (0..r).rev() {
            let mut v = s[k];
            for (j, &mj) in mu.iter().enumerate().take(r).skip(k + 1) {
                v -= qr[k + j * N] * mj;
            }
            mu[k] = v / qr[k + k * N];
        }
    } else {
        // R₁ᵀ = Z [T; 0]: R₁ mu = Tᵀ (Zᵀ mu)[..r] = s, so the minimum-norm mu = Z [T⁻ᵀ s; 0].
        for k in 0..r {
            let mut v = s[k];
            for (i, &mi) in mu.iter().enumerate().take(k) {
                v -= z[i + k * M] * mi; // Tᵀ(k, i) = T(i, k)
            }
            mu[k] = v / z[k + k * M];
        }
        linalg::apply_q(&z[..M * r], M, ztau, r, &mut mu, false);
    }
    for (k, &p) in perm.iter().enumerate().take(M) {
        lambda[p] = mu[k];
    }
    // Ẍ = S Q y.
    linalg::apply_q(qr, N, tau, r, &mut y, false);
    for (x, (&yj, &sj)) in xddot.iter_mut().zip(y.iter().zip(scale.iter())) {
        *x = yj * sj;
    }
}
