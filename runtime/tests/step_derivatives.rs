//! The Jacobians `F_x`, `F_u` of one RK4 step and one semi-implicit Euler step against
//! fourth-order central differences of the steps themselves (`rk4_step_derivatives`' own new
//! state; `semi_implicit_euler_step`), on the 6-UPS and the five-bar, unstabilised and with
//! Baumgarte's gains, at states off the manifold (the step is a function of the full state).
//! The RK4 step's new state is also checked against the integrator's (`Simulator` with
//! `Method::Rk4`, one step, the same gains) from a state on the manifold, where the simulator's
//! initial projection leaves it unchanged: relative difference <= 1e-12.
//!
//! Error of an entry: `|a - b| / (|a| + |b| + floor)`, asserted `<= 1e-6`, with the floor
//! `10 eps F / (h TOL)` (`F` the largest entry of the state and `dt |Ẍ|`, `h = 1e-3`).

mod common;

use common::XorShift;
use rbss_runtime::integrate::Stabilization;
use rbss_runtime::tasks::{Derivatives, Simulate};
use rbss_runtime::{
    Baumgarte, Data, Model, StepDerivatives, rk4_step_derivatives, semi_implicit_euler_step,
    semi_implicit_euler_step_derivatives,
};

const TOL: f64 = 1e-6;

#[derive(Clone, Copy, Debug)]
enum Step {
    Rk4,
    Euler,
}

/// The new state `(X', Ẋ')` of one step from `(x, v)` with `u`.
fn step<K: Derivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    kind: Step,
    x: &[f64; N],
    v: &[f64; N],
    u: &[f64],
    dt: f64,
    b: Baumgarte,
) -> Vec<f64> {
    let mut d = Data::new(model);
    d.x = *x;
    d.xdot = *v;
    match kind {
        Step::Rk4 => {
            let mut out = StepDerivatives::new();
            rk4_step_derivatives(model, &mut d, &mut out, u, dt, b).unwrap();
            out.x.iter().chain(&out.xdot).copied().collect()
        }
        Step::Euler => {
            semi_implicit_euler_step(model, &mut d, u, dt, b).unwrap();
            d.x.iter().chain(&d.xdot).copied().collect()
        }
    }
}

fn check<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    kind: Step,
    b: Baumgarte,
    states: usize,
) -> f64 {
    let s = model.structure();
    let na = s.actuated.len();
    let dt = 1e-2;
    let mut rng = XorShift(0x1234_5678_9abc_def1);
    let mut out = StepDerivatives::<N, M>::new();
    let (mut worst, mut differing) = (0.0_f64, 0usize);
    for _ in 0..states {
        let x: [f64; N] = core::array::from_fn(|j| s.home[j] + rng.range(-0.02, 0.02));
        let v: [f64; N] = core::array::from_fn(|_| rng.range(-0.5, 0.5));
        let u: Vec<f64> = (0..na).map(|_| rng.range(-2.0, 2.0)).collect();
        let mut d = Data::new(model);
        d.x = x;
        d.xdot = v;
        match kind {
            Step::Rk4 => rk4_step_derivatives(model, &mut d, &mut out, &u, dt, b),
            Step::Euler => semi_implicit_euler_step_derivatives(model, &mut d, &mut out, &u, dt, b),
        }
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(out.na, na);
        let next = step(model, kind, &x, &v, &u, dt, b);
        let got: Vec<f64> = out.x.iter().chain(&out.xdot).copied().collect();
        assert_eq!(
            next, got,
            "{name} {kind:?}: the Jacobian's step and the step differ"
        );
        let fmax = next.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let floor = 10.0 * f64::EPSILON * fmax / (1e-3 * TOL);
        let diff = |f: &dyn Fn(f64) -> Vec<f64>, z: f64| -> Vec<f64> {
            let h = 1e-3 * z.abs().max(1.0);
            let (p2, p1, m1, m2) = (f(2.0 * h), f(h), f(-h), f(-2.0 * h));
            (0..2 * N)
                .map(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
                .collect()
        };
        let mut cmp = |what: &str, c: usize, a: &dyn Fn(usize) -> f64, num: Vec<f64>| {
            for (i, &nb) in num.iter().enumerate() {
                let av = a(i);
                let rel = (av - nb).abs() / (av.abs() + nb.abs() + floor);
                assert!(
                    rel <= TOL,
                    "{name} {kind:?} {b:?} {what}[{i},{c}]: analytic {av:e}, numeric {nb:e}, rel {rel:e}"
                );
                worst = worst.max(rel);
                if av != nb {
                    differing += 1;
                }
            }
        };
        for j in 0..N {
            let num = diff(
                &|h| {
                    let mut xx = x;
                    xx[j] += h;
                    step(model, kind, &xx, &v, &u, dt, b)
                },
                x[j],
            );
            cmp("F_x(X)", j, &|i| out.fx(i, j), num);
            let num = diff(
                &|h| {
                    let mut vv = v;
                    vv[j] += h;
                    step(model, kind, &x, &vv, &u, dt, b)
                },
                v[j],
            );
            cmp("F_x(Xdot)", j, &|i| out.fx(i, N + j), num);
        }
        for a in 0..na {
            let num = diff(
                &|h| {
                    let mut uu = u.clone();
                    uu[a] += h;
                    step(model, kind, &x, &v, &uu, dt, b)
                },
                u[a],
            );
            cmp("F_u", a, &|i| out.fu(i, a), num);
        }
    }
    assert!(differing > 0, "{name}: analytic equals numeric bit for bit");
    println!("{name} {kind:?} {b:?}: step Jacobians vs differences, worst {worst:.2e}");
    worst
}

/// `rk4_step_derivatives`' new state against the integrator's RK4 step from the same state
/// on the manifold (home, a velocity projected onto `G Ẋ = 0` by the simulator itself).
fn against_simulator<K: Derivatives<N, M> + Simulate<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    b: Baumgarte,
) {
    let s = model.structure();
    let na = s.actuated.len();
    let dt = 1e-2;
    let x0: [f64; N] = core::array::from_fn(|j| s.home[j]);
    let v0: [f64; N] = core::array::from_fn(|j| 0.05 * ((j % 5) as f64 - 2.0));
    let u: Vec<f64> = (0..na).map(|a| 0.5 + 0.1 * a as f64).collect();
    let stab = if b == Baumgarte::NONE {
        Stabilization::None
    } else {
        Stabilization::Baumgarte(b)
    };
    let ((xs, vs), (x1, v1)) = common::simulator_rk4_step(model, &x0, &v0, &u, dt, stab);
    let mut d = Data::new(model);
    d.x = xs;
    d.xdot = vs;
    let mut out = StepDerivatives::new();
    rk4_step_derivatives(model, &mut d, &mut out, &u, dt, b).unwrap();
    let (mut err, mut size) = (0.0_f64, 0.0_f64);
    for (a, c) in x1.iter().chain(&v1).zip(out.x.iter().chain(&out.xdot)) {
        err = err.max((a - c).abs());
        size = size.max(a.abs());
    }
    assert!(
        err <= 1e-12 * size,
        "{name} {b:?}: RK4 step vs the simulator's: {err:e} (size {size:e})"
    );
}

#[test]
fn stewart_6ups() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    for b in [Baumgarte::NONE, Baumgarte::DEFAULT] {
        against_simulator("stewart_6ups", &model, b);
        check("stewart_6ups", &model, Step::Rk4, b, 1);
        check("stewart_6ups", &model, Step::Euler, b, 1);
    }
}

#[test]
fn five_bar() {
    let model = Model::new(five_bar::FiveBar::default());
    for b in [Baumgarte::NONE, Baumgarte::DEFAULT] {
        against_simulator("five_bar", &model, b);
        check("five_bar", &model, Step::Rk4, b, 3);
        check("five_bar", &model, Step::Euler, b, 3);
    }
}
