//! Inverse kinematics on the hand-written five-bar: IK -> FK round trip, inverse velocity and
//! acceleration against finite differences of the IK solution, singular and invalid inputs.

mod common;

use common::XorShift;
use common::central_4th;
use common::five_bar::{B, FiveBar, HOME, L1, L2, M, N, reachable};
use rbss_runtime::{
    Data, Kernels, Model, SolverError, SolverOptions, forward_acceleration, forward_kinematics,
    forward_velocity, inverse_acceleration, inverse_kinematics, inverse_velocity,
};

/// Both elbows out, as at home: the left elbow angle negative, the right one positive.
fn elbow_out(x: &[f64; N]) -> bool {
    x[1].sin() < 0.0 && x[3].sin() > 0.0
}

/// The forward-kinematics assembly mode: the sign of the cross product of the distal links'
/// directions (zero at a parallel singularity, where the two modes meet).
fn working_mode(x: &[f64; N]) -> bool {
    ((x[2] + x[3]) - (x[0] + x[1])).sin() > 0.0
}

fn max_f(x: &[f64; N]) -> f64 {
    let mut f = [0.0; M];
    FiveBar.constraints(x, &mut f);
    f.iter().fold(0.0, |m, v| m.max(v.abs()))
}

#[test]
fn ik_then_fk_round_trip_at_random_reachable_poses() {
    let model = Model::new(FiveBar);
    let mut ik = Data::new(&model);
    let mut fk = Data::new(&model);
    let mut rng = XorShift(0x1234_5678_9ABC_DEF1);
    let (mut poses, mut worst_err, mut worst_res) = (0, 0.0_f64, 0.0_f64);
    let (mut cold_sum, mut cold_max, mut fk_sum, mut fk_max) = (0, 0, 0, 0);
    let (mut worst_cond, mut switched, mut other_mode, mut backtracks) = (0.0_f64, 0, 0, 0);
    while poses < 500 {
        let (px, py) = (rng.range(-0.2, 0.2), rng.range(0.12, 0.42));
        if !reachable(px, py, 0.02) {
            continue;
        }
        poses += 1;

        // Cold start from home.
        ik.set_home(&model);
        let rep = inverse_kinematics(&model, &mut ik, &[px, py])
            .unwrap_or_else(|e| panic!("IK at ({px}, {py}): {e}"));
        // Far from home, Newton may land in another assembly mode; near home it must not.
        if !elbow_out(&ik.x) {
            assert!(
                px.hypot(py - 0.3) > 0.1,
                "IK left the home mode at ({px}, {py}): {:?}",
                ik.x
            );
            switched += 1;
        }
        assert!(rep.residual <= 1e-12 && max_f(&ik.x) <= 1e-12);
        assert_eq!((ik.x[4], ik.x[5]), (px, py));
        backtracks += rep.evaluations - rep.iterations - 1;
        cold_sum += rep.iterations;
        cold_max = cold_max.max(rep.iterations);
        worst_cond = worst_cond.max(rep.cond);

        // FK from a perturbed warm start must come back to the same passive coordinates.
        fk.x = ik.x;
        for j in [1, 3] {
            fk.x[j] += rng.range(-0.05, 0.05);
        }
        for j in [4, 5] {
            fk.x[j] += rng.range(-0.01, 0.01);
        }
        let q = [ik.x[0], ik.x[2]];
        let rep = forward_kinematics(&model, &mut fk, &q)
            .unwrap_or_else(|e| panic!("FK at ({px}, {py}): {e}"));
        backtracks += rep.evaluations - rep.iterations - 1;
        fk_sum += rep.iterations;
        fk_max = fk_max.max(rep.iterations);
        worst_res = worst_res.max(rep.residual);
        assert!(rep.residual <= 1e-12 && max_f(&fk.x) <= 1e-12);
        if working_mode(&fk.x) != working_mode(&ik.x) {
            // The other forward-kinematics solution (the effector mirrored across the line
            // through the elbows): reachable from the perturbed start only when it is close,
            // that is near a parallel singularity.
            let gap = (fk.x[4] - px).hypot(fk.x[5] - py);
            assert!(
                gap < 0.1,
                "far mode switch at ({px}, {py}): gap {gap}, {rep:?}"
            );
            other_mode += 1;
            continue;
        }
        let err = (0..N).fold(0.0_f64, |m, j| m.max((fk.x[j] - ik.x[j]).abs()));
        worst_err = worst_err.max(err);
    }
    println!(
        "round trip over {poses} poses: max |x_fk - x_ik| = {worst_err:e}, max FK residual \
         {worst_res:e}; IK cold from home: mean {:.2} / max {cold_max} iterations, worst block \
         cond {worst_cond:.3e}, {switched} ended in another elbow mode; FK from a perturbed \
         start: mean {:.2} / max {fk_max} iterations, {other_mode} found the other assembly \
         mode (near-singular poses); {backtracks} backtracking trials in all",
        cold_sum as f64 / poses as f64,
        fk_sum as f64 / poses as f64
    );
    assert!(worst_err < 1e-12, "round-trip error {worst_err:e}");
    assert!(other_mode < poses / 50);
    assert!(cold_max <= 10 && fk_max <= 10);
}

/// A smooth effector path inside the workspace and its first two derivatives.
fn path(t: f64) -> ([f64; 2], [f64; 2], [f64; 2]) {
    let w = std::f64::consts::PI;
    let p = [
        0.06 * (w * t).cos() + 0.02 * (3.0 * w * t).sin(),
        0.3 + 0.04 * (2.0 * w * t).sin(),
    ];
    let v = [
        -0.06 * w * (w * t).sin() + 0.06 * w * (3.0 * w * t).cos(),
        0.08 * w * (2.0 * w * t).cos(),
    ];
    let a = [
        -0.06 * w * w * (w * t).cos() - 0.18 * w * w * (3.0 * w * t).sin(),
        -0.16 * w * w * (2.0 * w * t).sin(),
    ];
    (p, v, a)
}

#[test]
fn inverse_velocity_and_acceleration_match_finite_differences_of_ik() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let mut fd = Data::new(&model);
    let mut fwd = Data::new(&model);
    let h = 1e-3;
    let (mut warm_sum, mut warm_max, mut n_warm) = (0, 0, 0);
    let (mut worst_v, mut worst_a, mut worst_cross) = (0.0_f64, 0.0_f64, 0.0_f64);
    for step in 0..=40 {
        let t = step as f64 * 0.05;
        let (p, v, a) = path(t);
        let rep = inverse_kinematics(&model, &mut data, &p).unwrap();
        if step > 0 {
            warm_sum += rep.iterations;
            warm_max = warm_max.max(rep.iterations);
            n_warm += 1;
        }
        let rv = inverse_velocity(&model, &mut data, &v).unwrap();
        let ra = inverse_acceleration(&model, &mut data, &a).unwrap();
        assert!(rv.residual < 1e-14 && ra.residual < 1e-12, "{rv:?} {ra:?}");
        assert_eq!((data.xdot[4], data.xdot[5]), (v[0], v[1]));
        assert_eq!((data.xddot[4], data.xddot[5]), (a[0], a[1]));

        // Fourth-order central differences of the IK solution in time.
        let mut xs = [[0.0; N]; 5];
        for (k, xk) in xs.iter_mut().enumerate() {
            fd.x = data.x;
            let (pk, _, _) = path(t + (k as f64 - 2.0) * h);
            inverse_kinematics(&model, &mut fd, &pk).unwrap();
            *xk = fd.x;
        }
        let (d1s, d2s) = central_4th(&xs, h);
        for (j, (&d1, &d2)) in d1s.iter().zip(&d2s).enumerate() {
            let ev = (data.xdot[j] - d1).abs() / (1.0 + d1.abs());
            let ea = (data.xddot[j] - d2).abs() / (1.0 + d2.abs());
            assert!(ev < 1e-8, "t={t} xdot[{j}]: {} vs FD {d1}", data.xdot[j]);
            assert!(ea < 1e-5, "t={t} xddot[{j}]: {} vs FD {d2}", data.xddot[j]);
            worst_v = worst_v.max(ev);
            worst_a = worst_a.max(ea);
        }

        // Cross-check with the forward solvers at the same state (two independent paths).
        fwd.x = data.x;
        forward_velocity(&model, &mut fwd, &[data.xdot[0], data.xdot[2]]).unwrap();
        forward_acceleration(&model, &mut fwd, &[data.xddot[0], data.xddot[2]]).unwrap();
        for j in 0..N {
            let e = (fwd.xdot[j] - data.xdot[j]).abs() + (fwd.xddot[j] - data.xddot[j]).abs();
            worst_cross = worst_cross.max(e / (1.0 + data.xddot[j].abs()));
        }
    }
    println!(
        "inverse velocity/acceleration vs 4th-order FD (h = {h}): worst rel err {worst_v:e} / \
         {worst_a:e}; vs forward solvers {worst_cross:e}; IK warm start along the path \
         (dt = 0.05 s): mean {:.2} / max {warm_max} iterations",
        warm_sum as f64 / n_warm as f64
    );
    assert!(worst_cross < 1e-12);
}

/// The left arm fully stretched (|P - left base| = L1 + L2), at 45 degrees.
fn stretched_pose() -> [f64; 2] {
    let r = L1 + L2;
    let phi = std::f64::consts::FRAC_PI_4;
    [-B + r * phi.cos(), r * phi.sin()]
}

#[test]
fn stretched_arm_is_singular_with_the_condition_estimate() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let p = stretched_pose();
    assert!(reachable(p[0], p[1], -1e-12));

    // From home, Newton creeps towards the double root until the block is singular.
    let before = data.x;
    let e = inverse_kinematics(&model, &mut data, &p).unwrap_err();
    println!("IK to a stretched left arm, from home: {e}");
    match e {
        SolverError::Singular { cond, what, block } => {
            assert!(
                cond > model.options.cond_max && cond.is_finite(),
                "cond {cond:e}"
            );
            assert_eq!(block, Some(0));
            assert_eq!(what, "IK block G_r");
        }
        other => panic!("expected Singular, got {other:?}"),
    }
    assert_eq!(data.x, before, "a failed solve leaves data.x untouched");

    // Exactly at the stretched assembly: singular at once.
    let phi = std::f64::consts::FRAC_PI_4;
    let mut x = HOME;
    x[0] = phi;
    x[1] = 0.0;
    data.x = x;
    let e = inverse_kinematics(&model, &mut data, &p).unwrap_err();
    println!("IK at the stretched assembly: {e}");
    assert!(matches!(e, SolverError::Singular { cond, block: Some(0), .. } if cond > 1e12));

    // Inverse velocity there: the same block is singular.
    let mut f = [0.0; M];
    FiveBar.constraints(&data.x, &mut f);
    let e = inverse_velocity(&model, &mut data, &[0.1, 0.0]).unwrap_err();
    assert!(matches!(e, SolverError::Singular { cond, block: Some(0), .. } if cond > 1e12));
    assert!(e.to_string().contains("block 0"), "{e}");
}

#[test]
fn unreachable_pose_is_an_error_not_nan() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let before = data.x;
    let e = inverse_kinematics(&model, &mut data, &[0.0, 0.6]).unwrap_err();
    println!("IK to an unreachable pose: {e}");
    // Each arm (l1 + l2 = 0.45 m) misses the effector point P = (0, 0.6) from its base
    // (-+0.15, 0) by D - 0.45 along B -> P at best (D = |P - B|): the least max |f| is that
    // miss's y component. Both arms are out of reach, equally (either may be named).
    let d = (0.15_f64.powi(2) + 0.6_f64.powi(2)).sqrt();
    let want = (d - 0.45) * 0.6 / d;
    match e {
        SolverError::Unreachable { block, residual } => {
            assert!(block < 2, "{block}");
            assert!((residual - want).abs() < 1e-9, "{residual} vs {want}");
        }
        other => panic!("expected Unreachable, got {other:?}"),
    }
    assert!(e.to_string().contains("out of reach"), "{e}");
    assert_eq!(data.x, before);

    // Only the right arm out of reach: the point (-0.2, 0.4) is 0.532 m from its base (0.15, 0)
    // (> 0.45) and 0.403 m from the left base.
    let e = inverse_kinematics(&model, &mut data, &[-0.2, 0.4]).unwrap_err();
    let d = (0.35_f64.powi(2) + 0.4_f64.powi(2)).sqrt();
    let want = (d - 0.45) * 0.4 / d;
    match e {
        SolverError::Unreachable { block, residual } => {
            assert_eq!(block, 1, "the right arm");
            assert!((residual - want).abs() < 1e-9, "{residual} vs {want}");
        }
        other => panic!("expected Unreachable, got {other:?}"),
    }
}

#[test]
fn non_finite_and_malformed_inputs_are_typed_errors() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    assert_eq!(
        inverse_kinematics(&model, &mut data, &[f64::NAN, 0.3]),
        Err(SolverError::NonFinite { what: "outputs" })
    );
    assert_eq!(
        inverse_kinematics(&model, &mut data, &[0.0, f64::INFINITY]),
        Err(SolverError::NonFinite { what: "outputs" })
    );
    assert_eq!(
        inverse_kinematics(&model, &mut data, &[0.0]),
        Err(SolverError::Dimension {
            what: "outputs",
            expected: 2,
            found: 1
        })
    );
    assert_eq!(
        inverse_velocity(&model, &mut data, &[f64::NAN, 0.0]),
        Err(SolverError::NonFinite {
            what: "outputs_dot"
        })
    );
    assert_eq!(
        inverse_acceleration(&model, &mut data, &[0.0, f64::NAN]),
        Err(SolverError::NonFinite {
            what: "outputs_ddot"
        })
    );
    data.x[1] = f64::NAN;
    assert_eq!(
        inverse_kinematics(&model, &mut data, &[0.0, 0.3]),
        Err(SolverError::NonFinite {
            what: "data.x (warm start)"
        })
    );
    assert!(data.x[1].is_nan(), "untouched on error");
    data.set_home(&model);
    data.xdot = [f64::NAN; N];
    assert_eq!(
        inverse_acceleration(&model, &mut data, &[0.0, 0.0]),
        Err(SolverError::NonFinite { what: "data.xdot" })
    );
}

#[test]
fn iteration_limit_gives_not_converged_with_the_residual() {
    let model = Model::new(FiveBar).with_options(SolverOptions {
        max_iterations: 1,
        ..SolverOptions::default()
    });
    let mut data = Data::new(&model);
    match inverse_kinematics(&model, &mut data, &[0.1, 0.25]) {
        Err(SolverError::NotConverged {
            iterations,
            residual,
        }) => {
            assert_eq!(iterations, 1);
            assert!(residual > 1e-12 && residual.is_finite());
        }
        other => panic!("expected NotConverged, got {other:?}"),
    }
    assert_eq!(data.x, HOME);
}
