//! Forward dynamics from the whole saddle-point system by a dense LU with partial pivoting:
//! the alternative to the null-space method that was measured against it (see the
//! [module](super) documentation); reachable through
//! [`forward_dynamics_with`](super::forward_dynamics_with).

use crate::data::SaddlePointBuffers;
use crate::error::SolverError;
use crate::factor::lu_error;
use crate::linalg;

const WHAT: &str = "saddle-point system [M Gᵀ; G 0]";

/// Factors the whole saddle-point matrix
///
/// ```text
/// [ M  Gᵀ ]
/// [ G  0  ]
/// ```
///
/// by a dense LU with partial pivoting, for [`solve`]: regular as long as `G` has full rank and
/// `M` is positive definite on the null space of `G` (massless coordinates are fine). Its
/// `(N + M)²` matrix lives in `buf`, allocated at the first call and reused (no allocation
/// afterwards). Returns the estimated 1-norm condition number; `Singular` above `cond_max`
/// (which a rank-deficient `G`, a redundant constraint, always is).
pub(super) fn factor<const N: usize, const M: usize>(
    mass: &nalgebra::SMatrix<f64, N, N>,
    g: &nalgebra::SMatrix<f64, M, N>,
    cond_max: f64,
    buf: &mut SaddlePointBuffers,
) -> Result<f64, SolverError> {
    let k = N + M;
    buf.a.resize(k * k, 0.0);
    buf.piv.resize(k, 0);
    buf.b.resize(k, 0.0);
    buf.work.resize(2 * k, 0.0);
    let SaddlePointBuffers { a, piv, work, .. } = buf;
    a.fill(0.0); // column-major
    for c in 0..N {
        a[c * k..c * k + N].copy_from_slice(&mass.data.0[c]);
        for r in 0..M {
            let gv = g.data.0[c][r];
            a[(N + r) + c * k] = gv;
            a[c + (N + r) * k] = gv;
        }
    }
    let err = |e| lu_error(e, WHAT, None, k, "M or G (kernel output)");
    let anorm = linalg::norm1(a, k).map_err(err)?;
    linalg::lu_factor(a, k, piv).map_err(err)?;
    let cond = linalg::cond1_estimate(a, k, piv, anorm, work).map_err(err)?;
    if cond.is_nan() || cond > cond_max {
        return Err(SolverError::Singular {
            cond,
            what: WHAT,
            block: None,
        });
    }
    Ok(cond)
}

/// Solves the saddle-point system factored by [`factor`] for the right-hand side
/// `(force, gamma)`.
pub(super) fn solve<const N: usize, const M: usize>(
    buf: &mut SaddlePointBuffers,
    force: &[f64; N],
    gamma: &[f64; M],
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) {
    let k = N + M;
    let SaddlePointBuffers { a, piv, b, .. } = buf;
    b[..N].copy_from_slice(force);
    b[N..].copy_from_slice(gamma);
    // Dimensions match by construction, the factor is regular (checked).
    let _ = linalg::lu_solve(a, k, piv, b);
    xddot.copy_from_slice(&b[..N]);
    lambda.copy_from_slice(&b[N..]);
}
