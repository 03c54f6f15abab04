//! rbss-ffi: a generated robot as a loadable library with a C ABI.
//!
//! The ABI (version [`ABI_VERSION`]) is the same for every robot: a handle made by
//! `rbss_new`, sizes and names queried from it, and one function per solver or kernel of the
//! runtime over `double` arrays whose lengths the sizes give. `include/rbss.h` documents it
//! (the C programs' view); this crate holds its one implementation, generic over the robot.
//! A robot's `cdylib` is one line:
//!
//! ```ignore
//! rbss_ffi::export!(stewart_6ups::Stewart6Ups, dynamics);   // or `kinematics` (no dynamics)
//! ```
//!
//! Errors are codes ([`RBSS_OK`] and the `RBSS_ERR_*` constants) plus a message kept in the
//! handle (`rbss_last_error`), valid until the next call on that handle. No function unwinds
//! into C: a panic (a bug) is caught and becomes [`RBSS_ERR_PANIC`].

use std::ffi::{CString, c_char, c_int};
use std::panic::{AssertUnwindSafe, catch_unwind};

use rbss_runtime::tasks::Robot;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, IntegrateOptions, Kernels, Method, Model, Simulator, Stabilization,
};

/// The version of the C ABI: `rbss_abi_version()` returns it; a loader refuses another.
pub const ABI_VERSION: u32 = 1;

/// Success.
pub const RBSS_OK: c_int = 0;
/// A solver failed (singular, no convergence, non-finite values ...); the message says why.
pub const RBSS_ERR_SOLVER: c_int = 1;
/// An argument is invalid: a null pointer, a non-finite number, a bad option.
pub const RBSS_ERR_ARGUMENT: c_int = 2;
/// The robot was generated without dynamics (kinematics only).
pub const RBSS_ERR_NO_DYNAMICS: c_int = 3;
/// A bug: a panic was caught at the boundary.
pub const RBSS_ERR_PANIC: c_int = 4;

/// A robot behind the C ABI: its model, the solvers' data and the last error message.
pub struct Handle<K, const N: usize, const M: usize> {
    model: Model<K, N, M>,
    data: Data<N, M>,
    error: CString,
    names: Names,
}

/// The structure's names as C strings (made once).
struct Names {
    name: CString,
    coordinates: Vec<CString>,
    constraints: Vec<CString>,
}

/// An error: its code and message.
type Failure = (c_int, String);

fn c_string(s: &str) -> CString {
    CString::new(s.replace('\0', " ")).unwrap_or_default()
}

thread_local! {
    /// The message of the last `rbss_new` that failed on this thread.
    static NEW_ERROR: std::cell::RefCell<CString> = std::cell::RefCell::new(CString::default());
}

/// `rbss_new`: a handle at the robot's home, or null (the message in `rbss_last_error(NULL)`).
pub fn new<K: Robot<N, M>, const N: usize, const M: usize>(kernels: K) -> *mut Handle<K, N, M> {
    let made = catch_unwind(AssertUnwindSafe(|| {
        Model::try_new(kernels).map(|model| {
            let data = Data::new(&model);
            let s = model.structure();
            let names = Names {
                name: c_string(s.name),
                coordinates: s.coordinates.iter().map(|c| c_string(c)).collect(),
                constraints: s.constraints.iter().map(|c| c_string(c)).collect(),
            };
            Box::new(Handle {
                model,
                data,
                error: CString::default(),
                names,
            })
        })
    }));
    let message = match made {
        Ok(Ok(h)) => return Box::into_raw(h),
        Ok(Err(e)) => e.to_string(),
        Err(_) => "rbss_new: a panic (a bug in rbss)".to_string(),
    };
    NEW_ERROR.with(|m| *m.borrow_mut() = c_string(&message));
    std::ptr::null_mut()
}

/// `rbss_free`.
///
/// # Safety
/// `h` is null or a handle from `rbss_new` of this library, not freed before.
pub unsafe fn free<K, const N: usize, const M: usize>(h: *mut Handle<K, N, M>) {
    if !h.is_null() {
        // SAFETY: the caller's contract.
        drop(unsafe { Box::from_raw(h) });
    }
}

/// `rbss_last_error`: the message of the last failed call on `h` ("" after a success), or of
/// the last failed `rbss_new` on this thread when `h` is null.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn last_error<K, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
) -> *const c_char {
    // SAFETY: the caller's contract.
    match unsafe { h.as_ref() } {
        Some(h) => h.error.as_ptr(),
        None => NEW_ERROR.with(|m| m.borrow().as_ptr()),
    }
}

/// The sizes `rbss_size` reports.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// Coordinates `n`.
    Coordinates = 0,
    /// Loop-closure equations `m`.
    Constraints = 1,
    /// Actuated coordinates.
    Actuated = 2,
    /// Output coordinates.
    Outputs = 3,
    /// 1 when the robot has dynamics, else 0.
    Dynamics = 4,
}

/// `rbss_size(h, what)`: a size of the robot (`what` as [`Size`]), or `usize::MAX` for a null
/// handle or an unknown `what`.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn size<K: Robot<N, M>, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    what: c_int,
    dynamics: bool,
) -> usize {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return usize::MAX;
    };
    let s = h.model.structure();
    match what {
        0 => N,
        1 => M,
        2 => s.actuated.len(),
        3 => s.outputs.len(),
        4 => usize::from(dynamics),
        _ => usize::MAX,
    }
}

/// `rbss_name(h)`: the robot's name (null for a null handle).
///
/// # Safety
/// `h` is null or a live handle; the string lives as long as the handle.
pub unsafe fn name<K, const N: usize, const M: usize>(h: *const Handle<K, N, M>) -> *const c_char {
    // SAFETY: the caller's contract.
    unsafe { h.as_ref() }.map_or(std::ptr::null(), |h| h.names.name.as_ptr())
}

/// `rbss_coordinate(h, i)` / `rbss_constraint(h, i)`: the name of coordinate (constraint) `i`,
/// null out of range.
///
/// # Safety
/// `h` is null or a live handle; the string lives as long as the handle.
pub unsafe fn label<K, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    constraint: bool,
    i: usize,
) -> *const c_char {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return std::ptr::null();
    };
    let list = if constraint {
        &h.names.constraints
    } else {
        &h.names.coordinates
    };
    list.get(i).map_or(std::ptr::null(), |c| c.as_ptr())
}

/// `rbss_actuated(h, i)` / `rbss_output(h, i)`: the coordinate index of actuated (output)
/// coordinate `i`, or `usize::MAX` out of range.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn index<K: Robot<N, M>, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    output: bool,
    i: usize,
) -> usize {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return usize::MAX;
    };
    let s = h.model.structure();
    let list = if output { s.outputs } else { s.actuated };
    list.get(i).copied().unwrap_or(usize::MAX)
}

/// Reads `len` doubles at `p` (null: `None`), every one finite.
///
/// # Safety
/// `p` is null or points to `len` doubles.
unsafe fn read(p: *const f64, len: usize, what: &str) -> Result<Vec<f64>, Failure> {
    if p.is_null() {
        return Err((RBSS_ERR_ARGUMENT, format!("`{what}` is a null pointer")));
    }
    // SAFETY: the caller's contract.
    let v = unsafe { std::slice::from_raw_parts(p, len) }.to_vec();
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err((
            RBSS_ERR_ARGUMENT,
            format!("`{what}`[{i}] is not finite ({})", v[i]),
        ));
    }
    Ok(v)
}

/// `N` finite doubles at `p`.
///
/// # Safety
/// `p` is null or points to `N` doubles.
unsafe fn read_n<const L: usize>(p: *const f64, what: &str) -> Result<[f64; L], Failure> {
    // SAFETY: the caller's contract.
    let v = unsafe { read(p, L, what) }?;
    let mut out = [0.0; L];
    out.copy_from_slice(&v);
    Ok(out)
}

/// `p + offset`, or null for a null `p` (then refused by [`read`]).
fn ptr(p: *const f64, offset: usize) -> *const f64 {
    if p.is_null() {
        p
    } else {
        p.wrapping_add(offset)
    }
}

/// `p + offset`, or null for a null `p` (then refused by [`write`]).
fn ptr_mut(p: *mut f64, offset: usize) -> *mut f64 {
    if p.is_null() {
        p
    } else {
        p.wrapping_add(offset)
    }
}

/// Writes `v` to `p`.
///
/// # Safety
/// `p` is null or points to `v.len()` writable doubles.
unsafe fn write(p: *mut f64, v: &[f64], what: &str) -> Result<(), Failure> {
    if p.is_null() {
        return Err((RBSS_ERR_ARGUMENT, format!("`{what}` is a null pointer")));
    }
    // SAFETY: the caller's contract.
    unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), p, v.len()) };
    Ok(())
}

fn solver(e: impl std::fmt::Display) -> Failure {
    (RBSS_ERR_SOLVER, e.to_string())
}

/// Runs `f` on the handle: the code, the message stored (cleared on success), panics caught.
///
/// # Safety
/// `h` is null or a live handle not used by another thread during the call.
pub unsafe fn call<K, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    f: impl FnOnce(&mut Handle<K, N, M>) -> Result<(), Failure>,
) -> c_int {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_mut() }) else {
        return RBSS_ERR_ARGUMENT;
    };
    let (code, message) = match catch_unwind(AssertUnwindSafe(|| f(&mut *h))) {
        Ok(Ok(())) => (RBSS_OK, String::new()),
        Ok(Err((code, message))) => (code, message),
        Err(_) => (RBSS_ERR_PANIC, "a panic (a bug in rbss)".to_string()),
    };
    h.error = c_string(&message);
    code
}

impl<K: Robot<N, M>, const N: usize, const M: usize> Handle<K, N, M> {
    /// Sets `data.x` to the start `x0` (null: the home).
    ///
    /// # Safety
    /// `x0` is null or points to `N` doubles.
    unsafe fn start(&mut self, x0: *const f64) -> Result<(), Failure> {
        self.data.x = if x0.is_null() {
            let mut x = [0.0; N];
            x.copy_from_slice(self.model.structure().home);
            x
        } else {
            // SAFETY: the caller's contract.
            unsafe { read_n(x0, "x_start") }?
        };
        Ok(())
    }

    fn actuated(&self) -> usize {
        self.model.structure().actuated.len()
    }

    fn outputs(&self) -> usize {
        self.model.structure().outputs.len()
    }
}

/// The functions of every robot (kinematics and kernels); [`export!`] wraps them in
/// `extern "C"` functions. Each is `unsafe`: the pointers must hold the lengths `rbss.h` gives.
pub mod kinematics {
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
                write(f, &out, "f")
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
                write(g, out.as_flattened(), "g")
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
                write(gamma, &out, "gamma")
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
}

/// The functions of a robot with dynamics.
pub mod dynamics {
    use super::*;

    /// `rbss_inverse_dynamics(h, x, xdot, xddot, u, lambda)`: the actuated forces `u` and the
    /// multipliers `lambda` of `M Xddot = psi + S U - G^T lambda`.
    ///
    /// # Safety
    /// See [`kinematics`].
    pub unsafe fn inverse_dynamics<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x: *const f64,
        xdot: *const f64,
        xddot: *const f64,
        u: *mut f64,
        lambda: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                h.data.x = read_n(x, "x")?;
                h.data.xdot = read_n(xdot, "xdot")?;
                h.data.xddot = read_n(xddot, "xddot")?;
                rbss_runtime::inverse_dynamics(&h.model, &mut h.data, None).map_err(solver)?;
                let k = h.actuated();
                write(u, &h.data.u[..k], "u")?;
                write(lambda, &h.data.lambda, "lambda")
            })
        }
    }

    /// `rbss_forward_dynamics(h, x, xdot, u, xddot, lambda)`.
    ///
    /// # Safety
    /// See [`kinematics`].
    pub unsafe fn forward_dynamics<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x: *const f64,
        xdot: *const f64,
        u: *const f64,
        xddot: *mut f64,
        lambda: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                h.data.x = read_n(x, "x")?;
                h.data.xdot = read_n(xdot, "xdot")?;
                let u = read(u, h.actuated(), "u")?;
                rbss_runtime::forward_dynamics(&h.model, &mut h.data, &u, None, Baumgarte::NONE)
                    .map_err(solver)?;
                write(xddot, &h.data.xddot, "xddot")?;
                write(lambda, &h.data.lambda, "lambda")
            })
        }
    }

    /// `rbss_forward_dynamics_batch(h, count, x, xdot, u, xddot, lambda)`: `count` states
    /// back to back (state `i` at `x + i n`, `u + i actuated`, `lambda + i m`), looped here.
    /// On a failure, the code of the first failed state and its message prefixed with
    /// `state i: `; the states before it are written.
    ///
    /// # Safety
    /// See [`kinematics`]; every array holds `count` times its length.
    pub unsafe fn forward_dynamics_batch<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        count: usize,
        x: *const f64,
        xdot: *const f64,
        u: *const f64,
        xddot: *mut f64,
        lambda: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                let k = h.actuated();
                for i in 0..count {
                    let at = |e: Failure| (e.0, format!("state {i}: {}", e.1));
                    let xi = read_n(ptr(x, i * N), "x").map_err(at)?;
                    let vi = read_n(ptr(xdot, i * N), "xdot").map_err(at)?;
                    let ui = read(ptr(u, i * k), k, "u").map_err(at)?;
                    h.data.x = xi;
                    h.data.xdot = vi;
                    rbss_runtime::forward_dynamics(
                        &h.model,
                        &mut h.data,
                        &ui,
                        None,
                        Baumgarte::NONE,
                    )
                    .map_err(solver)
                    .map_err(at)?;
                    write(ptr_mut(xddot, i * N), &h.data.xddot, "xddot").map_err(at)?;
                    write(ptr_mut(lambda, i * M), &h.data.lambda, "lambda").map_err(at)?;
                }
                Ok(())
            })
        }
    }

    /// `rbss_simulate(h, x0, xdot0, u, t_end, rtol, atol, x, xdot)`: DOPRI5 with projection
    /// onto the constraints from `t = 0` to `t_end` under the constant forces `u` (null: zero).
    ///
    /// # Safety
    /// See [`kinematics`].
    #[allow(clippy::too_many_arguments)]
    pub unsafe fn simulate<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x0: *const f64,
        xdot0: *const f64,
        u: *const f64,
        t_end: f64,
        rtol: f64,
        atol: f64,
        x: *mut f64,
        xdot: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                let x0 = read_n(x0, "x0")?;
                let xdot0 = read_n(xdot0, "xdot0")?;
                let k = h.actuated();
                let u = if u.is_null() {
                    vec![0.0; k]
                } else {
                    read(u, k, "u")?
                };
                for (v, what) in [(t_end, "t_end"), (rtol, "rtol"), (atol, "atol")] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err((
                            RBSS_ERR_ARGUMENT,
                            format!("`{what}` = {v}: a finite number >= 0"),
                        ));
                    }
                }
                let options =
                    IntegrateOptions::new(Method::dopri5(rtol, atol), Stabilization::Projection);
                let mut sim = Simulator::new(&h.model, &mut h.data, 0.0, &x0, &xdot0, options)
                    .map_err(solver)?;
                let mut control = |_t: f64, _x: &[f64; N], _v: &[f64; N], out: &mut [f64]| {
                    out.copy_from_slice(&u);
                    Ok(())
                };
                sim.run(&h.model, &mut h.data, t_end, &mut control, |_| {})
                    .map_err(solver)?;
                write(x, sim.x(), "x")?;
                write(xdot, sim.xdot(), "xdot")
            })
        }
    }

    /// `rbss_energy(h, x, xdot, out)`: `[T, Pi]`.
    ///
    /// # Safety
    /// See [`kinematics`].
    pub unsafe fn energy<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x: *const f64,
        xdot: *const f64,
        out: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                let x = read_n(x, "x")?;
                let xdot = read_n(xdot, "xdot")?;
                let mut e = [0.0; 2];
                Dynamics::energy(h.model.kernels(), &x, &xdot, &mut e);
                write(out, &e, "energy")
            })
        }
    }

    /// `rbss_mass_matrix(h, x, mass)`: `M(X)`, n × n (symmetric).
    ///
    /// # Safety
    /// See [`kinematics`].
    pub unsafe fn mass_matrix<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x: *const f64,
        mass: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                let x = read_n(x, "x")?;
                let mut out = [[0.0; N]; N];
                Dynamics::mass_matrix(h.model.kernels(), &x, &mut out);
                write(mass, out.as_flattened(), "mass")
            })
        }
    }

    /// `rbss_psi(h, x, xdot, psi)`: the generalised forces `psi(X, Xdot)` (n values).
    ///
    /// # Safety
    /// See [`kinematics`].
    pub unsafe fn psi<K: Dynamics<N, M>, const N: usize, const M: usize>(
        h: *mut Handle<K, N, M>,
        x: *const f64,
        xdot: *const f64,
        psi: *mut f64,
    ) -> c_int {
        // SAFETY: the caller's contract.
        unsafe {
            call(h, |h| {
                let x = read_n(x, "x")?;
                let xdot = read_n(xdot, "xdot")?;
                let mut out = [0.0; N];
                Dynamics::psi(h.model.kernels(), &x, &xdot, &mut out);
                write(psi, &out, "psi")
            })
        }
    }
}

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
            unsafe { $crate::dynamics::simulate(h, x0, xdot0, u, t_end, rtol, atol, x, xdot) }
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
