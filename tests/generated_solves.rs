//! The solves the generator emits (`forward_dynamics_solve`, `inverse_dynamics_solve`, codegen's
//! `solve` module) against the runtime's own paths, for every robot, at 64 seeded random states
//! near its home. Forward dynamics:
//!
//! - it runs (it is not declining everywhere, which would only make it dead code): at the home
//!   and at most of the states;
//! - where it runs, `Ẍ` and `lambda` equal the runtime's elimination (the same algorithm with
//!   run-time indices, reached by hiding the generated solve) and the Schur complement (another
//!   algorithm) to a relative 1e-9, and the saddle-point system's residuals, computed here in
//!   full, are at rounding level;
//! - its reported residual is the residual of `G Ẍ = gamma`;
//! - it declines, and the runtime still answers, where its structure fails: a singular
//!   inverse-kinematics block, a NaN in `M` (then the runtime names `M`).
//!
//! Inverse dynamics, at random `Ẍ` as well: it runs; `U` and `lambda` equal the runtime's block
//! elimination and the dense LU of `[S | Gᵀ]` to a relative 1e-9; its residual is that of the N
//! equations.

// Matrix code: the indices say which entry, so loops over them read better than iterators.
#![allow(clippy::needless_range_loop)]

mod common;

use common::Rng;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, DynamicsMethod, Kernels, Model, SolverError, Structure,
    forward_dynamics, forward_dynamics_schur, gear_ratio, inverse_dynamics, inverse_dynamics_dense,
};

const STATES: usize = 64;

/// A robot with its generated solve hidden: the runtime's general paths run.
struct NoSolve<K>(K);

impl<K: Kernels<N, M>, const N: usize, const M: usize> Kernels<N, M> for NoSolve<K> {
    const IK_BLOCK_ORDER: usize = K::IK_BLOCK_ORDER;
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

impl<K: Dynamics<N, M>, const N: usize, const M: usize> Dynamics<N, M> for NoSolve<K> {
    fn mass_blocks(&self) -> &'static [&'static [usize]] {
        self.0.mass_blocks()
    }
    fn mass_matrix(&self, x: &[f64; N], out: &mut [[f64; N]; N]) {
        self.0.mass_matrix(x, out)
    }
    fn psi(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; N]) {
        self.0.psi(x, xdot, out)
    }
    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]) {
        self.0.energy(x, xdot, out)
    }
    fn dynamics_terms(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        g: &mut [[f64; M]; N],
        gamma: &mut [f64; M],
        mass: &mut [[f64; N]; N],
        psi: &mut [f64; N],
    ) {
        self.0.dynamics_terms(x, xdot, g, gamma, mass, psi)
    }
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// `max |a - b| / (1 + max |b|)`.
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let d = a
        .iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
    d / (1.0 + max_abs(b))
}

/// The saddle-point residuals of `(xddot, lambda)` with the terms in `d`, relative to the
/// sizes of the terms: `(|M Ẍ + Gᵀ lambda - F|, |G Ẍ - gamma|)`.
fn residuals<const N: usize, const M: usize>(
    d: &Data<N, M>,
    force: &[f64; N],
    xddot: &[f64; N],
    lambda: &[f64; M],
) -> (f64, f64) {
    let g = &d.g().data.0;
    let mass = &d.mass().data.0;
    let mut r1 = 0.0_f64;
    let mut scale1 = max_abs(force);
    for i in 0..N {
        let mut s = -force[i];
        let mut size = 0.0;
        for j in 0..N {
            s += mass[j][i] * xddot[j];
            size += (mass[j][i] * xddot[j]).abs();
        }
        for r in 0..M {
            s += g[i][r] * lambda[r];
            size += (g[i][r] * lambda[r]).abs();
        }
        r1 = r1.max(s.abs());
        scale1 = scale1.max(size);
    }
    let mut r2 = 0.0_f64;
    let mut scale2 = max_abs(&d.gamma);
    for r in 0..M {
        let mut s = -d.gamma[r];
        let mut size = 0.0;
        for j in 0..N {
            s += g[j][r] * xddot[j];
            size += (g[j][r] * xddot[j]).abs();
        }
        r2 = r2.max(s.abs());
        scale2 = scale2.max(size);
    }
    (r1 / scale1.max(1e-300), r2 / scale2.max(1e-300))
}

fn check<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(k: K, seed: u64) {
    let name = k.structure().name;
    let home = k.structure().home;
    let n_act = k.structure().actuated.len();
    let generated = Model::new(k.clone());
    let general = Model::new(NoSolve(k.clone()));
    let mut rng = Rng::new(seed);
    let (mut ran, mut worst_gen, mut worst_res) = (0, 0.0_f64, 0.0_f64);
    for trial in 0..=STATES {
        let mut d = Data::new(&generated);
        let mut u = vec![0.0; n_act];
        for j in 0..N {
            // Trial 0: the home at rest with zero controls.
            let spread = if trial == 0 { 0.0 } else { 1.0 };
            d.x[j] = home[j] + 0.1 * spread * rng.sym();
            d.xdot[j] = spread * rng.sym();
        }
        for ua in &mut u {
            *ua = if trial == 0 { 0.0 } else { 10.0 * rng.sym() };
        }
        let rep = forward_dynamics(&generated, &mut d, &u, None, Baumgarte::NONE)
            .unwrap_or_else(|e| panic!("{name}, state {trial}: {e}"));

        // Did the generated solve answer? Call it on the same terms.
        let mut force = d.psi;
        for (i, (&j, &ua)) in k.structure().actuated.iter().zip(&u).enumerate() {
            force[j] += gear_ratio(k.structure().gear, i) * ua;
        }
        let (mut xg, mut lg) = ([0.0; N], [0.0; M]);
        let gamma = d.gamma;
        let c = k.forward_dynamics_solve(
            &d.g().data.0,
            &d.mass().data.0,
            &force,
            &gamma,
            &mut xg,
            &mut lg,
        );
        let Some(c) = c else {
            assert!(
                trial != 0,
                "{name}: the generated solve declines at the home"
            );
            continue;
        };
        if c.blocks > 1e2 {
            continue; // the runtime does not take it there (a leg near its singularity)
        }
        ran += 1;
        assert_eq!(rep.method, DynamicsMethod::Reduced, "{name}, state {trial}");
        assert_eq!(
            d.xddot, xg,
            "{name}, state {trial}: forward_dynamics took another path"
        );
        assert_eq!(d.lambda, lg, "{name}, state {trial}");

        // Its certificate is the residual of G Ẍ = gamma.
        // (Both are rounding noise, summed in different orders: they agree to the rounding of
        // the sums, 32 N ε times the size of their terms.)
        let (mut gx, mut size) = ([0.0; M], [0.0; M]);
        for j in 0..N {
            for r in 0..M {
                gx[r] += d.g().data.0[j][r] * xg[j];
                size[r] += (d.g().data.0[j][r] * xg[j]).abs();
            }
        }
        let res = gx
            .iter()
            .zip(&gamma)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        let scale = max_abs(&size).max(max_abs(&gamma));
        assert!(
            (c.residual - res).abs() <= 32.0 * N as f64 * f64::EPSILON * scale,
            "{name}, state {trial}: reported residual {:e}, recomputed {res:e} (terms {scale:e})",
            c.residual
        );
        let (r1, r2) = residuals(&d, &force, &xg, &lg);
        worst_res = worst_res.max(r1).max(r2);
        assert!(
            r1 < 1e-11 && r2 < 1e-11,
            "{name}, state {trial}: saddle-point residuals {r1:e} {r2:e}"
        );

        // The runtime's elimination and the Schur complement at the same state.
        let mut d2 = Data::new(&general);
        d2.x = d.x;
        d2.xdot = d.xdot;
        forward_dynamics(&general, &mut d2, &u, None, Baumgarte::NONE).unwrap();
        let mut d3 = Data::new(&general);
        d3.x = d.x;
        d3.xdot = d.xdot;
        forward_dynamics_schur(&general, &mut d3, &u, None, Baumgarte::NONE).unwrap();
        for (other, what) in [
            (&d2, "the runtime's elimination"),
            (&d3, "the Schur complement"),
        ] {
            let (ex, el) = (rel(&xg, &other.xddot), rel(&lg, &other.lambda));
            worst_gen = worst_gen.max(ex).max(el);
            assert!(
                ex < 1e-9 && el < 1e-9,
                "{name}, state {trial}: against {what}: Ẍ {ex:e}, lambda {el:e}"
            );
        }
    }
    eprintln!(
        "{name}: generated forward dynamics ran at {ran} of {} states; worst relative difference {worst_gen:.1e}, worst residual {worst_res:.1e}",
        STATES + 1
    );
    assert!(
        ran * 4 >= 3 * (STATES + 1),
        "{name}: the generated solve ran at only {ran} of {} states",
        STATES + 1
    );
    check_inverse(k, seed);
}

fn check_inverse<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(k: K, seed: u64) {
    let name = k.structure().name;
    let home = k.structure().home;
    let n_act = k.structure().actuated.len();
    let generated = Model::new(k.clone());
    let general = Model::new(NoSolve(k.clone()));
    let mut rng = Rng::new(seed ^ 0x1d);
    let (mut ran, mut worst) = (0, 0.0_f64);
    for trial in 0..=STATES {
        let spread = if trial == 0 { 0.0 } else { 1.0 };
        let mut d = Data::new(&generated);
        for j in 0..N {
            d.x[j] = home[j] + 0.1 * spread * rng.sym();
            d.xdot[j] = spread * rng.sym();
            d.xddot[j] = spread * rng.sym();
        }
        let q: [f64; N] = core::array::from_fn(|_| spread * rng.sym());
        let rep = inverse_dynamics(&generated, &mut d, Some(&q))
            .unwrap_or_else(|e| panic!("{name}, state {trial}: {e}"));
        let mut u = vec![0.0; n_act];
        let mut l = [0.0; M];
        let c = k.inverse_dynamics_solve(
            &d.g().data.0,
            &d.mass().data.0,
            &d.psi,
            &d.xddot,
            Some(&q),
            &mut u,
            &mut l,
        );
        let Some(c) = c else {
            assert!(
                trial != 0,
                "{name}: generated inverse dynamics declines at the home"
            );
            continue;
        };
        ran += 1;
        assert_eq!(
            rep.method,
            DynamicsMethod::BlockElimination,
            "{name}, state {trial}"
        );
        // The generated solve gives the forces on the coordinates; `U` is in the actuators'
        // units (divided by their gear ratios).
        let geared: Vec<f64> = (0..n_act)
            .map(|i| u[i] / gear_ratio(k.structure().gear, i))
            .collect();
        assert_eq!(
            d.u(),
            &geared[..],
            "{name}, state {trial}: inverse_dynamics took another path"
        );
        assert_eq!(d.lambda, l, "{name}, state {trial}");
        assert_eq!(rep.residual, c.residual);
        // The residual of the N equations M Ẍ - psi - Q - S U + Gᵀ lambda, recomputed.
        let (g, mass) = (&d.g().data.0, &d.mass().data.0);
        let (mut res, mut scale) = (0.0_f64, 0.0_f64);
        for j in 0..N {
            let mut r = -d.psi[j] - q[j];
            let mut size = d.psi[j].abs() + q[j].abs();
            for i in 0..N {
                r += mass[i][j] * d.xddot[i];
                size += (mass[i][j] * d.xddot[i]).abs();
            }
            for (rr, &lr) in l.iter().enumerate() {
                r += g[j][rr] * lr;
                size += (g[j][rr] * lr).abs();
            }
            if let Some(a) = k.structure().actuated.iter().position(|&x| x == j) {
                r -= u[a];
                size += u[a].abs();
            }
            res = res.max(r.abs());
            scale = scale.max(size);
        }
        assert!(
            res <= 1e-12 * scale
                && (c.residual - res).abs() <= 64.0 * N as f64 * f64::EPSILON * scale,
            "{name}, state {trial}: residual {res:e} (reported {:e}, terms {scale:e})",
            c.residual
        );
        for (what, run) in [
            ("the runtime's block elimination", 0),
            ("the dense LU of [S | Gᵀ]", 1),
        ] {
            let mut d2 = Data::new(&general);
            d2.x = d.x;
            d2.xdot = d.xdot;
            d2.xddot = d.xddot;
            if run == 0 {
                inverse_dynamics(&general, &mut d2, Some(&q)).unwrap();
            } else {
                inverse_dynamics_dense(&general, &mut d2, Some(&q)).unwrap();
            }
            let (eu, el) = (rel(&geared, d2.u()), rel(&l, &d2.lambda));
            worst = worst.max(eu).max(el);
            assert!(
                eu < 1e-9 && el < 1e-9,
                "{name}, state {trial}: against {what}: U {eu:e}, lambda {el:e}"
            );
        }
    }
    eprintln!(
        "{name}: generated inverse dynamics ran at {ran} of {} states; worst relative difference {worst:.1e}",
        STATES + 1
    );
    assert!(
        ran * 4 >= 3 * (STATES + 1),
        "{name}: generated inverse dynamics ran at only {ran} of {} states",
        STATES + 1
    );
}

macro_rules! robots {
    ($($test:ident: $krate:ident :: $ty:ident, $seed:expr;)*) => {$(
        #[test]
        fn $test() {
            check($krate::$ty::default(), $seed);
        }
    )*};
}

robots! {
    stewart_6ups_generated_solves: stewart_6ups::Stewart6Ups, 0xfd_0001;
    five_bar_generated_solves: five_bar::FiveBar, 0xfd_0002;
    delta_generated_solves: delta::Delta, 0xfd_0003;
    planar_3rrr_generated_solves: planar_3rrr::Planar3Rrr, 0xfd_0004;
    tripod_3rps_generated_solves: tripod_3rps::Tripod3Rps, 0xfd_0005;
    hexa_6rus_generated_solves: hexa_6rus::Hexa6Rus, 0xfd_0006;
    hybrid_tricept_generated_solves: hybrid_tricept::HybridTricept, 0xfd_0007;
    ur5_generated_solves: ur5::Ur5, 0xfd_0008;
    stewart_2stage_generated_solves: stewart_2stage::Stewart2Stage, 0xfd_0009;
    four_bar_rod_generated_solves: four_bar_rod::FourBarRod, 0xfd_000a;
    gear_pair_generated_solves: gear_pair::GearPair, 0xfd_000b;
    leg_four_bar_generated_solves: leg_four_bar::LegFourBar, 0xfd_000c;
    slider_crank_generated_solves: slider_crank::SliderCrank, 0xfd_000d;
    spatial_crank_generated_solves: spatial_crank::SpatialCrank, 0xfd_000e;
}

/// A singular inverse-kinematics block (a leg's column of `G` zeroed): the generated solve
/// declines, and forward dynamics still answers by the Schur complement.
#[test]
fn a_singular_block_declines() {
    let k = stewart_6ups::Stewart6Ups::default();
    let model = Model::new(k);
    let mut d = Data::new(&model);
    d.x.copy_from_slice(k.structure().home);
    forward_dynamics(&model, &mut d, &[0.0; 6], None, Baumgarte::NONE).unwrap();
    let mut g = d.g().data.0;
    let leg = k.structure().ik_blocks[0];
    for &r in leg.rows {
        g[leg.cols[0]][r] = 0.0;
    }
    let (mut x, mut l) = ([0.0; 24], [0.0; 18]);
    let c = k.forward_dynamics_solve(&g, &d.mass().data.0, &d.psi, &d.gamma, &mut x, &mut l);
    assert!(c.is_none(), "{c:?}");
}

/// A NaN in `M` (a kernel output): not returned; the runtime names `M`.
#[test]
fn a_nan_in_the_mass_matrix_is_named() {
    #[derive(Clone)]
    struct NanMass(stewart_6ups::Stewart6Ups);
    impl Kernels<24, 18> for NanMass {
        fn structure(&self) -> &'static Structure {
            self.0.structure()
        }
        fn constraints(&self, x: &[f64; 24], f: &mut [f64; 18]) {
            self.0.constraints(x, f)
        }
        fn jacobian(&self, x: &[f64; 24], g: &mut [[f64; 18]; 24]) {
            self.0.jacobian(x, g)
        }
        fn jacobian_p(&self, x: &[f64; 24], g: &mut [[f64; 18]; 24]) {
            self.0.jacobian_p(x, g)
        }
        fn jacobian_ik(&self, x: &[f64; 24], g: &mut [[f64; 18]; 24]) {
            self.0.jacobian_ik(x, g)
        }
        fn gamma(&self, x: &[f64; 24], xdot: &[f64; 24], out: &mut [f64; 18]) {
            self.0.gamma(x, xdot, out)
        }
    }
    impl Dynamics<24, 18> for NanMass {
        fn mass_blocks(&self) -> &'static [&'static [usize]] {
            self.0.mass_blocks()
        }
        fn mass_matrix(&self, x: &[f64; 24], out: &mut [[f64; 24]; 24]) {
            self.0.mass_matrix(x, out)
        }
        fn psi(&self, x: &[f64; 24], xdot: &[f64; 24], out: &mut [f64; 24]) {
            self.0.psi(x, xdot, out)
        }
        fn energy(&self, x: &[f64; 24], xdot: &[f64; 24], out: &mut [f64; 2]) {
            self.0.energy(x, xdot, out)
        }
        fn dynamics_terms(
            &self,
            x: &[f64; 24],
            xdot: &[f64; 24],
            g: &mut [[f64; 18]; 24],
            gamma: &mut [f64; 18],
            mass: &mut [[f64; 24]; 24],
            psi: &mut [f64; 24],
        ) {
            self.0.dynamics_terms(x, xdot, g, gamma, mass, psi);
            mass[20][20] = f64::NAN; // a platform coordinate: every solve reads it
        }
        #[allow(clippy::too_many_arguments)]
        fn inverse_dynamics_solve(
            &self,
            g: &[[f64; 18]; 24],
            mass: &[[f64; 24]; 24],
            psi: &[f64; 24],
            xddot: &[f64; 24],
            q_forces: Option<&[f64; 24]>,
            u: &mut [f64],
            lambda: &mut [f64; 18],
        ) -> Option<rbss_runtime::SolveConditioning> {
            self.0
                .inverse_dynamics_solve(g, mass, psi, xddot, q_forces, u, lambda)
        }
        fn forward_dynamics_solve(
            &self,
            g: &[[f64; 18]; 24],
            mass: &[[f64; 24]; 24],
            force: &[f64; 24],
            gamma: &[f64; 18],
            xddot: &mut [f64; 24],
            lambda: &mut [f64; 18],
        ) -> Option<rbss_runtime::SolveConditioning> {
            self.0
                .forward_dynamics_solve(g, mass, force, gamma, xddot, lambda)
        }
    }
    let k = NanMass(stewart_6ups::Stewart6Ups::default());
    let model = Model::new(k.clone());
    let mut d = Data::new(&model);
    d.x.copy_from_slice(k.structure().home);
    let before = d.xddot;
    let e = forward_dynamics(&model, &mut d, &[0.0; 6], None, Baumgarte::NONE).unwrap_err();
    assert!(
        matches!(e, SolverError::NonFinite { what } if what.contains('M')),
        "{e:?}"
    );
    assert_eq!(d.xddot, before, "a failed solve wrote Ẍ");
    // Inverse dynamics too: the NaN is named, nothing is written.
    let u_before = d.u().to_vec();
    let e = inverse_dynamics(&model, &mut d, None).unwrap_err();
    assert!(
        matches!(e, SolverError::NonFinite { what } if what.contains('M')),
        "{e:?}"
    );
    assert_eq!(d.u(), &u_before[..]);
}
