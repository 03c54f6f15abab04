//! `rbss bench solvers`: the table's deterministic parts (rows, columns, the kernel calls each
//! solver makes, ratio = ns_per_call / kernels_ns); the timings themselves are reported, not
//! asserted.

use std::process::Command;

#[test]
fn solver_table_for_every_solver() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "bench",
            "solvers",
            "--model",
            "five_bar",
            "--batches",
            "3",
            "--out",
        ])
        .arg(dir)
        .output()
        .expect("run rbss");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("solvers.csv")).expect("solvers.csv");
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("solver,ns_per_call,kernels_ns,ratio,kernel_calls")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let names: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(
        names,
        [
            "ik_warm",
            "fk_warm",
            "inverse_velocity",
            "inverse_acceleration",
            "forward_velocity",
            "forward_acceleration",
            "inverse_dynamics",
            "forward_dynamics",
            "id_sample"
        ]
    );
    for r in &rows {
        assert_eq!(r.len(), 5, "{r:?}");
        let ns: f64 = r[1].parse().unwrap();
        let kernels: f64 = r[2].parse().unwrap();
        let ratio: f64 = r[3].parse().unwrap();
        assert!(ns > 0.0 && kernels > 0.0, "{r:?}");
        assert!((ratio - ns / kernels).abs() <= 0.01 + 1e-3 * ratio, "{r:?}");
        assert!(
            stdout.contains(&format!("| five_bar | {} |", r[0])),
            "{stdout}"
        );
    }
    // Which kernels each solver calls is decided by the runtime, not by the clock.
    let calls = |name: &str| rows.iter().find(|r| r[0] == name).unwrap()[4];
    assert_eq!(calls("inverse_velocity"), "1 jacobian");
    assert_eq!(calls("inverse_acceleration"), "1 jacobian + 1 gamma");
    assert_eq!(calls("forward_velocity"), "1 jacobian");
    assert_eq!(calls("forward_acceleration"), "1 jacobian + 1 gamma");
    assert_eq!(calls("inverse_dynamics"), "1 dynamics_terms");
    assert_eq!(calls("forward_dynamics"), "1 dynamics_terms");
    assert!(calls("ik_warm").contains("constraints_jacobian_ik"));
    assert!(calls("fk_warm").contains("constraints_jacobian_p"));
    assert!(calls("id_sample").ends_with("1 dynamics_terms"));
}

/// A robot with passive degrees of freedom (spring_pendulum: 2 of them, 1 actuated) gets the
/// rows of the tasks it has, and the table says which it has not (issue 37): before, the
/// command failed on inverse dynamics.
#[test]
fn solver_table_with_passive_degrees_of_freedom() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "bench",
            "solvers",
            "--model",
            "spring_pendulum",
            "--batches",
            "3",
            "--out",
        ])
        .arg(dir)
        .output()
        .expect("run rbss");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("solvers.csv")).expect("solvers.csv");
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let names: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(
        names,
        [
            "ik_warm",
            "inverse_velocity",
            "inverse_acceleration",
            "forward_dynamics"
        ]
    );
    for r in &rows {
        let (ns, kernels): (f64, f64) = (r[1].parse().unwrap(), r[2].parse().unwrap());
        assert!(ns > 0.0 && kernels > 0.0, "{r:?}");
    }
    let calls = |name: &str| rows.iter().find(|r| r[0] == name).unwrap()[4];
    assert_eq!(calls("forward_dynamics"), "1 dynamics_terms");
    assert!(
        stdout.contains("spring_pendulum: 2 degree(s) of freedom, 1 actuated: no fk_warm")
            && stdout.contains("inverse_dynamics"),
        "{stdout}"
    );
}
