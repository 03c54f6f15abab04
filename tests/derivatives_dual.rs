//! The derivative kernel `dynamics_derivatives` and `forward_dynamics_derivatives` against
//! forward-mode dual numbers, on every generated robot with dynamics (the Cassie-like
//! closed-chain legs included).
//!
//! The reference: the robot's model file is derived again by `rbss_codegen::derive` (the same
//! graph the generator emitted the kernels from, parameters as leaves with their values), and
//! the graph is evaluated node by node in dual numbers `a + b ε` (`ε² = 0`) seeded along one
//! coordinate `X_j` or velocity `Ẋ_j`: every node's `b` is its exact directional derivative up
//! to rounding (no truncation, no step), giving `dM`, `dG`, `dpsi`, `dgamma` along each
//! direction. The evaluator below is written for this test over the graph's public nodes; it
//! shares no code with the generator's derivative (the chain rule it applies to named
//! intermediates) nor with the runtime.
//!
//! What is compared:
//!
//! - **Kernel**: at a random state `X` near home (not on the manifold), `Ẋ`, `Ẍ`, `lambda`,
//!   column `j` of `∂r/∂X` against `dM Ẍ - dpsi + dGᵀ lambda` along `X_j`, of `∂r/∂Ẋ` against
//!   `-dpsi` along `Ẋ_j`, of `∂c/∂X` against `dG Ẍ - dgamma`, of `∂c/∂Ẋ` against `-dgamma`.
//!   Error of each of the four matrices, normwise: `max |kernel - dual| / max s_i`, with `s_i`
//!   the size of the terms summed into an entry (`Σ_k |dM_ik Ẍ_k| + |dpsi_i| +
//!   Σ_c |dG_ci lambda_c|`, for `c` `Σ_k |dG_ik Ẍ_k| + |dgamma_i|`) and the maximum over the
//!   matrix (an entry whose terms cancel inside the graph, such as a column of `∂c/∂Ẋ` that is
//!   zero, compares at its matrix's rounding). Asserted `<= 1e-12`.
//! - **Forward-dynamics derivatives**: at a random state and `U`, the exact derivative of
//!   `(Ẍ, lambda)` along each `X_j`, `Ẋ_j`, `U_a` solves
//!   `[M Gᵀ; G 0] [dẌ; dlambda] = [dpsi + S dU - dM Ẍ - dGᵀ lambda; dgamma - dG Ẍ]` with
//!   the duals' `dM, dG, dpsi, dgamma`, the solver's `Ẍ`, `lambda` and the kernels' `M`, `G`;
//!   the right-hand side is formed and the system solved in double-double (LU with partial
//!   pivoting, `common/kkt.rs`'s arithmetic), the reference to which each of the six matrices
//!   `forward_dynamics_derivatives` returns is compared normwise: `max |runtime - reference| /
//!   max |reference|` per matrix, asserted `<= 1e-12`. The runtime's f64 solve has a forward
//!   error of order `kappa eps` (`kappa = ‖K‖∞ ‖K⁻¹‖∞` of the saddle-point matrix, from the
//!   double-double inverse, printed; at most 4.3e4 on these robots, so `kappa eps` stays below
//!   1e-11 and 1e-12 is not a bound that holds by conditioning alone: it is what the solve
//!   achieves here, measured). The backward error of the columns in that exactly
//!   differentiated system,
//!   normwise over each matrix (`max_col ‖K d - rhs‖∞ / max_col (‖K‖∞ ‖d‖∞ + ‖rhs‖∞)`), is
//!   condition-free and asserted `<= 1e-12`. The multipliers' scale in the forward error is at
//!   least `max |forces of the right-hand sides| / max |G|` (the UR5's multipliers on its
//!   task frame's closure are zero, their derivatives rounding).
//!
//! `cargo test --release --test derivatives_dual -- --nocapture` prints each robot's worst
//! errors and `kappa`.

// Matrix entries by their indices, as the formulas read.
#![allow(clippy::needless_range_loop)]

mod common;

use common::Rng;
use common::kkt::Dd;
use rbss_codegen::derive::{Derivation, derive};
use rbss_codegen::graph::{Graph, Node};
use rbss_runtime::tasks::Derivatives;
use rbss_runtime::{Data, ForwardDynamicsDerivatives, Model, forward_dynamics_derivatives};

/// A dual number `v + d ε`.
#[derive(Clone, Copy, Debug)]
struct Dual {
    v: f64,
    d: f64,
}

impl Dual {
    fn c(v: f64) -> Self {
        Dual { v, d: 0.0 }
    }
}

/// Every node of `g` in dual numbers, `x` and `xdot` carrying the derivatives `dx`, `dv`.
fn eval_dual(g: &Graph, x: &[f64], dx: &[f64], v: &[f64], dv: &[f64], p: &[f64]) -> Vec<Dual> {
    let mut val: Vec<Dual> = Vec::with_capacity(g.len());
    for id in 0..g.len() {
        let e = |i: u32| val[i as usize];
        let r = match g.node(id as u32) {
            Node::Num(r) => Dual::c(r.to_f64()),
            Node::Float(b) => Dual::c(f64::from_bits(b)),
            Node::Pi => Dual::c(std::f64::consts::PI),
            Node::X(i) => Dual {
                v: x[i as usize],
                d: dx[i as usize],
            },
            Node::V(i) => Dual {
                v: v[i as usize],
                d: dv[i as usize],
            },
            Node::P(j) => Dual::c(p[j as usize]),
            Node::In(_) => Dual::c(f64::NAN),
            Node::Add(a, b) => Dual {
                v: e(a).v + e(b).v,
                d: e(a).d + e(b).d,
            },
            Node::Mul(a, b) => Dual {
                v: e(a).v * e(b).v,
                d: e(a).d * e(b).v + e(a).v * e(b).d,
            },
            Node::Neg(a) => Dual {
                v: -e(a).v,
                d: -e(a).d,
            },
            Node::Div(a, b) => {
                let (a, b) = (e(a), e(b));
                let q = a.v / b.v;
                Dual {
                    v: q,
                    d: (a.d - q * b.d) / b.v,
                }
            }
            Node::Sin(a) => Dual {
                v: e(a).v.sin(),
                d: e(a).v.cos() * e(a).d,
            },
            Node::Cos(a) => Dual {
                v: e(a).v.cos(),
                d: -e(a).v.sin() * e(a).d,
            },
            Node::Sqrt(a) => {
                let s = e(a).v.sqrt();
                Dual {
                    v: s,
                    d: e(a).d / (2.0 * s),
                }
            }
            Node::Pow(a, b) => {
                let (a, b) = (e(a), e(b));
                let v = a.v.powf(b.v);
                let d = if b.d == 0.0 {
                    b.v * a.v.powf(b.v - 1.0) * a.d
                } else {
                    v * (b.d * a.v.ln() + b.v * a.d / a.v)
                };
                Dual { v, d }
            }
            Node::Log(a) => Dual {
                v: e(a).v.ln(),
                d: e(a).d / e(a).v,
            },
            Node::Exp(a) => {
                let v = e(a).v.exp();
                Dual { v, d: v * e(a).d }
            }
            Node::Atan2(y, xx) => {
                let (y, xx) = (e(y), e(xx));
                Dual {
                    v: y.v.atan2(xx.v),
                    d: (xx.v * y.d - y.v * xx.d) / (xx.v * xx.v + y.v * y.v),
                }
            }
            Node::Asin(a) => Dual {
                v: e(a).v.asin(),
                d: e(a).d / (1.0 - e(a).v * e(a).v).sqrt(),
            },
            Node::Acos(a) => Dual {
                v: e(a).v.acos(),
                d: -e(a).d / (1.0 - e(a).v * e(a).v).sqrt(),
            },
            Node::Abs(a) => Dual {
                v: e(a).v.abs(),
                d: e(a).d * e(a).v.signum() * f64::from(u8::from(e(a).v != 0.0)),
            },
        };
        val.push(r);
    }
    val
}

/// One compared entry: direction, row, kernel, duals, size of the terms.
type Entry = (usize, usize, f64, f64, f64);

/// The directional derivatives of `M` (row-major), `G` (row-major, M × N), `psi`, `gamma`.
struct Terms {
    dm: Vec<Vec<f64>>,
    dg: Vec<Vec<f64>>,
    dpsi: Vec<f64>,
    dgamma: Vec<f64>,
}

fn terms(d: &Derivation, val: &[Dual]) -> Terms {
    let dy = d.dynamics.as_ref().expect("dynamics");
    let at = |id: u32| val[id as usize].d;
    Terms {
        dm: dy
            .mass
            .iter()
            .map(|r| r.iter().map(|&i| at(i)).collect())
            .collect(),
        dg: d
            .g
            .iter()
            .map(|r| r.iter().map(|&i| at(i)).collect())
            .collect(),
        dpsi: dy.psi.iter().map(|&i| at(i)).collect(),
        dgamma: d.gamma.iter().map(|&i| at(i)).collect(),
    }
}

fn derivation(path: &str) -> (Derivation, Vec<f64>, Vec<String>) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let source = std::fs::read_to_string(root.join(path)).unwrap();
    let model = rbss_codegen::parse::parse_model(path, &source).unwrap_or_else(|e| panic!("{e:?}"));
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let names = model.coordinates.iter().map(|c| c.name.clone()).collect();
    let d = derive(&model, true, &vec![false; p.len()], &mut |_| {})
        .unwrap_or_else(|e| panic!("{path}: {}", e[0].message));
    (d, p, names)
}

fn amax(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// LU with partial pivoting in double-double of the row-major `k × k` `a`, solving every
/// right-hand side of `rhs` in place.
fn dd_solve_many(a: &[Vec<f64>], rhs: &mut [Vec<Dd>]) {
    let k = a.len();
    let mut a: Vec<Vec<Dd>> = a
        .iter()
        .map(|r| r.iter().map(|&v| Dd::from_f64(v)).collect())
        .collect();
    let mut perm: Vec<usize> = (0..k).collect();
    let mut l = vec![vec![Dd::ZERO; k]; k];
    for c in 0..k {
        let p = (c..k)
            .max_by(|&i, &j| a[i][c].abs().to_f64().total_cmp(&a[j][c].abs().to_f64()))
            .unwrap();
        assert!(a[p][c].hi != 0.0, "singular saddle-point matrix");
        a.swap(c, p);
        l.swap(c, p);
        perm.swap(c, p);
        for i in c + 1..k {
            let f = a[i][c].div(a[c][c]);
            l[i][c] = f;
            if f.hi == 0.0 {
                continue;
            }
            let pivot = a[c].clone();
            for (aij, &acj) in a[i][c + 1..].iter_mut().zip(&pivot[c + 1..]) {
                *aij = aij.sub(f.mul(acj));
            }
        }
    }
    for b in rhs.iter_mut() {
        let mut y: Vec<Dd> = perm.iter().map(|&i| b[i]).collect();
        for i in 0..k {
            for j in 0..i {
                y[i] = y[i].sub(l[i][j].mul(y[j]));
            }
        }
        for i in (0..k).rev() {
            for j in i + 1..k {
                y[i] = y[i].sub(a[i][j].mul(y[j]));
            }
            y[i] = y[i].div(a[i][i]);
        }
        *b = y;
    }
}

/// The checks of the module documentation on one robot at `states` random states; prints the
/// worst errors.
fn check<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    path: &str,
    model: &Model<K, N, M>,
    seed: u64,
    states: usize,
) {
    let (d, p, names) = derivation(path);
    let s = model.structure();
    assert_eq!((d.n, d.m), (N, M), "{name}: sizes");
    assert_eq!(names, s.coordinates, "{name}: coordinates");
    let na = s.actuated.len();
    let mut rng = Rng::new(seed);
    let mut data = Data::new(model);
    let mut out = ForwardDynamicsDerivatives::<N, M>::new();
    let (mut worst_kernel, mut worst_fwd, mut worst_bwd, mut kappa_max) =
        (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    let zero = [0.0; N];
    let unit = |j: usize| -> [f64; N] { core::array::from_fn(|i| f64::from(u8::from(i == j))) };
    for _ in 0..states {
        let x: [f64; N] = core::array::from_fn(|j| s.home[j] + 0.05 * rng.sym());
        let v: [f64; N] = core::array::from_fn(|_| rng.sym());
        let dirs: Vec<Terms> = (0..2 * N)
            .map(|j| {
                let (dx, dv) = if j < N {
                    (unit(j), zero)
                } else {
                    (zero, unit(j - N))
                };
                terms(&d, &eval_dual(&d.graph, &x, &dx, &v, &dv, &p))
            })
            .collect();

        // The kernel at a random Ẍ, lambda.
        let a: [f64; N] = core::array::from_fn(|_| rng.sym());
        let l: [f64; M] = core::array::from_fn(|_| 10.0 * rng.sym());
        let (mut rx, mut rv) = ([[0.0; N]; N], [[0.0; N]; N]);
        let (mut cx, mut cv) = ([[0.0; M]; N], [[0.0; M]; N]);
        model
            .kernels()
            .dynamics_derivatives(&x, &v, &a, &l, &mut rx, &mut rv, &mut cx, &mut cv);
        // (direction, row, kernel, dual, size of the terms) per entry of ∂r/∂X, ∂r/∂Ẋ, ∂c/∂X,
        // ∂c/∂Ẋ.
        let mut mats: [Vec<Entry>; 4] = Default::default();
        for (j, t) in dirs.iter().enumerate() {
            let (kr, kc) = if j < N {
                (&rx[j], &cx[j])
            } else {
                (&rv[j - N], &cv[j - N])
            };
            // (kernel, dual, size of the terms) per entry of the column of r, then of c.
            for i in 0..N {
                let (mut r, mut size) = (-t.dpsi[i], t.dpsi[i].abs());
                for k in 0..N {
                    r += t.dm[i][k] * a[k];
                    size += (t.dm[i][k] * a[k]).abs();
                }
                for c in 0..M {
                    r += t.dg[c][i] * l[c];
                    size += (t.dg[c][i] * l[c]).abs();
                }
                mats[usize::from(j >= N)].push((j, i, kr[i], r, size));
            }
            for c in 0..M {
                let (mut r, mut size) = (-t.dgamma[c], t.dgamma[c].abs());
                for k in 0..N {
                    r += t.dg[c][k] * a[k];
                    size += (t.dg[c][k] * a[k]).abs();
                }
                mats[2 + usize::from(j >= N)].push((j, c, kc[c], r, size));
            }
        }

        for (what, mat) in ["dr/dX", "dr/dXdot", "dc/dX", "dc/dXdot"].iter().zip(&mats) {
            let scale = mat.iter().fold(0.0_f64, |m, e| m.max(e.4));
            for &(j, i, k, r, _) in mat {
                let err = (k - r).abs();
                let rel = if err == 0.0 { 0.0 } else { err / scale };
                assert!(
                    rel <= 1e-12,
                    "{name}: {what}[{i}, {j}]: kernel {k:e} vs duals {r:e} ({rel:e})"
                );
                worst_kernel = worst_kernel.max(rel);
            }
        }

        // Forward dynamics' derivatives.
        let u: Vec<f64> = (0..na).map(|_| 2.0 * rng.sym()).collect();
        data.x = x;
        data.xdot = v;
        forward_dynamics_derivatives(model, &mut data, &mut out, &u, None)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let (xa, lam) = (data.xddot, data.lambda);
        let (mass, g) = (data.mass(), data.g());
        let k = N + M;
        let mut kk = vec![vec![0.0; k]; k];
        for i in 0..N {
            for j in 0..N {
                kk[i][j] = mass[(i, j)];
            }
            for c in 0..M {
                kk[i][N + c] = g[(c, i)];
                kk[N + c][i] = g[(c, i)];
            }
        }
        let knorm = kk
            .iter()
            .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0_f64, f64::max);
        // Right-hand sides in double-double: the 2 N directions, then the actuators.
        let dd = Dd::from_f64;
        let mut rhs: Vec<Vec<Dd>> = Vec::with_capacity(2 * N + na + k);
        for t in &dirs {
            let mut b = vec![Dd::ZERO; k];
            for i in 0..N {
                let mut acc = dd(t.dpsi[i]);
                for kx in 0..N {
                    acc = acc.sub(dd(t.dm[i][kx]).mul(dd(xa[kx])));
                }
                for c in 0..M {
                    acc = acc.sub(dd(t.dg[c][i]).mul(dd(lam[c])));
                }
                b[i] = acc;
            }
            for c in 0..M {
                let mut acc = dd(t.dgamma[c]);
                for kx in 0..N {
                    acc = acc.sub(dd(t.dg[c][kx]).mul(dd(xa[kx])));
                }
                b[N + c] = acc;
            }
            rhs.push(b);
        }
        for (a_i, &j) in s.actuated.iter().enumerate() {
            let mut b = vec![Dd::ZERO; k];
            b[j] = dd(s.gear.get(a_i).copied().unwrap_or(1.0));
            rhs.push(b);
        }
        let nrhs = rhs.len();
        // And the identity's columns, for ‖K⁻¹‖∞.
        for c in 0..k {
            let mut b = vec![Dd::ZERO; k];
            b[c] = dd(1.0);
            rhs.push(b);
        }
        let rhs0: Vec<Vec<Dd>> = rhs.clone();
        dd_solve_many(&kk, &mut rhs);
        let inv_norm = (0..k)
            .map(|i| (0..k).map(|c| rhs[nrhs + c][i].to_f64().abs()).sum::<f64>())
            .fold(0.0_f64, f64::max);
        let kappa = knorm * inv_norm;
        kappa_max = kappa_max.max(kappa);
        // The runtime's columns, in the order of the right-hand sides.
        let runtime = |col: usize| -> Vec<f64> {
            let (xm, lm, j) = match col {
                c if c < N => (&out.dxddot_dx, &out.dlambda_dx, c),
                c if c < 2 * N => (&out.dxddot_dxdot, &out.dlambda_dxdot, c - N),
                c => (&out.dxddot_du, &out.dlambda_du, c - 2 * N),
            };
            xm.column(j)
                .iter()
                .chain(lm.column(j).iter())
                .copied()
                .collect()
        };
        // Per matrix (X, Ẋ, U) x (Ẍ, lambda): the normwise forward error. The multipliers'
        // scale is at least that of the forces of the right-hand sides over `max |G|` (a
        // multiplier that does not move, such as the UR5's on its task frame's closure, comes out of
        // them with that rounding).
        let ranges = [(0, N), (N, 2 * N), (2 * N, nrhs)];
        let bound = 1e-12;
        let gmax = amax(g.as_slice());
        for (lo, hi) in ranges {
            let forces = (lo..hi).fold(0.0_f64, |m, col| {
                m.max(
                    rhs0[col][..N]
                        .iter()
                        .fold(0.0_f64, |m, v| m.max(v.to_f64().abs())),
                )
            });
            for (rlo, rhi, what) in [(0, N, "Ẍ"), (N, k, "lambda")] {
                let (mut diff, mut size) = (0.0_f64, 0.0_f64);
                for col in lo..hi {
                    let rt = runtime(col);
                    for i in rlo..rhi {
                        let r = rhs[col][i].to_f64();
                        diff = diff.max((rt[i] - r).abs());
                        size = size.max(r.abs());
                    }
                }
                if rlo == N {
                    size = size.max(forces / gmax);
                }
                if hi > lo && size > 0.0 {
                    let e = diff / size;
                    assert!(
                        e <= bound,
                        "{name}: d{what}/d[{lo}..{hi}]: forward error {e:e} > {bound:e} (kappa {kappa:e})"
                    );
                    worst_fwd = worst_fwd.max(e);
                }
            }
            // The backward error of the matrix's columns in the exactly differentiated system,
            // normwise over the matrix: `max ‖K d - b‖∞ / max (‖K‖∞ ‖d‖∞ + ‖b‖∞)`.
            let (mut res, mut den) = (0.0_f64, 0.0_f64);
            for col in lo..hi {
                let (rt, b) = (runtime(col), &rhs0[col]);
                let mut bn = 0.0_f64;
                for i in 0..k {
                    let mut acc = b[i];
                    for (j, &r) in rt.iter().enumerate() {
                        acc = acc.sub(dd(kk[i][j]).mul(dd(r)));
                    }
                    res = res.max(acc.to_f64().abs());
                    bn = bn.max(b[i].to_f64().abs());
                }
                den = den.max(knorm * amax(&rt) + bn);
            }
            let eta = if res == 0.0 { 0.0 } else { res / den };
            assert!(
                eta <= 1e-12,
                "{name}: columns {lo}..{hi}: backward error {eta:e}"
            );
            worst_bwd = worst_bwd.max(eta);
        }
    }
    println!(
        "{name}: kernel vs duals {worst_kernel:.2e}; forward_dynamics_derivatives: forward error \
         {worst_fwd:.2e} (kappa up to {kappa_max:.2e}), \
         backward error {worst_bwd:.2e}"
    );
}

macro_rules! robot {
    ($test:ident, $krate:ident, $ty:ident, $seed:expr, $states:expr) => {
        #[test]
        fn $test() {
            let model = Model::new($krate::$ty::default());
            check(
                stringify!($krate),
                concat!("models/", stringify!($krate), ".toml"),
                &model,
                $seed,
                $states,
            );
        }
    };
}

robot!(
    stewart_6ups_against_duals,
    stewart_6ups,
    Stewart6Ups,
    0xd0a1_0001,
    2
);
robot!(five_bar_against_duals, five_bar, FiveBar, 0xd0a1_0002, 4);
robot!(
    five_bar_turned_against_duals,
    five_bar_turned,
    FiveBarTurned,
    0xd0a1_0003,
    4
);
robot!(
    stewart_2stage_against_duals,
    stewart_2stage,
    Stewart2Stage,
    0xd0a1_0004,
    1
);
robot!(ur5_against_duals, ur5, Ur5, 0xd0a1_0005, 3);
robot!(delta_against_duals, delta, Delta, 0xd0a1_0006, 3);
robot!(
    planar_3rrr_against_duals,
    planar_3rrr,
    Planar3Rrr,
    0xd0a1_0007,
    3
);
robot!(
    tripod_3rps_against_duals,
    tripod_3rps,
    Tripod3Rps,
    0xd0a1_0008,
    3
);
robot!(hexa_6rus_against_duals, hexa_6rus, Hexa6Rus, 0xd0a1_0009, 2);
robot!(
    hybrid_tricept_against_duals,
    hybrid_tricept,
    HybridTricept,
    0xd0a1_000a,
    2
);
robot!(
    spring_pendulum_against_duals,
    spring_pendulum,
    SpringPendulum,
    0xd0a1_000b,
    4
);
robot!(
    four_bar_rod_against_duals,
    four_bar_rod,
    FourBarRod,
    0xd0a1_000c,
    4
);
robot!(gear_pair_against_duals, gear_pair, GearPair, 0xd0a1_000d, 4);
robot!(
    leg_four_bar_against_duals,
    leg_four_bar,
    LegFourBar,
    0xd0a1_000e,
    4
);
robot!(
    slider_crank_against_duals,
    slider_crank,
    SliderCrank,
    0xd0a1_000f,
    4
);
robot!(
    spatial_crank_against_duals,
    spatial_crank,
    SpatialCrank,
    0xd0a1_0010,
    4
);
robot!(
    cassie_legs_against_duals,
    cassie_legs,
    CassieLegs,
    0xd0a1_0011,
    2
);
