//! The derivatives of the equations of motion against finite differences, on four generated
//! robots: the paper's 6-UPS (closed chains, 18 constraints), the five-bar (one planar loop),
//! the UR5 (an open arm whose flange pose is a task frame, coordinates that move no mass, tied
//! to the flange by its closure: `M` singular, the saddle-point system not) and the spring pendulum (a joint spring and damper).
//!
//! - The generated kernel `dynamics_derivatives` (`∂r/∂X`, `∂r/∂Ẋ` of
//!   `r = M Ẍ - psi + Gᵀ lambda` and `∂c/∂X`, `∂c/∂Ẋ` of `c = G Ẍ - gamma`) against central
//!   differences of `dynamics_terms` at fixed `Ẍ`, `lambda`.
//! - `forward_dynamics_derivatives` (`∂Ẍ`, `∂lambda` with respect to `X`, `Ẋ`, `U`) against
//!   central differences of the forward-dynamics solver itself (a second `Data`, Pinocchio's
//!   way), at states near home and off it (the derivatives hold wherever the saddle-point
//!   system is regular, on the constraint manifold or not).
//!
//! Differences: fourth-order central, step `h_j = 1e-3 max(1, |z_j|)` per perturbed entry `z_j`
//! (truncation `O(h⁴)`, rounding `O(eps F / h)` with `F` the size of the differenced
//! function's terms). Error of an entry: `|a - b| / (|a| + |b| + floor)`, asserted `<= 1e-6`,
//! with the absolute floor `10 eps F / (h TOL)` (`h = 1e-3`, the smallest step) for entries
//! that are structurally or nearly zero: an entry passes with an absolute error of at most ten
//! times the rounding error of its difference. Analytic and numeric results are also asserted
//! not bit-identical.

mod common;

use common::XorShift;
use rbss_runtime::tasks::Derivatives;
use rbss_runtime::{
    Baumgarte, Data, DerivativesSolver, DynamicsMethod, ForwardDynamicsDerivatives, Model,
    SolverError, forward_dynamics, forward_dynamics_derivatives, forward_dynamics_derivatives_with,
};

const TOL: f64 = 1e-6;

thread_local! {
    /// Entries where the analytic and the numeric value differ (the comparison is not of a
    /// quantity with itself), on this test's thread: asserted non-zero per comparison run.
    static DIFFERING: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn differing() -> usize {
    DIFFERING.get()
}

/// Fourth-order central difference of `f` along entry `j` of `z`.
fn diff<const K: usize, const L: usize>(
    z: &[f64; K],
    j: usize,
    f: &mut dyn FnMut(&[f64; K]) -> [f64; L],
) -> [f64; L] {
    let h = 1e-3 * z[j].abs().max(1.0);
    let at = |s: f64, f: &mut dyn FnMut(&[f64; K]) -> [f64; L]| {
        let mut zz = *z;
        zz[j] += s * h;
        f(&zz)
    };
    let (p2, p1, m1, m2) = (at(2.0, f), at(1.0, f), at(-1.0, f), at(-2.0, f));
    core::array::from_fn(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
}

/// The worst entry error of `analytic` (column `j` is `col(j)`, `rows` long) against `numeric`,
/// as described in the module documentation; panics above `TOL`. Returns the worst error.
fn compare(what: &str, analytic: &[Vec<f64>], numeric: &[Vec<f64>], fmax: f64) -> f64 {
    let scale = analytic
        .iter()
        .chain(numeric)
        .flatten()
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut worst = 0.0_f64;
    for (j, (a, b)) in analytic.iter().zip(numeric).enumerate() {
        for (i, (&a, &b)) in a.iter().zip(b).enumerate() {
            let floor = 10.0 * f64::EPSILON * fmax / (1e-3 * TOL);
            let rel = (a - b).abs() / (a.abs() + b.abs() + floor);
            assert!(
                rel <= TOL,
                "{what}[{i},{j}]: analytic {a:e}, numeric {b:e}, rel {rel:e}"
            );
            worst = worst.max(rel);
            if a != b {
                DIFFERING.set(DIFFERING.get() + 1);
            }
        }
    }
    assert!(scale.is_finite(), "{what}: not finite");
    worst
}

fn cols<const R: usize, const C: usize>(
    m: &nalgebra::SMatrix<f64, R, C>,
    ncols: usize,
) -> Vec<Vec<f64>> {
    (0..ncols)
        .map(|j| m.column(j).iter().copied().collect())
        .collect()
}

/// A state near home: `X = home + dx` (`|dx| <= off`), a random `Ẋ`, `U` and `Ẍ`, `lambda`.
fn state<const N: usize, const M: usize>(
    home: &[f64],
    off: f64,
    rng: &mut XorShift,
) -> ([f64; N], [f64; N], [f64; N], [f64; M]) {
    let x = core::array::from_fn(|j| home[j] + rng.range(-off, off));
    let v = core::array::from_fn(|_| rng.range(-1.0, 1.0));
    let a = core::array::from_fn(|_| rng.range(-1.0, 1.0));
    let l = core::array::from_fn(|_| rng.range(-1.0, 1.0));
    (x, v, a, l)
}

/// The residuals `[r; c]` at fixed `Ẍ`, `lambda`, from `dynamics_terms`.
fn residuals<K: Derivatives<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    v: &[f64; N],
    a: &[f64; N],
    l: &[f64; M],
) -> ([f64; N], [f64; M]) {
    let (mut g, mut gamma, mut mass, mut psi) = ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
    k.dynamics_terms(x, v, &mut g, &mut gamma, &mut mass, &mut psi);
    let r = core::array::from_fn(|i| {
        (0..N).map(|k| mass[k][i] * a[k]).sum::<f64>() - psi[i]
            + (0..M).map(|c| g[i][c] * l[c]).sum::<f64>()
    });
    let c = core::array::from_fn(|row| (0..N).map(|k| g[k][row] * a[k]).sum::<f64>() - gamma[row]);
    (r, c)
}

/// The kernel `dynamics_derivatives` against central differences of `dynamics_terms`.
fn kernel_against_differences<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    k: &K,
    home: &[f64],
    states: usize,
) -> f64 {
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let before = differing();
    let mut worst = 0.0_f64;
    for _ in 0..states {
        let (x, v, a, l) = state::<N, M>(home, 0.05, &mut rng);
        let (mut rx, mut rv) = (
            nalgebra::SMatrix::<f64, N, N>::zeros(),
            nalgebra::SMatrix::<f64, N, N>::zeros(),
        );
        let (mut cx, mut cv) = (
            nalgebra::SMatrix::<f64, M, N>::zeros(),
            nalgebra::SMatrix::<f64, M, N>::zeros(),
        );
        k.dynamics_derivatives(
            &x,
            &v,
            &a,
            &l,
            &mut rx.data.0,
            &mut rv.data.0,
            &mut cx.data.0,
            &mut cv.data.0,
        );
        // The largest term summed into r and c: the differences' rounding scales with it.
        let (mut g, mut gamma, mut mass, mut psi) =
            ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
        k.dynamics_terms(&x, &v, &mut g, &mut gamma, &mut mass, &mut psi);
        let amax = |v: &[f64]| v.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let fmax = amax(&psi)
            .max(amax(&gamma))
            .max(amax(mass.as_flattened()) * amax(&a) * N as f64)
            .max(amax(g.as_flattened()) * amax(&l) * M as f64);
        let (mut nrx, mut nrv, mut ncx, mut ncv) = (vec![], vec![], vec![], vec![]);
        for j in 0..N {
            nrx.push(diff(&x, j, &mut |x| residuals(k, x, &v, &a, &l).0).to_vec());
            ncx.push(diff(&x, j, &mut |x| residuals(k, x, &v, &a, &l).1).to_vec());
            nrv.push(diff(&v, j, &mut |v| residuals(k, &x, v, &a, &l).0).to_vec());
            ncv.push(diff(&v, j, &mut |v| residuals(k, &x, v, &a, &l).1).to_vec());
        }
        worst = worst.max(compare(&format!("{name} dr/dX"), &cols(&rx, N), &nrx, fmax));
        worst = worst.max(compare(
            &format!("{name} dr/dXdot"),
            &cols(&rv, N),
            &nrv,
            fmax,
        ));
        worst = worst.max(compare(&format!("{name} dc/dX"), &cols(&cx, N), &ncx, fmax));
        worst = worst.max(compare(
            &format!("{name} dc/dXdot"),
            &cols(&cv, N),
            &ncv,
            fmax,
        ));
    }
    assert!(
        differing() > before,
        "{name}: the kernel equals its differences bit for bit"
    );
    println!("{name}: kernel derivatives vs differences, worst {worst:.2e}");
    worst
}

/// `forward_dynamics_derivatives` against central differences of `forward_dynamics`.
fn solver_against_differences<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    off: f64,
    states: usize,
    method: DynamicsMethod,
    baumgarte: Baumgarte,
) -> f64 {
    let home = model.structure().home;
    let na = model.structure().actuated.len();
    let mut rng = XorShift(0x2545_f491_4f6c_dd1d);
    let before = differing();
    let mut data = Data::new(model);
    let mut other = Data::new(model);
    let mut out = ForwardDynamicsDerivatives::<N, M>::new();
    let mut worst = 0.0_f64;
    for _ in 0..states {
        let (x, v, _, _) = state::<N, M>(home, off, &mut rng);
        let u: Vec<f64> = (0..na).map(|_| rng.range(-2.0, 2.0)).collect();
        data.x = x;
        data.xdot = v;
        forward_dynamics_derivatives_with(
            model,
            &mut data,
            &mut out,
            &u,
            None,
            baumgarte,
            DerivativesSolver::Auto,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(out.method, method, "{name}: the path that solved");
        against_dense_lu(name, model, &data, &out, &u, baumgarte);
        // Ẍ and lambda of the solver, stacked.
        let mut solve = |x: &[f64; N], v: &[f64; N], u: &[f64]| -> Vec<f64> {
            other.x = *x;
            other.xdot = *v;
            forward_dynamics(model, &mut other, u, None, baumgarte)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            other.xddot.iter().chain(&other.lambda).copied().collect()
        };
        let fmax = data
            .xddot
            .iter()
            .chain(&data.lambda)
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let split = |d: Vec<f64>| (d[..N].to_vec(), d[N..].to_vec());
        let (mut ax, mut lx, mut av, mut lv, mut au, mut lu) =
            (vec![], vec![], vec![], vec![], vec![], vec![]);
        for j in 0..N {
            let col = |f: &mut dyn FnMut(f64) -> Vec<f64>, z: f64| {
                let h = 1e-3 * z.abs().max(1.0);
                let (p2, p1, m1, m2) = (f(2.0 * h), f(h), f(-h), f(-2.0 * h));
                (0..N + M)
                    .map(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * h))
                    .collect::<Vec<f64>>()
            };
            let dx = col(
                &mut |s| {
                    let mut xx = x;
                    xx[j] += s;
                    solve(&xx, &v, &u)
                },
                x[j],
            );
            let (a, l) = split(dx);
            ax.push(a);
            lx.push(l);
            let dv = col(
                &mut |s| {
                    let mut vv = v;
                    vv[j] += s;
                    solve(&x, &vv, &u)
                },
                v[j],
            );
            let (a, l) = split(dv);
            av.push(a);
            lv.push(l);
            if j < na {
                let du = col(
                    &mut |s| {
                        let mut uu = u.clone();
                        uu[j] += s;
                        solve(&x, &v, &uu)
                    },
                    u[j],
                );
                let (a, l) = split(du);
                au.push(a);
                lu.push(l);
            }
        }
        worst = worst.max(compare(
            &format!("{name} dXddot/dX"),
            &cols(&out.dxddot_dx, N),
            &ax,
            fmax,
        ));
        worst = worst.max(compare(
            &format!("{name} dXddot/dXdot"),
            &cols(&out.dxddot_dxdot, N),
            &av,
            fmax,
        ));
        worst = worst.max(compare(
            &format!("{name} dXddot/dU"),
            &cols(&out.dxddot_du, na),
            &au,
            fmax,
        ));
        worst = worst.max(compare(
            &format!("{name} dlambda/dX"),
            &cols(&out.dlambda_dx, N),
            &lx,
            fmax,
        ));
        worst = worst.max(compare(
            &format!("{name} dlambda/dXdot"),
            &cols(&out.dlambda_dxdot, N),
            &lv,
            fmax,
        ));
        worst = worst.max(compare(
            &format!("{name} dlambda/dU"),
            &cols(&out.dlambda_du, na),
            &lu,
            fmax,
        ));
        // The derivatives' solve took the same Ẍ, lambda as forward dynamics.
        assert_eq!(data.xddot, {
            other.x = x;
            other.xdot = v;
            forward_dynamics(model, &mut other, &u, None, baumgarte).unwrap();
            other.xddot
        });
    }
    assert!(
        differing() > before,
        "{name}: the derivatives equal their differences bit for bit"
    );
    println!("{name}: forward-dynamics derivatives vs differences, worst {worst:.2e}");
    worst
}

/// The answer of the structured solve against the dense LU's at the same state (the largest
/// entry difference relative to the largest entry of the derivatives of `Ẍ`, resp. `lambda`
/// or the forces they balance over `max |G|`, <= 1e-10), and the residuals of
/// the saddle-point system `M dẌ + Gᵀ dlambda = -(∂r/∂X dX + ∂r/∂Ẋ dẊ - S dU)`,
/// `G dẌ = -(∂c/∂X dX + ∂c/∂Ẋ dẊ)` column by column, relative to the terms' size (<= 1e-12).
fn against_dense_lu<K: Derivatives<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    out: &ForwardDynamicsDerivatives<N, M>,
    u: &[f64],
    baumgarte: Baumgarte,
) {
    let mut d2 = data.clone();
    let mut dense = ForwardDynamicsDerivatives::<N, M>::new();
    forward_dynamics_derivatives_with(
        model,
        &mut d2,
        &mut dense,
        u,
        None,
        baumgarte,
        DerivativesSolver::SaddlePointLu,
    )
    .unwrap_or_else(|e| panic!("{name} (dense): {e}"));
    assert_eq!(dense.method, DynamicsMethod::SaddlePoint);
    let pairs: [(&str, &[f64], &[f64]); 6] = [
        (
            "dXddot/dX",
            out.dxddot_dx.as_slice(),
            dense.dxddot_dx.as_slice(),
        ),
        (
            "dXddot/dXdot",
            out.dxddot_dxdot.as_slice(),
            dense.dxddot_dxdot.as_slice(),
        ),
        (
            "dXddot/dU",
            out.dxddot_du.as_slice(),
            dense.dxddot_du.as_slice(),
        ),
        (
            "dlambda/dX",
            out.dlambda_dx.as_slice(),
            dense.dlambda_dx.as_slice(),
        ),
        (
            "dlambda/dXdot",
            out.dlambda_dxdot.as_slice(),
            dense.dlambda_dxdot.as_slice(),
        ),
        (
            "dlambda/dU",
            out.dlambda_du.as_slice(),
            dense.dlambda_du.as_slice(),
        ),
    ];
    // The scale of each: the largest entry of the three derivatives of the same quantity (Ẍ
    // or lambda), so that a structurally zero block compares at the rounding of its siblings.
    let amax = |v: &[f64]| v.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let sx = pairs[..3].iter().fold(0.0_f64, |m, p| m.max(amax(p.2)));
    // lambda: at least the size of the forces it balances (`∂r` and the gears) over that of `G`
    // (a multiplier that is zero comes out of `F - M Ẍ` with that rounding).
    let forces = amax(out.dr_dx.as_slice())
        .max(amax(out.dr_dxdot.as_slice()))
        .max(amax(model.structure().gear).max(1.0));
    let sl = pairs[3..]
        .iter()
        .fold(forces / amax(data.g().as_slice()), |m, p| m.max(amax(p.2)));
    for (i, (what, a, b)) in pairs.into_iter().enumerate() {
        let scale = if i < 3 { sx } else { sl };
        let diff = a
            .iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(
            diff <= 1e-10 * scale.max(f64::MIN_POSITIVE),
            "{name} {what}: structured vs dense LU differ by {diff:e} (scale {scale:e})"
        );
    }
    // Residuals of the saddle-point system, column by column.
    let s = model.structure();
    let (mass, g) = (data.mass(), data.g());
    let mut worst = 0.0_f64;
    let mut check = |a: Vec<f64>, b: Vec<f64>, x: Vec<f64>, l: Vec<f64>| {
        let mut size = 0.0_f64;
        let mut res = 0.0_f64;
        for i in 0..N {
            let mut r = a[i];
            size = size.max(a[i].abs());
            for k in 0..N {
                r -= mass[(i, k)] * x[k];
                size = size.max((mass[(i, k)] * x[k]).abs());
            }
            for c in 0..M {
                r -= g[(c, i)] * l[c];
                size = size.max((g[(c, i)] * l[c]).abs());
            }
            res = res.max(r.abs());
        }
        for c in 0..M {
            let mut r = b[c];
            size = size.max(b[c].abs());
            for k in 0..N {
                r -= g[(c, k)] * x[k];
                size = size.max((g[(c, k)] * x[k]).abs());
            }
            res = res.max(r.abs());
        }
        worst = worst.max(if res == 0.0 { 0.0 } else { res / size });
    };
    for j in 0..N {
        let col = |m: &dyn Fn(usize) -> f64, n: usize| (0..n).map(m).collect::<Vec<f64>>();
        check(
            col(&|i| -out.dr_dx[(i, j)], N),
            col(&|i| -out.dc_dx[(i, j)], M),
            col(&|i| out.dxddot_dx[(i, j)], N),
            col(&|i| out.dlambda_dx[(i, j)], M),
        );
        check(
            col(&|i| -out.dr_dxdot[(i, j)], N),
            col(&|i| -out.dc_dxdot[(i, j)], M),
            col(&|i| out.dxddot_dxdot[(i, j)], N),
            col(&|i| out.dlambda_dxdot[(i, j)], M),
        );
    }
    for (a, &j) in s.actuated.iter().enumerate() {
        let mut e = vec![0.0; N];
        e[j] = s.gear.get(a).copied().unwrap_or(1.0);
        check(
            e,
            vec![0.0; M],
            (0..N).map(|i| out.dxddot_du[(i, a)]).collect(),
            (0..M).map(|i| out.dlambda_du[(i, a)]).collect(),
        );
    }
    assert!(
        worst <= 1e-12,
        "{name}: residual of the derivatives' saddle-point solves {worst:e}"
    );
}

#[test]
fn stewart_6ups() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let home = model.structure().home;
    kernel_against_differences("stewart_6ups", model.kernels(), home, 4);
    solver_against_differences(
        "stewart_6ups",
        &model,
        0.0,
        1,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    solver_against_differences(
        "stewart_6ups",
        &model,
        0.02,
        3,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    // With Baumgarte's stabilisation (its gains' terms in ∂c/∂X, ∂c/∂Ẋ), off the manifold.
    let b = Baumgarte::DEFAULT;
    solver_against_differences("stewart_6ups", &model, 0.02, 2, DynamicsMethod::Reduced, b);
}

#[test]
fn five_bar() {
    let model = Model::new(five_bar::FiveBar::default());
    let home = model.structure().home;
    kernel_against_differences("five_bar", model.kernels(), home, 8);
    solver_against_differences(
        "five_bar",
        &model,
        0.0,
        1,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    solver_against_differences(
        "five_bar",
        &model,
        0.05,
        8,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    let b = Baumgarte {
        alpha: 0.0,
        beta: 10.0,
    };
    solver_against_differences("five_bar", &model, 0.05, 4, DynamicsMethod::Reduced, b);
}

#[test]
fn ur5_with_its_massless_frame() {
    let model = Model::new(ur5::Ur5::default());
    let home = model.structure().home;
    kernel_against_differences("ur5", model.kernels(), home, 8);
    solver_against_differences(
        "ur5",
        &model,
        0.0,
        1,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    solver_against_differences(
        "ur5",
        &model,
        0.05,
        8,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
}

#[test]
fn spring_pendulum() {
    let model = Model::new(spring_pendulum::SpringPendulum::default());
    let home = model.structure().home;
    kernel_against_differences("spring_pendulum", model.kernels(), home, 8);
    solver_against_differences(
        "spring_pendulum",
        &model,
        0.0,
        1,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
    solver_against_differences(
        "spring_pendulum",
        &model,
        0.05,
        8,
        DynamicsMethod::Reduced,
        Baumgarte::NONE,
    );
}

/// A non-finite state is a typed error, not a panic or NaN derivatives.
#[test]
fn non_finite_state_is_a_typed_error() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    let mut out = ForwardDynamicsDerivatives::new();
    data.xdot = [0.0; stewart_6ups::N];
    data.x[3] = f64::NAN;
    let err =
        forward_dynamics_derivatives(&model, &mut data, &mut out, &[0.0; 6], None).unwrap_err();
    assert!(matches!(err, SolverError::NonFinite { .. }), "{err:?}");
}

/// A condition limit below the saddle-point matrix's own: the elimination declines (its blocks'
/// condition numbers pass the limit) and the dense fallback refuses with a typed `Singular`, not
/// a panic or derivatives of a system declared ill-conditioned.
#[test]
fn ill_conditioned_is_a_typed_error() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    let mut out = ForwardDynamicsDerivatives::new();
    let u = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0];
    forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None).unwrap();
    assert!(out.cond_blocks > 1.0 && out.cond >= 1.0, "{out:?}");
    // Between what forward dynamics needs (its reduced matrix) and what the derivatives' blocks
    // have: forward dynamics answers, the derivatives' factors are refused.
    let mut options = model.options;
    options.cond_max = out.cond_blocks * 0.5;
    let strict = Model::new(stewart_6ups::Stewart6Ups::default()).with_options(options);
    match forward_dynamics_derivatives(&strict, &mut data, &mut out, &u, None) {
        Err(SolverError::Singular { what, cond, .. }) => {
            assert_eq!(what, "[M Gᵀ; G 0]", "{cond:e}");
            assert!(cond > options.cond_max, "{what}: {cond:e}");
        }
        other => panic!("expected Singular, got {other:?}"),
    }
}
