//! Every generated derivative against central differences at 32 seeded random states per robot.
//!
//! Step `h_j = cbrt(EPSILON) * max(1, |x_j|)` (about 6e-6): the truncation error of a central
//! difference is O(h^2 f''') ~ 4e-11 and the rounding error O(eps |f| / h) ~ 4e-11 for entries of
//! size 1, so `|kernel - numeric| <= 1e-7 (|kernel| + |numeric|) + 1e-8` leaves a margin of
//! more than 100 on both.

mod common;

use common::{Rng, assert_close};
use rbss_runtime::Kernels;

const STATES: usize = 32;
const REL: f64 = 1e-7;
const ABS: f64 = 1e-8;

fn step(x: f64) -> f64 {
    f64::EPSILON.cbrt() * x.abs().max(1.0)
}

/// A random state near the home assembly (not on the constraint manifold: the derivatives of
/// `f` hold everywhere) and a random velocity.
fn random_state<const N: usize>(home: &[f64], rng: &mut Rng) -> ([f64; N], [f64; N]) {
    let mut x = [0.0; N];
    let mut v = [0.0; N];
    for j in 0..N {
        x[j] = home[j] + 0.3 * rng.sym();
        v[j] = rng.sym();
    }
    (x, v)
}

fn check_robot<K: Kernels<N, M>, const N: usize, const M: usize>(k: &K, seed: u64) {
    let s = k.structure();
    let mut rng = Rng::new(seed);
    let mut bit_identical = 0usize;
    let mut compared = 0usize;
    // G at home: an entry with the same value at every state (a constant entry, such as a
    // coupling's ratio) is what a central difference gives exactly, and is left out of the
    // bit-identity count below.
    let mut g_home = [[0.0; M]; N];
    let home: [f64; N] = std::array::from_fn(|j| s.home[j]);
    k.jacobian(&home, &mut g_home);
    for st in 0..STATES {
        let (x, v) = random_state::<N>(s.home, &mut rng);
        let mut g = [[0.0; M]; N];
        k.jacobian(&x, &mut g);

        // G against central differences of f, column by column.
        for j in 0..N {
            let h = step(x[j]);
            let (mut xp, mut xm) = (x, x);
            xp[j] += h;
            xm[j] -= h;
            let (mut fp, mut fm) = ([0.0; M], [0.0; M]);
            k.constraints(&xp, &mut fp);
            k.constraints(&xm, &mut fm);
            for i in 0..M {
                let num = (fp[i] - fm[i]) / (xp[j] - xm[j]);
                let what = format!(
                    "{} state {st}: G[{}, {}]",
                    s.name, s.constraints[i], s.coordinates[j]
                );
                assert_close(&what, g[j][i], num, REL, ABS);
                if g[j][i] != g_home[j][i] {
                    compared += 1;
                    if g[j][i] == num && num != 0.0 {
                        bit_identical += 1;
                    }
                }
            }
        }

        // The column-subset kernels write G's entries in their columns (to rounding) and nothing else.
        let mut is_output = vec![false; N];
        for &o in s.outputs {
            is_output[o] = true;
        }
        for (name, f, cols) in [
            (
                "jacobian_p",
                K::jacobian_p as fn(&K, &[f64; N], &mut [[f64; M]; N]),
                s.passive.to_vec(),
            ),
            (
                "jacobian_ik",
                K::jacobian_ik,
                (0..N).filter(|&j| !is_output[j]).collect::<Vec<_>>(),
            ),
        ] {
            let mut sub = [[f64::NAN; M]; N];
            for &c in &cols {
                sub[c] = [0.0; M];
            }
            f(k, &x, &mut sub);
            for j in 0..N {
                for i in 0..M {
                    if cols.contains(&j) {
                        // A separate evaluator (own CSE): equal up to rounding.
                        assert_close(
                            &format!("{name} ({i}, {j}) vs jacobian"),
                            sub[j][i],
                            g[j][i],
                            1e-13,
                            1e-15,
                        );
                    } else {
                        assert!(
                            sub[j][i].is_nan(),
                            "{name} wrote column {j}, which is not one of its columns"
                        );
                    }
                }
            }
        }

        // gamma = -(dG/dt) Xdot = -(d/de G(x + e v)|_0) v, by a central difference along v.
        let mut gamma = [0.0; M];
        k.gamma(&x, &v, &mut gamma);
        let h = f64::EPSILON.cbrt();
        let (mut xp, mut xm) = (x, x);
        for j in 0..N {
            xp[j] += h * v[j];
            xm[j] -= h * v[j];
        }
        let (mut gp, mut gm) = ([[0.0; M]; N], [[0.0; M]; N]);
        k.jacobian(&xp, &mut gp);
        k.jacobian(&xm, &mut gm);
        for i in 0..M {
            let mut num = 0.0;
            for j in 0..N {
                num -= (gp[j][i] - gm[j][i]) / (2.0 * h) * v[j];
            }
            let what = format!("{} state {st}: gamma[{}]", s.name, s.constraints[i]);
            assert_close(&what, gamma[i], num, REL, ABS);
        }
    }
    // The kernel is not the finite difference in disguise (MuJoCo's check).
    assert!(
        compared == 0 || bit_identical < compared / 2,
        "{}: {bit_identical} of {compared} entries are bit-identical",
        s.name
    );
}

#[test]
fn stewart_6ups_kernels_match_central_differences() {
    check_robot(&stewart_6ups::Stewart6Ups::default(), 0x5eed_0001);
}

#[test]
fn five_bar_kernels_match_central_differences() {
    check_robot(&five_bar::FiveBar::default(), 0x5eed_0002);
}

/// A robot with a passive degree of freedom (`J_p` has 3 columns for 2 rows).
#[test]
fn spring_pendulum_kernels_match_central_differences() {
    check_robot(&spring_pendulum::SpringPendulum::default(), 0x5eed_000b);
}

#[test]
fn stewart_2stage_kernels_match_central_differences() {
    check_robot(&stewart_2stage::Stewart2Stage::default(), 0x5eed_0003);
}

#[test]
fn ur5_kernels_match_central_differences() {
    check_robot(&ur5::Ur5::default(), 0x5eed_0004);
}

#[test]
fn delta_kernels_match_central_differences() {
    check_robot(&delta::Delta::default(), 0x5eed_0005);
}

#[test]
fn planar_3rrr_kernels_match_central_differences() {
    check_robot(&planar_3rrr::Planar3Rrr::default(), 0x5eed_0006);
}

#[test]
fn tripod_3rps_kernels_match_central_differences() {
    check_robot(&tripod_3rps::Tripod3Rps::default(), 0x5eed_0007);
}

#[test]
fn hexa_6rus_kernels_match_central_differences() {
    check_robot(&hexa_6rus::Hexa6Rus::default(), 0x5eed_0008);
}

#[test]
fn hybrid_tricept_kernels_match_central_differences() {
    check_robot(&hybrid_tricept::HybridTricept::default(), 0x5eed_0009);
}

#[test]
fn four_bar_rod_kernels_match_central_differences() {
    check_robot(&four_bar_rod::FourBarRod::default(), 0x5eed_000a);
}

#[test]
fn gear_pair_kernels_match_central_differences() {
    check_robot(&gear_pair::GearPair::default(), 0x5eed_000b);
}

#[test]
fn leg_four_bar_kernels_match_central_differences() {
    check_robot(&leg_four_bar::LegFourBar::default(), 0x5eed_000c);
}

#[test]
fn slider_crank_kernels_match_central_differences() {
    check_robot(&slider_crank::SliderCrank::default(), 0x5eed_000d);
}

#[test]
fn spatial_crank_kernels_match_central_differences() {
    check_robot(&spatial_crank::SpatialCrank::default(), 0x5eed_000e);
}

#[test]
fn cassie_legs_kernels_match_central_differences() {
    check_robot(&cassie_legs::CassieLegs::default(), 0x5eed_000f);
}

/// Non-default parameters reach the kernels: a longer base radius moves `f` by exactly the
/// change, along the base joint direction.
#[test]
fn parameters_reach_the_kernels() {
    use stewart_6ups::{Params, Stewart6Ups};
    let p0 = Params::default();
    let p1 = Params {
        r0: p0.r0 + 0.01,
        ..p0
    };
    let (k0, k1) = (Stewart6Ups::new(&p0), Stewart6Ups::new(&p1));
    let x: [f64; stewart_6ups::N] = stewart_6ups::STRUCTURE.home.try_into().unwrap();
    let (mut f0, mut f1) = ([0.0; stewart_6ups::M], [0.0; stewart_6ups::M]);
    k0.constraints(&x, &mut f0);
    k1.constraints(&x, &mut f1);
    // leg 1: base joint at Rz(alpha1) Tx(r0): f moves by 0.01 (cos alpha1, sin alpha1, 0)
    let a = p0.alpha1;
    assert_close("leg1.x", f1[0] - f0[0], 0.01 * a.cos(), 1e-12, 1e-15);
    assert_close("leg1.y", f1[1] - f0[1], 0.01 * a.sin(), 1e-12, 1e-15);
    assert_close("leg1.z", f1[2] - f0[2], 0.0, 0.0, 1e-15);
}
