//! A serial arm imported as it comes: a URDF of six revolute joints (axes along z, y, x, with
//! rotated joint origins, centres of mass off the axes and full inertia tensors in rotated
//! inertial frames), written by this test, and a model file of one line, `urdf = "arm6.urdf"`
//! (no loop, no outputs, no home). `rbss fd --model-file` at a state must give the
//! accelerations of the test's own Lagrangian: forward kinematics by URDF's conventions, the
//! geometric Jacobians of the centres of mass and of the links' rotations, `M = Σ m Jvᵀ Jv +
//! Jwᵀ R I Rᵀ Jw`, and the bias `Ṁ q̇ - ∂T/∂q` from central differences of that `M` along
//! `q̇` and along each `q_k`: nothing of rbss's derivation. Also: the energy, and that inverse
//! kinematics says it needs outputs. With a second line naming link 6's frame as the outputs
//! (`robot.outputs = [{ frame = "link6", pose = "xyz-rpy" }]`), `rbss fk` gives the test's
//! flange pose, `rbss ik` joints whose flange is the asked pose, and `rbss fd` the plain arm's
//! accelerations (the task frame adds no mass). With the frame as outputs the imported
//! actuators stay (the six joints): inverse dynamics, through the model's library, gives the
//! test's Lagrangian's torques, and forward dynamics under them the motion back.

mod common;

use std::path::Path;
use std::process::Command;

use common::robot_lib::{RobotLib, library};

/// One link and the joint that carries it: the joint's origin (xyz, rpy) in the parent's
/// frame, its axis, then the link's mass, centre of mass and inertial frame (xyz, rpy) and its
/// inertia (ixx, iyy, izz, ixy, ixz, iyz) in that frame.
struct Link {
    xyz: [f64; 3],
    rpy: [f64; 3],
    axis: [f64; 3],
    mass: f64,
    com: [f64; 3],
    com_rpy: [f64; 3],
    inertia: [f64; 6],
}

const LINKS: [Link; 6] = [
    Link {
        xyz: [0.0, 0.0, 0.1],
        rpy: [0.0, 0.0, 0.0],
        axis: [0.0, 0.0, 1.0],
        mass: 3.1,
        com: [0.01, -0.02, 0.05],
        com_rpy: [0.0, 0.0, 0.3],
        inertia: [0.021, 0.019, 0.012, 0.001, -0.0005, 0.0008],
    },
    Link {
        xyz: [0.0, 0.05, 0.12],
        rpy: [std::f64::consts::FRAC_PI_2, 0.0, 0.0],
        axis: [0.0, 0.0, 1.0],
        mass: 4.2,
        com: [0.2, 0.01, 0.03],
        com_rpy: [0.1, -0.2, 0.05],
        inertia: [0.011, 0.062, 0.059, -0.002, 0.0015, 0.0004],
    },
    Link {
        xyz: [0.4, 0.0, 0.0],
        rpy: [0.0, 0.0, 0.2],
        axis: [0.0, 1.0, 0.0],
        mass: 2.3,
        com: [0.15, 0.0, -0.02],
        com_rpy: [0.0, 0.0, 0.0],
        inertia: [0.006, 0.031, 0.029, 0.0, 0.0007, 0.0],
    },
    Link {
        xyz: [0.35, 0.0, 0.02],
        rpy: [0.0, -0.3, 0.0],
        axis: [1.0, 0.0, 0.0],
        mass: 1.2,
        com: [0.04, 0.01, 0.0],
        com_rpy: [0.4, 0.0, 0.0],
        inertia: [0.0024, 0.0021, 0.0018, 0.0001, 0.0, -0.0002],
    },
    Link {
        xyz: [0.08, 0.0, 0.0],
        rpy: [-std::f64::consts::FRAC_PI_2, 0.0, 0.0],
        axis: [0.0, 1.0, 0.0],
        mass: 0.9,
        com: [0.0, 0.02, 0.03],
        com_rpy: [0.0, 0.25, 0.0],
        inertia: [0.0013, 0.0011, 0.0009, 0.0, 0.0001, 0.0],
    },
    Link {
        xyz: [0.0, 0.0, 0.09],
        rpy: [0.0, 0.0, 0.7],
        axis: [0.0, 0.0, 1.0],
        mass: 0.35,
        com: [0.0, 0.0, 0.025],
        com_rpy: [0.0, 0.0, 0.0],
        inertia: [0.0004, 0.0004, 0.0003, 0.0, 0.0, 0.0],
    },
];

const GRAVITY: f64 = 9.81;

fn urdf() -> String {
    let v = |a: &[f64; 3]| format!("{} {} {}", a[0], a[1], a[2]);
    let mut s =
        String::from("<?xml version=\"1.0\"?>\n<robot name=\"arm6\">\n  <link name=\"base\"/>\n");
    for (i, l) in LINKS.iter().enumerate() {
        let [ixx, iyy, izz, ixy, ixz, iyz] = l.inertia;
        s += &format!(
            "  <link name=\"link{n}\">\n    <inertial>\n      <origin xyz=\"{}\" rpy=\"{}\"/>\n      \
             <mass value=\"{}\"/>\n      <inertia ixx=\"{ixx}\" ixy=\"{ixy}\" ixz=\"{ixz}\" iyy=\"{iyy}\" \
             iyz=\"{iyz}\" izz=\"{izz}\"/>\n    </inertial>\n    <visual><geometry><box size=\"0.1 0.1 0.1\"/></geometry></visual>\n  </link>\n  \
             <joint name=\"j{n}\" type=\"revolute\">\n    <parent link=\"{p}\"/>\n    <child link=\"link{n}\"/>\n    \
             <origin xyz=\"{}\" rpy=\"{}\"/>\n    <axis xyz=\"{}\"/>\n    \
             <limit lower=\"-3\" upper=\"3\" effort=\"100\" velocity=\"3\"/>\n  </joint>\n",
            v(&l.com),
            v(&l.com_rpy),
            l.mass,
            v(&l.xyz),
            v(&l.rpy),
            v(&l.axis),
            n = i + 1,
            p = if i == 0 {
                "base".to_string()
            } else {
                format!("link{i}")
            },
        );
    }
    s + "</robot>\n"
}

type M3 = [[f64; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(a: &M3, v: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
fn axis_angle(axis: &[f64; 3], angle: f64) -> M3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = *axis;
    [
        [
            c + x * x * (1.0 - c),
            x * y * (1.0 - c) - z * s,
            x * z * (1.0 - c) + y * s,
        ],
        [
            y * x * (1.0 - c) + z * s,
            c + y * y * (1.0 - c),
            y * z * (1.0 - c) - x * s,
        ],
        [
            z * x * (1.0 - c) - y * s,
            z * y * (1.0 - c) + x * s,
            c + z * z * (1.0 - c),
        ],
    ]
}

/// URDF's rpy: `Rz(yaw) Ry(pitch) Rx(roll)` (fixed axes x, y, z).
fn rpy(r: &[f64; 3]) -> M3 {
    let rx = axis_angle(&[1.0, 0.0, 0.0], r[0]);
    let ry = axis_angle(&[0.0, 1.0, 0.0], r[1]);
    let rz = axis_angle(&[0.0, 0.0, 1.0], r[2]);
    mul(&rz, &mul(&ry, &rx))
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn add(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] + b[i])
}

/// For each link: its centre of mass in the world, its inertial frame's rotation, and the
/// world's joint axes and joint origins (for the geometric Jacobians).
struct Kinematics {
    com: Vec<[f64; 3]>,
    r_inertia: Vec<M3>,
    axis: Vec<[f64; 3]>,
    origin: Vec<[f64; 3]>,
}

fn kinematics(q: &[f64]) -> Kinematics {
    let (mut r, mut p): (M3, [f64; 3]) = (
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [0.0; 3],
    );
    let mut k = Kinematics {
        com: vec![],
        r_inertia: vec![],
        axis: vec![],
        origin: vec![],
    };
    for (l, &qi) in LINKS.iter().zip(q) {
        p = add(&p, &apply(&r, &l.xyz));
        r = mul(&r, &rpy(&l.rpy));
        k.axis.push(apply(&r, &l.axis));
        k.origin.push(p);
        r = mul(&r, &axis_angle(&l.axis, qi));
        k.com.push(add(&p, &apply(&r, &l.com)));
        k.r_inertia.push(mul(&r, &rpy(&l.com_rpy)));
    }
    k
}

/// `M(q)` by the geometric Jacobians.
fn mass_matrix(q: &[f64]) -> Vec<Vec<f64>> {
    let n = LINKS.len();
    let k = kinematics(q);
    let mut m = vec![vec![0.0; n]; n];
    for (b, l) in LINKS.iter().enumerate() {
        let [ixx, iyy, izz, ixy, ixz, iyz] = l.inertia;
        let local = [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]];
        let world = mul(&k.r_inertia[b], &mul(&local, &transpose(&k.r_inertia[b])));
        // Columns j <= b: the joints that move link b.
        let jv: Vec<[f64; 3]> = (0..=b)
            .map(|j| {
                cross(
                    &k.axis[j],
                    &std::array::from_fn(|i| k.com[b][i] - k.origin[j][i]),
                )
            })
            .collect();
        for i in 0..=b {
            for j in 0..=b {
                let lin: f64 = (0..3).map(|c| jv[i][c] * jv[j][c]).sum();
                let iw = apply(&world, &k.axis[j]);
                let ang: f64 = (0..3).map(|c| k.axis[i][c] * iw[c]).sum();
                m[i][j] += l.mass * lin + ang;
            }
        }
    }
    m
}

fn potential(q: &[f64]) -> f64 {
    let k = kinematics(q);
    LINKS
        .iter()
        .zip(&k.com)
        .map(|(l, c)| l.mass * GRAVITY * c[2])
        .sum()
}

fn mat_vec(m: &[Vec<f64>], v: &[f64]) -> Vec<f64> {
    m.iter()
        .map(|row| row.iter().zip(v).map(|(a, b)| a * b).sum())
        .collect()
}

/// `q̈` of `M q̈ = u - (Ṁ q̇ - ∂T/∂q) - ∂Π/∂q`, with `Ṁ`, `∂T/∂q` and `∂Π/∂q` by central
/// differences of the test's own `M` and `Π`; and `T`, `Π` at the state.
fn oracle(q: &[f64], qd: &[f64], u: &[f64]) -> (Vec<f64>, f64, f64) {
    let n = q.len();
    let h = 1e-6;
    let shifted =
        |dir: &[f64], t: f64| -> Vec<f64> { q.iter().zip(dir).map(|(a, d)| a + t * d).collect() };
    let (mp, mm) = (mass_matrix(&shifted(qd, h)), mass_matrix(&shifted(qd, -h)));
    let mdot_qd: Vec<f64> = mat_vec(&mp, qd)
        .iter()
        .zip(mat_vec(&mm, qd))
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    let mut rhs = vec![0.0; n];
    for k in 0..n {
        let e: Vec<f64> = (0..n).map(|i| f64::from(u8::from(i == k))).collect();
        let (ap, am) = (mass_matrix(&shifted(&e, h)), mass_matrix(&shifted(&e, -h)));
        let quad = |m: &[Vec<f64>]| -> f64 {
            mat_vec(m, qd)
                .iter()
                .zip(qd)
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / 2.0
        };
        let dt_dq = (quad(&ap) - quad(&am)) / (2.0 * h);
        let dpi_dq = (potential(&shifted(&e, 1e-5)) - potential(&shifted(&e, -1e-5))) / 2e-5;
        rhs[k] = u[k] - mdot_qd[k] + dt_dq - dpi_dq;
    }
    // Gaussian elimination with partial pivoting.
    let mut a = mass_matrix(q);
    let t = mat_vec(&a, qd)
        .iter()
        .zip(qd)
        .map(|(a, b)| a * b)
        .sum::<f64>()
        / 2.0;
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
    (rhs, t, potential(q))
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

#[test]
fn a_urdf_arm_from_a_one_line_model_file_runs_forward_dynamics() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-urdf-arm-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("arm6.urdf"), urdf()).unwrap();
    let model = dir.join("arm6.toml");
    // The whole model file: the line a user writes.
    std::fs::write(&model, "urdf = \"arm6.urdf\"\n").unwrap();
    let (q, qd, u) = (
        [0.3, -0.7, 1.1, 0.4, -0.9, 0.2],
        [0.5, -0.4, 0.8, -1.2, 0.6, 1.5],
        [2.0, -5.0, 3.0, 0.5, -0.4, 0.1],
    );
    let state = dir.join("state.json");
    std::fs::write(
        &state,
        serde_json::json!({ "X": q, "Xdot": qd, "U": u }).to_string(),
    )
    .unwrap();
    let cache = dir.join("cache");
    let model_arg = model.to_str().unwrap();
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "fd",
            "--model-file",
            model_arg,
            "--state",
            state.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let xddot = numbers(&out["Xddot"]);
    assert!(numbers(&out["lambda"]).is_empty(), "no loop, no multiplier");
    let (want, t, pi) = oracle(&q, &qd, &u);
    for (j, (a, b)) in xddot.iter().zip(&want).enumerate() {
        assert!(
            (a - b).abs() < 1e-6 * (1.0 + b.abs()),
            "Xddot[{j}]: rbss {a:e}, the test's Lagrangian {b:e}"
        );
    }
    // Not the same arithmetic: rbss's answer is not bit-identical to the oracle's.
    assert_ne!(xddot, want);
    let energy = numbers(&out["energy"]);
    assert!(
        (energy[0] - t).abs() < 1e-12 * (1.0 + t),
        "T: {} vs {t}",
        energy[0]
    );
    assert!(
        (energy[1] - pi).abs() < 1e-12 * (1.0 + pi.abs()),
        "Pi: {} vs {pi}",
        energy[1]
    );

    // Inverse kinematics needs outputs: a clear error, no panic.
    let (ok, _, stderr) = rbss(&cache, &["ik", "--model-file", model_arg, "--pose", "0.1"]);
    assert!(!ok);
    assert!(stderr.contains("no outputs"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Link 6's frame in the world (the flange: after its joint's rotation), by URDF's conventions.
fn flange(q: &[f64]) -> (M3, [f64; 3]) {
    let (mut r, mut p): (M3, [f64; 3]) = (
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [0.0; 3],
    );
    for (l, &qi) in LINKS.iter().zip(q) {
        p = add(&p, &apply(&r, &l.xyz));
        r = mul(&mul(&r, &rpy(&l.rpy)), &axis_angle(&l.axis, qi));
    }
    (r, p)
}

/// URDF's roll, pitch, yaw of `r = Rz(yaw) Ry(pitch) Rx(roll)`.
fn angles(r: &M3) -> [f64; 3] {
    [
        r[2][1].atan2(r[2][2]),
        (-r[2][0]).asin(),
        r[1][0].atan2(r[0][0]),
    ]
}

fn max_diff(a: &M3, b: &M3) -> f64 {
    (0..3)
        .flat_map(|i| (0..3).map(move |j| (a[i][j] - b[i][j]).abs()))
        .fold(0.0, f64::max)
}

/// The flange's pose rates `[ẋ, ẏ, ż, roll̇, pitcḣ, yaẇ]` at `q, q̇`: the geometric Jacobian's
/// linear and angular velocity, the angular one written in URDF's rpy rates
/// (`ω = roll̇ Rz Ry e_x + pitcḣ Rz e_y + yaẇ e_z`, solved by Cramer's rule).
fn flange_rates(q: &[f64], qd: &[f64]) -> [f64; 6] {
    let k = kinematics(q);
    let (r, p) = flange(q);
    let (mut v, mut w) = ([0.0; 3], [0.0; 3]);
    for ((axis, origin), &rate) in k.axis.iter().zip(&k.origin).zip(qd) {
        let lin = cross(axis, &std::array::from_fn(|i| p[i] - origin[i]));
        v = std::array::from_fn(|i| v[i] + lin[i] * rate);
        w = std::array::from_fn(|i| w[i] + axis[i] * rate);
    }
    let [_, pitch, yaw] = angles(&r);
    let rz = axis_angle(&[0.0, 0.0, 1.0], yaw);
    let c0 = apply(
        &mul(&rz, &axis_angle(&[0.0, 1.0, 0.0], pitch)),
        &[1.0, 0.0, 0.0],
    );
    let c1 = apply(&rz, &[0.0, 1.0, 0.0]);
    let c2 = [0.0, 0.0, 1.0];
    let det = |a: &[f64; 3], b: &[f64; 3], c: &[f64; 3]| {
        a[0] * (b[1] * c[2] - b[2] * c[1]) - b[0] * (a[1] * c[2] - a[2] * c[1])
            + c[0] * (a[1] * b[2] - a[2] * b[1])
    };
    let d = det(&c0, &c1, &c2);
    [
        v[0],
        v[1],
        v[2],
        det(&w, &c1, &c2) / d,
        det(&c0, &w, &c2) / d,
        det(&c0, &c1, &w) / d,
    ]
}

#[test]
fn a_urdf_arm_with_its_tool_frame_as_outputs_runs_fk_ik_and_fd() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-urdf-frame-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("arm6.urdf"), urdf()).unwrap();
    // The whole model file: the source and the task frame.
    let model = dir.join("arm6_tool.toml");
    std::fs::write(
        &model,
        "urdf = \"arm6.urdf\"\nrobot.outputs = [{ frame = \"link6\", pose = \"xyz-rpy\" }]\n",
    )
    .unwrap();
    let plain = dir.join("arm6.toml");
    std::fs::write(&plain, "urdf = \"arm6.urdf\"\n").unwrap();
    let cache = dir.join("cache");
    let model_arg = model.to_str().unwrap();
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:e}"))
            .collect::<Vec<_>>()
            .join(",")
    };

    // `rbss list --model-file --json`: X, f by loop, actuated and outputs by name and index.
    let (ok, stdout, stderr) = rbss(&cache, &["list", "--model-file", model_arg, "--json"]);
    assert!(ok, "{stderr}");
    let d: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let coords: Vec<&str> = d["coordinates"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
        .map(|(j, c)| {
            assert_eq!(c["index"].as_u64(), Some(j as u64));
            c["name"].as_str().unwrap()
        })
        .collect();
    let actuated: Vec<(&str, usize)> = d["actuated"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (
                a["name"].as_str().unwrap(),
                a["index"].as_u64().unwrap() as usize,
            )
        })
        .collect();
    // The URDF's six revolute joints, in the source's order, every one driven.
    let names: Vec<&str> = actuated.iter().map(|a| a.0).collect();
    assert_eq!(names, ["j1", "j2", "j3", "j4", "j5", "j6"]);
    for (name, j) in &actuated {
        assert_eq!(coords[*j], *name);
    }
    // The tool frame's pose: six outputs, each named at its index of X, none actuated.
    let outputs = d["outputs"].as_array().unwrap();
    assert_eq!(outputs.len(), 6, "{stdout}");
    for o in outputs {
        let j = o["index"].as_u64().unwrap() as usize;
        assert_eq!(coords[j], o["name"].as_str().unwrap());
        assert!(!actuated.iter().any(|a| a.1 == j));
    }
    // Every constraint row in exactly one loop, named `loop.component`; N - M = 6.
    let constraints = d["constraints"].as_array().unwrap();
    let mut seen = vec![0; constraints.len()];
    for lp in d["loops"].as_array().unwrap() {
        for r in lp["rows"].as_array().unwrap() {
            let r = r.as_u64().unwrap() as usize;
            seen[r] += 1;
            let c = &constraints[r];
            assert_eq!(c["loop"], lp["name"]);
            assert_eq!(
                c["name"].as_str().unwrap(),
                format!(
                    "{}.{}",
                    lp["name"].as_str().unwrap(),
                    c["component"].as_str().unwrap()
                )
            );
        }
    }
    assert!(seen.iter().all(|&k| k == 1), "{seen:?}");
    assert_eq!(coords.len() - constraints.len(), 6);
    assert_eq!(d["degrees_of_freedom"].as_u64(), Some(6));

    // Forward kinematics gives the outputs y = h(X): the test's flange pose.
    let q = [0.3, -0.7, 1.1, 0.4, -0.9, 0.2];
    let (r_want, p_want) = flange(&q);
    let (ok, stdout, stderr) = rbss(
        &cache,
        &["fk", "--model-file", model_arg, "--q", &list(&q), "--json"],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let y = numbers(&out["outputs"]);
    assert_eq!(y.len(), 6);
    let x = numbers(&out["x"]);
    assert_eq!(x.len(), 12, "six joints, then the frame's six coordinates");
    for (j, (a, b)) in x[..6].iter().zip(&q).enumerate() {
        assert!((a - b).abs() < 1e-12, "fk moved joint {j}: {a} vs {b}");
    }
    let pos_err = (0..3).map(|i| (y[i] - p_want[i]).abs()).fold(0.0, f64::max);
    let rot_err = max_diff(&rpy(&[y[3], y[4], y[5]]), &r_want);
    assert!(pos_err < 1e-12, "fk position error {pos_err:e}");
    assert!(rot_err < 1e-12, "fk orientation error {rot_err:e}");

    // Inverse kinematics from the pose: joints whose flange is that pose.
    let mut pose = p_want.to_vec();
    pose.extend(angles(&r_want));
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "ik",
            "--model-file",
            model_arg,
            "--pose",
            &list(&pose),
            "--json",
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let q_ik = numbers(&out["q"]);
    let (r_ik, p_ik) = flange(&q_ik);
    let pos_err = (0..3)
        .map(|i| (p_ik[i] - p_want[i]).abs())
        .fold(0.0, f64::max);
    let rot_err = max_diff(&r_ik, &r_want);
    eprintln!("ik: flange position error {pos_err:e} m, rotation error {rot_err:e}");
    assert!(
        pos_err < 1e-10 && rot_err < 1e-10,
        "ik: {pos_err:e}, {rot_err:e}"
    );

    // Forward dynamics: the frame adds no mass; the joints' accelerations are the plain
    // arm's (and the test's Lagrangian's).
    let qd = [0.5, -0.4, 0.8, -1.2, 0.6, 1.5];
    let u = [2.0, -5.0, 3.0, 0.5, -0.4, 0.1];
    let mut xd = qd.to_vec();
    xd.extend(flange_rates(&q, &qd));
    let state = dir.join("state.json");
    std::fs::write(
        &state,
        serde_json::json!({ "X": x, "Xdot": xd, "U": u }).to_string(),
    )
    .unwrap();
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "fd",
            "--model-file",
            model_arg,
            "--state",
            state.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let with_frame = numbers(&out["Xddot"]);
    let plain_state = dir.join("plain_state.json");
    std::fs::write(
        &plain_state,
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
            plain_state.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let without = numbers(&out["Xddot"]);
    let (want, _, _) = oracle(&q, &qd, &u);
    let mut worst: f64 = 0.0;
    for (j, ((a, b), w)) in with_frame.iter().zip(&without).zip(&want).enumerate() {
        worst = worst.max((a - b).abs() / (1.0 + b.abs()));
        assert!(
            (a - w).abs() < 1e-6 * (1.0 + w.abs()),
            "Xddot[{j}]: {a} vs the test's Lagrangian {w}"
        );
    }
    eprintln!("fd: the task frame changes the joints' accelerations by {worst:e} (relative)");
    assert!(worst < 1e-12, "fd with the task frame differs by {worst:e}");
}

#[test]
fn a_urdf_arm_with_its_tool_frame_and_its_actuators_runs_inverse_dynamics() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-urdf-id-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("arm6.urdf"), urdf()).unwrap();
    let model = dir.join("arm6_tool.toml");
    std::fs::write(
        &model,
        "urdf = \"arm6.urdf\"\nrobot.outputs = [{ frame = \"link6\", pose = \"xyz-rpy\" }]\n",
    )
    .unwrap();
    let robot = RobotLib::open(&library(&model, &dir.join("cache")));
    // The six joints actuated (the importer's), the frame's six coordinates the outputs.
    assert_eq!((robot.n, robot.m, robot.k, robot.p), (12, 6, 6, 6));
    assert_eq!(
        (0..6).map(|i| robot.actuated(i)).collect::<Vec<_>>(),
        [0, 1, 2, 3, 4, 5]
    );
    assert_eq!(
        (0..6).map(|i| robot.output(i)).collect::<Vec<_>>(),
        [6, 7, 8, 9, 10, 11]
    );

    let cases = [
        (
            [0.3, -0.7, 1.1, 0.4, -0.9, 0.2],
            [0.5, -0.4, 0.8, -1.2, 0.6, 1.5],
            [1.0, 0.5, -2.0, 3.0, -1.5, 0.7],
        ),
        (
            [-0.5, 0.4, -0.8, 1.2, 0.3, -1.0],
            [-0.3, 0.9, 0.2, 0.4, -1.1, 0.6],
            [-0.4, 1.5, 0.8, -0.6, 2.0, -1.2],
        ),
    ];
    let (mut worst_u, mut worst_xdd): (f64, f64) = (0.0, 0.0);
    for (q, qd, qdd) in cases {
        // The state: the joints and the flange's pose by the test's URDF kinematics (forward
        // kinematics from the home would start at the frame's pitch of pi/2, where the
        // roll-pitch-yaw coordinates are singular).
        let (r, p) = flange(&q);
        let mut x = q.to_vec();
        x.extend(p);
        x.extend(angles(&r));
        let x_fk = robot.fk(&q, Some(&x)).unwrap();
        for (j, (a, b)) in x_fk.iter().zip(&x).enumerate() {
            assert!((a - b).abs() < 1e-12, "fk X[{j}]: {a} vs the test's {b}");
        }
        let xd = robot.forward_velocity(&x, &qd).unwrap();
        let xdd = robot.forward_acceleration(&x, &xd, &qdd).unwrap();
        let (u, _) = robot.inverse_dynamics(&x, &xd, &xdd).unwrap();
        // The test's Lagrangian: U = M(q) (q̈ - q̈₀), q̈₀ the accelerations without forces.
        let (free, _, _) = oracle(&q, &qd, &[0.0; 6]);
        let dq: Vec<f64> = qdd.iter().zip(&free).map(|(a, b)| a - b).collect();
        let want = mat_vec(&mass_matrix(&q), &dq);
        for (j, (a, b)) in u.iter().zip(&want).enumerate() {
            let err = (a - b).abs() / (1.0 + b.abs());
            assert!(
                err < 1e-6,
                "U[{j}]: rbss {a:e}, the test's Lagrangian {b:e}"
            );
            worst_u = worst_u.max(err);
        }
        // Forward dynamics under U: the motion back.
        let (xdd_fd, _) = robot.forward_dynamics(&x, &xd, &u).unwrap();
        for (a, b) in xdd_fd.iter().zip(&xdd) {
            worst_xdd = worst_xdd.max((a - b).abs() / (1.0 + b.abs()));
        }
    }
    eprintln!("id vs the Lagrangian: {worst_u:.1e} (relative); fd(id) Xddot {worst_xdd:.1e}");
    assert!(worst_xdd < 1e-12, "fd(id(U)) off by {worst_xdd:e}");
}
