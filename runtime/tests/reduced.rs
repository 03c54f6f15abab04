//! Forward kinematics by elimination onto the outputs (the 6-UPS's 18 × 18 `J_p` through its
//! six 3 × 2 leg blocks and the 6 × 6 inverse Jacobian): the solution against the inverse
//! kinematics it must undo, the reported condition number against the exact one of the dense
//! `J_p`, and the velocity solve against the dense one.

mod common;

use common::{XorShift, random_stewart_pose};
use nalgebra::DMatrix;
use rbss_runtime::{
    Data, Kernels, Model, SolverOptions, forward_kinematics, forward_velocity, inverse_kinematics,
    inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

const N: usize = 24;
const M: usize = 18;

/// `‖J_p‖₁ ‖J_p⁻¹‖₁` of the dense `J_p` at `x`, by nalgebra's LU inverse.
fn exact_cond(model: &Model<Stewart6Ups, N, M>, x: &[f64; N]) -> f64 {
    let mut g = [[0.0; M]; N];
    model.kernels().jacobian(x, &mut g);
    let passive = model.structure().passive;
    let jp = DMatrix::from_fn(M, M, |r, c| g[passive[c]][r]);
    let inv = jp.clone().try_inverse().expect("regular J_p");
    let norm1 = |a: &DMatrix<f64>| {
        a.column_iter()
            .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    norm1(&jp) * norm1(&inv)
}

/// Measured over 200 poses: FK returns the IK solution to 1.4e-15 (max over coordinates), the
/// reported cond(J_p) is within 1.2e-15 (relative) of the dense exact value (99 to 108), and
/// forward velocity agrees with inverse velocity to 2.0e-15 (relative).
#[test]
fn forward_kinematics_undoes_inverse_kinematics_with_the_exact_condition_number() {
    let model = Model::new(Stewart6Ups::default()).with_options(SolverOptions {
        exact_cond: true,
        ..SolverOptions::default()
    });
    let s = model.structure();
    let mut rng = XorShift(0x2009_FEED);
    let (mut worst_x, mut worst_cond, mut worst_v) = (0.0_f64, 0.0_f64, 0.0_f64);
    let (mut cmin, mut cmax) = (f64::INFINITY, 0.0_f64);
    for _ in 0..200 {
        let pose = random_stewart_pose(&mut rng);
        let mut ik = Data::new(&model);
        inverse_kinematics(&model, &mut ik, &pose).unwrap();
        let q: Vec<f64> = s.actuated.iter().map(|&j| ik.x[j]).collect();
        // Warm start: the solution disturbed by up to 1e-2 in every passive coordinate.
        let mut fk = Data::new(&model);
        fk.x = ik.x;
        for &j in s.passive {
            fk.x[j] += rng.range(-1e-2, 1e-2);
        }
        let rep = forward_kinematics(&model, &mut fk, &q).unwrap();
        let dx =
            fk.x.iter()
                .zip(&ik.x)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        worst_x = worst_x.max(dx);
        let exact = exact_cond(&model, &fk.x);
        worst_cond = worst_cond.max((rep.cond - exact).abs() / exact);
        cmin = cmin.min(exact);
        cmax = cmax.max(exact);

        // Velocity: forward with the actuated rates of an inverse velocity solve.
        let od: [f64; 6] = core::array::from_fn(|_| rng.range(-0.5, 0.5));
        inverse_velocity(&model, &mut ik, &od).unwrap();
        let qd: Vec<f64> = s.actuated.iter().map(|&j| ik.xdot[j]).collect();
        forward_velocity(&model, &mut fk, &qd).unwrap();
        let sv = ik.xdot.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let dv = fk
            .xdot
            .iter()
            .zip(&ik.xdot)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        worst_v = worst_v.max(dv / sv);
    }
    println!(
        "200 poses: |x - x_ik| {worst_x:.1e}, cond rel. error {worst_cond:.1e} (cond {cmin:.0} to \
         {cmax:.0}), velocity rel. error {worst_v:.1e}"
    );
    assert!(worst_x < 1e-13, "{worst_x:e}");
    assert!(worst_cond < 1e-10, "{worst_cond:e}");
    assert!(worst_v < 1e-13, "{worst_v:e}");
}
