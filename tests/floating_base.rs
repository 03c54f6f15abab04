//! A floating base as it comes: `tests/data/floating_biped.urdf` (a trunk on a URDF `floating`
//! joint, two legs of three revolute joints, turned origins, a general knee axis, full inertia
//! tensors in turned inertial frames) imported by a model file of one line,
//! `urdf = "floating_biped.urdf"`. The base is `X = [x, y, z, qw, qx, qy, qz, joints...]`, the
//! quaternion's unit norm a constraint row. Checked against the test's own rigid-body
//! formulas (nothing of rbss's derivation): URDF's frames, the trunk's rotation from the
//! normalised quaternion and its angular velocity `2 Im(q* q̇) / |q|²`, `T = Σ ½ m |v_c|² +
//! ½ ωᵀ I ω`:
//!
//! - the energy at random states on the constraint (T and Pi to 1e-12);
//! - forward dynamics (`rbss fd --model-file`): the accelerations of Lagrange's equations of
//!   the test's `T` with the unit norm as a multiplier's constraint (its `M` by polarisation of
//!   `T`, singular along `q̇ ∥ q`, its bias by central differences), to 1e-6;
//! - `rbss eval`: `M` on the constraint's tangent space equals the test's (polarisation), and
//!   `M` is regular (`qᵀ M q = mu` from docs/model-format.md's `free` joint);
//! - a free fall (`rbss simulate`, no actuator force): energy, horizontal momentum and the
//!   angular momentum about the centre of mass conserved, the vertical momentum changed by
//!   `-m g t`, the quaternion's norm kept at 1.

// Rigid-body algebra over index triples reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use std::path::Path;
use std::process::Command;

type M3 = [[f64; 3]; 3];
type V3 = [f64; 3];

/// A link of the URDF: its joint (parent link, origin xyz/rpy, axis) and its inertial
/// (mass, origin xyz/rpy, inertia ixx iyy izz ixy ixz iyz). Link 0 is the trunk (no joint).
struct Link {
    parent: usize,
    xyz: V3,
    rpy: V3,
    axis: V3,
    mass: f64,
    com: V3,
    com_rpy: V3,
    inertia: [f64; 6],
}

#[allow(clippy::too_many_arguments)]
const fn link(
    parent: usize,
    xyz: V3,
    rpy: V3,
    axis: V3,
    mass: f64,
    com: V3,
    com_rpy: V3,
    inertia: [f64; 6],
) -> Link {
    Link {
        parent,
        xyz,
        rpy,
        axis,
        mass,
        com,
        com_rpy,
        inertia,
    }
}

/// The links of tests/data/floating_biped.urdf, in its joints' order.
const LINKS: [Link; 7] = [
    link(
        0,
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        8.5,
        [0.02, -0.01, 0.05],
        [0.1, -0.05, 0.2],
        [0.21, 0.17, 0.09, 0.012, -0.008, 0.005],
    ),
    link(
        0,
        [0.01, 0.11, -0.08],
        [0.0, 0.0, 0.1],
        [1.0, 0.0, 0.0],
        0.7,
        [0.0, 0.01, -0.02],
        [0.0; 3],
        [0.0011, 0.0012, 0.0009, 0.0, 0.0001, 0.0],
    ),
    link(
        1,
        [0.0, 0.02, -0.05],
        [0.05, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        1.6,
        [0.01, 0.0, -0.15],
        [0.1, 0.2, 0.0],
        [0.021, 0.022, 0.0021, 0.0004, -0.0011, 0.0003],
    ),
    link(
        2,
        [0.0, 0.0, -0.3],
        [0.0, 0.1, 0.0],
        [0.0, 0.8, 0.6],
        1.1,
        [0.0, 0.01, -0.14],
        [0.0, -0.1, 0.3],
        [0.014, 0.0135, 0.0012, 0.0002, 0.0004, -0.0002],
    ),
    link(
        0,
        [0.01, -0.11, -0.08],
        [0.0, 0.0, -0.1],
        [1.0, 0.0, 0.0],
        0.7,
        [0.0, -0.01, -0.02],
        [0.0; 3],
        [0.0011, 0.0012, 0.0009, 0.0, 0.0001, 0.0],
    ),
    link(
        4,
        [0.0, -0.02, -0.05],
        [-0.05, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        1.6,
        [0.01, 0.0, -0.15],
        [-0.1, 0.2, 0.0],
        [0.021, 0.022, 0.0021, -0.0004, -0.0011, -0.0003],
    ),
    link(
        5,
        [0.0, 0.0, -0.3],
        [0.0, 0.1, 0.0],
        [0.0, 1.0, 0.0],
        1.1,
        [0.0, -0.01, -0.14],
        [0.0, -0.1, -0.3],
        [0.014, 0.0135, 0.0012, -0.0002, 0.0004, 0.0002],
    ),
];

const N: usize = 13;
const GRAVITY: f64 = 9.81;

fn mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(a: &M3, v: &V3) -> V3 {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn cross(a: &V3, b: &V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn add(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] + b[i])
}

fn sub(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] - b[i])
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn axis_angle(axis: &V3, angle: f64) -> M3 {
    let n = dot(axis, axis).sqrt();
    let [x, y, z] = axis.map(|a| a / n);
    let (s, c) = angle.sin_cos();
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

fn rpy(r: &V3) -> M3 {
    let rx = axis_angle(&[1.0, 0.0, 0.0], r[0]);
    let ry = axis_angle(&[0.0, 1.0, 0.0], r[1]);
    let rz = axis_angle(&[0.0, 0.0, 1.0], r[2]);
    mul(&rz, &mul(&ry, &rx))
}

/// The rotation of the unit quaternion `q / |q|` (Hamilton, scalar first), from the axis and
/// angle it encodes (not the quadratic form the generator writes).
fn quat_rotation(q: &[f64]) -> M3 {
    let n = dot(q, q).sqrt();
    let (w, v) = (q[0] / n, [q[1] / n, q[2] / n, q[3] / n]);
    let s = dot(&v, &v).sqrt();
    if s == 0.0 {
        return axis_angle(&[0.0, 0.0, 1.0], 0.0);
    }
    axis_angle(&v, 2.0 * s.atan2(w))
}

/// Per link: centre of mass (world), its velocity, the angular velocity (world) and the
/// rotational inertia about the centre of mass in world axes.
struct State {
    com: Vec<V3>,
    vcom: Vec<V3>,
    omega: Vec<V3>,
    inertia: Vec<M3>,
}

fn kinematics(x: &[f64], xd: &[f64]) -> State {
    let (q, qd) = (&x[3..7], &xd[3..7]);
    let nn = dot(q, q);
    // omega_body = 2 Im(q* q̇) / |q|² = 2 (w v̇ - ẇ v - v × v̇) / |q|².
    let v = [q[1], q[2], q[3]];
    let vd = [qd[1], qd[2], qd[3]];
    let vxvd = cross(&v, &vd);
    let wb: V3 = std::array::from_fn(|i| 2.0 * (q[0] * vd[i] - qd[0] * v[i] - vxvd[i]) / nn);
    let r0 = quat_rotation(q);
    let mut frames: Vec<(M3, V3, V3, V3)> = vec![(
        r0,
        [x[0], x[1], x[2]],
        apply(&r0, &wb),
        [xd[0], xd[1], xd[2]],
    )];
    for (i, l) in LINKS.iter().enumerate().skip(1) {
        let (rp, pp, wp, vp) = frames[l.parent];
        let p = add(&pp, &apply(&rp, &l.xyz));
        let r0 = mul(&rp, &rpy(&l.rpy));
        let axis = apply(&r0, &l.axis);
        let axis = axis.map(|a| a / dot(&axis, &axis).sqrt());
        let th = x[6 + i];
        let r = mul(&r0, &axis_angle(&l.axis, th));
        let w = add(&wp, &axis.map(|a| a * xd[6 + i]));
        let v = add(&vp, &cross(&wp, &sub(&p, &pp)));
        frames.push((r, p, w, v));
    }
    let mut s = State {
        com: vec![],
        vcom: vec![],
        omega: vec![],
        inertia: vec![],
    };
    for (l, (r, p, w, v)) in LINKS.iter().zip(&frames) {
        let rc = apply(r, &l.com);
        s.com.push(add(p, &rc));
        s.vcom.push(add(v, &cross(w, &rc)));
        s.omega.push(*w);
        let [ixx, iyy, izz, ixy, ixz, iyz] = l.inertia;
        let local = [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]];
        let ri = mul(r, &rpy(&l.com_rpy));
        s.inertia.push(mul(&ri, &mul(&local, &transpose(&ri))));
    }
    s
}

fn kinetic(x: &[f64], xd: &[f64]) -> f64 {
    let s = kinematics(x, xd);
    LINKS
        .iter()
        .enumerate()
        .map(|(b, l)| {
            0.5 * l.mass * dot(&s.vcom[b], &s.vcom[b])
                + 0.5 * dot(&s.omega[b], &apply(&s.inertia[b], &s.omega[b]))
        })
        .sum()
}

fn potential(x: &[f64]) -> f64 {
    let s = kinematics(x, &[0.0; N]);
    LINKS
        .iter()
        .zip(&s.com)
        .map(|(l, c)| l.mass * GRAVITY * c[2])
        .sum()
}

/// Linear momentum, and angular momentum about the centre of mass.
fn momenta(x: &[f64], xd: &[f64]) -> (V3, V3) {
    let s = kinematics(x, xd);
    let m: f64 = LINKS.iter().map(|l| l.mass).sum();
    let mut c = [0.0; 3];
    let mut p = [0.0; 3];
    for (b, l) in LINKS.iter().enumerate() {
        for i in 0..3 {
            c[i] += l.mass * s.com[b][i] / m;
            p[i] += l.mass * s.vcom[b][i];
        }
    }
    let mut h = [0.0; 3];
    for (b, l) in LINKS.iter().enumerate() {
        let r = sub(&s.com[b], &c);
        let mv = s.vcom[b].map(|v| v * l.mass);
        h = add(
            &h,
            &add(&cross(&r, &mv), &apply(&s.inertia[b], &s.omega[b])),
        );
    }
    (p, h)
}

/// `M` of the test's `T` (quadratic in `Xdot`) by polarisation: exact up to rounding.
fn mass_matrix(x: &[f64]) -> Vec<Vec<f64>> {
    let e = |i: usize| -> Vec<f64> { (0..N).map(|k| f64::from(u8::from(k == i))).collect() };
    let t: Vec<f64> = (0..N).map(|i| kinetic(x, &e(i))).collect();
    let mut m = vec![vec![0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            m[i][j] = if i == j {
                2.0 * t[i]
            } else {
                let ij: Vec<f64> = (0..N).map(|k| e(i)[k] + e(j)[k]).collect();
                kinetic(x, &ij) - t[i] - t[j]
            };
        }
    }
    m
}

fn mat_vec(m: &[Vec<f64>], v: &[f64]) -> Vec<f64> {
    m.iter().map(|row| dot(row, v)).collect()
}

/// Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap();
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            let pivot = a[c].clone();
            for (arj, acj) in a[r][c..].iter_mut().zip(&pivot[c..]) {
                *arj -= f * acj;
            }
            b[r] -= f * b[c];
        }
    }
    for c in (0..n).rev() {
        let s: f64 = (c + 1..n).map(|j| a[c][j] * b[j]).sum();
        b[c] = (b[c] - s) / a[c][c];
    }
    b
}

/// Lagrange's equations of the test's `T - Pi` with the unit norm `(qᵀq - 1) / 2 = 0` as a
/// multiplier's constraint: `M Ẍ + Gᵀ lambda = S U - Ṁ Ẋ + ∂T/∂X - ∂Pi/∂X`, `G Ẍ = -|q̇|²`,
/// `M` singular along `q` (the KKT matrix is not). Central differences for the bias.
fn oracle(x: &[f64], xd: &[f64], u: &[f64]) -> Vec<f64> {
    let h = 1e-6;
    let shifted =
        |dir: &[f64], t: f64| -> Vec<f64> { x.iter().zip(dir).map(|(a, d)| a + t * d).collect() };
    let (mp, mm) = (mass_matrix(&shifted(xd, h)), mass_matrix(&shifted(xd, -h)));
    let mdot: Vec<f64> = mat_vec(&mp, xd)
        .iter()
        .zip(mat_vec(&mm, xd))
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    let mut rhs = vec![0.0; N + 1];
    for k in 0..N {
        let e: Vec<f64> = (0..N).map(|i| f64::from(u8::from(i == k))).collect();
        let dt = (kinetic(&shifted(&e, h), xd) - kinetic(&shifted(&e, -h), xd)) / (2.0 * h);
        let dpi = (potential(&shifted(&e, h)) - potential(&shifted(&e, -h))) / (2.0 * h);
        let uk = if k >= 7 { u[k - 7] } else { 0.0 };
        rhs[k] = uk - mdot[k] + dt - dpi;
    }
    rhs[N] = -dot(&xd[3..7], &xd[3..7]);
    let m = mass_matrix(x);
    let mut a = vec![vec![0.0; N + 1]; N + 1];
    for i in 0..N {
        a[i][..N].copy_from_slice(&m[i]);
    }
    for k in 0..4 {
        a[3 + k][N] = x[3 + k];
        a[N][3 + k] = x[3 + k];
    }
    solve(a, rhs)[..N].to_vec()
}

/// A small deterministic generator (xorshift), uniform in [-1, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// A random state on the constraint: unit quaternion, `qᵀq̇ = 0`.
fn random_state(rng: &mut Rng) -> (Vec<f64>, Vec<f64>) {
    let mut x: Vec<f64> = (0..N).map(|_| rng.next()).collect();
    let mut xd: Vec<f64> = (0..N).map(|_| 2.0 * rng.next()).collect();
    let n = dot(&x[3..7], &x[3..7]).sqrt();
    for k in 3..7 {
        x[k] /= n;
    }
    let qv = dot(&x[3..7], &xd[3..7]);
    for k in 3..7 {
        xd[k] -= qv * x[k];
    }
    (x, xd)
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

fn setup() -> (tempfile::TempDir, String) {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-floating-")
        .tempdir()
        .unwrap();
    let dir = tmp.path();
    std::fs::write(
        dir.join("floating_biped.urdf"),
        include_str!("data/floating_biped.urdf"),
    )
    .unwrap();
    let model = dir.join("floating_biped.toml");
    // The whole model file: the line a user writes.
    std::fs::write(&model, include_str!("data/floating_biped.toml")).unwrap();
    assert_eq!(include_str!("data/floating_biped.toml").lines().count(), 1);
    let m = model.to_str().unwrap().to_string();
    (tmp, m)
}

#[test]
fn a_floating_biped_from_a_one_line_model_file_matches_its_rigid_body_formulas() {
    let (tmp, model) = setup();
    let dir = tmp.path();
    let cache = dir.join("cache");
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut states = Vec::new();
    let mut want = Vec::new();
    for _ in 0..5 {
        let (x, xd) = random_state(&mut rng);
        let u: Vec<f64> = (0..6).map(|_| 5.0 * rng.next()).collect();
        want.push((
            oracle(&x, &xd, &u),
            kinetic(&x, &xd),
            potential(&x),
            mass_matrix(&x),
        ));
        states.push(serde_json::json!({ "X": x, "Xdot": xd, "U": u }));
    }
    let file = dir.join("states.json");
    std::fs::write(&file, serde_json::json!({ "states": states }).to_string()).unwrap();
    let (ok, stdout, stderr) = rbss(
        &cache,
        &[
            "eval",
            "--model-file",
            &model,
            "--states",
            file.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let out: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let results = out["states"]
        .as_array()
        .unwrap_or_else(|| panic!("{stdout}"));
    let (mut worst_a, mut worst_m) = (0.0f64, 0.0f64);
    for (s, (state, (acc, t, pi, m_test))) in results.iter().zip(&want).enumerate() {
        let x = numbers(&states[s]["X"]);
        // The one constraint: the quaternion's norm, f = (qᵀq - 1) / 2, G = [0, qᵀ, 0].
        let g = &state["G"].as_array().unwrap();
        assert_eq!(g.len(), 1);
        let g0 = numbers(&g[0]);
        for k in 0..N {
            let want = if (3..7).contains(&k) { x[k] } else { 0.0 };
            assert!((g0[k] - want).abs() < 1e-15, "G[0][{k}] = {}", g0[k]);
        }
        // M on the tangent space of the constraint: the test's M there.
        let m: Vec<Vec<f64>> = state["M"].as_array().unwrap().iter().map(numbers).collect();
        let mut basis: Vec<Vec<f64>> = Vec::new();
        for k in 0..N {
            let mut e: Vec<f64> = (0..N).map(|i| f64::from(u8::from(i == k))).collect();
            let qe = dot(&x[3..7], &e[3..7]);
            for i in 3..7 {
                e[i] -= qe * x[i];
            }
            basis.push(e);
        }
        let scale = m_test.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
        for a in &basis {
            for b in &basis {
                let ours = dot(a, &mat_vec(&m, b));
                let theirs = dot(a, &mat_vec(m_test, b));
                worst_m = worst_m.max((ours - theirs).abs() / scale);
            }
        }
        // Along q: mu = 4/3 tr(I) of the trunk and the legs (the generator's documented value).
        let q_only: Vec<f64> = (0..N)
            .map(|i| if (3..7).contains(&i) { x[i] } else { 0.0 })
            .collect();
        let qm = dot(&q_only, &mat_vec(&m, &q_only));
        let mu: f64 = 4.0 / 3.0
            * LINKS
                .iter()
                .map(|l| l.inertia[..3].iter().sum::<f64>())
                .sum::<f64>();
        assert!((qm - mu).abs() < 1e-12 * mu, "qᵀ M q = {qm}, mu = {mu}");
        let xddot = numbers(&state["Xddot"]);
        for (j, (a, b)) in xddot.iter().zip(acc).enumerate() {
            let e = (a - b).abs() / (1.0 + b.abs());
            worst_a = worst_a.max(e);
            assert!(
                e < 1e-6,
                "state {s}: Xddot[{j}]: rbss {a:e}, the test's Lagrangian {b:e}"
            );
        }
        assert_ne!(&xddot, acc, "not the same arithmetic");
        // The energy, exactly the test's on the constraint.
        let (ok, stdout, stderr) = {
            let f = dir.join("state.json");
            std::fs::write(&f, states[s].to_string()).unwrap();
            rbss(
                &cache,
                &["fd", "--model-file", &model, "--state", f.to_str().unwrap()],
            )
        };
        assert!(ok, "{stderr}");
        let fd: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        let energy = numbers(&fd["energy"]);
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
        let fd_x = numbers(&fd["Xddot"]);
        for (a, b) in fd_x.iter().zip(&xddot) {
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                "fd {a:e} vs eval {b:e}"
            );
        }
    }
    eprintln!(
        "floating biped: M on the tangent space to {worst_m:.1e}, Xddot to {worst_a:.1e} (the oracle's differences)"
    );
}

#[test]
fn a_free_falling_biped_conserves_energy_and_momentum() {
    let (tmp, model) = setup();
    let dir = tmp.path();
    let cache = dir.join("cache");
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let (x, xd) = random_state(&mut rng);
    let state = dir.join("state.json");
    std::fs::write(
        &state,
        serde_json::json!({ "X": x, "Xdot": xd }).to_string(),
    )
    .unwrap();
    let out = dir.join("sim");
    let t_end = 1.0;
    let (ok, _, stderr) = rbss(
        &cache,
        &[
            "simulate",
            "--model-file",
            &model,
            "--state",
            state.to_str().unwrap(),
            "--t-end",
            "1",
            "--rtol",
            "1e-11",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(ok, "{stderr}");
    let csv = std::fs::read_to_string(out.join("simulate.csv")).unwrap();
    let mut rows = csv
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().unwrap())
                .collect::<Vec<f64>>()
        });
    let first = rows.next().unwrap();
    let last = rows.next_back().unwrap();
    assert!((last[0] - t_end).abs() < 1e-9, "ends at {}", last[0]);
    let split = |r: &[f64]| (r[1..1 + N].to_vec(), r[1 + N..1 + 2 * N].to_vec());
    let (x0, v0) = split(&first);
    let (x1, v1) = split(&last);
    let m: f64 = LINKS.iter().map(|l| l.mass).sum();
    let e = |x: &[f64], v: &[f64]| kinetic(x, v) + potential(x);
    let (e0, e1) = (e(&x0, &v0), e(&x1, &v1));
    let ((p0, h0), (p1, h1)) = (momenta(&x0, &v0), momenta(&x1, &v1));
    let norm = dot(&x1[3..7], &x1[3..7]).sqrt();
    eprintln!(
        "free fall, 1 s: energy {e0} -> {e1} ({:.1e}), momentum x {:.1e} y {:.1e}, z {:.1e} \
         against -m g t, angular momentum about the centre of mass {:.1e} {:.1e} {:.1e}, |q| - 1 = {:.1e}",
        e1 - e0,
        p1[0] - p0[0],
        p1[1] - p0[1],
        p1[2] - p0[2] + m * GRAVITY * t_end,
        h1[0] - h0[0],
        h1[1] - h0[1],
        h1[2] - h0[2],
        norm - 1.0
    );
    assert!(
        (e1 - e0).abs() < 1e-7 * (1.0 + e0.abs()),
        "energy {e0} -> {e1}"
    );
    for i in 0..2 {
        assert!(
            (p1[i] - p0[i]).abs() < 1e-7,
            "momentum {i}: {} -> {}",
            p0[i],
            p1[i]
        );
    }
    assert!(
        (p1[2] - p0[2] + m * GRAVITY * t_end).abs() < 1e-7,
        "vertical momentum"
    );
    for i in 0..3 {
        assert!(
            (h1[i] - h0[i]).abs() < 1e-7,
            "angular momentum {i}: {} -> {}",
            h0[i],
            h1[i]
        );
    }
    assert!((norm - 1.0).abs() < 1e-9, "|q| = {norm}");
    // The motion is not trivial: the base turned and the legs moved.
    assert!((x1[3] - x0[3]).abs() > 1e-3 && (x1[9] - x0[9]).abs() > 1e-3);
}
