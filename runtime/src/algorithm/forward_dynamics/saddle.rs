//! Forward dynamics from the whole saddle-point system by a dense LU, for a mass matrix with
//! massless coordinates (only positive semi-definite).

use crate::data::SaddlePointBuffers;
use crate::error::SolverError;
use crate::factor::lu_error;
use crate::linalg;

/// Forward dynamics from the whole saddle-point system
///
/// ```text
/// [ M  Gᵀ ] [ Ẍ      ]   [ F          ]
/// [ G  0  ] [ lambda ] = [ gamma_stab ]
/// ```
///
/// by a dense LU with partial pivoting, for an `M` that is only positive semi-definite (massless
/// coordinates): the system is regular as long as `M` is positive definite on the null space of
/// `G`. Its `(N + M)²` matrix lives in `buf`, allocated at the first call and reused (no
/// allocation afterwards). Returns the estimated 1-norm condition number; `Singular` above
/// `cond_max`.
#[allow(clippy::too_many_arguments)]
pub(super) fn saddle_point<const N: usize, const M: usize>(
    mass: &nalgebra::SMatrix<f64, N, N>,
    g: &nalgebra::SMatrix<f64, M, N>,
    force: &[f64; N],
    gamma_stab: &[f64],
    cond_max: f64,
    buf: &mut SaddlePointBuffers,
    xddot: &mut [f64; N],
    lambda: &mut [f64; M],
) -> Result<f64, SolverError> {
    const WHAT: &str = "saddle-point system [M Gᵀ; G 0]";
    let k = N + M;
    buf.a.resize(k * k, 0.0);
    buf.piv.resize(k, 0);
    buf.b.resize(k, 0.0);
    buf.work.resize(2 * k, 0.0);
    let SaddlePointBuffers { a, piv, b, work } = buf;
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
    b[..N].copy_from_slice(force);
    b[N..].copy_from_slice(&gamma_stab[..M]);
    linalg::lu_solve(a, k, piv, b).map_err(err)?;
    xddot.copy_from_slice(&b[..N]);
    lambda.copy_from_slice(&b[N..]);
    Ok(cond)
}
