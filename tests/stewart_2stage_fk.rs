//! Forward kinematics of the two-stage Stewart platform (12 outputs, twelve 3 × 3 leg blocks)
//! by elimination onto the outputs, as runtime/tests/reduced.rs checks it for the 6-UPS: the
//! solution against the inverse kinematics it must undo, the reported condition number against
//! the exact one of the dense 36 × 36 `J_p`, and forward velocity and acceleration against the
//! inverse ones. The elimination reports the exact condition number (to rounding); the dense
//! fallback only the Hager/Higham estimate. With the generated elimination
//! (`Kernels::forward_rates_solve`, taken by the Newton steps before the last) and without it.

mod common;

use common::{Rng, two_stage};
use rbss::paper::T_END;
use rbss_runtime::{
    Data, Kernels, Model, SolverOptions, Structure, forward_acceleration, forward_kinematics,
    forward_velocity, inverse_acceleration, inverse_kinematics, inverse_velocity,
};
use stewart_2stage::Stewart2Stage;

const N: usize = 48;
const M: usize = 36;

/// `‖A‖₁ ‖A⁻¹‖₁` of the dense `J_p` at `x`, its inverse by Gauss–Jordan with partial pivoting.
fn exact_cond<K: Kernels<N, M>>(model: &Model<K, N, M>, x: &[f64; N]) -> f64 {
    let mut g = [[0.0; M]; N];
    model.kernels().jacobian(x, &mut g);
    let passive = model.structure().passive;
    // a[r][c] = J_p[r][c], inv starts as the identity.
    let mut a: Vec<Vec<f64>> = (0..M)
        .map(|r| (0..M).map(|c| g[passive[c]][r]).collect())
        .collect();
    let norm1 = |m: &[Vec<f64>]| {
        (0..M)
            .map(|c| (0..M).map(|r| m[r][c].abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    let anorm = norm1(&a);
    let mut inv: Vec<Vec<f64>> = (0..M)
        .map(|r| (0..M).map(|c| if r == c { 1.0 } else { 0.0 }).collect())
        .collect();
    for c in 0..M {
        let piv = (c..M)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap();
        a.swap(c, piv);
        inv.swap(c, piv);
        let d = a[c][c];
        assert!(d != 0.0, "singular J_p");
        for k in 0..M {
            a[c][k] /= d;
            inv[c][k] /= d;
        }
        for r in 0..M {
            if r != c && a[r][c] != 0.0 {
                let f = a[r][c];
                for k in 0..M {
                    a[r][k] -= f * a[c][k];
                    inv[r][k] -= f * inv[c][k];
                }
            }
        }
    }
    anorm * norm1(&inv)
}

/// The robot with its generated solves hidden: the runtime's elimination runs at every step.
struct RuntimeOnly(Stewart2Stage);

impl Kernels<N, M> for RuntimeOnly {
    const IK_BLOCK_ORDER: usize = Stewart2Stage::IK_BLOCK_ORDER;
    fn structure(&self) -> &'static Structure {
        self.0.structure()
    }
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        self.0.constraints(x, f)
    }
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.0.jacobian(x, g)
    }
    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.0.jacobian_p(x, g)
    }
    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.0.jacobian_ik(x, g)
    }
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; M]) {
        self.0.gamma(x, xdot, out)
    }
}

/// Over 100 poses along the two-platform motion, each disturbed by up to 1 cm and 0.03 rad per
/// output: FK from a warm start 1e-2 off in every passive coordinate returns the IK solution,
/// the reported cond(J_p) of FK, forward velocity and forward acceleration is the exact one of
/// the dense `J_p` (the elimination's, not the dense path's estimate), and forward velocity and
/// acceleration agree with the inverse ones; with and without the generated elimination.
#[test]
fn forward_kinematics_undoes_inverse_kinematics_with_the_exact_condition_number() {
    let runtime = run(&Model::new(RuntimeOnly(Stewart2Stage::default())));
    assert!(
        runtime.iter().all(|&r| (r - 1.0).abs() < 1e-12),
        "{runtime:?}"
    );
    let exact = SolverOptions {
        exact_cond: true,
        ..SolverOptions::default()
    };
    let generated = run(&Model::new(Stewart2Stage::default()).with_options(exact));
    assert!(
        generated.iter().all(|&r| (1.0 - 1e-12..=40.0).contains(&r)),
        "{generated:?}"
    );
    // By default the generated elimination reports its rigorous upper bound: never below the
    // exact value.
    let bound = run(&Model::new(Stewart2Stage::default()));
    println!("default options: reported cond / exact {bound:?}");
    assert!(bound[0] >= 1.0 - 1e-12 && bound[1] <= 100.0, "{bound:?}");
}

/// The check over the 100 poses; returns the smallest and the largest ratio of a reported
/// condition number to the exact one.
fn run<K: Kernels<N, M>>(model: &Model<K, N, M>) -> [f64; 2] {
    let s = model.structure();
    let mut rng = Rng::new(0x2_57A6_E0FC);
    let (mut worst_x, mut worst_v, mut worst_a) = (0.0_f64, 0.0_f64, 0.0_f64);
    let (mut rmin, mut rmax) = (f64::INFINITY, 0.0_f64);
    let (mut cmin, mut cmax) = (f64::INFINITY, 0.0_f64);
    let max_rel = |a: &[f64; N], b: &[f64; N]| {
        let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
            / scale
    };
    for i in 0..100 {
        let [mut pose, pose_dot, pose_ddot] = two_stage(T_END * i as f64 / 100.0);
        for (k, v) in pose.iter_mut().enumerate() {
            *v += if k % 6 < 3 { 0.01 } else { 0.03 } * rng.sym();
        }
        let mut ik = Data::new(model);
        inverse_kinematics(model, &mut ik, &pose).expect("IK");
        inverse_velocity(model, &mut ik, &pose_dot).expect("inverse velocity");
        inverse_acceleration(model, &mut ik, &pose_ddot).expect("inverse acceleration");
        let q = |v: &[f64; N]| s.actuated.iter().map(|&j| v[j]).collect::<Vec<_>>();

        let mut fk = Data::new(model);
        fk.x = ik.x;
        for &j in s.passive {
            fk.x[j] += 1e-2 * rng.sym();
        }
        let rep = forward_kinematics(model, &mut fk, &q(&ik.x)).expect("FK");
        let dx =
            fk.x.iter()
                .zip(&ik.x)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        worst_x = worst_x.max(dx);
        let exact = exact_cond(model, &fk.x);
        cmin = cmin.min(exact);
        cmax = cmax.max(exact);
        let mut ratio = |c: f64| {
            rmin = rmin.min(c / exact);
            rmax = rmax.max(c / exact);
        };
        ratio(rep.cond);

        let rep = forward_velocity(model, &mut fk, &q(&ik.xdot)).expect("forward velocity");
        ratio(rep.cond);
        worst_v = worst_v.max(max_rel(&fk.xdot, &ik.xdot));
        let rep =
            forward_acceleration(model, &mut fk, &q(&ik.xddot)).expect("forward acceleration");
        ratio(rep.cond);
        worst_a = worst_a.max(max_rel(&fk.xddot, &ik.xddot));
    }
    println!(
        "100 poses: |x - x_ik| {worst_x:.1e}, reported cond / exact {rmin:.3} to {rmax:.3} (cond \
         {cmin:.0} to {cmax:.0}), velocity rel. error {worst_v:.1e}, acceleration rel. error \
         {worst_a:.1e}"
    );
    assert!(worst_x < 1e-13, "{worst_x:e}");
    assert!(worst_v < 1e-13, "{worst_v:e}");
    assert!(worst_a < 1e-12, "{worst_a:e}");
    [rmin, rmax]
}
