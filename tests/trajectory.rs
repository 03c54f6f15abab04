//! User trajectories: expressions (exact derivatives), samples (not-a-knot spline), their error
//! messages, and `rbss inverse-dynamics --trajectory` on both robots.

use std::path::{Path, PathBuf};
use std::process::Command;

use rbss::paper::{OMEGA, traek_p};
use rbss::trajectory::{Expressions, Samples, Trajectory, load};

const STEWART: &[&str] = &["x", "y", "z", "rotx", "roty", "rotz"];
const FIVE_BAR: &[&str] = &["x", "y"];

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/trajectories")
        .join(name)
}

/// A scratch directory of the test's own, removed when dropped.
fn temp_dir(tag: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("rbss-traj-{tag}-"))
        .tempdir()
        .unwrap()
}

fn rbss(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

fn eval(tr: &dyn Trajectory, t: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let k = tr.dim();
    let (mut p, mut v, mut a) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    tr.eval(t, &mut p, &mut v, &mut a);
    (p, v, a)
}

/// Every operator and function, against central differences: the first derivative against
/// `(f(t+h) - f(t-h)) / 2h` and the second against both the difference of the first
/// derivatives and `(f(t+h) - 2 f(t) + f(t-h)) / h²`.
#[test]
fn expression_derivatives_match_central_differences() {
    let exprs = [
        "sin(t)^2 + cos(3*t)/(2 + t^2)",
        "-exp(-t)*ln(1 + t) + sqrt(1 + t^2)*tan(0.3*t)",
        "2^t - t^-1.5 + (t + 1)^(t/2)",
        "1/(t - 3) - 4*t^3 + 0.5e1*t + pi",
        "(1 + t)^2.5 - sqrt(t)^3 / exp(sin(2*pi*t))",
    ];
    let names: Vec<String> = (0..exprs.len()).map(|i| format!("e{i}")).collect();
    let toml: String = names
        .iter()
        .zip(exprs)
        .map(|(n, e)| format!("{n} = \"{e}\"\n"))
        .collect();
    let outputs: Vec<&str> = names.iter().map(String::as_str).collect();
    let tr = Expressions::parse("test.toml", &toml, &outputs).unwrap();
    for k in 0..40 {
        let t = 0.2 + 0.035 * k as f64;
        let (p, v, a) = eval(&tr, t);
        let h = 1e-5;
        let (pp, vp, _) = eval(&tr, t + h);
        let (pm, vm, _) = eval(&tr, t - h);
        let h2 = 1e-4;
        let (pp2, _, _) = eval(&tr, t + h2);
        let (pm2, _, _) = eval(&tr, t - h2);
        for i in 0..exprs.len() {
            let scale = 1.0 + p[i].abs() + v[i].abs() + a[i].abs();
            let fd1 = (pp[i] - pm[i]) / (2.0 * h);
            let fd2 = (vp[i] - vm[i]) / (2.0 * h);
            let fd2b = (pp2[i] - 2.0 * p[i] + pm2[i]) / (h2 * h2);
            assert!(
                (fd1 - v[i]).abs() < 1e-8 * scale,
                "{} at t = {t}: d/dt {} vs {fd1}",
                exprs[i],
                v[i]
            );
            assert!(
                (fd2 - a[i]).abs() < 1e-8 * scale,
                "{} at t = {t}: d²/dt² {} vs {fd2}",
                exprs[i],
                a[i]
            );
            assert!(
                (fd2b - a[i]).abs() < 1e-5 * scale,
                "{} at t = {t}: d²/dt² {} vs {fd2b}",
                exprs[i],
                a[i]
            );
        }
    }
}

/// models/trajectories/stewart_6ups.toml is TraekP: pose, velocity and acceleration to 1e-12.
#[test]
fn traek_p_expressions_reproduce_traek_p() {
    let tr = load(&example("stewart_6ups.toml"), STEWART).unwrap();
    let mut worst: f64 = 0.0;
    for k in 0..=400 {
        let t = -0.5 + 3.0 * k as f64 / 400.0;
        let (p, v, a) = eval(tr.as_ref(), t);
        let (pe, ve, ae) = traek_p(t, OMEGA);
        for i in 0..6 {
            worst = worst
                .max((p[i] - pe[i]).abs())
                .max((v[i] - ve[i]).abs())
                .max((a[i] - ae[i]).abs());
        }
    }
    eprintln!("max |expressions - traek_p| = {worst:e}");
    assert!(worst < 1e-12, "max |expressions - traek_p| = {worst:e}");
}

/// The command along stewart_6ups.toml gives TraekP's forces (the default of stewart_6ups).
#[test]
fn traek_p_expressions_give_the_same_forces_via_the_command() {
    let tmp = temp_dir("traek");
    let dir = tmp.path();
    let (a, b) = (dir.join("file.csv"), dir.join("builtin.csv"));
    let file = example("stewart_6ups.toml");
    let common = [
        "inverse-dynamics",
        "--model",
        "stewart_6ups",
        "--samples",
        "41",
    ];
    let (ok, err) = rbss(
        &[
            &common[..],
            &[
                "--trajectory",
                file.to_str().unwrap(),
                "--csv",
                a.to_str().unwrap(),
            ],
        ]
        .concat(),
    );
    assert!(ok, "{err}");
    let (ok, err) = rbss(&[&common[..], &["--csv", b.to_str().unwrap()]].concat());
    assert!(ok, "{err}");
    let ((ha, ra), (hb, rb)) = (read_csv(&a), read_csv(&b));
    assert_eq!(ha, hb);
    assert_eq!(ha.len(), 1 + 6 + 18);
    assert_eq!((ra.len(), rb.len()), (41, 41));
    let mut worst: f64 = 0.0;
    for (x, y) in ra.iter().zip(&rb) {
        for (u, v) in x.iter().zip(y) {
            worst = worst.max((u - v).abs() / (1.0 + v.abs()));
        }
    }
    eprintln!("TraekP: expressions vs built-in, max relative force difference {worst:e}");
    assert!(worst < 1e-9, "max relative force difference {worst:e}");
}

/// A cubic polynomial comes back exactly from samples at uneven times (not-a-knot).
#[test]
fn spline_reproduces_a_cubic() {
    let f = |t: f64| {
        (
            0.3 - 1.2 * t + 0.7 * t * t + 0.45 * t * t * t,
            -1.2 + 1.4 * t + 1.35 * t * t,
            1.4 + 2.7 * t,
        )
    };
    let g = |t: f64| (2.0 - t * t * t, -3.0 * t * t, -6.0 * t);
    let times: Vec<f64> = (0..12)
        .map(|k| 0.25 * k as f64 + 0.04 * ((k * 5) % 3) as f64 - 1.0)
        .collect();
    let mut text = String::from("t, y, x\n");
    for &t in &times {
        text += &format!("{t:?}, {:?}, {:?}\n", g(t).0, f(t).0);
    }
    let tr = Samples::parse("cubic.csv", &text, FIVE_BAR).unwrap();
    assert_eq!(tr.domain(), (times[0], times[11]));
    for k in 0..=300 {
        let t = times[0] + (times[11] - times[0]) * k as f64 / 300.0;
        let (p, v, a) = eval(&tr, t);
        for (i, e) in [f(t), g(t)].into_iter().enumerate() {
            assert!(
                (p[i] - e.0).abs() < 1e-13
                    && (v[i] - e.1).abs() < 1e-12
                    && (a[i] - e.2).abs() < 1e-11,
                "t = {t}, output {i}: ({}, {}, {}) vs {e:?}",
                p[i],
                v[i],
                a[i]
            );
        }
    }
}

/// Max |spline - exact| of position, velocity and acceleration of the figure eight sampled
/// every `h` over one lap, checked on a fine grid.
fn figure_eight_spline_error(h: f64) -> [f64; 3] {
    let exact = load(&example("five_bar.toml"), FIVE_BAR).unwrap();
    let n = (2.0 / h).round() as usize;
    let mut text = String::from("t,x,y\n");
    for k in 0..=n {
        let t = 2.0 * k as f64 / n as f64;
        let (p, _, _) = eval(exact.as_ref(), t);
        text += &format!("{t:?},{:?},{:?}\n", p[0], p[1]);
    }
    let tr = Samples::parse("eight.csv", &text, FIVE_BAR).unwrap();
    let mut err = [0.0f64; 3];
    for k in 0..=4000 {
        let t = 2.0 * k as f64 / 4000.0;
        let (p, v, a) = eval(&tr, t);
        let (pe, ve, ae) = eval(exact.as_ref(), t);
        for i in 0..2 {
            err[0] = err[0].max((p[i] - pe[i]).abs());
            err[1] = err[1].max((v[i] - ve[i]).abs());
            err[2] = err[2].max((a[i] - ae[i]).abs());
        }
    }
    err
}

/// The smooth figure eight (|y''| up to 1.2 m/s²) sampled every 20 ms: the spline's
/// acceleration is within 2e-3 m/s² of the exact one over the whole lap, ends included
/// (measured 1.56e-3, 0.13 % of the largest), velocity 1e-5 m/s (8.2e-6), position 5e-8 m
/// (2.7e-8). Halving the spacing divides the acceleration error by 4 (measured 3.99: O(h²))
/// and the position error by at least 16 (measured 22: O(h⁴)).
#[test]
fn spline_accuracy_on_a_smooth_trajectory() {
    let e20 = figure_eight_spline_error(0.02);
    let e10 = figure_eight_spline_error(0.01);
    eprintln!("h = 20 ms: {e20:?}; h = 10 ms: {e10:?}");
    assert!(e20[2] < 2e-3, "acceleration error {:e}", e20[2]);
    assert!(e20[1] < 1e-5, "velocity error {:e}", e20[1]);
    assert!(e20[0] < 5e-8, "position error {:e}", e20[0]);
    let ratio_a = e20[2] / e10[2];
    let ratio_p = e20[0] / e10[0];
    assert!(
        ratio_a > 3.5 && ratio_a < 4.5,
        "acceleration ratio {ratio_a}"
    );
    assert!(ratio_p > 14.0, "position ratio {ratio_p}");
}

/// `_dot` / `_ddot` columns replace the spline's derivatives.
#[test]
fn derivative_columns_are_used_when_present() {
    let text = "t,x,y,x_dot,y_ddot\n0,0,0,7,-1\n1,1,1,7,-1\n2,4,4,7,-1\n3,9,9,7,-1\n";
    let tr = Samples::parse("d.csv", text, FIVE_BAR).unwrap();
    let (p, v, a) = eval(&tr, 1.5);
    assert!((p[0] - 2.25).abs() < 1e-14 && (p[1] - 2.25).abs() < 1e-14);
    assert_eq!((v[0], a[0]), (7.0, 0.0), "x: from x_dot and its derivative");
    assert!((v[1] - 3.0).abs() < 1e-14, "y: spline velocity {}", v[1]);
    assert_eq!(a[1], -1.0, "y: from y_ddot");
}

#[test]
fn bad_sample_files_name_the_file_and_line() {
    let cases: &[(&str, &str)] = &[
        ("", "traj.csv: empty: expected a header `t,x,y`"),
        ("# only a comment\n", "traj.csv: empty"),
        (
            "time,x,y\n0,0,0\n",
            "traj.csv:1: header: the first column must be `t`",
        ),
        ("t,x\n0,0\n1,1\n", "traj.csv:1: header: no column for `y`"),
        (
            "t,x,y,z\n",
            "traj.csv:1: header: column 4: `z` is not an output",
        ),
        (
            "t,x,y,x\n",
            "traj.csv:1: header: column 4: `x` appears twice",
        ),
        (
            "# c\nt,x,y\n0,0,0\n\n1,1,x1\n",
            "traj.csv:5: column `y`: `x1` is not a number",
        ),
        (
            "t,x,y\n0,0,0\n1,1\n",
            "traj.csv:3: expected 3 fields (t,x,y), found 2",
        ),
        (
            "t,x,y\n0,0,0\n1,inf,0\n",
            "traj.csv:3: column `x`: `inf` is not a finite",
        ),
        (
            "t,x,y\n0,0,0\n1,1,1\n1,2,2\n",
            "traj.csv:4: column `t`: 1 is not greater than 1 (line 3)",
        ),
        ("t,x,y\n0,0,0\n", "traj.csv: 1 sample row(s): at least 2"),
    ];
    for (text, want) in cases {
        let e = Samples::parse("traj.csv", text, FIVE_BAR).unwrap_err();
        assert!(e.contains(want), "{text:?}:\n  got  {e}\n  want {want}");
    }
}

#[test]
fn bad_expression_files_name_the_file_line_and_column() {
    let cases: &[(&str, &str)] = &[
        ("x = \"t\"\n", "traj.toml: no expression for `y`"),
        (
            "x = \"t\"\ny = \"0.1*cos(pi*s)\"\n",
            "traj.toml:2:17: `y`: unknown name `s`",
        ),
        (
            "x = \"t\"\n  y = \"(1 + t\"\n",
            "traj.toml:2:8: `y`: unclosed `(`",
        ),
        (
            "x = \"t\"\ny = 'sin t'\n",
            "traj.toml:2:10: `y`: expected `(` after `sin`",
        ),
        (
            "x = \"2 t\"\ny = \"t\"\n",
            "traj.toml:1:8: `x`: expected an operator",
        ),
        (
            "x = \"t\"\ny = \"\"\n",
            "traj.toml:2:5: `y`: empty expression",
        ),
        (
            "x = \"t\"\ny = \"t\"\nz = \"t\"\n",
            "traj.toml:3:1: `z` is not an output",
        ),
        (
            "x = \"t\"\ny = [1, 2]\n",
            "traj.toml:2:5: `y`: expected an expression in t",
        ),
        ("x = \"t\"\ny = \"t\n", "traj.toml:2:"),
        ("x = \"t\"\nx = \"t\"\n", "traj.toml:2:"),
        ("x = 0.5\ny = 3\n", ""),
    ];
    for (text, want) in cases {
        match Expressions::parse("traj.toml", text, FIVE_BAR) {
            Err(e) => assert!(
                !want.is_empty() && e.contains(want),
                "{text:?}:\n  got  {e}\n  want {want}"
            ),
            Ok(tr) => {
                assert!(want.is_empty(), "{text:?} parsed, want {want}");
                assert_eq!(eval(&tr, 1.0).0, vec![0.5, 3.0]);
            }
        }
    }
    // A file that does not exist, and an unknown extension.
    let e = load(Path::new("no/such/traj.toml"), FIVE_BAR)
        .err()
        .unwrap();
    assert!(e.starts_with("no/such/traj.toml: cannot read"), "{e}");
    let e = load(Path::new("traj.json"), FIVE_BAR).err().unwrap();
    assert!(e.contains("traj.json: unknown trajectory format"), "{e}");
}

/// The five-bar along the example samples file, via the command: the header, one row per
/// time, and the forces of the exact motion (the expressions file) to the spline's accuracy.
#[test]
fn five_bar_inverse_dynamics_from_samples_via_the_command() {
    let tmp = temp_dir("five");
    let dir = tmp.path();
    let (a, b) = (dir.join("samples.csv"), dir.join("exact.csv"));
    let samples = example("five_bar_figure_eight.csv");
    let exact = example("five_bar.toml");
    for (traj, out) in [(&samples, &a), (&exact, &b)] {
        let (ok, err) = rbss(&[
            "inverse-dynamics",
            "--model",
            "five_bar",
            "--trajectory",
            traj.to_str().unwrap(),
            "--samples",
            "201",
            "--csv",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
    }
    let ((ha, ra), (hb, rb)) = (read_csv(&a), read_csv(&b));
    assert_eq!(
        ha.join(","),
        "t,U1,U2,lambda1,lambda2,lambda3,lambda4",
        "k = 2 actuated, m = 4"
    );
    assert_eq!(ha, hb);
    assert_eq!((ra.len(), rb.len()), (201, 201));
    assert_eq!(
        (ra[0][0], ra[200][0]),
        (0.0, 2.0),
        "the samples' range by default"
    );
    let max_u = rb
        .iter()
        .flat_map(|r| [r[1].abs(), r[2].abs()])
        .fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for (x, y) in ra.iter().zip(&rb) {
        worst = worst.max((x[1] - y[1]).abs()).max((x[2] - y[2]).abs());
    }
    eprintln!("five-bar: max |U| = {max_u:e} N m, max |U spline - U exact| = {worst:e} N m");
    // Measured: max |U| 0.71 N m, spline (20 ms samples) vs exact 8.3e-5 N m.
    assert!(max_u > 0.1, "max |U| = {max_u}");
    assert!(
        worst < 3e-4 * max_u,
        "max |U spline - U exact| = {worst:e} N m"
    );

    // Outside the samples, without a trajectory, with --omega and a trajectory: clear errors.
    let (ok, err) = rbss(&[
        "inverse-dynamics",
        "--model",
        "five_bar",
        "--trajectory",
        samples.to_str().unwrap(),
        "--t-end",
        "3",
        "--csv",
        a.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("which cover [0, 2]"), "{err}");
    let (ok, err) = rbss(&[
        "inverse-dynamics",
        "--model",
        "five_bar",
        "--csv",
        a.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("--trajectory") && err.contains("TraekP"),
        "{err}"
    );
    let (ok, err) = rbss(&[
        "inverse-dynamics",
        "--model",
        "stewart_6ups",
        "--trajectory",
        samples.to_str().unwrap(),
        "--csv",
        a.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("header: no column for `z`"), "{err}");
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "x = \"0.05*sin(pi*t)\"\ny = \"0.3 + 0.03*sin(2*pi*t\"\n",
    )
    .unwrap();
    let (ok, err) = rbss(&[
        "inverse-dynamics",
        "--model",
        "five_bar",
        "--trajectory",
        bad.to_str().unwrap(),
        "--csv",
        a.to_str().unwrap(),
    ]);
    let want = format!("{}:2:20: `y`: unclosed `(`", bad.display());
    assert!(!ok && err.contains(&want), "{err}\nwant {want}");
}
