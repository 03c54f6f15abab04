//! The Jacobians of a step followed by the integrator's projection (`project_step_derivatives`)
//! against fourth-order central differences of that projected step itself (the raw RK4 or
//! semi-implicit Euler step, then `project_position` and `project_velocity` as the simulator
//! calls them), on the 6-UPS and the five-bar, from states on the manifold (where the terms the
//! position part leaves out, proportional to the raw step's distance from the manifold, are of
//! the step's local error: RK4 with dt = 1e-2, Euler with 1e-4, both drifting below 1e-7). The projected RK4 step is also checked against the integrator's
//! (`Simulator`, `Method::Rk4`, `Stabilization::Projection`, one step): relative difference
//! <= 1e-12. And the projection is not the identity on the Jacobians: the projected `F_x`
//! differs from the raw one by more than the tolerance, and its columns lie in the tangent space
//! (`G(X*) D X* = 0` to rounding).
//!
//! Error of an entry: `|a - b| / (|a| + |b| + floor)`, asserted `<= 1e-6`, with the floor
//! `10 eps F / (h TOL)` (`F` the largest entry of the state, `h = 1e-3`), as in
//! `step_derivatives.rs`.

mod common;

use common::XorShift;
use rbss_runtime::integrate::Stabilization;
use rbss_runtime::tasks::{Derivatives, Jacobian, Simulate};
use rbss_runtime::{
    Baumgarte, Data, Model, SolverOptions, StepDerivatives, project_position,
    project_step_derivatives, project_velocity, rk4_step_derivatives, semi_implicit_euler_step,
    semi_implicit_euler_step_derivatives,
};

const TOL: f64 = 1e-6;

#[derive(Clone, Copy, Debug)]
enum Step {
    Rk4,
    Euler,
}

/// The raw step's Jacobians (and new state) from `(x, v)` with `u`.
#[allow(clippy::too_many_arguments)]
fn raw<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    kind: Step,
    x: &[f64; N],
    v: &[f64; N],
    u: &[f64],
    dt: f64,
    out: &mut StepDerivatives<N, M>,
) {
    let mut d = Data::new(model);
    d.x = *x;
    d.xdot = *v;
    match kind {
        Step::Rk4 => rk4_step_derivatives(model, &mut d, out, u, dt, Baumgarte::NONE),
        Step::Euler => {
            semi_implicit_euler_step_derivatives(model, &mut d, out, u, dt, Baumgarte::NONE)
        }
    }
    .unwrap();
}

/// The projected step's new state `(X*, Ẋ*)`: the raw step, then the projections as the
/// simulator makes them (position, then velocity at the new position).
fn projected<K: Derivatives<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    kind: Step,
    x: &[f64; N],
    v: &[f64; N],
    u: &[f64],
    dt: f64,
) -> Vec<f64> {
    let mut d = Data::new(model);
    d.x = *x;
    d.xdot = *v;
    let (xn, vn) = match kind {
        Step::Rk4 => {
            let mut out = StepDerivatives::new();
            rk4_step_derivatives(model, &mut d, &mut out, u, dt, Baumgarte::NONE).unwrap();
            (out.x, out.xdot)
        }
        Step::Euler => {
            semi_implicit_euler_step(model, &mut d, u, dt, Baumgarte::NONE).unwrap();
            (d.x, d.xdot)
        }
    };
    d.x = xn;
    project_position(model, &mut d).unwrap();
    d.xdot = vn;
    project_velocity(model, &mut d).unwrap();
    d.x.iter().chain(&d.xdot).copied().collect()
}

/// A state on the manifold near home: a random position projected onto `f = 0`, a random
/// velocity projected onto `G Ẋ = 0`.
fn on_manifold<K: Derivatives<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    rng: &mut XorShift,
) -> ([f64; N], [f64; N]) {
    let s = model.structure();
    let mut d = Data::new(model);
    d.x = core::array::from_fn(|j| s.home[j] + rng.range(-0.02, 0.02));
    project_position(model, &mut d).unwrap();
    d.xdot = core::array::from_fn(|_| rng.range(-0.5, 0.5));
    project_velocity(model, &mut d).unwrap();
    (d.x, d.xdot)
}

fn check<K: Derivatives<N, M> + Jacobian<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    kind: Step,
    states: usize,
) -> f64 {
    let na = model.structure().actuated.len();
    let dt = 1e-2;
    let mut rng = XorShift(0x0bad_cafe_1234_5677);
    let mut out = StepDerivatives::<N, M>::new();
    let mut raw_out = StepDerivatives::<N, M>::new();
    let (mut worst, mut moved, mut drift) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut at = String::new();
    for _ in 0..states {
        let (x, v) = on_manifold(model, &mut rng);
        let u: Vec<f64> = (0..na).map(|_| rng.range(-2.0, 2.0)).collect();
        raw(model, kind, &x, &v, &u, dt, &mut raw_out);
        raw(model, kind, &x, &v, &u, dt, &mut out);
        let mut d = Data::new(model);
        let rep = project_step_derivatives(model, &mut d, &mut out)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        // Steps long enough that the projection works: the exact Jacobians must not rely on a
        // small drift.
        assert!(
            rep.iterations >= 1,
            "{name} {kind:?}: no projection step: {rep:?}"
        );
        drift = drift.max(rep.position_residual);
        let next = projected(model, kind, &x, &v, &u, dt);
        let got: Vec<f64> = out.x.iter().chain(&out.xdot).copied().collect();
        assert_eq!(
            next, got,
            "{name} {kind:?}: the Jacobian's state and the step's differ"
        );
        // The projected position's columns lie in the tangent space at X*.
        let mut g = [[0.0; M]; N];
        model.kernels().jacobian(&out.x, &mut g);
        let gscale = g.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
        for c in 0..2 * N + na {
            let col = &out.jacobian[c * 2 * N..c * 2 * N + N];
            let cscale = col.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            for (i, _) in g[0].iter().enumerate() {
                let gd: f64 = g.iter().zip(col).map(|(gj, cj)| gj[i] * cj).sum();
                assert!(
                    gd.abs() <= 1e-12 * gscale * cscale.max(1.0),
                    "{name} {kind:?}: column {c} of D X* leaves the tangent space: {gd:e}"
                );
            }
        }
        for (a, b) in out.jacobian.iter().zip(&raw_out.jacobian) {
            moved = moved.max((a - b).abs() / (a.abs() + b.abs() + 1e-300));
        }
        let fmax = next.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let floor = 10.0 * f64::EPSILON * fmax / (1e-3 * TOL);
        let diff = |f: &dyn Fn(f64) -> Vec<f64>, z: f64| -> Vec<f64> {
            let h = 1e-3 * z.abs().max(1.0);
            let (p2, p1, m1, m2) = (f(2.0 * h), f(h), f(-h), f(-2.0 * h));
            (0..2 * N)
                .map(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
                .collect()
        };
        let mut cmp = |what: &str, c: usize, num: Vec<f64>| {
            for (i, &nb) in num.iter().enumerate() {
                let av = out.jacobian[c * 2 * N + i];
                let rel = (av - nb).abs() / (av.abs() + nb.abs() + floor);
                assert!(
                    rel <= TOL,
                    "{name} {kind:?} {what}[{i},{c}]: analytic {av:e}, numeric {nb:e}, rel {rel:e}"
                );
                if rel > worst {
                    worst = rel;
                    at = format!("{what}[{i},{c}] = {av:e} (numeric {nb:e})");
                }
            }
        };
        for j in 0..N {
            let num = diff(
                &|h| {
                    let mut xx = x;
                    xx[j] += h;
                    projected(model, kind, &xx, &v, &u, dt)
                },
                x[j],
            );
            cmp("F_x(X)", j, num);
            let num = diff(
                &|h| {
                    let mut vv = v;
                    vv[j] += h;
                    projected(model, kind, &x, &vv, &u, dt)
                },
                v[j],
            );
            cmp("F_x(Xdot)", N + j, num);
        }
        for a in 0..na {
            let num = diff(
                &|h| {
                    let mut uu = u.clone();
                    uu[a] += h;
                    projected(model, kind, &x, &v, &uu, dt)
                },
                u[a],
            );
            cmp("F_u", 2 * N + a, num);
        }
    }
    assert!(
        moved > 100.0 * TOL,
        "{name} {kind:?}: the projection hardly changed the Jacobians ({moved:e})"
    );
    println!(
        "{name} {kind:?} dt {dt:e}: projected step Jacobians vs differences, worst {worst:.2e} at {at} \
         (drift max |f(X+)| {drift:.1e}; raw vs projected Jacobians differ by up to {moved:.1e})"
    );
    worst
}

/// The projected RK4 step against the integrator's step with projection, from a state on the
/// manifold.
fn against_simulator<K: Derivatives<N, M> + Simulate<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
) {
    let na = model.structure().actuated.len();
    let dt = 1e-2;
    let (x0, v0) = on_manifold(model, &mut XorShift(0x5eed_0000_0000_0001));
    let u: Vec<f64> = (0..na).map(|a| 0.5 + 0.1 * a as f64).collect();
    let ((xs, vs), (x1, v1)) =
        common::simulator_rk4_step(model, &x0, &v0, &u, dt, Stabilization::Projection);
    let mut out = StepDerivatives::new();
    raw(model, Step::Rk4, &xs, &vs, &u, dt, &mut out);
    project_step_derivatives(model, &mut Data::new(model), &mut out).unwrap();
    let (mut err, mut size) = (0.0_f64, 0.0_f64);
    for (a, c) in x1.iter().chain(&v1).zip(out.x.iter().chain(&out.xdot)) {
        err = err.max((a - c).abs());
        size = size.max(a.abs());
    }
    assert!(
        err <= 1e-12 * size,
        "{name}: projected RK4 step vs the simulator's: {err:e} (size {size:e})"
    );
}

/// The projection converged to rounding (`tol_f` 1e-14, not 1e-12), so that where it stops does
/// not add noise of its tolerance over the differences' step (1e-12 / 1e-3) to the comparison.
fn tight() -> SolverOptions {
    SolverOptions {
        tol_f: 1e-14,
        ..SolverOptions::default()
    }
}

#[test]
fn stewart_6ups() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default()).with_options(tight());
    against_simulator("stewart_6ups", &model);
    check("stewart_6ups", &model, Step::Rk4, 1);
    check("stewart_6ups", &model, Step::Euler, 1);
}

#[test]
fn five_bar() {
    let model = Model::new(five_bar::FiveBar::default()).with_options(tight());
    against_simulator("five_bar", &model);
    check("five_bar", &model, Step::Rk4, 3);
    check("five_bar", &model, Step::Euler, 3);
}
