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
//! the actuators `a` of block `k`. The output coordinates (`Structure::outputs`, never
//! actuated) then give `Σ_k G[r_k, o]ᵀ mu_k = b_o`, a square system of order
//! `#outputs = #actuated = N - M` in `U` (6 × 6 for the 6-UPS, whose blocks are 3 × 3):
//!
//! ```text
//! A U = G_oᵀ mu⁰ - b_o,     A[o, a] = G[:, o]ᵀ w_a
//! ```
//!
//! Since `det [S | Gᵀ] = ± Π_k det G_kk · det A`, `A` is singular exactly at the mechanism's
//! parallel (type II) singularities, and a singular `G_kk` (an inverse-kinematics
//! singularity of one leg) does not make the problem singular: the solver then falls back to a
//! dense LU of `[S | Gᵀ]` ([`inverse_dynamics_dense`]).

use super::{
    DynamicsMethod, DynamicsReport, G_SOURCE, check_finite, dynamics_terms, factor_block,
    factor_lu, mass_times, solve_block_transpose,
};
use crate::data::{Data, Workspace};
use crate::error::SolverError;
use crate::kernels::Dynamics;
use crate::linalg;
use crate::model::Model;

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
pub fn inverse_dynamics<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    solve(model, data, q_forces, false)
}

/// The same inverse dynamics by a dense LU (partial pivoting) of the N × N matrix
/// `[S | Gᵀ]`, without exploiting the block structure: the reference for
/// [`inverse_dynamics`] and its fallback. Same outputs and errors.
pub fn inverse_dynamics_dense<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
) -> Result<DynamicsReport, SolverError> {
    solve(model, data, q_forces, true)
}

fn solve<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    q_forces: Option<&[f64; N]>,
    dense: bool,
) -> Result<DynamicsReport, SolverError> {
    let s = model.structure();
    check_finite("data.x", &data.x)?;
    check_finite("data.xdot", &data.xdot)?;
    check_finite("data.xddot", &data.xddot)?;
    if let Some(q) = q_forces {
        check_finite("q_forces", q)?;
    }
    let blocks = dynamics_terms(model, data)?;

    // b = M Ẍ - psi - Q.
    let b = &mut data.ws.v;
    mass_times(&data.mass, blocks, &data.xddot, b);
    for (j, bj) in b.iter_mut().enumerate() {
        *bj -= data.psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    check_finite("M Ẍ - psi - Q", b)?;

    let n_act = s.actuated.len();
    let (method, cond_blocks, cond) = if dense || s.outputs.len() != n_act {
        (DynamicsMethod::DenseLu, 0.0, dense_solve(model, data)?)
    } else {
        match block_elimination(model, data) {
            Ok((cond_blocks, cond)) => (DynamicsMethod::BlockElimination, cond_blocks, cond),
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
        }
    };

    // The solution: U in ws.v2[..n_act], mu = -lambda in ws.rhs.
    for l in data.ws.rhs.iter_mut() {
        *l = -*l;
    }
    // Residual of all N equations M Ẍ - psi - Q - S U + Gᵀ lambda = 0.
    let Data { g, ws, .. } = &*data;
    let (u, lambda) = (&ws.v2[..n_act], &ws.rhs);
    check_finite("U", u)?;
    check_finite("lambda", lambda)?;
    let mut residual = 0.0_f64;
    for (j, gcol) in g.data.0.iter().enumerate() {
        let mut r = ws.v[j];
        let a = model.actuator_of[j];
        if let Some(&ua) = u.get(a) {
            r -= ua;
        }
        for (&gij, &li) in gcol.iter().zip(lambda) {
            r += gij * li;
        }
        residual = residual.max(r.abs());
    }

    data.u = [0.0; N];
    data.u[..n_act].copy_from_slice(&data.ws.v2[..n_act]);
    data.lambda = data.ws.rhs;
    Ok(DynamicsReport {
        method,
        cond_blocks,
        cond,
        residual,
    })
}

/// Block elimination; `b` in `ws.v` on entry. Leaves `U` in `ws.v2[..n_act]` and `mu` in
/// `ws.rhs`. Returns `(worst block cond, reduced system cond)`.
fn block_elimination<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
) -> Result<(f64, f64), SolverError> {
    let s = model.structure();
    let cond_max = model.options.cond_max;
    let n = s.actuated.len();
    let Data { g, ws, .. } = data;
    let Workspace {
        rhs: mu,
        dx: t,
        lu,
        piv,
        work,
        z,
        v: b,
        v2: u,
        lu_n,
        piv_n,
        work_n,
        ..
    } = ws;
    // w_a, column a of an M × n matrix with leading dimension M (n M <= N M; for M = 0 the
    // slice is empty and `chunks_exact(M.max(1))` yields nothing).
    let w = &mut z.as_flattened_mut()[..n * M];
    w.fill(0.0);
    mu.fill(0.0);
    let mut worst = 0.0_f64;
    for (bk, blk) in s.ik_blocks.iter().enumerate() {
        let cond = factor_block(
            g,
            blk.rows,
            blk.cols,
            lu,
            piv,
            work,
            cond_max,
            WHAT_BLOCK,
            Some(bk),
        )?;
        worst = worst.max(cond);
        // Blocks are square with at most M <= N rows (Model::try_new).
        let t = &mut t[..blk.rows.len()];
        // lambda⁰_k = G_kk⁻ᵀ b_k.
        for (tc, &j) in t.iter_mut().zip(blk.cols) {
            *tc = b[j];
        }
        solve_block_transpose(lu, piv, t, WHAT_BLOCK, Some(bk))?;
        for (&tr, &i) in t.iter().zip(blk.rows) {
            mu[i] = tr;
        }
        // w_a = G_kk⁻ᵀ e_c for the actuated coordinate at position c of the block.
        for (c, &j) in blk.cols.iter().enumerate() {
            let a = model.actuator_of[j];
            if a >= n {
                continue; // not actuated
            }
            let col = &mut w[a * M..(a + 1) * M];
            t.fill(0.0);
            t[c] = 1.0;
            solve_block_transpose(lu, piv, t, WHAT_BLOCK, Some(bk))?;
            for (&tr, &i) in t.iter().zip(blk.rows) {
                col[i] = tr;
            }
        }
    }

    // The reduced system A U = G_oᵀ lambda⁰ - b_o, rows = outputs, cols = actuators.
    let a_mat = &mut lu_n.as_flattened_mut()[..n * n];
    let u = &mut u[..n];
    for (r, &o) in s.outputs.iter().enumerate() {
        let go = &g.data.0[o];
        for (a, wa) in w.chunks_exact(M.max(1)).enumerate() {
            a_mat[r + a * n] = dot(go, wa);
        }
        u[r] = dot(go, mu) - b[o];
    }
    let piv_n = &mut piv_n[..n];
    let cond = factor_lu(
        a_mat,
        n,
        piv_n,
        work_n.as_flattened_mut(),
        cond_max,
        WHAT_REDUCED,
        None,
        G_SOURCE,
    )?;
    linalg::lu_solve(a_mat, n, piv_n, u).map_err(|e| {
        super::lu_error(e, WHAT_REDUCED, None, n, G_SOURCE) // unreachable: sizes match
    })?;
    // mu = lambda⁰ - Σ_a w_a U_a.
    for (wa, &ua) in w.chunks_exact(M.max(1)).zip(u.iter()) {
        for (l, &wi) in mu.iter_mut().zip(wa) {
            *l -= wi * ua;
        }
    }
    Ok((worst, cond))
}

/// Dense LU of `[S | Gᵀ]`; `b` in `ws.v` on entry. Leaves `U` in `ws.v2[..n_act]` and
/// `mu` in `ws.rhs`. Returns the condition estimate.
fn dense_solve<K: Dynamics<N, M>, const N: usize, const M: usize>(
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
    let a = ws.lu_n.as_flattened_mut();
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
    let sol = &mut ws.v2;
    *sol = ws.v;
    let cond = factor_lu(
        a,
        N,
        &mut ws.piv_n,
        ws.work_n.as_flattened_mut(),
        model.options.cond_max,
        WHAT_DENSE,
        None,
        G_SOURCE,
    )?;
    linalg::lu_solve(a, N, &ws.piv_n, sol)
        .map_err(|e| super::lu_error(e, WHAT_DENSE, None, N, G_SOURCE))?;
    for (l, &v) in ws.rhs.iter_mut().zip(&sol[n_act..]) {
        *l = v;
    }
    Ok(cond)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
