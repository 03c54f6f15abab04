//! The derivatives of inverse dynamics (`∂U`, `∂lambda` with respect to `X`, `Ẋ`, `Ẍ`) on
//! the generated 6-UPS (18 loop equations, 3 × 3 blocks), five-bar (one planar loop), UR5 (a
//! task frame on its flange, coordinates that move no mass: `M` singular, `[S | Gᵀ]` not) and spring
//! pendulum (a joint spring and damper):
//!
//! - against central differences of `inverse_dynamics` itself (a second `Data`), at states
//!   near home and off it (the derivatives hold wherever `[S | Gᵀ]` is regular, on the
//!   constraint manifold or not). Fourth-order differences, step `h_j = 1e-3 max(1, |z_j|)`
//!   per perturbed entry; error of an entry `|a - b| / (|a| + |b| + floor)` <= 1e-6 with the
//!   absolute floor `10 eps F / (h TOL)` (`F`: the largest `|U|`, `|lambda|`), as in
//!   `derivatives.rs`;
//! - the block elimination against the dense LU of `[S | Gᵀ]` (1e-10 of each block's scale);
//! - a round trip with forward dynamics' derivatives at the same state. With `Ẍ(X, Ẋ, U)` and
//!   `lambda(X, Ẋ, U)` from forward dynamics, inverse dynamics at `(X, Ẋ, Ẍ(X, Ẋ, U))` returns
//!   `U` and the same `lambda` for every `(X, Ẋ, U)`, so by the chain rule
//!
//!   ```text
//!   ∂U/∂Ẍ ∂Ẍ/∂U = I,   ∂U/∂X + ∂U/∂Ẍ ∂Ẍ/∂X = 0,   ∂U/∂Ẋ + ∂U/∂Ẍ ∂Ẍ/∂Ẋ = 0,
//!   ∂λ_ID/∂Ẍ ∂Ẍ/∂U = ∂λ_FD/∂U,   ∂λ_ID/∂X + ∂λ_ID/∂Ẍ ∂Ẍ/∂X = ∂λ_FD/∂X   (and for Ẋ),
//!   ```
//!
//!   and the other way round `P = ∂Ẍ/∂U ∂U/∂Ẍ` is the identity on the tangent space
//!   `ker G` (forward dynamics inverts inverse dynamics only on the accelerations that satisfy
//!   `G Ẍ = gamma`; `P` maps every `dẌ` into `ker G`): `P t = t` for `t` in `ker G` and
//!   `G P = 0`. Each identity is asserted to 1e-9 of the size of its terms.

mod common;

use common::XorShift;
use nalgebra::{DMatrix, SMatrix};
use rbss_runtime::tasks::{Derivatives, InverseDynamics};
use rbss_runtime::{
    Data, DynamicsMethod, ForwardDynamicsDerivatives, IdDerivativesSolver,
    InverseDynamicsDerivatives, Model, SolverError, forward_dynamics_derivatives, inverse_dynamics,
    inverse_dynamics_derivatives, inverse_dynamics_derivatives_with,
};

const TOL: f64 = 1e-6;

fn amax(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The worst entry error of `a` against `b` (both column lists); panics above `TOL`.
/// Returns `(worst, entries that differ)`.
fn compare(what: &str, a: &[Vec<f64>], b: &[Vec<f64>], fmax: f64) -> (f64, usize) {
    let floor = 10.0 * f64::EPSILON * fmax / (1e-3 * TOL);
    let (mut worst, mut differ) = (0.0_f64, 0);
    for (j, (a, b)) in a.iter().zip(b).enumerate() {
        for (i, (&a, &b)) in a.iter().zip(b).enumerate() {
            let rel = (a - b).abs() / (a.abs() + b.abs() + floor);
            assert!(
                rel <= TOL,
                "{what}[{i},{j}]: analytic {a:e}, numeric {b:e}, rel {rel:e}"
            );
            worst = worst.max(rel);
            differ += usize::from(a != b);
        }
    }
    (worst, differ)
}

fn cols<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, rows: usize) -> Vec<Vec<f64>> {
    (0..C)
        .map(|j| m.column(j).iter().take(rows).copied().collect())
        .collect()
}

/// `inverse_dynamics_derivatives` against central differences of `inverse_dynamics` at
/// `states` random motions `X = home + dx` (`|dx| <= off`), `Ẋ`, `Ẍ` in `[-1, 1]`; the block
/// elimination against the dense LU. Returns the worst error.
fn against_differences<K, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    off: f64,
    states: usize,
    method: DynamicsMethod,
) -> f64
where
    K: Derivatives<N, M> + InverseDynamics<N, M>,
{
    let home = model.structure().home;
    let mut rng = XorShift(0x1d_de71_a7e5);
    let (mut worst, mut differ) = (0.0_f64, 0);
    for _ in 0..states {
        let x: [f64; N] = core::array::from_fn(|j| home[j] + rng.range(-off, off));
        let v: [f64; N] = core::array::from_fn(|_| rng.range(-1.0, 1.0));
        let a: [f64; N] = core::array::from_fn(|_| rng.range(-1.0, 1.0));
        let (w, d) = check_at(name, model, x, v, a, method);
        worst = worst.max(w);
        differ += d;
    }
    assert!(
        differ > 0,
        "{name}: the derivatives equal their differences bit for bit"
    );
    println!("{name}: inverse-dynamics derivatives vs differences, worst {worst:.2e}");
    worst
}

/// The checks of [`against_differences`] at one motion: `(worst error, entries that differ)`.
fn check_at<K, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    x: [f64; N],
    v: [f64; N],
    a: [f64; N],
    method: DynamicsMethod,
) -> (f64, usize)
where
    K: Derivatives<N, M> + InverseDynamics<N, M>,
{
    let na = model.structure().actuated.len();
    let mut data = Data::new(model);
    let mut other = Data::new(model);
    let mut out = InverseDynamicsDerivatives::<N, M>::new();
    let mut dense = InverseDynamicsDerivatives::<N, M>::new();
    let (mut worst, mut differ) = (0.0_f64, 0);
    {
        (data.x, data.xdot, data.xddot) = (x, v, a);
        inverse_dynamics_derivatives(model, &mut data, &mut out, None)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(out.method, method, "{name}: the path that solved");
        // The derivatives' inverse dynamics is inverse dynamics.
        (other.x, other.xdot, other.xddot) = (x, v, a);
        inverse_dynamics(model, &mut other, None).unwrap();
        assert_eq!((data.u, data.lambda), (other.u, other.lambda));
        // The elimination against the dense LU.
        let mut d2 = data.clone();
        inverse_dynamics_derivatives_with(
            model,
            &mut d2,
            &mut dense,
            None,
            IdDerivativesSolver::DenseLu,
        )
        .unwrap_or_else(|e| panic!("{name} (dense): {e}"));
        assert_eq!(dense.method, DynamicsMethod::DenseLu);
        // Each scale at least that of the forces the derivatives balance (`∂r`, `M`) over
        // `max |G|` (a derivative that is zero comes out of them with that rounding).
        let forces = amax(out.dr_dx.as_slice())
            .max(amax(out.dr_dxdot.as_slice()))
            .max(amax(data.mass().as_slice()));
        let floor = forces / amax(data.g().as_slice()).max(1.0);
        let su = amax(out.du_dx.as_slice())
            .max(amax(out.du_dxdot.as_slice()))
            .max(amax(out.du_dxddot.as_slice()))
            .max(floor);
        let sl = amax(out.dlambda_dx.as_slice())
            .max(amax(out.dlambda_dxdot.as_slice()))
            .max(amax(out.dlambda_dxddot.as_slice()))
            .max(floor);
        for (what, p, q, scale) in [
            ("dU/dX", out.du_dx.as_slice(), dense.du_dx.as_slice(), su),
            (
                "dU/dXdot",
                out.du_dxdot.as_slice(),
                dense.du_dxdot.as_slice(),
                su,
            ),
            (
                "dU/dXddot",
                out.du_dxddot.as_slice(),
                dense.du_dxddot.as_slice(),
                su,
            ),
            (
                "dl/dX",
                out.dlambda_dx.as_slice(),
                dense.dlambda_dx.as_slice(),
                sl,
            ),
            (
                "dl/dXdot",
                out.dlambda_dxdot.as_slice(),
                dense.dlambda_dxdot.as_slice(),
                sl,
            ),
            (
                "dl/dXddot",
                out.dlambda_dxddot.as_slice(),
                dense.dlambda_dxddot.as_slice(),
                sl,
            ),
        ] {
            let diff = p
                .iter()
                .zip(q)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                diff <= 1e-10 * scale,
                "{name} {what}: elimination vs dense LU differ by {diff:e} (scale {scale:e})"
            );
        }
        // U and lambda of the solver, stacked.
        let mut solve = |x: &[f64; N], v: &[f64; N], a: &[f64; N]| -> Vec<f64> {
            (other.x, other.xdot, other.xddot) = (*x, *v, *a);
            inverse_dynamics(model, &mut other, None).unwrap_or_else(|e| panic!("{name}: {e}"));
            other.u[..na].iter().chain(&other.lambda).copied().collect()
        };
        let fmax = amax(&data.u[..na]).max(amax(&data.lambda));
        let mut num = [vec![], vec![], vec![]];
        for j in 0..N {
            for (which, z) in [x, v, a].into_iter().enumerate() {
                let h = 1e-3 * z[j].abs().max(1.0);
                let mut at = |s: f64| {
                    let mut zz = [x, v, a];
                    zz[which][j] += s * h;
                    solve(&zz[0], &zz[1], &zz[2])
                };
                let (p2, p1, m1, m2) = (at(2.0), at(1.0), at(-1.0), at(-2.0));
                num[which].push(
                    (0..na + M)
                        .map(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
                        .collect::<Vec<f64>>(),
                );
            }
        }
        let split = |d: &[Vec<f64>], lo: usize, hi: usize| -> Vec<Vec<f64>> {
            d.iter().map(|c| c[lo..hi].to_vec()).collect()
        };
        let pairs = [
            ("dU/dX", cols(&out.du_dx, na), split(&num[0], 0, na)),
            ("dU/dXdot", cols(&out.du_dxdot, na), split(&num[1], 0, na)),
            ("dU/dXddot", cols(&out.du_dxddot, na), split(&num[2], 0, na)),
            (
                "dlambda/dX",
                cols(&out.dlambda_dx, M),
                split(&num[0], na, na + M),
            ),
            (
                "dlambda/dXdot",
                cols(&out.dlambda_dxdot, M),
                split(&num[1], na, na + M),
            ),
            (
                "dlambda/dXddot",
                cols(&out.dlambda_dxddot, M),
                split(&num[2], na, na + M),
            ),
        ];
        for (what, an, nu) in &pairs {
            let (w, d) = compare(&format!("{name} {what}"), an, nu, fmax);
            worst = worst.max(w);
            differ += d;
        }
    }
    (worst, differ)
}

/// `C = A B` of column-major nalgebra views, as a `DMatrix`.
fn mul<const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<f64, R, K>,
    b: &SMatrix<f64, K, C>,
    rows: usize,
    inner: usize,
    cols: usize,
) -> DMatrix<f64> {
    let a = DMatrix::from_fn(rows, inner, |i, k| a[(i, k)]);
    let b = DMatrix::from_fn(inner, cols, |k, j| b[(k, j)]);
    a * b
}

fn dmat<const R: usize, const C: usize>(
    m: &SMatrix<f64, R, C>,
    rows: usize,
    cols: usize,
) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |i, j| m[(i, j)])
}

/// `|lhs - rhs|_max / scale`, asserted <= 1e-9.
fn identity(name: &str, what: &str, lhs: &DMatrix<f64>, rhs: &DMatrix<f64>, scale: f64) -> f64 {
    let err = amax((lhs - rhs).as_slice()) / scale;
    assert!(err <= 1e-9, "{name}: {what}: relative error {err:e}");
    err
}

/// The round trip of the module documentation at `states` states; returns the worst error.
fn round_trip<K, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    off: f64,
    states: usize,
) -> f64
where
    K: Derivatives<N, M> + InverseDynamics<N, M>,
{
    let home = model.structure().home;
    let na = model.structure().actuated.len();
    let mut rng = XorShift(0x0123_4567_89ab_cdef);
    let mut fd_data = Data::new(model);
    let mut id_data = Data::new(model);
    let mut fd = ForwardDynamicsDerivatives::<N, M>::new();
    let mut id = InverseDynamicsDerivatives::<N, M>::new();
    let mut worst = 0.0_f64;
    for _ in 0..states {
        fd_data.x = core::array::from_fn(|j| home[j] + rng.range(-off, off));
        fd_data.xdot = core::array::from_fn(|_| rng.range(-1.0, 1.0));
        let u: Vec<f64> = (0..na).map(|_| rng.range(-2.0, 2.0)).collect();
        forward_dynamics_derivatives(model, &mut fd_data, &mut fd, &u, None)
            .unwrap_or_else(|e| panic!("{name} (fd): {e}"));
        (id_data.x, id_data.xdot, id_data.xddot) = (fd_data.x, fd_data.xdot, fd_data.xddot);
        inverse_dynamics_derivatives(model, &mut id_data, &mut id, None)
            .unwrap_or_else(|e| panic!("{name} (id): {e}"));
        // Inverse dynamics returns U and the same lambda.
        let fu = amax(&u).max(amax(&fd_data.lambda)).max(1.0);
        for (a, &ua) in u.iter().enumerate() {
            assert!(
                (id_data.u[a] - ua).abs() <= 1e-9 * fu,
                "{name}: U round trip"
            );
        }
        for (l1, l2) in id_data.lambda.iter().zip(&fd_data.lambda) {
            assert!((l1 - l2).abs() <= 1e-9 * fu, "{name}: lambda round trip");
        }
        let du_da = dmat(&id.du_dxddot, na, N);
        let da_du = dmat(&fd.dxddot_du, N, na);
        let dl_da = dmat(&id.dlambda_dxddot, M, N);
        let nrm = |m: &DMatrix<f64>| amax(m.as_slice());
        // The multipliers' derivatives are at least at the scale of the forces they balance
        // (the gears for `U`, `∂r` for `X` and `Ẋ`) over `max |G|`: a multiplier that does not
        // move (the UR5's, whose closure ties its task frame, which moves no mass) comes out of them with that
        // rounding.
        let gmax = amax(model.structure().gear).max(1.0);
        let rmax = amax(id.dr_dx.as_slice()).max(amax(id.dr_dxdot.as_slice()));
        let s_u = nrm(&du_da) * nrm(&da_du) * N as f64;
        worst = worst.max(identity(
            name,
            "dU/dXddot dXddot/dU = I",
            &(&du_da * &da_du),
            &DMatrix::identity(na, na),
            s_u.max(1.0),
        ));
        worst = worst.max(identity(
            name,
            "dlambda_ID/dXddot dXddot/dU = dlambda_FD/dU",
            &(&dl_da * &da_du),
            &dmat(&fd.dlambda_du, M, na),
            (nrm(&dl_da) * nrm(&da_du) * N as f64)
                .max(nrm(&dmat(&fd.dlambda_du, M, na)))
                .max(gmax / amax(fd_data.g().as_slice())),
        ));
        for (what, du, dl, da, dlf) in [
            (
                "X",
                &id.du_dx,
                &id.dlambda_dx,
                &fd.dxddot_dx,
                &fd.dlambda_dx,
            ),
            (
                "Xdot",
                &id.du_dxdot,
                &id.dlambda_dxdot,
                &fd.dxddot_dxdot,
                &fd.dlambda_dxdot,
            ),
        ] {
            let chain = mul(&id.du_dxddot, da, na, N, N);
            let direct = dmat(du, na, N);
            let scale = (nrm(&du_da) * nrm(&dmat(da, N, N)) * N as f64).max(nrm(&direct));
            worst = worst.max(identity(
                name,
                &format!("dU/d{what} + dU/dXddot dXddot/d{what} = 0"),
                &(&direct + &chain),
                &DMatrix::zeros(na, N),
                scale,
            ));
            let chain = mul(&id.dlambda_dxddot, da, M, N, N);
            let scale = (nrm(&dl_da) * nrm(&dmat(da, N, N)) * N as f64)
                .max(nrm(&dmat(dl, M, N)))
                .max(nrm(&dmat(dlf, M, N)))
                .max(rmax / amax(fd_data.g().as_slice()));
            worst = worst.max(identity(
                name,
                &format!(
                    "dlambda_ID/d{what} + dlambda_ID/dXddot dXddot/d{what} = dlambda_FD/d{what}"
                ),
                &(dmat(dl, M, N) + &chain),
                &dmat(dlf, M, N),
                scale,
            ));
        }
        // P = dXddot/dU dU/dXddot: the identity on ker G, and G P = 0.
        let p = &da_du * &du_da;
        let g = dmat(fd_data.g(), M, N);
        let svd = g.clone().svd(false, true);
        let vt = svd.v_t.expect("V requested");
        let sv = &svd.singular_values;
        let rank = sv.iter().filter(|&&s| s > 1e-10 * sv[0]).count();
        // The rows of Vᵀ beyond the rank (and beyond M) span ker G.
        let mut kernel: Vec<Vec<f64>> = (rank..vt.nrows())
            .map(|i| vt.row(i).iter().copied().collect())
            .collect();
        for extra in 0..N.saturating_sub(vt.nrows()) {
            // Vᵀ is min(M, N) × N: complete the basis by projecting unit vectors.
            let mut e = DMatrix::<f64>::zeros(N, 1);
            e[(extra % N, 0)] = 1.0;
            let proj = &e - vt.transpose() * (&vt * &e);
            kernel.push(proj.iter().copied().collect());
        }
        let scale = nrm(&da_du) * nrm(&du_da) * N as f64;
        for t in kernel {
            let t = DMatrix::from_vec(N, 1, t);
            worst = worst.max(identity(
                name,
                "P t = t on ker G",
                &(&p * &t),
                &t,
                scale.max(1.0),
            ));
        }
        worst = worst.max(identity(
            name,
            "G P = 0",
            &(&g * &p),
            &DMatrix::zeros(M, N),
            (nrm(&g) * scale).max(1.0),
        ));
    }
    println!("{name}: inverse- and forward-dynamics derivatives round trip, worst {worst:.2e}");
    worst
}

#[test]
fn stewart_6ups() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    against_differences(
        "stewart_6ups",
        &model,
        0.0,
        1,
        DynamicsMethod::BlockElimination,
    );
    against_differences(
        "stewart_6ups",
        &model,
        0.02,
        2,
        DynamicsMethod::BlockElimination,
    );
    round_trip("stewart_6ups", &model, 0.02, 3);
}

#[test]
fn five_bar() {
    let model = Model::new(five_bar::FiveBar::default());
    against_differences(
        "five_bar",
        &model,
        0.05,
        4,
        DynamicsMethod::BlockElimination,
    );
    round_trip("five_bar", &model, 0.05, 4);
}

#[test]
fn ur5_massless_frame() {
    let model = Model::new(ur5::Ur5::default());
    against_differences("ur5", &model, 0.05, 3, DynamicsMethod::BlockElimination);
    round_trip("ur5", &model, 0.05, 3);
}

/// The spring pendulum has a passive degree of freedom: inverse dynamics, and so its
/// derivatives, are a typed `Underactuated`.
#[test]
fn spring_pendulum_is_underactuated() {
    let model = Model::new(spring_pendulum::SpringPendulum::default());
    let mut data = Data::new(&model);
    let mut out = InverseDynamicsDerivatives::new();
    let e = inverse_dynamics_derivatives(&model, &mut data, &mut out, None).unwrap_err();
    assert!(matches!(e, SolverError::Underactuated { .. }), "{e}");
}

/// The five-bar with its left arm fully stretched (`a1 = 0`, as in `dynamics.rs`): the left
/// inverse-kinematics block is singular, `[S | Gᵀ]` is not. The derivatives fall back to the
/// dense LU, as inverse dynamics does, and still match the differences.
#[test]
fn five_bar_singular_block_falls_back_to_dense() {
    let model = Model::new(five_bar::FiveBar::default());
    let (b, l1, l2) = (0.15, 0.2, 0.25);
    let th1 = std::f64::consts::PI / 3.0;
    let (px, py) = (-b + (l1 + l2) * th1.cos(), (l1 + l2) * th1.sin());
    let (dx, dy) = (px - b, py);
    let dist = dx.hypot(dy);
    let g = ((l1 * l1 + dist * dist - l2 * l2) / (2.0 * l1 * dist)).acos();
    let th2 = dy.atan2(dx) - g;
    let (ex, ey) = (b + l1 * th2.cos(), l1 * th2.sin());
    let a2 = (py - ey).atan2(px - ex) - th2;
    let x = [th1, 0.0, th2, a2, px, py];
    let v = [0.4, -0.3, 0.2, 0.1, -0.2, 0.3];
    let a = [0.3, 0.1, -0.5, 0.2, 0.1, -0.1];
    let (worst, differ) = check_at(
        "five_bar stretched",
        &model,
        x,
        v,
        a,
        DynamicsMethod::DenseLu,
    );
    assert!(differ > 0);
    println!("five_bar stretched arm (dense fallback): worst {worst:.2e}");
}

/// Non-finite input and an ill-conditioned system give typed errors, never a panic: a NaN
/// state is `NonFinite`; a condition limit below the 6-UPS's `[S | Gᵀ]` structure is
/// `Singular`.
#[test]
fn errors_are_typed() {
    let model = Model::new(five_bar::FiveBar::default());
    let mut data = Data::new(&model);
    let mut out = InverseDynamicsDerivatives::new();
    data.x[2] = f64::NAN;
    let e = inverse_dynamics_derivatives(&model, &mut data, &mut out, None).unwrap_err();
    assert!(matches!(e, SolverError::NonFinite { .. }), "{e}");

    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    let mut out = InverseDynamicsDerivatives::new();
    inverse_dynamics_derivatives(&model, &mut data, &mut out, None).unwrap();
    let mut options = model.options;
    options.cond_max = 1.01;
    let strict = Model::new(stewart_6ups::Stewart6Ups::default()).with_options(options);
    let e = inverse_dynamics_derivatives(&strict, &mut data, &mut out, None).unwrap_err();
    assert!(matches!(e, SolverError::Singular { .. }), "{e}");
}
