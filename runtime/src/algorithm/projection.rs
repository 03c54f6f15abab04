//! Projection of a state onto the constraint manifold, by minimum-norm corrections:
//!
//! - position: Gauss–Newton on `f(X) = 0` over all N coordinates, each step the smallest
//!   (Euclidean) correction `dX = -Gᵀ (G Gᵀ)⁻¹ f`;
//! - velocity: the orthogonal projection of `Ẋ` onto `G Ẋ = 0`,
//!   `Ẋ := Ẋ - Gᵀ (G Gᵀ)⁻¹ G Ẋ` (one step: the constraint is linear).
//!
//! Neither forms `G Gᵀ` (whose condition number is the square of `G`'s): both use a
//! Householder QR with column pivoting of `Gᵀ`, `Gᵀ P = Q R` (`linalg::qr_col_piv`), so that
//! `Gᵀ (G Gᵀ)⁻¹ f = Q₁ R⁻ᵀ Pᵀ f` (one triangular solve) and `I - Gᵀ (G Gᵀ)⁻¹ G = Q₂ Q₂ᵀ`
//! (the velocity's component in `null(G)`, exactly orthogonal up to rounding). The reported
//! condition number is `|r_00| / |r_(M-1)(M-1)|`, a lower bound of `G`'s 2-norm condition
//! number; `Singular` above `cond_max` or when the QR finds `G`'s rank below M. The Euclidean metric
//! mixes the coordinates' units (m and rad); near the manifold, where projections are used
//! (after an integration step, or for a slightly inconsistent initial state), any metric gives
//! the same point to first order.

use super::input::{check_finite, max_abs};
use super::report::SolveReport;
use crate::data::{BlockFactors, Data, DynamicsScratch, Workspace};
use crate::error::SolverError;
use crate::factor::{G_SOURCE, lu_error};
use crate::linalg;
use crate::model::Model;
use crate::plan::mat_vec;
use crate::tasks::{Constraints, Jacobian};

const WHAT: &str = "G (pivoted QR of Gᵀ)";

/// Projects `data.x` onto `f(X) = 0` by Gauss–Newton with minimum-norm steps
/// `dX = -Gᵀ (G Gᵀ)⁻¹ f`, until `max |f| <= tol_f` (`SolverOptions`; no step is taken when
/// `data.x` already satisfies it). Writes `data.x` on success. The report gives the steps, the
/// kernel evaluations, the final residual `max |f|` and the worst condition number of `G`
/// from its pivoted QR (0 when no step was needed; see the [module](self) documentation).
///
/// Errors: `NonFinite` for a NaN/inf in `data.x` or a kernel output, `Singular` when `G` loses
/// rank, `NotConverged` after `max_iterations` steps (no backtracking: meant for states near
/// the manifold), `SpuriousRoot` when the result fails the certificate (`certify_position`).
pub fn project_position<K: Constraints<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<SolveReport, SolverError> {
    project_position_with(model, data, &mut |_| {})
}

/// One Gauss–Newton step of [`project_position_with`], for a caller that differentiates the
/// projection (`step_projection.rs`): the iterate `X_k`, the pivoted QR of `G(X_k)ᵀ` (`qr`,
/// `tau`, `piv`, as `factor_qr` writes them), `R⁻ᵀ Pᵀ f(X_k)` and the step
/// `G⁺ f = Q₁ R⁻ᵀ Pᵀ f` about to be subtracted.
pub(crate) struct GaussNewtonStep<'a, const N: usize> {
    pub x: &'a [f64; N],
    pub qr: &'a [f64],
    pub tau: &'a [f64],
    pub piv: &'a [usize],
    pub rt_f: &'a [f64],
    pub step: &'a [f64; N],
}

/// [`project_position`], calling `on_step` before each step is taken.
pub(crate) fn project_position_with<
    K: Constraints<N, M> + Jacobian<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    on_step: &mut dyn FnMut(&GaussNewtonStep<'_, N>),
) -> Result<SolveReport, SolverError> {
    let o = model.options;
    let k = model.kernels();
    check_finite("data.x", &data.x)?;
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        factors: BlockFactors { piv, work, .. },
        dynamics: DynamicsScratch { z: qr, .. },
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
        let cond = factor_qr(g, qr, piv, work, o.cond_max)?;
        rep.cond = rep.cond.max(cond);
        // dX = -Q₁ R⁻ᵀ Pᵀ f.
        let mut step = [0.0; N];
        let qr = qr.as_flattened();
        for k in 0..M {
            let col = &qr[k * N..k * N + k];
            let v = f[piv[k]] - linalg::dot4(col, &step[..k]);
            step[k] = v / qr[k + k * N];
        }
        let mut rt_f = [0.0; M];
        rt_f.copy_from_slice(&step[..M]);
        linalg::apply_q(qr, N, &work[0], M, &mut step, false);
        on_step(&GaussNewtonStep {
            x,
            qr,
            tau: &work[0],
            piv: &piv[..],
            rt_f: &rt_f,
            step: &step,
        });
        for (xj, &sj) in x.iter_mut().zip(&step) {
            *xj -= sj;
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
/// report gives the residual `max |G Ẋ|` after the projection and the condition number of `G`
/// from its pivoted QR (see the [module](self) documentation).
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
        factors: BlockFactors { piv, work, .. },
        dynamics: DynamicsScratch { z: qr, .. },
        ..
    } = ws;
    let cond = factor_qr(g, qr, piv, work, model.options.cond_max)?;
    // Ẋ := Q₂ Q₂ᵀ Ẋ: Qᵀ Ẋ with its first M entries zeroed, times Q.
    let qr = qr.as_flattened();
    *v = *xdot;
    tangent::<N, M>(qr, &work[0], v);
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

/// `v := P v = Q₂ Q₂ᵀ v`, the orthogonal projection onto `null(G)`, from the pivoted QR of `Gᵀ`
/// (N × M column-major, as `factor_qr` writes it) and its reflectors' factors `tau`.
pub(super) fn tangent<const N: usize, const M: usize>(qr: &[f64], tau: &[f64], v: &mut [f64]) {
    linalg::apply_q(qr, N, tau, M, v, true);
    v[..M].fill(0.0);
    linalg::apply_q(qr, N, tau, M, v, false);
}

/// A state's consistency with the constraints, `[max |f(X)|, max |G(X) Ẋ|]`, without moving
/// it: what `simulate` (the command, the C ABI, Python) compares with its tolerance before it
/// projects an initial state, so that an inconsistent state is refused or its projection
/// asked for, never done silently. NaN when a kernel gives a NaN.
pub fn state_residual<K: Constraints<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
    xdot: &[f64; N],
) -> [f64; 2] {
    let k = model.kernels();
    let mut f = [0.0; M];
    k.constraints(x, &mut f);
    let mut g = [[0.0; M]; N];
    k.jacobian(x, &mut g);
    let nan_max = |a: f64, v: f64| {
        if a.is_nan() || v.is_nan() {
            f64::NAN
        } else {
            a.max(v)
        }
    };
    let f_max = f.iter().fold(0.0_f64, |a, v| nan_max(a, v.abs()));
    let gv_max = (0..M)
        .map(|c| (0..N).map(|j| g[j][c] * xdot[j]).sum::<f64>().abs())
        .fold(0.0_f64, nan_max);
    [f_max, gv_max]
}

/// The pivoted QR of `Gᵀ` into `qr` (N × M, column-major: `Gᵀ`'s columns are `G`'s rows),
/// the reflectors' factors into `work[0]`, the permutation into `piv`; returns
/// `|r_00| / |r_(M-1)(M-1)|`. `Singular` when the numerical rank is below M or that ratio
/// exceeds `cond_max`; `NonFinite` for a NaN/inf in `G`.
pub(super) fn factor_qr<const N: usize, const M: usize>(
    g: &nalgebra::SMatrix<f64, M, N>,
    qr: &mut [[f64; N]; M],
    piv: &mut [usize; M],
    work: &mut [[f64; M]; 2],
    cond_max: f64,
) -> Result<f64, SolverError> {
    for (i, col) in qr.iter_mut().enumerate() {
        for (j, v) in col.iter_mut().enumerate() {
            *v = g.data.0[j][i];
        }
    }
    let [tau, norms] = work;
    let a = qr.as_flattened_mut();
    let r = linalg::qr_col_piv(a, N, M, tau, piv, norms, 0.0)
        .map_err(|e| lu_error(e, WHAT, None, M, G_SOURCE))?;
    let cond = if M == 0 {
        1.0
    } else if r < M {
        f64::INFINITY
    } else {
        a[0].abs() / a[(M - 1) + (M - 1) * N].abs()
    };
    if cond.is_nan() || cond > cond_max {
        return Err(SolverError::Singular {
            cond,
            what: WHAT,
            block: None,
        });
    }
    Ok(cond)
}
