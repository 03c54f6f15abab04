//! Inverse dynamics (paper eqs. 33-36): given the motion `X, Ẋ, Ẍ` (from inverse kinematics,
//! velocity and acceleration) and the applied forces `Q`, find the control forces `U` and the
//! Lagrange multipliers `lambda` of the equations of motion
//! `M Ẍ = psi + Q + S U - Gᵀ lambda`, that is
//!
//! ```text
//! [S | Gᵀ] [U; mu] = b,    b = M(X) Ẍ - psi(X, Ẋ) - Q,    lambda = -mu
//! ```
//!
//! (N equations, `N - M` + M unknowns), where `S` places `U` on the actuated coordinates. The
//! sign: `data.lambda` is always the multiplier of the equations of motion, the one
//! [`forward_dynamics`](crate::forward_dynamics()) returns (constraint forces `-Gᵀ lambda`);
//! the unknown of the `[S | Gᵀ]` form (the paper's eq. 34 as written in `design.md`) is
//! `mu = -lambda`.
//!
//! Block elimination ([`inverse_dynamics`]): the coordinates of inverse-kinematics block `k`
//! (`Structure::ik_blocks`: constraint rows `r_k`, coordinates `c_k`) appear only in the
//! constraints `r_k`, so their `|c_k|` equations read `G_kkᵀ mu_k = b_k - S_k U_k` with the
//! square `G_kk = G[r_k, c_k]`: `mu_k = G_kk⁻ᵀ b_k - Σ_a w_a U_a`, `w_a = G_kk⁻ᵀ e_a` for
//! the actuators `a` of block `k`. The output coordinates (`Structure::outputs`) then give
//! `Σ_k G[r_k, o]ᵀ mu_k = b_o`, a square system of order `#outputs = #actuated = N - M` in
//! `U` (6 × 6 for the 6-UPS, whose blocks are 3 × 3):
//!
//! ```text
//! A U = G_oᵀ mu⁰ - b_o,     A[o, a] = G[:, o]ᵀ w_a
//! ```
//!
//! An output that is actuated too (a coordinate in no loop, such as a legged robot's hip) is
//! in no block; its row reads `U_a + G_oᵀ mu = b_o`, so `A[o, a] = -1` for its own actuator
//! `a` (whose `w_a` is zero), and its column of `G` (zero for a coordinate in no loop) enters
//! as any output's.
//!
//! Since `det [S | Gᵀ] = ± Π_k det G_kk · det A`, `A` is singular exactly at the mechanism's
//! parallel (type II) singularities, and a singular `G_kk` (an inverse-kinematics
//! singularity of one leg) does not make the problem singular: the solver then falls back to a
//! dense LU of `[S | Gᵀ]` ([`inverse_dynamics_dense`]).

use super::blockwise::{Blocks, factor_blocks, fixed_store};
use super::input::{all_finite, check_finite, check_input};
use super::inverse_kinematics::{KinematicsReport, acceleration_after, position_and_velocity};
use super::report::{DynamicsMethod, DynamicsReport};
use super::terms::{check_terms, dynamics_terms, evaluate_terms};
use crate::data::{BlockFactors, Data, DynamicsScratch, Workspace};
use crate::error::SolverError;
use crate::factor::{CondMode, G_SOURCE, Slot, factor_lu, lu_error, solve_block, solve_factored};
use crate::kernels::gear_ratio;
use crate::linalg;
use crate::linalg::dot4 as dot;
use crate::model::{Model, col_dot_structured};
use crate::plan::mass_times;
use crate::tasks::{EquationsOfMotion, InverseDynamics, InverseKinematics, Robot, Velocity};

const WHAT_BLOCK: &str = "IK block G_r";
const WHAT_REDUCED: &str = "reduced inverse-dynamics system A (U)";
const WHAT_DENSE: &str = "[S | Gᵀ]";

/// Solves the inverse dynamics at `data.x`, `data.xdot`, `data.xddot` with the applied forces
/// `q_forces` (`Q`, N, zero if `None`) by block elimination on the inverse-kinematics blocks
/// (see the [module](self) documentation). Writes `data.u` (the `N - M` control forces, in
/// `Structure::actuated` order) and `data.lambda` on success, and `data.mass`, `data.psi`,
/// `data.g`, `data.gamma` in any case. Calls the fused `Dynamics::dynamics_terms` once (its
/// `gamma` is not needed here, but the fused kernel shares its trigonometry with `G`).
///
/// Falls back to the dense LU of [`inverse_dynamics_dense`] when a block `G_kk` is singular
/// (estimated condition number above `SolverOptions::cond_max`), or when the structure does
/// not allow the elimination (`#outputs != #actuated`, which a structure accepted by
/// `Model::try_new` never has). The report says which method ran and gives the worst block's
/// and the reduced (or dense) system's condition estimates.
///
/// Errors: `NonFinite` for a NaN/inf in the state, `q_forces` or a kernel output;
/// `Dimension` for inconsistent `Dynamics::mass_blocks`; `Singular` when the reduced system
/// `A` (a parallel singularity) or, after a fallback, `[S | Gᵀ]` is singular.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn inverse_dynamics<K: InverseDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    model.structure().require_actuated("inverse dynamics")?;
    solve(model, data, q_forces, false)
}

/// The same inverse dynamics by a dense LU (partial pivoting) of the N × N matrix
/// `[S | Gᵀ]`, without exploiting the block structure: the reference for
/// [`inverse_dynamics`] and its fallback. Same outputs and errors.
pub fn inverse_dynamics_dense<K: InverseDynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    model.structure().require_actuated("inverse dynamics")?;
    solve(model, data, q_forces, true)
}

/// [`inverse_kinematics_full`](crate::inverse_kinematics_full) and [`inverse_dynamics`] in one
/// call: one sample of a feed-forward loop along an output trajectory (the paper's `U` along
/// `TraekP`). Writes `data.x`, `data.xdot`, `data.xddot` for the output pose, rates and
/// accelerations (Newton warm-started from `data.x`), then `data.u` and `data.lambda`, with the
/// same results as the four separate calls up to rounding.
///
/// Cheaper than the separate calls: after Newton, one `Kernels::jacobian` at the solution and
/// one factorisation of the inverse-kinematics blocks serve the velocity, the acceleration and
/// the block elimination of inverse dynamics, and the fused `Dynamics::dynamics_terms` at the
/// solution and its velocity gives `gamma` for the acceleration together with `M` and `psi`
/// (the separate calls evaluate `G` three times more and factor the blocks three times).
/// Always `DynamicsMethod::BlockElimination` when it succeeds: a singular block fails the
/// velocity solve first.
///
/// All inputs are checked before anything is written. Errors: those of the separate calls; the
/// levels before the failing one stay committed, the failing one and those after it are left
/// untouched.
// A function of its own in profiles (bench/instructions.sh); it is far too large to gain from
// inlining into its caller.
#[inline(never)]
pub fn inverse_dynamics_full<
    K: InverseKinematics<N, M> + Velocity<N, M> + InverseDynamics<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    outputs: &[f64],
    outputs_dot: &[f64],
    outputs_ddot: &[f64],
    q_forces: Option<&[f64; N]>,
) -> Result<(KinematicsReport, DynamicsReport), SolverError> {
    model.structure().require_actuated("inverse dynamics")?;
    check_input(
        "outputs_ddot",
        outputs_ddot,
        model.structure().outputs.len(),
    )?;
    if let Some(q) = q_forces {
        check_finite("q_forces", q)?;
    }
    let (position, velocity, factored) = position_and_velocity(model, data, outputs, outputs_dot)?;
    // G (again, bit for bit or nearly), gamma, M and psi at the solution and its velocity.
    let blocks = dynamics_terms(model, data)?;
    let (acceleration, factors) =
        acceleration_after(model, data, outputs_ddot, &velocity, factored)?;
    let dynamics = match generated(model, data, q_forces) {
        Some(report) => report,
        None => {
            let cond = match factors {
                Some(c) => c,
                None => factor_blocks::<K, N, M>(
                    data,
                    Blocks::Ik(model.structure().ik_blocks),
                    model.options.cond_max,
                    "IK block G_r",
                )?,
            };
            solve_terms(model, data, blocks, q_forces, Method::Factored(cond))?
        }
    };
    Ok((
        KinematicsReport {
            position,
            velocity,
            acceleration,
        },
        dynamics,
    ))
}

fn solve<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
    dense: bool,
) -> Result<DynamicsReport, SolverError> {
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    check_finite("data.xddot", &data.xddot)?;
    if let Some(q) = q_forces {
        check_finite("q_forces", q)?;
    }
    if !dense {
        evaluate_terms(model, data);
        if let Some(report) = generated(model, data, q_forces) {
            return Ok(report);
        }
        let blocks = check_terms(model, data)?;
        return solve_terms(model, data, blocks, q_forces, Method::Blocks);
    }
    let blocks = dynamics_terms(model, data)?;
    solve_terms(model, data, blocks, q_forces, Method::Dense)
}

/// The solve the generator emitted for this robot (`Dynamics::inverse_dynamics_solve`: the
/// block elimination of [`solve_terms`], written out over the structure), on the kernel outputs
/// in `data` (not yet checked: a NaN or an infinity there ends in its results, which are
/// checked). Commits and reports when it answers with regular blocks, a regular reduced system
/// and finite results; its certificate is the residual of all N equations. `None` (nothing
/// committed) otherwise: the checked path then runs.
fn generated<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Option<DynamicsReport> {
    let s = model.structure();
    let n_act = s.actuated.len();
    if s.outputs.len() != n_act {
        return None;
    }
    let cond_max = model.options.cond_max;
    let Data {
        g,
        mass,
        psi,
        xddot,
        ws,
        ..
    } = &mut *data;
    let c = model.kernels().inverse_dynamics_solve(
        &g.data.0,
        &mass.data.0,
        psi,
        xddot,
        q_forces,
        &mut ws.dynamics.v2[..n_act],
        &mut ws.rhs,
    )?;
    let ok = c.blocks <= cond_max
        && c.reduced <= cond_max
        && c.residual.is_finite()
        && all_finite(&ws.dynamics.v2[..n_act])
        && all_finite(&ws.rhs);
    if !ok {
        return None;
    }
    commit_u(model, data, n_act);
    data.lambda = data.ws.rhs;
    Some(DynamicsReport {
        method: DynamicsMethod::BlockElimination,
        cond_blocks: c.blocks,
        cond: c.reduced,
        residual: c.residual,
        rank: M,
        backward_error: backward_error(model, data, q_forces),
    })
}

/// How [`solve_terms`] solves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Method {
    /// The dense LU of `[S | Gᵀ]`.
    Dense,
    /// Block elimination, factoring the blocks `G_kk` of `data.g` first (dense fallback).
    Blocks,
    /// Block elimination with the block factors already in the workspace
    /// (`algorithm::factor_blocks` on the inverse-kinematics blocks of a `G` at `data.x`), whose
    /// worst condition number is given.
    Factored(f64),
}

/// Inverse dynamics once `data.g`, `data.mass`, `data.psi` hold the terms at the state (checked
/// finite) and `mass_blocks` their blocks; the inputs are checked by the caller.
pub(crate) fn solve_terms<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    blocks: &[&[usize]],
    q_forces: Option<&[f64; N]>,
    method: Method,
) -> Result<DynamicsReport, SolverError> {
    let s = model.structure();
    // b = M Ẍ - psi - Q.
    let b = &mut data.ws.dynamics.v;
    mass_times(&data.mass, blocks, &data.xddot, b);
    match q_forces {
        Some(q) => {
            for ((bj, &pj), &qj) in b.iter_mut().zip(&data.psi).zip(q) {
                *bj -= pj + qj;
            }
        }
        None => {
            for (bj, &pj) in b.iter_mut().zip(&data.psi) {
                *bj -= pj;
            }
        }
    }
    check_finite("M Ẍ - psi - Q", b)?;

    let n_act = s.actuated.len();
    let structured = s.outputs.len() == n_act;
    let (method, cond_blocks, cond) = match method {
        Method::Dense => (DynamicsMethod::DenseLu, 0.0, dense_solve(model, data)?),
        Method::Factored(cond_blocks) if structured => {
            let cond = eliminate(model, data)?;
            (DynamicsMethod::BlockElimination, cond_blocks, cond)
        }
        _ if !structured => (DynamicsMethod::DenseLu, 0.0, dense_solve(model, data)?),
        _ => match factor_blocks::<K, N, M>(
            data,
            Blocks::Ik(s.ik_blocks),
            model.options.cond_max,
            WHAT_BLOCK,
        ) {
            Ok(cond_blocks) => (
                DynamicsMethod::BlockElimination,
                cond_blocks,
                eliminate(model, data)?,
            ),
            Err(SolverError::Singular {
                cond: cond_block,
                block: Some(_),
                ..
            }) => (
                DynamicsMethod::DenseLu,
                cond_block,
                dense_solve(model, data)?,
            ),
            Err(e) => return Err(e),
        },
    };

    // The solution: U in ws.dynamics.v2[..n_act], mu = -lambda in ws.rhs.
    for l in data.ws.rhs.iter_mut() {
        *l = -*l;
    }
    // Residual of all N equations M Ẍ - psi - Q - S U + Gᵀ lambda = 0.
    let Data { g, ws, .. } = &*data;
    let (u, lambda) = (&ws.dynamics.v2[..n_act], &ws.rhs);
    check_finite("U", u)?;
    check_finite("lambda", lambda)?;
    let mut residual = 0.0_f64;
    for j in 0..N {
        let mut r = ws.dynamics.v[j] + col_dot_structured(model, g, j, lambda);
        let a = model.actuator_of[j];
        if let Some(&ua) = u.get(a) {
            r -= ua;
        }
        residual = residual.max(r.abs());
    }

    commit_u(model, data, n_act);
    data.lambda = data.ws.rhs;
    Ok(DynamicsReport {
        method,
        cond_blocks,
        cond,
        residual,
        rank: M,
        backward_error: backward_error(model, data, q_forces),
    })
}

/// Block elimination with the factors of the blocks `G_kk` in the workspace slots
/// (`factor_blocks`); `b` in `ws.dynamics.v` on entry. Leaves `U` in `ws.dynamics.v2[..n_act]` and `mu` in
/// `ws.rhs`. Returns the reduced system's condition number.
fn eliminate<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<f64, SolverError> {
    let ik = model.structure().ik_blocks;
    let fixed = by_ik_order!(K, ik, B => eliminate_fixed::<K, N, M, B>(model, data), _ => None);
    if let Some(r) = fixed {
        return r;
    }
    let s = model.structure();
    let cond_max = model.options.cond_max;
    let n = s.actuated.len();
    let Data { g, ws, .. } = data;
    let Workspace {
        rhs: mu,
        dx: t,
        factors: BlockFactors { lu, piv, .. },
        dynamics:
            DynamicsScratch {
                z,
                v: b,
                v2: u,
                lu_n,
                piv_n,
                work_n,
                ..
            },
        ..
    } = ws;
    // w_a = G_kk⁻ᵀ e_c for the actuator a at position c of block k, packed: the block's `k`
    // rows' entries at offset a M of the flattened z (n M <= N M), its block in `owner`.
    let w = z.as_flattened_mut();
    // An actuator in no block (an actuated output) keeps `usize::MAX`: no `w_a`.
    let mut owner = [usize::MAX; N];
    let mut slot = Slot::default();
    for (bk, blk) in s.ik_blocks.iter().enumerate() {
        slot = slot.next(blk.rows.len());
        // Blocks are square with at most M <= N rows (Model::try_new).
        let k = slot.k.min(N);
        let t = &mut t[..k];
        // mu⁰_k = G_kk⁻ᵀ b_k.
        for (tc, &j) in t.iter_mut().zip(blk.cols) {
            *tc = b[j];
        }
        solve_block(lu, piv, slot, t, true, WHAT_BLOCK, Some(bk))?;
        for (&tr, &i) in t.iter().zip(blk.rows) {
            mu[i] = tr;
        }
        for (c, &j) in blk.cols.iter().enumerate() {
            let a = model.actuator_of[j];
            let (Some(o), Some(wa)) = (owner.get_mut(a), w.get_mut(a * M..a * M + k)) else {
                continue; // not actuated
            };
            *o = bk;
            wa.fill(0.0);
            wa[c] = 1.0;
            solve_block(lu, piv, slot, wa, true, WHAT_BLOCK, Some(bk))?;
        }
    }

    // The reduced system A U = G_oᵀ mu⁰ - b_o, rows = outputs, cols = actuators:
    // A[o, a] = Σ_{i in rows of a's block} G[i, o] w_a[i].
    let a_mat = &mut lu_n.as_flattened_mut()[..n * n];
    let u = &mut u[..n];
    for (r, &o) in s.outputs.iter().enumerate() {
        let go = &g.data.0[o];
        for (a, &bk) in owner.iter().enumerate().take(n) {
            let rows = s.ik_blocks.get(bk).map_or(&[][..], |blk| blk.rows);
            let wa = &w[a * M..a * M + rows.len()];
            a_mat[r + a * n] = rows.iter().zip(wa).map(|(&i, &wi)| go[i] * wi).sum();
        }
        actuated_output(model, a_mat, n, r, o);
        u[r] = dot(go, mu) - b[o];
    }
    let piv_n = &mut piv_n[..n];
    let cond = factor_lu(
        a_mat,
        n,
        piv_n,
        work_n.as_flattened_mut(),
        cond_max,
        CondMode::Report,
        WHAT_REDUCED,
        None,
        G_SOURCE,
    )?
    .cond;
    solve_factored(a_mat, n, piv_n, u, false).map_err(|e| {
        lu_error(e, WHAT_REDUCED, None, n, G_SOURCE) // unreachable: sizes match
    })?;
    // mu = mu⁰ - Σ_a w_a U_a, on the rows of a's block.
    for (a, (&ua, &bk)) in u.iter().zip(owner.iter()).enumerate() {
        let rows = s.ik_blocks.get(bk).map_or(&[][..], |blk| blk.rows);
        let wa = &w[a * M..a * M + rows.len()];
        for (&i, &wi) in rows.iter().zip(wa) {
            mu[i] -= wi * ua;
        }
    }
    Ok(cond)
}

/// Dense LU of `[S | Gᵀ]`; `b` in `ws.dynamics.v` on entry. Leaves `U` in `ws.dynamics.v2[..n_act]` and
/// `mu` in `ws.rhs`. Returns the condition estimate.
/// [`eliminate`] for inverse-kinematics blocks all of order `B`, whose inverses are in the
/// workspace (`None`: the structure does not fit; nothing written).
fn eliminate_fixed<K: EquationsOfMotion<N, M>, const N: usize, const M: usize, const B: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Option<Result<f64, SolverError>> {
    let s = model.structure();
    let ik = s.ik_blocks;
    let n = s.actuated.len();
    let Data { g, ws, .. } = data;
    let Workspace {
        rhs: mu,
        factors: BlockFactors { lu, .. },
        dynamics:
            DynamicsScratch {
                v: b,
                v2: u,
                lu_n,
                piv_n,
                work_n,
                ..
            },
        ..
    } = ws;
    let store = fixed_store::<M, B>(lu);
    if store.len() < ik.len() || n > N {
        return None;
    }
    let mut rows = [[0_usize; B]; M];
    for (r, blk) in rows.iter_mut().zip(ik) {
        *r = blk.rows.try_into().ok()?;
    }
    // mu⁰_k = G_kk⁻ᵀ b_k, and w_a = G_kk⁻ᵀ e_c = row c of G_kk⁻¹ for the actuator a at
    // position c of block k (its block and the entries on the block's rows).
    let mut w = [(0_usize, [0.0; B]); N];
    for (bk, ((blk, inv), rk)) in ik.iter().zip(store).zip(&rows).enumerate() {
        let cols: &[usize; B] = blk.cols.try_into().ok()?;
        let t: [f64; B] = core::array::from_fn(|i| b[cols[i]]);
        let m0 = linalg::mul_transpose_fixed(inv, &t);
        for (&v, &r) in m0.iter().zip(rk) {
            mu[r] = v;
        }
        for (c, &j) in cols.iter().enumerate() {
            if let Some(wa) = w.get_mut(model.actuator_of[j]) {
                *wa = (bk, core::array::from_fn(|r| inv[r][c]));
            }
        }
    }
    // The reduced system A U = G_oᵀ mu⁰ - b_o: A[o, a] = Σ_r G[rows_k[r], o] w_a[r].
    let a_mat = &mut lu_n.as_flattened_mut()[..n * n];
    let u = &mut u[..n];
    for (r, &o) in s.outputs.iter().enumerate() {
        let go = &g.data.0[o];
        for (a, (bk, wa)) in w.iter().enumerate().take(n) {
            let rk = rows.get(*bk)?;
            a_mat[r + a * n] = rk.iter().zip(wa).map(|(&i, &x)| go[i] * x).sum();
        }
        actuated_output(model, a_mat, n, r, o);
        u[r] = dot(go, mu) - b[o];
    }
    let piv_n = &mut piv_n[..n];
    let cond = match factor_lu(
        a_mat,
        n,
        piv_n,
        work_n.as_flattened_mut(),
        model.options.cond_max,
        CondMode::Report,
        WHAT_REDUCED,
        None,
        G_SOURCE,
    ) {
        Ok(c) => c.cond,
        Err(e) => return Some(Err(e)),
    };
    if let Err(e) = solve_factored(a_mat, n, piv_n, u, false) {
        return Some(Err(lu_error(e, WHAT_REDUCED, None, n, G_SOURCE)));
    }
    // mu = mu⁰ - Σ_a w_a U_a, on the rows of a's block.
    for ((bk, wa), &ua) in w.iter().zip(u.iter()) {
        let rk = rows.get(*bk)?;
        for (&i, &x) in rk.iter().zip(wa) {
            mu[i] -= x * ua;
        }
    }
    Some(Ok(cond))
}

/// The reduced system's row `r` for an output `o` that is actuated too (`a` its actuator,
/// in no block, so `w_a = 0`): its equation `U_a + G_oᵀ mu = b_o` gives
/// `Σ_a' A[o, a'] U_a' - U_a = G_oᵀ mu⁰ - b_o`, a `-1` in column `a`.
#[inline]
fn actuated_output<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    a_mat: &mut [f64],
    n: usize,
    r: usize,
    o: usize,
) {
    let a = model.actuator_of[o];
    if let Some(e) = a_mat.get_mut(r + a.wrapping_mul(n)).filter(|_| a < n) {
        *e -= 1.0;
    }
}

fn dense_solve<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<f64, SolverError> {
    let s = model.structure();
    let n_act = s.actuated.len();
    if n_act + M != N {
        // Unreachable for a structure accepted by Model::try_new.
        return Err(SolverError::Dimension {
            what: "actuated coordinates (N - M)",
            expected: N.saturating_sub(M),
            found: n_act,
        });
    }
    let Data { g, ws, .. } = data;
    let a = ws.dynamics.lu_n.as_flattened_mut();
    // Columns 0..n_act: S (unit vectors on the actuated coordinates); then Gᵀ.
    // (`max(1)`: no panic for the degenerate N = 0; the slices are then empty.)
    for (col, &j) in a.chunks_exact_mut(N.max(1)).zip(s.actuated) {
        col.fill(0.0);
        col[j] = 1.0;
    }
    for (i, col) in a.chunks_exact_mut(N.max(1)).skip(n_act).enumerate() {
        for (aj, gcol) in col.iter_mut().zip(g.data.0.iter()) {
            *aj = gcol[i];
        }
    }
    let sol = &mut ws.dynamics.v2;
    *sol = ws.dynamics.v;
    let cond = factor_lu(
        a,
        N,
        &mut ws.dynamics.piv_n,
        ws.dynamics.work_n.as_flattened_mut(),
        model.options.cond_max,
        CondMode::Report,
        WHAT_DENSE,
        None,
        G_SOURCE,
    )?
    .cond;
    solve_factored(a, N, &ws.dynamics.piv_n, sol, false)
        .map_err(|e| lu_error(e, WHAT_DENSE, None, N, G_SOURCE))?;
    for (l, &v) in ws.rhs.iter_mut().zip(&sol[n_act..]) {
        *l = v;
    }
    Ok(cond)
}

/// Commits the solved actuator forces (`ws.dynamics.v2`, the forces on the coordinates) to
/// `data.u` in the actuators' units: divided by their gear ratios ([`Structure::gear`](crate::kernels::Structure::gear)).
/// The normwise relative backward error of committed inverse dynamics (`data.u`,
/// `data.lambda`): `‖r‖ / (‖M‖ ‖Ẍ‖ + ‖psi + Q‖ + ‖S‖ ‖U‖ + ‖Gᵀ‖ ‖lambda‖)`, ∞-norms,
/// `r = M Ẍ - psi - Q - S U + Gᵀ lambda` (see `DynamicsReport::backward_error`).
fn backward_error<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> f64 {
    let s = model.structure();
    let inf = |v: &[f64]| v.iter().fold(0.0_f64, |m, &a| m.max(a.abs()));
    let mut r = [0.0; N];
    let mut norm_m = 0.0_f64;
    for blk in model.kernels().mass_blocks() {
        for &c in blk.iter() {
            let Some(col) = data.mass.data.0.get(c) else {
                continue;
            };
            let (mut v, mut a) = (0.0, 0.0);
            for &rr in blk.iter() {
                if let (Some(&m), Some(&x)) = (col.get(rr), data.xddot.get(rr)) {
                    v += m * x;
                    a += m.abs();
                }
            }
            if let Some(rc) = r.get_mut(c) {
                *rc = v;
            }
            norm_m = norm_m.max(a);
        }
    }
    let mut pq = data.psi;
    if let Some(q) = q_forces {
        for (p, &qj) in pq.iter_mut().zip(q) {
            *p += qj;
        }
    }
    let mut norm_gt = 0.0_f64;
    let mut norm_s = 0.0_f64;
    let mut su = 0.0_f64;
    for (j, rj) in r.iter_mut().enumerate() {
        *rj -= pq[j];
        *rj += col_dot_structured(model, &data.g, j, &data.lambda);
        norm_gt = norm_gt.max(data.g.data.0[j].iter().map(|v| v.abs()).sum());
        let a = model.actuator_of[j];
        if let Some(&ua) = data.u.get(a).filter(|_| a < s.actuated.len()) {
            let gr = gear_ratio(s.gear, a);
            *rj -= gr * ua;
            norm_s = norm_s.max(gr.abs());
            su = su.max(ua.abs());
        }
    }
    let num = inf(&r);
    if num == 0.0 {
        return 0.0;
    }
    let e =
        num / (norm_m * inf(&data.xddot) + inf(&pq) + norm_s * su + norm_gt * inf(&data.lambda));
    if e.is_nan() { f64::INFINITY } else { e }
}

fn commit_u<K: EquationsOfMotion<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    n_act: usize,
) {
    let gear = model.structure().gear;
    data.u = [0.0; N];
    for (i, u) in data.u[..n_act].iter_mut().enumerate() {
        *u = data.ws.dynamics.v2[i] / gear_ratio(gear, i);
    }
}
