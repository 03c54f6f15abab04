//! The combined calls `inverse_kinematics_full` and `inverse_dynamics_full` against the
//! separate calls they replace (`inverse_kinematics`, `inverse_velocity`,
//! `inverse_acceleration`, `inverse_dynamics`): the same results up to rounding, the same
//! reports, and the same errors, on the generated 6-UPS and five-bar.

mod common;

use std::f64::consts::PI;

use common::XorShift;
use five_bar::FiveBar;
use rbss_runtime::{
    Data, Dynamics, DynamicsMethod, Model, SolverError, inverse_acceleration, inverse_dynamics,
    inverse_dynamics_full, inverse_kinematics, inverse_kinematics_full, inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(1e-300_f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Along a smooth output trajectory (`motion(t)` = pose, rate, acceleration), sampled every
/// `dt` from a warm start: the combined calls against the separate ones. Returns the worst
/// relative differences of (X, Ẋ, Ẍ, U, lambda).
fn compare<K: Dynamics<N, M>, const N: usize, const M: usize, const O: usize>(
    model: &Model<K, N, M>,
    motion: impl Fn(f64) -> [[f64; O]; 3],
    samples: usize,
    dt: f64,
    q_forces: Option<&[f64; N]>,
) -> [f64; 5] {
    let mut sep = Data::new(model);
    let mut kin = Data::new(model);
    let mut full = Data::new(model);
    let mut worst = [0.0_f64; 5];
    for i in 0..samples {
        let [p, v, a] = motion(i as f64 * dt);
        let rp = inverse_kinematics(model, &mut sep, &p).unwrap();
        let rv = inverse_velocity(model, &mut sep, &v).unwrap();
        let ra = inverse_acceleration(model, &mut sep, &a).unwrap();
        let rd = inverse_dynamics(model, &mut sep, q_forces).unwrap();

        let rk = inverse_kinematics_full(model, &mut kin, &p, &v, &a).unwrap();
        let (rk2, rd2) = inverse_dynamics_full(model, &mut full, &p, &v, &a, q_forces).unwrap();
        for r in [rk, rk2] {
            assert_eq!(r.position, rp, "Newton is the same code");
            assert_eq!(r.velocity.iterations, rv.iterations);
            assert_eq!(r.velocity.evaluations, rv.evaluations);
            assert!(
                r.velocity.residual < 1e-13 && r.acceleration.residual < 1e-11,
                "{r:?}"
            );
            assert!((r.velocity.cond - rv.cond).abs() <= 1e-12 * rv.cond);
            assert!((r.acceleration.cond - ra.cond).abs() <= 1e-12 * ra.cond);
        }
        assert_eq!(rd2.method, DynamicsMethod::BlockElimination);
        assert_eq!(rd.method, DynamicsMethod::BlockElimination);
        assert!(
            (rd2.cond - rd.cond).abs() <= 1e-9 * rd.cond,
            "{rd2:?} {rd:?}"
        );
        assert!((rd2.cond_blocks - rd.cond_blocks).abs() <= 1e-12 * rd.cond_blocks);
        assert!(rd2.residual <= 1e-12 * max_abs(full.u()).max(max_abs(&full.lambda)));

        assert_eq!(kin.x, sep.x);
        assert_eq!(full.x, sep.x);
        for d in [&kin, &full] {
            worst[0] = worst[0].max(max_rel(&d.x, &sep.x));
            worst[1] = worst[1].max(max_rel(&d.xdot, &sep.xdot));
            worst[2] = worst[2].max(max_rel(&d.xddot, &sep.xddot));
        }
        worst[3] = worst[3].max(max_rel(full.u(), sep.u()));
        worst[4] = worst[4].max(max_rel(&full.lambda, &sep.lambda));
        assert!(full.u[N - M..].iter().all(|&v| v == 0.0));
    }
    worst
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn traek_p(t: f64) -> [[f64; 6]; 3] {
    let w = PI;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let (s3, c3) = (3.0 * w * t).sin_cos();
    let w2 = w * w;
    [
        [
            0.1 * c1,
            0.1 * s1,
            0.94 * (1.0 + 0.01 * s3),
            0.1 * c2,
            0.1 * s2,
            0.1 * c2 * s2,
        ],
        [
            -0.1 * w * s1,
            0.1 * w * c1,
            0.94 * 0.03 * w * c3,
            -0.2 * w * s2,
            0.2 * w * c2,
            0.2 * w * (c2 * c2 - s2 * s2),
        ],
        [
            -0.1 * w2 * c1,
            -0.1 * w2 * s1,
            -0.94 * 0.09 * w2 * s3,
            -0.4 * w2 * c2,
            -0.4 * w2 * s2,
            -1.6 * w2 * c2 * s2,
        ],
    ]
}

fn figure_eight(t: f64) -> [[f64; 2]; 3] {
    let w = PI;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    [
        [0.05 * s1, 0.3 + 0.03 * s2],
        [0.05 * w * c1, 0.06 * w * c2],
        [-0.05 * w * w * s1, -0.12 * w * w * s2],
    ]
}

#[test]
fn combined_calls_match_the_separate_ones_stewart() {
    let model = Model::new(Stewart6Ups::default());
    let mut rng = XorShift(0xC0_4B1D);
    let q: [f64; 24] = core::array::from_fn(|_| rng.range(-50.0, 50.0));
    for (q_forces, dt) in [(None, 1e-3), (Some(&q), 0.05)] {
        let w = compare(&model, traek_p, 200, dt, q_forces);
        println!("6-UPS, dt {dt}: worst relative differences X, Ẋ, Ẍ, U, lambda: {w:?}");
        assert!(w[0] == 0.0 && w[1] < 1e-13 && w[2] < 1e-12, "{w:?}");
        assert!(w[3] < 1e-11 && w[4] < 1e-11, "{w:?}");
    }
}

#[test]
fn combined_calls_match_the_separate_ones_five_bar() {
    let model = Model::new(FiveBar::default());
    let q = [0.3, -0.2, 0.1, 0.5, -1.0, 2.0];
    for (q_forces, dt) in [(None, 1e-3), (Some(&q), 0.05)] {
        let w = compare(&model, figure_eight, 200, dt, q_forces);
        println!("five-bar, dt {dt}: worst relative differences X, Ẋ, Ẍ, U, lambda: {w:?}");
        assert!(w[0] == 0.0 && w[1] < 1e-13 && w[2] < 1e-12, "{w:?}");
        assert!(w[3] < 1e-11 && w[4] < 1e-11, "{w:?}");
    }
}

#[test]
fn combined_calls_check_inputs_first_and_stop_at_the_first_error() {
    let model = Model::new(Stewart6Ups::default());
    let [p, v, a] = traek_p(0.3);
    let mut d = Data::new(&model);
    inverse_dynamics_full(&model, &mut d, &p, &v, &a, None).unwrap();
    let before = d.clone();
    let nan = [f64::NAN; 6];
    // Every input is checked before anything is written.
    let [p2, v2, a2] = traek_p(0.4);
    for (pp, vv, aa, what) in [
        (&nan, &v2, &a2, "outputs"),
        (&p2, &nan, &a2, "outputs_dot"),
        (&p2, &v2, &nan, "outputs_ddot"),
    ] {
        let mut e = before.clone();
        assert_eq!(
            inverse_kinematics_full(&model, &mut e, pp, vv, aa),
            Err(SolverError::NonFinite { what })
        );
        assert_eq!(
            inverse_dynamics_full(&model, &mut e, pp, vv, aa, None),
            Err(SolverError::NonFinite { what })
        );
        assert_eq!(
            (e.x, e.xdot, e.xddot, e.u),
            (before.x, before.xdot, before.xddot, before.u)
        );
    }
    let mut e = before.clone();
    let mut q = [0.0; 24];
    q[3] = f64::INFINITY;
    assert_eq!(
        inverse_dynamics_full(&model, &mut e, &p2, &v2, &a2, Some(&q)),
        Err(SolverError::NonFinite { what: "q_forces" })
    );
    assert_eq!(e.x, before.x);
    assert_eq!(
        inverse_kinematics_full(&model, &mut e, &p2[..5], &v2, &a2),
        Err(SolverError::Dimension {
            what: "outputs",
            expected: 6,
            found: 5
        })
    );

    // The five-bar: an unreachable pose fails in Newton and writes nothing; a stretched left
    // arm fails in the velocity solve (a singular block) with the position committed.
    let model = Model::new(FiveBar::default());
    let mut d = Data::new(&model);
    let [p, v, a] = figure_eight(0.1);
    inverse_dynamics_full(&model, &mut d, &p, &v, &a, None).unwrap();
    let before = d.clone();
    let mut e = before.clone();
    assert!(matches!(
        inverse_dynamics_full(&model, &mut e, &[0.0, 0.6], &v, &a, None),
        Err(SolverError::Unreachable { .. })
    ));
    assert_eq!(
        (e.x, e.xdot, e.xddot, e.u),
        (before.x, before.xdot, before.xddot, before.u)
    );
    let (b, l1, l2) = (0.15, 0.2, 0.25);
    let th = PI / 3.0;
    let stretched = [-b + (l1 + l2) * th.cos(), (l1 + l2) * th.sin()];
    let mut x = before.x;
    x[0] = th;
    x[1] = 0.0;
    e.x = x;
    match inverse_dynamics_full(&model, &mut e, &stretched, &v, &a, None) {
        // Newton stops at once or creeps towards the double root: either way singular.
        Err(SolverError::Singular { block: Some(0), .. }) => {}
        other => panic!("{other:?}"),
    }
}
