//! The derivatives of forward dynamics: `∂Ẍ/∂X`, `∂Ẍ/∂Ẋ`, `∂Ẍ/∂U` and `∂lambda/∂X`,
//! `∂lambda/∂Ẋ`, `∂lambda/∂U` at one state.
//!
//! Forward dynamics solves `M Ẍ + Gᵀ lambda = psi + Q + S U` and `G Ẍ = gamma` (see
//! `design.md`). With the inverse-dynamics residual `r = M Ẍ - psi + Gᵀ lambda` and the
//! acceleration constraint `c = G Ẍ - gamma`, whose derivatives the generated kernel
//! `dynamics_derivatives` writes (the chain rule through the generator's named intermediates),
//! the implicit function theorem gives, for a perturbation `(dX, dẊ, dU)` at fixed `Q`:
//!
//! ```text
//! [M  Gᵀ] [dẌ     ]     [∂r/∂X dX + ∂r/∂Ẋ dẊ - S dU]
//! [G  0 ] [dlambda] = - [∂c/∂X dX + ∂c/∂Ẋ dẊ        ]
//! ```
//!
//! one saddle-point system with `2 N + (N - M)` right-hand sides. This first version factors
//! it densely (LU with partial pivoting of the `(N + M) × (N + M)` matrix, `linalg::lu_factor`)
//! rather than through the structure the generated solves know; the derivatives are those of
//! the unstabilised system (`Baumgarte::NONE`).

use nalgebra::SMatrix;

use super::baumgarte::Baumgarte;
use super::forward_dynamics::forward_dynamics;
use super::report::DynamicsReport;
use crate::data::Data;
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::Derivatives;

/// The derivatives of forward dynamics at one state and the buffers that compute them:
/// [`ForwardDynamicsDerivatives::new`] allocates once, [`forward_dynamics_derivatives`] never.
#[derive(Debug, Clone)]
pub struct ForwardDynamicsDerivatives<const N: usize, const M: usize> {
    /// `∂Ẍ/∂X` (N × N).
    pub dxddot_dx: SMatrix<f64, N, N>,
    /// `∂Ẍ/∂Ẋ` (N × N).
    pub dxddot_dxdot: SMatrix<f64, N, N>,
    /// `∂Ẍ/∂U` (N × N): column `a` for the control force `u[a]` on `Structure::actuated[a]`;
    /// the columns from `Structure::actuated.len()` on stay zero.
    pub dxddot_du: SMatrix<f64, N, N>,
    /// `∂lambda/∂X` (M × N).
    pub dlambda_dx: SMatrix<f64, M, N>,
    /// `∂lambda/∂Ẋ` (M × N).
    pub dlambda_dxdot: SMatrix<f64, M, N>,
    /// `∂lambda/∂U` (M × N), columns as in `dxddot_du`.
    pub dlambda_du: SMatrix<f64, M, N>,
    /// `∂r/∂X` of the residual `r = M Ẍ - psi + Gᵀ lambda` at the solution (N × N), as the
    /// generated kernel wrote it.
    pub dr_dx: SMatrix<f64, N, N>,
    /// `∂r/∂Ẋ = -∂psi/∂Ẋ` (N × N).
    pub dr_dxdot: SMatrix<f64, N, N>,
    /// `∂c/∂X` of `c = G Ẍ - gamma` at the solution (M × N).
    pub dc_dx: SMatrix<f64, M, N>,
    /// `∂c/∂Ẋ = -∂gamma/∂Ẋ` (M × N).
    pub dc_dxdot: SMatrix<f64, M, N>,
    /// The Hager/Higham estimate of the 1-norm condition number of `[M Gᵀ; G 0]`.
    pub cond: f64,
    /// LU factors of `[M Gᵀ; G 0]`, column-major, `(N + M)²`.
    kkt: Vec<f64>,
    piv: Vec<usize>,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl<const N: usize, const M: usize> ForwardDynamicsDerivatives<N, M> {
    /// Zeroed derivatives and the saddle-point system's buffers (the only allocation).
    pub fn new() -> Self {
        let k = N + M;
        Self {
            dxddot_dx: SMatrix::zeros(),
            dxddot_dxdot: SMatrix::zeros(),
            dxddot_du: SMatrix::zeros(),
            dlambda_dx: SMatrix::zeros(),
            dlambda_dxdot: SMatrix::zeros(),
            dlambda_du: SMatrix::zeros(),
            dr_dx: SMatrix::zeros(),
            dr_dxdot: SMatrix::zeros(),
            dc_dx: SMatrix::zeros(),
            dc_dxdot: SMatrix::zeros(),
            cond: f64::NAN,
            kkt: vec![0.0; k * k],
            piv: vec![0; k],
            rhs: vec![0.0; k],
            work: vec![0.0; 2 * k],
        }
    }
}

impl<const N: usize, const M: usize> Default for ForwardDynamicsDerivatives<N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Forward dynamics at `data.x`, `data.xdot` with the control forces `u` and the generalised
/// forces `q_forces` (held fixed), then its derivatives with respect to `X`, `Ẋ` and `U` into
/// `out` (see the [module](self) documentation). Writes what [`forward_dynamics`] writes
/// (`data.xddot`, `data.lambda`, ...) and returns its report.
///
/// Errors: those of [`forward_dynamics`] (without stabilisation); `NonFinite` when the
/// derivative kernel's outputs are not finite; `Singular` (`what`: `"[M Gᵀ; G 0]"`) when the
/// saddle-point matrix is exactly singular or its condition estimate exceeds
/// `SolverOptions::cond_max` (a rank-deficient `G`: redundant constraints leave `lambda`, and
/// so its derivatives, not unique).
pub fn forward_dynamics_derivatives<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut ForwardDynamicsDerivatives<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    let report = forward_dynamics(model, data, u, q_forces, Baumgarte::NONE)?;
    model.kernels().dynamics_derivatives(
        &data.x,
        &data.xdot,
        &data.xddot,
        &data.lambda,
        &mut out.dr_dx.data.0,
        &mut out.dr_dxdot.data.0,
        &mut out.dc_dx.data.0,
        &mut out.dc_dxdot.data.0,
    );
    let k = N + M;
    // [M Gᵀ; G 0], column-major.
    let kkt = &mut out.kkt;
    for j in 0..N {
        let col = &mut kkt[j * k..(j + 1) * k];
        col[..N].copy_from_slice(data.mass.column(j).as_slice());
        col[N..].copy_from_slice(data.g.column(j).as_slice());
    }
    for l in 0..M {
        let col = &mut kkt[(N + l) * k..(N + l + 1) * k];
        for (i, c) in col[..N].iter_mut().enumerate() {
            *c = data.g[(l, i)];
        }
        col[N..].fill(0.0);
    }
    let what = "[M Gᵀ; G 0]";
    let lu_error = |e: LuError| match e {
        LuError::Singular { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block: None,
        },
        _ => SolverError::NonFinite {
            what: "dynamics_derivatives",
        },
    };
    let anorm = linalg::norm1(kkt, k).map_err(lu_error)?;
    linalg::lu_factor(kkt, k, &mut out.piv).map_err(lu_error)?;
    out.cond = linalg::cond1_estimate(kkt, k, &out.piv, anorm, &mut out.work).map_err(lu_error)?;
    if out.cond.is_nan() || out.cond > model.options.cond_max {
        return Err(SolverError::Singular {
            cond: out.cond,
            what,
            block: None,
        });
    }
    let (kkt, piv, rhs) = (&out.kkt[..], &out.piv[..], &mut out.rhs[..]);
    let solve = |rhs: &mut [f64], dxddot: &mut [f64], dlambda: &mut [f64]| {
        linalg::lu_solve(kkt, k, piv, rhs).map_err(lu_error)?;
        dxddot.copy_from_slice(&rhs[..N]);
        dlambda.copy_from_slice(&rhs[N..]);
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(SolverError::NonFinite {
                what: "dynamics_derivatives",
            })
        }
    };
    for j in 0..N {
        for (r, &d) in rhs[..N].iter_mut().zip(out.dr_dx.column(j).iter()) {
            *r = -d;
        }
        for (r, &d) in rhs[N..].iter_mut().zip(out.dc_dx.column(j).iter()) {
            *r = -d;
        }
        solve(
            rhs,
            out.dxddot_dx.column_mut(j).as_mut_slice(),
            out.dlambda_dx.column_mut(j).as_mut_slice(),
        )?;
        for (r, &d) in rhs[..N].iter_mut().zip(out.dr_dxdot.column(j).iter()) {
            *r = -d;
        }
        for (r, &d) in rhs[N..].iter_mut().zip(out.dc_dxdot.column(j).iter()) {
            *r = -d;
        }
        solve(
            rhs,
            out.dxddot_dxdot.column_mut(j).as_mut_slice(),
            out.dlambda_dxdot.column_mut(j).as_mut_slice(),
        )?;
    }
    let s = model.structure();
    for (a, &j) in s.actuated.iter().enumerate() {
        rhs.fill(0.0);
        rhs[j] = gear_ratio(s.gear, a);
        solve(
            rhs,
            out.dxddot_du.column_mut(a).as_mut_slice(),
            out.dlambda_du.column_mut(a).as_mut_slice(),
        )?;
    }
    Ok(report)
}
