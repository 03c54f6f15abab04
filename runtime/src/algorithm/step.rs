//! The Jacobians of one discrete step of the dynamics, for iLQR/DDP and direct methods: with
//! the state `s = (X, Ẋ)` (2N) and the control forces `U` held over the step (zero-order
//! hold), `F_x = ∂s'/∂s` (2N × 2N) and `F_u = ∂s'/∂U` (2N × na) of
//!
//! - one classic Runge–Kutta 4 step, `s' = s + h/6 (k1 + 2 k2 + 2 k3 + k4)`,
//!   `k_i = (Ẋ_i, Ẍ(X_i, Ẋ_i, U))` at the stages `s_1 = s`, `s_2 = s + h/2 k1`,
//!   `s_3 = s + h/2 k2`, `s_4 = s + h k3`: the integrator's `Method::Rk4` step without
//!   projection (`Stabilization::None`, or `Baumgarte` with its gains, which enter each stage's
//!   acceleration and so its derivatives);
//! - one semi-implicit (symplectic) Euler step [`semi_implicit_euler_step`]:
//!   `Ẋ' = Ẋ + h Ẍ(X, Ẋ, U)`, `X' = X + h Ẋ'`.
//!
//! By the chain rule through the stages: with `D` the derivative with respect to `(s, U)`,
//! `D s_i = [I 0] + c_i h D k_{i-1}` and `D k_i = J(s_i) D s_i + [0 B(s_i)]`, where
//! `J = [0 I; ∂Ẍ/∂X ∂Ẍ/∂Ẋ]` and `B = [0; ∂Ẍ/∂U]` come from
//! [`forward_dynamics_derivatives_with`](crate::forward_dynamics_derivatives_with) at each stage (four for RK4, one for Euler).
//!
//! The RK4 products run over rows (all `2N + na` directions of a row at once, the solve's own
//! layout) and use the elimination's split `[∂Ẍ/∂X ∂Ẍ/∂Ẋ] = X0 + R Z`: `Z D k` on the `P`
//! outputs' rows, then `X0`'s rows (non-zero only on the blocks' coordinates, and sparse there)
//! and `R` times it, rather than the dense `N × 2N` product (the dense product after the
//! dense LU).

use super::baumgarte::Baumgarte;
use super::derivatives::{
    DerivativesSolver, ForwardDynamicsDerivatives, Outputs, P_MAX, Terms, prepare, row_width,
    solve_prepared,
};
use super::forward_dynamics::forward_dynamics;
use super::report::DynamicsReport;
use crate::data::Data;
use crate::error::SolverError;
use crate::model::Model;
use crate::tasks::Derivatives;

/// The Jacobians of one step and the buffers that compute them: [`StepDerivatives::new`]
/// allocates once, the steps never.
#[derive(Debug, Clone)]
pub struct StepDerivatives<const N: usize, const M: usize> {
    /// `X` after the step.
    pub x: [f64; N],
    /// `Ẋ` after the step.
    pub xdot: [f64; N],
    /// The number of control forces `na` of the last call.
    pub na: usize,
    /// `F_x` and `F_u` side by side: `2N × (2N + na)`, column-major (column `c < 2N`: the
    /// derivative with respect to `s_c`, `(X, Ẋ)` in that order; column `2N + a`: with respect
    /// to `u[a]`).
    pub jacobian: Vec<f64>,
    /// Forward dynamics' derivatives at the last stage evaluated.
    pub derivatives: ForwardDynamicsDerivatives<N, M>,
    /// The stages' `D Ẍ_i = ∂Ẍ(s_i)/∂(s, U)` as rows (see `rk4_step_derivatives`): four blocks
    /// of N rows of the derivatives' row width.
    kv: Vec<f64>,
    /// `c h Z D k_{i-1}` (the outputs' rows of the low-rank part, see `rk4_step_derivatives`).
    tz: Vec<f64>,
}

impl<const N: usize, const M: usize> StepDerivatives<N, M> {
    /// Zeroed Jacobians and the buffers (the only allocation).
    pub fn new() -> Self {
        let len = 2 * N * 3 * N;
        Self {
            x: [0.0; N],
            xdot: [0.0; N],
            na: 0,
            jacobian: vec![0.0; len],
            derivatives: ForwardDynamicsDerivatives::new(),
            kv: vec![0.0; 4 * N * row_width(N, N)],
            tz: vec![0.0; P_MAX * row_width(N, N)],
        }
    }

    /// `F_x[i, j] = ∂s'_i/∂s_j` (`i, j < 2N`).
    pub fn fx(&self, i: usize, j: usize) -> f64 {
        self.jacobian[j * 2 * N + i]
    }

    /// `F_u[i, a] = ∂s'_i/∂u_a` (`i < 2N`, `a < na`).
    pub fn fu(&self, i: usize, a: usize) -> f64 {
        self.jacobian[(2 * N + a) * 2 * N + i]
    }
}

impl<const N: usize, const M: usize> Default for StepDerivatives<N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// One semi-implicit Euler step of `dt` from `data.x`, `data.xdot` with the control forces
/// `u` and Baumgarte's gains `baumgarte`: `Ẋ' = Ẋ + dt Ẍ`, `X' = X + dt Ẋ'`, written to
/// `data.x`, `data.xdot` (`data.xddot` holds the acceleration at the start). Errors: those of
/// [`forward_dynamics`]; `NonFinite` for a step that is not finite.
pub fn semi_implicit_euler_step<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    u: &[f64],
    dt: f64,
    baumgarte: Baumgarte,
) -> Result<DynamicsReport, SolverError> {
    if !dt.is_finite() {
        return Err(SolverError::NonFinite { what: "dt" });
    }
    let report = forward_dynamics(model, data, u, None, baumgarte)?;
    for j in 0..N {
        data.xdot[j] += dt * data.xddot[j];
        data.x[j] += dt * data.xdot[j];
    }
    Ok(report)
}

/// Forward dynamics' derivatives at `(x, xdot)` into `out.derivatives` (`outputs` of them),
/// `Ẍ` into `acc`.
#[allow(clippy::too_many_arguments)]
fn stage<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut StepDerivatives<N, M>,
    u: &[f64],
    baumgarte: Baumgarte,
    x: &[f64; N],
    xdot: &[f64; N],
    acc: &mut [f64; N],
    outputs: Outputs,
) -> Result<(), SolverError> {
    data.x = *x;
    data.xdot = *xdot;
    let (_, reduced) = prepare(
        model,
        data,
        &mut out.derivatives,
        u,
        None,
        baumgarte,
        DerivativesSolver::Auto,
    )?;
    solve_prepared(model, data, &mut out.derivatives, reduced, outputs)?;
    *acc = data.xddot;
    Ok(())
}

/// One classic RK4 step of `dt` from `data.x`, `data.xdot` with the control forces `u` held
/// and Baumgarte's gains `baumgarte`, and its Jacobians `F_x`, `F_u` (see the
/// [module](self) documentation) into `out`; the new state in `out.x`, `out.xdot` (`data`
/// holds the last stage's). Errors: those of [`forward_dynamics_derivatives_with`](crate::forward_dynamics_derivatives_with) at any
/// stage; `NonFinite` for a `dt` or a Jacobian that is not finite.
pub fn rk4_step_derivatives<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut StepDerivatives<N, M>,
    u: &[f64],
    dt: f64,
    baumgarte: Baumgarte,
) -> Result<(), SolverError> {
    if !dt.is_finite() {
        return Err(SolverError::NonFinite { what: "dt" });
    }
    let na = model.structure().actuated.len();
    let n2 = 2 * N;
    let cols = n2 + na;
    let w = row_width(N, na);
    out.na = na;
    let (x0, v0) = (data.x, data.xdot);
    let mut acc = [0.0; N];
    let (mut xs, mut vs) = (x0, v0);
    let (mut x1, mut v1) = (x0, v0);
    let stages = [(0.0, 1.0), (0.5, 2.0), (0.5, 2.0), (1.0, 1.0)];
    let mut t = Terms::new();
    for (i, &(c, b)) in stages.iter().enumerate() {
        // s_i = s + c h k_{i-1} (k_{i-1} = (vs, acc) of the previous stage).
        if i > 0 {
            let (kx, kv) = (vs, acc);
            for j in 0..N {
                xs[j] = x0[j] + c * dt * kx[j];
                vs[j] = v0[j] + c * dt * kv[j];
            }
        }
        // The rows of ∂Ẍ are all the products use; the last stage's derivatives whole (what
        // `out.derivatives` documents).
        let outputs = if i + 1 < stages.len() {
            Outputs::XddotRows
        } else {
            Outputs::All
        };
        stage(model, data, out, u, baumgarte, &xs, &vs, &mut acc, outputs)?;
        // D Ẍ_i = wx_i + c h (J_x,i D Ẋ_{i-1} + J_v,i D Ẍ_{i-1}) with
        // D Ẋ_{i-1} = E_v + c_{i-1} h D Ẍ_{i-2} (module documentation; wx_i the rows of
        // [∂Ẍ/∂X ∂Ẍ/∂Ẋ ∂Ẍ/∂U] at the stage, E_v the unit rows of Ẋ).
        let wx = &out.derivatives.xddot_rows()[..N * w];
        let (prev, rest) = out.kv.split_at_mut(i * N * w);
        let cur = &mut rest[..N * w];
        cur.copy_from_slice(wx);
        if i > 0 {
            let jd = JdProduct {
                ch: c * dt,
                cph: if i > 1 { stages[i - 1].0 * dt } else { 0.0 },
                i,
                w,
            };
            let p = model.structure().outputs.len();
            match (
                out.derivatives.low_rank_rows(),
                out.derivatives.reduced_parts(),
            ) {
                (Some((x0, z)), Some((rt, _, _))) if p <= P_MAX => {
                    // J_i = X0 + R Z (X0 zero off the blocks' rows): Z D k_{i-1} first
                    // (P rows), then X0's rows and R times it.
                    let tz = &mut out.tz[..p * w];
                    for (trow, zrow) in tz.chunks_exact_mut(w).zip(z.chunks_exact(w)) {
                        trow.fill(0.0);
                        jd.add::<N>(&mut t, zrow, trow, prev);
                    }
                    for (r, row) in cur.chunks_exact_mut(w).enumerate() {
                        if model.ik_block_of[r] < model.structure().ik_blocks.len() {
                            jd.add::<N>(&mut t, &x0[r * w..(r + 1) * w], row, prev);
                        }
                        for c in 0..p {
                            t.push(rt[c * N + r], c, row, tz, w);
                        }
                        t.flush(row, tz, w);
                    }
                }
                _ => {
                    for (row, src) in cur.chunks_exact_mut(w).zip(wx.chunks_exact(w)) {
                        jd.add::<N>(&mut t, src, row, prev);
                    }
                }
            }
        }
        for j in 0..N {
            x1[j] += dt / 6.0 * b * vs[j];
            v1[j] += dt / 6.0 * b * acc[j];
        }
    }
    // F = I + h/6 Σ b_i D k_i, D k_i = (D Ẋ_i, D Ẍ_i): the rows of X gather
    // h Σ b_i c_i D Ẍ_{i-1} = h (D Ẍ_1 + D Ẍ_2 + D Ẍ_3) beside 6 E_v, those of Ẋ
    // D Ẍ_1 + 2 D Ẍ_2 + 2 D Ẍ_3 + D Ẍ_4.
    let kv = &out.kv[..4 * N * w];
    let (k1, rest) = kv.split_at(N * w);
    let (k2, rest) = rest.split_at(N * w);
    let (k3, k4) = rest.split_at(N * w);
    let (hx, hv) = (dt * dt / 6.0, dt / 6.0);
    let jac = &mut out.jacobian[..n2 * cols];
    for (col, c) in jac.chunks_exact_mut(n2).zip(0..cols) {
        let (top, bottom) = col.split_at_mut(N);
        for k in 0..N {
            let e = k * w + c;
            top[k] = hx * (k1[e] + k2[e] + k3[e]);
            bottom[k] = hv * (k1[e] + 2.0 * (k2[e] + k3[e]) + k4[e]);
        }
        if c < N {
            top[c] += 1.0;
        } else if c < n2 {
            top[c - N] += dt;
            bottom[c - N] += 1.0;
        }
    }
    out.x = x1;
    out.xdot = v1;
    finite(&out.jacobian[..n2 * cols])
}

/// `row += c h (J D k_{i-1})` for a row `J` of `[∂Ẍ/∂X ∂Ẍ/∂Ẋ]` (the first 2N entries of
/// `src`), with `D k_{i-1} = (D Ẋ_{i-1}, D Ẍ_{i-1})`, `D Ẋ_{i-1} = E_v + c_{i-1} h D Ẍ_{i-2}`
/// and the earlier stages' `D Ẍ` in `prev` (N rows each).
struct JdProduct {
    /// `c_i h`.
    ch: f64,
    /// `c_{i-1} h` (zero at the second stage: `D Ẋ_1 = E_v`).
    cph: f64,
    i: usize,
    w: usize,
}

impl JdProduct {
    #[inline(always)]
    fn add<const N: usize>(&self, t: &mut Terms, src: &[f64], row: &mut [f64], prev: &[f64]) {
        let (ch, i, w) = (self.ch, self.i, self.w);
        for k in 0..N {
            row[N + k] += ch * src[k];
        }
        for k in 0..N {
            if self.cph != 0.0 {
                t.push(ch * self.cph * src[k], (i - 2) * N + k, row, prev, w);
            }
            t.push(ch * src[N + k], (i - 1) * N + k, row, prev, w);
        }
        t.flush(row, prev, w);
    }
}

/// One semi-implicit Euler step ([`semi_implicit_euler_step`]) and its Jacobians `F_x`, `F_u`
/// into `out` (the new state in `out.x`, `out.xdot` and in `data`). Errors: those of
/// [`forward_dynamics_derivatives_with`](crate::forward_dynamics_derivatives_with); `NonFinite` for a `dt` or a Jacobian that is not
/// finite.
pub fn semi_implicit_euler_step_derivatives<
    K: Derivatives<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut StepDerivatives<N, M>,
    u: &[f64],
    dt: f64,
    baumgarte: Baumgarte,
) -> Result<(), SolverError> {
    if !dt.is_finite() {
        return Err(SolverError::NonFinite { what: "dt" });
    }
    let na = model.structure().actuated.len();
    let n2 = 2 * N;
    let len = n2 * (n2 + na);
    out.na = na;
    let (x0, v0) = (data.x, data.xdot);
    let mut acc = [0.0; N];
    stage(
        model,
        data,
        out,
        u,
        baumgarte,
        &x0,
        &v0,
        &mut acc,
        Outputs::All,
    )?;
    // D Ẋ' = [0 I 0] + h [∂Ẍ/∂X ∂Ẍ/∂Ẋ ∂Ẍ/∂U]; D X' = [I 0 0] + h D Ẋ'.
    let fd = &out.derivatives;
    let jac = &mut out.jacobian[..len];
    for c in 0..n2 + na {
        let col = &mut jac[c * n2..(c + 1) * n2];
        let src: &[f64; N] = match c {
            c if c < N => &fd.dxddot_dx.data.0[c],
            c if c < n2 => &fd.dxddot_dxdot.data.0[c - N],
            c => &fd.dxddot_du.data.0[c - n2],
        };
        let (top, bottom) = col.split_at_mut(N);
        for (b, &m) in bottom.iter_mut().zip(src) {
            *b = dt * m;
        }
        if (N..n2).contains(&c) {
            bottom[c - N] += 1.0;
        }
        for (t, &b) in top.iter_mut().zip(bottom.iter()) {
            *t = dt * b;
        }
        if c < N {
            top[c] += 1.0;
        }
    }
    for j in 0..N {
        data.xdot[j] = v0[j] + dt * acc[j];
        data.x[j] = x0[j] + dt * data.xdot[j];
    }
    out.x = data.x;
    out.xdot = data.xdot;
    finite(&out.jacobian[..len])
}

fn finite(v: &[f64]) -> Result<(), SolverError> {
    if super::input::all_finite(v) {
        Ok(())
    } else {
        Err(SolverError::NonFinite {
            what: "step Jacobian",
        })
    }
}
