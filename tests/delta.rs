//! The delta robot (models/delta.toml) against an oracle written here from Williams' geometry
//! and nothing of rbss's generated code: the standard closed-form inverse kinematics, one arm
//! at a time (the elbow on the sphere of radius l about the platform joint), and from it the
//! forearm's universal-joint angles.
//!
//! Checked: inverse kinematics (every coordinate, not only the actuated angles) against the
//! closed form, forward kinematics from the closed-form angles back to the pose, and the
//! inverse dynamics at rest against virtual work on the closed form (gravity only: the torques
//! that hold the robot, from the potential energy and the Jacobian of the closed-form IK).

mod common;

use common::{Rng, max_diff, static_forces};
use delta::{Delta, N};
use rbss_runtime::{Data, Model, forward_kinematics, inverse_dynamics, inverse_kinematics};

/// Williams (2015): the ABB IRB 360-1600's s_B, s_P, L, l.
const S_BASE: f64 = 0.567;
const S_PLATFORM: f64 = 0.076;
const L_ARM: f64 = 0.524;
const L_FOREARM: f64 = 1.244;
const HOME: [f64; 3] = [0.0, 0.0, -1.1];

/// The closed-form inverse kinematics: `[th1, b1, c1, th2, b2, c2, th3, b3, c3]` of the
/// platform position `p` (the elbow-out assembly of the model's home).
fn closed_form_ik(p: &[f64; 3]) -> [f64; 9] {
    let w_base = 3f64.sqrt() / 6.0 * S_BASE;
    let w_platform = 3f64.sqrt() / 6.0 * S_PLATFORM;
    let mut out = [0.0; 9];
    for (i, deg) in [0.0f64, 120.0, 240.0].into_iter().enumerate() {
        let (sa, ca) = deg.to_radians().sin_cos();
        // The platform joint in the leg's frame (rotated by -alpha), from the actuator axis.
        let u = ca * p[0] + sa * p[1] + w_platform - w_base;
        let v = -sa * p[0] + ca * p[1];
        let w = p[2];
        // Elbow (w_base + L cos th, 0, -L sin th): |joint - elbow| = l gives
        // A cos th + B sin th = C.
        let a = -2.0 * u * L_ARM;
        let b = 2.0 * w * L_ARM;
        let c = L_FOREARM * L_FOREARM - (u * u + v * v + w * w + L_ARM * L_ARM);
        let th = b.atan2(a) + (c / a.hypot(b)).acos();
        let (st, ct) = th.sin_cos();
        // The forearm's direction (platform joint - elbow) / l in the leg's frame, then in the
        // arm's (Ry(th) transposed); the rod is Ry(b) Rx(c) (0, 0, -1) =
        // (-sin b cos c, sin c, -cos b cos c).
        let d = [
            (u - L_ARM * ct) / L_FOREARM,
            v / L_FOREARM,
            (w + L_ARM * st) / L_FOREARM,
        ];
        let da = [ct * d[0] - st * d[2], d[1], st * d[0] + ct * d[2]];
        out[3 * i] = th;
        out[3 * i + 1] = (-da[0]).atan2(-da[2]);
        out[3 * i + 2] = da[1].asin();
    }
    out
}

/// A random platform position in the working volume: 0.3 m about the home horizontally, from
/// 0.95 m to 1.25 m below the base.
fn random_pose(rng: &mut Rng) -> [f64; 3] {
    [
        HOME[0] + 0.3 * rng.sym(),
        HOME[1] + 0.3 * rng.sym(),
        HOME[2] + 0.15 * rng.sym(),
    ]
}

/// The model's assumed masses (models/delta.toml).
const M_ARM: f64 = 0.6;
const M_FOREARM: f64 = 0.3;
const M_PLATFORM: f64 = 0.6;

/// Potential energy from the closed form: each arm's centre of mass at its middle, each
/// rod's midway between the elbow and the platform joint (at the platform's height).
fn potential(p: &[f64; 3]) -> f64 {
    let x = closed_form_ik(p);
    let mut v = M_PLATFORM * p[2];
    for i in 0..3 {
        let elbow_z = -L_ARM * x[3 * i].sin();
        v += M_ARM * 0.5 * elbow_z + M_FOREARM * 0.5 * (elbow_z + p[2]);
    }
    9.81 * v
}

#[test]
fn delta_ik_matches_the_closed_form() {
    let model = Model::new(Delta::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0xde17a);
    let mut err = 0.0f64;
    for _ in 0..200 {
        let p = random_pose(&mut rng);
        let want = closed_form_ik(&p);
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &p)
            .unwrap_or_else(|e| panic!("IK at {p:?}: {e}"));
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        err = err.max(max_diff(&data.x[..9], &want));
        assert_eq!(&data.x[9..N], &p, "the outputs are held");
    }
    println!("delta: IK vs the closed form {err:.1e} rad");
    assert!(err <= 1e-12, "IK error {err:e}");
}

#[test]
fn delta_fk_round_trips_the_closed_form() {
    let model = Model::new(Delta::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0xde17b);
    let mut err = 0.0f64;
    for _ in 0..200 {
        let p = random_pose(&mut rng);
        let x = closed_form_ik(&p);
        let q = [x[0], x[3], x[6]];
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &q).unwrap_or_else(|e| panic!("FK at {q:?}: {e}"));
        // The pose, and the passive joints too.
        err = err.max(max_diff(&data.x[9..], &p));
        err = err.max(max_diff(&data.x[..9], &x));
    }
    println!("delta: FK from the closed-form angles back to the pose {err:.1e}");
    assert!(err <= 1e-12, "FK error {err:e}");
}

#[test]
fn delta_static_inverse_dynamics_matches_virtual_work() {
    let model = Model::new(Delta::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0xde17c);
    let (mut err, mut scale) = (0.0f64, 0.0f64);
    for _ in 0..50 {
        let o = random_pose(&mut rng);
        let want = static_forces(
            &o,
            |p: &[f64; 3]| {
                let x = closed_form_ik(p);
                [x[0], x[3], x[6]]
            },
            potential,
        );
        data.set_home(&model);
        inverse_kinematics(&model, &mut data, &o).expect("IK");
        data.xdot = [0.0; N];
        data.xddot = [0.0; N];
        inverse_dynamics(&model, &mut data, None).expect("inverse dynamics");
        err = err.max(max_diff(data.u(), &want));
        scale = want.iter().fold(scale, |m, u| m.max(u.abs()));
    }
    println!("delta: static inverse dynamics vs virtual work {err:.1e} (forces up to {scale:.2})");
    assert!(err <= 1e-7 * scale, "static ID error {err:e}");
}
