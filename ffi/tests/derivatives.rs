//! The C ABI's derivative functions (issue 36) on the five-bar exported with dynamics:
//! `rbss_forward_dynamics_derivatives`, `rbss_inverse_dynamics_derivatives`, `rbss_linearize`
//! and `rbss_step_derivatives` write the runtime's numbers (the same calls in this process, bit
//! for bit), column-major (the inverse-dynamics derivatives also against central differences of
//! `rbss_inverse_dynamics`); and their
//! refusals: a non-finite or null argument, a bad option, a state off the constraint manifold
//! for the linearisation (`RBSS_ERR_STATE`), a non-finite value on the way
//! (`RBSS_ERR_NONFINITE`) — each with nothing written.

use std::ffi::CStr;

use five_bar::{FiveBar, M, N};
use rbss_abi::{
    RBSS_LINEARIZE_ACTUATED, RBSS_LINEARIZE_OUTPUTS, RBSS_STEP_RK4, RBSS_STEP_SEMI_IMPLICIT_EULER,
};
use rbss_ffi::{RBSS_ERR_ARGUMENT, RBSS_ERR_NONFINITE, RBSS_ERR_STATE, RBSS_OK};
use rbss_runtime::{
    Baumgarte, Coordinates, Data, ForwardDynamicsDerivatives, InverseDynamicsDerivatives,
    Linearization, Model, StepDerivatives, forward_dynamics_derivatives,
    inverse_dynamics_derivatives, inverse_velocity, linearize, rk4_step_derivatives,
    semi_implicit_euler_step_derivatives,
};

rbss_ffi::export!(five_bar::FiveBar, dynamics);

const K: usize = 2;
const D: usize = N - M;

fn message(h: *const RbssRobot) -> String {
    // SAFETY: a live handle; the string lives until the next call.
    unsafe { CStr::from_ptr(rbss_last_error(h)) }
        .to_str()
        .unwrap()
        .to_string()
}

/// A state on the manifold with a velocity (the home, the outputs moving) and a control.
fn state(model: &Model<FiveBar, N, M>) -> ([f64; N], [f64; N], [f64; K]) {
    let mut data = Data::new(model);
    inverse_velocity(model, &mut data, &[0.3, -0.2]).unwrap();
    (data.x, data.xdot, [0.05, -0.03])
}

#[test]
fn the_derivatives_are_the_runtimes_column_major() {
    let model = Model::new(FiveBar::default());
    let (x, xdot, u) = state(&model);
    let h = rbss_new();
    assert!(!h.is_null());
    // SAFETY: `h` is live until `rbss_free`; every array has the length the header gives.
    unsafe {
        // Forward dynamics' derivatives.
        let mut data = Data::new(&model);
        data.x = x;
        data.xdot = xdot;
        let mut fdd = ForwardDynamicsDerivatives::new();
        forward_dynamics_derivatives(&model, &mut data, &mut fdd, &u, None).unwrap();
        let (mut xddot, mut lambda) = ([0.0; N], [0.0; M]);
        let (mut dx, mut dv, mut du) = ([0.0; N * N], [0.0; N * N], [0.0; N * K]);
        let (mut lx, mut lv, mut lu) = ([0.0; M * N], [0.0; M * N], [0.0; M * K]);
        let code = rbss_forward_dynamics_derivatives(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            xddot.as_mut_ptr(),
            lambda.as_mut_ptr(),
            dx.as_mut_ptr(),
            dv.as_mut_ptr(),
            du.as_mut_ptr(),
            lx.as_mut_ptr(),
            lv.as_mut_ptr(),
            lu.as_mut_ptr(),
        );
        assert_eq!(code, RBSS_OK, "{}", message(h));
        assert_eq!(xddot, data.xddot);
        assert_eq!(lambda, data.lambda);
        for i in 0..N {
            for j in 0..N {
                assert_eq!(dx[i + j * N], fdd.dxddot_dx[(i, j)], "dxddot_dx ({i}, {j})");
                assert_eq!(dv[i + j * N], fdd.dxddot_dxdot[(i, j)]);
            }
            for j in 0..K {
                assert_eq!(du[i + j * N], fdd.dxddot_du[(i, j)], "dxddot_du ({i}, {j})");
            }
        }
        for i in 0..M {
            for j in 0..N {
                assert_eq!(lx[i + j * M], fdd.dlambda_dx[(i, j)]);
                assert_eq!(lv[i + j * M], fdd.dlambda_dxdot[(i, j)]);
            }
            for j in 0..K {
                assert_eq!(
                    lu[i + j * M],
                    fdd.dlambda_du[(i, j)],
                    "dlambda_du ({i}, {j})"
                );
            }
        }
        assert!(dx.iter().any(|v| *v != 0.0) && du.iter().any(|v| *v != 0.0));

        // The linearisation, both coordinates: A and B column-major against the runtime's
        // row-major state_space.
        for (code_c, c) in [
            (RBSS_LINEARIZE_OUTPUTS, Coordinates::Outputs),
            (RBSS_LINEARIZE_ACTUATED, Coordinates::Actuated),
        ] {
            let mut data = Data::new(&model);
            data.x = x;
            data.xdot = xdot;
            let mut lin = Linearization::new();
            linearize(&model, &mut data, &mut lin, &u, None, c).unwrap();
            let (mut ra, mut rb) = ([0.0; 4 * D * D], [0.0; 2 * D * K]);
            lin.state_space(&mut ra, &mut rb).unwrap();
            let (mut a, mut b) = ([0.0; 4 * D * D], [0.0; 2 * D * K]);
            let code = rbss_linearize(
                h,
                code_c,
                x.as_ptr(),
                xdot.as_ptr(),
                u.as_ptr(),
                a.as_mut_ptr(),
                b.as_mut_ptr(),
            );
            assert_eq!(code, RBSS_OK, "{}", message(h));
            let w = 2 * D;
            for i in 0..w {
                for j in 0..w {
                    assert_eq!(a[i + j * w], ra[i * w + j], "{c:?}: A ({i}, {j})");
                }
                for j in 0..K {
                    assert_eq!(b[i + j * w], rb[i * K + j], "{c:?}: B ({i}, {j})");
                }
            }
            // The kinematic rows: A = [0 I; ...].
            assert_eq!(a[2 * w], 1.0);
        }

        // One step and its Jacobians, both methods, with and without Baumgarte's gains.
        for (method, gains) in [
            (RBSS_STEP_RK4, None),
            (RBSS_STEP_RK4, Some([5.0, 8.0])),
            (RBSS_STEP_SEMI_IMPLICIT_EULER, None),
            (RBSS_STEP_SEMI_IMPLICIT_EULER, Some([5.0, 8.0])),
        ] {
            let dt = 2e-3;
            let mut data = Data::new(&model);
            data.x = x;
            data.xdot = xdot;
            let mut st = StepDerivatives::new();
            let b = gains.map_or(Baumgarte::NONE, |[alpha, beta]| Baumgarte { alpha, beta });
            if method == RBSS_STEP_RK4 {
                rk4_step_derivatives(&model, &mut data, &mut st, &u, dt, b).unwrap();
            } else {
                semi_implicit_euler_step_derivatives(&model, &mut data, &mut st, &u, dt, b)
                    .unwrap();
            }
            let (mut x1, mut v1) = ([0.0; N], [0.0; N]);
            let (mut fx, mut fu) = ([0.0; 4 * N * N], [0.0; 2 * N * K]);
            let g = gains.as_ref().map_or(std::ptr::null(), |g| g.as_ptr());
            let code = rbss_step_derivatives(
                h,
                method,
                x.as_ptr(),
                xdot.as_ptr(),
                u.as_ptr(),
                dt,
                g,
                x1.as_mut_ptr(),
                v1.as_mut_ptr(),
                fx.as_mut_ptr(),
                fu.as_mut_ptr(),
            );
            assert_eq!(code, RBSS_OK, "{}", message(h));
            assert_eq!((x1, v1), (st.x, st.xdot), "method {method} {gains:?}");
            for i in 0..2 * N {
                for j in 0..2 * N {
                    assert_eq!(fx[i + j * 2 * N], st.fx(i, j), "F_x ({i}, {j})");
                }
                for j in 0..K {
                    assert_eq!(fu[i + j * 2 * N], st.fu(i, j), "F_u ({i}, {j})");
                }
            }
        }
        rbss_free(h);
    }
}

#[test]
fn refusals_are_typed_and_write_nothing() {
    let model = Model::new(FiveBar::default());
    let (x, xdot, u) = state(&model);
    let h = rbss_new();
    // SAFETY: as above; the null pointers are refused before any use.
    unsafe {
        let (mut a, mut b) = ([7.0; 4 * D * D], [7.0; 2 * D * K]);
        let untouched = |a: &[f64], b: &[f64]| a.iter().chain(b).all(|v| *v == 7.0);
        let lin =
            |c: i32, x: &[f64; N], xdot: &[f64; N], u: &[f64; K], a: &mut [f64], b: &mut [f64]| {
                rbss_linearize(
                    h,
                    c,
                    x.as_ptr(),
                    xdot.as_ptr(),
                    u.as_ptr(),
                    a.as_mut_ptr(),
                    b.as_mut_ptr(),
                )
            };
        // Off the manifold: the position 5 mm off, or a velocity across the constraints.
        let mut off = x;
        off[4] += 0.005;
        assert_eq!(
            lin(RBSS_LINEARIZE_OUTPUTS, &off, &xdot, &u, &mut a, &mut b),
            RBSS_ERR_STATE
        );
        let e = message(h);
        assert!(
            e.contains("not on the constraint manifold") && e.contains("5.000e-3"),
            "{e}"
        );
        let mut across = xdot;
        across[1] += 0.1;
        assert_eq!(
            lin(RBSS_LINEARIZE_OUTPUTS, &x, &across, &u, &mut a, &mut b),
            RBSS_ERR_STATE
        );
        // A bad option, a NaN.
        assert_eq!(lin(7, &x, &xdot, &u, &mut a, &mut b), RBSS_ERR_ARGUMENT);
        assert!(
            message(h).contains("RBSS_LINEARIZE_OUTPUTS (0)"),
            "{}",
            message(h)
        );
        let mut nan = x;
        nan[2] = f64::NAN;
        assert_eq!(
            lin(RBSS_LINEARIZE_OUTPUTS, &nan, &xdot, &u, &mut a, &mut b),
            RBSS_ERR_ARGUMENT
        );
        assert_eq!(message(h), "`x`[2] is not finite (NaN)");
        let bad_u = [0.0, f64::INFINITY];
        assert_eq!(
            lin(RBSS_LINEARIZE_OUTPUTS, &x, &xdot, &bad_u, &mut a, &mut b),
            RBSS_ERR_ARGUMENT
        );
        assert_eq!(message(h), "`u`[1] is not finite (inf)");
        assert!(untouched(&a, &b));
        // A null output: refused before anything is computed, the other output untouched.
        let code = rbss_linearize(
            h,
            RBSS_LINEARIZE_OUTPUTS,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            a.as_mut_ptr(),
            std::ptr::null_mut(),
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT);
        assert_eq!(message(h), "`b` is a null pointer");
        assert!(untouched(&a, &b));
        // And then a success clears the message.
        assert_eq!(
            lin(RBSS_LINEARIZE_OUTPUTS, &x, &xdot, &u, &mut a, &mut b),
            RBSS_OK
        );
        assert_eq!(message(h), "");

        // The step: a bad method, dt, gains.
        let (mut x1, mut v1) = ([7.0; N], [7.0; N]);
        let (mut fx, mut fu) = ([7.0; 4 * N * N], [7.0; 2 * N * K]);
        let mut step = |method: i32, dt: f64, gains: *const f64, xdot: &[f64; N]| {
            rbss_step_derivatives(
                h,
                method,
                x.as_ptr(),
                xdot.as_ptr(),
                u.as_ptr(),
                dt,
                gains,
                x1.as_mut_ptr(),
                v1.as_mut_ptr(),
                fx.as_mut_ptr(),
                fu.as_mut_ptr(),
            )
        };
        let null = std::ptr::null();
        assert_eq!(step(2, 1e-3, null, &xdot), RBSS_ERR_ARGUMENT);
        assert!(
            message(h).contains("RBSS_STEP_SEMI_IMPLICIT_EULER (1)"),
            "{}",
            message(h)
        );
        for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
            assert_eq!(
                step(RBSS_STEP_RK4, dt, null, &xdot),
                RBSS_ERR_ARGUMENT,
                "dt {dt}"
            );
            assert!(message(h).starts_with("`dt` = "), "{}", message(h));
        }
        let negative = [-1.0, 1.0];
        assert_eq!(
            step(RBSS_STEP_RK4, 1e-3, negative.as_ptr(), &xdot),
            RBSS_ERR_ARGUMENT
        );
        assert!(message(h).contains("gains >= 0"), "{}", message(h));
        // A rate so large that the velocity-squared terms overflow: a non-finite value met on
        // the way.
        let mut huge = xdot;
        huge[0] = 1e200;
        let code = step(RBSS_STEP_RK4, 1e-3, null, &huge);
        assert_eq!(code, RBSS_ERR_NONFINITE, "{}", message(h));
        assert!(
            x1.iter()
                .chain(&v1)
                .chain(&fx)
                .chain(&fu)
                .all(|v| *v == 7.0)
        );
        rbss_free(h);
    }
}

/// `rbss_inverse_dynamics_derivatives(h, x, xdot, xddot, ...)` at the five-bar's moving state
/// with an acceleration: `u`, `lambda` and the six matrices are the runtime's (bit for bit, the
/// `dU` matrices its first `actuated` rows, column-major), and they match central differences of
/// `rbss_inverse_dynamics` through the ABI (step 1e-6; inverse dynamics is linear in `Xddot`).
#[test]
fn inverse_dynamics_derivatives_are_the_runtimes_and_the_differences() {
    let model = Model::new(FiveBar::default());
    let (x, xdot, _) = state(&model);
    let xddot: [f64; N] = std::array::from_fn(|i| 0.3 - 0.1 * i as f64);
    let h = rbss_new();
    // SAFETY: `h` is live until `rbss_free`; every array has the length the header gives.
    unsafe {
        let mut data = Data::new(&model);
        data.x = x;
        data.xdot = xdot;
        data.xddot = xddot;
        let mut idd = InverseDynamicsDerivatives::new();
        inverse_dynamics_derivatives(&model, &mut data, &mut idd, None).unwrap();
        let (mut u, mut lambda) = ([0.0; K], [0.0; M]);
        let mut du = [[0.0; K * N]; 3];
        let mut dl = [[0.0; M * N]; 3];
        let code = rbss_inverse_dynamics_derivatives(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            xddot.as_ptr(),
            u.as_mut_ptr(),
            lambda.as_mut_ptr(),
            du[0].as_mut_ptr(),
            du[1].as_mut_ptr(),
            du[2].as_mut_ptr(),
            dl[0].as_mut_ptr(),
            dl[1].as_mut_ptr(),
            dl[2].as_mut_ptr(),
        );
        assert_eq!(code, RBSS_OK, "{}", message(h));
        assert_eq!(u[..], data.u[..K]);
        assert_eq!(lambda, data.lambda);
        let runtime_u = [&idd.du_dx, &idd.du_dxdot, &idd.du_dxddot];
        let runtime_l = [&idd.dlambda_dx, &idd.dlambda_dxdot, &idd.dlambda_dxddot];
        for w in 0..3 {
            for j in 0..N {
                for i in 0..K {
                    assert_eq!(du[w][i + j * K], runtime_u[w][(i, j)], "dU {w} ({i}, {j})");
                }
                for i in 0..M {
                    assert_eq!(
                        dl[w][i + j * M],
                        runtime_l[w][(i, j)],
                        "dlambda {w} ({i}, {j})"
                    );
                }
            }
        }
        assert!(du.iter().all(|d| d.iter().any(|v| *v != 0.0)));

        // Central differences of rbss_inverse_dynamics, column j of each matrix.
        let id = |x: &[f64; N], v: &[f64; N], a: &[f64; N]| {
            let (mut u, mut l) = ([0.0; K], [0.0; M]);
            let code = rbss_inverse_dynamics(
                h,
                x.as_ptr(),
                v.as_ptr(),
                a.as_ptr(),
                u.as_mut_ptr(),
                l.as_mut_ptr(),
            );
            assert_eq!(code, RBSS_OK, "{}", message(h));
            (u, l)
        };
        let step = 1e-6;
        let mut worst = 0.0_f64;
        for w in 0..3 {
            for j in 0..N {
                let mut p = [x, xdot, xddot];
                let mut q = [x, xdot, xddot];
                p[w][j] += step;
                q[w][j] -= step;
                let (up, lp) = id(&p[0], &p[1], &p[2]);
                let (uq, lq) = id(&q[0], &q[1], &q[2]);
                for i in 0..K {
                    let fd = (up[i] - uq[i]) / (2.0 * step);
                    let e = (fd - du[w][i + j * K]).abs() / (1.0 + fd.abs());
                    worst = worst.max(e);
                }
                for i in 0..M {
                    let fd = (lp[i] - lq[i]) / (2.0 * step);
                    let e = (fd - dl[w][i + j * M]).abs() / (1.0 + fd.abs());
                    worst = worst.max(e);
                }
            }
        }
        assert!(worst < 1e-6, "against central differences: {worst:e}");
        eprintln!("five-bar inverse-dynamics derivatives vs central differences: {worst:.1e}");

        // Refusals: a null output (nothing written), a non-finite acceleration.
        let mut u7 = [7.0; K];
        let code = rbss_inverse_dynamics_derivatives(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            xddot.as_ptr(),
            u7.as_mut_ptr(),
            lambda.as_mut_ptr(),
            du[0].as_mut_ptr(),
            du[1].as_mut_ptr(),
            du[2].as_mut_ptr(),
            dl[0].as_mut_ptr(),
            dl[1].as_mut_ptr(),
            std::ptr::null_mut(),
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT);
        assert_eq!(message(h), "`dlambda_dxddot` is a null pointer");
        assert_eq!(u7, [7.0; K]);
        let mut nan = xddot;
        nan[1] = f64::NAN;
        let code = rbss_inverse_dynamics_derivatives(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            nan.as_ptr(),
            u7.as_mut_ptr(),
            lambda.as_mut_ptr(),
            du[0].as_mut_ptr(),
            du[1].as_mut_ptr(),
            du[2].as_mut_ptr(),
            dl[0].as_mut_ptr(),
            dl[1].as_mut_ptr(),
            dl[2].as_mut_ptr(),
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT);
        assert_eq!(message(h), "`xddot`[1] is not finite (NaN)");
        assert_eq!(u7, [7.0; K]);
        rbss_free(h);
    }
}
