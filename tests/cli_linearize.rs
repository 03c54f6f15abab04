//! `rbss linearize`: the JSON against the runtime's `linearize` in the same process (the same
//! numbers after the JSON round trip), `A`'s and `B`'s layout, both choices of coordinates, and
//! the refusals (an inconsistent state, a bad `--coordinates`). `rbss id-derivatives`: the JSON
//! against the runtime's `inverse_dynamics_derivatives` (the same numbers) and against central
//! differences of the runtime's `inverse_dynamics`, and its refusals.

// The checks compare a JSON matrix (rows of rows) with nalgebra's entry by entry: index loops
// over both are the plain form.
#![allow(clippy::needless_range_loop)]

mod common;

use common::rbss;
use rbss_runtime::{
    Coordinates, Data, InverseDynamicsDerivatives, Linearization, Model, inverse_dynamics,
    inverse_dynamics_derivatives, inverse_velocity, linearize,
};

fn matrix(v: &serde_json::Value, what: &str) -> Vec<Vec<f64>> {
    v[what]
        .as_array()
        .unwrap_or_else(|| panic!("{what}: not an array"))
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

/// The state file at home with the velocity from the outputs' rates `rates`, and the runtime's
/// linearisation there in `c`.
fn case<K: rbss_runtime::DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    rates: &[f64],
    u: &[f64],
    c: Coordinates,
    dir: &std::path::Path,
) -> (String, Data<N, M>, Linearization<N, M>) {
    let mut data = Data::new(model);
    inverse_velocity(model, &mut data, rates).unwrap();
    let state = serde_json::json!({"X": data.x.to_vec(), "Xdot": data.xdot.to_vec(), "U": u});
    let path = dir.join("state.json");
    std::fs::write(&path, state.to_string()).unwrap();
    let mut lin = Linearization::new();
    lin.full_derivatives = true; // the command writes the full derivatives
    linearize(model, &mut data, &mut lin, u, None, c).unwrap();
    (path.to_str().unwrap().to_string(), data, lin)
}

fn check<K: rbss_runtime::DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    rates: &[f64],
    u: &[f64],
) {
    let tmp = tempfile::tempdir().unwrap();
    for (c, flag) in [
        (Coordinates::Outputs, None),
        (Coordinates::Outputs, Some("outputs")),
        (Coordinates::Actuated, Some("actuated")),
    ] {
        let (path, data, lin) = case(model, rates, u, c, tmp.path());
        let mut args = vec!["linearize", "--model", name, "--state", &path];
        if let Some(f) = flag {
            args.extend(["--coordinates", f]);
        }
        let (ok, stdout, stderr) = rbss(&args);
        assert!(ok, "rbss linearize {name} {flag:?} failed: {stderr}");
        let v: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
        let (d, k) = (lin.d, lin.na);
        assert_eq!(v["coordinates"], flag.unwrap_or("outputs"));
        let s = model.structure();
        let idx = if c == Coordinates::Outputs {
            s.outputs
        } else {
            s.actuated
        };
        let index: Vec<usize> = v["index"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(index, idx);
        let a = matrix(&v, "A");
        let b = matrix(&v, "B");
        assert_eq!(
            (a.len(), a[0].len(), b.len(), b[0].len()),
            (2 * d, 2 * d, 2 * d, k)
        );
        for i in 0..d {
            for j in 0..d {
                assert_eq!(a[i][j], 0.0);
                assert_eq!(a[i][d + j], if i == j { 1.0 } else { 0.0 });
                assert_eq!(
                    a[d + i][j],
                    lin.dyddot_dy[(i, j)],
                    "{name} A[{},{j}]",
                    d + i
                );
                assert_eq!(a[d + i][d + j], lin.dyddot_dydot[(i, j)]);
            }
            for j in 0..k {
                assert_eq!(b[i][j], 0.0);
                assert_eq!(b[d + i][j], lin.dyddot_du[(i, j)]);
            }
        }
        // The full derivatives and the solution.
        let fd = &lin.derivatives;
        let dx = matrix(&v, "dXddot_dX");
        let dl = matrix(&v, "dlambda_dU");
        let t = matrix(&v, "tangent");
        assert_eq!((dx.len(), dx[0].len(), dl.len(), t.len()), (N, N, M, N));
        for i in 0..N {
            for j in 0..N {
                assert_eq!(dx[i][j], fd.dxddot_dx[(i, j)]);
            }
            for j in 0..d {
                assert_eq!(t[i][j], lin.tangent[(i, j)]);
            }
        }
        for i in 0..M {
            for j in 0..k {
                assert_eq!(dl[i][j], fd.dlambda_du[(i, j)]);
            }
        }
        let xddot: Vec<f64> = v["Xddot"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(xddot, data.xddot.to_vec());
        // Not a trivial answer: the dynamics move.
        assert!(
            a[d][0] != 0.0 || a[d][d] != 0.0,
            "{name}: A's dynamics rows are zero"
        );
    }
}

#[test]
fn five_bar_and_6ups_match_the_runtime() {
    check(
        "five_bar",
        &Model::new(five_bar::FiveBar::default()),
        &[0.1, -0.2],
        &[0.3, -0.1],
    );
    check(
        "stewart_6ups",
        &Model::new(stewart_6ups::Stewart6Ups::default()),
        &[0.01, -0.02, 0.03, 0.01, 0.02, -0.01],
        &[300.0, 310.0, 320.0, 330.0, 340.0, 350.0],
    );
}

#[test]
fn refusals() {
    let tmp = tempfile::tempdir().unwrap();
    let home: Vec<f64> = five_bar::STRUCTURE.home.to_vec();
    let n = home.len();
    // An inconsistent velocity: refused with the residual, as `rbss fd` does.
    let bad = tmp.path().join("bad.json");
    let state = serde_json::json!({"X": home, "Xdot": vec![1.0; n]});
    std::fs::write(&bad, state.to_string()).unwrap();
    let bad = bad.to_str().unwrap();
    let (ok, _, stderr) = rbss(&["linearize", "--model", "five_bar", "--state", bad]);
    assert!(!ok);
    assert!(stderr.contains("not consistent"), "{stderr}");
    // ... and accepted after projection.
    let (ok, stdout, stderr) = rbss(&[
        "linearize",
        "--model",
        "five_bar",
        "--state",
        bad,
        "--project",
    ]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(v["projected"][1].as_f64().unwrap() > 0.1);
    let (ok, _, stderr) = rbss(&[
        "linearize",
        "--model",
        "five_bar",
        "--state",
        bad,
        "--coordinates",
        "platform",
    ]);
    assert!(!ok);
    assert!(stderr.contains("platform"), "{stderr}");
}

/// `rbss id-derivatives` at a moving state of `model` with the acceleration `xddot`: the JSON's
/// numbers are the runtime's `inverse_dynamics_derivatives` (exactly, after the JSON round
/// trip) and match central differences of the runtime's `inverse_dynamics` (relative to each
/// matrix's largest entry, <= 1e-6); returns the worst relative difference.
fn check_id<K: rbss_runtime::DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    rates: &[f64],
    xddot: &[f64; N],
) -> f64 {
    let tmp = tempfile::tempdir().unwrap();
    let mut data = Data::new(model);
    inverse_velocity(model, &mut data, rates).unwrap();
    data.xddot = *xddot;
    let (x, xdot) = (data.x, data.xdot);
    let motion =
        serde_json::json!({"X": x.to_vec(), "Xdot": xdot.to_vec(), "Xddot": xddot.to_vec()});
    let path = tmp.path().join("motion.json");
    std::fs::write(&path, motion.to_string()).unwrap();
    let (ok, stdout, stderr) = rbss(&[
        "id-derivatives",
        "--model",
        name,
        "--state",
        path.to_str().unwrap(),
    ]);
    assert!(ok, "rbss id-derivatives {name} failed: {stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("stdout is JSON");
    let mut d = InverseDynamicsDerivatives::new();
    inverse_dynamics_derivatives(model, &mut data, &mut d, None).unwrap();
    let k = model.structure().actuated.len();
    let vector = |what: &str| -> Vec<f64> {
        v[what]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    assert_eq!(vector("U"), data.u[..k].to_vec());
    assert_eq!(vector("lambda"), data.lambda.to_vec());
    assert_eq!(v["method"], "block_elimination", "{name}");
    let got_u = [
        matrix(&v, "dU_dX"),
        matrix(&v, "dU_dXdot"),
        matrix(&v, "dU_dXddot"),
    ];
    let got_l = [
        matrix(&v, "dlambda_dX"),
        matrix(&v, "dlambda_dXdot"),
        matrix(&v, "dlambda_dXddot"),
    ];
    let want_u = [&d.du_dx, &d.du_dxdot, &d.du_dxddot];
    let want_l = [&d.dlambda_dx, &d.dlambda_dxdot, &d.dlambda_dxddot];
    for w in 0..3 {
        assert_eq!((got_u[w].len(), got_u[w][0].len()), (k, N));
        assert_eq!(got_l[w].len(), M);
        for j in 0..N {
            for i in 0..k {
                assert_eq!(
                    got_u[w][i][j],
                    want_u[w][(i, j)],
                    "{name} dU {w} ({i}, {j})"
                );
            }
            for i in 0..M {
                assert_eq!(
                    got_l[w][i][j],
                    want_l[w][(i, j)],
                    "{name} dlambda {w} ({i}, {j})"
                );
            }
        }
    }
    // Central differences of inverse dynamics, a step per entry.
    let id = |p: &[[f64; N]; 3]| {
        let mut e = Data::new(model);
        (e.x, e.xdot, e.xddot) = (p[0], p[1], p[2]);
        inverse_dynamics(model, &mut e, None).unwrap();
        (e.u, e.lambda)
    };
    let mut worst = 0.0_f64;
    for w in 0..3 {
        let (mut num_u, mut num_l) = (vec![vec![0.0; N]; k], vec![vec![0.0; N]; M]);
        for j in 0..N {
            let base = [x, xdot, *xddot];
            let h = f64::EPSILON.cbrt() * base[w][j].abs().max(1.0);
            let (mut p, mut q) = (base, base);
            p[w][j] += h;
            q[w][j] -= h;
            let ((up, lp), (uq, lq)) = (id(&p), id(&q));
            let step = p[w][j] - q[w][j];
            for i in 0..k {
                num_u[i][j] = (up[i] - uq[i]) / step;
            }
            for i in 0..M {
                num_l[i][j] = (lp[i] - lq[i]) / step;
            }
        }
        for (got, num) in [(&got_u[w], &num_u), (&got_l[w], &num_l)] {
            let scale = num.iter().flatten().fold(0.0_f64, |m, e| m.max(e.abs()));
            if scale == 0.0 {
                continue;
            }
            for (g, n) in got.iter().flatten().zip(num.iter().flatten()) {
                worst = worst.max((g - n).abs() / scale);
            }
        }
    }
    assert!(
        worst <= 1e-6,
        "{name}: against central differences {worst:e}"
    );
    worst
}

#[test]
fn id_derivatives_match_the_runtime_and_central_differences() {
    let xddot: [f64; five_bar::N] = std::array::from_fn(|i| 0.4 - 0.15 * i as f64);
    let w5 = check_id(
        "five_bar",
        &Model::new(five_bar::FiveBar::default()),
        &[0.1, -0.2],
        &xddot,
    );
    let xddot: [f64; stewart_6ups::N] = std::array::from_fn(|i| 0.2 * ((i as f64) * 0.7).sin());
    let w6 = check_id(
        "stewart_6ups",
        &Model::new(stewart_6ups::Stewart6Ups::default()),
        &[0.01, -0.02, 0.03, 0.01, 0.02, -0.01],
        &xddot,
    );
    eprintln!("id-derivatives vs central differences: five_bar {w5:.1e}, stewart_6ups {w6:.1e}");
}

#[test]
fn id_derivatives_refusals() {
    let tmp = tempfile::tempdir().unwrap();
    let home: Vec<f64> = five_bar::STRUCTURE.home.to_vec();
    let n = home.len();
    let write = |name: &str, v: serde_json::Value| {
        let p = tmp.path().join(name);
        std::fs::write(&p, v.to_string()).unwrap();
        p.to_str().unwrap().to_string()
    };
    let run = |path: &str, project: bool| {
        let mut args = vec!["id-derivatives", "--model", "five_bar", "--state", path];
        if project {
            args.push("--project");
        }
        rbss(&args)
    };
    // No acceleration: the file names what is missing.
    let p = write(
        "no_xddot.json",
        serde_json::json!({"X": home, "Xdot": vec![0.0; n]}),
    );
    let (ok, _, stderr) = run(&p, false);
    assert!(!ok && stderr.contains("Xddot"), "{stderr}");
    // A wrong length, a U that belongs to `rbss fd`'s file.
    let p = write(
        "short.json",
        serde_json::json!({"X": home, "Xdot": vec![0.0; n], "Xddot": vec![0.0; n - 1]}),
    );
    let (ok, _, stderr) = run(&p, false);
    assert!(
        !ok && stderr.contains(&format!("\"Xddot\" has {} values", n - 1)),
        "{stderr}"
    );
    let p = write(
        "with_u.json",
        serde_json::json!({"X": home, "Xdot": vec![0.0; n], "Xddot": vec![0.0; n], "U": [1.0, 2.0]}),
    );
    let (ok, _, stderr) = run(&p, false);
    assert!(!ok && stderr.contains("unknown field `U`"), "{stderr}");
    // An inconsistent velocity: refused as by `rbss fd`, accepted after projection.
    let p = write(
        "bad.json",
        serde_json::json!({"X": home, "Xdot": vec![1.0; n], "Xddot": vec![0.0; n]}),
    );
    let (ok, _, stderr) = run(&p, false);
    assert!(!ok && stderr.contains("not consistent"), "{stderr}");
    let (ok, stdout, stderr) = run(&p, true);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(v["projected"][1].as_f64().unwrap() > 0.1);
}
