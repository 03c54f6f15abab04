//! The manifold linearisation (`linearize`) against finite differences along the manifold, on
//! the 6-UPS, the five-bar and the UR5 (its flange's task frame, which moves no mass), in both choices of independent
//! coordinates: perturb `y` (or `ẏ`, or `U`), re-solve the positions with the runtime's own
//! solve (inverse kinematics from the outputs, forward kinematics' Newton solve from the
//! actuated coordinates, each from the same warm start), re-solve the velocities
//! (`inverse_velocity` / `forward_velocity`), then forward dynamics: `ÿ = Ẍ[y]`.
//!
//! Differences: fourth-order central, step `h = 1e-3 max(1, |z|)`. Error of an entry:
//! `|a - b| / (|a| + |b| + floor)` with the floor `10 eps F / (h TOL)` (`F` the largest of the
//! state's `|Ẍ|`, `|lambda|`, as in `derivatives.rs`), asserted `<= 1e-6`; the position and
//! velocity solves run with `tol_f = tol_x = 1e-15` so that their convergence is below that.
//! Also checked: `G T = 0` for the tangent map, `A`, `B` laid out by `state_space`, and that
//! analytic and numeric values are not bit-identical.

mod common;

use common::XorShift;
use rbss_runtime::tasks::{Derivatives, ForwardKinematics, InverseKinematics, Velocity};
use rbss_runtime::{
    Coordinates, Data, Linearization, Model, SolverError, forward_dynamics, linearize,
};

const TOL: f64 = 1e-6;

/// Re-solves the state from `(y, ẏ)` from the warm start `x0`: positions, then velocities.
type Place<'a, const N: usize, const M: usize> =
    &'a dyn Fn(&mut Data<N, M>, &[f64], &[f64]) -> Result<(), SolverError>;

fn check<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    coordinates: Coordinates,
    place: Place<'_, N, M>,
    states: usize,
    off: f64,
) -> f64 {
    let s = model.structure();
    let idx: &[usize] = match coordinates {
        Coordinates::Outputs => s.outputs,
        Coordinates::Actuated => s.actuated,
    };
    let (d, na) = (idx.len(), s.actuated.len());
    let mut rng = XorShift(0x5851_f42d_4c95_7f2d);
    let mut lin = Linearization::<N, M>::new();
    let mut differing = 0usize;
    let mut worst = 0.0_f64;
    for _ in 0..states {
        let y: Vec<f64> = idx
            .iter()
            .map(|&j| s.home[j] + rng.range(-off, off))
            .collect();
        let yd: Vec<f64> = (0..d).map(|_| rng.range(-0.5, 0.5)).collect();
        let u: Vec<f64> = (0..na).map(|_| rng.range(-2.0, 2.0)).collect();
        let mut data = Data::new(model);
        place(&mut data, &y, &yd).unwrap_or_else(|e| panic!("{name}: place: {e}"));
        let at = data.clone();
        linearize(model, &mut data, &mut lin, &u, None, coordinates)
            .unwrap_or_else(|e| panic!("{name}: linearize: {e}"));
        // The same linearisation through the full derivatives (in the outputs' coordinates on
        // the elimination, the default solves only the directions on the manifold).
        let mut full = Linearization::<N, M>::new();
        full.full_derivatives = true;
        linearize(model, &mut at.clone(), &mut full, &u, None, coordinates)
            .unwrap_or_else(|e| panic!("{name}: linearize (full): {e}"));
        agree(name, &lin, &full, d, na);
        assert_eq!((lin.d, lin.na), (d, na));
        // G T = 0 and T[y, :] = I.
        let g = data.g().clone_owned();
        for k in 0..d {
            let gt = (0..M).fold(0.0_f64, |m, i| {
                m.max(
                    (0..N)
                        .map(|j| g[(i, j)] * lin.tangent[(j, k)])
                        .sum::<f64>()
                        .abs(),
                )
            });
            let gmax = g.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            let tmax = lin
                .tangent
                .column(k)
                .iter()
                .fold(0.0_f64, |m, v| m.max(v.abs()));
            assert!(gt <= 1e-13 * gmax * tmax, "{name}: G T column {k}: {gt:e}");
            for (i, &j) in idx.iter().enumerate() {
                assert_eq!(lin.tangent[(j, k)], if i == k { 1.0 } else { 0.0 });
            }
        }
        let fmax = data
            .xddot
            .iter()
            .chain(&data.lambda)
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let yddot = |y: &[f64], yd: &[f64], u: &[f64]| -> Vec<f64> {
            let mut other = Data::new(model);
            place(&mut other, y, yd).unwrap_or_else(|e| panic!("{name}: place: {e}"));
            forward_dynamics(model, &mut other, u, None, rbss_runtime::Baumgarte::NONE)
                .unwrap_or_else(|e| panic!("{name}: forward dynamics: {e}"));
            idx.iter().map(|&j| other.xddot[j]).collect()
        };
        let diff = |f: &dyn Fn(f64) -> Vec<f64>, z: f64| -> Vec<f64> {
            let h = 1e-3 * z.abs().max(1.0);
            let (p2, p1, m1, m2) = (f(2.0 * h), f(h), f(-h), f(-2.0 * h));
            (0..d)
                .map(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
                .collect()
        };
        let floor = 10.0 * f64::EPSILON * fmax / (1e-3 * TOL);
        let mut cmp = |what: &str, k: usize, analytic: &dyn Fn(usize) -> f64, num: Vec<f64>| {
            for (i, &b) in num.iter().enumerate() {
                let a = analytic(i);
                let rel = (a - b).abs() / (a.abs() + b.abs() + floor);
                assert!(
                    rel <= TOL,
                    "{name} {what}[{i},{k}]: analytic {a:e}, numeric {b:e}, rel {rel:e}"
                );
                worst = worst.max(rel);
                if a != b {
                    differing += 1;
                }
            }
        };
        for k in 0..d {
            let num = diff(
                &|h| {
                    let mut yy = y.clone();
                    yy[k] += h;
                    yddot(&yy, &yd, &u)
                },
                y[k],
            );
            cmp("dyddot/dy", k, &|i| lin.dyddot_dy[(i, k)], num);
            let num = diff(
                &|h| {
                    let mut vv = yd.clone();
                    vv[k] += h;
                    yddot(&y, &vv, &u)
                },
                yd[k],
            );
            cmp("dyddot/dydot", k, &|i| lin.dyddot_dydot[(i, k)], num);
        }
        for c in 0..na {
            let num = diff(
                &|h| {
                    let mut uu = u.clone();
                    uu[c] += h;
                    yddot(&y, &yd, &uu)
                },
                u[c],
            );
            cmp("dyddot/du", c, &|i| lin.dyddot_du[(i, c)], num);
        }
        // A and B as state_space lays them out.
        let w = 2 * d;
        let (mut a, mut b) = (vec![0.0; w * w], vec![0.0; w * na]);
        lin.state_space(&mut a, &mut b).unwrap();
        for i in 0..d {
            for k in 0..d {
                assert_eq!(a[i * w + k], 0.0);
                assert_eq!(a[i * w + d + k], if i == k { 1.0 } else { 0.0 });
                assert_eq!(a[(d + i) * w + k], lin.dyddot_dy[(i, k)]);
                assert_eq!(a[(d + i) * w + d + k], lin.dyddot_dydot[(i, k)]);
            }
            for c in 0..na {
                assert_eq!(b[i * na + c], 0.0);
                assert_eq!(b[(d + i) * na + c], lin.dyddot_du[(i, c)]);
            }
        }
        assert!(matches!(
            lin.state_space(&mut a[1..], &mut b),
            Err(SolverError::Dimension { .. })
        ));
    }
    assert!(differing > 0, "{name}: analytic equals numeric bit for bit");
    println!(
        "{name} {coordinates:?}: linearisation vs differences along the manifold, worst {worst:.2e}"
    );
    worst
}

/// `lin` and `full` agree to `1e-12` of each matrix's largest entry, the condition numbers
/// exactly (both from the blocks' norms or both from the same LU).
fn agree<const N: usize, const M: usize>(
    name: &str,
    lin: &Linearization<N, M>,
    full: &Linearization<N, M>,
    d: usize,
    na: usize,
) {
    assert_eq!((full.d, full.na), (d, na));
    assert_eq!(lin.cond, full.cond, "{name}: cond");
    let pairs = [
        ("tangent", &lin.tangent, &full.tangent, N, d),
        ("dxdot_dy", &lin.dxdot_dy, &full.dxdot_dy, N, d),
        ("dyddot_dy", &lin.dyddot_dy, &full.dyddot_dy, d, d),
        ("dyddot_dydot", &lin.dyddot_dydot, &full.dyddot_dydot, d, d),
        ("dyddot_du", &lin.dyddot_du, &full.dyddot_du, d, na),
    ];
    for (what, a, b, rows, cols) in pairs {
        let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        for i in 0..rows {
            for k in 0..cols {
                let (x, y) = (a[(i, k)], b[(i, k)]);
                assert!(
                    (x - y).abs() <= 1e-12 * scale,
                    "{name} {what}[{i},{k}]: {x:e} vs full derivatives' {y:e} (scale {scale:e})"
                );
            }
        }
        // Nothing outside the block in use.
        let outside = a
            .iter()
            .enumerate()
            .filter(|&(e, _)| e % N >= rows || e / N >= cols)
            .fold(0.0_f64, |m, (_, v)| m.max(v.abs()));
        assert_eq!(
            outside, 0.0,
            "{name} {what}: entries outside {rows} x {cols}"
        );
    }
}

fn tight<K: rbss_runtime::tasks::Robot<N, M>, const N: usize, const M: usize>(
    model: Model<K, N, M>,
) -> Model<K, N, M> {
    let mut o = model.options;
    o.tol_f = 1e-15;
    o.tol_x = 1e-15;
    model.with_options(o)
}

/// Both choices of coordinates on one robot.
fn both<K, const N: usize, const M: usize>(
    name: &str,
    model: Model<K, N, M>,
    off: f64,
    states: usize,
) where
    K: Derivatives<N, M> + InverseKinematics<N, M> + ForwardKinematics<N, M> + Velocity<N, M>,
{
    let model = tight(model);
    let home = model.structure().home;
    let outputs = |d: &mut Data<N, M>, y: &[f64], yd: &[f64]| {
        d.x.copy_from_slice(home);
        rbss_runtime::inverse_kinematics(&model, d, y)?;
        rbss_runtime::inverse_velocity(&model, d, yd)?;
        Ok(())
    };
    let actuated = |d: &mut Data<N, M>, q: &[f64], qd: &[f64]| {
        d.x.copy_from_slice(home);
        rbss_runtime::forward_kinematics(&model, d, q)?;
        rbss_runtime::forward_velocity(&model, d, qd)?;
        Ok(())
    };
    check(name, &model, Coordinates::Outputs, &outputs, states, off);
    check(name, &model, Coordinates::Actuated, &actuated, states, off);
}

#[test]
fn stewart_6ups() {
    both(
        "stewart_6ups",
        Model::new(stewart_6ups::Stewart6Ups::default()),
        0.02,
        3,
    );
}

#[test]
fn five_bar() {
    both(
        "five_bar",
        Model::new(five_bar::FiveBar::default()),
        0.05,
        6,
    );
}

#[test]
fn ur5_with_its_massless_frame() {
    both("ur5", Model::new(ur5::Ur5::default()), 0.05, 4);
}
