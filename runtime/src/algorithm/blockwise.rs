//! Blockwise direct solves with `G`'s square blocks (the velocity and acceleration solvers and
//! inverse dynamics): every block factored into its slot of the workspace, then solved.

use super::input::{all_finite, check_finite};
use crate::data::{BlockFactors, Data, Workspace};
use crate::error::SolverError;
use crate::factor::{
    CondMode, G_SOURCE, Slot, check_cond, condition, factor_block, lu_error, solve_block,
};
use crate::kernels::IkBlock;
use crate::linalg;
use crate::plan::{invert_block, mat_vec};
use crate::tasks::Robot;

/// Which derivative a blockwise rate solve gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Level {
    /// `G_r ṙ = -G_o ȯ`, into `data.xdot`.
    Velocity,
    /// `G_r r̈ = gamma - G_o ö`, into `data.xddot` (`data.gamma` set by the caller).
    Acceleration,
}

/// A set of independent square subsystems `(rows, cols)` of `G`.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Blocks<'a> {
    /// The inverse-kinematics blocks of the structure.
    Ik(&'static [IkBlock]),
    /// One system (forward kinematics: all rows, the passive columns).
    Single {
        rows: &'a [usize],
        cols: &'static [usize],
    },
}

impl Blocks<'_> {
    pub(crate) fn len(&self) -> usize {
        match self {
            Blocks::Ik(b) => b.len(),
            Blocks::Single { .. } => 1,
        }
    }

    /// `(rows, cols, block index for errors)`; `b < self.len()`.
    pub(crate) fn get(&self, b: usize) -> (&[usize], &[usize], Option<usize>) {
        match self {
            Blocks::Ik(blocks) => match blocks.get(b) {
                Some(blk) => (blk.rows, blk.cols, Some(b)),
                None => (&[], &[], Some(b)),
            },
            Blocks::Single { rows, cols } => (rows, cols, None),
        }
    }
}

/// Factors every block of `G` (`data.g` as it is) into its slot of the workspace, with
/// reportable condition numbers; returns the worst.
pub(crate) fn factor_blocks<K: Robot<N, M>, const N: usize, const M: usize>(
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    cond_max: f64,
    what: &'static str,
) -> Result<f64, SolverError> {
    if let Blocks::Ik(ik) = blocks {
        let fixed = by_ik_order!(K, ik, B => factor_blocks_fixed::<N, M, B>(data, ik, cond_max, what), _ => None);
        if let Some(r) = fixed {
            return r;
        }
    }
    let Data { g, ws, .. } = data;
    let mut worst = 0.0_f64;
    let mut slot = Slot::default();
    for b in 0..blocks.len() {
        let (rows, cols, block) = blocks.get(b);
        slot = slot.next(rows.len());
        let c = factor_block(
            g,
            rows,
            cols,
            slot,
            &mut ws.factors.lu,
            &mut ws.factors.piv,
            &mut ws.factors.work,
            cond_max,
            CondMode::Report,
            what,
            block,
        )?;
        worst = worst.max(c.cond);
    }
    Ok(worst)
}

/// The inverses of the blocks in the workspace, as arrays, when all have the order `B` (the
/// slots of [`Slot`]: block `b` at offset `b B²`).
pub(crate) fn fixed_store<const M: usize, const B: usize>(lu: &[[f64; M]; M]) -> &[[[f64; B]; B]] {
    lu.as_flattened().as_chunks::<B>().0.as_chunks::<B>().0
}

/// [`factor_blocks`] for inverse-kinematics blocks all of order `B` (`None`: they are not).
fn factor_blocks_fixed<const N: usize, const M: usize, const B: usize>(
    data: &mut Data<N, M>,
    ik: &[IkBlock],
    cond_max: f64,
    what: &'static str,
) -> Option<Result<f64, SolverError>> {
    let Data { g, ws, .. } = data;
    let store = ws
        .factors
        .lu
        .as_flattened_mut()
        .as_chunks_mut::<B>()
        .0
        .as_chunks_mut::<B>()
        .0;
    if store.len() < ik.len() {
        return None;
    }
    let mut worst = 0.0_f64;
    for (b, (blk, inv)) in ik.iter().zip(store.iter_mut()).enumerate() {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let r = invert_block::<N, M, B>(g, rows, cols)
            .map_err(|e| lu_error(e, what, Some(b), B, G_SOURCE))
            .and_then(|(a, anorm, inv_norm)| {
                *inv = a;
                check_cond(condition(anorm, inv_norm), cond_max, what, Some(b))
            });
        match r {
            Ok(cond) => worst = worst.max(cond),
            Err(e) => return Some(Err(e)),
        }
    }
    Some(Ok(worst))
}

/// [`linear_solve`] for inverse-kinematics blocks all of order `B`, factored by
/// [`factor_blocks_fixed`] (`None`: they are not).
fn linear_solve_fixed<const N: usize, const M: usize, const B: usize>(
    data: &mut Data<N, M>,
    ik: &[IkBlock],
    with_gamma: bool,
) -> Option<Result<f64, SolverError>> {
    let Data { g, gamma, ws, .. } = data;
    let Workspace {
        x: v,
        rhs,
        factors: BlockFactors { lu, .. },
        ..
    } = ws;
    let store = fixed_store::<M, B>(lu);
    if store.len() < ik.len() {
        return None;
    }
    // rhs = base - G v, over all rows, before any block writes v.
    mat_vec(g, v, rhs);
    for (r, &gam) in rhs.iter_mut().zip(gamma.iter()) {
        let base = if with_gamma { gam } else { 0.0 };
        *r = base - *r;
    }
    if !all_finite(rhs) {
        return Some(Err(SolverError::NonFinite {
            what: "right-hand side (G or gamma)",
        }));
    }
    let mut residual = 0.0_f64;
    let mut finite = true;
    for (blk, inv) in ik.iter().zip(store) {
        let rows: &[usize; B] = blk.rows.try_into().ok()?;
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let r: [f64; B] = core::array::from_fn(|i| rhs[rows[i]]);
        let sol = linalg::mul_fixed(inv, &r);
        // The residual of the block's rows (see `linear_solve`).
        let mut gv = [0.0; B];
        for (&s, &j) in sol.iter().zip(cols) {
            let gcol = &g.data.0[j];
            finite &= s.is_finite();
            v[j] = s;
            for (a, &i) in gv.iter_mut().zip(rows) {
                *a += gcol[i] * s;
            }
        }
        for (&a, &ri) in gv.iter().zip(&r) {
            residual = residual.max((a - ri).abs());
        }
    }
    if !finite {
        return Some(Err(SolverError::NonFinite { what: "solution" }));
    }
    Some(Ok(residual))
}

/// Blockwise direct solve of `G v = base` (`base = gamma` if `with_gamma`, else zero) for the
/// blocks' columns of `v = data.ws.x`, whose other entries (the given rates) are set by the
/// caller and whose block entries are zero on entry. Uses `data.g` as it is and the block
/// factors from [`factor_blocks`] (the caller runs both). Returns `max |G v - base|`.
pub(crate) fn linear_solve<K: Robot<N, M>, const N: usize, const M: usize>(
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    with_gamma: bool,
    what: &'static str,
) -> Result<f64, SolverError> {
    if let Blocks::Ik(ik) = blocks {
        let fixed = by_ik_order!(K, ik, B => linear_solve_fixed::<N, M, B>(data, ik, with_gamma), _ => None);
        if let Some(r) = fixed {
            return r;
        }
    }
    let Data { g, gamma, ws, .. } = data;
    let Workspace {
        x: v,
        dx,
        rhs,
        factors: BlockFactors { lu, piv, .. },
        ..
    } = ws;
    // rhs = base - G v, over all rows, before any block writes v.
    mat_vec(g, v, rhs);
    for (r, &gam) in rhs.iter_mut().zip(gamma.iter()) {
        let base = if with_gamma { gam } else { 0.0 };
        *r = base - *r;
    }
    check_finite("right-hand side (G or gamma)", rhs)?;
    let mut slot = Slot::default();
    let mut residual = 0.0_f64;
    for b in 0..blocks.len() {
        let (rows, cols, block) = blocks.get(b);
        slot = slot.next(rows.len());
        let k = slot.k.min(N);
        let sol = &mut dx[..k];
        for (s, &i) in sol.iter_mut().zip(rows) {
            *s = rhs[i];
        }
        solve_block(lu, piv, slot, sol, false, what, block)?;
        check_finite("solution", sol)?;
        for (&s, &j) in sol.iter().zip(cols) {
            v[j] = s;
        }
        // The residual of the block's rows, G[rows, cols] v_cols - rhs[rows]: the other columns
        // of G are zero in these rows or went into rhs (the blocks' rows involve only their
        // columns and the given ones), so this is max |G v - base| over the rows.
        let mut gv = [0.0; M];
        let gv = &mut gv[..k.min(M)];
        for (&s, &j) in sol.iter().zip(cols) {
            let gcol = &g.data.0[j];
            for (a, &i) in gv.iter_mut().zip(rows) {
                *a += gcol[i] * s;
            }
        }
        for (&a, &i) in gv.iter().zip(rows) {
            residual = residual.max((a - rhs[i]).abs());
        }
    }
    Ok(residual)
}
