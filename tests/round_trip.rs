//! Kinematics end to end on the generated robots: IK -> FK round trips, and the velocity and
//! acceleration solvers along the paper's TraekP against finite differences in time.

mod common;

use common::{Rng, assert_close};
use rbss::paper::{OMEGA, T_END, traek_p};
use rbss_runtime::{
    Data, Kernels, Model, forward_acceleration, forward_kinematics, forward_velocity,
    inverse_acceleration, inverse_kinematics, inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

fn q_of<K: Kernels<N, M>, const N: usize, const M: usize>(
    m: &Model<K, N, M>,
    x: &[f64; N],
) -> Vec<f64> {
    m.structure().actuated.iter().map(|&j| x[j]).collect()
}

/// IK at random poses around the paper's workspace, then FK from a perturbed start: FK returns
/// the IK configuration to 1e-10 (Newton converges quadratically to ~1e-15; the margin covers
/// the conditioning of J_p, cond < 1e3 here).
#[test]
fn stewart_ik_fk_round_trip() {
    let model = Model::new(Stewart6Ups::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(7);
    let mut max_err: f64 = 0.0;
    for _ in 0..200 {
        let pose = [
            0.15 * rng.sym(),
            0.15 * rng.sym(),
            0.94 + 0.08 * rng.sym(),
            0.15 * rng.sym(),
            0.15 * rng.sym(),
            0.15 * rng.sym(),
        ];
        data.set_home(&model);
        let rep = inverse_kinematics(&model, &mut data, &pose).expect("reachable pose");
        assert!(rep.residual < 1e-12, "IK residual {}", rep.residual);
        let x_ik = data.x;
        let q = q_of(&model, &x_ik);
        // FK from a start 0.02 away in every passive coordinate.
        for &j in model.structure().passive {
            data.x[j] += 0.02 * rng.sym();
        }
        let rep = forward_kinematics(&model, &mut data, &q).expect("FK converges");
        assert!(
            rep.iterations <= 8,
            "FK took {} Newton steps",
            rep.iterations
        );
        for (a, b) in data.x.iter().zip(&x_ik) {
            max_err = max_err.max((a - b).abs());
        }
    }
    assert!(max_err < 1e-10, "IK -> FK round trip error {max_err:e}");
}

#[test]
fn five_bar_ik_fk_round_trip() {
    let model = Model::new(five_bar::FiveBar::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(11);
    for _ in 0..200 {
        let pose = [0.08 * rng.sym(), 0.3 + 0.05 * rng.sym()];
        data.set_home(&model);
        inverse_kinematics(&model, &mut data, &pose)
            .unwrap_or_else(|e| panic!("pose {pose:?}: {e}"));
        let x_ik = data.x;
        let q = q_of(&model, &x_ik);
        for &j in model.structure().passive {
            data.x[j] += 0.01 * rng.sym();
        }
        forward_kinematics(&model, &mut data, &q).expect("FK converges");
        for (a, b) in data.x.iter().zip(&x_ik) {
            assert_close("five_bar round trip", *a, *b, 0.0, 1e-10);
        }
    }
}

/// Along TraekP: inverse velocity and acceleration against central differences in time of the
/// IK solution (h = 1e-4 s: truncation ~ h^2 |X'''| ~ 1e-7, rounding ~ 1e-15 / h ~ 1e-11), and
/// forward velocity and acceleration from the actuated rates give back the same Xdot, Xddot.
#[test]
fn stewart_velocity_and_acceleration_along_traek_p() {
    let model = Model::new(Stewart6Ups::default());
    let mut data = Data::new(&model);
    let mut probe = Data::new(&model);
    let h = 1e-4;
    let ik_at = |d: &mut Data<24, 18>, t: f64| {
        let (pose, _, _) = traek_p(t, OMEGA);
        inverse_kinematics(&model, d, &pose).expect("TraekP is reachable");
        d.x
    };
    for k in 0..=40 {
        let t = T_END * k as f64 / 40.0;
        let (pose, vel, acc) = traek_p(t, OMEGA);
        inverse_kinematics(&model, &mut data, &pose).unwrap();
        inverse_velocity(&model, &mut data, &vel).unwrap();
        inverse_acceleration(&model, &mut data, &acc).unwrap();
        probe.x = data.x;
        let xp = ik_at(&mut probe, t + h);
        let xm = ik_at(&mut probe, t - h);
        for j in 0..stewart_6ups::N {
            let v_num = (xp[j] - xm[j]) / (2.0 * h);
            let a_num = (xp[j] - 2.0 * data.x[j] + xm[j]) / (h * h);
            assert_close(
                &format!("t = {t}: Xdot[{j}]"),
                data.xdot[j],
                v_num,
                1e-6,
                1e-6,
            );
            assert_close(
                &format!("t = {t}: Xddot[{j}]"),
                data.xddot[j],
                a_num,
                1e-5,
                1e-4,
            );
        }

        // Forward: from q, qdot, qddot of the inverse solution.
        let (x, xdot, xddot) = (data.x, data.xdot, data.xddot);
        let s = model.structure();
        let q: Vec<f64> = s.actuated.iter().map(|&j| x[j]).collect();
        let qd: Vec<f64> = s.actuated.iter().map(|&j| xdot[j]).collect();
        let qdd: Vec<f64> = s.actuated.iter().map(|&j| xddot[j]).collect();
        forward_kinematics(&model, &mut data, &q).unwrap();
        forward_velocity(&model, &mut data, &qd).unwrap();
        forward_acceleration(&model, &mut data, &qdd).unwrap();
        for j in 0..stewart_6ups::N {
            assert_close("forward X", data.x[j], x[j], 0.0, 1e-12);
            assert_close("forward Xdot", data.xdot[j], xdot[j], 1e-10, 1e-12);
            assert_close("forward Xddot", data.xddot[j], xddot[j], 1e-9, 1e-10);
        }
    }
}
