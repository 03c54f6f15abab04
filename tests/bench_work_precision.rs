//! `rbss bench work-precision --quick` through the binary: the CSV has every integrator ×
//! stabilisation, RK4's counts are exact, and every method's error falls with its step or
//! tolerance; another robot along its trajectory file measures what `rbss roundtrip` does.
//! Deterministic quantities only, never timings.

use std::collections::BTreeMap;
use std::process::Command;

#[test]
fn quick_work_precision_sweep() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "bench",
            "work-precision",
            "--model",
            "stewart_6ups",
            "--quick",
        ])
        .args(["--repeats", "1", "--out"])
        .arg(dir)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "rbss bench failed: {stderr}");
    assert!(
        stdout.contains("Pareto front"),
        "prints the front: {stdout}"
    );
    // One progress line per run.
    assert_eq!(stderr.lines().filter(|l| l.contains("/24] ")).count(), 24);

    let csv = std::fs::read_to_string(dir.join("work_precision.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(
        rows.len(),
        24,
        "3 integrators x 2 settings x 4 stabilisations"
    );

    // (method, stabilisation) -> [(parameter, position error, energy balance error)]
    type Curve = Vec<(f64, f64, f64)>;
    let mut curves: BTreeMap<(String, String), Curve> = BTreeMap::new();
    for r in &rows {
        let (method, stab) = (r[col("method")], r[col("stabilization")]);
        assert_eq!(r[col("status")], "ok", "{method} {stab} failed: {r:?}");
        let num = |name: &str| r[col(name)].parse::<f64>().unwrap();
        let int = |name: &str| r[col(name)].parse::<usize>().unwrap();
        let (param, err) = (num("parameter"), num("position_error_m"));
        assert!(err.is_finite() && err > 0.0);
        assert!(num("max_violation_m").is_finite());
        // The work-energy balance holds to a small fraction of the energy's swing (~28 J).
        let (energy, swing) = (num("energy_error_j"), num("energy_swing_j"));
        assert!(
            swing > 20.0 && swing < 40.0,
            "{method} {stab}: swing {swing}"
        );
        assert!(energy < 1e-2 * swing, "{method} {stab}: balance {energy}");
        if method == "rk4" {
            // Fixed steps landing on t_end = 2 s: 2 / dt steps, four evaluations each.
            assert_eq!(
                int("steps"),
                (2.0 / param).round() as usize,
                "{method} {stab}"
            );
            assert_eq!(int("rhs_evaluations"), 4 * int("steps"), "{method} {stab}");
            assert_eq!(int("rejected"), 0);
        } else {
            // Six evaluations per DOPRI5 step, twelve per DOP853 step (FSAL), more after
            // projections and rejections.
            let per_step = if method == "dop853" { 12 } else { 6 };
            assert!(
                int("rhs_evaluations") >= per_step * int("steps"),
                "{method} {stab}"
            );
        }
        if stab == "partitioning" {
            assert!(
                num("max_violation_m") < 1e-12,
                "partitioning keeps f(X) = 0"
            );
        }
        curves
            .entry((method.to_string(), stab.to_string()))
            .or_default()
            .push((param, err, num("energy_error_j")));
    }
    let mut names: Vec<String> = curves.keys().map(|(m, s)| format!("{m} {s}")).collect();
    names.sort();
    assert_eq!(
        names,
        [
            "dop853 baumgarte",
            "dop853 none",
            "dop853 partitioning",
            "dop853 projection",
            "dopri5 baumgarte",
            "dopri5 none",
            "dopri5 partitioning",
            "dopri5 projection",
            "rk4 baumgarte",
            "rk4 none",
            "rk4 partitioning",
            "rk4 projection"
        ]
    );
    for ((method, stab), mut pts) in curves {
        // Coarse to fine: the position error and the energy balance error must fall.
        pts.sort_by(|a, b| b.0.total_cmp(&a.0));
        for w in pts.windows(2) {
            assert!(
                w[1].1 < w[0].1,
                "{method} {stab}: error {:e} at {:e} is not below {:e} at {:e}",
                w[1].1,
                w[1].0,
                w[0].1,
                w[0].0
            );
            assert!(
                w[1].2 < w[0].2,
                "{method} {stab}: energy balance {:e} at {:e} is not below {:e} at {:e}",
                w[1].2,
                w[1].0,
                w[0].2,
                w[0].0
            );
        }
    }

    let png = std::fs::read(dir.join("work_precision.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
}

/// Any robot along its default trajectory file (models/trajectories/five_bar.toml): RK4
/// without stabilisation gives the outputs' error `rbss roundtrip` measures with the same
/// integrator, from its own CSV (the same control, integrator and states: equal).
#[test]
fn five_bar_along_its_trajectory_matches_roundtrip() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rbss = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let wp = dir.join("wp");
    let stdout = rbss(&[
        "bench",
        "work-precision",
        "--model",
        "five_bar",
        "--quick",
        "--repeats",
        "1",
        "--out",
        wp.to_str().unwrap(),
    ]);
    assert!(stdout.contains("five_bar round trip, 24 runs"), "{stdout}");
    let csv = std::fs::read_to_string(wp.join("work_precision.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let row: Vec<&str> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|r| {
            r[col("method")] == "rk4"
                && r[col("stabilization")] == "none"
                && r[col("parameter")] == "1e-3"
        })
        .expect("the rk4 dt=1e-3 run without stabilisation");
    // Both outputs (x, y) are lengths: the position error is the outputs' error; no rotation.
    let error: f64 = row[col("output_error")].parse().unwrap();
    assert_eq!(row[col("position_error_m")].parse::<f64>().unwrap(), error);
    assert_eq!(row[col("rotation_error_rad")], "");

    let rt = dir.join("rt");
    rbss(&[
        "roundtrip",
        "--model",
        "five_bar",
        "--method",
        "rk4",
        "--dt",
        "1e-3",
        "--stabilization",
        "none",
        "--out",
        rt.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(rt.join("roundtrip.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut worst = 0.0_f64;
    for l in lines {
        for (h, v) in header.iter().zip(l.split(',')) {
            if h.ends_with("_error") {
                worst = worst.max(v.parse::<f64>().unwrap().abs());
            }
        }
    }
    assert!(worst > 0.0);
    assert!(
        (error - worst).abs() <= 1e-12 * worst,
        "work-precision {error:e}, roundtrip {worst:e}"
    );
}

/// A robot without a default trajectory file: the round trip's error, naming the files and
/// the outputs to give.
#[test]
fn work_precision_needs_a_trajectory() {
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "bench",
            "work-precision",
            "--model",
            "spring_pendulum",
            "--out",
        ])
        .arg(tempfile::tempdir().unwrap().path().join("none"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("`spring_pendulum` has no default trajectory")
            && stderr.contains("--trajectory FILE"),
        "{stderr}"
    );
}
