//! The kinematic solves the generator emits (`ik_block_solve`, `forward_rates_solve`, codegen's
//! `solve::rates` and `solve::forward_rates`) against dense linear algebra written here, for
//! every robot, at its home and 64 seeded random states near it (`G` at any state is a matrix to
//! solve with; the constraints need not hold):
//!
//! - they run (they are not declining everywhere): at the home and at most of the states;
//! - `ik_block_solve` gives `x[cols] = K⁻¹ (rhs[rows] - G[rows, outputs] x[outputs])` to a
//!   relative 1e-10 of a dense Gaussian elimination with partial pivoting, its condition
//!   number is the exact `cond₁(K)` up to order 3 and beyond an estimate within a factor 10 of
//!   it (read off the pivots, the Hager/Higham estimate where that passes 1e3), its residual is
//!   the block's;
//! - `forward_rates_solve` gives the passive coordinates of `J_p x_p = rhs - J_q x_q` to a
//!   relative 1e-9 of the dense solve, and those of a Newton step (`x_q = 0`) without reading
//!   the actuated columns of `G` (NaN there), its condition number is an upper bound of the
//!   exact `cond₁(J_p)` (the measured ratio is printed) and, asked for, the exact value to a
//!   relative 1e-9, its residual is the system's;
//! - the solvers that take them (`inverse_velocity`, `forward_velocity`,
//!   `forward_acceleration`, `forward_kinematics`) agree with the runtime's general paths
//!   (reached by hiding the generated solves) to 1e-9;
//! - forward kinematics' chord steps (`forward_rates_keep`, `forward_rates_chord`: the
//!   elimination's factors kept from a full Newton step) give the point full Newton steps give
//!   to a relative 1e-13, with the same residual bound, and less than half the Jacobian
//!   evaluations where the generator chose them (`FR_CHORD`), the same number elsewhere.

// Matrix code: the indices say which entry, so loops over them read better than iterators.
#![allow(clippy::needless_range_loop)]

mod common;

use std::cell::Cell;

use common::Rng;
use rbss_runtime::{
    Data, Kernels, Model, Structure, forward_acceleration, forward_kinematics, forward_velocity,
    inverse_kinematics, inverse_velocity,
};

const STATES: usize = 64;

/// A robot with its generated kinematic solves hidden: the runtime's general paths run.
struct NoSolve<K>(K);

impl<K: Kernels<N, M>, const N: usize, const M: usize> Kernels<N, M> for NoSolve<K> {
    const IK_BLOCK_ORDER: usize = K::IK_BLOCK_ORDER;
    fn structure(&self) -> &'static Structure {
        self.0.structure()
    }
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        self.0.constraints(x, f)
    }
    fn closure_checks(&self) -> &'static [&'static str] {
        self.0.closure_checks()
    }
    fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
        self.0.closure_check(x, out)
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

/// A robot with or without forward kinematics' chord steps (`chord`: its
/// `forward_rates_keep` keeps nothing otherwise), counting its Jacobian evaluations.
#[derive(Clone)]
struct Chords<K> {
    k: K,
    chord: bool,
    jacobians: Cell<usize>,
}

impl<K: Kernels<N, M>, const N: usize, const M: usize> Kernels<N, M> for Chords<K> {
    const IK_BLOCK_ORDER: usize = K::IK_BLOCK_ORDER;
    fn structure(&self) -> &'static Structure {
        self.k.structure()
    }
    fn ik_block_solve(
        &self,
        block: usize,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        outputs: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        self.k.ik_block_solve(block, g, rhs, outputs, x)
    }
    fn forward_rates_solve(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        actuated: bool,
        exact: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        self.k.forward_rates_solve(g, rhs, actuated, exact, x)
    }
    fn forward_rates_keep(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        exact: bool,
        x: &mut [f64; N],
        store: &mut [f64],
    ) -> Option<([f64; 2], bool)> {
        if self.chord {
            self.k.forward_rates_keep(g, rhs, exact, x, store)
        } else {
            self.k
                .forward_rates_solve(g, rhs, false, exact, x)
                .map(|r| (r, false))
        }
    }
    fn forward_rates_chord(&self, store: &[f64], rhs: &[f64; M], x: &mut [f64; N]) -> Option<()> {
        assert!(
            self.chord,
            "a chord step after a full step that kept nothing"
        );
        self.k.forward_rates_chord(store, rhs, x)
    }
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        self.k.constraints(x, f)
    }
    fn closure_checks(&self) -> &'static [&'static str] {
        self.k.closure_checks()
    }
    fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
        self.k.closure_check(x, out)
    }
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.k.jacobian(x, g)
    }
    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.k.jacobian_p(x, g)
    }
    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        self.k.jacobian_ik(x, g)
    }
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; M]) {
        self.k.gamma(x, xdot, out)
    }
    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.k.constraints_jacobian_ik(x, f, g)
    }
    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.jacobians.set(self.jacobians.get() + 1);
        self.k.constraints_jacobian_p(x, f, g)
    }
}

/// Forward kinematics with and without chord steps from the same starts (1e-3 off in the
/// passive coordinates, then 0.05 off: a start Newton needs more steps from), the outputs
/// moved by 0.02 from the home.
fn check_chord<K: Kernels<N, M> + Clone, const N: usize, const M: usize>(
    k: K,
    seed: u64,
    chord_here: bool,
) {
    let s = k.structure();
    let name = s.name;
    let with = |chord| {
        Model::new(Chords {
            k: k.clone(),
            chord,
            jacobians: Cell::new(0),
        })
    };
    let (chord, newton) = (with(true), with(false));
    let mut rng = Rng::new(seed ^ 0xc40d);
    let (mut worst, mut solved, mut worst_res) = (0.0_f64, 0, 0.0_f64);
    for trial in 0..32 {
        let out: Vec<f64> = s
            .outputs
            .iter()
            .map(|&z| s.home[z] + 0.02 * rng.sym())
            .collect();
        let mut a = Data::new(&chord);
        if inverse_kinematics(&chord, &mut a, &out).is_err() {
            continue;
        }
        let q: Vec<f64> = s.actuated.iter().map(|&j| a.x[j]).collect();
        let spread = if trial % 2 == 0 { 1e-3 } else { 0.05 };
        for &j in s.passive {
            a.x[j] += spread * rng.sym();
        }
        let mut b = a.clone();
        let (ra, rb) = (
            forward_kinematics(&chord, &mut a, &q),
            forward_kinematics(&newton, &mut b, &q),
        );
        let (Ok(ra), Ok(rb)) = (ra, rb) else {
            assert_eq!(
                ra.is_ok(),
                rb.is_ok(),
                "{name}: one of them failed: {ra:?} {rb:?}"
            );
            continue;
        };
        solved += 1;
        worst = worst.max(rel(&a.x, &b.x));
        worst_res = worst_res.max(ra.residual);
        assert!(
            ra.residual <= chord.options.tol_f,
            "{name}: residual {ra:?}"
        );
        assert!(
            rb.residual <= newton.options.tol_f,
            "{name}: residual {rb:?}"
        );
    }
    let (ja, jb) = (
        chord.kernels().jacobians.get(),
        newton.kernels().jacobians.get(),
    );
    eprintln!(
        "{name}: forward kinematics with and without chord steps: {solved} starts, worst relative \
         difference {worst:.1e}, residual at most {worst_res:.1e}; Jacobian evaluations {ja} and {jb}"
    );
    assert!(solved >= 16, "{name}: IK solved only {solved} of 32 poses");
    assert!(worst < 1e-13, "{name}: {worst:e}");
    if chord_here {
        assert!(
            2 * ja < jb,
            "{name}: {ja} Jacobian evaluations with chord steps, {jb} without"
        );
    } else {
        assert_eq!(ja, jb, "{name}: chord steps where the generator chose none");
    }
}

/// Solves the dense `a x = b` (`a[r][c]`) by Gaussian elimination with partial pivoting.
fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap();
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for c in (0..n).rev() {
        let s: f64 = (c + 1..n).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    x
}

/// The exact 1-norm condition number of `a` (its inverse column by column).
fn cond1(a: &[Vec<f64>]) -> f64 {
    let n = a.len();
    let norm = |m: &dyn Fn(usize, usize) -> f64| {
        (0..n)
            .map(|c| (0..n).map(|r| m(r, c).abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    let inv: Vec<Vec<f64>> = (0..n)
        .map(|c| {
            let e = (0..n).map(|r| if r == c { 1.0 } else { 0.0 }).collect();
            dense_solve(a.to_vec(), e)
        })
        .collect();
    norm(&|r, c| a[r][c]) * norm(&|r, c| inv[c][r])
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs())).max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

fn check<K: Kernels<N, M> + Clone, const N: usize, const M: usize>(k: K, seed: u64) {
    let s = k.structure();
    let name = s.name;
    let mut rng = Rng::new(seed);
    let (mut ran_ik, mut ran_fk) = (0, 0);
    let (mut worst_ik, mut worst_fk) = (0.0_f64, 0.0_f64);
    let (mut est_ratio, mut bound_ratio) = (f64::INFINITY, 0.0_f64);
    let mut est_ratio_max = 0.0_f64;
    let (mut worst_cond, mut exact_ran) = (0.0_f64, 0);
    let mut g = [[0.0; M]; N];
    for trial in 0..=STATES {
        let spread = if trial == 0 { 0.0 } else { 0.1 };
        let x: [f64; N] = core::array::from_fn(|j| s.home[j] + spread * rng.sym());
        k.jacobian(&x, &mut g);
        let rhs: [f64; M] = core::array::from_fn(|_| rng.sym());
        let given: [f64; N] = core::array::from_fn(|_| rng.sym());

        // Inverse kinematics' blocks, with and without the outputs' term.
        let mut all = true;
        for (b, blk) in s.ik_blocks.iter().enumerate() {
            for outputs in [true, false] {
                let mut xs = given;
                let Some([cond, res]) = k.ik_block_solve(b, &g, &rhs, outputs, &mut xs) else {
                    all = false;
                    continue;
                };
                let kk: Vec<Vec<f64>> = blk
                    .rows
                    .iter()
                    .map(|&r| blk.cols.iter().map(|&c| g[c][r]).collect())
                    .collect();
                let rb: Vec<f64> = blk
                    .rows
                    .iter()
                    .map(|&r| {
                        let go: f64 = s.outputs.iter().map(|&z| g[z][r] * given[z]).sum();
                        rhs[r] - if outputs { go } else { 0.0 }
                    })
                    .collect();
                let want = dense_solve(kk.clone(), rb.clone());
                let got: Vec<f64> = blk.cols.iter().map(|&c| xs[c]).collect();
                let e = rel(&got, &want);
                worst_ik = worst_ik.max(e);
                assert!(e < 1e-10, "{name}, state {trial}, block {b}: x {e:e}");
                let exact = cond1(&kk);
                if blk.rows.len() <= 3 {
                    assert!(
                        (cond - exact).abs() <= 1e-10 * exact,
                        "{name}, state {trial}, block {b}: cond {cond} against {exact}"
                    );
                } else {
                    // Read off the pivots (the Hager/Higham estimate past 1e3): within the
                    // factor of 10 that codegen's `block::SCREEN` leaves below the runtime's
                    // thresholds.
                    assert!(
                        cond <= exact * 10.0 && cond >= exact / 10.0,
                        "{name}, state {trial}, block {b}: estimate {cond} against {exact}"
                    );
                    est_ratio = est_ratio.min(cond / exact);
                    est_ratio_max = est_ratio_max.max(cond / exact);
                }
                let r_here = (0..kk.len())
                    .map(|j| {
                        let kx: f64 = (0..kk.len()).map(|i| kk[j][i] * got[i]).sum();
                        (kx - rb[j]).abs()
                    })
                    .fold(0.0, f64::max);
                assert!(
                    (res - r_here).abs() <= 1e-12 * (1.0 + rb.iter().map(|v| v.abs()).sum::<f64>()),
                    "{name}, state {trial}, block {b}: residual {res:e} against {r_here:e}"
                );
                // Only the block's columns are written.
                for j in 0..N {
                    if !blk.cols.contains(&j) {
                        assert_eq!(
                            xs[j].to_bits(),
                            given[j].to_bits(),
                            "{name}: x[{j}] written"
                        );
                    }
                }
            }
        }
        ran_ik += usize::from(all);

        // Forward kinematics' elimination.
        let mut xs = given;
        if let Some([bound, res]) = k.forward_rates_solve(&g, &rhs, true, false, &mut xs) {
            ran_fk += 1;
            let jp: Vec<Vec<f64>> = (0..M)
                .map(|r| s.passive.iter().map(|&c| g[c][r]).collect())
                .collect();
            let b: Vec<f64> = (0..M)
                .map(|r| rhs[r] - s.actuated.iter().map(|&a| g[a][r] * given[a]).sum::<f64>())
                .collect();
            let want = dense_solve(jp.clone(), b.clone());
            let got: Vec<f64> = s.passive.iter().map(|&c| xs[c]).collect();
            let e = rel(&got, &want);
            worst_fk = worst_fk.max(e);
            assert!(e < 1e-9, "{name}, state {trial}: forward rates {e:e}");
            for &a in s.actuated {
                assert_eq!(
                    xs[a].to_bits(),
                    given[a].to_bits(),
                    "{name}: actuated written"
                );
            }
            let exact = cond1(&jp);
            assert!(
                bound >= exact * (1.0 - 1e-10),
                "{name}, state {trial}: bound {bound} below cond(J_p) {exact}"
            );
            bound_ratio = bound_ratio.max(bound / exact);
            let r_here = (0..M)
                .map(|r| {
                    let jx: f64 = (0..M).map(|i| jp[r][i] * got[i]).sum();
                    (jx - b[r]).abs()
                })
                .fold(0.0, f64::max);
            let scale = 1.0 + b.iter().map(|v| v.abs()).fold(0.0, f64::max);
            assert!(
                (res - r_here).abs() <= 1e-11 * scale,
                "{name}, state {trial}: residual {res:e} against {r_here:e}"
            );
            // A Newton step: `x_q = 0`, and the actuated columns of `G` are not read (NaN here).
            let mut gp = g;
            for &a in s.actuated {
                gp[a] = [f64::NAN; M];
            }
            let mut xn = [f64::NAN; N];
            let [bn, _] = k
                .forward_rates_solve(&gp, &rhs, false, false, &mut xn)
                .unwrap_or_else(|| panic!("{name}, state {trial}: the Newton step declines"));
            let want = dense_solve(jp.clone(), rhs.to_vec());
            let got: Vec<f64> = s.passive.iter().map(|&c| xn[c]).collect();
            let e = rel(&got, &want);
            worst_fk = worst_fk.max(e);
            assert!(e < 1e-9, "{name}, state {trial}: Newton step {e:e}");
            assert_eq!(
                bn.to_bits(),
                bound.to_bits(),
                "{name}: the bound depends on x_q"
            );
            // The exact condition number, from the same elimination (not emitted where it would
            // cost more than the dense inverse: a single block as small as the UR5's).
            let mut xe = given;
            let exact_cond = k.forward_rates_solve(&g, &rhs, true, true, &mut xe);
            let Some([ce, _]) = exact_cond else {
                assert!(
                    s.ik_blocks.len() == 1,
                    "{name}, state {trial}: the exact condition number declines"
                );
                continue;
            };
            exact_ran += 1;
            assert!(
                (ce - exact).abs() <= 1e-9 * exact,
                "{name}, state {trial}: exact cond {ce} against {exact}"
            );
            worst_cond = worst_cond.max((ce - exact).abs() / exact);
        } else {
            assert!(
                trial > 0,
                "{name}: forward_rates_solve declines at the home"
            );
        }
    }
    eprintln!(
        "{name}: ik_block_solve ran at {ran_ik}, forward_rates_solve at {ran_fk} of {} states; \
         worst relative difference {worst_ik:.1e} and {worst_fk:.1e}; smallest estimate/cond(K) \
         {est_ratio:.3}, largest {est_ratio_max:.3}; largest bound/cond(J_p) {bound_ratio:.1}; exact cond(J_p) at {exact_ran} states, \
         to {worst_cond:.1e}",
        STATES + 1
    );
    for (what, ran) in [("ik_block_solve", ran_ik), ("forward_rates_solve", ran_fk)] {
        assert!(
            ran * 4 >= 3 * (STATES + 1),
            "{name}: {what} ran at only {ran} of {} states",
            STATES + 1
        );
    }
    check_solvers(k, seed);
}

/// The solvers that take the generated solves against the general paths, along IK solutions
/// near the home.
fn check_solvers<K: Kernels<N, M> + Clone, const N: usize, const M: usize>(k: K, seed: u64) {
    let s = k.structure();
    let name = s.name;
    let generated = Model::new(k.clone());
    let general = Model::new(NoSolve(k));
    let mut rng = Rng::new(seed ^ 0x5eed);
    let mut worst = 0.0_f64;
    let mut solved = 0;
    for trial in 0..16 {
        let spread = if trial == 0 { 0.0 } else { 0.02 };
        let out: Vec<f64> = s
            .outputs
            .iter()
            .map(|&z| s.home[z] + spread * rng.sym())
            .collect();
        let rates: Vec<f64> = s.outputs.iter().map(|_| rng.sym()).collect();
        let (mut a, mut b) = (Data::new(&generated), Data::new(&general));
        if inverse_kinematics(&generated, &mut a, &out).is_err() {
            continue;
        }
        inverse_kinematics(&general, &mut b, &out).unwrap();
        solved += 1;
        worst = worst.max(rel(&a.x, &b.x));
        inverse_velocity(&generated, &mut a, &rates).unwrap();
        inverse_velocity(&general, &mut b, &rates).unwrap();
        worst = worst.max(rel(&a.xdot, &b.xdot));
        let q: Vec<f64> = s.actuated.iter().map(|&j| a.x[j]).collect();
        let qd: Vec<f64> = s.actuated.iter().map(|_| rng.sym()).collect();
        let qdd: Vec<f64> = s.actuated.iter().map(|_| rng.sym()).collect();
        // FK from a start 1e-3 off in the passive coordinates.
        for &j in s.passive {
            let d = 1e-3 * rng.sym();
            a.x[j] += d;
            b.x[j] += d;
        }
        forward_kinematics(&generated, &mut a, &q).unwrap();
        forward_kinematics(&general, &mut b, &q).unwrap();
        worst = worst.max(rel(&a.x, &b.x));
        forward_velocity(&generated, &mut a, &qd).unwrap();
        forward_velocity(&general, &mut b, &qd).unwrap();
        worst = worst.max(rel(&a.xdot, &b.xdot));
        forward_acceleration(&generated, &mut a, &qdd).unwrap();
        forward_acceleration(&general, &mut b, &qdd).unwrap();
        worst = worst.max(rel(&a.xddot, &b.xddot));
    }
    eprintln!(
        "{name}: solvers with and without the generated solves: {solved} poses, worst relative difference {worst:.1e}"
    );
    assert!(solved >= 8, "{name}: IK solved only {solved} of 16 poses");
    assert!(worst < 1e-9, "{name}: {worst:e}");
}

macro_rules! robots {
    ($($test:ident: $krate:ident :: $ty:ident, $seed:expr;)*) => {$(
        #[test]
        fn $test() {
            check($krate::$ty::default(), $seed);
            check_chord($krate::$ty::default(), $seed, $krate::FR_CHORD);
        }
    )*};
}

robots! {
    stewart_6ups_generated_kinematics: stewart_6ups::Stewart6Ups, 0xfa_0001;
    five_bar_generated_kinematics: five_bar::FiveBar, 0xfa_0002;
    delta_generated_kinematics: delta::Delta, 0xfa_0003;
    planar_3rrr_generated_kinematics: planar_3rrr::Planar3Rrr, 0xfa_0004;
    tripod_3rps_generated_kinematics: tripod_3rps::Tripod3Rps, 0xfa_0005;
    hexa_6rus_generated_kinematics: hexa_6rus::Hexa6Rus, 0xfa_0006;
    hybrid_tricept_generated_kinematics: hybrid_tricept::HybridTricept, 0xfa_0007;
    ur5_generated_kinematics: ur5::Ur5, 0xfa_0008;
    stewart_2stage_generated_kinematics: stewart_2stage::Stewart2Stage, 0xfa_0009;
    five_bar_turned_generated_kinematics: five_bar_turned::FiveBarTurned, 0xfa_000a;
    four_bar_rod_generated_kinematics: four_bar_rod::FourBarRod, 0xfa_000b;
    gear_pair_generated_kinematics: gear_pair::GearPair, 0xfa_000c;
    leg_four_bar_generated_kinematics: leg_four_bar::LegFourBar, 0xfa_000d;
    slider_crank_generated_kinematics: slider_crank::SliderCrank, 0xfa_000e;
    spatial_crank_generated_kinematics: spatial_crank::SpatialCrank, 0xfa_000f;
}
