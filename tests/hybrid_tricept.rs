//! The hybrid Tricept-like machine (models/hybrid_tricept.toml) against oracles written here from
//! its geometry and nothing of rbss's generated code:
//!
//! - inverse kinematics in closed form: the wrist centre `W = tip - lt * axis` lies on the
//!   central leg's axis, which gives the central leg's angles and extension, the platform's
//!   rotation, the legs' lengths and joint angles (as for a 6-UPS leg) and the wrist angles from
//!   the tool axis in the platform's frame;
//! - forward kinematics of the wrist by the product of rotations
//!   `Rx(a1) Ry(a2) Rx(w1) Ry(w2)`;
//! - statics by virtual work: at rest, the actuator forces and torques `U` satisfy
//!   `U · dq/dp = dPi/dp` for every direction `p` of the tool pose, with `q(p)` from the closed
//!   form and the potential energy `Pi(p)` summed over the bodies (the model's solids, by hand).
//!
//! Checked: IK against the closed form, FK giving the pose back from the actuators and agreeing
//! with the product of rotations, the static forces against virtual work, and the inverse ->
//! forward dynamics round trip along models/trajectories/hybrid_tricept.toml.

// Vectors and matrices over index triples read best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod common;

use std::f64::consts::PI;

use common::Rng;
use common::la3::{V3, mat_mul, mat_t_vec, mat_vec, norm, rx, ry, rz};
use hybrid_tricept::HybridTricept;
use rbss::roundtrip::{RoundTripRequest, roundtrip_command};
use rbss_runtime::{
    Data, IntegrateOptions, Method, Model, Stabilization, forward_acceleration, forward_kinematics,
    forward_velocity, inverse_dynamics, inverse_kinematics,
};

const RB: f64 = 0.5;
const RP: f64 = 0.2;
const HW: f64 = 0.2;
const LT: f64 = 0.3;
const ALPHA: [f64; 3] = [90.0, 210.0, 330.0];
const HOME: [f64; 5] = [0.0, 0.0, 1.5, 0.0, 0.0];
const G: f64 = 9.81;

/// Indices in X = [d1..d3, w1, w2, phi1..phi3, psi1..psi3, a1, a2, r, x, y, z, rotx, roty].
const W1: usize = 3;
const PHI: usize = 5;
const PSI: usize = 8;
const A1: usize = 11;

/// `(a, b)` with `Rx(a) Ry(b) e_z = u` (u a unit vector with u_z > 0).
fn angles_of_axis(u: &V3) -> (f64, f64) {
    ((-u[1]).atan2(u[2]), u[0].asin())
}

/// Everything the closed form gives at a tool pose.
struct Ik {
    /// X without the outputs: [d1..d3, w1, w2, phi1..3, psi1..3, a1, a2, r].
    q: [f64; 14],
    /// World points: the legs' base and platform joints, the platform origin, the tool axis.
    base: [V3; 3],
    top: [V3; 3],
    n: V3,
    r: f64,
    axis: V3,
}

fn oracle_ik(pose: &[f64; 5]) -> Ik {
    let axis = mat_vec(&mat_mul(&rx(pose[3]), &ry(pose[4])), &[0.0, 0.0, 1.0]);
    let w: V3 = std::array::from_fn(|k| pose[k] - LT * axis[k]);
    let len = norm(&w);
    let n = w.map(|c| c / len);
    let r = len - HW;
    let (a1, a2) = angles_of_axis(&n);
    let rp = mat_mul(&rx(a1), &ry(a2));
    let (w1, w2) = angles_of_axis(&mat_t_vec(&rp, &axis));
    let mut q = [0.0; 14];
    q[W1] = w1;
    q[W1 + 1] = w2;
    q[A1] = a1;
    q[A1 + 1] = a2;
    q[A1 + 2] = r;
    let (mut base, mut top) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
    for i in 0..3 {
        let al = ALPHA[i].to_radians();
        let b = [RB * al.cos(), RB * al.sin(), 0.0];
        let pl = mat_vec(&rp, &[RP * al.cos(), RP * al.sin(), 0.0]);
        let s: V3 = std::array::from_fn(|k| r * n[k] + pl[k]);
        let d: V3 = std::array::from_fn(|k| s[k] - b[k]);
        let l = norm(&d);
        let (phi, psi) = angles_of_axis(&mat_t_vec(&rz(al), &d.map(|c| c / l)));
        q[i] = l;
        q[PHI + i] = phi;
        q[PSI + i] = psi;
        base[i] = b;
        top[i] = s;
    }
    Ik {
        q,
        base,
        top,
        n,
        r,
        axis,
    }
}

/// The tool pose from the central leg and the wrist by the product of rotations.
fn oracle_fk(a1: f64, a2: f64, r: f64, w1: f64, w2: f64) -> [f64; 5] {
    let rp = mat_mul(&rx(a1), &ry(a2));
    let rt = mat_mul(&mat_mul(&rp, &rx(w1)), &ry(w2));
    let c = mat_vec(&rp, &[0.0, 0.0, r + HW]);
    let u = mat_vec(&rt, &[0.0, 0.0, 1.0]);
    let (rx_, ry_) = angles_of_axis(&u);
    [
        c[0] + LT * u[0],
        c[1] + LT * u[1],
        c[2] + LT * u[2],
        rx_,
        ry_,
    ]
}

/// The potential energy of the model's bodies (gravity +9.81 along z: Pi = -g sum m z).
fn potential(pose: &[f64; 5]) -> f64 {
    let cyl = |rho: f64, r: f64, l: f64| rho * PI * r * r * l;
    let ik = oracle_ik(pose);
    let z = |s: f64| s * ik.n[2]; // height of a point at distance s along the ram's axis
    let mut mz = cyl(2700.0, 0.08, 0.6) * z(0.3) // tube
        + cyl(2700.0, 0.05, 0.9) * z(ik.r - 0.45) // ram
        + cyl(7800.0, 0.25, 0.05) * z(ik.r) // platform
        + 2700.0 * 0.2f64.powi(3) * z(ik.r + HW) // wrist head
        + cyl(7800.0, 0.06, LT) * (z(ik.r + HW) + LT / 2.0 * ik.axis[2]); // spindle
    for i in 0..3 {
        let (b, s, l) = (ik.base[i], ik.top[i], ik.q[i]);
        let dir_z = (s[2] - b[2]) / l;
        mz += cyl(7800.0, 0.05, 0.6) * (b[2] + 0.3 * dir_z)
            + cyl(7800.0, 0.03, 0.8) * (s[2] - 0.4 * dir_z);
    }
    -G * mz
}

fn random_pose(rng: &mut Rng) -> [f64; 5] {
    let amp = [0.1, 0.1, 0.05, 0.2, 0.2];
    std::array::from_fn(|k| HOME[k] + amp[k] * rng.sym())
}

fn actuated(q: &[f64; 14]) -> [f64; 5] {
    [q[0], q[1], q[2], q[W1], q[W1 + 1]]
}

#[test]
fn hybrid_tricept_ik_matches_the_closed_form_and_fk_round_trips() {
    let model = Model::new(HybridTricept::default());
    let mut data = Data::new(&model);
    let outputs = model.structure().outputs;
    let mut rng = Rng::new(0x7_21ce);
    let (mut ik_err, mut fk_err, mut wrist_err) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..200 {
        let pose = random_pose(&mut rng);
        let ik = oracle_ik(&pose);
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &pose)
            .unwrap_or_else(|e| panic!("IK at {pose:?}: {e}"));
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        for k in 0..14 {
            ik_err = ik_err.max((data.x[k] - ik.q[k]).abs());
        }
        // FK from the home assembly with the oracle's leg lengths and wrist angles.
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &actuated(&ik.q))
            .unwrap_or_else(|e| panic!("FK at {:?}: {e}", actuated(&ik.q)));
        let x = data.x;
        let by_rotations = oracle_fk(x[A1], x[A1 + 1], x[A1 + 2], x[W1], x[W1 + 1]);
        for (k, &o) in outputs.iter().enumerate() {
            fk_err = fk_err.max((x[o] - pose[k]).abs());
            wrist_err = wrist_err.max((x[o] - by_rotations[k]).abs());
        }
    }
    println!(
        "hybrid_tricept: IK vs closed form {ik_err:.1e}, FK pose {fk_err:.1e}, \
         FK vs product of rotations {wrist_err:.1e}"
    );
    assert!(ik_err <= 1e-12, "IK error {ik_err:e}");
    assert!(fk_err <= 1e-12, "FK pose error {fk_err:e}");
    assert!(wrist_err <= 1e-12, "FK vs rotations {wrist_err:e}");
}

#[test]
fn hybrid_tricept_static_forces_match_virtual_work() {
    let model = Model::new(HybridTricept::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x7_21cf);
    let (mut worst, mut scale) = (0.0f64, 0.0f64);
    for _ in 0..20 {
        let pose = random_pose(&mut rng);
        data.set_home(&model);
        inverse_kinematics(&model, &mut data, &pose).expect("IK");
        forward_velocity(&model, &mut data, &[0.0; 5]).expect("velocity");
        forward_acceleration(&model, &mut data, &[0.0; 5]).expect("acceleration");
        inverse_dynamics(&model, &mut data, None).expect("inverse dynamics");
        let u: Vec<f64> = data.u().to_vec();
        let h = 1e-6;
        for k in 0..5 {
            let (mut pp, mut pm) = (pose, pose);
            pp[k] += h;
            pm[k] -= h;
            let (qp, qm) = (actuated(&oracle_ik(&pp).q), actuated(&oracle_ik(&pm).q));
            let work: f64 = (0..5).map(|i| u[i] * (qp[i] - qm[i]) / (2.0 * h)).sum();
            let dpi = (potential(&pp) - potential(&pm)) / (2.0 * h);
            worst = worst.max((work - dpi).abs());
            scale = scale.max(dpi.abs());
        }
    }
    println!(
        "hybrid_tricept: static forces vs virtual work {worst:.1e} (dPi/dp up to {scale:.2e})"
    );
    assert!(worst < 1e-7 * scale, "virtual work mismatch {worst:e}");
}

#[test]
fn hybrid_tricept_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    let req = RoundTripRequest {
        model: "hybrid_tricept".to_string(),
        trajectory: None,
        t_end: None,
        integrate: IntegrateOptions::new(Method::dopri5(1e-12, 1e-14), Stabilization::Projection),
        out: out.to_string_lossy().into_owned(),
    };
    let s = roundtrip_command(&req).unwrap_or_else(|e| panic!("{e}"));
    println!(
        "hybrid_tricept round trip: max output error {:.3e}",
        s.max_output_error
    );
    assert!(s.max_output_error <= 1e-9, "{:e}", s.max_output_error);
}
