//! The 3-RPS tripod (models/tripod_3rps.toml) against an oracle written here from the model's
//! geometry and nothing of rbss's generated code: the parasitic motion in closed form, then
//! the leg lengths and angles from the platform pose.
//!
//! The parasitic motion: each revolute joint keeps its platform joint P_i in the leg's vertical
//! plane, `P_i . t_i = 0` with `t_i = (-sin alpha_i, cos alpha_i, 0)`. With
//! `P_i = p + R p_i`, `R = Rx(rotx) Ry(roty) Rz(rotz)` and `p_i = r_p (cos alpha_i, sin alpha_i, 0)`
//! at three equally spaced angles, the sum of the three conditions drops `p` (the `t_i` sum to
//! zero) and leaves `tr(J^T K Rz(rotz)) = 0` (K the upper-left 2x2 of Rx Ry, J the quarter
//! turn), i.e. `tan rotz = -sin rotx sin roty / (cos rotx + cos roty)`; then leg 1's condition
//! gives y and leg 2's x.
//!
//! Checked: inverse kinematics (every coordinate, the passive platform ones included) against
//! the closed form, forward kinematics from the closed-form leg lengths back to the pose, and
//! the inverse dynamics at rest against virtual work on the closed form (the leg forces that
//! hold the tripod, from the potential energy and the Jacobian of the closed-form IK).

mod common;

use common::la3::{M3, mat_mul};
use common::{Rng, max_diff, static_forces};
use rbss_runtime::{Data, Model, forward_kinematics, inverse_dynamics, inverse_kinematics};
use tripod_3rps::{N, Tripod3Rps};

const R_BASE: f64 = 0.2;
const R_PLATFORM: f64 = 0.1;

/// Rx(a) Ry(b) Rz(c).
fn rotation(a: f64, b: f64, c: f64) -> M3 {
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let (sc, cc) = c.sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]];
    let ry = [[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]];
    let rz = [[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]];
    mat_mul(&mat_mul(&rx, &ry), &rz)
}

/// The closed form: every coordinate `[th1, d1, th2, d2, th3, d3, x, y, z, rotx, roty, rotz]`
/// from the outputs `(z, rotx, roty)`.
fn closed_form_ik(out: &[f64; 3]) -> [f64; 12] {
    let [z, rotx, roty] = *out;
    let rotz = (-rotx.sin() * roty.sin()).atan2(rotx.cos() + roty.cos());
    let r = rotation(rotx, roty, rotz);
    let alphas = [0.0f64, 120.0, 240.0].map(f64::to_radians);
    // R p_i and t_i.
    let rp: [[f64; 3]; 3] = std::array::from_fn(|i| {
        let (s, c) = alphas[i].sin_cos();
        std::array::from_fn(|k| r[k][0] * R_PLATFORM * c + r[k][1] * R_PLATFORM * s)
    });
    let h = |i: usize| {
        let (s, c) = alphas[i].sin_cos();
        -(-s * rp[i][0] + c * rp[i][1])
    };
    // Leg 1 (alpha = 0): y = h_1; leg 2: -x sin alpha_2 + y cos alpha_2 = h_2.
    let y = h(0);
    let (s2, c2) = alphas[1].sin_cos();
    let x = (y * c2 - h(1)) / s2;
    let mut all = [0.0; 12];
    for i in 0..3 {
        let (s, c) = alphas[i].sin_cos();
        let p = [x + rp[i][0], y + rp[i][1], z + rp[i][2]];
        // In the leg's frame, from the base joint: (u, 0, w) = d (sin th, 0, cos th).
        let u = c * p[0] + s * p[1] - R_BASE;
        let w = p[2];
        all[2 * i] = u.atan2(w);
        all[2 * i + 1] = u.hypot(w);
    }
    all[6..].copy_from_slice(&[x, y, z, rotx, roty, rotz]);
    all
}

/// Random outputs: heave of 5 cm about the home height 0.4 m, tilts of up to 0.2 rad.
fn random_outputs(rng: &mut Rng) -> [f64; 3] {
    [0.4 + 0.05 * rng.sym(), 0.2 * rng.sym(), 0.2 * rng.sym()]
}

/// The model's assumed solids (models/tripod_3rps.toml): aluminium cylinders.
const RHO: f64 = 2700.0;
const L_LOWER: f64 = 0.3;
const L_UPPER: f64 = 0.3;

/// Potential energy from the closed form: the lower cylinders' centres at l_lower / 2 up the
/// leg, the pistons' at l_upper / 2 below the platform joint, the platform disc at its origin.
fn potential(o: &[f64; 3]) -> f64 {
    let pi = std::f64::consts::PI;
    let m_lower = RHO * pi * 0.03 * 0.03 * L_LOWER;
    let m_upper = RHO * pi * 0.02 * 0.02 * L_UPPER;
    let m_platform = RHO * pi * 0.12 * 0.12 * 0.02;
    let x = closed_form_ik(o);
    let mut v = m_platform * o[0];
    for i in 0..3 {
        let (th, d) = (x[2 * i], x[2 * i + 1]);
        v += m_lower * 0.5 * L_LOWER * th.cos() + m_upper * (d - 0.5 * L_UPPER) * th.cos();
    }
    9.81 * v
}

#[test]
fn tripod_3rps_ik_matches_the_closed_form() {
    let model = Model::new(Tripod3Rps::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x3_5001);
    let (mut err, mut parasitic) = (0.0f64, 0.0f64);
    for _ in 0..200 {
        let o = random_outputs(&mut rng);
        let want = closed_form_ik(&o);
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &o)
            .unwrap_or_else(|e| panic!("IK at {o:?}: {e}"));
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        err = err.max(max_diff(&data.x, &want));
        parasitic = parasitic.max(want[6].abs()).max(want[7].abs());
    }
    println!(
        "tripod_3rps: IK vs the closed form {err:.1e} (m or rad); parasitic x, y up to {parasitic:.1e} m"
    );
    // The parasitic motion is real: the test would not pass with x = y = 0.
    assert!(parasitic > 1e-3, "parasitic motion {parasitic:e}");
    assert!(err <= 1e-12, "IK error {err:e}");
}

#[test]
fn tripod_3rps_fk_round_trips_the_closed_form() {
    let model = Model::new(Tripod3Rps::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x3_5002);
    let mut err = 0.0f64;
    for _ in 0..200 {
        let o = random_outputs(&mut rng);
        let x = closed_form_ik(&o);
        let q = [x[1], x[3], x[5]];
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &q).unwrap_or_else(|e| panic!("FK at {q:?}: {e}"));
        err = err.max(max_diff(&data.x, &x));
    }
    println!("tripod_3rps: FK from the closed-form leg lengths back to the pose {err:.1e}");
    assert!(err <= 1e-12, "FK error {err:e}");
}

#[test]
fn tripod_3rps_static_inverse_dynamics_matches_virtual_work() {
    let model = Model::new(Tripod3Rps::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x3_5003);
    let (mut err, mut scale) = (0.0f64, 0.0f64);
    for _ in 0..50 {
        let o = random_outputs(&mut rng);
        let want = static_forces(
            &o,
            |o: &[f64; 3]| {
                let x = closed_form_ik(o);
                [x[1], x[3], x[5]]
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
    println!(
        "tripod_3rps: static inverse dynamics vs virtual work {err:.1e} (forces up to {scale:.2})"
    );
    assert!(err <= 1e-7 * scale, "static ID error {err:e}");
}
