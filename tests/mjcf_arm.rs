//! A fixed-base arm in MJCF, imported as it comes: six bodies written by this test (hinges
//! about x, y, z and a general axis, with anchors off the body origins, a slide joint, body
//! orientations as quaternions, inertial frames turned by their own quaternions), a massless
//! tool body at the end, and model files of one and two lines (`mjcf = "arm5.xml"`, then
//! `robot.outputs = [{ frame = "tool", pose = "xyz-rpy" }]`).
//!
//! The oracle is the test's own: MuJoCo's kinematic conventions by hand (a body at `pos`,
//! `quat` in its parent, its joint about `axis` through the anchor `pos`, a slide along
//! `axis`), the tool frame's pose from them, and the recursive Newton–Euler algorithm for the
//! joint forces of a motion, whose columns give `M` and whose zero-acceleration value gives the
//! bias: `rbss fd`'s accelerations must solve `M q̈ = u - bias` (no finite differences, so to
//! 1e-9), `rbss fk` must give the tool's pose and `rbss ik` joints whose tool is at the pose.

// The oracle is dense linear algebra (a Gaussian elimination, M by columns): index loops read
// as the formulas.
#![allow(clippy::needless_range_loop)]

use std::path::Path;
use std::process::Command;

#[derive(Clone, Copy, PartialEq)]
enum Joint {
    Hinge,
    Slide,
}

/// One body of the chain: its `pos` and `quat` in the parent, its joint (type, anchor `pos`,
/// `axis`, in the body's frame), its `<inertial>` (`pos`, `quat`, `mass`, `diaginertia`).
struct Body {
    pos: [f64; 3],
    quat: [f64; 4],
    joint: Joint,
    anchor: [f64; 3],
    axis: [f64; 3],
    com: [f64; 3],
    com_quat: [f64; 4],
    mass: f64,
    inertia: [f64; 3],
}

/// A unit quaternion (w, x, y, z) of the turn by `angle` about `axis` (normalised here).
fn quat(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let n = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
    let (s, c) = (angle / 2.0).sin_cos();
    [c, s * axis[0] / n, s * axis[1] / n, s * axis[2] / n]
}

fn bodies() -> Vec<Body> {
    vec![
        Body {
            pos: [0.0, 0.0, 0.15],
            quat: [1.0, 0.0, 0.0, 0.0],
            joint: Joint::Hinge,
            anchor: [0.0, 0.0, 0.0],
            axis: [0.0, 0.0, 1.0],
            com: [0.01, 0.02, 0.08],
            com_quat: quat([0.0, 0.0, 1.0], 0.3),
            mass: 3.2,
            inertia: [0.03, 0.028, 0.012],
        },
        Body {
            pos: [0.0, 0.04, 0.2],
            quat: quat([1.0, 0.0, 0.0], 0.4),
            joint: Joint::Hinge,
            anchor: [0.0, 0.0, -0.03],
            axis: [0.0, 1.0, 0.0],
            com: [0.15, 0.0, 0.02],
            com_quat: quat([1.0, 2.0, -1.0], 0.5),
            mass: 2.4,
            inertia: [0.004, 0.021, 0.02],
        },
        Body {
            pos: [0.35, 0.0, 0.0],
            quat: quat([0.0, 0.0, 1.0], -0.25),
            joint: Joint::Slide,
            anchor: [0.0, 0.0, 0.0],
            axis: [1.0, 0.0, 0.0],
            com: [0.05, 0.01, 0.0],
            com_quat: [1.0, 0.0, 0.0, 0.0],
            mass: 1.1,
            inertia: [0.001, 0.004, 0.0045],
        },
        Body {
            pos: [0.12, 0.0, 0.03],
            quat: quat([0.0, 1.0, 1.0], 0.6),
            joint: Joint::Hinge,
            anchor: [0.02, 0.0, 0.0],
            axis: [1.0, 0.0, 0.0],
            com: [0.04, -0.01, 0.01],
            com_quat: quat([0.0, 1.0, 0.0], -0.2),
            mass: 0.8,
            inertia: [0.0009, 0.0012, 0.001],
        },
        Body {
            pos: [0.09, 0.0, 0.0],
            quat: [1.0, 0.0, 0.0, 0.0],
            joint: Joint::Hinge,
            anchor: [0.0, 0.01, 0.0],
            axis: [0.3, 0.5, 0.8],
            com: [0.02, 0.0, 0.015],
            com_quat: quat([1.0, 1.0, 1.0], 0.7),
            mass: 0.45,
            inertia: [0.0003, 0.00035, 0.0004],
        },
        Body {
            pos: [0.0, 0.0, 0.06],
            quat: quat([1.0, 0.0, 0.0], -0.5),
            joint: Joint::Hinge,
            anchor: [0.0, 0.0, 0.0],
            axis: [0.0, 0.0, 1.0],
            com: [0.0, 0.005, 0.02],
            com_quat: [1.0, 0.0, 0.0, 0.0],
            mass: 0.3,
            inertia: [0.0002, 0.00021, 0.0001],
        },
    ]
}

/// The tool body (no joint, no mass): its `pos` and `quat` in the last body.
const TOOL_POS: [f64; 3] = [0.05, 0.0, 0.07];
const TOOL_AXIS: [f64; 3] = [0.0, 1.0, 0.0];
const TOOL_ANGLE: f64 = 1.2;
const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

fn mjcf() -> String {
    let v = |a: &[f64]| {
        a.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut s = String::from(
        "<mujoco model=\"arm5\">\n  <option gravity=\"0 0 -9.81\"/>\n  <worldbody>\n    \
         <geom type=\"plane\" size=\"1 1 0.1\"/>\n",
    );
    let bodies = bodies();
    for (i, b) in bodies.iter().enumerate() {
        let pad = "  ".repeat(i + 2);
        let kind = match b.joint {
            Joint::Hinge => "hinge",
            Joint::Slide => "slide",
        };
        s += &format!(
            "{pad}<body name=\"link{n}\" pos=\"{}\" quat=\"{}\">\n{pad}  \
             <joint name=\"j{n}\" type=\"{kind}\" pos=\"{}\" axis=\"{}\"/>\n{pad}  \
             <inertial pos=\"{}\" quat=\"{}\" mass=\"{}\" diaginertia=\"{}\"/>\n{pad}  \
             <geom type=\"sphere\" size=\"0.02\" contype=\"0\"/>\n",
            v(&b.pos),
            v(&b.quat),
            v(&b.anchor),
            v(&b.axis),
            v(&b.com),
            v(&b.com_quat),
            b.mass,
            v(&b.inertia),
            n = i + 1,
        );
    }
    let pad = "  ".repeat(bodies.len() + 2);
    s += &format!(
        "{pad}<body name=\"tool\" pos=\"{}\" quat=\"{}\"/>\n",
        v(&TOOL_POS),
        v(&quat(TOOL_AXIS, TOOL_ANGLE))
    );
    for i in (0..bodies.len()).rev() {
        s += &format!("{}</body>\n", "  ".repeat(i + 2));
    }
    s += "  </worldbody>\n  <actuator>\n";
    for i in 0..bodies.len() {
        s += &format!("    <motor joint=\"j{}\"/>\n", i + 1);
    }
    s + "  </actuator>\n</mujoco>\n"
}

type V3 = [f64; 3];
type M3 = [[f64; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(a: &M3, v: &V3) -> V3 {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn add(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] + b[i])
}

fn sub(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] - b[i])
}

fn scale(a: &V3, s: f64) -> V3 {
    a.map(|x| x * s)
}

fn dot(a: &V3, b: &V3) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}

fn cross(a: &V3, b: &V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The rotation of a quaternion (w, x, y, z), normalised as MuJoCo does.
fn rot(q: &[f64; 4]) -> M3 {
    let n = q.iter().map(|a| a * a).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|a| a / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn unit(a: &V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

/// Each body's world rotation and origin, its joint's world axis and anchor, its centre of
/// mass and its inertia in the world; the tool's rotation and position.
struct Frames {
    r: Vec<M3>,
    p: Vec<V3>,
    axis: Vec<V3>,
    anchor: Vec<V3>,
    com: Vec<V3>,
    inertia: Vec<M3>,
    tool: (M3, V3),
}

fn frames(q: &[f64]) -> Frames {
    let bodies = bodies();
    let mut f = Frames {
        r: vec![],
        p: vec![],
        axis: vec![],
        anchor: vec![],
        com: vec![],
        inertia: vec![],
        tool: ([[0.0; 3]; 3], [0.0; 3]),
    };
    let (mut r, mut p): (M3, V3) = (
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [0.0; 3],
    );
    for (b, &qi) in bodies.iter().zip(q) {
        // The body's frame before its joint moves it.
        p = add(&p, &apply(&r, &b.pos));
        r = mul(&r, &rot(&b.quat));
        let axis = apply(&r, &unit(&b.axis));
        let anchor = add(&p, &apply(&r, &b.anchor));
        match b.joint {
            Joint::Hinge => {
                // Turned by qi about the axis through the anchor.
                let turn = rot(&quat(axis, qi));
                p = add(&anchor, &apply(&turn, &sub(&p, &anchor)));
                r = mul(&turn, &r);
            }
            Joint::Slide => p = add(&p, &scale(&axis, qi)),
        }
        let rc = mul(&r, &rot(&b.com_quat));
        let d = [
            [b.inertia[0], 0.0, 0.0],
            [0.0, b.inertia[1], 0.0],
            [0.0, 0.0, b.inertia[2]],
        ];
        f.r.push(r);
        f.p.push(p);
        f.axis.push(axis);
        // The anchor moves with the body (a slide's anchor: the body's origin).
        f.anchor.push(match b.joint {
            Joint::Hinge => anchor,
            Joint::Slide => p,
        });
        f.com.push(add(&p, &apply(&r, &b.com)));
        f.inertia.push(mul(&rc, &mul(&d, &transpose(&rc))));
    }
    f.tool = (
        mul(&r, &rot(&quat(TOOL_AXIS, TOOL_ANGLE))),
        add(&p, &apply(&r, &TOOL_POS)),
    );
    f
}

/// The recursive Newton–Euler algorithm: the joint forces of the motion `q, q̇, q̈` under
/// gravity. Forward: each body's angular velocity and acceleration and its anchor's
/// acceleration (a point of the parent, moved by a slide's rate); backward: the force and the
/// moment about the anchor each body takes from its parent, projected on the joint's axis.
fn rnea(q: &[f64], qd: &[f64], qdd: &[f64]) -> Vec<f64> {
    let bodies = bodies();
    let f = frames(q);
    let n = bodies.len();
    let (mut w, mut dw, mut a_o, mut o) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
    let mut forces = Vec::new();
    for i in 0..n {
        let s = f.axis[i];
        // The anchor as a point of the parent (the world for the first body).
        let rel = sub(&f.anchor[i], &o);
        let mut a_anchor = add(&a_o, &add(&cross(&dw, &rel), &cross(&w, &cross(&w, &rel))));
        match bodies[i].joint {
            Joint::Hinge => {
                dw = add(&dw, &add(&scale(&s, qdd[i]), &cross(&w, &scale(&s, qd[i]))));
                w = add(&w, &scale(&s, qd[i]));
            }
            Joint::Slide => {
                a_anchor = add(
                    &a_anchor,
                    &add(&scale(&s, qdd[i]), &scale(&cross(&w, &s), 2.0 * qd[i])),
                );
            }
        }
        a_o = a_anchor;
        o = f.anchor[i];
        let c = sub(&f.com[i], &o);
        let a_c = add(&a_o, &add(&cross(&dw, &c), &cross(&w, &cross(&w, &c))));
        let m = bodies[i].mass;
        let force = scale(&sub(&a_c, &GRAVITY), m);
        let iw = &f.inertia[i];
        let moment = add(&apply(iw, &dw), &cross(&w, &apply(iw, &w)));
        forces.push((force, moment));
    }
    let mut tau = vec![0.0; n];
    let (mut fo, mut no) = ([0.0; 3], [0.0; 3]);
    for i in (0..n).rev() {
        let (force, moment) = forces[i];
        // The child's force and moment (about its anchor), moved to this body's anchor.
        let shift = if i + 1 < n {
            sub(&f.anchor[i + 1], &f.anchor[i])
        } else {
            [0.0; 3]
        };
        let n_child = add(&no, &cross(&shift, &fo));
        let c = sub(&f.com[i], &f.anchor[i]);
        no = add(&add(&moment, &cross(&c, &force)), &n_child);
        fo = add(&force, &fo);
        tau[i] = match bodies[i].joint {
            Joint::Hinge => dot(&f.axis[i], &no),
            Joint::Slide => dot(&f.axis[i], &fo),
        };
    }
    tau
}

/// `q̈` of `M q̈ = u - bias`, `M`'s columns and the bias by the Newton–Euler algorithm.
fn oracle(q: &[f64], qd: &[f64], u: &[f64]) -> Vec<f64> {
    let n = q.len();
    let zero = vec![0.0; n];
    let g = rnea(q, &zero, &zero);
    let bias = rnea(q, qd, &zero);
    let mut a: Vec<Vec<f64>> = vec![vec![0.0; n]; n];
    for k in 0..n {
        let e: Vec<f64> = (0..n).map(|i| f64::from(u8::from(i == k))).collect();
        let col = rnea(q, &zero, &e);
        for i in 0..n {
            a[i][k] = col[i] - g[i];
        }
    }
    let mut rhs: Vec<f64> = u.iter().zip(&bias).map(|(u, b)| u - b).collect();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap();
        a.swap(c, p);
        rhs.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            let pivot_row = a[c].clone();
            for (arj, &acj) in a[r][c..n].iter_mut().zip(&pivot_row[c..n]) {
                *arj -= f * acj;
            }
            rhs[r] -= f * rhs[c];
        }
    }
    for c in (0..n).rev() {
        let s: f64 = (c + 1..n).map(|j| a[c][j] * rhs[j]).sum();
        rhs[c] = (rhs[c] - s) / a[c][c];
    }
    rhs
}

/// URDF's roll, pitch, yaw of `r = Rz(yaw) Ry(pitch) Rx(roll)` (the task frame's angles).
fn angles(r: &M3) -> V3 {
    [
        r[2][1].atan2(r[2][2]),
        (-r[2][0]).asin(),
        r[1][0].atan2(r[0][0]),
    ]
}

fn rpy(a: &V3) -> M3 {
    let rx = rot(&quat([1.0, 0.0, 0.0], a[0]));
    let ry = rot(&quat([0.0, 1.0, 0.0], a[1]));
    let rz = rot(&quat([0.0, 0.0, 1.0], a[2]));
    mul(&rz, &mul(&ry, &rx))
}

fn max_diff(a: &M3, b: &M3) -> f64 {
    (0..3)
        .flat_map(|i| (0..3).map(move |j| (a[i][j] - b[i][j]).abs()))
        .fold(0.0, f64::max)
}

fn rbss(cache: &Path, args: &[&str]) -> (bool, String, String) {
    let exe = Path::new(env!("CARGO_BIN_EXE_rbss"));
    let target = exe.parent().and_then(Path::parent).unwrap();
    let out = Command::new(exe)
        .args(args)
        .env("RBSS_CACHE", cache)
        .env("RBSS_CACHE_TARGET", target)
        .env_remove("RBSS_CODEGEN")
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:e}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// The oracle checks itself: `M` from the Newton–Euler columns is symmetric, and the bias's
/// velocity part is quadratic in `q̇` (a wrong Coriolis term breaks neither alone, but an
/// asymmetric `M` shows a wrong moment arm).
#[test]
fn the_oracle_mass_matrix_is_symmetric_and_the_bias_quadratic() {
    let q = [0.3, -0.6, 0.05, 0.9, -0.4, 0.8];
    let qd = [0.7, -0.3, 0.2, 1.1, -0.8, 0.5];
    let n = q.len();
    let zero = vec![0.0; n];
    let g = rnea(&q, &zero, &zero);
    let cols: Vec<Vec<f64>> = (0..n)
        .map(|k| {
            let e: Vec<f64> = (0..n).map(|i| f64::from(u8::from(i == k))).collect();
            rnea(&q, &zero, &e)
                .iter()
                .zip(&g)
                .map(|(a, b)| a - b)
                .collect()
        })
        .collect();
    for i in 0..n {
        for j in 0..n {
            assert!(
                (cols[i][j] - cols[j][i]).abs() < 1e-14,
                "M[{i}][{j}] {} vs {}",
                cols[j][i],
                cols[i][j]
            );
        }
    }
    let b1 = rnea(&q, &qd, &zero);
    let qd2: Vec<f64> = qd.iter().map(|x| 2.0 * x).collect();
    let b2 = rnea(&q, &qd2, &zero);
    for i in 0..n {
        let (c1, c2) = (b1[i] - g[i], b2[i] - g[i]);
        assert!((c2 - 4.0 * c1).abs() < 1e-13, "bias[{i}]: {c1} {c2}");
    }
}

#[test]
fn an_mjcf_arm_imported_as_it_comes_runs_fd_fk_and_ik() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-mjcf-arm-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("arm5.xml"), mjcf()).unwrap();
    let plain = dir.join("arm5.toml");
    std::fs::write(&plain, "mjcf = \"arm5.xml\"\n").unwrap();
    let tool = dir.join("arm5_tool.toml");
    std::fs::write(
        &tool,
        // Three lines: the source, the tool frame, and a home off the joints' zeros (from q = 0
        // the continuation stalled at 0.18 % of the way: a singular start).
        "mjcf = \"arm5.xml\"\nrobot.outputs = [{ frame = \"tool\", pose = \"xyz-rpy\" }]\n\
         coordinates = [{ name = \"j1\", home = 0.2 }, { name = \"j2\", home = 0.25 }, \
         { name = \"j3\", home = -0.015 }, { name = \"j4\", home = -0.35 }, \
         { name = \"j5\", home = 0.6 }, { name = \"j6\", home = 0.15 }]\n",
    )
    .unwrap();
    let cache = dir.join("cache");

    // Forward dynamics against the Newton–Euler oracle.
    let (q, qd, u) = (
        [0.3, -0.6, 0.05, 0.9, -0.4, 0.8],
        [0.7, -0.3, 0.2, 1.1, -0.8, 0.5],
        [1.5, -4.0, 2.0, 0.3, -0.2, 0.05],
    );
    let state = dir.join("state.json");
    std::fs::write(
        &state,
        serde_json::json!({ "X": q, "Xdot": qd, "U": u }).to_string(),
    )
    .unwrap();
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "fd",
            "--model-file",
            plain.to_str().unwrap(),
            "--state",
            state.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let xddot = numbers(&out["Xddot"]);
    let want = oracle(&q, &qd, &u);
    assert_eq!(xddot.len(), want.len());
    let mut worst: f64 = 0.0;
    for (j, (a, b)) in xddot.iter().zip(&want).enumerate() {
        let e = (a - b).abs() / (1.0 + b.abs());
        worst = worst.max(e);
        assert!(e < 1e-9, "Xddot[{j}]: rbss {a:e}, Newton–Euler {b:e}");
    }
    eprintln!("fd: largest relative difference to the Newton–Euler oracle {worst:e}");

    // Forward kinematics of the tool frame.
    let qk = [0.4, 0.5, -0.03, -0.7, 1.2, 0.3];
    let (r_want, p_want) = frames(&qk).tool;
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "fk",
            "--model-file",
            tool.to_str().unwrap(),
            "--q",
            &list(&qk),
            "--json",
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let y = numbers(&out["outputs"]);
    assert_eq!(y.len(), 6);
    let pos_err = (0..3).map(|i| (y[i] - p_want[i]).abs()).fold(0.0, f64::max);
    let rot_err = max_diff(&rpy(&[y[3], y[4], y[5]]), &r_want);
    eprintln!("fk: tool position error {pos_err:e} m, rotation error {rot_err:e}");
    assert!(
        pos_err < 1e-12 && rot_err < 1e-12,
        "fk: {pos_err:e}, {rot_err:e}"
    );

    // Inverse kinematics from the pose (from the home): joints whose tool is at it.
    let mut pose = p_want.to_vec();
    pose.extend(angles(&r_want));
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "ik",
            "--model-file",
            tool.to_str().unwrap(),
            "--pose",
            &list(&pose),
            "--json",
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let q_ik = numbers(&out["q"]);
    let (r_ik, p_ik) = frames(&q_ik).tool;
    let pos_err = (0..3)
        .map(|i| (p_ik[i] - p_want[i]).abs())
        .fold(0.0, f64::max);
    let rot_err = max_diff(&r_ik, &r_want);
    eprintln!("ik: tool position error {pos_err:e} m, rotation error {rot_err:e}");
    assert!(
        pos_err < 1e-10 && rot_err < 1e-10,
        "ik: {pos_err:e}, {rot_err:e}"
    );
}
