//! The hand-written five-bar fixture is itself right: its Jacobians and gamma against central
//! differences, its column-subset kernels against the full Jacobian, its home assembly.

mod common;

use common::XorShift;
use common::five_bar::{B, FiveBar, HOME, L1, M, N, STRUCTURE};
use rbss_runtime::{IK_BLOCK_ORDER_UNDECLARED, IkBlock, Kernels, Model, Structure};

fn random_state(rng: &mut XorShift) -> ([f64; N], [f64; N]) {
    let x = core::array::from_fn(|_| rng.range(-3.0, 3.0));
    let v = core::array::from_fn(|_| rng.range(-2.0, 2.0));
    (x, v)
}

fn close(a: f64, b: f64) -> bool {
    let rel = (a - b).abs() / (a.abs() + b.abs() + 1e-9);
    rel < 1e-6
}

#[test]
fn jacobian_matches_central_differences() {
    let k = FiveBar;
    let mut rng = XorShift(0x5EED_0001);
    let mut identical = 0;
    for _ in 0..32 {
        let (x, _) = random_state(&mut rng);
        let mut g = [[0.0; M]; N];
        k.jacobian(&x, &mut g);
        for j in 0..N {
            let h = f64::EPSILON.cbrt() * x[j].abs().max(1.0);
            let (mut xp, mut xm) = (x, x);
            xp[j] += h;
            xm[j] -= h;
            let (mut fp, mut fm) = ([0.0; M], [0.0; M]);
            k.constraints(&xp, &mut fp);
            k.constraints(&xm, &mut fm);
            for i in 0..M {
                let num = (fp[i] - fm[i]) / (xp[j] - xm[j]);
                let a = g[j][i];
                assert!(
                    close(a, num),
                    "G[{i},{j}]: kernel {a:e}, numeric {num:e}, diff {:e}",
                    a - num
                );
                if a == num && a != 0.0 && a != -1.0 {
                    identical += 1;
                }
            }
        }
    }
    assert!(
        identical < 10,
        "numeric and analytic suspiciously bit-identical"
    );
}

#[test]
fn gamma_matches_central_differences() {
    let k = FiveBar;
    let mut rng = XorShift(0x5EED_0002);
    for _ in 0..32 {
        let (x, v) = random_state(&mut rng);
        let mut gam = [0.0; M];
        k.gamma(&x, &v, &mut gam);
        // gamma = -(dG/dt) v along x(t) = x + t v.
        let h = f64::EPSILON.cbrt();
        let xp: [f64; N] = core::array::from_fn(|j| x[j] + h * v[j]);
        let xm: [f64; N] = core::array::from_fn(|j| x[j] - h * v[j]);
        let (mut gp, mut gm) = ([[0.0; M]; N], [[0.0; M]; N]);
        k.jacobian(&xp, &mut gp);
        k.jacobian(&xm, &mut gm);
        for i in 0..M {
            let num: f64 = -(0..N)
                .map(|j| (gp[j][i] - gm[j][i]) / (2.0 * h) * v[j])
                .sum::<f64>();
            assert!(
                close(gam[i], num),
                "gamma[{i}]: kernel {:e}, numeric {num:e}",
                gam[i]
            );
            assert_ne!(gam[i].to_bits(), num.to_bits());
        }
    }
}

#[test]
fn subset_kernels_write_the_same_entries_restricted_to_their_columns() {
    let k = FiveBar;
    let mut rng = XorShift(0x5EED_0003);
    let (x, _) = random_state(&mut rng);
    let mut full = [[f64::NAN; M]; N];
    k.jacobian(&x, &mut full);
    type JacobianKernel = fn(&FiveBar, &[f64; N], &mut [[f64; M]; N]);
    let subsets: [(&str, JacobianKernel, Vec<usize>); 2] = [
        (
            "jacobian_p",
            FiveBar::jacobian_p,
            STRUCTURE.passive.to_vec(),
        ),
        ("jacobian_ik", FiveBar::jacobian_ik, vec![0, 1, 2, 3]),
    ];
    for (name, kernel, cols) in subsets {
        let mut g = [[f64::NAN; M]; N];
        kernel(&k, &x, &mut g);
        for j in 0..N {
            for i in 0..M {
                let expect = if cols.contains(&j) {
                    full[j][i]
                } else {
                    f64::NAN
                };
                assert_eq!(
                    g[j][i].to_bits(),
                    expect.to_bits(),
                    "{name}: entry ({i},{j})"
                );
            }
        }
    }
    // Structural zeros are left untouched by the full Jacobian too.
    let written = full.iter().flatten().filter(|v| !v.is_nan()).count();
    assert_eq!(written, 12);
}

#[test]
fn home_is_an_elbow_out_assembly_with_the_effector_at_0_03() {
    let k = FiveBar;
    let mut f = [0.0; M];
    k.constraints(&HOME, &mut f);
    assert!(f.iter().all(|v| v.abs() < 1e-15), "f(home) = {f:?}");
    assert_eq!((HOME[4], HOME[5]), (0.0, 0.3));
    let left_elbow_x = -B + L1 * HOME[0].cos();
    let right_elbow_x = B + L1 * HOME[2].cos();
    assert!(left_elbow_x < -B && right_elbow_x > B);
}

#[test]
fn model_checks_the_structure() {
    let m = Model::new(FiveBar);
    assert_eq!(m.structure().name, "five_bar");

    /// The five-bar with another structure, and a declared IK block order (`ORDER`).
    #[derive(Clone, Copy)]
    struct Broken<const ORDER: usize = IK_BLOCK_ORDER_UNDECLARED>(&'static Structure);
    impl<const ORDER: usize> Kernels<N, M> for Broken<ORDER> {
        const IK_BLOCK_ORDER: usize = ORDER;
        fn structure(&self) -> &'static Structure {
            self.0
        }
        fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
            FiveBar.constraints(x, f)
        }
        fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
            FiveBar.jacobian(x, g)
        }
        fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
            FiveBar.jacobian_p(x, g)
        }
        fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
            FiveBar.jacobian_ik(x, g)
        }
        fn gamma(&self, x: &[f64; N], v: &[f64; N], g: &mut [f64; M]) {
            FiveBar.gamma(x, v, g)
        }
    }
    // An output may be actuated too (a coordinate in no loop), but never in a block.
    static OUTPUT_IN_A_BLOCK: Structure = Structure {
        outputs: &[0, 5],
        ..STRUCTURE
    };
    static OVERLAPPING_BLOCKS: Structure = Structure {
        ik_blocks: &[
            IkBlock {
                rows: &[0, 1],
                cols: &[0, 1],
            },
            IkBlock {
                rows: &[1, 3],
                cols: &[2, 3],
            },
        ],
        ..STRUCTURE
    };
    static NOT_SQUARE: Structure = Structure {
        ik_blocks: &[IkBlock {
            rows: &[0, 1, 2, 3],
            cols: &[0, 1, 2],
        }],
        ..STRUCTURE
    };
    static BAD_HOME: Structure = Structure {
        home: &[0.0; 5],
        ..STRUCTURE
    };
    // Gear ratios: one per actuator (two here), finite and nonzero.
    static GEAR_LENGTH: Structure = Structure {
        gear: &[20.0],
        ..STRUCTURE
    };
    static GEAR_ZERO: Structure = Structure {
        gear: &[20.0, 0.0],
        ..STRUCTURE
    };
    for s in [
        &OUTPUT_IN_A_BLOCK,
        &OVERLAPPING_BLOCKS,
        &NOT_SQUARE,
        &BAD_HOME,
        &GEAR_LENGTH,
        &GEAR_ZERO,
    ] {
        let e = Model::try_new(Broken::<IK_BLOCK_ORDER_UNDECLARED>(s))
            .err()
            .expect("must be rejected");
        assert!(e.to_string().contains("five_bar"), "{e}");
    }

    // A declared block order must be the structure's: the solvers compile only that size.
    assert!(Model::try_new(Broken::<2>(&STRUCTURE)).is_ok());
    for e in [
        Model::try_new(Broken::<3>(&STRUCTURE)).err(),
        Model::try_new(Broken::<0>(&STRUCTURE)).err(),
    ] {
        let e = e
            .expect("a wrong IK_BLOCK_ORDER must be rejected")
            .to_string();
        assert!(e.contains("IK_BLOCK_ORDER") && e.contains("order 2"), "{e}");
    }
}
