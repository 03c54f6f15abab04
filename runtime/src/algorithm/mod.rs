//! The solvers, one module per problem (Pinocchio's `algorithm/`), and the machinery they
//! share: block Newton with backtracking, and blockwise linear solves with a condition check.
//!
//! Every solver reads the model and writes `Data`; on success it commits its result
//! (`data.x`, `data.xdot` or `data.xddot`), on error it leaves that result untouched.

/// `$body` with the constant `$b` bound to `$order` when it is 1, 2, 3 or 4; `$other`
/// otherwise. With a constant `$order` (a robot's `IK_BLOCK_ORDER`, or `M`) only the arm taken
/// is compiled: rustc does not instantiate code under a `match` on a constant that cannot run.
macro_rules! by_order {
    ($order:expr, $b:ident => $body:expr, _ => $other:expr) => {
        match $order {
            1 => {
                const $b: usize = 1;
                $body
            }
            2 => {
                const $b: usize = 2;
                $body
            }
            3 => {
                const $b: usize = 3;
                $body
            }
            4 => {
                const $b: usize = 4;
                $body
            }
            _ => $other,
        }
    };
}

/// [`by_order!`] on the order of robot `$k`'s inverse-kinematics blocks: the order it declares
/// (`IK_BLOCK_ORDER`, a constant: one size compiled per robot), or the one `$ik` (its
/// `Structure::ik_blocks`) has when it declares none.
macro_rules! by_ik_order {
    ($k:ty, $ik:expr, $b:ident => $body:expr, _ => $other:expr) => {
        match <$k as $crate::tasks::Robot<N, M>>::IK_BLOCK_ORDER {
            $crate::kernels::IK_BLOCK_ORDER_UNDECLARED => by_order!(
                $crate::algorithm::uniform_order($ik).unwrap_or(0),
                $b => $body,
                _ => $other
            ),
            _ => by_order!(
                <$k as $crate::tasks::Robot<N, M>>::IK_BLOCK_ORDER,
                $b => $body,
                _ => $other
            ),
        }
    };
}

pub mod certify;
pub mod fk_robust;
pub mod forward_dynamics;
pub mod forward_kinematics;
mod generated;
pub mod inverse_dynamics;
pub mod inverse_kinematics;
pub mod projection;
pub(crate) mod reach;
pub(crate) mod reduced;

pub use forward_dynamics::{forward_dynamics, forward_dynamics_schur};
pub use forward_kinematics::{forward_acceleration, forward_kinematics, forward_velocity};
pub use inverse_dynamics::{inverse_dynamics, inverse_dynamics_dense, inverse_dynamics_full};
pub use inverse_kinematics::{
    KinematicsReport, inverse_acceleration, inverse_kinematics, inverse_kinematics_full,
    inverse_velocity,
};
pub use projection::{project_position, project_velocity};

use nalgebra::SMatrix;

use crate::data::{BlockState, Data, Workspace};
use crate::error::SolverError;
use crate::kernels::IkBlock;
use crate::linalg::{self, LuError};
use crate::model::Model;
use crate::tasks::{Constraints, EquationsOfMotion, Robot};

/// What a successful solve reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    /// Newton steps taken (inverse kinematics: by the slowest block); `0` for the velocity and
    /// acceleration solves, which are direct.
    pub iterations: usize,
    /// Kernel evaluations. Newton solves: `constraints` + Jacobian pairs, line-search trials
    /// included, so `evaluations - iterations - 1` steps were shortened by backtracking (one
    /// more `constraints` call, not counted, measures the final residual). Direct solves: `1`.
    pub evaluations: usize,
    /// The residual at the returned solution: `max |f(X)|` for the position solvers,
    /// `max |G Ẋ|` for velocity, `max |G Ẍ - gamma|` for acceleration.
    pub residual: f64,
    /// The largest 1-norm condition number among the matrices factored at the returned
    /// solution (`J_p`, or the worst inverse-kinematics block): exact for blocks of order up to
    /// 3, and up to 16 where the runtime's own factorisation ran; for larger blocks solved by
    /// the generated code (`Kernels::ik_block_solve`) the pivots' value `‖K‖₁ max_c 1 / |u_cc|`,
    /// the Hager/Higham estimate where that passes 1e3; the Hager/Higham estimate for the dense
    /// paths (see `SolverOptions::cond_max`). For `J_p` solved by the generated elimination onto
    /// the outputs (forward kinematics and its rates): its rigorous upper bound, free with the
    /// solve (6 to 90 times the exact value at the states measured), unless
    /// `SolverOptions::exact_cond` asks for the exact value; the runtime's own elimination
    /// reports the exact value.
    pub cond: f64,
}

/// Which algorithm a dynamics solve used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DynamicsMethod {
    /// Inverse dynamics by block elimination: one transposed solve per inverse-kinematics
    /// block `G_kk`, then the small reduced system in `U` (order `N - M`).
    BlockElimination,
    /// Inverse dynamics by a dense LU of the N × N matrix `[S | Gᵀ]`.
    DenseLu,
    /// Forward dynamics by the Schur complement `G M⁻¹ Gᵀ` on the block-diagonal `M`.
    SchurComplement,
    /// Forward dynamics by elimination onto the outputs' coordinates: the inverse-kinematics
    /// blocks of `G` eliminated, the small reduced mass matrix `Rᵀ M R` (order: the number of
    /// outputs, 6 for the 6-UPS) solved explicitly.
    Reduced,
    /// Forward dynamics by a dense LU of the whole saddle-point system `[M Gᵀ; G 0]`, when `M`
    /// has massless coordinates (a frame that only closes loops, such as a serial arm's
    /// end-effector pose) and so is only positive semi-definite.
    SaddlePoint,
}

/// What a successful dynamics solve ([`inverse_dynamics()`], [`forward_dynamics()`]) reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicsReport {
    /// The algorithm used.
    pub method: DynamicsMethod,
    /// Conditioning of the small blocks.
    ///
    /// - Inverse dynamics: the largest 1-norm condition number of the inverse-kinematics
    ///   blocks `G_kk` (block elimination; exact for blocks up to 16 × 16). When a block was
    ///   singular and the solve fell back to the dense LU, the value of that block (`inf` for a
    ///   zero pivot).
    /// - Forward dynamics by elimination onto the outputs ([`DynamicsMethod::Reduced`]): the
    ///   largest 1-norm condition number of the inverse-kinematics blocks `K_b` (exact: they are
    ///   inverted explicitly). By the Schur complement: `max l_ii² / min l_ii²` over the
    ///   Cholesky pivots of all blocks of `M`, a lower bound of the 2-norm condition number of
    ///   `M` (exact for a diagonal `M`).
    pub cond_blocks: f64,
    /// The 1-norm condition number of the main system: the reduced `U` system (block
    /// elimination) or `[S | Gᵀ]` (dense LU) of inverse dynamics, exact for orders up to 16
    /// (`linalg::INVERT_MAX`, the 6 × 6 reduced system of the 6-UPS), else the Hager/Higham
    /// estimate; for forward dynamics `S_c = G M⁻¹ Gᵀ`: exact after its structured solve, the
    /// estimate after the dense one (see [`forward_dynamics()`]), and after the elimination
    /// onto the outputs ([`DynamicsMethod::Reduced`]) that of the reduced mass matrix `Rᵀ M R`
    /// that path solves with: its Cholesky pivot ratio `(max l_ii / min l_ii)²` (a lower bound
    /// of the 2-norm value, free with the factor), the Hager/Higham 1-norm estimate when that
    /// ratio passes `cond_max / 100` or 1e6 (the elimination declines above `cond_max`, and the
    /// Schur complement decides `Singular` on the constraints' rank).
    /// Above `SolverOptions::cond_max` the solve fails with `Singular` instead.
    pub cond: f64,
    /// The residual of the solved equations at the result. Inverse dynamics:
    /// `max |M Ẍ - psi - Q - S U + Gᵀ lambda|` (forces). Forward dynamics:
    /// `max |G Ẍ - gamma_stab|` (the acceleration constraint, with Baumgarte's terms).
    pub residual: f64,
}

/// Baumgarte's constraint stabilisation in forward dynamics: the acceleration constraint
/// `G Ẍ = gamma` becomes `G Ẍ = gamma - 2 alpha G Ẋ - beta² f(X)`, so that the constraint
/// error `e = f(X)` obeys `ë + 2 alpha ė + beta² e = 0` instead of `ë = 0`.
///
/// `alpha = beta = 0` ([`Baumgarte::NONE`], the default) is the plain index-1 system. With
/// `alpha = beta = ω` the error decays critically damped with time constant `1/ω`; an explicit
/// integrator then needs `ω h` well inside its stability region (RK4 and DOPRI5: about 2.8 and
/// 3.3 on the negative real axis). See [`Baumgarte::DEFAULT`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Baumgarte {
    /// Damping gain `alpha` (1/s).
    pub alpha: f64,
    /// Stiffness gain `beta` (1/s).
    pub beta: f64,
}

impl Baumgarte {
    /// No stabilisation.
    pub const NONE: Self = Self {
        alpha: 0.0,
        beta: 0.0,
    };

    /// `alpha = beta = 10 /s`: critically damped, time constant 0.1 s.
    ///
    /// Why 10, measured on the paper's round trip (`TraekP` over 2 s, feed-forward `U` from
    /// inverse dynamics; `runtime/tests/dynamics.rs`), sweeping `ω` over 1, 2, 5, 10, 20, 50,
    /// 100 /s:
    ///
    /// - the drift comes from integration error, and the violation settles near
    ///   (local error rate) / ω²: at `ω = 10` the largest `|f|` is about 100 times smaller than
    ///   without stabilisation for RK4 (`dt` 1e-2 and 1e-3) and DOPRI5 (rtol 1e-4 to 1e-8);
    /// - but the stabilised system gains a double eigenvalue `-ω` that the integrator must
    ///   resolve: with RK4 at `dt = 1e-2` the violation is smallest at `ω` = 5 to 10 and grows
    ///   again beyond (3e-7 at 50 /s, worse than 1.1e-8 at 10 /s); DOPRI5's error control
    ///   shortens its steps, costing +40 % right-hand-side evaluations at `ω = 10` (rtol 1e-6),
    ///   +110 % at 20 and +330 % at 50.
    pub const DEFAULT: Self = Self {
        alpha: 10.0,
        beta: 10.0,
    };

    /// Critically damped gains `alpha = beta = omega`.
    pub const fn critical(omega: f64) -> Self {
        Self {
            alpha: omega,
            beta: omega,
        }
    }
}

impl Default for Baumgarte {
    fn default() -> Self {
        Self::NONE
    }
}

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

/// Levenberg–Marquardt's damping `mu` with Nielsen's update from the gain ratio `rho`:
/// `mu *= max(1/3, 1 - (2 rho - 1)³)` on an accepted step, `mu *= nu, nu *= 2` on a rejected
/// one (forward kinematics by LM, and the reach search after a failed IK).
pub(crate) struct Damping {
    /// The damping; `0` until the caller sets it from the first `JᵀJ`.
    pub mu: f64,
    nu: f64,
}

impl Damping {
    pub fn new() -> Self {
        Self { mu: 0.0, nu: 2.0 }
    }

    /// An accepted step with gain ratio `rho > 0`.
    pub fn accept(&mut self, rho: f64) {
        let t = 2.0 * rho - 1.0;
        self.mu = (self.mu * (1.0 / 3.0_f64).max(1.0 - t * t * t)).max(1e-300);
        self.nu = 2.0;
    }

    /// A rejected step (no decrease, or the damped system could not be solved).
    pub fn reject(&mut self) {
        self.mu *= self.nu;
        self.nu *= 2.0;
    }
}

/// The common order of the inverse-kinematics blocks, if they have one (the fixed-size paths
/// dispatch on it).
pub(crate) fn uniform_order(ik: &[IkBlock]) -> Option<usize> {
    let k = ik.first()?.rows.len();
    ik.iter().all(|b| b.rows.len() == k).then_some(k)
}

impl Blocks<'_> {
    fn len(&self) -> usize {
        match self {
            Blocks::Ik(b) => b.len(),
            Blocks::Single { .. } => 1,
        }
    }

    /// `(rows, cols, block index for errors)`; `b < self.len()`.
    fn get(&self, b: usize) -> (&[usize], &[usize], Option<usize>) {
        match self {
            Blocks::Ik(blocks) => match blocks.get(b) {
                Some(blk) => (blk.rows, blk.cols, Some(b)),
                None => (&[], &[], Some(b)),
            },
            Blocks::Single { rows, cols } => (rows, cols, None),
        }
    }
}

/// Where the factors of each block live in the workspace: the blocks are packed one after the
/// other, block `b` of order `k_b` at offset `Σ_{c<b} k_c²` of `Workspace::lu` (at most
/// `(Σ k_b)² <= M²` entries) and its pivots at offset `Σ_{c<b} k_c` of `Workspace::piv`, so the
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
    fn next(&self, k: usize) -> Slot {
        Slot {
            k,
            off: self.off + self.k * self.k,
            poff: self.poff + self.k,
        }
    }
}

/// The factors of a block in its slot, or `Dimension` (unreachable: `Model::try_new` makes the
/// blocks partition the rows, so they fit in `M × M`).
fn slot_mut<'a, const M: usize>(
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

fn slot_ref<'a, const M: usize>(
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

fn slot_error(slot: Slot) -> SolverError {
    SolverError::Dimension {
        what: "LU workspace",
        expected: slot.off + slot.k * slot.k,
        found: 0,
    }
}

/// Cap on `SolverOptions::max_step_halvings`: a step of `2^-60` is below rounding anyway.
const MAX_HALVINGS: u32 = 60;

/// The fused kernel of a Newton solve: `constraints` and a column subset of `G` at once
/// (`Kernels::constraints_jacobian_ik` or `Kernels::constraints_jacobian_p`).
pub(crate) type NewtonKernel<K, const N: usize, const M: usize> =
    fn(&K, &[f64; N], &mut [f64; M], &mut [[f64; M]; N]);

/// What a `NonFinite` from a factorisation of `G`'s blocks names.
const G_SOURCE: &str = "G (Jacobian kernel output)";

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
    anorm: f64,
    /// `cond` is the exact value or the estimate, not a bound.
    reportable: bool,
}

/// The matrices factored by LU (in place) are stored as: the explicit inverse for order at most
/// [`linalg::INVERT_MAX`], the LU factors and pivots otherwise. [`solve_factored`] dispatches.
fn is_small(k: usize) -> bool {
    k <= linalg::INVERT_MAX
}

/// Gathers `G[rows, cols]` into the block's slot of the LU workspace and factors it
/// (see [`factor_lu`]).
#[allow(clippy::too_many_arguments)]
fn factor_block<const N: usize, const M: usize>(
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
fn factor_fixed<const K: usize, const N: usize, const M: usize>(
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
fn reported_cond(
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
fn condition(anorm: f64, inv: f64) -> f64 {
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
fn solve_block<const M: usize>(
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

/// `out = G v` by columns, using the structure of `G`: column `j` is zero outside the rows of
/// its inverse-kinematics block (`Model::ik_block_of`; a dense column for an output).
pub(crate) fn mat_vec_structured<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    v: &[f64; N],
    out: &mut [f64; M],
) {
    let blocks = model.structure().ik_blocks;
    out.fill(0.0);
    for ((col, &vj), &b) in g.data.0.iter().zip(v).zip(&model.ik_block_of) {
        match blocks.get(b) {
            Some(blk) => {
                for &i in blk.rows {
                    out[i] += col[i] * vj;
                }
            }
            None => {
                for (o, &gij) in out.iter_mut().zip(col) {
                    *o += gij * vj;
                }
            }
        }
    }
}

/// `(Gᵀ l)_j`, using the structure of `G` as [`mat_vec_structured`] does.
pub(crate) fn col_dot_structured<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    j: usize,
    l: &[f64; M],
) -> f64 {
    let col = &g.data.0[j];
    match model
        .ik_block_of
        .get(j)
        .and_then(|&b| model.structure().ik_blocks.get(b))
    {
        Some(blk) => blk.rows.iter().map(|&i| col[i] * l[i]).sum(),
        None => dot(col, l),
    }
}

/// `Σ a_i b_i` over the common length, with four partial sums (see [`linalg::dot4`]).
pub(crate) use crate::linalg::dot4 as dot;

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

/// Newton's method on independent blocks, from the iterate `data.ws.x` (set by the caller,
/// finite). Each evaluation calls the fused `kernel` (`constraints` and the Jacobian columns)
/// once for all blocks; each unconverged block then either tests its trial step (backtracking)
/// or takes a Newton step. Converged blocks stop updating; the step that passes the convergence
/// test is applied, and one more `constraints` call measures the returned residual. On success
/// `data.ws.x` is the solution, `data.f` is `f` there, and `data.g` is the Jacobian one (tiny)
/// step before it.
///
/// When every block has the same order `B <= linalg::SMALL` (3 for a Stewart platform, 2 for a
/// five-bar), the loop is compiled for that order: the blocks are gathered, inverted and
/// applied in registers, without a loop over a run-time length.
pub(crate) fn newton<K: Constraints<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Result<SolveReport, SolverError> {
    match blocks {
        Blocks::Ik(ik) => {
            by_ik_order!(K, ik, B => match newton_fixed::<K, N, M, B>(model, data, ik, kernel, what) {
            Some(r) => r,
            None => newton_impl::<K, N, M, B>(model, data, blocks, kernel, what),
        }, _ => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what))
        }
        // Forward kinematics: one system of all M rows.
        Blocks::Single { rows, .. } if rows.len() == M => by_order!(M, B =>
            newton_impl::<K, N, M, B>(model, data, blocks, kernel, what),
            _ => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what)),
        Blocks::Single { .. } => newton_impl::<K, N, M, 0>(model, data, blocks, kernel, what),
    }
}

/// [`newton`] on inverse-kinematics blocks all of order `B` (`None`: they are not; nothing
/// done), with the blocks' index lists as arrays: the same iteration as [`newton_impl`], every
/// per-block loop of compile-time length.
fn newton_fixed<K: Constraints<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    ik: &[IkBlock],
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Option<Result<SolveReport, SolverError>> {
    let nb = ik.len();
    if nb > M {
        return None;
    }
    let mut idx = [([0_usize; B], [0_usize; B]); M];
    for (slot, blk) in idx.iter_mut().zip(ik) {
        *slot = (blk.rows.try_into().ok()?, blk.cols.try_into().ok()?);
    }
    let idx = &idx[..nb];
    let o = model.options;
    let kern = model.kernels();
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        x_base,
        dx,
        blocks: states,
        ..
    } = ws;
    let states = &mut states[..nb];
    states.fill(BlockState::default());
    let mut evaluations = 0;
    let fail = |e| Some(Err(e));
    loop {
        kernel(kern, x, f, &mut g.data.0);
        evaluations += 1;
        let mut done = true;
        for (b, (st, (rows, cols))) in states.iter_mut().zip(idx).enumerate() {
            if st.converged {
                continue;
            }
            let fb: [f64; B] = core::array::from_fn(|i| f[rows[i]]);
            let (mut rmax, mut r2) = (0.0_f64, 0.0_f64);
            for &v in &fb {
                rmax = rmax.max(v.abs());
                r2 += v * v;
            }
            if r2.is_nan() || rmax == f64::INFINITY {
                return fail(SolverError::NonFinite {
                    what: "f (constraint kernel output)",
                });
            }
            let rnorm = r2.sqrt();
            if st.trial {
                let accept = rmax <= o.tol_f
                    || rnorm <= (1.0 - 1e-4 * st.alpha) * st.norm_base
                    || st.halvings >= o.max_step_halvings.min(MAX_HALVINGS);
                if !accept {
                    st.alpha *= 0.5;
                    st.halvings += 1;
                    for &j in cols {
                        x[j] = x_base[j] + st.alpha * dx[j];
                    }
                    done = false;
                    continue;
                }
                st.trial = false;
            }

            // Newton step at x: G_b dx = -f_b.
            let (inv, anorm, inv_norm) = match invert_block::<N, M, B>(g, rows, cols) {
                Ok(r) => r,
                Err(e) => return fail(lu_error(e, what, Some(b), B, G_SOURCE)),
            };
            let cond = match check_cond(condition(anorm, inv_norm), o.cond_max, what, Some(b)) {
                Ok(c) => c,
                Err(e) => return fail(e),
            };
            let step = linalg::mul_fixed(&inv, &fb);
            let (mut dmax, mut xmax, mut finite) = (0.0_f64, 0.0_f64, true);
            for (&d, &j) in step.iter().zip(cols) {
                dmax = dmax.max(d.abs());
                xmax = xmax.max(x[j].abs());
                finite &= d.is_finite();
                dx[j] = -d;
            }
            if !finite {
                return fail(SolverError::NonFinite {
                    what: "Newton step",
                });
            }
            if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + xmax) {
                // Converged; the last, tiny step is still applied.
                st.converged = true;
                st.cond = cond;
                for &j in cols {
                    x[j] += dx[j];
                }
                continue;
            }
            if st.steps >= o.max_iterations {
                return fail(SolverError::NotConverged {
                    iterations: st.steps,
                    residual: max_abs(f),
                });
            }
            st.steps += 1;
            st.trial = true;
            st.alpha = 1.0;
            st.halvings = 0;
            st.norm_base = rnorm;
            for &j in cols {
                x_base[j] = x[j];
                x[j] += dx[j];
            }
            done = false;
        }
        if done {
            break;
        }
    }
    // The residual at the returned point, after the final steps.
    kern.constraints(x, f);
    if !all_finite(f) {
        return fail(SolverError::NonFinite {
            what: "f (constraint kernel output)",
        });
    }
    let mut rep = SolveReport {
        iterations: 0,
        evaluations,
        residual: 0.0,
        cond: 0.0,
    };
    for (st, (rows, _)) in states.iter().zip(idx) {
        for &i in rows {
            rep.residual = rep.residual.max(f[i].abs());
        }
        rep.iterations = rep.iterations.max(st.steps);
        rep.cond = rep.cond.max(st.cond);
    }
    Some(Ok(rep))
}

/// [`newton`] for blocks of order `B` (`B = 0`: any order, factored in the workspace).
fn newton_impl<K: Constraints<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: Blocks<'_>,
    kernel: NewtonKernel<K, N, M>,
    what: &'static str,
) -> Result<SolveReport, SolverError> {
    let o = model.options;
    let kern = model.kernels();
    let Data { f, g, ws, .. } = data;
    let Workspace {
        x,
        x_base,
        dx,
        rhs,
        lu,
        piv,
        work,
        blocks: states,
        fk,
        ..
    } = ws;
    let nb = blocks.len().min(M);
    let states = &mut states[..nb];
    states.fill(BlockState::default());
    let mut evaluations = 0;
    loop {
        kernel(kern, x, f, &mut g.data.0);
        evaluations += 1;
        let mut done = true;
        let mut slot = Slot::default();
        for (b, st) in states.iter_mut().enumerate() {
            let (rows, cols, block) = blocks.get(b);
            slot = slot.next(rows.len());
            if st.converged {
                continue;
            }
            let (mut rmax, mut r2) = (0.0_f64, 0.0_f64);
            for &i in rows {
                let v = f[i];
                rmax = rmax.max(v.abs());
                r2 += v * v;
            }
            if r2.is_nan() || rmax == f64::INFINITY {
                return Err(SolverError::NonFinite {
                    what: "f (constraint kernel output)",
                });
            }
            let rnorm = r2.sqrt();
            if st.trial {
                let accept = rmax <= o.tol_f
                    || rnorm <= (1.0 - 1e-4 * st.alpha) * st.norm_base
                    || st.halvings >= o.max_step_halvings.min(MAX_HALVINGS);
                if !accept {
                    st.alpha *= 0.5;
                    st.halvings += 1;
                    for &j in cols {
                        x[j] = x_base[j] + st.alpha * dx[j];
                    }
                    done = false;
                    continue;
                }
                st.trial = false;
            }

            // Newton step at x: G_b dx = -f_b.
            let k = slot.k;
            let step = &mut rhs[..k];
            // Forward kinematics: J_p by elimination onto the outputs when it certifies itself.
            let mut structured = false;
            let cond = if B > 0 {
                newton_step_fixed::<N, M, B>(g, f, rows, cols, step, o.cond_max, what, block)?
            } else if let (Blocks::Ik(_), Some(b)) = (blocks, block)
                && let Some(cond) =
                    generated::ik_newton_step(kern, b, cols, &g.data.0, f, dx, step, o.cond_max)
            {
                // The block solve the generator emitted; its condition number is reportable.
                Conditioning {
                    cond,
                    anorm: 0.0,
                    reportable: true,
                }
            } else if let Blocks::Single { .. } = blocks
                && let Some(cond) = generated::fk_newton_step(
                    kern,
                    cols,
                    &g.data.0,
                    f,
                    dx,
                    step,
                    o.cond_max,
                    rmax <= o.tol_f && o.exact_cond,
                )
            {
                // The elimination the generator emitted: its rigorous upper bound decides
                // `Singular` while the residual is above `tol_f`; the step that can converge
                // reports the bound, or the exact condition number if the options ask for it
                // (`SolverOptions::exact_cond`). Where the bound does not certify, the
                // runtime's own elimination and then the LU decide on the exact value or the
                // estimate.
                Conditioning {
                    cond,
                    anorm: 0.0,
                    reportable: rmax <= o.tol_f,
                }
            } else if let Blocks::Single { .. } = blocks
                && let Some(bound) = reduced::fk_factor(model, g, fk, o.cond_max)
            {
                structured = true;
                let minus_f: [f64; M] = core::array::from_fn(|i| -f[i]);
                let mut d = [0.0; N];
                reduced::fk_solve(model, fk, &minus_f, &mut d);
                for (sv, &j) in step.iter_mut().zip(cols) {
                    *sv = d[j];
                }
                Conditioning {
                    cond: bound,
                    anorm: 0.0,
                    reportable: false,
                }
            } else {
                let c = factor_block(
                    g,
                    rows,
                    cols,
                    slot,
                    lu,
                    piv,
                    work,
                    o.cond_max,
                    CondMode::Decide,
                    what,
                    block,
                )?;
                for (s, &i) in step.iter_mut().zip(rows) {
                    *s = -f[i];
                }
                solve_block(lu, piv, slot, step, false, what, block)?;
                c
            };
            let (mut dmax, mut xmax, mut finite) = (0.0_f64, 0.0_f64, true);
            for (&d, &j) in step.iter().zip(cols) {
                dmax = dmax.max(d.abs());
                xmax = xmax.max(x[j].abs());
                finite &= d.is_finite();
                dx[j] = d;
            }
            if !finite {
                return Err(SolverError::NonFinite {
                    what: "Newton step",
                });
            }
            if rmax <= o.tol_f && dmax <= o.tol_x * (1.0 + xmax) {
                // Converged; the last, tiny step is still applied: it costs nothing and
                // Newton's quadratic convergence makes the solution far more accurate.
                st.converged = true;
                st.cond = if structured {
                    check_cond(reduced::fk_cond::<N, M>(fk), o.cond_max, what, block)?
                } else if B > 0 {
                    cond.cond
                } else {
                    let (a, p) = slot_ref(lu, piv, slot)?;
                    reported_cond(
                        cond,
                        a,
                        k,
                        p,
                        work.as_flattened_mut(),
                        o.cond_max,
                        what,
                        block,
                    )?
                };
                for &j in cols {
                    x[j] += dx[j];
                }
                continue;
            }
            if st.steps >= o.max_iterations {
                return Err(SolverError::NotConverged {
                    iterations: st.steps,
                    residual: max_abs(f),
                });
            }
            st.steps += 1;
            st.trial = true;
            st.alpha = 1.0;
            st.halvings = 0;
            st.norm_base = rnorm;
            for &j in cols {
                x_base[j] = x[j];
                x[j] += dx[j];
            }
            done = false;
        }
        if done {
            break;
        }
    }
    // The residual at the returned point, after the final steps.
    kern.constraints(x, f);
    check_finite("f (constraint kernel output)", f)?;
    let mut rep = SolveReport {
        iterations: 0,
        evaluations,
        residual: 0.0,
        cond: 0.0,
    };
    for (b, st) in states.iter().enumerate() {
        let (rows, _, _) = blocks.get(b);
        for &i in rows {
            rep.residual = rep.residual.max(f[i].abs());
        }
        rep.iterations = rep.iterations.max(st.steps);
        rep.cond = rep.cond.max(st.cond);
    }
    Ok(rep)
}

/// The Newton step `step = -G_b⁻¹ f_b` of a block of order `B <= linalg::SMALL`, with the exact
/// condition number of `G_b` checked against `cond_max`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn newton_step_fixed<const N: usize, const M: usize, const B: usize>(
    g: &SMatrix<f64, M, N>,
    f: &[f64; M],
    rows: &[usize],
    cols: &[usize],
    step: &mut [f64],
    cond_max: f64,
    what: &'static str,
    block: Option<usize>,
) -> Result<Conditioning, SolverError> {
    let (Ok(rows), Ok(cols), Ok(step)) = (
        <&[usize; B]>::try_from(rows),
        <&[usize; B]>::try_from(cols),
        <&mut [f64; B]>::try_from(step),
    ) else {
        return Err(slot_error(Slot {
            k: B,
            off: 0,
            poff: 0,
        }));
    };
    let (inv, anorm, inv_norm) = invert_block::<N, M, B>(g, rows, cols)
        .map_err(|e| lu_error(e, what, block, B, G_SOURCE))?;
    let cond = check_cond(condition(anorm, inv_norm), cond_max, what, block)?;
    let minus_f: [f64; B] = core::array::from_fn(|i| -f[rows[i]]);
    *step = linalg::mul_fixed(&inv, &minus_f);
    Ok(Conditioning {
        cond,
        anorm,
        reportable: true,
    })
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
            &mut ws.lu,
            &mut ws.piv,
            &mut ws.work,
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
    let Workspace { x: v, rhs, lu, .. } = ws;
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
        lu,
        piv,
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
