//! The factorizations: a square matrix or block of `G` factored in place (explicit inverse up to
//! order [`linalg::INVERT_MAX`], LU or Cholesky beyond) with its condition number checked
//! against `cond_max`, the slots the blockwise factors live in, and the storage of the
//! eliminations onto the outputs. Above [`plan`](crate::plan), below the model and the solvers.

use nalgebra::SMatrix;

use crate::error::SolverError;
use crate::linalg::{self, LuError};
use crate::plan::invert_block;

/// What a `NonFinite` from a factorisation of `G`'s blocks names.
pub(crate) const G_SOURCE: &str = "G (Jacobian kernel output)";

/// Where the factors of each block live in the workspace: the blocks are packed one after the
/// other, block `b` of order `k_b` at offset `Σ_{c<b} k_c²` of `BlockFactors::lu` (`data.ws.factors`) (at most
/// `(Σ k_b)² <= M²` entries) and its pivots at offset `Σ_{c<b} k_c` of `BlockFactors::piv`, so the
/// factors of every block stay available together (velocity, acceleration and inverse dynamics
/// at one point reuse them).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Slot {
    /// Order of the block (clamped to `M`).
    pub k: usize,
    /// Offset of its factors in the flattened `lu`.
    pub off: usize,
    /// Offset of its pivots in `piv`.
    pub poff: usize,
}

impl Slot {
    /// The slot after this one, for a block of order `k`.
    pub(crate) fn next(&self, k: usize) -> Slot {
        Slot {
            k,
            off: self.off + self.k * self.k,
            poff: self.poff + self.k,
        }
    }
}

/// The factors of a block in its slot, or `Dimension` (unreachable: `Model::try_new` makes the
/// blocks partition the rows, so they fit in `M × M`).
pub(crate) fn slot_mut<'a, const M: usize>(
    lu: &'a mut [[f64; M]; M],
    piv: &'a mut [usize; M],
    slot: Slot,
) -> Result<(&'a mut [f64], &'a mut [usize]), SolverError> {
    let k = slot.k;
    let a = lu.as_flattened_mut().get_mut(slot.off..slot.off + k * k);
    let p = piv.get_mut(slot.poff..slot.poff + k);
    match (a, p) {
        (Some(a), Some(p)) => Ok((a, p)),
        _ => Err(slot_error(slot)),
    }
}

pub(crate) fn slot_ref<'a, const M: usize>(
    lu: &'a [[f64; M]; M],
    piv: &'a [usize; M],
    slot: Slot,
) -> Result<(&'a [f64], &'a [usize]), SolverError> {
    let k = slot.k;
    let a = lu.as_flattened().get(slot.off..slot.off + k * k);
    let p = piv.get(slot.poff..slot.poff + k);
    match (a, p) {
        (Some(a), Some(p)) => Ok((a, p)),
        _ => Err(slot_error(slot)),
    }
}

pub(crate) fn slot_error(slot: Slot) -> SolverError {
    SolverError::Dimension {
        what: "LU workspace",
        expected: slot.off + slot.k * slot.k,
        found: 0,
    }
}

/// Maps a factorisation error to the solver's; `source` names the matrix's origin for
/// `NonFinite`.
pub(crate) fn lu_error(
    e: LuError,
    what: &'static str,
    block: Option<usize>,
    k: usize,
    source: &'static str,
) -> SolverError {
    match e {
        // A zero pivot (LU), or a non-positive pivot of a Gram matrix that must be positive
        // definite when the mechanism is regular (Cholesky of G Gᵀ or G M⁻¹ Gᵀ).
        LuError::Singular { .. } | LuError::NotPositiveDefinite { .. } => SolverError::Singular {
            cond: f64::INFINITY,
            what,
            block,
        },
        LuError::NonFinite => SolverError::NonFinite { what: source },
        // Unreachable: Model::try_new bounds every block by M, the workspace's order.
        LuError::Dimension => SolverError::Dimension {
            what: "LU workspace",
            expected: k * k,
            found: 0,
        },
    }
}

/// How much a factorisation must say about the matrix's condition number.
///
/// Matrices of order at most [`linalg::INVERT_MAX`] (16) factored by [`factor_lu`] are inverted
/// explicitly and get their exact 1-norm condition number in either mode. For larger ones:
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CondMode {
    /// The value is reported: the Hager/Higham estimate.
    Report,
    /// Only the `Singular` decision is needed (intermediate Newton iterates): a rigorous upper
    /// bound from the factors (two triangular solves) certifies the matrix when it is at most
    /// `cond_max / 2`; otherwise the estimator decides, as in `Report`. The decision is the
    /// estimator's either way: a certified matrix has a true condition number, and so an
    /// estimate (a lower bound), below `cond_max`.
    Decide,
}

/// The condition number a factorisation found, and whether it is a reportable value.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Conditioning {
    /// The exact value (small orders), the estimate, or (certified in `CondMode::Decide`) the
    /// upper bound.
    pub cond: f64,
    /// `‖A‖₁`, taken before factoring.
    pub anorm: f64,
    /// `cond` is the exact value or the estimate, not a bound.
    pub reportable: bool,
}

/// The matrices factored by LU (in place) are stored as: the explicit inverse for order at most
/// [`linalg::INVERT_MAX`], the LU factors and pivots otherwise. [`solve_factored`] dispatches.
pub(crate) fn is_small(k: usize) -> bool {
    k <= linalg::INVERT_MAX
}

/// Gathers `G[rows, cols]` into the block's slot of the LU workspace and factors it
/// (see [`factor_lu`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn factor_block<const N: usize, const M: usize>(
    g: &SMatrix<f64, M, N>,
    rows: &[usize],
    cols: &[usize],
    slot: Slot,
    lu: &mut [[f64; M]; M],
    piv: &mut [usize; M],
    work: &mut [[f64; M]; 2],
    cond_max: f64,
    mode: CondMode,
    what: &'static str,
    block: Option<usize>,
) -> Result<Conditioning, SolverError> {
    let k = slot.k;
    let (a, piv) = slot_mut(lu, piv, slot)?;
    let small = match k {
        1 => factor_fixed::<1, N, M>(g, rows, cols, a),
        2 => factor_fixed::<2, N, M>(g, rows, cols, a),
        3 => factor_fixed::<3, N, M>(g, rows, cols, a),
        4 => factor_fixed::<4, N, M>(g, rows, cols, a),
        _ => None,
    };
    if let Some(r) = small {
        let (anorm, inv) = r.map_err(|e| lu_error(e, what, block, k, G_SOURCE))?;
        let cond = check_cond(condition(anorm, inv), cond_max, what, block)?;
        return Ok(Conditioning {
            cond,
            anorm,
            reportable: true,
        });
    }
    for (c, &j) in cols.iter().take(k).enumerate() {
        let gcol = &g.data.0[j];
        for (r, &i) in rows.iter().take(k).enumerate() {
            a[r + c * k] = gcol[i];
        }
    }
    factor_lu(
        a,
        k,
        piv,
        work.as_flattened_mut(),
        cond_max,
        mode,
        what,
        block,
        G_SOURCE,
    )
}

/// The fixed-order path of [`factor_block`] (`K <= linalg::SMALL`): gathers `G[rows, cols]`,
/// inverts it into `out` (`K²` entries, column-major) and returns `(‖A‖₁, ‖A⁻¹‖₁)`; `None` if
/// the index lists do not have `K` entries.
#[inline]
pub(crate) fn factor_fixed<const K: usize, const N: usize, const M: usize>(
    g: &SMatrix<f64, M, N>,
    rows: &[usize],
    cols: &[usize],
    out: &mut [f64],
) -> Option<Result<(f64, f64), LuError>> {
    let rows: &[usize; K] = rows.try_into().ok()?;
    let cols: &[usize; K] = cols.try_into().ok()?;
    let out: &mut [[f64; K]; K] = out.as_chunks_mut::<K>().0.try_into().ok()?;
    Some(
        invert_block::<N, M, K>(g, rows, cols).map(|(inv, anorm, inv_norm)| {
            *out = inv;
            (anorm, inv_norm)
        }),
    )
}

/// Factors the column-major `k × k` matrix `a` in place and checks its 1-norm condition number
/// against `cond_max` (`Singular` above it, `NonFinite { what: source }` for a NaN or infinite
/// entry). Order at most [`linalg::INVERT_MAX`]: explicit inverse and exact condition number;
/// larger: LU with partial pivoting, condition as `mode` asks. `piv.len() == k`,
/// `work.len() >= 2 k`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn factor_lu(
    a: &mut [f64],
    k: usize,
    piv: &mut [usize],
    work: &mut [f64],
    cond_max: f64,
    mode: CondMode,
    what: &'static str,
    block: Option<usize>,
    source: &'static str,
) -> Result<Conditioning, SolverError> {
    let err = |e| lu_error(e, what, block, k, source);
    let anorm = linalg::norm1(a, k).map_err(err)?;
    if !anorm.is_finite() {
        return Err(SolverError::NonFinite { what: source });
    }
    if is_small(k) {
        let inv = linalg::invert_small(a, k).map_err(err)?;
        let cond = check_cond(condition(anorm, inv), cond_max, what, block)?;
        return Ok(Conditioning {
            cond,
            anorm,
            reportable: true,
        });
    }
    linalg::lu_factor(a, k, piv).map_err(err)?;
    if mode == CondMode::Decide {
        let bound = anorm * linalg::lu_inverse_norm1_bound(a, k, piv, work).map_err(err)?;
        if bound <= 0.5 * cond_max {
            return Ok(Conditioning {
                cond: bound,
                anorm,
                reportable: false,
            });
        }
    }
    let cond = linalg::cond1_estimate(a, k, piv, anorm, work).map_err(err)?;
    let cond = check_cond(cond, cond_max, what, block)?;
    Ok(Conditioning {
        cond,
        anorm,
        reportable: true,
    })
}

/// The reportable condition number of a matrix factored by [`factor_lu`] (`a`, `piv` its
/// factors): `c.cond` if it is one, else the Hager/Higham estimate now, with the same
/// `Singular` check.
#[allow(clippy::too_many_arguments)]
pub(crate) fn reported_cond(
    c: Conditioning,
    a: &[f64],
    k: usize,
    piv: &[usize],
    work: &mut [f64],
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<f64, SolverError> {
    if c.reportable {
        return Ok(c.cond);
    }
    let cond = linalg::cond1_estimate(a, k, piv, c.anorm, work)
        .map_err(|e| lu_error(e, what, block, k, G_SOURCE))?;
    check_cond(cond, cond_max, what, block)
}

/// `anorm * inv`, with `+inf` for NaN (`0 * inf`).
pub(crate) fn condition(anorm: f64, inv: f64) -> f64 {
    let cond = anorm * inv;
    if cond.is_nan() { f64::INFINITY } else { cond }
}

/// Solves `A x = b` (or `Aᵀ x = b`) in place with the factors from [`factor_lu`]
/// (`b.len() == k`).
pub(crate) fn solve_factored(
    a: &[f64],
    k: usize,
    piv: &[usize],
    b: &mut [f64],
    transpose: bool,
) -> Result<(), LuError> {
    match (is_small(k), transpose) {
        (true, false) => linalg::small_mul(a, k, b),
        (true, true) => linalg::small_mul_transpose(a, k, b),
        (false, false) => linalg::lu_solve(a, k, piv, b),
        (false, true) => linalg::lu_solve_transpose(a, k, piv, b),
    }
}

/// Cholesky-factors the symmetric column-major `k × k` matrix `a` in place (both triangles
/// given: the 1-norm is taken over the whole matrix) and checks its 1-norm condition number as
/// `mode` asks (the same rules as [`factor_lu`] for orders above [`linalg::SMALL`]; for smaller
/// ones the estimate, which is then exact or nearly so). A non-positive pivot is `Singular` (the
/// Gram matrices factored this way are positive definite exactly when the mechanism is regular),
/// as is an estimate above `cond_max`. Returns the condition number: the estimate, or in
/// `CondMode::Decide` possibly the certifying upper bound.
pub(crate) fn factor_spd(
    a: &mut [f64],
    k: usize,
    work: &mut [f64],
    cond_max: f64,
    mode: CondMode,
    what: &'static str,
    source: &'static str,
) -> Result<f64, SolverError> {
    let err = |e| lu_error(e, what, None, k, source);
    let anorm = linalg::norm1(a, k).map_err(err)?;
    if !anorm.is_finite() {
        return Err(SolverError::NonFinite { what: source });
    }
    linalg::cholesky_factor(a, k).map_err(err)?;
    if mode == CondMode::Decide && k > linalg::SMALL {
        let bound = anorm * linalg::cholesky_inverse_norm1_bound(a, k, work).map_err(err)?;
        if bound <= 0.5 * cond_max {
            return Ok(bound);
        }
    }
    let cond = linalg::cholesky_cond1_estimate(a, k, anorm, work).map_err(err)?;
    check_cond(cond, cond_max, what, None)
}

pub(crate) fn check_cond(
    cond: f64,
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<f64, SolverError> {
    if cond > cond_max || cond.is_nan() {
        return Err(SolverError::Singular { cond, what, block });
    }
    Ok(cond)
}

/// Solves the factored block in its slot in place (`b` has the block's order).
pub(crate) fn solve_block<const M: usize>(
    lu: &[[f64; M]; M],
    piv: &[usize; M],
    slot: Slot,
    b: &mut [f64],
    transpose: bool,
    what: &'static str,
    block: Option<usize>,
) -> Result<(), SolverError> {
    let (a, p) = slot_ref(lu, piv, slot)?;
    solve_factored(a, slot.k, p, b, transpose)
        .map_err(|e| lu_error(e, what, block, slot.k, G_SOURCE))
}

/// The largest inverse-kinematics block [`FkFactors`] handles.
pub(crate) const BMAX: usize = 3;

/// The most outputs [`FkFactors`] handles (`E` is inverted explicitly, by
/// `linalg::invert_small`).
pub(crate) const WMAX: usize = linalg::INVERT_MAX;

/// The factors of `J_p` (forward kinematics) by elimination onto the outputs.
///
/// The rows `R_b` of block `b` involve its `l_b` passive columns `L_b` (the block's columns
/// without its actuated one: the two joint angles of a Stewart leg) and the outputs `z`:
/// `A_b dl_b + G[R_b, z] dz = r_b` with `A_b = J_p[R_b, L_b]`. Completing `A_b` by a column
/// `n_b` orthogonal to it (the cross product of its two columns for a 3 × 2 block) gives an
/// invertible `K_b = [A_b | n_b]`; with `W_b = K_b⁻¹ G[R_b, z]` and `t_b = K_b⁻¹ r_b`, the
/// block's equations are `dl_b = t_b,L - W_b,L dz` and the last row `W_b,n dz = t_b,n`. Stacked
/// over the blocks the last rows are the `P × P` system `E dz = s` (the robot's inverse
/// Jacobian up to row scaling: 6 × 6 for the 6-UPS, one row per leg; 12 × 12 for the two-stage
/// platform). A solve with `J_p` (18 × 18, 36 × 36) then costs one 3 × 3 product per leg and
/// one product with the explicit `E⁻¹`.
///
/// This needs blocks with exactly one actuated column each (`l_b = B - 1`), of order 2 or 3,
/// and at most [`WMAX`] (16) outputs: Stewart platforms (one or two stages), hexapods, deltas,
/// five-bars. Other structures take the dense path.
///
/// The rows over the outputs have the width `W = fk_width(N - M)` (8 or 16) and are stored
/// with that stride, so a robot with few outputs reads the same compact rows whatever
/// [`WMAX`] is.
#[derive(Debug, Clone)]
pub(crate) struct FkFactors<const M: usize> {
    /// Blocks factored (`Structure::ik_blocks.len()`, also `P`) and their order `B`.
    pub nb: usize,
    pub bk: usize,
    /// Per block: its passive columns.
    pub lcols: [[usize; BMAX]; M],
    /// Per block: `K_b⁻¹` (`[column][row]`).
    pub kinv: [[[f64; BMAX]; BMAX]; M],
    /// Per block (at most [`WMAX`]: one per output): `W_b = K_b⁻¹ G[R_b, z]`, row `r` (over the
    /// outputs, zero-padded to `W`) at `r W`; row `B - 1` is the block's row of `E`.
    pub w: [[f64; BMAX * WMAX]; WMAX],
    /// `E⁻¹`, column `c` (zero-padded to `W`) at `c W`.
    pub einv: [f64; WMAX * WMAX],
    /// `‖J_p‖₁`.
    pub anorm: f64,
}

impl<const M: usize> FkFactors<M> {
    pub(crate) fn new() -> Self {
        Self {
            nb: 0,
            bk: 0,
            lcols: [[0; BMAX]; M],
            kinv: [[[0.0; BMAX]; BMAX]; M],
            w: [[0.0; BMAX * WMAX]; WMAX],
            einv: [0.0; WMAX * WMAX],
            anorm: 0.0,
        }
    }
}

/// Scratch of forward dynamics by elimination onto the outputs
/// (`algorithm::forward_dynamics::reduced`): the explicit inverses of the blocks `K_b`, packed one after
/// the other (block `b` of order `k_b` at `Σ_{c<b} k_c²`, column-major; `Σ k_b² <= M²`).
#[derive(Debug, Clone)]
pub(crate) struct FdFactors<const M: usize> {
    pub inv: [[f64; M]; M],
}

impl<const M: usize> FdFactors<M> {
    pub(crate) fn new() -> Self {
        Self { inv: [[0.0; M]; M] }
    }
}
/// The null-space method's buffers and factors (`forward_dynamics::null_space`), in
/// `data.ws.dynamics`: allocated at its first use, reused afterwards.
#[derive(Debug, Clone, Default)]
pub(crate) struct NullSpaceBuffers {
    /// `Gᵀ P = Q R` (N × M column-major): `R` on and above the diagonal, reflectors below.
    pub qr: Vec<f64>,
    pub tau: Vec<f64>,
    pub perm: Vec<usize>,
    /// `Qᵀ M Q` (N × N).
    pub b: Vec<f64>,
    /// The Cholesky factor of the scaled `H` ((N - r)², leading dimension N - r).
    pub h: Vec<f64>,
    /// `D = diag(H)^(-1/2)`.
    pub d: Vec<f64>,
    /// The coordinates' scaling `S`.
    pub scale: Vec<f64>,
    /// The QR (no pivoting) of `R₁ᵀ` (M × r) when `r < M`.
    pub z: Vec<f64>,
    pub ztau: Vec<f64>,
    pub work: Vec<f64>,
    pub rank: usize,
}

/// What the null-space method's factorisation (`forward_dynamics::null_space::factor`)
/// found.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Factored {
    /// The numerical rank of `G`.
    pub rank: usize,
    /// `|r_00| / |r_(r-1)(r-1)|` of the pivoted QR: a lower bound of the condition number of
    /// `G` on its range (1 for `r = 0`).
    pub cond_g: f64,
    /// The Hager/Higham 1-norm estimate of the condition number of the Jacobi-scaled `H`.
    pub cond_h: f64,
}
