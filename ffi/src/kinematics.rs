//! The functions of every robot (kinematics and kernels); [`export!`](crate::export) wraps
//! them in `extern "C"` functions. Each is `unsafe`: the pointers must hold the lengths
//! `rbss.h` gives.

use super::*;

/// `rbss_home(h, x)`.
///
/// # Safety
/// See the module.
pub unsafe fn home<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    x: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe { call(h, |h| write(x, h.model.structure().home, "x")) }
}

/// `rbss_ik(h, pose, x_start, x)`.
///
/// # Safety
/// See the module.
pub unsafe fn ik<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    pose: *const f64,
    x_start: *const f64,
    x: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let pose = read(pose, h.outputs(), "pose")?;
            h.start(x_start)?;
            rbss_runtime::inverse_kinematics(&h.model, &mut h.data, &pose).map_err(solver)?;
            write(x, &h.data.x, "x")
        })
    }
}

/// `rbss_fk(h, q, x_start, x)`.
///
/// # Safety
/// See the module.
pub unsafe fn fk<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    q: *const f64,
    x_start: *const f64,
    x: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let q = read(q, h.actuated(), "q")?;
            h.start(x_start)?;
            rbss_runtime::forward_kinematics(&h.model, &mut h.data, &q).map_err(solver)?;
            write(x, &h.data.x, "x")
        })
    }
}

/// `rbss_inverse_velocity(h, x, pose_dot, xdot)` (`inverse = true`) and
/// `rbss_forward_velocity(h, x, qdot, xdot)`.
///
/// # Safety
/// See the module.
pub unsafe fn velocity<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    inverse: bool,
    x: *const f64,
    rates: *const f64,
    xdot: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            h.data.x = read_n(x, "x")?;
            if inverse {
                let r = read(rates, h.outputs(), "pose_dot")?;
                rbss_runtime::inverse_velocity(&h.model, &mut h.data, &r)
            } else {
                let r = read(rates, h.actuated(), "qdot")?;
                rbss_runtime::forward_velocity(&h.model, &mut h.data, &r)
            }
            .map_err(solver)?;
            write(xdot, &h.data.xdot, "xdot")
        })
    }
}

/// `rbss_inverse_acceleration(h, x, xdot, pose_ddot, xddot)` (`inverse = true`) and
/// `rbss_forward_acceleration(h, x, xdot, qddot, xddot)`.
///
/// # Safety
/// See the module.
pub unsafe fn acceleration<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    inverse: bool,
    x: *const f64,
    xdot: *const f64,
    rates: *const f64,
    xddot: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            h.data.x = read_n(x, "x")?;
            h.data.xdot = read_n(xdot, "xdot")?;
            if inverse {
                let r = read(rates, h.outputs(), "pose_ddot")?;
                rbss_runtime::inverse_acceleration(&h.model, &mut h.data, &r)
            } else {
                let r = read(rates, h.actuated(), "qddot")?;
                rbss_runtime::forward_acceleration(&h.model, &mut h.data, &r)
            }
            .map_err(solver)?;
            write(xddot, &h.data.xddot, "xddot")
        })
    }
}

/// `rbss_constraints(h, x, f)`: the loop closure `f(X)` (m values).
///
/// # Safety
/// See the module.
pub unsafe fn constraints<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    x: *const f64,
    f: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let x = read_n(x, "x")?;
            let mut out = [0.0; M];
            Kernels::constraints(h.model.kernels(), &x, &mut out);
            write_finite(f, &out, "f", &[&x])
        })
    }
}

/// `rbss_jacobian(h, x, g)`: `G = df/dX`, m × n, column-major (column j at `g + j m`).
///
/// # Safety
/// See the module.
pub unsafe fn jacobian<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    x: *const f64,
    g: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let x = read_n(x, "x")?;
            let mut out = [[0.0; M]; N];
            Kernels::jacobian(h.model.kernels(), &x, &mut out);
            write_finite(g, out.as_flattened(), "g", &[&x])
        })
    }
}

/// `rbss_gamma(h, x, xdot, gamma)`: `gamma = -(dG/dt) Xdot` (m values).
///
/// # Safety
/// See the module.
pub unsafe fn gamma<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    x: *const f64,
    xdot: *const f64,
    gamma: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let x = read_n(x, "x")?;
            let xdot = read_n(xdot, "xdot")?;
            let mut out = [0.0; M];
            Kernels::gamma(h.model.kernels(), &x, &xdot, &mut out);
            write_finite(gamma, &out, "gamma", &[&x, &xdot])
        })
    }
}

/// The dynamics functions of a robot generated without dynamics: the error.
///
/// # Safety
/// See the module.
pub unsafe fn no_dynamics<K: Kernels<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            Err((
                RBSS_ERR_NO_DYNAMICS,
                format!(
                    "robot `{}` was generated without dynamics (no masses, or \
                     --kinematics-only)",
                    h.model.structure().name
                ),
            ))
        })
    }
}
