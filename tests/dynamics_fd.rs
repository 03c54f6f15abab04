//! The generated dynamics kernels against independent numeric formulations, at 32 seeded random
//! states per robot:
//!
//! - `M` is symmetric positive definite, equals the Hessian of `T` in `Xdot` (exact for a
//!   quadratic form up to rounding) and `½ Xdotᵀ M Xdot = T`;
//! - `T` equals the kinetic energy computed from finite differences in time of the generated
//!   body frames with the paper's mass table (shared/paper-example.md), an oracle that shares
//!   nothing with the symbolic derivation but the frames;
//! - `psi` equals the numeric Lagrangian `-(d/dt ∂T/∂Xdot - ∂T/∂X + ∂Pi/∂X) + M Xddot` from
//!   central differences of the `energy` kernel;
//! - the fused `dynamics_terms` kernel (which may compute `gamma`, `M` and `psi` another way
//!   than the separate kernels, to share work) gives what `jacobian`, `gamma`, `mass_matrix` and
//!   `psi` give, to rounding.

mod common;

use common::{Rng, assert_close};
use rbss_runtime::Dynamics;

const STATES: usize = 32;

fn random_state<const N: usize>(home: &[f64], rng: &mut Rng) -> ([f64; N], [f64; N], [f64; N]) {
    let mut x = [0.0; N];
    let mut v = [0.0; N];
    let mut a = [0.0; N];
    for j in 0..N {
        x[j] = home[j] + 0.3 * rng.sym();
        v[j] = rng.sym();
        a[j] = rng.sym();
    }
    (x, v, a)
}

fn energy<K: Dynamics<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    v: &[f64; N],
) -> (f64, f64) {
    let mut e = [0.0; 2];
    k.energy(x, v, &mut e);
    (e[0], e[1])
}

/// Cholesky of a dense symmetric matrix; `false` when not positive definite.
/// Cholesky on the coordinates that carry mass: a coordinate whose row of `M` is zero moves
/// no body (the UR5's flange pose, the coordinates of its task frame, tied to the arm by their closure) and is
/// left out; every other must make `M` positive definite.
fn is_positive_definite<const N: usize>(m: &[[f64; N]; N]) -> bool {
    let idx: Vec<usize> = (0..N).filter(|&i| m[i].iter().any(|&x| x != 0.0)).collect();
    let k = idx.len();
    let mut l = vec![vec![0.0; k]; k];
    for i in 0..k {
        for j in 0..=i {
            let mut s = m[idx[i]][idx[j]];
            s -= (0..j).map(|c| l[i][c] * l[j][c]).sum::<f64>();
            if i == j {
                if s <= 0.0 {
                    return false;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    true
}

fn check_mass_and_psi<K: Dynamics<N, M>, const N: usize, const M: usize>(k: &K, seed: u64) {
    let s = k.structure();
    let mut rng = Rng::new(seed);
    for st in 0..STATES {
        let (x, v, a) = random_state::<N>(s.home, &mut rng);
        let mut mm = [[0.0; N]; N];
        k.mass_matrix(&x, &mut mm);
        // symmetric, positive definite, zero outside the declared blocks
        let mut block_of = [usize::MAX; N];
        for (b, cols) in k.mass_blocks().iter().enumerate() {
            for &c in cols.iter() {
                block_of[c] = b;
            }
        }
        assert!(
            block_of.iter().all(|&b| b != usize::MAX),
            "mass_blocks cover every coordinate"
        );
        for i in 0..N {
            for j in 0..N {
                assert_eq!(
                    mm[i][j], mm[j][i],
                    "{}: M not symmetric at ({i}, {j})",
                    s.name
                );
                if block_of[i] != block_of[j] {
                    assert_eq!(mm[i][j], 0.0, "{}: M[{i}][{j}] outside the blocks", s.name);
                }
            }
        }
        assert!(
            is_positive_definite(&mm),
            "{} state {st}: M is not positive definite",
            s.name
        );

        // The fused kernel against the separate ones.
        let (mut gf, mut gamf, mut mf, mut pf) = ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
        k.dynamics_terms(&x, &v, &mut gf, &mut gamf, &mut mf, &mut pf);
        let (mut g1, mut gam1, mut p1) = ([[0.0; M]; N], [0.0; M], [0.0; N]);
        k.jacobian(&x, &mut g1);
        k.gamma(&x, &v, &mut gam1);
        k.psi(&x, &v, &mut p1);
        let fused = |what: &str, a: f64, b: f64| {
            assert_close(
                &format!("{} state {st}: fused {what}", s.name),
                a,
                b,
                1e-12,
                1e-12,
            )
        };
        for j in 0..N {
            for i in 0..M {
                fused(&format!("G[{i}][{j}]"), gf[j][i], g1[j][i]);
            }
            for i in 0..N {
                fused(&format!("M[{i}][{j}]"), mf[j][i], mm[j][i]);
            }
            fused(&format!("psi[{j}]"), pf[j], p1[j]);
        }
        for i in 0..M {
            fused(&format!("gamma[{i}]"), gamf[i], gam1[i]);
        }

        // ½ vᵀ M v = T, and M = ∂²T/∂v² by exact polarisation of the quadratic form.
        let (t, _) = energy(k, &x, &v);
        let mut vmv = 0.0;
        for i in 0..N {
            for j in 0..N {
                vmv += v[i] * mm[i][j] * v[j];
            }
        }
        assert_close(
            &format!("{} state {st}: ½ vᵀMv vs T", s.name),
            0.5 * vmv,
            t,
            1e-12,
            1e-14,
        );
        for i in 0..N {
            for j in i..N {
                let mut e = [0.0; N];
                e[i] += 1.0;
                e[j] += 1.0;
                let (tij, _) = energy(k, &x, &e);
                let (ti, _) = energy(k, &x, &unit::<N>(i));
                let (tj, _) = energy(k, &x, &unit::<N>(j));
                // T(ei + ej) = T(ei) + T(ej) + M_ij (i != j); T(2 ei) = 4 T(ei) = 2 M_ii
                let hess = if i == j { 2.0 * ti } else { tij - ti - tj };
                assert_close(
                    &format!("{} state {st}: M[{i}][{j}] vs Hessian of T", s.name),
                    mm[i][j],
                    hess,
                    1e-12,
                    1e-12,
                );
            }
        }

        // psi against the numeric Lagrangian:
        //   M a - psi = d/dt(∂T/∂v) - ∂T/∂x + ∂Pi/∂x  along  x(t) = x + t v, v(t) = v + t a.
        let mut psi = [0.0; N];
        k.psi(&x, &v, &mut psi);
        let h = 1e-5;
        // ∂T/∂v_k is linear in v: a central difference with a unit step is exact up to rounding.
        let dt_dv = |x: &[f64; N], v: &[f64; N], kk: usize| {
            let (mut vp, mut vm) = (*v, *v);
            vp[kk] += 1.0;
            vm[kk] -= 1.0;
            (energy(k, x, &vp).0 - energy(k, x, &vm).0) / 2.0
        };
        for kk in 0..N {
            let (mut xp, mut xm, mut vp, mut vm) = (x, x, v, v);
            for j in 0..N {
                xp[j] += h * v[j];
                xm[j] -= h * v[j];
                vp[j] += h * a[j];
                vm[j] -= h * a[j];
            }
            let ddt = (dt_dv(&xp, &vp, kk) - dt_dv(&xm, &vm, kk)) / (2.0 * h);
            let hk = 1e-6 * x[kk].abs().max(1.0);
            let (mut xk1, mut xk2) = (x, x);
            xk1[kk] += hk;
            xk2[kk] -= hk;
            let (t1, p1) = energy(k, &xk1, &v);
            let (t2, p2) = energy(k, &xk2, &v);
            let dl = ddt - (t1 - t2) / (2.0 * hk) + (p1 - p2) / (2.0 * hk);
            let mut ma = 0.0;
            for j in 0..N {
                ma += mm[kk][j] * a[j];
            }
            // Errors: truncation h² ~ 1e-10 and rounding eps |T| / h ~ 1e-9 relative to |T| ~ 10..1000.
            assert_close(
                &format!("{} state {st}: psi[{}]", s.name, s.coordinates[kk]),
                psi[kk],
                ma - dl,
                1e-7,
                1e-6,
            );
        }
    }
}

fn unit<const N: usize>(i: usize) -> [f64; N] {
    let mut e = [0.0; N];
    e[i] = 1.0;
    e
}

#[test]
fn stewart_6ups_mass_matrix_and_psi() {
    check_mass_and_psi(&stewart_6ups::Stewart6Ups::default(), 0xd1_0001);
}

#[test]
fn five_bar_mass_matrix_and_psi() {
    check_mass_and_psi(&five_bar::FiveBar::default(), 0xd1_0002);
}

/// The joints' springs (in `Pi`) and armatures (in `T` and `M`) without the dampers, whose force
/// is not from a potential (tests/spring_pendulum.rs checks it).
#[test]
fn spring_pendulum_mass_matrix_and_psi() {
    let p = spring_pendulum::Params {
        c1: 0.0,
        c2: 0.0,
        ..Default::default()
    };
    check_mass_and_psi(&spring_pendulum::SpringPendulum::new(&p), 0xd1_000b);
}

#[test]
fn stewart_2stage_mass_matrix_and_psi() {
    check_mass_and_psi(&stewart_2stage::Stewart2Stage::default(), 0xd1_0003);
}

#[test]
fn ur5_mass_matrix_and_psi() {
    check_mass_and_psi(&ur5::Ur5::default(), 0xd1_0004);
}

#[test]
fn delta_mass_matrix_and_psi() {
    check_mass_and_psi(&delta::Delta::default(), 0xd1_0005);
}

#[test]
fn planar_3rrr_mass_matrix_and_psi() {
    check_mass_and_psi(&planar_3rrr::Planar3Rrr::default(), 0xd1_0006);
}

#[test]
fn tripod_3rps_mass_matrix_and_psi() {
    check_mass_and_psi(&tripod_3rps::Tripod3Rps::default(), 0xd1_0007);
}

#[test]
fn hexa_6rus_mass_matrix_and_psi() {
    check_mass_and_psi(&hexa_6rus::Hexa6Rus::default(), 0xd1_0008);
}

#[test]
fn hybrid_tricept_mass_matrix_and_psi() {
    check_mass_and_psi(&hybrid_tricept::HybridTricept::default(), 0xd1_0009);
}

/// The paper's mass table (shared/paper-example.md): mass, centre of mass in the body frame,
/// and the solid-cylinder inertia about it, axis z.
fn paper_body(name: &str) -> (f64, [f64; 3], [f64; 3]) {
    let cyl = |m: f64, r: f64, l: f64| {
        [
            m * (3.0 * r * r + l * l) / 12.0,
            m * (3.0 * r * r + l * l) / 12.0,
            m * r * r / 2.0,
        ]
    };
    if name.ends_with("_lower") {
        let m = 30.630528372500;
        (m, [0.0, 0.0, 0.25], cyl(m, 0.05, 0.5))
    } else if name.ends_with("_upper") {
        let m = 31.365661053441;
        (m, [0.0, 0.0, -0.40], cyl(m, 0.04, 0.8))
    } else if name == "platform" {
        let m = 74.160674941682;
        (m, [0.0; 3], cyl(m, 0.389, 0.02))
    } else {
        panic!("unexpected body {name}")
    }
}

/// `T` and `Pi` against the paper's bodies moved along the generated frames.
#[test]
fn stewart_6ups_energy_matches_the_paper_bodies() {
    use stewart_6ups::{BODIES, NB, Stewart6Ups, body_frames};
    let k = Stewart6Ups::default();
    let c = k.c;
    let mut rng = Rng::new(0xe0_0001);
    let h = 1e-6;
    for st in 0..STATES {
        let (x, v, _) = random_state::<24>(stewart_6ups::STRUCTURE.home, &mut rng);
        let frames = |x: &[f64; 24]| {
            let mut out = [[0.0; 12]; NB];
            body_frames(&c, x, &mut out);
            out
        };
        let f0 = frames(&x);
        let (mut xp, mut xm) = (x, x);
        for j in 0..24 {
            xp[j] += h * v[j];
            xm[j] -= h * v[j];
        }
        let (fp, fm) = (frames(&xp), frames(&xm));
        let (mut t_num, mut pi_num) = (0.0, 0.0);
        for b in 0..NB {
            let (m, com, inertia) = paper_body(BODIES[b]);
            let r = |fr: &[f64; 12]| -> [f64; 3] {
                // p + R com, R column-major
                std::array::from_fn(|i| {
                    fr[9 + i] + (0..3).map(|l| fr[3 * l + i] * com[l]).sum::<f64>()
                })
            };
            let (rp, rm, r0) = (r(&fp[b]), r(&fm[b]), r(&f0[b]));
            let vel: [f64; 3] = std::array::from_fn(|i| (rp[i] - rm[i]) / (2.0 * h));
            // body angular velocity: vee(Rᵀ Rdot)
            let rr = |fr: &[f64; 12], i: usize, j: usize| fr[3 * j + i];
            let rdot = |i: usize, j: usize| (rr(&fp[b], i, j) - rr(&fm[b], i, j)) / (2.0 * h);
            let s = |i: usize, j: usize| (0..3).map(|a| rr(&f0[b], a, i) * rdot(a, j)).sum::<f64>();
            let w = [s(2, 1), s(0, 2), s(1, 0)];
            t_num += 0.5 * m * vel.iter().map(|u| u * u).sum::<f64>()
                + 0.5
                    * (inertia[0] * w[0] * w[0]
                        + inertia[1] * w[1] * w[1]
                        + inertia[2] * w[2] * w[2]);
            pi_num += m * 9.81 * r0[2];
        }
        let mut e = [0.0; 2];
        k.energy(&x, &v, &mut e);
        assert_close(&format!("state {st}: T"), e[0], t_num, 1e-8, 1e-8);
        assert_close(&format!("state {st}: Pi"), e[1], pi_num, 1e-12, 1e-10);
    }
}
