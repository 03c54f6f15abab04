//! [`export!`](crate::export): the `extern "C"` functions of `include/rbss.h` for one robot.

/// The `extern "C"` functions of `include/rbss.h` for one robot type, in a `cdylib` crate:
/// `rbss_ffi::export!(stewart_6ups::Stewart6Ups, dynamics);` (or `kinematics` for a robot
/// generated without dynamics, whose dynamics functions return `RBSS_ERR_NO_DYNAMICS`). The
/// crate `$krate` is the generated crate (its `N` and `M` are the sizes).
#[macro_export]
macro_rules! export {
    ($krate:ident :: $ty:ident, dynamics) => {
        $crate::export!(@common $krate :: $ty, true);
        $crate::export!(@dynamics);
    };
    ($krate:ident :: $ty:ident, kinematics) => {
        $crate::export!(@common $krate :: $ty, false);
        $crate::export!(@no_dynamics);
    };
    (@common $krate:ident :: $ty:ident, $dynamics:expr) => {
        /// The robot's handle type.
        pub type RbssRobot = $crate::Handle<$krate::$ty, { $krate::N }, { $krate::M }>;
        use ::std::ffi::{c_char, c_int};

        #[unsafe(no_mangle)]
        pub extern "C" fn rbss_abi_version() -> u32 {
            $crate::ABI_VERSION
        }
        #[unsafe(no_mangle)]
        pub extern "C" fn rbss_new() -> *mut RbssRobot {
            $crate::new(<$krate::$ty as ::core::default::Default>::default())
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_free(h: *mut RbssRobot) {
            unsafe { $crate::free(h) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_last_error(h: *const RbssRobot) -> *const c_char {
            unsafe { $crate::last_error(h) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_size(h: *const RbssRobot, what: c_int) -> usize {
            unsafe { $crate::size(h, what, $dynamics) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_name(h: *const RbssRobot) -> *const c_char {
            unsafe { $crate::name(h) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_coordinate(h: *const RbssRobot, i: usize) -> *const c_char {
            unsafe { $crate::label(h, false, i) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_constraint(h: *const RbssRobot, i: usize) -> *const c_char {
            unsafe { $crate::label(h, true, i) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_actuated(h: *const RbssRobot, i: usize) -> usize {
            unsafe { $crate::index(h, false, i) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_output(h: *const RbssRobot, i: usize) -> usize {
            unsafe { $crate::index(h, true, i) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_home(h: *mut RbssRobot, x: *mut f64) -> c_int {
            unsafe { $crate::kinematics::home(h, x) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_ik(
            h: *mut RbssRobot,
            pose: *const f64,
            x_start: *const f64,
            x: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::ik(h, pose, x_start, x) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_fk(
            h: *mut RbssRobot,
            q: *const f64,
            x_start: *const f64,
            x: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::fk(h, q, x_start, x) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_inverse_velocity(
            h: *mut RbssRobot,
            x: *const f64,
            pose_dot: *const f64,
            xdot: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::velocity(h, true, x, pose_dot, xdot) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_forward_velocity(
            h: *mut RbssRobot,
            x: *const f64,
            qdot: *const f64,
            xdot: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::velocity(h, false, x, qdot, xdot) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_inverse_acceleration(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            pose_ddot: *const f64,
            xddot: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::acceleration(h, true, x, xdot, pose_ddot, xddot) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_forward_acceleration(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            qddot: *const f64,
            xddot: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::acceleration(h, false, x, xdot, qddot, xddot) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_constraints(
            h: *mut RbssRobot,
            x: *const f64,
            f: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::constraints(h, x, f) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_jacobian(
            h: *mut RbssRobot,
            x: *const f64,
            g: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::jacobian(h, x, g) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_gamma(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            gamma: *mut f64,
        ) -> c_int {
            unsafe { $crate::kinematics::gamma(h, x, xdot, gamma) }
        }
    };
    (@dynamics) => {
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_inverse_dynamics(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            xddot: *const f64,
            u: *mut f64,
            lambda: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::inverse_dynamics(h, x, xdot, xddot, u, lambda) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_forward_dynamics(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            u: *const f64,
            xddot: *mut f64,
            lambda: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::forward_dynamics(h, x, xdot, u, xddot, lambda) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_forward_dynamics_batch(
            h: *mut RbssRobot,
            count: usize,
            x: *const f64,
            xdot: *const f64,
            u: *const f64,
            xddot: *mut f64,
            lambda: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::forward_dynamics_batch(h, count, x, xdot, u, xddot, lambda) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        #[allow(clippy::too_many_arguments)]
        pub unsafe extern "C" fn rbss_simulate(
            h: *mut RbssRobot,
            x0: *const f64,
            xdot0: *const f64,
            u: *const f64,
            t_end: f64,
            rtol: f64,
            atol: f64,
            x: *mut f64,
            xdot: *mut f64,
        ) -> c_int {
            unsafe {
                $crate::dynamics::simulate(
                    h,
                    $crate::RBSS_METHOD_DOPRI5,
                    x0,
                    xdot0,
                    u,
                    t_end,
                    rtol,
                    atol,
                    x,
                    xdot,
                )
            }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        #[allow(clippy::too_many_arguments)]
        pub unsafe extern "C" fn rbss_simulate_method(
            h: *mut RbssRobot,
            method: c_int,
            x0: *const f64,
            xdot0: *const f64,
            u: *const f64,
            t_end: f64,
            rtol: f64,
            atol: f64,
            x: *mut f64,
            xdot: *mut f64,
        ) -> c_int {
            unsafe {
                $crate::dynamics::simulate(h, method, x0, xdot0, u, t_end, rtol, atol, x, xdot)
            }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_energy(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            out: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::energy(h, x, xdot, out) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_mass_matrix(
            h: *mut RbssRobot,
            x: *const f64,
            mass: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::mass_matrix(h, x, mass) }
        }
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_psi(
            h: *mut RbssRobot,
            x: *const f64,
            xdot: *const f64,
            psi: *mut f64,
        ) -> c_int {
            unsafe { $crate::dynamics::psi(h, x, xdot, psi) }
        }
    };
    (@no_dynamics) => {
        $crate::export!(@no_dynamics_fn rbss_inverse_dynamics(x: *const f64, xdot: *const f64, xddot: *const f64, u: *mut f64, lambda: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_forward_dynamics(x: *const f64, xdot: *const f64, u: *const f64, xddot: *mut f64, lambda: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_forward_dynamics_batch(count: usize, x: *const f64, xdot: *const f64, u: *const f64, xddot: *mut f64, lambda: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_simulate(x0: *const f64, xdot0: *const f64, u: *const f64, t_end: f64, rtol: f64, atol: f64, x: *mut f64, xdot: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_simulate_method(method: c_int, x0: *const f64, xdot0: *const f64, u: *const f64, t_end: f64, rtol: f64, atol: f64, x: *mut f64, xdot: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_energy(x: *const f64, xdot: *const f64, out: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_mass_matrix(x: *const f64, mass: *mut f64));
        $crate::export!(@no_dynamics_fn rbss_psi(x: *const f64, xdot: *const f64, psi: *mut f64));
    };
    (@no_dynamics_fn $name:ident ($($arg:ident : $t:ty),*)) => {
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        #[allow(clippy::too_many_arguments)]
        pub unsafe extern "C" fn $name(h: *mut RbssRobot, $(_: $t),*) -> c_int {
            unsafe { $crate::kinematics::no_dynamics(h) }
        }
    };
}
