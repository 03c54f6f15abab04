//! Projection of a state onto the constraint manifold, by minimum-norm corrections:
//!
//! - position: Gauss–Newton on `f(X) = 0` over all N coordinates, each step the smallest
//!   (Euclidean) correction `dX = -Gᵀ (G Gᵀ)⁻¹ f`;
//! - velocity: the orthogonal projection of `Ẋ` onto `G Ẋ = 0`,
//!   `Ẋ := Ẋ - Gᵀ (G Gᵀ)⁻¹ G Ẋ` (one step: the constraint is linear).
//!
//! `G Gᵀ` (M × M) is symmetric positive definite when `G` has full rank; it is factored by
//! Cholesky with a 1-norm condition estimate (about the square of `G`'s). The Euclidean metric
//! mixes the coordinates' units (m and rad); near the manifold, where projections are used
//! (after an integration step, or for a slightly inconsistent initial state), any metric gives
//! the same point to first order.

use super::input::{check_finite, max_abs};
use super::report::SolveReport;
use crate::data::{BlockFactors, Data, Workspace};
use crate::error::SolverError;
use crate::factor::{CondMode, G_SOURCE, factor_spd, lu_error};
use crate::linalg;
use crate::model::Model;
use crate::plan::mat_vec;
use crate::tasks::{Constraints, Jacobian};

const WHAT: &str = "G Gᵀ";

/// Projects `data.x` onto `f(X) = 0` by Gauss–Newton with minimum-norm steps
/// `dX = -Gᵀ (G Gᵀ)⁻¹ f`, until `max |f| <= tol_f` (`SolverOptions`; no step is taken when
/// `data.x` already satisfies it). Writes `data.x` on success. The report gives the steps, the
/// kernel evaluations, the final residual `max |f|` and the worst condition estimate of
/// `G Gᵀ` (0 when no step was needed).
///
/// Errors: `NonFinite` for a NaN/inf in `data.x` or a kernel output, `Singular` when `G` loses
/// rank, `NotConverged` after `max_iterations` steps (no backtracking: meant for states near
/// the manifold), `SpuriousRoot` when the result fails the certificate (`certify_position`).
pub fn project_position<K: Constraints<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<SolveReport, SolverError> {
    let o = model.options;
    let k = model.kernels();
    check_finite("data.x", &data.x)?;
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        rhs: mu,
        factors: BlockFactors { lu, work, .. },
        ..
    } = ws;
    *x = data.x;
    let mut rep = SolveReport {
        iterations: 0,
        evaluations: 0,
        residual: 0.0,
        cond: 0.0,
    };
    loop {
        k.constraints(x, f);
        check_finite("f (constraint kernel output)", f)?;
        rep.residual = max_abs(f);
        if rep.residual <= o.tol_f {
            break;
        }
        if rep.iterations >= o.max_iterations {
            return Err(SolverError::NotConverged {
                iterations: rep.iterations,
                residual: rep.residual,
            });
        }
        k.jacobian(x, &mut g.data.0);
        rep.evaluations += 1;
        let cond = gram(g, lu, work, o.cond_max)?;
        rep.cond = rep.cond.max(cond);
        *mu = *f;
        linalg::cholesky_solve(lu.as_flattened(), M, mu)
            .map_err(|e| lu_error(e, WHAT, None, M, G_SOURCE))?;
        // x -= Gᵀ mu.
        for (xj, gcol) in x.iter_mut().zip(g.data.0.iter()) {
            *xj -= dot(gcol, mu);
        }
        check_finite("projection step", x)?;
        rep.iterations += 1;
    }
    super::certify::certify_position(model, &data.ws.x)?;
    data.x = data.ws.x;
    Ok(rep)
}

/// Projects `data.xdot` onto `G Ẋ = 0` at `data.x`: `Ẋ := Ẋ - Gᵀ (G Gᵀ)⁻¹ G Ẋ`, the
/// smallest (Euclidean) change. Writes `data.xdot` on success. Calls `Kernels::jacobian`. The
/// report gives the residual `max |G Ẋ|` after the projection and the condition estimate of
/// `G Gᵀ`.
///
/// Errors: `NonFinite` for a NaN/inf in `data.x`, `data.xdot` or `G`, `Singular` when `G`
/// loses rank.
pub fn project_velocity<K: Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<SolveReport, SolverError> {
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    model.kernels().jacobian(&data.x, &mut data.g.data.0);
    let Data { xdot, g, ws, .. } = data;
    let Workspace {
        x: v,
        rhs: mu,
        factors: BlockFactors { lu, work, .. },
        ..
    } = ws;
    let cond = gram(g, lu, work, model.options.cond_max)?;
    mat_vec(g, xdot, mu);
    linalg::cholesky_solve(lu.as_flattened(), M, mu)
        .map_err(|e| lu_error(e, WHAT, None, M, G_SOURCE))?;
    for ((vj, &xdj), gcol) in v.iter_mut().zip(xdot.iter()).zip(g.data.0.iter()) {
        *vj = xdj - dot(gcol, mu);
    }
    check_finite("projected velocity", v)?;
    mat_vec(g, v, mu);
    let residual = max_abs(mu);
    data.xdot = data.ws.x;
    Ok(SolveReport {
        iterations: 0,
        evaluations: 1,
        residual,
        cond,
    })
}

/// Forms `G Gᵀ` in `lu` and Cholesky-factors it; returns its condition estimate.
fn gram<const N: usize, const M: usize>(
    g: &nalgebra::SMatrix<f64, M, N>,
    lu: &mut [[f64; M]; M],
    work: &mut [[f64; M]; 2],
    cond_max: f64,
) -> Result<f64, SolverError> {
    let a = lu.as_flattened_mut();
    a.fill(0.0);
    for gcol in g.data.0.iter() {
        for c in 0..M {
            let gc = gcol[c];
            if gc != 0.0 {
                for r in c..M {
                    a[r + c * M] += gcol[r] * gc;
                }
            }
        }
    }
    for c in 0..M {
        for r in c + 1..M {
            a[c + r * M] = a[r + c * M];
        }
    }
    factor_spd(
        a,
        M,
        work.as_flattened_mut(),
        cond_max,
        CondMode::Report,
        WHAT,
        G_SOURCE,
    )
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
