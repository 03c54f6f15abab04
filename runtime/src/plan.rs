//! The robot's structure as the solvers use it: what the generator fixed (the blocks of `G`
//! and of `M`) turned into checks, gathers and products that need neither the model nor the
//! solvers' buffers. Above [`linalg`](crate::linalg) and the kernel traits, below the
//! factorizations ([`factor`](crate::factor)).

use nalgebra::SMatrix;

use crate::error::SolverError;
use crate::linalg::{self, LuError};

/// Checks that `Dynamics::mass_blocks` lists every coordinate exactly once, in range, with no
/// empty block (after this the dynamics solvers index with them without any bounds failure).
pub(crate) fn check_mass_blocks<const N: usize>(blocks: &[&[usize]]) -> Result<(), SolverError> {
    let mut seen = [false; N];
    let mut count = 0;
    let bad = |found| SolverError::Dimension {
        what: "Dynamics::mass_blocks (each coordinate exactly once)",
        expected: N,
        found,
    };
    for blk in blocks {
        if blk.is_empty() {
            return Err(bad(count));
        }
        for &j in blk.iter() {
            match seen.get_mut(j) {
                Some(s) if !*s => {
                    *s = true;
                    count += 1;
                }
                _ => return Err(bad(count + 1)),
            }
        }
    }
    if count != N {
        return Err(bad(count));
    }
    Ok(())
}

/// `out = M v` with the block-diagonal `M` (blocks checked by [`check_mass_blocks`]).
pub(crate) fn mass_times<const N: usize>(
    mass: &SMatrix<f64, N, N>,
    blocks: &[&[usize]],
    v: &[f64; N],
    out: &mut [f64; N],
) {
    for blk in blocks {
        for &r in blk.iter() {
            let mut s = 0.0;
            for &c in blk.iter() {
                s += mass.data.0[c][r] * v[c];
            }
            out[r] = s;
        }
    }
}

/// Gathers `G[rows, cols]` (order `B <= linalg::SMALL`) and inverts it: `(G_b⁻¹, ‖G_b‖₁,
/// ‖G_b⁻¹‖₁)`.
#[inline(always)]
pub(crate) fn invert_block<const N: usize, const M: usize, const B: usize>(
    g: &SMatrix<f64, M, N>,
    rows: &[usize; B],
    cols: &[usize; B],
) -> Result<([[f64; B]; B], f64, f64), LuError> {
    let a: [[f64; B]; B] = core::array::from_fn(|c| {
        let gcol = &g.data.0[cols[c]];
        core::array::from_fn(|r| gcol[rows[r]])
    });
    let anorm = linalg::norm1_fixed(&a);
    if !anorm.is_finite() {
        return Err(LuError::NonFinite);
    }
    let mut inv = [[0.0; B]; B];
    let inv_norm = linalg::invert_fixed(&a, &mut inv)?;
    Ok((inv, anorm, inv_norm))
}

/// `out = G v`.
pub(crate) fn mat_vec<const N: usize, const M: usize>(
    g: &SMatrix<f64, M, N>,
    v: &[f64; N],
    out: &mut [f64; M],
) {
    out.fill(0.0);
    for (col, &vj) in g.data.0.iter().zip(v) {
        if vj != 0.0 {
            for (o, &gij) in out.iter_mut().zip(col) {
                *o += gij * vj;
            }
        }
    }
}
