//! Pose steps (`rpy`, `quat`, `axis_angle`, `pose`, `inverse`, `[frames]`), the functions of
//! the expression language that came with them (`atan2 asin acos hypot abs`), and constant
//! folding.
//!
//! - The UR5 written with pose steps derives the same kernels as models/ur5.toml (f, G,
//!   gamma, M, psi at random states, to rounding), and written with exact pose steps the same
//!   operation counts.
//! - `rpy`, `quat` and `axis_angle` give the rotation matrices computed here independently
//!   (the product of elementary rotations, the quaternion's action `q v q*`, the matrix
//!   exponential of the axis's skew matrix by its series).
//! - The new functions equal std's and fold exactly where they can (`atan2(1, 1)` is `pi / 4`).

use rbss_codegen::derive::{Derivation, derive};
use rbss_codegen::graph::{Graph, Id, Node, Rat};
use rbss_codegen::model::Model;
use rbss_codegen::parse::{parse_model, parse_model_with_warnings};

fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).unwrap()
}

fn model(source: &str) -> Model {
    parse_model("test.toml", source).unwrap_or_else(|e| panic!("{}", e.render()))
}

fn derived(m: &Model) -> Derivation {
    derive(m, true, &vec![false; m.parameters.len()], &mut |_| {})
        .unwrap_or_else(|e| panic!("{e:?}"))
}

/// Replaces `from` (which must occur) with `to`.
fn edit(source: &str, from: &str, to: &str) -> String {
    assert!(source.contains(from), "`{from}` not in the model");
    source.replacen(from, to, 1)
}

/// The UR5 with its constant offsets written as pose steps, a named frame, an inverse chain
/// and an absolute pose undone and done again; `general` adds a cancelling pair of rotations
/// about a general axis (inexact).
fn ur5_with_poses(general: bool) -> String {
    let s = read("models/ur5.toml");
    let s = edit(
        &s,
        "[[body]]\nname = \"link1\"",
        "[frames]\n# Rx(pi / 2) after Tz(d4), as a quaternion with 7 digits (normalised exactly).\n\
         wrist1 = [{ pose = { xyz = [0, 0, \"d4\"], quat = [0.7071068, 0.7071068, 0, 0] } }]\n\
         # An absolute pose, SDF style: undone, then done again (nothing, folded exactly).\n\
         sdf = [{ pose = { xyz = [0.1, -0.2, 0.3], rpy = [0.3, 0.2, 0.1] } }]\n\n\
         [[body]]\nname = \"link1\"",
    );
    let s = edit(
        &s,
        r#"["Rz(q1)", "Tz(d1)", "Rx(pi / 2)"]"#,
        r#"["Rz(q1)", { pose = { xyz = [0, 0, "d1"], rpy = [90, 0, 0], unit = "deg" } }]"#,
    );
    let link2 = if general {
        r#"["Rz(q2)", { axis_angle = [1, -2, 3, 0.7] }, { axis_angle = [1, -2, 3, -0.7] }, "Tx(a2)"]"#
    } else {
        r#"["Rz(q2)", { axis_angle = [0, 0, 2, 0] }, "Tx(a2)"]"#
    };
    let s = edit(&s, r#"["Rz(q2)", "Tx(a2)"]"#, link2);
    let s = edit(
        &s,
        r#"["Rz(q3)", "Tx(a3)"]"#,
        r#"["Rz(q3)", { inverse = [{ frame = "sdf" }] }, { frame = "sdf" }, "Tx(a3)"]"#,
    );
    let s = edit(
        &s,
        r#"["Rz(q4)", "Tz(d4)", "Rx(pi / 2)"]"#,
        r#"["Rz(q4)", { frame = "wrist1" }]"#,
    );
    edit(
        &s,
        r#"["Rz(q5)", "Tz(d5)", "Rx(-pi / 2)"]"#,
        r#"["Rz(q5)", { inverse = [{ rpy = ["pi / 2", 0, 0] }, "Tz(-d5)"] }]"#,
    )
}

/// Every kernel quantity of a derivation at a state: f, G, gamma, M, psi.
fn kernels(d: &Derivation, p: &[f64], x: &[f64], v: &[f64]) -> Vec<f64> {
    let vals = d.graph.eval_all(x, v, p);
    let dy = d.dynamics.as_ref().unwrap();
    let ids: Vec<Id> =
        d.f.iter()
            .chain(d.g.iter().flatten())
            .chain(&d.gamma)
            .chain(dy.mass.iter().flatten())
            .chain(&dy.psi)
            .copied()
            .collect();
    ids.iter().map(|&i| vals[i as usize]).collect()
}

/// A deterministic pseudo-random sequence in [-1, 1) (xorshift).
fn random(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

#[test]
fn ur5_written_with_pose_steps_has_the_same_kernels() {
    let plain = model(&read("models/ur5.toml"));
    let a = derived(&plain);
    let p: Vec<f64> = plain.parameters.iter().map(|q| q.value).collect();
    for general in [false, true] {
        let posed = model(&ur5_with_poses(general));
        assert_eq!(posed.coordinates.len(), plain.coordinates.len());
        let b = derived(&posed);
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut worst = 0.0f64;
        for _ in 0..16 {
            let x: Vec<f64> = (0..12).map(|_| 3.0 * random(&mut seed)).collect();
            let v: Vec<f64> = (0..12).map(|_| 2.0 * random(&mut seed)).collect();
            let (ka, kb) = (kernels(&a, &p, &x, &v), kernels(&b, &p, &x, &v));
            assert_eq!(ka.len(), kb.len());
            for (i, (u, w)) in ka.iter().zip(&kb).enumerate() {
                let err = (u - w).abs() / (1.0 + u.abs());
                worst = worst.max(err);
                assert!(err < 1e-12, "general {general}: entry {i}: {u} vs {w}");
            }
        }
        // Exact pose steps give the same numbers to the bit; the inexact general rotations
        // differ by rounding only.
        assert_eq!(worst > 0.0, general, "general {general}: worst {worst:e}");
    }
}

#[test]
fn exact_pose_steps_cost_what_the_elementary_steps_cost() {
    let report = |src: &str| {
        rbss_codegen::generate("models/ur5.toml", src, &Default::default(), &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"))
            .report
    };
    let plain = report(&read("models/ur5.toml"));
    let posed = report(&ur5_with_poses(false));
    for (a, b) in plain.kernels.iter().zip(&posed.kernels) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.ops, b.ops, "{}: {} vs {}", a.name, a.ops, b.ops);
    }
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn elementary(axis: usize, t: f64) -> [[f64; 3]; 3] {
    let (s, c) = t.sin_cos();
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// The world rotation of every probe body appended to the five-bar (massless frames).
fn probe_rotations(probes: &[&str]) -> Vec<[[f64; 3]; 3]> {
    let mut src = read("models/five_bar.toml");
    for (k, t) in probes.iter().enumerate() {
        src.push_str(&format!(
            "\n[[body]]\nname = \"probe{k}\"\ntransforms = [{t}]\n"
        ));
    }
    let (m, _warnings) = parse_model_with_warnings("probe.toml", &src);
    let m = m.unwrap_or_else(|e| panic!("{}", e.render()));
    let d = derive(&m, false, &vec![false; m.parameters.len()], &mut |_| {}).unwrap();
    let p: Vec<f64> = m.parameters.iter().map(|q| q.value).collect();
    let n = m.coordinates.len();
    let vals = d.graph.eval_all(&vec![0.0; n], &vec![0.0; n], &p);
    let first = m.bodies.len() - probes.len();
    d.frames[first..]
        .iter()
        .map(|f| std::array::from_fn(|i| std::array::from_fn(|j| vals[f.r[i][j] as usize])))
        .collect()
}

fn assert_close(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3], what: &str) {
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (a[i][j] - b[i][j]).abs() < 1e-14,
                "{what}: R[{i}][{j}] = {} vs {}",
                a[i][j],
                b[i][j]
            );
        }
    }
}

#[test]
fn rpy_quat_and_axis_angle_match_independent_rotations() {
    let (r, p, y) = (0.3, -0.7, 1.1);
    let q = [0.5, 0.1, -0.3, 0.8]; // norm sqrt(0.99): normalised (with a warning)
    let axis = [0.2, -0.5, 0.8];
    let angle = 1.3;
    let got = probe_rotations(&[
        &format!("{{ rpy = [{r}, {p}, {y}] }}"),
        &format!("{{ rpy = [{}, {}, {}], unit = \"deg\" }}", 30, -45, 120),
        &format!("{{ quat = [{}, {}, {}, {}] }}", q[0], q[1], q[2], q[3]),
        &format!(
            "{{ axis_angle = [{}, {}, {}, {angle}] }}",
            axis[0], axis[1], axis[2]
        ),
        "{ pose = { xyz = [1, 2, 3], axis_angle = [0, -1, 0, 0.4] } }",
        &format!("{{ rpy = [{r}, {p}, {y}] }}, {{ inverse = [{{ rpy = [{r}, {p}, {y}] }}] }}"),
    ]);
    // URDF: R = Rz(y) Ry(p) Rx(r).
    let rpy = |r: f64, p: f64, y: f64| {
        mat_mul(
            &mat_mul(&elementary(2, y), &elementary(1, p)),
            &elementary(0, r),
        )
    };
    assert_close(&got[0], &rpy(r, p, y), "rpy");
    let d = std::f64::consts::PI / 180.0;
    assert_close(
        &got[1],
        &rpy(30.0 * d, -45.0 * d, 120.0 * d),
        "rpy in degrees",
    );
    // The quaternion's action on the basis vectors: column j of R is q e_j q*.
    let nq = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let u = q.map(|v| v / nq);
    let hamilton = |a: [f64; 4], b: [f64; 4]| {
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    };
    let conj = [u[0], -u[1], -u[2], -u[3]];
    let mut want = [[0.0; 3]; 3];
    for j in 0..3 {
        let mut e = [0.0; 4];
        e[j + 1] = 1.0;
        let col = hamilton(hamilton(u, e), conj);
        for i in 0..3 {
            want[i][j] = col[i + 1];
        }
    }
    assert_close(&got[2], &want, "quat");
    // exp(angle K), K the skew matrix of the unit axis, by its series.
    let expm = |axis: [f64; 3], angle: f64| {
        let n = axis.iter().map(|v| v * v).sum::<f64>().sqrt();
        let a = axis.map(|v| v * angle / n);
        let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
        let mut sum = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut term = sum;
        for m in 1..40 {
            term = mat_mul(&term, &k).map(|row| row.map(|v| v / m as f64));
            for i in 0..3 {
                for j in 0..3 {
                    sum[i][j] += term[i][j];
                }
            }
        }
        sum
    };
    assert_close(&got[3], &expm(axis, angle), "axis_angle");
    assert_close(&got[4], &elementary(1, -0.4), "axis_angle about -y");
    let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    assert_close(&got[5], &identity, "rpy then its inverse");
}

#[test]
fn a_quaternion_far_from_unit_is_normalised_with_a_warning() {
    let mut src = read("models/five_bar.toml");
    src.push_str("\n[[body]]\nname = \"probe\"\ntransforms = [{ quat = [2, 0, 0, 0] }]\n");
    let (m, warnings) = parse_model_with_warnings("probe.toml", &src);
    assert!(m.is_ok());
    let text = warnings.render_warnings();
    assert!(
        text.contains("has norm 2, not 1: it is normalised"),
        "{text}"
    );
    assert!(text.contains("probe.toml:"), "{text}");
    let mut unit = read("models/five_bar.toml");
    unit.push_str(
        "\n[[body]]\nname = \"probe\"\ntransforms = [{ quat = [0.7071068, 0, 0.7071068, 0] }]\n",
    );
    let (_, warnings) = parse_model_with_warnings("probe.toml", &unit);
    assert!(!warnings.render_warnings().contains("quaternion"));
}

/// The parameters' values of a five-bar with `extra` appended to its `[parameters]`.
fn with_parameters(extra: &str) -> Result<Model, String> {
    let src = edit(
        &read("models/five_bar.toml"),
        "[parameters]\n",
        &format!("[parameters]\n{extra}\n"),
    );
    parse_model("funcs.toml", &src).map_err(|e| e.render())
}

#[test]
fn new_functions_equal_std_and_fold_exactly() {
    let m = with_parameters(
        "fa = \"atan2(1, -2)\"\nfb = \"asin(0.3)\"\nfc = \"acos(-0.2)\"\nfd = \"hypot(0.3, 0.4)\"\n\
         fe = \"abs(-2.5)\"\nff = \"exp(0.5) + ln(3)\"",
    )
    .unwrap();
    let value = |name: &str| m.parameters.iter().find(|p| p.name == name).unwrap().value;
    assert_eq!(value("fa"), 1f64.atan2(-2.0));
    assert_eq!(value("fb"), 0.3f64.asin());
    assert_eq!(value("fc"), (-0.2f64).acos());
    assert_eq!(value("fd"), 0.5);
    assert_eq!(value("fe"), 2.5);
    assert_eq!(value("ff"), 0.5f64.exp() + 3f64.ln());
    // Exact folding in the derivation's graph.
    let fold = |src: &str| {
        let m = with_parameters(&format!("k = \"{src}\"")).unwrap();
        let mut g = Graph::new(m.coordinates.len());
        let k = m.parameters.iter().find(|p| p.name == "k").unwrap();
        let id = rbss_codegen::derive::expr(&mut g, &k.expr, &m, &vec![true; m.parameters.len()]);
        (g.node(id), g.eval(id, &[], &[], &[]))
    };
    let pi_times = |num, den| {
        let mut g = Graph::new(0);
        let c = g.num(Rat::new(num, den).unwrap());
        let pi = g.pi();
        let id = g.mul(c, pi);
        g.eval(id, &[], &[], &[])
    };
    for (src, num, den) in [
        ("atan2(1, 1)", 1, 4),
        ("atan2(-2, -2)", -3, 4),
        ("atan2(0, -3)", 1, 1),
        ("atan2(-5, 0)", -1, 2),
        ("asin(1 / 2)", 1, 6),
        ("asin(-1)", -1, 2),
        ("acos(-1 / 2)", 2, 3),
        ("acos(1)", 0, 1),
    ] {
        let (node, v) = fold(src);
        assert!(
            !matches!(node, Node::Float(_)),
            "{src} is not exact: {node:?}"
        );
        assert_eq!(v, pi_times(num, den), "{src}");
    }
    assert_eq!(fold("hypot(3, 4)").0, Node::Num(Rat::int(5)));
    assert_eq!(fold("abs(-7 / 2)").0, Node::Num(Rat::new(7, 2).unwrap()));
    assert!(matches!(fold("atan2(1, 2)").0, Node::Float(_)));
}

#[test]
fn domain_errors_are_located() {
    let cases = [
        (
            "fa = \"1 + asin(2)\"",
            "the argument of `asin` must lie in [-1, 1], found 2",
            11,
        ),
        (
            "fa = \"acos(-1.5)\"",
            "the argument of `acos` must lie in [-1, 1], found -1.5",
            7,
        ),
        ("fa = \"atan2(0, 0)\"", "`atan2(0, 0)` has no angle", 7),
        ("fa = \"atan2(1)\"", "`atan2` takes 2 arguments, found 1", 7),
    ];
    for (line, message, col) in cases {
        let err = with_parameters(line).unwrap_err();
        assert!(err.contains(message), "{line}: {err}");
        let at = format!("funcs.toml:{}:{col}", find_line(line));
        assert!(err.contains(&at), "{line}: want {at} in {err}");
    }
    let coord = read("models/five_bar.toml").replacen("\"Tx(-b)\"", "\"Tx(-b * abs(th1))\"", 1);
    let err = parse_model("c.toml", &coord).unwrap_err().render();
    assert!(err.contains("`abs` takes constant arguments"), "{err}");
}

/// The line of `[parameters]`'s first entry in the edited five-bar (the inserted one).
fn find_line(_inserted: &str) -> usize {
    read("models/five_bar.toml")
        .lines()
        .position(|l| l == "[parameters]")
        .unwrap()
        + 2
}
