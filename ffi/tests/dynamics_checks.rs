//! The C ABI's checks of its inputs and outputs with dynamics, on the five-bar exported with
//! dynamics (issue 37):
//!
//! - `rbss_simulate` and `rbss_simulate_method` refuse an initial state inconsistent with the
//!   constraints (`RBSS_ERR_STATE`, the residual in the message) instead of projecting it
//!   silently; `rbss_simulate_checked` reports the residual and, with `project`, projects and
//!   reports the move, equal to the runtime's own projection of that state; within the
//!   tolerance the run is the plain `rbss_simulate`'s.
//! - The raw kernels report an inf or NaN output as `RBSS_ERR_NONFINITE` and leave the output
//!   untouched (before: `RBSS_OK` with inf in it); a finite output at a huge input is `RBSS_OK`.
//! - A function with several outputs refuses a null one before it writes any.

use std::ffi::CStr;

use rbss_ffi::{
    RBSS_ERR_ARGUMENT, RBSS_ERR_NONFINITE, RBSS_ERR_STATE, RBSS_METHOD_DOPRI5, RBSS_OK,
};
use rbss_runtime::{Data, Model, project_position, project_velocity};

rbss_ffi::export!(five_bar::FiveBar, dynamics);

fn message(h: *const RbssRobot) -> String {
    // SAFETY: a live handle; the string lives until the next call.
    unsafe { CStr::from_ptr(rbss_last_error(h)) }
        .to_str()
        .unwrap()
        .to_string()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, x| m.max(x.abs()))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (p, q)| m.max((p - q).abs()))
}

/// The first number after `label` in `text`.
fn number_after(text: &str, label: &str) -> f64 {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("no `{label}` in {text}"))
        + label.len();
    let tail: String = text[at..]
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | '-' | '+'))
        .collect();
    tail.parse().unwrap()
}

#[test]
fn an_inconsistent_initial_state_is_refused_or_projected_with_its_move() {
    let h = rbss_new();
    assert!(!h.is_null());
    let (n, m) = (five_bar::N, five_bar::M);
    // SAFETY: `h` is live until `rbss_free`; every array has the length the header gives.
    unsafe {
        let mut home = vec![0.0; n];
        assert_eq!(rbss_home(h, home.as_mut_ptr()), RBSS_OK);
        // The effector's x 5 mm off the loop, and a velocity along no constraint's null space.
        let mut x0 = home.clone();
        x0[4] += 0.005;
        let mut xdot0 = vec![0.0; n];
        xdot0[0] = 0.3;
        let mut f = vec![0.0; m];
        assert_eq!(rbss_constraints(h, x0.as_ptr(), f.as_mut_ptr()), RBSS_OK);
        let f_max = max_abs(&f);
        assert!((f_max - 0.005).abs() < 1e-9, "{f_max}");
        let mut g = vec![0.0; m * n];
        assert_eq!(rbss_jacobian(h, x0.as_ptr(), g.as_mut_ptr()), RBSS_OK);
        let gv_max = max_abs(
            &(0..m)
                .map(|r| (0..n).map(|j| g[r + j * m] * xdot0[j]).sum::<f64>())
                .collect::<Vec<_>>(),
        );
        assert!(gv_max > 1e-3, "{gv_max}");

        let (mut x, mut xdot) = (vec![7.0; n], vec![7.0; n]);
        let null = std::ptr::null();
        // The plain functions: refused, the residual named, nothing written.
        let code = rbss_simulate(
            h,
            x0.as_ptr(),
            xdot0.as_ptr(),
            null,
            0.05,
            1e-10,
            1e-12,
            x.as_mut_ptr(),
            xdot.as_mut_ptr(),
        );
        assert_eq!(code, RBSS_ERR_STATE, "{}", message(h));
        let e = message(h);
        assert!(e.contains("not consistent with the constraints"), "{e}");
        assert!(
            (number_after(&e, "max |f(x0)| =") - f_max).abs() < 1e-6 * f_max,
            "{e}"
        );
        assert!(
            (number_after(&e, "max |G xdot0| =") - gv_max).abs() < 1e-3 * gv_max,
            "{e}"
        );
        assert!(x.iter().chain(&xdot).all(|&v| v == 7.0));
        let code = rbss_simulate_method(
            h,
            RBSS_METHOD_DOPRI5,
            x0.as_ptr(),
            xdot0.as_ptr(),
            null,
            0.05,
            1e-10,
            1e-12,
            x.as_mut_ptr(),
            xdot.as_mut_ptr(),
        );
        assert_eq!(code, RBSS_ERR_STATE);

        // Checked, no projection: refused, the residuals in `state`, the moves 0.
        let mut state = [9.0; 4];
        let checked = |x0: &[f64],
                       xdot0: &[f64],
                       tol: f64,
                       project: i32,
                       x: &mut [f64],
                       xdot: &mut [f64],
                       state: &mut [f64; 4]| {
            rbss_simulate_checked(
                h,
                RBSS_METHOD_DOPRI5,
                x0.as_ptr(),
                xdot0.as_ptr(),
                std::ptr::null(),
                0.05,
                1e-10,
                1e-12,
                tol,
                project,
                x.as_mut_ptr(),
                xdot.as_mut_ptr(),
                state.as_mut_ptr(),
            )
        };
        assert_eq!(
            checked(&x0, &xdot0, 1e-6, 0, &mut x, &mut xdot, &mut state),
            RBSS_ERR_STATE
        );
        assert_eq!(state[0], f_max);
        assert!(
            (state[1] - gv_max).abs() <= 1e-12 * gv_max,
            "{state:?} {gv_max}"
        );
        assert_eq!(&state[2..], &[0.0, 0.0]);
        assert!(x.iter().all(|&v| v == 7.0));
        // A tolerance above the residuals accepts it (and projects it, as reported).
        assert_eq!(
            checked(&x0, &xdot0, 0.1, 0, &mut x, &mut xdot, &mut state),
            RBSS_OK,
            "{}",
            message(h)
        );
        let wide = state;
        // Projected on request: the move is the runtime's own projection of that state, and the
        // run ends on the constraints.
        assert_eq!(
            checked(&x0, &xdot0, 1e-6, 1, &mut x, &mut xdot, &mut state),
            RBSS_OK,
            "{}",
            message(h)
        );
        assert_eq!(state, wide);
        let model = Model::new(five_bar::FiveBar::default());
        let mut data = Data::new(&model);
        data.x.copy_from_slice(&x0);
        project_position(&model, &mut data).unwrap();
        data.xdot.copy_from_slice(&xdot0);
        project_velocity(&model, &mut data).unwrap();
        assert_eq!(state[2], max_diff(&data.x, &x0));
        assert_eq!(state[3], max_diff(&data.xdot, &xdot0));
        assert!(state[2] > 1e-4 && state[3] > 1e-4, "{state:?}");
        assert_eq!(rbss_constraints(h, x.as_ptr(), f.as_mut_ptr()), RBSS_OK);
        assert!(max_abs(&f) < 1e-9, "{f:?}");

        // A consistent state: the checked run (no projection asked) is the plain run, its
        // residuals and moves at rounding level.
        let (xc, vc) = (data.x, data.xdot);
        let (mut xa, mut va) = (vec![0.0; n], vec![0.0; n]);
        assert_eq!(
            rbss_simulate(
                h,
                xc.as_ptr(),
                vc.as_ptr(),
                null,
                0.05,
                1e-10,
                1e-12,
                xa.as_mut_ptr(),
                va.as_mut_ptr()
            ),
            RBSS_OK,
            "{}",
            message(h)
        );
        assert_eq!(
            checked(&xc, &vc, 1e-6, 0, &mut x, &mut xdot, &mut state),
            RBSS_OK
        );
        assert_eq!((x.clone(), xdot.clone()), (xa, va));
        assert!(state.iter().all(|&v| v < 1e-9), "{state:?}");

        // Bad arguments: a non-positive tolerance, a null `state`.
        assert_eq!(
            checked(&xc, &vc, 0.0, 0, &mut x, &mut xdot, &mut state),
            RBSS_ERR_ARGUMENT
        );
        assert!(message(h).contains("state_tol"), "{}", message(h));
        let code = rbss_simulate_checked(
            h,
            RBSS_METHOD_DOPRI5,
            xc.as_ptr(),
            vc.as_ptr(),
            null,
            0.05,
            1e-10,
            1e-12,
            1e-6,
            0,
            x.as_mut_ptr(),
            xdot.as_mut_ptr(),
            std::ptr::null_mut(),
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT);
        rbss_free(h);
    }
}

#[test]
fn raw_kernels_report_non_finite_outputs() {
    let h = rbss_new();
    let (n, m) = (five_bar::N, five_bar::M);
    // SAFETY: as above.
    unsafe {
        let mut home = vec![0.0; n];
        assert_eq!(rbss_home(h, home.as_mut_ptr()), RBSS_OK);
        let huge = vec![1e300; n];
        // Velocities of 1e300: every kernel quadratic in them overflows.
        let mut out = vec![5.0; n * n];
        for name in ["gamma", "psi", "energy"] {
            let (x, v, o) = (home.as_ptr(), huge.as_ptr(), out.as_mut_ptr());
            let code = match name {
                "gamma" => rbss_gamma(h, x, v, o),
                "psi" => rbss_psi(h, x, v, o),
                _ => rbss_energy(h, x, v, o),
            };
            assert_eq!(code, RBSS_ERR_NONFINITE, "{name}: {}", message(h));
            let e = message(h);
            assert!(
                e.contains(&format!("`{name}`["))
                    && e.contains("not finite")
                    && e.contains("1e300"),
                "{e}"
            );
            assert!(out.iter().all(|&v| v == 5.0), "{name} wrote its output");
        }
        // Positions of 1e300: the five-bar's f is affine in the effector's coordinates and
        // periodic in the angles, so f is finite (and huge): a success, as is G.
        let mut f = vec![0.0; m];
        assert_eq!(rbss_constraints(h, huge.as_ptr(), f.as_mut_ptr()), RBSS_OK);
        assert!(
            f.iter().all(|v| v.is_finite()) && max_abs(&f) > 1e299,
            "{f:?}"
        );
        let mut g = vec![0.0; m * n];
        assert_eq!(rbss_jacobian(h, huge.as_ptr(), g.as_mut_ptr()), RBSS_OK);
        // The mass matrix depends on the angles only: finite.
        assert_eq!(
            rbss_mass_matrix(h, huge.as_ptr(), out.as_mut_ptr()),
            RBSS_OK
        );
        assert!(out.iter().all(|v| v.is_finite()));
        // Moderate velocities: finite, success.
        let v = vec![1.0; n];
        assert_eq!(
            rbss_gamma(h, home.as_ptr(), v.as_ptr(), out.as_mut_ptr()),
            RBSS_OK
        );
        rbss_free(h);
    }
}

/// A function with several outputs checks every one before it writes any: a null `lambda`
/// (the last output) leaves `xddot` (`u`, `x`) as it was (before: `rbss_forward_dynamics`
/// wrote `xddot`, then failed on `lambda`).
#[test]
fn a_null_output_is_refused_before_any_output_is_written() {
    let h = rbss_new();
    let (n, m) = (five_bar::N, five_bar::M);
    let null = std::ptr::null_mut::<f64>();
    // SAFETY: as above; the null pointers are refused before any use.
    unsafe {
        let mut x = vec![0.0; n];
        assert_eq!(rbss_home(h, x.as_mut_ptr()), RBSS_OK);
        let (xdot, u) = (vec![0.0; n], vec![0.1, -0.2]);
        let mut first = vec![7.0; n];
        let untouched = |v: &[f64]| v.iter().all(|&e| e == 7.0);
        let code = rbss_forward_dynamics(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            first.as_mut_ptr(),
            null,
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT);
        assert_eq!(message(h), "`lambda` is a null pointer");
        assert!(untouched(&first), "rbss_forward_dynamics wrote xddot");
        let code = rbss_forward_dynamics_batch(
            h,
            1,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            first.as_mut_ptr(),
            null,
        );
        assert_eq!(
            (code, message(h).as_str()),
            (RBSS_ERR_ARGUMENT, "`lambda` is a null pointer")
        );
        assert!(untouched(&first), "rbss_forward_dynamics_batch wrote xddot");
        let xddot = vec![0.3; n];
        let code = rbss_inverse_dynamics(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            xddot.as_ptr(),
            first.as_mut_ptr(),
            null,
        );
        assert_eq!(
            (code, message(h).as_str()),
            (RBSS_ERR_ARGUMENT, "`lambda` is a null pointer")
        );
        assert!(untouched(&first), "rbss_inverse_dynamics wrote u");
        let code = rbss_simulate(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            0.01,
            1e-8,
            1e-8,
            first.as_mut_ptr(),
            null,
        );
        assert_eq!(
            (code, message(h).as_str()),
            (RBSS_ERR_ARGUMENT, "`xdot` is a null pointer")
        );
        assert!(untouched(&first), "rbss_simulate wrote x");
        let mut state = vec![7.0; 4];
        let code = rbss_simulate_checked(
            h,
            RBSS_METHOD_DOPRI5,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            0.01,
            1e-8,
            1e-8,
            1e-6,
            0,
            first.as_mut_ptr(),
            null,
            state.as_mut_ptr(),
        );
        assert_eq!(code, RBSS_ERR_ARGUMENT, "{}", message(h));
        assert!(
            untouched(&first) && untouched(&state),
            "rbss_simulate_checked wrote"
        );
        // The same calls with every output given succeed (the refusals were the null alone).
        let mut lambda = vec![0.0; m];
        let code = rbss_forward_dynamics(
            h,
            x.as_ptr(),
            xdot.as_ptr(),
            u.as_ptr(),
            first.as_mut_ptr(),
            lambda.as_mut_ptr(),
        );
        assert_eq!(code, RBSS_OK, "{}", message(h));
        assert!(!untouched(&first));
        rbss_free(h);
    }
}
