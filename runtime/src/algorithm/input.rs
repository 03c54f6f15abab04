//! The checks of the solvers' inputs and of kernel outputs: lengths and finiteness.

use crate::error::SolverError;

pub(crate) fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

pub(crate) fn check_input(
    what: &'static str,
    v: &[f64],
    expected: usize,
) -> Result<(), SolverError> {
    if v.len() != expected {
        return Err(SolverError::Dimension {
            what,
            expected,
            found: v.len(),
        });
    }
    if !all_finite(v) {
        return Err(SolverError::NonFinite { what });
    }
    Ok(())
}

/// No NaN or infinity in `v`. Branch-free integer arithmetic over the whole slice, so it
/// vectorises: an entry is NaN or infinite iff its exponent bits are all set, iff adding one
/// unit of the exponent field to them carries into the sign bit.
#[inline]
pub(crate) fn all_finite(v: &[f64]) -> bool {
    const EXP: u64 = 0x7FF0_0000_0000_0000;
    const ONE: u64 = 0x0010_0000_0000_0000;
    let bad = v
        .iter()
        .fold(0_u64, |acc, x| acc | ((x.to_bits() & EXP) + ONE));
    bad >> 63 == 0
}

pub(crate) fn check_finite(what: &'static str, v: &[f64]) -> Result<(), SolverError> {
    if !all_finite(v) {
        return Err(SolverError::NonFinite { what });
    }
    Ok(())
}
