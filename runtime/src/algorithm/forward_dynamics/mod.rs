//! Forward dynamics (paper eqs. 29-32): given the state `X, Ẋ`, the control forces `U` and the
//! applied forces `Q`, find `Ẍ` and the Lagrange multipliers `lambda` of the saddle-point system
//!
//! ```text
//! M Ẍ + Gᵀ lambda = F,   F = psi(X, Ẋ) + Q + S U
//! G Ẍ             = gamma_stab = gamma(X, Ẋ) - 2 alpha G Ẋ - beta² f(X)
//! ```
//!
//! # Accuracy: every answer carries its backward error
//!
//! Whatever path answers, its answer is checked by the residuals of both equations,
//! `r1 = F - M Ẍ - Gᵀ lambda` and `r2 = gamma_stab - G Ẍ`, and the report carries the normwise
//! relative backward error (∞-norms; `‖Gᵀ‖∞` is the largest column sum of `G`)
//!
//! ```text
//! eta = max( ‖r1‖ / (‖M‖ ‖Ẍ‖ + ‖Gᵀ‖ ‖lambda‖ + ‖F‖),  ‖r2‖ / (‖G‖ ‖Ẍ‖ + ‖gamma_stab‖) )
//! ```
//!
//! ([`DynamicsReport::backward_error`](super::DynamicsReport::backward_error)): the answer is
//! the exact solution of a system whose `M, G, F, gamma_stab` differ from the given ones by
//! `eta` relative, so its error is at most `eta` times the problem's own condition number. The
//! generated solve forms `eta` of its answer itself (`SolveConditioning::backward_error`: the
//! residuals and norms over the structural non-zeros, known at generation), and the runtime
//! only compares; for the other paths, and a generated solve that reports none (NaN), the
//! runtime forms it over the structure (`M` by its blocks, `G` by the inverse-kinematics
//! blocks' rows). On the 6-UPS the generated residuals and norms cost about 1 500
//! instructions beside the solve's 6 100 (`docs/benchmarks-robust-dynamics.md`; formed here
//! they cost 4 300). Above [`REFINE_ABOVE`] (1e-14, about
//! 45 ε) the answer is refined: at most two steps of iterative refinement, each solving for the
//! correction from `(r1, r2)` with the same path (the null-space method and the saddle-point LU
//! reuse their factors; the eliminations re-run theirs), kept only while `eta` decreases. If
//! `eta` is still above `SolverOptions::backward_error_max` (default 1e-12), the null-space
//! method below is tried (refined the same way), and if that too stays above the bound the
//! solve fails with `SolverError::Inaccurate`, which states the accuracy reached.
//!
//! # The paths
//!
//! First choice: the same elimination as generated code, when the robot has it
//! ([`Dynamics::forward_dynamics_solve`](crate::Dynamics::forward_dynamics_solve), emitted by
//! codegen's `solve` module over the structural non-zeros of `G` and `M`, one function per kind
//! of inverse-kinematics block): it is taken when it answers, its blocks' condition numbers are
//! at most `reduced::FD_K_COND_MAX` and the pivot ratio of `Rᵀ M R` passes the check below;
//! the kernel outputs are checked for NaN and infinities only when it declines or its results
//! are not finite (a non-finite kernel output ends in its results). When its backward error is
//! at most [`REFINE_ABOVE`] (every state of the 6-UPS) that is the whole cost: the generated
//! solve, which forms its residuals and backward error itself. Otherwise, the runtime's own
//! code:
//!
//! Elimination onto the outputs' coordinates (`reduced.rs`): with the
//! inverse-kinematics blocks of `G` inverted explicitly (any order up to 16), `Ẍ = R z̈ + r0`
//! and the small SPD system `(Rᵀ M R) z̈ = Rᵀ (F - M r0)` (6 × 6 for the 6-UPS, 12 × 12 for the
//! two-stage robot), `lambda` from one transposed product per block. It needs no factor of `M`
//! (massless frames, such as a serial arm's tool pose, take it too) and runs whenever every
//! block's condition number is at most `reduced::FD_K_COND_MAX` (a serial singularity is not
//! one of forward dynamics, but the elimination's rounding grows with it); its checks come with
//! its factors. Otherwise, when a block of `M` is exactly zero (massless coordinates), the
//! null-space method; else the Schur complement on the block-diagonal `M`
//! (`Dynamics::mass_blocks`, `schur.rs`), and when that refuses (`S_c = G M⁻¹ Gᵀ` above
//! `cond_max`: its condition number is about that of `M` times that of `G` squared, so a thin
//! rod's 1e-6 kg m² spin alone can push it to 1e10 on a well-posed problem) the null-space
//! method:
//!
//! 1. Cholesky `M_b = L_b L_bᵀ` of every block (for the 6-UPS all blocks but one are 1 × 1);
//! 2. `Z = L⁻¹ Gᵀ` (N × M) and `z_F = L⁻¹ F`, blockwise forward substitutions;
//! 3. `S_c = G M⁻¹ Gᵀ = Zᵀ Z` (M × M, symmetric positive definite when `G` has full rank) and
//!    `S_c lambda = Zᵀ z_F - gamma_stab`;
//! 4. `Ẍ = L⁻ᵀ (z_F - Z lambda)`, blockwise back substitutions.
//!
//! The rows `z_j` of `Z` are sparse: a column of `G` is zero outside the constraint rows of
//! its inverse-kinematics block (a leg of a Stewart platform), so `z_j` of a mass block within
//! one inverse-kinematics block is too, and only the rows of the outputs (and of mass blocks
//! that couple several legs) are dense. Hence `S_c = D + W Wᵀ` with `D` block diagonal (one
//! small block `D_k` per leg) and `W` the few dense rows (6 for the 6-UPS). Step 3 solves
//! with `S_c` by the Sherman–Morrison–Woodbury identity on that structure (small explicit
//! inverses, no M × M factorisation), after certifying the condition number of `S_c` by a
//! rigorous upper bound, and reports its exact condition number, formed from the same
//! structure (see [`DynamicsReport::cond`](super::DynamicsReport::cond)). When the structure
//! does not apply (blocks of different orders or above 4 × 4, more than 8 dense rows, a
//! singular `D_k` or one with a condition number above 1e4, e.g. near a singularity of a leg's
//! inverse kinematics, which forward dynamics does not care about) or the bound does not
//! certify `S_c`, `S_c` is formed (sparse rows: a small update each) and factored by a dense
//! Cholesky with the Hager/Higham condition estimate.
//!
//! # The fallback, and how `Singular` is decided
//!
//! The null-space method (`null_space.rs`, [`DynamicsMethod::NullSpace`]): the coordinates
//! scaled by `1 / sqrt(M_jj)`, a Householder QR with column pivoting of `Gᵀ` (`Gᵀ P = Q R`,
//! the numerical rank `r` of `G` where `R`'s remaining column norms fall below 1e-12 of the
//! largest), the constraint rows from `R₁₁ᵀ`, the projected mass matrix
//! `H = Q₂ᵀ M Q₂` (`Q₂` an orthonormal basis of `null(G)`) by Cholesky, the multipliers from
//! `Q₁ᵀ (F - M Ẍ) = R₁ Pᵀ lambda`. It never forms `G M⁻¹ Gᵀ` and needs no factor of `M`.
//!
//! - `Singular` is decided by the projected mass matrix alone: its Cholesky fails, or the
//!   condition estimate of its Jacobi-scaled form exceeds `SolverOptions::cond_max`. That is
//!   what makes the problem ill posed (an acceleration no inertia resists), independent of a
//!   spread of `M`'s eigenvalues along the coordinates (thin rods, massless frames).
//! - A rank-deficient `G` is not singular: redundant constraints (a hinge written as two
//!   contact points, a planar loop written in 3-D) get the accelerations exactly and the
//!   minimum-norm multipliers; the report's `rank` says so (`M` otherwise). A dependent row
//!   whose `gamma_stab` is inconsistent shows in the backward error, which ends in
//!   `Inaccurate` above the bound.
//!
//! Measured against the alternative, a dense LU with partial pivoting of the whole
//! `(N + M)²` saddle-point matrix with the same refinement ([`FdSolver::SaddlePointLu`]): see
//! docs/dynamics.md for the figures. The null-space method is the fallback because it handles
//! redundant constraints (the LU's matrix is then singular), decides `Singular` on the matrix
//! that makes the problem ill posed, and is as accurate after refinement.
//! [`forward_dynamics_schur`] keeps the Schur complement alone and its `Singular` on
//! `cond(S_c)`, as the structured path's reference.

mod null_space;
mod reduced;

pub(crate) use reduced::{FD_K_COND_MAX, fd_cond_check};
mod saddle;
mod schur;

use super::baumgarte::Baumgarte;
use super::input::{all_finite, check_finite, check_input};
use super::report::{DynamicsMethod, DynamicsReport};
use super::terms::{check_terms, evaluate_terms};
use crate::data::{BlockFactors, Data, DynamicsScratch, Workspace};
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::model::Model;
use crate::plan::mat_vec;
use crate::tasks::{EquationsOfMotion, ForwardDynamics};

/// Relative backward error above which an answer is refined (see the [module](self)
/// documentation): about 45 ε, a few times the rounding of the residual itself for the orders
/// of the robots here (N up to 60).
pub const REFINE_ABOVE: f64 = 1e-14;

/// Iterative refinement steps at most, each on the factors (or the elimination) of the path
/// that answered.
const REFINE_STEPS: usize = 2;

/// What forward dynamics reports as the condition number of `S_c`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Report {
    /// Its exact value after a structured solve (the estimate after a dense one).
    Exact,
    /// Only the certifying bound after a structured solve (the simulator, which discards it).
    Bound,
}

/// Which algorithm [`forward_dynamics_with`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FdSolver {
    /// What [`forward_dynamics`] does: the generated elimination, the runtime's elimination
    /// onto the outputs, the Schur complement, and the null-space method when those decline,
    /// refuse (`S_c` ill-conditioned) or do not reach `SolverOptions::backward_error_max`.
    Auto,
    /// The Schur complement `S_c = G M⁻¹ Gᵀ` alone ([`forward_dynamics_schur`]).
    Schur,
    /// The null-space method alone ([`DynamicsMethod::NullSpace`]).
    NullSpace,
    /// The dense LU with partial pivoting of the whole saddle-point matrix alone
    /// ([`DynamicsMethod::SaddlePoint`]), the alternative measured against the null-space
    /// method.
    SaddlePointLu,
}

/// Solves the forward dynamics at `data.x`, `data.xdot` for the control forces `u`
/// (`Structure::actuated` order, length `N - M`) and the applied forces `q_forces` (`Q`, N,
/// zero if `None`), with Baumgarte's stabilisation `baumgarte` ([`Baumgarte::NONE`] for none).
/// Writes `data.xddot`, `data.lambda` and `data.u` (a copy of `u`) on success; `data.mass`,
/// `data.psi`, `data.g`, `data.gamma` (the kernel's `gamma`, without Baumgarte's terms) and,
/// when `beta != 0`, `data.f` in any case. Calls the fused `Dynamics::dynamics_terms` (`G`,
/// `gamma`, `M`, `psi`) and, if `beta != 0`, `Kernels::constraints`, once each. See the
/// [module](self) documentation for the algorithm and what the report's numbers mean.
///
/// Errors: `Dimension` for a `u` of the wrong length or inconsistent `Dynamics::mass_blocks`;
/// `NonFinite` for a NaN/inf in the state, `u`, `q_forces`, the gains or a kernel output;
/// `NotPositiveDefinite` for a block of `M` that is not positive definite (a model bug);
/// `Singular` when the projected mass matrix `Q₂ᵀ M Q₂` is (numerically) singular: the
/// problem is ill posed; `Inaccurate` when no path reaches `SolverOptions::backward_error_max`.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn forward_dynamics<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
) -> Result<DynamicsReport, SolverError> {
    solve(
        model,
        data,
        u,
        q_forces,
        baumgarte,
        Report::Exact,
        FdSolver::Auto,
    )
}

/// [`forward_dynamics`] by the Schur complement `S_c` alone (never the elimination onto the
/// outputs; refined like every path): the reference the structured path is tested against.
/// `Singular` is decided here on `cond(S_c)`. With massless coordinates (an exactly zero block
/// of `M`, no Schur complement) the null-space method answers instead.
pub fn forward_dynamics_schur<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
) -> Result<DynamicsReport, SolverError> {
    solve(
        model,
        data,
        u,
        q_forces,
        baumgarte,
        Report::Exact,
        FdSolver::Schur,
    )
}

/// [`forward_dynamics`] by the algorithm `solver` (see [`FdSolver`]); the same inputs, outputs,
/// report and errors.
pub fn forward_dynamics_with<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
    solver: FdSolver,
) -> Result<DynamicsReport, SolverError> {
    solve(model, data, u, q_forces, baumgarte, Report::Exact, solver)
}

/// An answer of one path, before it is committed to `data`.
#[derive(Clone, Copy)]
struct Answer<const N: usize, const M: usize> {
    x: [f64; N],
    l: [f64; M],
    method: DynamicsMethod,
    cond_blocks: f64,
    cond: f64,
    rank: usize,
}

/// The paths, as `run` knows them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Generated,
    Reduced,
    Schur,
    NullSpace,
    SaddleLu,
}

/// [`forward_dynamics`], with `cond` as `report` asks (the same results otherwise) and the
/// algorithms `path` allows.
pub(crate) fn solve<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
    report: Report,
    path: FdSolver,
) -> Result<DynamicsReport, SolverError> {
    if M == 0 {
        // No constraint (a serial arm or a tree): `M Ẍ = F`.
        return unconstrained(model, data, u, q_forces);
    }
    let s = model.structure();
    let k = model.kernels();
    let n_act = s.actuated.len();
    check_input("u", u, n_act)?;
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    if let Some(q) = q_forces {
        check_finite("q_forces", q)?;
    }
    let Baumgarte { alpha, beta } = baumgarte;
    check_finite("Baumgarte gains", &[alpha, beta])?;
    evaluate_terms(model, data);
    if beta != 0.0 {
        k.constraints(&data.x, &mut data.f);
    }

    // F = psi + Q + S gear U.
    let mut force = [0.0; N];
    for (j, fj) in force.iter_mut().enumerate() {
        *fj = data.psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    for (i, (&j, &ua)) in s.actuated.iter().zip(u).enumerate() {
        force[j] += gear_ratio(s.gear, i) * ua;
    }
    // gamma_stab = gamma - 2 alpha G Ẋ - beta² f.
    let mut gamma = data.gamma;
    if alpha != 0.0 {
        let mut gx = [0.0; M];
        mat_vec(&data.g, &data.xdot, &mut gx);
        for (gs, &v) in gamma.iter_mut().zip(gx.iter()) {
            *gs -= 2.0 * alpha * v;
        }
    }
    if beta != 0.0 {
        for (gs, &fi) in gamma.iter_mut().zip(data.f.iter()) {
            *gs -= beta * beta * fi;
        }
    }

    // The solve the generator emitted for this robot, when it has one (see
    // `Dynamics::forward_dynamics_solve`: the elimination below, written out over the
    // structure). Its checks are its own factors' and, with its backward error at most
    // `REFINE_ABOVE`, its answer is returned at once; the kernel outputs are checked only when
    // it declines or its results are not finite (a NaN or an infinity from the kernels ends
    // there).
    let mut first = None;
    if path == FdSolver::Auto {
        let (mut x, mut l) = ([0.0; N], [0.0; M]);
        if let Some(c) = generated(model, data, &force, &gamma, &mut x, &mut l) {
            // The solve's own backward error, formed over the structure while its operands
            // were at hand; NaN where it forms none.
            let eta = if c.backward_error.is_nan() {
                backward_error_fast(model, data, &force, &gamma, &x, &l, c.residual)
            } else {
                c.backward_error
            };
            if eta <= REFINE_ABOVE {
                data.xddot = x;
                data.lambda = l;
                data.u = [0.0; N];
                data.u[..u.len()].copy_from_slice(u);
                return Ok(DynamicsReport {
                    method: DynamicsMethod::Reduced,
                    cond_blocks: c.blocks,
                    cond: c.reduced,
                    residual: c.residual,
                    rank: M,
                    backward_error: eta,
                });
            }
            let a = Answer {
                x,
                l,
                method: DynamicsMethod::Reduced,
                cond_blocks: c.blocks,
                cond: c.reduced,
                rank: M,
            };
            first = Some((Kind::Generated, a));
        }
    }
    let blocks = check_terms(model, data)?;
    if beta != 0.0 {
        check_finite("f (constraint kernel output)", &data.f)?;
    }
    check_finite("gamma_stab (Baumgarte)", &gamma)?;
    let exact = report == Report::Exact;
    let cond_max = model.options.cond_max;

    let (kind, answer) = match (first, path) {
        (Some(f), _) => f,
        (None, FdSolver::Auto) => {
            // The elimination onto the outputs (`reduced`) first: it needs no factor of M, so
            // massless frames take it too; near a serial singularity it declines.
            if let Some(a) = run(
                Kind::Reduced,
                model,
                data,
                blocks,
                &force,
                &gamma,
                true,
                exact,
            )? {
                (Kind::Reduced, a)
            } else if massless(data, blocks) {
                // M only positive semi-definite: no Schur complement.
                fallback(model, data, blocks, &force, &gamma)?
            } else {
                match run(
                    Kind::Schur,
                    model,
                    data,
                    blocks,
                    &force,
                    &gamma,
                    true,
                    exact,
                ) {
                    // A mass matrix worse conditioned than `cond_max` (its Cholesky pivots'
                    // ratio, a lower bound): the Schur complement's rounding grows with it, and
                    // whether the problem is singular is the projected mass matrix's to say.
                    Ok(Some(a)) if a.cond_blocks > cond_max => {
                        fallback(model, data, blocks, &force, &gamma)?
                    }
                    Ok(Some(a)) => (Kind::Schur, a),
                    // cond(S_c) squares that of M: the null-space method decides. So it does
                    // for an M that is only semi-definite (a massless coordinate within a block;
                    // a negative diagonal entry is a model bug, and its error stands).
                    Ok(None) | Err(SolverError::Singular { .. }) => {
                        fallback(model, data, blocks, &force, &gamma)?
                    }
                    Err(e @ SolverError::NotPositiveDefinite { .. }) => {
                        if (0..N).any(|j| data.mass.data.0[j][j] < 0.0) {
                            return Err(e);
                        }
                        fallback(model, data, blocks, &force, &gamma)?
                    }
                    Err(e) => return Err(e),
                }
            }
        }
        // No Schur complement without a factor of M: massless coordinates take the null-space
        // method there too.
        (None, FdSolver::Schur) if massless(data, blocks) => {
            fallback(model, data, blocks, &force, &gamma)?
        }
        (None, only) => {
            let kind = match only {
                FdSolver::NullSpace => Kind::NullSpace,
                FdSolver::SaddlePointLu => Kind::SaddleLu,
                _ => Kind::Schur,
            };
            let a = run(kind, model, data, blocks, &force, &gamma, true, exact)?.ok_or(
                SolverError::Singular {
                    cond: f64::INFINITY,
                    what: "S_c = G M⁻¹ Gᵀ",
                    block: None,
                },
            )?;
            (kind, a)
        }
    };
    let (answer, be) = refine(model, data, blocks, kind, answer, &force, &gamma)?;
    let bound = model.options.backward_error_max;
    if be.eta <= bound {
        return Ok(commit(data, &answer, u, be));
    }
    if path == FdSolver::Auto && kind != FALLBACK {
        let (kind, a) = fallback(model, data, blocks, &force, &gamma)?;
        let (a, be2) = refine(model, data, blocks, kind, a, &force, &gamma)?;
        if be2.eta <= bound {
            return Ok(commit(data, &a, u, be2));
        }
        return Err(SolverError::Inaccurate {
            backward_error: be2.eta.min(be.eta),
            bound,
        });
    }
    Err(SolverError::Inaccurate {
        backward_error: be.eta,
        bound,
    })
}

/// The fallback of [`forward_dynamics`]: the null-space method (see the [module](self)
/// documentation for why not the LU of the whole saddle-point matrix).
const FALLBACK: Kind = Kind::NullSpace;

fn fallback<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: &[&[usize]],
    force: &[f64; N],
    gamma: &[f64; M],
) -> Result<(Kind, Answer<N, M>), SolverError> {
    let a = run(FALLBACK, model, data, blocks, force, gamma, true, true)?;
    // The null-space method always answers or errs.
    let a = a.ok_or(SolverError::NonFinite { what: "Ẍ" })?;
    Ok((FALLBACK, a))
}

/// Whether a block of M is exactly zero: massless coordinates (a frame that only closes
/// loops, such as a serial arm's end-effector pose), M only positive semi-definite.
fn massless<const N: usize, const M: usize>(data: &Data<N, M>, blocks: &[&[usize]]) -> bool {
    blocks.iter().any(|blk| {
        blk.iter()
            .all(|&c| blk.iter().all(|&r| data.mass.data.0[c][r] == 0.0))
    })
}

/// The generated solve into `x`, `l`, when the robot has one and it accepts (its conditioning
/// checks, finite results), with its certificate `max |G Ẍ - gamma|` and its backward error
/// (NaN where it forms none).
#[inline]
fn generated<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    force: &[f64; N],
    gamma: &[f64; M],
    x: &mut [f64; N],
    l: &mut [f64; M],
) -> Option<crate::kernels::SolveConditioning> {
    let c = model.kernels().forward_dynamics_solve(
        &data.g.data.0,
        &data.mass.data.0,
        force,
        gamma,
        x,
        l,
    )?;
    let ok = c.blocks <= reduced::FD_K_COND_MAX
        && c.reduced <= reduced::fd_cond_check(model.options.cond_max)
        && c.residual.is_finite()
        && all_finite(x)
        && all_finite(l);
    ok.then_some(c)
}

/// [`generated`] as an [`Answer`] (a refinement step's correction).
fn run_generated<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    force: &[f64; N],
    gamma: &[f64; M],
) -> Option<Answer<N, M>> {
    let (mut x, mut l) = ([0.0; N], [0.0; M]);
    let c = generated(model, data, force, gamma, &mut x, &mut l)?;
    Some(Answer {
        x,
        l,
        method: DynamicsMethod::Reduced,
        cond_blocks: c.blocks,
        cond: c.reduced,
        rank: M,
    })
}

/// One solve of the saddle-point system with the right-hand side `(force, gamma)` by the path
/// `kind`; `Ok(None)` when that path declines (the eliminations onto the outputs and the
/// structured Schur complement). `refactor`: the null-space and LU paths factor anew (else they
/// reuse their factors from the last call: refinement).
#[allow(clippy::too_many_arguments)]
fn run<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    kind: Kind,
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: &[&[usize]],
    force: &[f64; N],
    gamma: &[f64; M],
    refactor: bool,
    exact: bool,
) -> Result<Option<Answer<N, M>>, SolverError> {
    let cond_max = model.options.cond_max;
    if kind == Kind::Generated {
        return Ok(run_generated(model, data, force, gamma));
    }
    let Data {
        g,
        mass,
        ws:
            Workspace {
                factors: BlockFactors { lu: sc, work, .. },
                dynamics:
                    DynamicsScratch {
                        lu_n,
                        z,
                        v2: scratch,
                        wood,
                        kkt,
                        fd,
                        ns,
                        ns_info,
                        kkt_cond,
                        ..
                    },
                ..
            },
        ..
    } = data;
    let (mut x, mut l) = ([0.0; N], [0.0; M]);
    let a = |x: [f64; N], l: [f64; M], method, cond_blocks: f64, cond: f64, rank: usize| {
        Some(Answer {
            x,
            l,
            method,
            cond_blocks,
            cond,
            rank,
        })
    };
    Ok(match kind {
        Kind::Generated => None, // answered above
        Kind::Reduced => {
            let terms = reduced::Terms {
                g,
                mass,
                mass_blocks: blocks,
                force,
                gamma,
            };
            reduced::forward_dynamics(model, &terms, cond_max, fd, &mut x, &mut l)
                .and_then(|c| a(x, l, DynamicsMethod::Reduced, c.blocks, c.reduced, M))
        }
        Kind::Schur => {
            x = *force;
            let (cond_blocks, cond) = schur::solve(
                model,
                blocks,
                g,
                mass,
                gamma,
                schur::Scratch {
                    sc,
                    work,
                    lu_n,
                    z,
                    wood,
                },
                &mut x,
                scratch,
                &mut l,
                exact,
            )?;
            a(x, l, DynamicsMethod::SchurComplement, cond_blocks, cond, M)
        }
        Kind::NullSpace => {
            if refactor {
                *ns_info = Some(null_space::factor(mass, g, cond_max, ns)?);
            }
            let Some(info) = *ns_info else {
                return Ok(None);
            };
            null_space::solve(ns, force, gamma, &mut x, &mut l);
            a(
                x,
                l,
                DynamicsMethod::NullSpace,
                info.cond_g,
                info.cond_h,
                info.rank,
            )
        }
        Kind::SaddleLu => {
            if refactor {
                *kkt_cond = saddle::factor(mass, g, cond_max, kkt)?;
            }
            saddle::solve(kkt, force, gamma, &mut x, &mut l);
            a(
                x,
                l,
                DynamicsMethod::SaddlePoint,
                f64::INFINITY,
                *kkt_cond,
                M,
            )
        }
    })
}

/// Up to `REFINE_STEPS` steps of iterative refinement of `answer` by its path `kind`, while
/// its backward error is above `REFINE_ABOVE` and each step lowers it: the residuals of both
/// equations solved for a correction. Returns the best answer and its backward error;
/// `NonFinite` when it is not finite.
#[allow(clippy::too_many_arguments)]
fn refine<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: &[&[usize]],
    kind: Kind,
    mut answer: Answer<N, M>,
    force: &[f64; N],
    gamma: &[f64; M],
) -> Result<(Answer<N, M>, Backward), SolverError> {
    check_finite("Ẍ", &answer.x)?;
    check_finite("lambda", &answer.l)?;
    let (mut r1, mut r2) = ([0.0; N], [0.0; M]);
    let mut be = backward_error(
        model, data, force, gamma, &answer.x, &answer.l, &mut r1, &mut r2,
    );
    for _ in 0..REFINE_STEPS {
        if be.eta <= REFINE_ABOVE {
            break;
        }
        let Ok(Some(c)) = run(kind, model, data, blocks, &r1, &r2, false, false) else {
            break;
        };
        let mut cand = answer;
        for (x, d) in cand.x.iter_mut().zip(&c.x) {
            *x += d;
        }
        for (l, d) in cand.l.iter_mut().zip(&c.l) {
            *l += d;
        }
        let (mut s1, mut s2) = ([0.0; N], [0.0; M]);
        let b2 = backward_error(
            model, data, force, gamma, &cand.x, &cand.l, &mut s1, &mut s2,
        );
        // Stop unless strictly better (a NaN stops too).
        if b2.eta.partial_cmp(&be.eta) != Some(core::cmp::Ordering::Less) {
            break;
        }
        answer = cand;
        be = b2;
        r1 = s1;
        r2 = s2;
    }
    if !be.eta.is_finite() {
        return Err(SolverError::NonFinite { what: "Ẍ" });
    }
    Ok((answer, be))
}

/// The normwise relative backward error of an answer (see the [module](self) documentation).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Backward {
    /// `max(eta_force, eta_constraint)`.
    pub eta: f64,
    /// `max |G Ẍ - gamma_stab|`.
    pub residual: f64,
}

/// The residuals `r1 = F - M Ẍ - Gᵀ lambda`, `r2 = gamma_stab - G Ẍ` and the normwise relative
/// backward error `max(‖r1‖ / (‖M‖ ‖Ẍ‖ + ‖Gᵀ‖ ‖lambda‖ + ‖F‖), ‖r2‖ / (‖G‖ ‖Ẍ‖ + ‖gamma_stab‖))`
/// in the ∞-norm (`‖Gᵀ‖∞` is `G`'s largest column sum, `‖G‖∞` its largest row sum; 0 for a
/// zero residual, so 0/0 counts as exact), over the structure: `M` by its blocks
/// (`Dynamics::mass_blocks`), `G` by the rows of the inverse-kinematics blocks (as
/// `mat_vec_structured`).
#[allow(clippy::too_many_arguments)]
#[inline]
fn backward_error<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    force: &[f64; N],
    gamma: &[f64; M],
    x: &[f64; N],
    l: &[f64; M],
    r1: &mut [f64; N],
    r2: &mut [f64; M],
) -> Backward {
    let mass = &data.mass.data.0;
    let g = &data.g.data.0;
    *r1 = *force;
    let mut norm_m = 0.0_f64;
    for blk in model.kernels().mass_blocks() {
        for &c in blk.iter() {
            let Some(col) = mass.get(c) else { continue };
            let (mut s, mut a) = (0.0, 0.0);
            for &r in blk.iter() {
                if let (Some(&m), Some(&xr)) = (col.get(r), x.get(r)) {
                    s += m * xr;
                    a += m.abs();
                }
            }
            if let Some(rc) = r1.get_mut(c) {
                *rc -= s;
            }
            norm_m = norm_m.max(a);
        }
    }
    *r2 = *gamma;
    let mut rows = [0.0; M];
    let mut norm_gt = 0.0_f64;
    let ik = model.structure().ik_blocks;
    for (((col, &xj), r1j), &b) in g.iter().zip(x).zip(r1.iter_mut()).zip(&model.ik_block_of) {
        let (mut s, mut a) = (0.0, 0.0);
        match ik.get(b) {
            Some(blk) => {
                for &i in blk.rows {
                    let v = col[i];
                    s += v * l[i];
                    a += v.abs();
                    r2[i] -= v * xj;
                    rows[i] += v.abs();
                }
            }
            None => {
                for i in 0..M {
                    let v = col[i];
                    s += v * l[i];
                    a += v.abs();
                    r2[i] -= v * xj;
                    rows[i] += v.abs();
                }
            }
        }
        *r1j -= s;
        norm_gt = norm_gt.max(a);
    }
    let inf = |v: &[f64]| v.iter().fold(0.0_f64, |m, &a| m.max(a.abs()));
    let norm_g = inf(&rows);
    let (nx, nl) = (inf(x), inf(l));
    let (n1, n2) = (inf(r1), inf(r2));
    let rel = |num: f64, den: f64| if num == 0.0 { 0.0 } else { num / den };
    let e1 = rel(n1, norm_m * nx + norm_gt * nl + inf(force));
    let e2 = rel(n2, norm_g * nx + inf(gamma));
    Backward {
        eta: if e1.is_nan() || e2.is_nan() {
            f64::INFINITY
        } else {
            e1.max(e2)
        },
        residual: n2,
    }
}

/// [`backward_error`]'s `eta` without the residual vectors, for the answer of a generated
/// solve that does not form its own (`SolveConditioning::backward_error` NaN):
/// `max |G Ẍ - gamma_stab|` is its certificate `residual2`, so only
/// `F - M Ẍ - Gᵀ lambda` and the norms are formed, each column of `G` once, the dense ones by
/// four-way partial sums (independent additions the processor overlaps).
#[inline]
fn backward_error_fast<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    force: &[f64; N],
    gamma: &[f64; M],
    x: &[f64; N],
    l: &[f64; M],
    residual2: f64,
) -> f64 {
    let mass = &data.mass.data.0;
    let g = &data.g.data.0;
    let mut r1 = *force;
    let mut norm_m = 0.0_f64;
    for blk in model.kernels().mass_blocks() {
        if let &[j] = &blk[..] {
            if let (Some(col), Some(&xj), Some(rj)) = (mass.get(j), x.get(j), r1.get_mut(j)) {
                let m = col.get(j).copied().unwrap_or(0.0);
                *rj -= m * xj;
                norm_m = norm_m.max(m.abs());
            }
            continue;
        }
        for &c in blk.iter() {
            let Some(col) = mass.get(c) else { continue };
            let (mut s, mut a) = (0.0, 0.0);
            for &r in blk.iter() {
                if let (Some(&m), Some(&xr)) = (col.get(r), x.get(r)) {
                    s += m * xr;
                    a += m.abs();
                }
            }
            if let Some(rc) = r1.get_mut(c) {
                *rc -= s;
            }
            norm_m = norm_m.max(a);
        }
    }
    let mut rows = [0.0; M];
    let mut norm_gt = 0.0_f64;
    let ik = model.structure().ik_blocks;
    for ((col, r1j), &b) in g.iter().zip(r1.iter_mut()).zip(&model.ik_block_of) {
        match ik.get(b) {
            Some(blk) => {
                let (mut s, mut a) = (0.0, 0.0);
                for &i in blk.rows {
                    let v = col[i];
                    s += v * l[i];
                    a += v.abs();
                    rows[i] += v.abs();
                }
                *r1j -= s;
                norm_gt = norm_gt.max(a);
            }
            None => {
                let mut a = 0.0;
                for (ri, &v) in rows.iter_mut().zip(col) {
                    *ri += v.abs();
                }
                let (ac, ar) = col.as_chunks::<4>();
                let mut a4 = [0.0; 4];
                for c in ac {
                    for (s, &v) in a4.iter_mut().zip(c) {
                        *s += v.abs();
                    }
                }
                for &v in ar {
                    a += v.abs();
                }
                *r1j -= crate::linalg::dot4(col, l);
                norm_gt = norm_gt.max((a4[0] + a4[1]) + (a4[2] + a4[3]) + a);
            }
        }
    }
    let inf = |v: &[f64]| v.iter().fold(0.0_f64, |m, &a| m.max(a.abs()));
    let norm_g = inf(&rows);
    let nx = inf(x);
    let n1 = inf(&r1);
    let rel = |num: f64, den: f64| if num == 0.0 { 0.0 } else { num / den };
    let e1 = rel(n1, norm_m * nx + norm_gt * inf(l) + inf(force));
    let e2 = rel(residual2, norm_g * nx + inf(gamma));
    if e1.is_nan() || e2.is_nan() {
        f64::INFINITY
    } else {
        e1.max(e2)
    }
}

/// Commits an answer to `data` with a copy of `u`, and makes its report.
fn commit<const N: usize, const M: usize>(
    data: &mut Data<N, M>,
    a: &Answer<N, M>,
    u: &[f64],
    be: Backward,
) -> DynamicsReport {
    data.xddot = a.x;
    data.lambda = a.l;
    data.u = [0.0; N];
    data.u[..u.len()].copy_from_slice(u);
    DynamicsReport {
        method: a.method,
        cond_blocks: a.cond_blocks,
        cond: a.cond,
        residual: be.residual,
        rank: a.rank,
        backward_error: be.eta,
    }
}

/// `M Ẍ = psi + Q + S U` for a robot without constraints (`M = 0`: a serial arm or a tree, no
/// loop), by the Cholesky factor of `M` (the Schur complement with an empty `S_c`):
/// `cond_blocks` is the factor's pivot ratio `max l_ii² / min l_ii²`, `cond` the 1-norm
/// estimate of `M`'s condition number, `residual` 0 (no constraint), `backward_error` that of
/// `M Ẍ = F`.
fn unconstrained<K: ForwardDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    const WHAT: &str = "the mass matrix M";
    const SOURCE: &str = "M or psi (kernel output)";
    let s = model.structure();
    check_input("u", u, s.actuated.len())?;
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    if let Some(q) = q_forces {
        check_finite("q_forces", q)?;
    }
    evaluate_terms(model, data);
    check_finite(SOURCE, data.mass.as_slice())?;
    check_finite(SOURCE, &data.psi)?;
    let scratch = &mut data.ws.dynamics;
    let force = &mut scratch.v;
    for (j, fj) in force.iter_mut().enumerate() {
        *fj = data.psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    for (i, (&j, &ua)) in s.actuated.iter().zip(u).enumerate() {
        force[j] += gear_ratio(s.gear, i) * ua;
    }
    let l = scratch.lu_n.as_flattened_mut();
    l.copy_from_slice(data.mass.as_slice());
    let cond = crate::factor::factor_spd(
        l,
        N,
        scratch.work_n.as_flattened_mut(),
        model.options.cond_max,
        crate::factor::CondMode::Report,
        WHAT,
        SOURCE,
    )?;
    crate::linalg::cholesky_solve(l, N, force)
        .map_err(|e| crate::factor::lu_error(e, WHAT, None, N, SOURCE))?;
    check_finite("Xddot", force)?;
    let (lo, hi) = (0..N)
        .map(|i| l[i + i * N] * l[i + i * N])
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        });
    // The backward error of `M Ẍ = F`: ‖F - M Ẍ‖ / (‖M‖ ‖Ẍ‖ + ‖F‖), ∞-norms.
    let (mut r, mut m_norm, mut f_norm, mut x_norm) = (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    for i in 0..N {
        let (mut mx, mut row) = (0.0, 0.0);
        for (col, &xj) in data.mass.data.0.iter().zip(force.iter()) {
            mx += col[i] * xj;
            row += col[i].abs();
        }
        let fi = data.psi[i]
            + q_forces.map_or(0.0, |q| q[i])
            + s.actuated
                .iter()
                .position(|&a| a == i)
                .map_or(0.0, |a| gear_ratio(s.gear, a) * u[a]);
        r = r.max((fi - mx).abs());
        m_norm = m_norm.max(row);
        f_norm = f_norm.max(fi.abs());
        x_norm = x_norm.max(force[i].abs());
    }
    let denom = m_norm * x_norm + f_norm;
    let backward_error = if denom > 0.0 { r / denom } else { 0.0 };
    data.xddot = *force;
    data.u = [0.0; N];
    data.u[..u.len()].copy_from_slice(u);
    Ok(DynamicsReport {
        method: DynamicsMethod::SchurComplement,
        cond_blocks: if N == 0 { 1.0 } else { hi / lo },
        cond,
        residual: 0.0,
        rank: 0,
        backward_error,
    })
}
