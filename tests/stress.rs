//! Short versions of `rbss stress` (issue 5, "stress-test numerical stability"): the approach to
//! a parallel and a serial singularity, forward kinematics from perturbed starts, and a 10 s
//! RK4 run under each stabilisation. The full runs and their measured tables: `rbss stress
//! singularity | fk --samples 10000 | drift --steps 1000000`.

use rbss::stress::drift::{self, Reference, RunOptions, Servo};
use rbss::stress::fk::{self, Outcome as FkOutcome};
use rbss::stress::singularity::{self, Kind, Outcome, Path, Point};
use rbss_runtime::{SolverError, SolverOptions, Stabilization};

fn cond_max() -> f64 {
    SolverOptions::default().cond_max
}

/// How a solver is expected to fail.
#[derive(Clone, Copy, PartialEq)]
enum Solver {
    /// A direct solve (inverse, forward dynamics): a finite value up to the threshold.
    Direct,
    /// Newton (inverse, forward kinematics): its step test `max |dx| <= tol_x (1 + max |x|)`,
    /// `tol_x = 1e-12`, cannot be met once the rounding noise of the step, about `cond ε`,
    /// exceeds it, so from `cond` of about 1e4 on it may return `NotConverged` before the
    /// threshold.
    Newton,
}

/// A solver governed by the condition estimate `cond` of its matrix (measured at the exact
/// pose): `Singular` (with an estimate above `cond_max`) when `cond` is clearly past the
/// threshold, a finite value when clearly before it, and in the band between (where the
/// estimate at the solver's own iterate may differ by a small factor) a finite value,
/// `Singular` or, for Newton, `NotConverged`. Never NaN, never another error.
#[track_caller]
fn check_governed(what: &str, p: &Point, o: &Outcome, cond: f64, solver: Solver) {
    let cm = cond_max();
    if let Ok(v) = o {
        assert!(v.is_finite(), "{what} at 1 - s = {:e}: {v}", p.dist);
    }
    let ok_below = match solver {
        Solver::Direct => cm / 3.0,
        Solver::Newton => 1e4,
    };
    if cond > 3.0 * cm {
        match o {
            Err(SolverError::Singular { cond: c, .. }) => {
                assert!(*c > cm, "{what} at 1 - s = {:e}: {o:?}", p.dist)
            }
            _ => panic!(
                "{what} at 1 - s = {:e} (cond {cond:e}): expected Singular, got {o:?}",
                p.dist
            ),
        }
    } else if cond < ok_below {
        assert!(
            o.is_ok(),
            "{what} at 1 - s = {:e} (cond {cond:e}): {o:?}",
            p.dist
        );
    } else {
        let newton_miss =
            solver == Solver::Newton && matches!(o, Err(SolverError::NotConverged { .. }));
        assert!(
            matches!(o, Ok(_) | Err(SolverError::Singular { .. })) || newton_miss,
            "{what} at 1 - s = {:e} (cond {cond:e}): {o:?}",
            p.dist
        );
    }
}

/// The governing condition estimate grows like `C / (1 - s)` without bound.
#[track_caller]
fn check_growth(name: &str, pts: &[Point], cond: impl Fn(&Point) -> f64) {
    let approach: Vec<&Point> = pts
        .iter()
        .filter(|p| p.dist > 0.0 && p.dist <= 1e-2)
        .collect();
    assert!(approach.len() > 20);
    for w in approach.windows(2) {
        assert!(
            cond(w[1]) > cond(w[0]),
            "{name}: cond not increasing at 1 - s = {:e}",
            w[1].dist
        );
    }
    let scaled: Vec<f64> = approach.iter().map(|p| cond(p) * p.dist).collect();
    let (lo, hi) = scaled
        .iter()
        .fold((f64::INFINITY, 0.0_f64), |(l, h), &v| (l.min(v), h.max(v)));
    assert!(hi < 1.5 * lo, "{name}: cond (1 - s) in [{lo:e}, {hi:e}]");
    let last = approach.last().unwrap();
    assert!(cond(last) > 1e10, "{name}: {:e}", cond(last));
}

#[test]
fn singularities_end_in_typed_errors() {
    let samples = singularity::samples();
    for path in [Path::parallel(), Path::serial()] {
        let pts = singularity::walk(&path, &samples);
        println!("{}", singularity::table(&path, &pts, true));
        let name = path.name;
        for p in &pts {
            assert!(p.closed_form_residual < 1e-14, "{name}: {p:?}");
            // Forward dynamics is regular at both: G keeps full row rank.
            assert!(p.cond_fd < 200.0, "{name}: S_c {:e}", p.cond_fd);
            match p.fd {
                Ok(v) => assert!(v.is_finite()),
                Err(e) => panic!("{name}: forward dynamics at 1 - s = {:e}: {e}", p.dist),
            }
            if p.fk.is_ok() {
                assert!(p.fk_error < 1e-6, "{name}: FK left the path: {p:?}");
            }
        }
        match path.kind {
            Kind::Parallel => {
                check_growth(name, &pts, |p| p.cond_jp);
                check_growth(name, &pts, |p| p.cond_id);
                for p in &pts {
                    assert!(p.ik.is_ok() && p.cond_ik < 10.0, "{name}: {p:?}");
                    check_governed("parallel FK", p, &p.fk, p.cond_jp, Solver::Newton);
                    check_governed("parallel ID", p, &p.id, p.cond_id, Solver::Direct);
                    // Before the threshold the (large) holding forces are right: forward
                    // dynamics under them leaves the robot at rest.
                    if p.cond_id < cond_max() {
                        assert!(p.fd.unwrap() < 1e-6, "{name}: {p:?}");
                    }
                }
                // The forces grow without bound too, and the last ones returned are finite.
                let last_ok = pts.iter().rev().find_map(|p| p.id.ok()).unwrap();
                assert!(last_ok.is_finite() && last_ok > 1e7, "{last_ok:e}");
            }
            Kind::Serial => {
                check_growth(name, &pts, |p| p.cond_ik);
                check_growth(name, &pts, |p| p.cond_jp);
                for p in &pts {
                    check_governed("serial IK", p, &p.ik, p.cond_ik, Solver::Newton);
                    check_governed("serial FK", p, &p.fk, p.cond_jp, Solver::Newton);
                    // Inverse dynamics falls back to [S | Gᵀ] at a singular block, which is
                    // singular too: governed by the block.
                    check_governed("serial ID", p, &p.id, p.cond_ik, Solver::Direct);
                    // The reduced system and the forces stay regular (about 990 N).
                    assert!(p.cond_id < 100.0, "{name}: {p:?}");
                    if p.dist <= 1e-2 && p.dist > 0.0 {
                        assert!((p.u_max - 990.4).abs() < 3.0, "{name}: {p:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn forward_kinematics_from_perturbed_starts() {
    // 300 starts, 50 per noise level. Measured with these seeds (and at 10,000 starts, seed 2009:
    // `rbss stress fk`): Newton 100 % up to sigma 0.1, 99.7 % at 0.3, 87 % at 0.6, 36 % at 1;
    // LM 100 % up to 0.3, 99.9 % at 0.6, 89 % at 1.
    let st = fk::study(300, &fk::SIGMAS, 2009);
    println!("{}", fk::rates_table(&st));
    for (sigma, row) in st.sigmas.iter().zip(&st.tallies) {
        let [newton, lm, policy] = row;
        for t in row {
            assert_eq!(t.count, 50);
            assert_eq!(t.by_outcome[FkOutcome::NonFinite as usize], 0);
            assert_eq!(t.by_outcome[FkOutcome::OtherError as usize], 0);
        }
        let same = |t: &fk::Tally| t.rate(FkOutcome::Same);
        if *sigma <= 0.3 {
            assert!(same(newton) >= 0.95, "Newton at {sigma}: {newton:?}");
        }
        if *sigma <= 0.6 {
            assert!(same(lm) >= 0.95, "LM at {sigma}: {lm:?}");
        }
        if *sigma >= 1.0 {
            assert!(same(lm) >= 0.75, "LM at {sigma}: {lm:?}");
        }
        // LM does no worse than Newton (one start of 50 of slack).
        assert!(
            same(lm) + 0.02 >= same(newton),
            "at {sigma}: LM {lm:?} Newton {newton:?}"
        );
        // The policy only turns silent mode changes into rejections.
        assert_eq!(same(policy), same(lm), "at {sigma}");
        assert!(policy.rate(FkOutcome::OtherMode) <= lm.rate(FkOutcome::OtherMode));
        assert_eq!(
            policy.by_outcome[FkOutcome::Rejected as usize]
                + policy.by_outcome[FkOutcome::OtherMode as usize]
                + policy.by_outcome[FkOutcome::Branch as usize],
            lm.by_outcome[FkOutcome::OtherMode as usize]
                + lm.by_outcome[FkOutcome::Branch as usize],
            "at {sigma}"
        );
        // Newton and LM converge fast from good starts. Newton's steps include its chord steps
        // (at most 6 here, at most 5 before they were taken; LM's at most 5).
        if *sigma <= 0.1 {
            assert!(newton.iteration_quantile(1.0) <= 7 && lm.iteration_quantile(1.0) <= 6);
        }
    }
}

#[test]
fn drift_under_each_stabilisation() {
    let dt = 1e-3;
    let steps = 10_000;
    let mut reference = Reference::new(rbss::paper::OMEGA, dt).unwrap();
    let mut runs = Vec::new();
    for stab in drift::STABILIZATIONS {
        let o = RunOptions {
            stabilization: stab,
            servo: Servo::DEFAULT,
            dt,
            steps,
            window: 1000,
            stop_tracking: 1.0,
        };
        let r = drift::run(&mut reference, &o, &mut |_| {}).unwrap();
        assert!(r.error.is_none(), "{:?}", r.error);
        assert_eq!(r.steps, steps);
        runs.push(r);
    }
    println!("{}", drift::table(&runs));
    let s: Vec<drift::Summary> = runs.iter().map(drift::summary).collect();
    let [none, baum, proj, part] = [&s[0], &s[1], &s[2], &s[3]];
    // Measured over 10 s (dt 1e-3): none 1.0e-9 and growing, Baumgarte 2.2e-12 (bounded),
    // projection 1.0e-12 (tol_f, after projecting), partitioning 4e-16.
    let first = runs[0].samples.first().unwrap().violation;
    assert!(
        none.final_violation > 20.0 * first,
        "none: {first:e} → {none:?}"
    );
    assert!(none.final_violation > 1e-10, "{none:?}");
    assert!(baum.max_violation < 1e-11, "{baum:?}");
    assert!(none.final_violation > 50.0 * baum.max_violation);
    let tol_f = SolverOptions::default().tol_f;
    assert!(
        runs[2].samples.iter().all(|w| w.violation <= tol_f),
        "{proj:?}"
    );
    assert!(proj.max_velocity_violation < 1e-14, "{proj:?}");
    assert!(
        part.max_violation < 1e-14 && part.max_velocity_violation < 1e-14,
        "{part:?}"
    );
    for (r, x) in runs.iter().zip(&s) {
        // The balance E - E0 - W is RK4's own O(dt⁴) error of W (measured 4e-7 J in 10 s).
        assert!(x.max_balance < 2e-6, "{:?}: {x:?}", r.stabilization);
        assert!(x.max_tracking < 1e-8, "{:?}: {x:?}", r.stabilization);
    }
    // The costs: projection and partitioning spend Newton iterations.
    assert_eq!(runs[0].stats.newton_iterations, 0);
    assert!(runs[2].stats.newton_iterations > 0);
    assert!(runs[3].stats.newton_iterations >= 2 * steps);
    assert!(matches!(
        runs[3].stabilization,
        Stabilization::CoordinatePartitioning
    ));
}

#[test]
fn feed_forward_alone_leaves_the_path() {
    // Without the servo the same U(t) diverges from TraekP (unstable under fixed leg forces):
    // measured 2.3e-11 m at 1 s, 1.5e-7 at 3 s.
    let dt = 1e-3;
    let mut reference = Reference::new(rbss::paper::OMEGA, dt).unwrap();
    let o = RunOptions {
        stabilization: Stabilization::Projection,
        servo: Servo::OFF,
        dt,
        steps: 3000,
        window: 1000,
        stop_tracking: 0.1,
    };
    let r = drift::run(&mut reference, &o, &mut |_| {}).unwrap();
    let tr: Vec<f64> = r.samples.iter().map(|s| s.tracking).collect();
    println!("{tr:?}");
    assert!(
        tr[0] < 1e-9 && tr[2] > 1e-8 && tr[2] > 100.0 * tr[0],
        "{tr:?}"
    );
}

#[test]
fn levenberg_marquardt_errors_and_mode_policy() {
    use rbss_runtime::{
        Data, FkRobustError, LmOptions, Model, forward_kinematics, forward_kinematics_lm,
    };
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let geo = rbss::stress::geometry::Geometry::default();
    let x_ref = geo.x_of_pose(&[0.05, -0.03, 0.95, 0.1, -0.05, 0.08]);
    let q = &x_ref[..6];
    let mut data = Data::new(&model);

    // From home: the same solution as Newton, with the report filled in.
    let rep = forward_kinematics_lm(&model, &mut data, q, &LmOptions::default()).unwrap();
    let mut newton = Data::new(&model);
    let rep_n = forward_kinematics(&model, &mut newton, q).unwrap();
    let diff = (0..24).fold(0.0_f64, |m, j| m.max((data.x[j] - x_ref[j]).abs()));
    assert!(diff < 1e-12, "{diff:e}");
    assert!(
        rep.residual <= 1e-12 && rep.cond > 1.0 && rep.cond < 1e4,
        "{rep:?}"
    );
    assert!(
        rep.iterations <= rep_n.iterations + 2,
        "{rep:?} vs {rep_n:?}"
    );
    assert!(rep.max_change > 0.0 && rep.max_change_coordinate >= 6);

    // The policy: from home the platform moves 0.05 m, so a 0.01 limit rejects the solution and
    // leaves data.x as it was.
    let mut d = Data::new(&model);
    let before = d.x;
    let strict = LmOptions {
        max_passive_change: 0.01,
        ..LmOptions::default()
    };
    match forward_kinematics_lm(&model, &mut d, q, &strict) {
        Err(FkRobustError::ModeChange {
            max_change,
            residual,
            ..
        }) => assert!(max_change > 0.01 && residual <= 1e-12),
        other => panic!("{other:?}"),
    }
    assert_eq!(d.x, before);

    // Typed input errors.
    let e = forward_kinematics_lm(&model, &mut d, &q[..5], &LmOptions::default()).unwrap_err();
    assert!(matches!(
        e,
        FkRobustError::Solver(SolverError::Dimension { .. })
    ));
    let mut bad = q.to_vec();
    bad[2] = f64::NAN;
    let e = forward_kinematics_lm(&model, &mut d, &bad, &LmOptions::default()).unwrap_err();
    assert!(matches!(
        e,
        FkRobustError::Solver(SolverError::NonFinite { .. })
    ));
    let e = forward_kinematics_lm(
        &model,
        &mut d,
        q,
        &LmOptions {
            tau: -1.0,
            ..LmOptions::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, FkRobustError::Solver(_)));

    // At the parallel singularity LM reports Singular like Newton, not a NaN.
    let xs = geo.x_of_pose(&Path::parallel().pose(1.0 - 1e-9));
    let mut d = Data::new(&model);
    d.x = xs;
    match forward_kinematics_lm(&model, &mut d, &xs[..6], &LmOptions::default()) {
        Err(FkRobustError::Solver(SolverError::Singular { cond, .. })) => {
            assert!(cond > cond_max())
        }
        other => panic!("{other:?}"),
    }
    // Unreachable leg lengths: NotConverged (a least-squares point that is not a root).
    let far = [3.0, 0.2, 0.2, 0.2, 0.2, 0.2];
    let mut d = Data::new(&model);
    match forward_kinematics_lm(&model, &mut d, &far, &LmOptions::default()) {
        Err(FkRobustError::Solver(SolverError::NotConverged { residual, .. })) => {
            assert!(residual.is_finite() && residual > 1e-3)
        }
        other => panic!("{other:?}"),
    }
}
