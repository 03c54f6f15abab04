//! Forward dynamics (paper eqs. 29-32): given the state `X, Ẋ`, the control forces `U` and the
//! applied forces `Q`, find `Ẍ` and the Lagrange multipliers `lambda` of the saddle-point system
//!
//! ```text
//! M Ẍ + Gᵀ lambda = F,   F = psi(X, Ẋ) + Q + S U
//! G Ẍ             = gamma_stab = gamma(X, Ẋ) - 2 alpha G Ẋ - beta² f(X)
//! ```
//!
//! First choice: the same elimination as generated code, when the robot has it
//! ([`Dynamics::forward_dynamics_solve`](crate::Dynamics::forward_dynamics_solve), emitted by
//! codegen's `solve` module over the structural non-zeros of `G` and `M`, one function per kind
//! of inverse-kinematics block): it is taken when it answers, its blocks' condition numbers are
//! at most `reduced::FD_K_COND_MAX` and the pivot ratio of `Rᵀ M R` passes the check below;
//! its certificate is the residual of `G Ẍ = gamma_stab` it computes, and the kernel outputs are
//! checked for NaN and infinities only when it declines or its results are not finite (a
//! non-finite kernel output ends in its results). Otherwise, the runtime's own code:
//!
//! Elimination onto the outputs' coordinates (`reduced.rs`): with the
//! inverse-kinematics blocks of `G` inverted explicitly (any order up to 16), `Ẍ = R z̈ + r0`
//! and the small SPD system `(Rᵀ M R) z̈ = Rᵀ (F - M r0)` (6 × 6 for the 6-UPS, 12 × 12 for the
//! two-stage robot), `lambda` from one transposed product per block. It needs no factor of `M`
//! (massless frames, such as a serial arm's tool pose, take it too) and runs whenever every
//! block's condition number is at most `reduced::FD_K_COND_MAX` (a serial singularity is not
//! one of forward dynamics, but the elimination's rounding grows with it); its checks come with
//! its factors. Otherwise, and in [`forward_dynamics_schur`], the Schur complement on the
//! block-diagonal `M` (`Dynamics::mass_blocks`), which decides `Singular` on the constraints'
//! rank:
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
//! Cholesky with the Hager/Higham condition estimate, as before.

mod reduced;
mod saddle;
mod schur;

use super::baumgarte::Baumgarte;
use super::input::{all_finite, check_finite, check_input};
use super::report::{DynamicsMethod, DynamicsReport};
use super::terms::{check_terms, evaluate_terms};
use crate::data::{BlockFactors, Data, DynamicsScratch, Workspace};
use crate::error::SolverError;
use crate::kernels::gear_ratio;
use crate::model::{Model, mat_vec_structured};
use crate::plan::mat_vec;
use crate::tasks::{EquationsOfMotion, ForwardDynamics};

/// What forward dynamics reports as the condition number of `S_c`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Report {
    /// Its exact value after a structured solve (the estimate after a dense one).
    Exact,
    /// Only the certifying bound after a structured solve (the simulator, which discards it).
    Bound,
}
/// Solves the forward dynamics at `data.x`, `data.xdot` for the control forces `u`
/// (`Structure::actuated` order, length `N - M`) and the applied forces `q_forces` (`Q`, N,
/// zero if `None`), with Baumgarte's stabilisation `baumgarte` ([`Baumgarte::NONE`] for none).
/// Writes `data.xddot`, `data.lambda` and `data.u` (a copy of `u`) on success; `data.mass`,
/// `data.psi`, `data.g`, `data.gamma` (the kernel's `gamma`, without Baumgarte's terms) and,
/// when `beta != 0`, `data.f` in any case. Calls the fused `Dynamics::dynamics_terms` (`G`,
/// `gamma`, `M`, `psi`) and, if `beta != 0`, `Kernels::constraints`, once each. See the
/// [module](self) documentation for the algorithm.
///
/// The report gives, after the elimination onto the outputs (`DynamicsMethod::Reduced`),
/// `cond_blocks` as the largest exact 1-norm condition number of the inverse-kinematics blocks
/// and `cond` as the Cholesky pivot ratio `(max l_ii / min l_ii)²` of `Rᵀ M R` (a lower bound
/// of its condition number, read off the factor), the Hager/Higham estimate of
/// `cond₁(Rᵀ M R)` instead when that ratio passes `cond_max / 100` or 1e6; after the Schur
/// complement `cond_blocks`, a lower bound of the condition number of `M` from the Cholesky
/// pivots, and `cond` that of `S_c`, exact after the structured solve, the Hager/Higham
/// estimate after the dense one. `Singular` is
/// decided by the estimate, as in any dense solve: the structured solves of `S_c` run only when
/// a rigorous upper bound certifies it (at most `cond_max / 2`, so that the estimate would be
/// below `cond_max`).
///
/// Errors: `Dimension` for a `u` of the wrong length or inconsistent `Dynamics::mass_blocks`;
/// `NonFinite` for a NaN/inf in the state, `u`, `q_forces`, the gains or a kernel output;
/// `NotPositiveDefinite` for a block of `M` that is not positive definite; `Singular` when
/// `S_c` is (numerically) singular, i.e. `G` loses rank: a singularity of the constraints.
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
        Path::Auto,
    )
}

/// [`forward_dynamics`] by the Schur complement `S_c` alone (never the elimination onto the
/// outputs): the reference the structured path is tested against, and the path
/// [`forward_dynamics`] takes near a serial singularity.
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
        Path::Schur,
    )
}

/// Which algorithms forward dynamics may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Path {
    /// The elimination onto the outputs when it applies, else the Schur complement.
    Auto,
    /// The Schur complement only.
    Schur,
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
    path: Path,
) -> Result<DynamicsReport, SolverError> {
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

    let Data {
        xdot,
        f,
        gamma,
        g,
        mass,
        psi,
        ws,
        ..
    } = data;
    let Workspace {
        dx: gamma_stab,
        rhs: lambda,
        dynamics:
            DynamicsScratch {
                v: force,
                v2: scratch,
                ..
            },
        ..
    } = ws;

    // F = psi + Q + S gear U.
    for (j, fj) in force.iter_mut().enumerate() {
        *fj = psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    for (i, (&j, &ua)) in s.actuated.iter().zip(u).enumerate() {
        force[j] += gear_ratio(s.gear, i) * ua;
    }
    // gamma_stab = gamma - 2 alpha G Ẋ - beta² f, in the first M entries of ws.dx (M <= N).
    let gamma_stab = &mut gamma_stab[..M];
    gamma_stab.copy_from_slice(gamma);
    if alpha != 0.0 {
        mat_vec(g, xdot, lambda); // lambda: scratch for G Ẋ
        for (gs, &gx) in gamma_stab.iter_mut().zip(lambda.iter()) {
            *gs -= 2.0 * alpha * gx;
        }
    }
    if beta != 0.0 {
        for (gs, &fi) in gamma_stab.iter_mut().zip(f.iter()) {
            *gs -= beta * beta * fi;
        }
    }

    // The solve the generator emitted for this robot, when it has one (see
    // `Dynamics::forward_dynamics_solve`: the elimination below, written out over the
    // structure). Its checks are its own factors' and its certificate the residual of the
    // acceleration constraint; the kernel outputs are checked only when it declines or its
    // results are not finite (a NaN or an infinity from the kernels ends there).
    if path == Path::Auto
        && let Ok(gs) = <&[f64; M]>::try_from(&*gamma_stab)
        && let Some(c) =
            k.forward_dynamics_solve(&g.data.0, &mass.data.0, force, gs, scratch, lambda)
        && c.blocks <= reduced::FD_K_COND_MAX
        && c.reduced <= reduced::fd_cond_check(model.options.cond_max)
        && c.residual.is_finite()
        && all_finite(scratch)
        && all_finite(lambda)
    {
        data.xddot = *scratch;
        data.lambda = *lambda;
        data.u = [0.0; N];
        data.u[..u.len()].copy_from_slice(u);
        return Ok(DynamicsReport {
            method: DynamicsMethod::Reduced,
            cond_blocks: c.blocks,
            cond: c.reduced,
            residual: c.residual,
        });
    }
    let blocks = check_terms(model, data)?;
    if beta != 0.0 {
        check_finite("f (constraint kernel output)", &data.f)?;
    }
    let Data {
        g,
        mass,
        ws:
            Workspace {
                dx: gamma_stab,
                rhs: lambda,
                factors: BlockFactors { lu: sc, work, .. },
                dynamics:
                    DynamicsScratch {
                        lu_n,
                        z,
                        v: force,
                        v2: scratch,
                        wood,
                        kkt,
                        fd,
                        ..
                    },
                ..
            },
        ..
    } = data;
    let gamma_stab = &mut gamma_stab[..M];
    check_finite("gamma_stab (Baumgarte)", gamma_stab)?;

    // The elimination onto the outputs (`reduced`) first: it needs no factor of M, so massless
    // frames take it too; near a serial singularity it declines and the paths below run.
    if path == Path::Auto {
        let terms = reduced::Terms {
            g,
            mass,
            mass_blocks: blocks,
            force,
            gamma: gamma_stab,
        };
        let cond_max = model.options.cond_max;
        if let Some(c) = reduced::forward_dynamics(model, &terms, cond_max, fd, scratch, lambda) {
            let xddot = *scratch;
            return finish(
                model,
                data,
                xddot,
                u,
                DynamicsMethod::Reduced,
                c.blocks,
                c.reduced,
            );
        }
    }

    // 0. A block of M that is exactly zero belongs to massless coordinates (a frame that only
    //    closes loops, such as a serial arm's end-effector pose): M is then only positive
    //    semi-definite and the saddle-point system is solved as a whole.
    let massless = blocks.iter().any(|blk| {
        blk.iter()
            .all(|&c| blk.iter().all(|&r| mass.data.0[c][r] == 0.0))
    });
    if massless {
        let cond = saddle::saddle_point(
            mass,
            g,
            force,
            gamma_stab,
            model.options.cond_max,
            kkt,
            scratch,
            lambda,
        )?;
        let xddot = *scratch;
        return finish(
            model,
            data,
            xddot,
            u,
            DynamicsMethod::SaddlePoint,
            f64::INFINITY,
            cond,
        );
    }

    // The Schur complement on the block-diagonal M.
    let (cond_blocks, cond) = schur::solve(
        model,
        blocks,
        g,
        mass,
        gamma_stab,
        schur::Scratch {
            sc,
            work,
            lu_n,
            z,
            wood,
        },
        force,
        scratch,
        lambda,
        report == Report::Exact,
    )?;
    let xddot = *force;
    finish(
        model,
        data,
        xddot,
        u,
        DynamicsMethod::SchurComplement,
        cond_blocks,
        cond,
    )
}

/// Commits a solved `Ẍ` (and `lambda`, in `ws.rhs`) to `data` with a copy of `u`, and reports
/// the residual of the acceleration constraint, `max |G Ẍ - gamma_stab|` (`gamma_stab` in the
/// first M entries of `ws.dx`, as `solve` leaves it). `NonFinite` when either is not finite.
fn finish<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    xddot: [f64; N],
    u: &[f64],
    method: DynamicsMethod,
    cond_blocks: f64,
    cond: f64,
) -> Result<DynamicsReport, SolverError> {
    check_finite("Ẍ", &xddot)?;
    check_finite("lambda", &data.ws.rhs)?;
    let Data { g, ws, .. } = data;
    let gx = &mut ws.factors.work[0];
    mat_vec_structured(model, g, &xddot, gx);
    let residual = gx
        .iter()
        .zip(&ws.dx[..M])
        .fold(0.0_f64, |m, (&a, &b)| m.max((a - b).abs()));
    data.xddot = xddot;
    data.lambda = data.ws.rhs;
    data.u = [0.0; N];
    data.u[..u.len()].copy_from_slice(u);
    Ok(DynamicsReport {
        method,
        cond_blocks,
        cond,
        residual,
    })
}
