//! The planar 3-RRR (models/planar_3rrr.toml) against an oracle written here from the model's
//! geometry and nothing of rbss's generated code: each leg's closed-form inverse kinematics
//! (the elbow on the circles of radius l1 about the base joint and l2 about the platform
//! joint, the assembly of the model's home).
//!
//! Checked: inverse kinematics (every coordinate) against the closed form, and forward
//! kinematics from the closed-form angles back to the pose.

mod common;

use common::{Rng, max_diff};
use planar_3rrr::{N, Planar3Rrr};
use rbss_runtime::{Data, Model, forward_kinematics, inverse_kinematics};

const R_BASE: f64 = 0.3;
const R_PLATFORM: f64 = 0.1;
const L1: f64 = 0.2;
const L2: f64 = 0.2;

/// An angle in (-pi, pi].
fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w == -std::f64::consts::PI {
        std::f64::consts::PI
    } else {
        w
    }
}

/// The closed-form inverse kinematics: `[th1, a1, th2, a2, th3, a3]` of the pose
/// `(x, y, phi)`.
fn closed_form_ik(pose: &[f64; 3]) -> [f64; 6] {
    let [x, y, phi] = *pose;
    let mut out = [0.0; 6];
    for (i, deg) in [90.0f64, 210.0, 330.0].into_iter().enumerate() {
        let alpha = deg.to_radians();
        let base = [R_BASE * alpha.cos(), R_BASE * alpha.sin()];
        let joint = [
            x + R_PLATFORM * (alpha + phi).cos(),
            y + R_PLATFORM * (alpha + phi).sin(),
        ];
        let (dx, dy) = (joint[0] - base[0], joint[1] - base[1]);
        let dist = dx.hypot(dy);
        let gamma = ((L1 * L1 + dist * dist - L2 * L2) / (2.0 * L1 * dist)).acos();
        // The proximal link's world angle alpha + th: the elbow on the home's side.
        let psi = dy.atan2(dx) - gamma;
        let elbow = [base[0] + L1 * psi.cos(), base[1] + L1 * psi.sin()];
        let chi = (joint[1] - elbow[1]).atan2(joint[0] - elbow[0]);
        out[2 * i] = wrap(psi - alpha);
        out[2 * i + 1] = wrap(chi - psi);
    }
    out
}

/// A random pose: 5 cm about the centre, turned by up to 0.3 rad.
fn random_pose(rng: &mut Rng) -> [f64; 3] {
    [0.05 * rng.sym(), 0.05 * rng.sym(), 0.3 * rng.sym()]
}

#[test]
fn planar_3rrr_ik_matches_the_closed_form() {
    let model = Model::new(Planar3Rrr::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x3_0001);
    let mut err = 0.0f64;
    for _ in 0..200 {
        let p = random_pose(&mut rng);
        let want = closed_form_ik(&p);
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &p)
            .unwrap_or_else(|e| panic!("IK at {p:?}: {e}"));
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        err = err.max(max_diff(&data.x[..6], &want));
        assert_eq!(&data.x[6..N], &p, "the outputs are held");
    }
    println!("planar_3rrr: IK vs the closed form {err:.1e} rad");
    assert!(err <= 1e-12, "IK error {err:e}");
}

#[test]
fn planar_3rrr_fk_round_trips_the_closed_form() {
    let model = Model::new(Planar3Rrr::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x3_0002);
    let mut err = 0.0f64;
    for _ in 0..200 {
        let p = random_pose(&mut rng);
        let x = closed_form_ik(&p);
        let q = [x[0], x[2], x[4]];
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &q).unwrap_or_else(|e| panic!("FK at {q:?}: {e}"));
        err = err.max(max_diff(&data.x[6..], &p));
        err = err.max(max_diff(&data.x[..6], &x));
    }
    println!("planar_3rrr: FK from the closed-form angles back to the pose {err:.1e}");
    assert!(err <= 1e-12, "FK error {err:e}");
}
