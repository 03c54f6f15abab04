//! The Jacobians of a step followed by the projection the integrator makes after it
//! (`Stabilization::Projection`): the raw step `s⁺ = (X⁺, Ẋ⁺)` of [`rk4_step_derivatives`] or
//! [`semi_implicit_euler_step_derivatives`], then `X*` by [`project_position`] (Gauss–Newton with
//! minimum-norm steps onto `f(X) = 0`) and `Ẋ* = P(X*) Ẋ⁺` by [`project_velocity`] (the
//! orthogonal projection onto `G(X*) Ẋ = 0`, `P = I - G⁺ G`, `G⁺ = Gᵀ (G Gᵀ)⁻¹`).
//!
//! By the chain rule, with `D` the derivative with respect to `(s, U)`, through each
//! Gauss–Newton step `X_{k+1} = X_k - Gᵀ nu_k`, `nu_k = (G Gᵀ)⁻¹ f(X_k)` (all at `X_k`), then
//! through the velocity projection (`mu = (G Gᵀ)⁻¹ G Ẋ⁺` at `X*`, so `Ẋ* = Ẋ⁺ - Gᵀ mu`):
//!
//! ```text
//! D X_{k+1} = P (D X_k - ∂(Gᵀ nu_k)/∂X D X_k) + G⁺ ∂(G d)/∂X D X_k,   d = Gᵀ nu_k (the step)
//! D X*      = P(X*) D X_last
//! D Ẋ*      = P (D Ẋ⁺ - ∂(Gᵀ mu)/∂X D X*) - G⁺ ∂(G v)/∂X D X*,        v = Ẋ*
//! ```
//!
//! (differentiating `G⁺ f` and `P v` exactly). The last `P(X*)` is the derivative of the
//! converged projection (one more Gauss–Newton step from `X*`, where `f = 0`): without it a
//! state already within tolerance would have the identity as its derivative, and a perturbed
//! one would not. `∂(G v)/∂X = ½ ∂c/∂Ẋ` of the acceleration constraint `c = G Ẍ - gamma` at
//! `Ẋ = v` (gamma is quadratic in `Ẋ`: `gamma = -(∂(G Ẋ)/∂X) Ẋ`), and `∂(Gᵀ lambda)/∂X` is the
//! part of `∂r/∂X` linear in `lambda` (the difference of two calls): both from the generated
//! kernel `dynamics_derivatives`, two calls per Gauss–Newton step and two for the velocity. `P`
//! and `G⁺` are applied through the pivoted QR of `Gᵀ` the projections use (`G Gᵀ` is never
//! formed). Exact to rounding: the test compares with central differences of the projected step.
//!
//! [`rk4_step_derivatives`]: super::step::rk4_step_derivatives
//! [`semi_implicit_euler_step_derivatives`]: super::step::semi_implicit_euler_step_derivatives
//! [`project_position`]: super::projection::project_position

use super::input::{check_finite, max_abs};
use super::projection::{factor_qr, project_position_with, project_velocity, tangent};
use super::step::StepDerivatives;
use crate::data::Data;
use crate::error::SolverError;
use crate::linalg;
use crate::model::Model;
use crate::tasks::{Derivatives, Jacobian};

/// What [`project_step_derivatives`] measured: how far the raw step landed from the manifold
/// (the size of the terms its Jacobians leave out, relative to one) and the projection's work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepProjection {
    /// `max |f(X⁺)|` of the raw step.
    pub position_residual: f64,
    /// `max |G(X*) Ẋ⁺|` of the raw step's velocity at the projected position.
    pub velocity_residual: f64,
    /// Gauss–Newton steps of the position projection.
    pub iterations: usize,
    /// The condition number of `G(X*)` from its pivoted QR (see [`project_velocity`]).
    pub cond: f64,
}

/// Projects the new state of a step's Jacobians `out` (written by [`rk4_step_derivatives`] or
/// [`semi_implicit_euler_step_derivatives`]) onto the constraint manifold as the integrator's
/// `Stabilization::Projection` does after a step, and maps `F_x`, `F_u` through the
/// projection's derivative (see the [module](self) documentation): on return `out.x`,
/// `out.xdot` are the projected state and `out.jacobian` the Jacobians of the projected step.
/// `data` is scratch (it holds the projected state on return). Allocates nothing.
///
/// Errors: those of [`project_position`] and [`project_velocity`] (`Singular` when `G` loses
/// rank, `NotConverged`, `NonFinite`); `NonFinite` for a Jacobian that is not finite.
///
/// [`rk4_step_derivatives`]: super::step::rk4_step_derivatives
/// [`semi_implicit_euler_step_derivatives`]: super::step::semi_implicit_euler_step_derivatives
/// [`project_position`]: super::projection::project_position
pub fn project_step_derivatives<
    K: Derivatives<N, M> + Jacobian<N, M>,
    const N: usize,
    const M: usize,
>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    out: &mut StepDerivatives<N, M>,
) -> Result<StepProjection, SolverError> {
    let k = model.kernels();
    let (x_raw, v_raw) = (out.x, out.xdot);
    check_finite("step's X", &x_raw)?;
    check_finite("step's Xdot", &v_raw)?;
    let mut f = [0.0; M];
    k.constraints(&x_raw, &mut f);
    let position_residual = max_abs(&f);
    let n2 = 2 * N;
    let cols = n2 + out.na;
    let jac = &mut out.jacobian[..cols * n2];
    let mut sc = Scratch::<N, M>::new();
    // The position: through every Gauss–Newton step the projection takes.
    data.x = x_raw;
    let rep = project_position_with(model, data, &mut |st| {
        let nu = gram_solve::<N, M>(st.qr, st.piv, st.rt_f);
        sc.contract(k, st.x, st.step, &nu);
        for col in jac.chunks_exact_mut(n2) {
            let dx = &mut col[..N];
            let w = sc.a_times(dx);
            sc.subtract_h_times(dx);
            tangent::<N, M>(st.qr, st.tau, dx);
            let z = pinv_apply::<N, M>(st.qr, st.tau, st.piv, &w);
            for (d, zj) in dx.iter_mut().zip(&z) {
                *d += zj;
            }
        }
    })?;
    // The velocity, at X*.
    data.xdot = v_raw;
    project_velocity(model, data)?;
    let (x_star, v_star) = (data.x, data.xdot);
    let mut gv = [0.0; M];
    crate::plan::mat_vec(&data.g, &v_raw, &mut gv);
    let velocity_residual = max_abs(&gv);
    let mut qr = [[0.0; N]; M];
    let mut piv = [0usize; M];
    let mut work = [[0.0; M]; 2];
    let cond = factor_qr(
        &data.g,
        &mut qr,
        &mut piv,
        &mut work,
        model.options.cond_max,
    )?;
    let tau = work[0];
    let qr = qr.as_flattened();
    // mu = P R⁻¹ R⁻ᵀ Pᵀ (G Ẋ⁺).
    let mu = gram_solve::<N, M>(qr, &piv, &rt_solve::<N, M>(qr, &piv, &gv));
    sc.contract(k, &x_star, &v_star, &mu);
    for col in jac.chunks_exact_mut(n2) {
        let (dx, dv) = col.split_at_mut(N);
        // D X* = P(X*) D X_last.
        tangent::<N, M>(qr, &tau, dx);
        // D Ẋ* = P (D Ẋ⁺ - ∂(Gᵀ mu)/∂X D X*) - G⁺ ∂(G Ẋ*)/∂X D X*.
        let w = sc.a_times(dx);
        let mut hdx = [0.0; N];
        sc.h_times(dx, &mut hdx);
        for (d, h) in dv.iter_mut().zip(&hdx) {
            *d -= h;
        }
        tangent::<N, M>(qr, &tau, dv);
        let z = pinv_apply::<N, M>(qr, &tau, &piv, &w);
        for (d, zj) in dv.iter_mut().zip(&z) {
            *d -= zj;
        }
    }
    check_finite("projected step Jacobian", jac)?;
    out.x = x_star;
    out.xdot = v_star;
    Ok(StepProjection {
        position_residual,
        velocity_residual,
        iterations: rep.iterations,
        cond,
    })
}

/// The kernel's outputs two calls need, on the stack.
struct Scratch<const N: usize, const M: usize> {
    /// `∂r/∂X` at `lambda = 0`, then (after [`Scratch::contract`]) `∂(Gᵀ lambda)/∂X`.
    dr0: [[f64; N]; N],
    dr1: [[f64; N]; N],
    dr_dxdot: [[f64; N]; N],
    dc_dx: [[f64; M]; N],
    /// `∂c/∂Ẋ = 2 ∂(G v)/∂X` at the call's `Ẋ = v`.
    dc_dxdot: [[f64; M]; N],
}

impl<const N: usize, const M: usize> Scratch<N, M> {
    fn new() -> Self {
        Self {
            dr0: [[0.0; N]; N],
            dr1: [[0.0; N]; N],
            dr_dxdot: [[0.0; N]; N],
            dc_dx: [[0.0; M]; N],
            dc_dxdot: [[0.0; M]; N],
        }
    }

    /// `∂(G v)/∂X` (in `dc_dxdot`, doubled) and `∂(Gᵀ lambda)/∂X` (in `dr1`) at `x`. The kernel
    /// writes its structural non-zeros only: the same entries in every call at any state, so
    /// the buffers need no zeroing between calls.
    fn contract<K: Derivatives<N, M>>(
        &mut self,
        k: &K,
        x: &[f64; N],
        v: &[f64; N],
        lambda: &[f64; M],
    ) {
        let zero = [0.0; N];
        let s = self;
        k.dynamics_derivatives(
            x,
            v,
            &zero,
            &[0.0; M],
            &mut s.dr0,
            &mut s.dr_dxdot,
            &mut s.dc_dx,
            &mut s.dc_dxdot,
        );
        k.dynamics_derivatives(
            x,
            v,
            &zero,
            lambda,
            &mut s.dr1,
            &mut s.dr_dxdot,
            &mut s.dc_dx,
            &mut s.dc_dxdot,
        );
        for (c1, c0) in s.dr1.iter_mut().zip(&s.dr0) {
            for (a, b) in c1.iter_mut().zip(c0) {
                *a -= b;
            }
        }
    }

    /// `∂(G v)/∂X dx`.
    fn a_times(&self, dx: &[f64]) -> [f64; M] {
        let mut w = [0.0; M];
        for (col, &d) in self.dc_dxdot.iter().zip(dx) {
            if d != 0.0 {
                for (wi, &a) in w.iter_mut().zip(col) {
                    *wi += 0.5 * a * d;
                }
            }
        }
        w
    }

    /// `out = ∂(Gᵀ lambda)/∂X dx`.
    fn h_times(&self, dx: &[f64], out: &mut [f64; N]) {
        out.fill(0.0);
        for (col, &d) in self.dr1.iter().zip(dx) {
            if d != 0.0 {
                for (o, &h) in out.iter_mut().zip(col) {
                    *o += h * d;
                }
            }
        }
    }

    /// `dx -= ∂(Gᵀ lambda)/∂X dx`.
    fn subtract_h_times(&self, dx: &mut [f64]) {
        let mut h = [0.0; N];
        self.h_times(dx, &mut h);
        for (d, hv) in dx.iter_mut().zip(&h) {
            *d -= hv;
        }
    }
}

/// `G⁺ w = Gᵀ (G Gᵀ)⁻¹ w = Q₁ R⁻ᵀ Pᵀ w`.
fn pinv_apply<const N: usize, const M: usize>(
    qr: &[f64],
    tau: &[f64],
    piv: &[usize],
    w: &[f64; M],
) -> [f64; N] {
    let mut z = [0.0; N];
    z[..M].copy_from_slice(&rt_solve::<N, M>(qr, piv, w));
    linalg::apply_q(qr, N, tau, M, &mut z, false);
    z
}

/// `R⁻ᵀ Pᵀ y` (forward substitution with the QR's `R`, the pivoted entries of `y`).
fn rt_solve<const N: usize, const M: usize>(qr: &[f64], piv: &[usize], y: &[f64; M]) -> [f64; M] {
    let mut t = [0.0; M];
    for i in 0..M {
        let r = &qr[i * N..i * N + i];
        t[i] = (y[piv[i]] - linalg::dot4(r, &t[..i])) / qr[i + i * N];
    }
    t
}

/// `(G Gᵀ)⁻¹ y = P R⁻¹ R⁻ᵀ Pᵀ y` from `rt = R⁻ᵀ Pᵀ y`.
fn gram_solve<const N: usize, const M: usize>(qr: &[f64], piv: &[usize], rt: &[f64]) -> [f64; M] {
    let mut t = [0.0; M];
    t.copy_from_slice(&rt[..M]);
    for i in (0..M).rev() {
        let mut v = t[i];
        for (j, tj) in t.iter().enumerate().skip(i + 1) {
            v -= qr[i + j * N] * tj;
        }
        t[i] = v / qr[i + i * N];
    }
    let mut y = [0.0; M];
    for (i, &ti) in t.iter().enumerate() {
        y[piv[i]] = ti;
    }
    y
}
