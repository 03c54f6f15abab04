//! The `rbss` command with non-finite and absurd numbers: every one is a clear error on
//! stderr and a failing exit status, never a NaN (or a JSON `null`) on stdout.

mod common;

use common::rbss;

/// Fails with `rbss: error: ...` containing `expect`, and prints no number on stdout.
#[track_caller]
fn fails(args: &[&str], expect: &str) {
    let (ok, stdout, stderr) = rbss(args);
    assert!(!ok, "{args:?} succeeded:\n{stdout}");
    assert!(
        stderr.starts_with("rbss: error: ") && stderr.contains(expect),
        "{args:?}: expected an error containing `{expect}`, got:\n{stderr}"
    );
    assert!(
        !stdout.to_lowercase().contains("nan") && !stdout.contains("inf"),
        "{args:?} printed a non-finite value:\n{stdout}"
    );
}

const NON_FINITE: [&str; 6] = ["nan", "NaN", "inf", "-inf", "+infinity", "1e999"];

#[test]
fn ik_and_fk_reject_non_finite_numbers() {
    for bad in NON_FINITE {
        // The message quotes what was written (`1e999`, not `inf`).
        let expect = format!("`{bad}` (value ");
        let expect = expect.as_str();
        let pose = format!("0.1,0,{bad},0.1,0,0");
        fails(&["ik", "--model", "stewart_6ups", "--pose", &pose], expect);
        fails(
            &["ik", "--model", "five_bar", "--pose", &format!("{bad},0.3")],
            expect,
        );
        let q = format!("0.93,0.98,1.04,{bad},0.96,0.97");
        fails(&["fk", "--model", "stewart_6ups", "--q", &q], expect);
        fails(
            &["fk", "--model", "five_bar", "--q", &format!("1.9,{bad}")],
            expect,
        );
        fails(
            &[
                "fk",
                "--model",
                "stewart_6ups",
                "--q",
                "0.93,0.98,1.04,0.98,0.96,0.97",
                "--near",
                &pose,
            ],
            "--near: ",
        );
    }
}

/// Finite but absurd: the solvers' typed errors, not a NaN.
#[test]
fn ik_and_fk_fail_cleanly_on_absurd_numbers() {
    for bad in ["1e300", "-1e300", "1.7976931348623157e308"] {
        fails(
            &[
                "ik",
                "--model",
                "stewart_6ups",
                "--pose",
                &format!("{bad},0,0.94,0.1,0,0"),
            ],
            "inverse kinematics failed",
        );
        fails(
            &["ik", "--model", "five_bar", "--pose", &format!("0,{bad}")],
            "inverse kinematics failed",
        );
        fails(
            &[
                "fk",
                "--model",
                "stewart_6ups",
                "--q",
                &format!("{bad},0.98,1.04,0.98,0.96,0.97"),
            ],
            "forward kinematics failed",
        );
    }
}

#[test]
fn eval_rejects_non_finite_states() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let home: Vec<String> = stewart_6ups::STRUCTURE
        .home
        .iter()
        .map(|v| format!("{v:?}"))
        .collect();
    let zeros = vec!["0".to_string(); 24];
    let run = |name: &str, x: &[String], xdot: &[String], expect: &str| {
        let path = dir.join(format!("{name}.json"));
        let json = format!(
            "{{\"states\":[{{\"X\":[{}],\"Xdot\":[{}]}}]}}",
            x.join(","),
            xdot.join(",")
        );
        std::fs::write(&path, json).unwrap();
        fails(
            &[
                "eval",
                "--model",
                "stewart_6ups",
                "--states",
                path.to_str().unwrap(),
            ],
            expect,
        );
    };
    let with = |xs: &[String], j: usize, v: &str| {
        let mut xs = xs.to_vec();
        xs[j] = v.to_string();
        xs
    };
    // Not JSON numbers at all, or out of f64's range.
    for bad in ["NaN", "Infinity", "-Infinity", "null", "\"nan\""] {
        run("literal", &with(&home, 20, bad), &zeros, "bad states file");
    }
    run(
        "overflow",
        &with(&home, 20, "1e999"),
        &zeros,
        "number out of range",
    );
    run(
        "overflow_v",
        &home,
        &with(&zeros, 3, "-1e400"),
        "number out of range",
    );
    // Finite, but the kernels overflow: an error, not `null` in the output.
    run(
        "huge_v",
        &home,
        &vec!["1e300".to_string(); 24],
        "is not finite (NaN or inf) there",
    );
    run(
        "huge_x",
        &with(&home, 21, "1e300"),
        &vec!["1e300".to_string(); 24],
        "is not finite (NaN or inf) there",
    );
}

#[test]
fn trajectory_commands_reject_non_finite_settings() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("u.csv");
    let csv = csv.to_str().unwrap();
    for bad in ["nan", "inf"] {
        fails(
            &[
                "inverse-dynamics",
                "--model",
                "stewart_6ups",
                "--omega",
                bad,
                "--csv",
                csv,
            ],
            "finite",
        );
        fails(
            &[
                "inverse-dynamics",
                "--model",
                "stewart_6ups",
                "--t-end",
                bad,
                "--csv",
                csv,
            ],
            "finite",
        );
        fails(&["paper", "--out", csv, "--rtol", bad], "--rtol");
        fails(&["paper", "--out", csv, "--omega", bad], "finite");
    }
}

/// A pose so large that the IK blocks' determinants overflow is reported as a non-finite
/// value, not as a singular block (it is an overflow, not a singularity of the robot).
#[test]
fn ik_at_an_absurd_pose_is_an_overflow_not_a_singularity() {
    for pose in ["1e300,0,0.94,0,0,0", "0.1,0,1e300,0,0,0"] {
        fails(
            &["ik", "--model", "stewart_6ups", "--pose", pose],
            "non-finite value",
        );
        let (_, _, stderr) = rbss(&["ik", "--model", "stewart_6ups", "--pose", pose]);
        assert!(!stderr.contains("singular"), "{stderr}");
    }
}
