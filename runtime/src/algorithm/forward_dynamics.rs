//! Forward dynamics (paper eqs. 29-32): given the state `X, Ẋ`, the control forces `U` and the
//! applied forces `Q`, find `Ẍ` and the Lagrange multipliers `lambda` of the saddle-point system
//!
//! ```text
//! M Ẍ + Gᵀ lambda = F,   F = psi(X, Ẋ) + Q + S U
//! G Ẍ             = gamma_stab = gamma(X, Ẋ) - 2 alpha G Ẋ - beta² f(X)
//! ```
//!
//! by the Schur complement on the block-diagonal `M` (`Dynamics::mass_blocks`):
//!
//! 1. Cholesky `M_b = L_b L_bᵀ` of every block (for the 6-UPS all blocks but one are 1 × 1);
//! 2. `Z = L⁻¹ Gᵀ` (N × M) and `z_F = L⁻¹ F`, blockwise forward substitutions;
//! 3. `S_c = G M⁻¹ Gᵀ = Zᵀ Z` (M × M, symmetric positive definite when `G` has full rank):
//!    Cholesky, 1-norm condition estimate, and `S_c lambda = Zᵀ z_F - gamma_stab`;
//! 4. `Ẍ = L⁻ᵀ (z_F - Z lambda)`, blockwise back substitutions.
//!
//! Forming `S_c` as `Zᵀ Z` keeps it exactly symmetric. Cost beyond the kernels:
//! `O(M² N)` for `S_c` and `O(M³)` for its factorisation.

use super::{
    Baumgarte, DynamicsMethod, DynamicsReport, check_finite, check_input, dynamics_terms,
    factor_spd, mat_vec,
};
use crate::data::{Data, Workspace};
use crate::error::SolverError;
use crate::kernels::Dynamics;
use crate::linalg::{self, LuError};
use crate::model::Model;

const WHAT_SC: &str = "S_c = G M⁻¹ Gᵀ";
const SC_SOURCE: &str = "G or M (kernel output)";

/// Solves the forward dynamics at `data.x`, `data.xdot` for the control forces `u`
/// (`Structure::actuated` order, length `N - M`) and the applied forces `q_forces` (`Q`, N,
/// zero if `None`), with Baumgarte's stabilisation `baumgarte` ([`Baumgarte::NONE`] for none).
/// Writes `data.xddot`, `data.lambda` and `data.u` (a copy of `u`) on success; `data.mass`,
/// `data.psi`, `data.g`, `data.gamma` (the kernel's `gamma`, without Baumgarte's terms) and,
/// when `beta != 0`, `data.f` in any case. Calls the fused `Dynamics::dynamics_terms` (`G`,
/// `gamma`, `M`, `psi`) and, if `beta != 0`, `Kernels::constraints`, once each. See the
/// [module](self) documentation for the algorithm.
///
/// The report gives `cond_blocks`, a lower bound of the condition number of `M` from the
/// Cholesky pivots, and `cond`, the estimate for `S_c`.
///
/// Errors: `Dimension` for a `u` of the wrong length or inconsistent `Dynamics::mass_blocks`;
/// `NonFinite` for a NaN/inf in the state, `u`, `q_forces`, the gains or a kernel output;
/// `NotPositiveDefinite` for a block of `M` that is not positive definite; `Singular` when
/// `S_c` is (numerically) singular, i.e. `G` loses rank: a singularity of the constraints.
pub fn forward_dynamics<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    q_forces: Option<&[f64; N]>,
    baumgarte: Baumgarte,
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
    let blocks = dynamics_terms(model, data)?;
    if beta != 0.0 {
        k.constraints(&data.x, &mut data.f);
        check_finite("f (constraint kernel output)", &data.f)?;
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
        lu: sc,
        work,
        lu_n,
        z,
        v: force,
        v2: scratch,
        ..
    } = ws;

    // F = psi + Q + S U.
    for (j, fj) in force.iter_mut().enumerate() {
        *fj = psi[j] + q_forces.map_or(0.0, |q| q[j]);
    }
    for (&j, &ua) in s.actuated.iter().zip(u) {
        force[j] += ua;
    }
    // gamma_stab = gamma - 2 alpha G Ẋ - beta² f, in the first M entries of ws.dx (M <= N).
    let gamma_stab = &mut gamma_stab[..M];
    mat_vec(g, xdot, lambda); // lambda: scratch for G Ẋ
    for (i, gs) in gamma_stab.iter_mut().enumerate() {
        *gs = gamma[i] - 2.0 * alpha * lambda[i];
        if beta != 0.0 {
            *gs -= beta * beta * f[i];
        }
    }
    check_finite("gamma_stab (Baumgarte)", gamma_stab)?;

    // 1. Cholesky of every block of M, packed one after the other in ws.lu_n.
    let factors = lu_n.as_flattened_mut();
    let (mut pmin, mut pmax) = (f64::INFINITY, 0.0_f64);
    let mut off = 0;
    for (b, blk) in blocks.iter().enumerate() {
        let kb = blk.len();
        // Σ kb² <= (Σ kb)² = N² (blocks checked).
        let l = &mut factors[off..off + kb * kb];
        for (c, &jc) in blk.iter().enumerate() {
            for (r, &jr) in blk.iter().enumerate() {
                l[r + c * kb] = mass.data.0[jc][jr];
            }
        }
        linalg::cholesky_factor(l, kb).map_err(|e| match e {
            LuError::NotPositiveDefinite { column } => SolverError::NotPositiveDefinite {
                what: "mass block",
                block: Some(b),
                column,
            },
            _ => SolverError::NonFinite {
                what: "M (mass kernel output)",
            },
        })?;
        for i in 0..kb {
            let p = l[i + i * kb] * l[i + i * kb];
            pmin = pmin.min(p);
            pmax = pmax.max(p);
        }
        off += kb * kb;
    }
    let cond_blocks = if pmin > 0.0 {
        pmax / pmin
    } else {
        f64::INFINITY
    };

    // 2. Z = L⁻¹ Gᵀ (column i from row i of G) and z_F = L⁻¹ F.
    for (i, zi) in z.iter_mut().enumerate() {
        for (zij, gcol) in zi.iter_mut().zip(g.data.0.iter()) {
            *zij = gcol[i];
        }
        apply_blocks(factors, blocks, zi, scratch, Pass::Forward);
    }
    apply_blocks(factors, blocks, force, scratch, Pass::Forward);
    check_finite("L⁻¹ Gᵀ", z.as_flattened())?;
    check_finite("L⁻¹ F", force)?;

    // 3. S_c = Zᵀ Z, right-hand side Zᵀ z_F - gamma_stab, lambda.
    let sc = sc.as_flattened_mut();
    for c in 0..M {
        for r in c..M {
            let v = dot(&z[r], &z[c]);
            sc[r + c * M] = v;
            sc[c + r * M] = v;
        }
    }
    for (i, l) in lambda.iter_mut().enumerate() {
        *l = dot(&z[i], force) - gamma_stab[i];
    }
    let cond = factor_spd(
        sc,
        M,
        work.as_flattened_mut(),
        model.options.cond_max,
        WHAT_SC,
        SC_SOURCE,
    )?;
    linalg::cholesky_solve(sc, M, lambda)
        .map_err(|e| super::lu_error(e, WHAT_SC, None, M, SC_SOURCE))?;
    check_finite("lambda", lambda)?;

    // 4. Ẍ = L⁻ᵀ (z_F - Z lambda), in ws.v.
    for (zi, &li) in z.iter().zip(lambda.iter()) {
        if li != 0.0 {
            for (fj, &zij) in force.iter_mut().zip(zi) {
                *fj -= zij * li;
            }
        }
    }
    apply_blocks(factors, blocks, force, scratch, Pass::Backward);
    check_finite("Ẍ", force)?;

    // Residual of the acceleration constraint.
    let mut residual = 0.0_f64;
    for (i, &gs) in gamma_stab.iter().enumerate() {
        let gx: f64 = g
            .data
            .0
            .iter()
            .zip(force.iter())
            .map(|(c, a)| c[i] * a)
            .sum();
        residual = residual.max((gx - gs).abs());
    }

    data.xddot = data.ws.v;
    data.lambda = data.ws.rhs;
    data.u = [0.0; N];
    data.u[..n_act].copy_from_slice(u);
    Ok(DynamicsReport {
        method: DynamicsMethod::SchurComplement,
        cond_blocks,
        cond,
        residual,
    })
}

#[derive(Clone, Copy)]
enum Pass {
    /// `v := L⁻¹ v`.
    Forward,
    /// `v := L⁻ᵀ v`.
    Backward,
}

/// Applies `L⁻¹` or `L⁻ᵀ` of the block-diagonal Cholesky factor packed in `factors` to `v`
/// (blocks checked; factors finite and with a positive diagonal, so the triangular solves
/// cannot fail).
fn apply_blocks<const N: usize>(
    factors: &[f64],
    blocks: &[&[usize]],
    v: &mut [f64; N],
    scratch: &mut [f64; N],
    pass: Pass,
) {
    let mut off = 0;
    for blk in blocks {
        let kb = blk.len();
        let l = &factors[off..off + kb * kb];
        off += kb * kb;
        if let [j] = **blk {
            v[j] /= l[0];
            continue;
        }
        let t = &mut scratch[..kb];
        for (ti, &j) in t.iter_mut().zip(blk.iter()) {
            *ti = v[j];
        }
        if t.iter().all(|&x| x == 0.0) {
            continue;
        }
        // Dimensions match by construction; an error cannot occur.
        let _ = match pass {
            Pass::Forward => linalg::cholesky_forward(l, kb, t),
            Pass::Backward => linalg::cholesky_backward(l, kb, t),
        };
        for (&ti, &j) in t.iter().zip(blk.iter()) {
            v[j] = ti;
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
