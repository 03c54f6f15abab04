//! The dynamics terms `G`, `gamma`, `M`, `psi` at the state, by the fused kernel, and their
//! checks (the dynamics solvers' first step).

use super::input::check_finite;
use crate::data::Data;
use crate::error::SolverError;
use crate::model::Model;
use crate::plan::check_mass_blocks;
use crate::tasks::EquationsOfMotion;

/// Evaluates `G`, `gamma`, `M` and `psi` at `data.x`, `data.xdot` (finite, checked by the
/// caller) with the fused `Dynamics::dynamics_terms` kernel into `data.g`, `data.gamma`,
/// `data.mass`, `data.psi`, after checking the mass blocks; returns the blocks.
pub(crate) fn dynamics_terms<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<&'static [&'static [usize]], SolverError> {
    evaluate_terms(model, data);
    check_terms(model, data)
}

/// The fused `dynamics_terms` kernel at `data.x`, `data.xdot` into `data.g`, `data.gamma`,
/// `data.mass`, `data.psi`, unchecked: the generated solves run on it first and the checks of
/// [`check_terms`] only when they decline.
pub(crate) fn evaluate_terms<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) {
    model.kernels().dynamics_terms(
        &data.x,
        &data.xdot,
        &mut data.g.data.0,
        &mut data.gamma,
        &mut data.mass.data.0,
        &mut data.psi,
    );
}

/// The checks of [`dynamics_terms`] on the kernel outputs in `data`: the mass blocks, and every
/// output finite.
pub(crate) fn check_terms<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
) -> Result<&'static [&'static [usize]], SolverError> {
    let blocks = model.kernels().mass_blocks();
    check_mass_blocks::<N>(blocks)?;
    check_finite("G (Jacobian kernel output)", data.g.as_slice())?;
    check_finite("gamma (kernel output)", &data.gamma)?;
    // Only the blocks of M are ever written or read; the rest stays zero.
    let mut mass_ok = true;
    for blk in blocks {
        for &c in blk.iter() {
            let col = &data.mass.data.0[c];
            for &r in blk.iter() {
                mass_ok &= col[r].is_finite();
            }
        }
    }
    if !mass_ok {
        return Err(SolverError::NonFinite {
            what: "M (mass kernel output)",
        });
    }
    check_finite("psi (kernel output)", &data.psi)?;
    Ok(blocks)
}
