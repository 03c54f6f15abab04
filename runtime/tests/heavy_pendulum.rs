//! Forward dynamics and simulation do not depend on the units of mass (issue 37: a 1e9 kg
//! pendulum was refused mid-run as "singular"). On the spring pendulum (tests/spring_pendulum.rs
//! checks its kernels against the closed-form Lagrangian):
//!
//! - every inertial and force parameter scaled by `s` (masses, armatures, springs, dampers, and
//!   the control force) gives the same motion: the same accelerations, multipliers scaled by
//!   `s` (to the forces' rounding), for `s` from 1e-9 to 1e12, at random states including the straight arm (`th2 = 0`,
//!   where the inverse kinematics of the tip is singular), and the same simulated trajectory;
//! - the audit's case, the masses alone at 1e9 kg (the springs, dampers and armatures as they
//!   are, now negligible): 10 s of swinging from the straight arm and from a bent one, through
//!   `th2 = 0`, conserve the energy to the integrator's tolerance, without an error.

use rbss_runtime::{
    Baumgarte, Data, IntegrateOptions, Kernels, Method, Model, Simulator, Stabilization,
    forward_dynamics,
};
use spring_pendulum::{N, Params, SpringPendulum};

/// The consistent state of the joint angles `q` and rates `v` (the tip from the angles).
fn state(p: &Params, q: [f64; 2], v: [f64; 2]) -> ([f64; N], [f64; N]) {
    let (s1, c1) = q[0].sin_cos();
    let (s12, c12) = (q[0] + q[1]).sin_cos();
    let w12 = v[0] + v[1];
    (
        [q[0], q[1], -p.l1 * s1 - p.l2 * s12, -p.l1 * c1 - p.l2 * c12],
        [
            v[0],
            v[1],
            -p.l1 * c1 * v[0] - p.l2 * c12 * w12,
            p.l1 * s1 * v[0] + p.l2 * s12 * w12,
        ],
    )
}

/// The parameters with every inertial and force parameter times `s`.
fn scaled(s: f64) -> Params {
    let p = Params::default();
    Params {
        m1: p.m1 * s,
        m2: p.m2 * s,
        k1: p.k1 * s,
        k2: p.k2 * s,
        c1: p.c1 * s,
        c2: p.c2 * s,
        J1: p.J1 * s,
        J2: p.J2 * s,
        ..p
    }
}

fn energy(model: &Model<SpringPendulum, 4, 2>, x: &[f64; N], v: &[f64; N]) -> f64 {
    let mut e = [0.0; 2];
    rbss_runtime::Dynamics::energy(model.kernels(), x, v, &mut e);
    e[0] + e[1]
}

#[test]
fn scaling_the_masses_and_forces_scales_nothing_but_the_multipliers() {
    let base = Model::new(SpringPendulum::new(&Params::default()));
    let mut bd = Data::new(&base);
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut states: Vec<([f64; 2], [f64; 2])> = (0..20)
        .map(|_| ([1.5 * rnd(), 1.5 * rnd()], [2.0 * rnd(), 2.0 * rnd()]))
        .collect();
    // The straight arm: the tip's inverse kinematics is singular, forward dynamics is not.
    states.push(([0.7, 0.0], [1.0, -2.0]));
    states.push(([-1.2, 0.0], [0.0, 0.0]));
    let p0 = Params::default();
    for s in [1e-9, 1e-3, 1e3, 1e9, 1e12] {
        let model = Model::new(SpringPendulum::new(&scaled(s)));
        let mut data = Data::new(&model);
        for &(q, v) in &states {
            let (x, xdot) = state(&p0, q, v);
            let u = 0.7;
            bd.x = x;
            bd.xdot = xdot;
            forward_dynamics(&base, &mut bd, &[u], None, Baumgarte::NONE).unwrap();
            data.x = x;
            data.xdot = xdot;
            forward_dynamics(&model, &mut data, &[u * s], None, Baumgarte::NONE)
                .unwrap_or_else(|e| panic!("s = {s:e}, q = {q:?}, v = {v:?}: {e}"));
            let scale = bd.xddot.iter().fold(1.0_f64, |m, a| m.max(a.abs()));
            for i in 0..N {
                assert!(
                    (data.xddot[i] - bd.xddot[i]).abs() <= 1e-10 * scale,
                    "s = {s:e}, q = {q:?}: Xddot[{i}] {} vs {}",
                    data.xddot[i],
                    bd.xddot[i]
                );
            }
            // The multipliers against the forces' scale (the massless tip's are rounding, near
            // 0, at every scale).
            let lscale = bd.psi.iter().fold(u.abs(), |m, a| m.max(a.abs()));
            for i in 0..2 {
                assert!(
                    (data.lambda[i] / s - bd.lambda[i]).abs() <= 1e-9 * lscale,
                    "s = {s:e}, q = {q:?}: lambda[{i}] / s {} vs {}",
                    data.lambda[i] / s,
                    bd.lambda[i]
                );
            }
        }
    }
    // The simulated trajectory at 1e9 is the unscaled one.
    let (x0, v0) = state(&p0, [1.0, -0.6], [0.0, 1.5]);
    let run = |params: &Params| {
        let model = Model::new(SpringPendulum::new(params));
        let mut data = Data::new(&model);
        let options =
            IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::Projection);
        let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &v0, options).unwrap();
        let mut none = |_: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
            u.fill(0.0);
            Ok(())
        };
        sim.run(&model, &mut data, 3.0, &mut none, |_| {}).unwrap();
        (*sim.x(), *sim.xdot())
    };
    let (xa, va) = run(&p0);
    let (xb, vb) = run(&scaled(1e9));
    for i in 0..N {
        assert!(
            (xa[i] - xb[i]).abs() < 1e-7,
            "x[{i}] {} vs {}",
            xa[i],
            xb[i]
        );
        assert!(
            (va[i] - vb[i]).abs() < 1e-6,
            "xdot[{i}] {} vs {}",
            va[i],
            vb[i]
        );
    }
}

#[test]
fn a_1e9_kg_pendulum_swings_through_the_straight_arm() {
    let p = Params {
        m1: 1.2e9,
        m2: 0.8e9,
        ..Params::default()
    };
    let model = Model::new(SpringPendulum::new(&p));
    for (q, v) in [([1.2, 0.0], [0.0, 0.0]), ([0.3, 0.5], [5.0, -8.0])] {
        let (x0, v0) = state(&p, q, v);
        let mut data = Data::new(&model);
        let options =
            IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::Projection);
        let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &v0, options).unwrap();
        let e0 = energy(&model, sim.x(), sim.xdot());
        let mut none = |_: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
            u.fill(0.0);
            Ok(())
        };
        let (mut crossings, mut last, mut worst) = (0, q[1], 0.0_f64);
        sim.run(&model, &mut data, 10.0, &mut none, |s| {
            let th2 = s.x()[1];
            if th2 * last < 0.0 || (th2 == 0.0) != (last == 0.0) {
                crossings += 1;
            }
            last = th2;
            worst = worst.max((energy(&model, s.x(), s.xdot()) - e0).abs());
            let mut f = [0.0; 2];
            Kernels::constraints(model.kernels(), s.x(), &mut f);
            assert!(f.iter().all(|v| v.abs() < 1e-9), "{f:?}");
        })
        .unwrap_or_else(|e| panic!("from q = {q:?}: {e}"));
        assert!(crossings >= 4, "th2 crossed 0 only {crossings} times");
        // The dampers (0.05 and 0.03 N m s/rad) take some J out of some 1e9 J; the integrator's
        // error is relative.
        assert!(
            worst < 1e-8 * e0.abs(),
            "energy drift {worst:e} J of {e0:e} J from q = {q:?}"
        );
    }
}
