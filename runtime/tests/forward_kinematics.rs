//! Forward kinematics on the hand-written five-bar: velocity and acceleration against finite
//! differences in time of the position solution, the parallel singularity, invalid inputs.

mod common;

use std::f64::consts::{FRAC_PI_3, PI};

use common::central_4th;
use common::five_bar::{FiveBar, HOME, L1, M, N};
use rbss_runtime::{
    Data, Kernels, Model, SolverError, forward_acceleration, forward_kinematics, forward_velocity,
};

/// A smooth joint trajectory around home, and its first two derivatives.
fn joints(t: f64) -> ([f64; 2], [f64; 2], [f64; 2]) {
    let w = PI;
    let (a1, a2, w2, ph) = (0.25, 0.2, 1.3 * w, 0.5);
    let q = [
        HOME[0] + a1 * (w * t).sin(),
        HOME[2] + a2 * (w2 * t + ph).sin(),
    ];
    let qd = [a1 * w * (w * t).cos(), a2 * w2 * (w2 * t + ph).cos()];
    let qdd = [
        -a1 * w * w * (w * t).sin(),
        -a2 * w2 * w2 * (w2 * t + ph).sin(),
    ];
    (q, qd, qdd)
}

#[test]
fn forward_velocity_and_acceleration_match_finite_differences_in_time() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let mut fd = Data::new(&model);
    let h = 1e-3;
    let (mut warm_sum, mut warm_max, mut n) = (0, 0, 0);
    let (mut worst_v, mut worst_a, mut worst_cond) = (0.0_f64, 0.0_f64, 0.0_f64);
    for step in 0..=40 {
        let t = step as f64 * 0.05;
        let (q, qd, qdd) = joints(t);
        let rep = forward_kinematics(&model, &mut data, &q).unwrap();
        assert!(rep.residual <= 1e-12);
        if step > 0 {
            warm_sum += rep.iterations;
            warm_max = warm_max.max(rep.iterations);
            n += 1;
        }
        worst_cond = worst_cond.max(rep.cond);
        let rv = forward_velocity(&model, &mut data, &qd).unwrap();
        let ra = forward_acceleration(&model, &mut data, &qdd).unwrap();
        assert!(rv.residual < 1e-14 && ra.residual < 1e-12, "{rv:?} {ra:?}");
        assert_eq!((data.xdot[0], data.xdot[2]), (qd[0], qd[1]));
        assert_eq!((data.xddot[0], data.xddot[2]), (qdd[0], qdd[1]));

        // Fourth-order central differences of the FK solution in time.
        let mut xs = [[0.0; N]; 5];
        for (k, xk) in xs.iter_mut().enumerate() {
            fd.x = data.x;
            let (qk, _, _) = joints(t + (k as f64 - 2.0) * h);
            forward_kinematics(&model, &mut fd, &qk).unwrap();
            *xk = fd.x;
        }
        let (d1s, d2s) = central_4th(&xs, h);
        for (j, (&d1, &d2)) in d1s.iter().zip(&d2s).enumerate() {
            let ev = (data.xdot[j] - d1).abs() / (1.0 + d1.abs());
            let ea = (data.xddot[j] - d2).abs() / (1.0 + d2.abs());
            assert!(ev < 1e-8, "t={t} xdot[{j}]: {} vs FD {d1}", data.xdot[j]);
            assert!(ea < 1e-6, "t={t} xddot[{j}]: {} vs FD {d2}", data.xddot[j]);
            worst_v = worst_v.max(ev);
            worst_a = worst_a.max(ea);
        }
    }
    println!(
        "forward velocity/acceleration vs 4th-order FD (h = {h}): worst rel err {worst_v:e} / \
         {worst_a:e}; FK warm start along the path (dt = 0.05 s): mean {:.2} / max {warm_max} \
         iterations; worst cond(J_p) {worst_cond:.3e}",
        warm_sum as f64 / n as f64
    );
}

#[test]
fn cold_start_from_home_converges_in_the_home_mode() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let rep = forward_kinematics(&model, &mut data, &[HOME[0], HOME[2]]).unwrap();
    assert_eq!(rep.iterations, 0, "home is already assembled: {rep:?}");
    for (a, b) in data.x.iter().zip(HOME) {
        assert!((a - b).abs() < 1e-15);
    }
    let (q, _, _) = joints(0.4);
    data.set_home(&model);
    let rep = forward_kinematics(&model, &mut data, &q).unwrap();
    println!("FK cold from home to q(0.4): {rep:?}");
    assert!(rep.iterations <= 6 && rep.residual <= 1e-12);
}

/// th1 = 120°, th2 = 60°: the elbows are 2 L2 apart at the same height, so both distal links
/// lie on one line through the effector: a parallel (type-2) singularity, where J_p is
/// singular and the two assembly modes meet.
fn aligned() -> [f64; N] {
    let (th1, th2) = (2.0 * FRAC_PI_3, FRAC_PI_3);
    [th1, -th1, th2, PI - th2, 0.0, L1 * th2.sin()]
}

#[test]
fn aligned_distal_links_are_singular_with_the_condition_estimate() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let x = aligned();
    let mut f = [0.0; M];
    FiveBar.constraints(&x, &mut f);
    assert!(f.iter().all(|v| v.abs() < 1e-15), "{f:?}");
    let q = [x[0], x[2]];

    // Warm start exactly at the singular assembly.
    data.x = x;
    let e = forward_kinematics(&model, &mut data, &q).unwrap_err();
    println!("FK at the aligned assembly: {e}");
    assert!(matches!(e, SolverError::Singular { cond, what: "J_p", block: None } if cond > 1e12));
    assert_eq!(data.x, x, "untouched on error");

    // From home Newton creeps towards the double root until J_p is too ill-conditioned.
    data.set_home(&model);
    let e = forward_kinematics(&model, &mut data, &q).unwrap_err();
    println!("FK to the aligned assembly from home: {e}");
    match e {
        SolverError::Singular { cond, what, block } => {
            assert!(cond > model.options.cond_max && cond.is_finite());
            assert_eq!((what, block), ("J_p", None));
        }
        other => panic!("expected Singular, got {other:?}"),
    }
    assert_eq!(data.x, HOME);

    // The velocity problem at the singular assembly.
    data.x = x;
    let e = forward_velocity(&model, &mut data, &[0.1, -0.1]).unwrap_err();
    assert!(
        matches!(e, SolverError::Singular { cond, .. } if cond > 1e12),
        "{e}"
    );
    assert!(e.to_string().contains("J_p"), "{e}");
}

#[test]
fn non_finite_and_malformed_inputs_are_typed_errors() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    assert_eq!(
        forward_kinematics(&model, &mut data, &[f64::NAN, 1.0]),
        Err(SolverError::NonFinite { what: "q" })
    );
    assert_eq!(
        forward_kinematics(&model, &mut data, &[1.0, 2.0, 3.0]),
        Err(SolverError::Dimension {
            what: "q",
            expected: 2,
            found: 3
        })
    );
    assert_eq!(
        forward_velocity(&model, &mut data, &[0.0, f64::NEG_INFINITY]),
        Err(SolverError::NonFinite { what: "qdot" })
    );
    assert_eq!(
        forward_acceleration(&model, &mut data, &[f64::NAN, 0.0]),
        Err(SolverError::NonFinite { what: "qddot" })
    );
    data.x[4] = f64::INFINITY;
    assert_eq!(
        forward_kinematics(&model, &mut data, &[HOME[0], HOME[2]]),
        Err(SolverError::NonFinite {
            what: "data.x (warm start)"
        })
    );
    assert_eq!(
        forward_velocity(&model, &mut data, &[0.0, 0.0]),
        Err(SolverError::NonFinite { what: "data.x" })
    );
    // A kernel that produces NaN for finite but absurd input is caught too.
    data.x = HOME;
    data.xdot = [1e200; N];
    let e = forward_acceleration(&model, &mut data, &[0.0, 0.0]).unwrap_err();
    assert!(matches!(e, SolverError::NonFinite { .. }), "{e}");
}
