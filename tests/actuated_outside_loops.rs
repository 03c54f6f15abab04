//! An actuated coordinate outside every loop (issue 34): tests/data/leg_hip.toml, a leg whose
//! hip pitch `h` (geared 10:1) carries a four-bar knee driven by its crank `c`. The hip is in no
//! loop, so it is both actuated and an output (`actuated = ["h", "c"]`, `outputs = ["h", "r"]`).
//! Through the model's library (`rbss library --model-file`, the C ABI):
//!
//! - inverse kinematics takes the hip as given, forward kinematics gives the same assembly;
//! - inverse dynamics against the power balance `Σ gear_a U_a q̇_a = d(T + Pi)/dt` along three
//!   motions from the outputs: the hip alone (the knee rigid: this checks the hip's torque), the
//!   knee alone (the crank's), and both; `d(T + Pi)/dt` by a 5-point difference of the energy
//!   along the motion (nothing of the equations of motion);
//! - forward dynamics under inverse dynamics' `U` gives back the accelerations and multipliers.

mod common;

use std::path::Path;

use common::robot_lib::{RobotLib, library};

/// The gear ratios of `h` and `c` (tests/data/leg_hip.toml).
const GEAR: [f64; 2] = [10.0, 1.0];

/// A motion of the outputs `(h, r)`: position, rate, acceleration at `t`.
type Motion = fn(f64) -> [[f64; 2]; 3];

fn hip_alone(t: f64) -> [[f64; 2]; 3] {
    let (s, c) = (2.0 * t).sin_cos();
    [[0.2 + 0.3 * s, 1.55], [0.6 * c, 0.0], [-1.2 * s, 0.0]]
}

fn knee_alone(t: f64) -> [[f64; 2]; 3] {
    let (s, c) = (3.0 * t).sin_cos();
    [[0.2, 1.62 + 0.07 * s], [0.0, 0.21 * c], [0.0, -0.63 * s]]
}

fn both(t: f64) -> [[f64; 2]; 3] {
    let [[h, _], [hd, _], [hdd, _]] = hip_alone(t);
    let (s, c) = (3.0 * t + 0.5).sin_cos();
    [[h, 1.62 + 0.07 * s], [hd, 0.21 * c], [hdd, -0.63 * s]]
}

/// The state on the motion at `t`: IK (warm-started from `start`), then the rates.
fn state(robot: &RobotLib, motion: Motion, t: f64, start: &[f64]) -> [Vec<f64>; 3] {
    let [y, yd, ydd] = motion(t);
    let x = robot.ik(&y, Some(start)).unwrap();
    let xd = robot.inverse_velocity(&x, &yd).unwrap();
    let xdd = robot.inverse_acceleration(&x, &xd, &ydd).unwrap();
    [x, xd, xdd]
}

fn energy(robot: &RobotLib, motion: Motion, t: f64, start: &[f64]) -> f64 {
    let [x, xd, _] = state(robot, motion, t, start);
    let [t_kin, pi] = robot.energy(&x, &xd).unwrap();
    t_kin + pi
}

#[test]
fn an_actuated_hip_outside_the_knee_loop() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-leg-hip-")
        .tempdir()
        .unwrap();
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/leg_hip.toml");
    let robot = RobotLib::open(&library(&model, &tmp.path().join("cache")));
    assert_eq!((robot.n, robot.m, robot.k, robot.p), (4, 2, 2, 2));
    let (h, c) = (robot.actuated(0), robot.actuated(1));
    assert_eq!((h, c), (0, 1));
    assert_eq!((robot.output(0), robot.output(1)), (0, 3));

    let mut worst_power: f64 = 0.0;
    let (mut worst_xdd, mut worst_lambda): (f64, f64) = (0.0, 0.0);
    let mut start = robot.ik(&[0.2, 1.55], None).unwrap();
    for (name, motion) in [
        ("hip alone", hip_alone as Motion),
        ("knee alone", knee_alone as Motion),
        ("both", both as Motion),
    ] {
        for &t in &[0.1, 0.45, 0.8, 1.3] {
            let [x, xd, xdd] = state(&robot, motion, t, &start);
            // The hip is taken as given.
            assert_eq!(x[h], motion(t)[0][0], "{name}, t = {t}: IK moved the hip");
            // Forward kinematics from the actuated coordinates: the same assembly.
            let x_fk = robot.fk(&[x[h], x[c]], Some(&start)).unwrap();
            for (j, (a, b)) in x_fk.iter().zip(&x).enumerate() {
                assert!(
                    (a - b).abs() < 1e-12,
                    "{name}, t = {t}: fk X[{j}] {a} vs ik {b}"
                );
            }
            match name {
                "hip alone" => assert!(xd[c].abs() < 1e-12, "the knee is rigid: {}", xd[c]),
                "knee alone" => assert_eq!(xd[h], 0.0),
                _ => {}
            }

            let (u, lambda) = robot.inverse_dynamics(&x, &xd, &xdd).unwrap();
            // The power of the actuators against the energy's rate along the motion.
            let power = GEAR[0] * u[0] * xd[h] + GEAR[1] * u[1] * xd[c];
            let e = |dt: f64| energy(&robot, motion, t + dt, &x);
            let step = 1e-3;
            let rate =
                (e(-2.0 * step) - 8.0 * e(-step) + 8.0 * e(step) - e(2.0 * step)) / (12.0 * step);
            let err = (power - rate).abs() / (1.0 + rate.abs());
            eprintln!(
                "{name}, t = {t}: U = [{:.6}, {:.6}], power {power:.9} W, d(T + Pi)/dt {rate:.9} W, relative {err:.1e}",
                u[0], u[1]
            );
            assert!(err < 1e-8, "{name}, t = {t}: power {power} vs {rate}");
            worst_power = worst_power.max(err);

            // Forward dynamics under U: the motion's accelerations and the same multipliers.
            let (xdd_fd, lambda_fd) = robot.forward_dynamics(&x, &xd, &u).unwrap();
            for (a, b) in xdd_fd.iter().zip(&xdd) {
                worst_xdd = worst_xdd.max((a - b).abs() / (1.0 + b.abs()));
            }
            for (a, b) in lambda_fd.iter().zip(&lambda) {
                worst_lambda = worst_lambda.max((a - b).abs() / (1.0 + b.abs()));
            }
            start = x;
        }
    }
    eprintln!(
        "power balance worst {worst_power:.1e}; fd after id: Xddot {worst_xdd:.1e}, lambda {worst_lambda:.1e}"
    );
    assert!(worst_xdd < 1e-12, "fd(id(U)) Xddot off by {worst_xdd:e}");
    assert!(
        worst_lambda < 1e-12,
        "fd(id(U)) lambda off by {worst_lambda:e}"
    );
}
