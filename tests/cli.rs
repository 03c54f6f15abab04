//! The `rbss` command as a user runs it.

use std::process::Command;

use rbss_runtime::Kernels;

fn rbss(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn eval_writes_f_g_gamma_per_state() {
    let home: Vec<f64> = stewart_6ups::STRUCTURE.home.to_vec();
    let xdot: Vec<f64> = (0..24).map(|j| 0.01 * j as f64 - 0.1).collect();
    let mut x2 = home.clone();
    x2[0] += 0.05;
    let states =
        serde_json::json!({"states": [{"X": home, "Xdot": xdot}, {"X": x2, "Xdot": xdot}]});
    let dir = std::env::temp_dir().join(format!("rbss-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("states.json");
    std::fs::write(&path, states.to_string()).unwrap();
    let (ok, stdout, stderr) = rbss(&[
        "eval",
        "--model",
        "stewart_6ups",
        "--states",
        path.to_str().unwrap(),
    ]);
    assert!(ok, "rbss eval failed: {stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    let out = v["states"].as_array().unwrap();
    assert_eq!(out.len(), 2);
    let k = stewart_6ups::Stewart6Ups::default();
    for (s, input) in out.iter().zip([&home, &x2]) {
        let f = s["f"].as_array().unwrap();
        let g = s["G"].as_array().unwrap();
        let gamma = s["gamma"].as_array().unwrap();
        assert_eq!((f.len(), g.len(), gamma.len()), (18, 18, 18));
        let x: [f64; 24] = input.as_slice().try_into().unwrap();
        let mut gk = [[0.0; 18]; 24];
        k.jacobian(&x, &mut gk);
        for (r, row) in g.iter().enumerate() {
            let row = row.as_array().unwrap();
            assert_eq!(row.len(), 24, "G rows have n entries");
            for (c, val) in row.iter().enumerate() {
                assert_eq!(
                    val.as_f64().unwrap(),
                    gk[c][r],
                    "G[{r}][{c}] is row-major, model order"
                );
            }
        }
    }
    // The first state is the assembled home: f is tiny there.
    let f0: f64 = out[0]["f"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().abs())
        .fold(0.0, f64::max);
    assert!(f0 < 1e-9, "f(home) = {f0}");
}

#[test]
fn bad_input_gives_a_clear_error() {
    let (ok, _, stderr) = rbss(&["ik", "--model", "stewart_6ups", "--pose", "0.1,0,0.94"]);
    assert!(!ok);
    assert!(stderr.contains("expected 6 values, got 3"), "{stderr}");
    let (ok, _, stderr) = rbss(&["ik", "--model", "stewart_7ups", "--pose", "0"]);
    assert!(!ok);
    assert!(stderr.contains("unknown robot `stewart_7ups`"), "{stderr}");
    // An unreachable pose is a solver error, not a NaN.
    let (ok, stdout, stderr) = rbss(&["ik", "--model", "five_bar", "--pose", "0,2"]);
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("inverse kinematics failed"), "{stderr}");
}

#[test]
fn ik_then_fk_from_the_command_line() {
    let (ok, stdout, stderr) = rbss(&[
        "ik",
        "--model",
        "stewart_6ups",
        "--pose",
        "0.05,-0.02,0.95,0.05,-0.03,0.02",
    ]);
    assert!(ok, "{stderr}");
    let q: Vec<String> = stdout
        .lines()
        .filter(|l| l.contains("(actuated)"))
        .map(|l| {
            l.split('=')
                .nth(1)
                .unwrap()
                .split_whitespace()
                .next()
                .unwrap()
                .to_string()
        })
        .collect();
    assert_eq!(q.len(), 6);
    let (ok, stdout, stderr) = rbss(&["fk", "--model", "stewart_6ups", "--q", &q.join(",")]);
    assert!(ok, "{stderr}");
    let val = |name: &str| -> f64 {
        stdout
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{name} ")))
            .and_then(|l| l.split('=').nth(1))
            .and_then(|v| v.split_whitespace().next())
            .unwrap()
            .parse()
            .unwrap()
    };
    for (name, want) in [
        ("x", 0.05),
        ("y", -0.02),
        ("z", 0.95),
        ("rotx", 0.05),
        ("roty", -0.03),
        ("rotz", 0.02),
    ] {
        assert!(
            (val(name) - want).abs() < 1e-10,
            "{name} = {} (want {want})",
            val(name)
        );
    }
}
