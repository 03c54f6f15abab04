//! `export!(..., kinematics)` and the boundary's checks, on the five-bar (exported here as
//! kinematics only, so its dynamics functions must refuse): sizes and names, the error codes
//! and messages for null pointers, non-finite input, a solver failure and missing dynamics,
//! and forward kinematics back to the inverse kinematics' actuated values.

use std::ffi::CStr;

use rbss_ffi::{RBSS_ERR_ARGUMENT, RBSS_ERR_NO_DYNAMICS, RBSS_ERR_SOLVER, RBSS_OK};

rbss_ffi::export!(five_bar::FiveBar, kinematics);

fn message(h: *const RbssRobot) -> String {
    // SAFETY: a live handle or null; the string lives until the next call.
    unsafe { CStr::from_ptr(rbss_last_error(h)) }
        .to_str()
        .unwrap()
        .to_string()
}

#[test]
fn sizes_names_and_errors() {
    assert_eq!(rbss_abi_version(), rbss_ffi::ABI_VERSION);
    let h = rbss_new();
    assert!(!h.is_null());
    // SAFETY: `h` is live until `rbss_free`; every array has the length the header gives.
    unsafe {
        let n = rbss_size(h, 0);
        let m = rbss_size(h, 1);
        let k = rbss_size(h, 2);
        let o = rbss_size(h, 3);
        assert_eq!((n, m), (five_bar::N, five_bar::M));
        assert_eq!(rbss_size(h, 4), 0, "exported without dynamics");
        assert_eq!(rbss_size(h, 99), usize::MAX);
        assert_eq!(rbss_size(std::ptr::null(), 0), usize::MAX);
        assert_eq!(CStr::from_ptr(rbss_name(h)).to_str().unwrap(), "five_bar");
        assert!(rbss_coordinate(h, n).is_null());
        assert!(!rbss_constraint(h, m - 1).is_null());
        assert_eq!(rbss_actuated(h, k), usize::MAX);

        let mut home = vec![0.0; n];
        assert_eq!(rbss_home(h, home.as_mut_ptr()), RBSS_OK);
        let mut pose: Vec<f64> = (0..o).map(|i| home[rbss_output(h, i)]).collect();
        pose[0] += 0.01;
        let mut x = vec![0.0; n];
        assert_eq!(
            rbss_ik(h, pose.as_ptr(), std::ptr::null(), x.as_mut_ptr()),
            RBSS_OK,
            "{}",
            message(h)
        );
        assert_eq!(message(h), "");
        let mut f = vec![1.0; m];
        assert_eq!(rbss_constraints(h, x.as_ptr(), f.as_mut_ptr()), RBSS_OK);
        assert!(f.iter().all(|v| v.abs() < 1e-12), "{f:?}");
        // Forward kinematics from the home back to the same assembly.
        let q: Vec<f64> = (0..k).map(|i| x[rbss_actuated(h, i)]).collect();
        let mut x2 = vec![0.0; n];
        assert_eq!(
            rbss_fk(h, q.as_ptr(), std::ptr::null(), x2.as_mut_ptr()),
            RBSS_OK,
            "{}",
            message(h)
        );
        for (a, b) in x.iter().zip(&x2) {
            assert!((a - b).abs() < 1e-9, "{x:?} vs {x2:?}");
        }

        // Null and non-finite input.
        assert_eq!(
            rbss_ik(h, std::ptr::null(), std::ptr::null(), x.as_mut_ptr()),
            RBSS_ERR_ARGUMENT
        );
        assert_eq!(message(h), "`pose` is a null pointer");
        pose[1] = f64::INFINITY;
        assert_eq!(
            rbss_ik(h, pose.as_ptr(), std::ptr::null(), x.as_mut_ptr()),
            RBSS_ERR_ARGUMENT
        );
        assert_eq!(message(h), "`pose`[1] is not finite (inf)");
        // Out of reach: a solver error with the runtime's message; the output untouched.
        let far = vec![1e3; o];
        let before = x.clone();
        assert_eq!(
            rbss_ik(h, far.as_ptr(), std::ptr::null(), x.as_mut_ptr()),
            RBSS_ERR_SOLVER
        );
        assert!(!message(h).is_empty());
        assert_eq!(x, before);
        // No dynamics.
        let u = vec![0.0; k];
        let mut xddot = vec![0.0; n];
        let mut lambda = vec![0.0; m];
        assert_eq!(
            rbss_forward_dynamics(
                h,
                x.as_ptr(),
                home.as_ptr(),
                u.as_ptr(),
                xddot.as_mut_ptr(),
                lambda.as_mut_ptr()
            ),
            RBSS_ERR_NO_DYNAMICS
        );
        assert!(message(h).contains("without dynamics"), "{}", message(h));
        // A null handle: the argument error, no crash.
        assert_eq!(
            rbss_ik(
                std::ptr::null_mut(),
                pose.as_ptr(),
                std::ptr::null(),
                x.as_mut_ptr()
            ),
            RBSS_ERR_ARGUMENT
        );
        rbss_free(h);
        rbss_free(std::ptr::null_mut());
    }
}
