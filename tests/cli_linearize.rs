//! `rbss linearize`: the JSON against the runtime's `linearize` in the same process (the same
//! numbers after the JSON round trip), `A`'s and `B`'s layout, both choices of coordinates, and
//! the refusals (an inconsistent state, a bad `--coordinates`).

// The checks compare a JSON matrix (rows of rows) with nalgebra's entry by entry: index loops
// over both are the plain form.
#![allow(clippy::needless_range_loop)]

mod common;

use common::rbss;
use rbss_runtime::{Coordinates, Data, Linearization, Model, inverse_velocity, linearize};

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
fn case<K: rbss_runtime::Dynamics<N, M>, const N: usize, const M: usize>(
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

fn check<K: rbss_runtime::Dynamics<N, M>, const N: usize, const M: usize>(
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
