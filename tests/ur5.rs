//! The UR5 (models/ur5.toml), a serial arm whose outputs are its flange's pose (a task frame on
//! link 6, URDF's xyz-rpy), through the same runtime as the parallel robots, against oracles written here from UR's published
//! parameters and nothing of rbss's generated code:
//!
//! - forward kinematics by the product of the standard DH transforms;
//! - inverse dynamics by recursive Newton-Euler (world axes, moments about each joint).
//!
//! Checked: IK (pose -> joints) and FK (joints -> pose) against the DH product, the inverse
//! dynamics' joint torques against Newton-Euler, and forward dynamics under those torques giving
//! back the joint accelerations.

// Vectors and matrices over index triples read best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod common;

use common::Rng;
use common::la3::{M3, V3, add, cross, dot, mat_mul, mat_vec, scale, sub};
use rbss_runtime::{
    Baumgarte, Data, Model, SolverError, forward_acceleration, forward_dynamics,
    forward_kinematics, forward_velocity, inverse_dynamics, inverse_kinematics,
};
use ur5::{N, Ur5};

const D: [f64; 6] = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823];
const A: [f64; 6] = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0];
const ALPHA: [f64; 6] = [
    std::f64::consts::FRAC_PI_2,
    0.0,
    0.0,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    0.0,
];
const MASS: [f64; 6] = [3.7, 8.393, 2.33, 1.219, 1.219, 0.1879];
const COM: [[f64; 3]; 6] = [
    [0.0, -0.02561, 0.00193],
    [0.2125, 0.0, 0.11336],
    [0.15, 0.0, 0.0265],
    [0.0, -0.0018, 0.01634],
    [0.0, 0.0018, 0.01634],
    [0.0, 0.0, -0.001159],
];
const R_LINK: f64 = 0.054;
const L_WRIST: f64 = 0.12;
const HOME_Q: [f64; 6] = [0.2, -1.3, 1.5, -1.8, -1.57, 0.3];

/// World frames (R, p) of the DH frames 0..=6 (frame 0 the base).
fn dh_frames(q: &[f64; 6]) -> Vec<(M3, V3)> {
    let mut out = vec![(
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [0.0; 3],
    )];
    for i in 0..6 {
        let (r, p) = *out.last().unwrap();
        let (st, ct) = q[i].sin_cos();
        let (sa, ca) = ALPHA[i].sin_cos();
        // Rz(theta) Tz(d) Tx(a) Rx(alpha)
        let t = [
            [ct, -st * ca, st * sa],
            [st, ct * ca, -ct * sa],
            [0.0, sa, ca],
        ];
        let o = [A[i] * ct, A[i] * st, D[i]];
        out.push((mat_mul(&r, &t), add(&p, &mat_vec(&r, &o))));
    }
    out
}

/// The pose (x, y, z, roll, pitch, yaw) of the flange, R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's
/// rpy, pitch in [-pi/2, pi/2]).
fn dh_pose(q: &[f64; 6]) -> [f64; 6] {
    let (r, p) = dh_frames(q)[6];
    let roll = r[2][1].atan2(r[2][2]);
    let pitch = (-r[2][0]).atan2(r[0][0].hypot(r[1][0]));
    let yaw = r[1][0].atan2(r[0][0]);
    [p[0], p[1], p[2], roll, pitch, yaw]
}

/// The links' inertia about their centres of mass in their DH axes (the model's cylinders).
fn inertia(i: usize) -> M3 {
    let m = MASS[i];
    let (axial, across) = match i {
        1 | 2 => {
            let l = A[i].abs();
            (
                m * R_LINK * R_LINK / 2.0,
                m * (3.0 * R_LINK * R_LINK + l * l) / 12.0,
            )
        }
        _ => (
            m * R_LINK * R_LINK / 2.0,
            m * (3.0 * R_LINK * R_LINK + L_WRIST * L_WRIST) / 12.0,
        ),
    };
    let d = if i == 1 || i == 2 {
        [axial, across, across]
    } else {
        [across, across, axial]
    };
    [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
}

/// Joint torques by recursive Newton-Euler in world axes, gravity (0, 0, -9.81).
fn rnea(q: &[f64; 6], qd: &[f64; 6], qdd: &[f64; 6]) -> [f64; 6] {
    let g = [0.0, 0.0, -9.81];
    let fr = dh_frames(q);
    let (mut w, mut al, mut acc) = ([0.0; 3], [0.0; 3], [0.0; 3]); // frame 0 at rest
    let mut force = [[0.0; 3]; 6];
    let mut moment = [[0.0; 3]; 6];
    let mut com = [[0.0; 3]; 6];
    for i in 0..6 {
        let z = [fr[i].0[0][2], fr[i].0[1][2], fr[i].0[2][2]];
        let w_new = add(&w, &scale(qd[i], &z));
        let al_new = add(&add(&al, &scale(qdd[i], &z)), &cross(&w, &scale(qd[i], &z)));
        let dp = sub(&fr[i + 1].1, &fr[i].1);
        // acceleration of frame i+1's origin (moves rigidly with link i+1)
        acc = add(
            &add(&acc, &cross(&al_new, &dp)),
            &cross(&w_new, &cross(&w_new, &dp)),
        );
        w = w_new;
        al = al_new;
        let r = fr[i + 1].0;
        let c = add(&fr[i + 1].1, &mat_vec(&r, &COM[i]));
        let rc = sub(&c, &fr[i + 1].1);
        let ac = add(&add(&acc, &cross(&al, &rc)), &cross(&w, &cross(&w, &rc)));
        force[i] = scale(MASS[i], &sub(&ac, &g));
        let rt: M3 = std::array::from_fn(|a| std::array::from_fn(|b| r[b][a]));
        let iw = mat_mul(&mat_mul(&r, &inertia(i)), &rt);
        moment[i] = add(&mat_vec(&iw, &al), &cross(&w, &mat_vec(&iw, &w)));
        com[i] = c;
    }
    let mut tau = [0.0; 6];
    let (mut f_next, mut n_next) = ([0.0; 3], [0.0; 3]);
    for i in (0..6).rev() {
        let o = fr[i].1; // joint i's axis passes through frame i's origin
        let f = add(&force[i], &f_next);
        let n = add(
            &add(
                &add(&moment[i], &n_next),
                &cross(&sub(&com[i], &o), &force[i]),
            ),
            &cross(&sub(&fr[i + 1].1, &o), &f_next),
        );
        let z = [fr[i].0[0][2], fr[i].0[1][2], fr[i].0[2][2]];
        tau[i] = dot(&n, &z);
        f_next = f;
        n_next = n;
    }
    tau
}

fn perturbed(rng: &mut Rng, scale: f64) -> [f64; 6] {
    std::array::from_fn(|i| HOME_Q[i] + scale * rng.sym())
}

#[test]
fn ur5_ik_and_fk_match_the_dh_product() {
    let model = Model::new(Ur5::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(55);
    let (mut ik_err, mut fk_err) = (0.0f64, 0.0f64);
    for _ in 0..100 {
        let q = perturbed(&mut rng, 0.3);
        let pose = dh_pose(&q);
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &pose)
            .unwrap_or_else(|e| panic!("IK at {pose:?}: {e}"));
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        for i in 0..6 {
            ik_err = ik_err.max((data.x[i] - q[i]).abs());
        }
        // FK from the home assembly.
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &q).unwrap_or_else(|e| panic!("FK at {q:?}: {e}"));
        for (k, &o) in model.structure().outputs.iter().enumerate() {
            let mut d = data.x[o] - pose[k];
            if k >= 3 {
                // An angle: FK may land on the same orientation 2 pi away (the roll is near pi).
                d = (d + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
            }
            fk_err = fk_err.max(d.abs());
        }
    }
    println!("UR5: IK joints vs DH {ik_err:.1e} rad, FK pose vs DH {fk_err:.1e}");
    assert!(ik_err < 1e-10, "IK joint error {ik_err:e}");
    assert!(fk_err < 1e-10, "FK pose error {fk_err:e}");
}

/// Poses out of the arm's reach are reported as such (`SolverError::Unreachable`), with a least
/// residual no smaller than the distance the tool cannot cover: the flange is at most
/// `|a2| + |a3| + d4 + d5 + d6` from the shoulder (frame 1's origin, at height d1), and the
/// position rows' max norm is at least their 2-norm over sqrt 3.
#[test]
fn ur5_out_of_reach_poses_are_reported_unreachable() {
    let model = Model::new(Ur5::default());
    let mut data = Data::new(&model);
    let reach = A[1].abs() + A[2].abs() + D[3] + D[4] + D[5];
    let angles = &dh_pose(&HOME_Q)[3..];
    for target in [[2.0, 0.0, 0.5], [0.0, -1.5, 1.2], [0.3, 0.2, -1.6]] {
        let gap = dot(
            &sub(&target, &[0.0, 0.0, D[0]]),
            &sub(&target, &[0.0, 0.0, D[0]]),
        )
        .sqrt()
            - reach;
        assert!(gap > 0.3, "{target:?} is not out of reach");
        let pose: Vec<f64> = target.iter().chain(angles).copied().collect();
        data.set_home(&model);
        match inverse_kinematics(&model, &mut data, &pose) {
            Err(SolverError::Unreachable { block: 0, residual }) => {
                println!("UR5 {target:?}: {gap:.3} m out of reach, least max |f| {residual:.4}");
                assert!(
                    residual >= gap / 3f64.sqrt(),
                    "{target:?}: residual {residual}"
                );
            }
            other => panic!("{target:?}: expected Unreachable, got {other:?}"),
        }
    }
}

#[test]
fn ur5_dynamics_match_newton_euler() {
    let model = Model::new(Ur5::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(56);
    let (mut id_err, mut fd_err, mut tau_max) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..50 {
        let q = perturbed(&mut rng, 0.3);
        let qd: [f64; 6] = std::array::from_fn(|_| 1.5 * rng.sym());
        let qdd: [f64; 6] = std::array::from_fn(|_| 3.0 * rng.sym());
        // The full state from the joints: X by FK, Xdot and Xddot by the velocity and
        // acceleration solvers (the pose's rates follow from the joints').
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &q).expect("FK");
        forward_velocity(&model, &mut data, &qd).expect("velocity");
        forward_acceleration(&model, &mut data, &qdd).expect("acceleration");
        inverse_dynamics(&model, &mut data, None).expect("inverse dynamics");
        let u: Vec<f64> = data.u().to_vec();
        let tau = rnea(&q, &qd, &qdd);
        for i in 0..6 {
            id_err = id_err.max((u[i] - tau[i]).abs());
            tau_max = tau_max.max(tau[i].abs());
        }
        // Forward dynamics under those torques: the joint accelerations come back.
        let xddot_id: [f64; N] = data.xddot;
        data.xddot = [0.0; N];
        forward_dynamics(&model, &mut data, &u, None, Baumgarte::default()).expect("FD");
        for i in 0..N {
            fd_err = fd_err.max((data.xddot[i] - xddot_id[i]).abs());
        }
    }
    println!(
        "UR5: inverse dynamics vs Newton-Euler {id_err:.1e} N m (torques up to {tau_max:.1} N m), \
         ID -> FD Xddot {fd_err:.1e}"
    );
    assert!(id_err < 1e-10 * tau_max, "ID torque error {id_err:e}");
    assert!(fd_err < 1e-10, "FD acceleration error {fd_err:e}");
}
