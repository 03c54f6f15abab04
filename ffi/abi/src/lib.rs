//! rbss-abi: the C ABI's one table (`ffi/include/rbss.h`, version [`ABI_VERSION`]).
//!
//! [`functions!`] lists every `rbss_*` function once: its group, its arguments with their kinds
//! and lengths, its return kind, and the function of rbss-ffi that implements it. The other
//! places that spell the ABI are made from it or checked against it:
//!
//! | place | how |
//! |---|---|
//! | `rbss_ffi::export!` (the `extern "C"` functions of a robot's library) | made from it |
//! | the PyO3 core's function pointers (`python/native`, `rbss._native`) | made from it |
//! | the ctypes layer's signatures (`python/rbss/_abi.py`) | written from [`FUNCTIONS`]; `ffi/tests/abi.rs` fails when stale (`RBSS_BLESS=1` rewrites) |
//! | `ffi/include/rbss.h` (prototypes, `#define`s) | checked by `ffi/tests/abi.rs` |
//! | rbss-ffi's implementations (`kinematics.rs`, `dynamics.rs`, `derivatives.rs`) | named by the table: the compiler checks the calls |
//!
//! Adding a function: one line here, its implementation in rbss-ffi, its prototype and comment
//! in `rbss.h`, its method in the Python layers; the tests name what is missing.
//!
//! The entry grammar, for the macros that read the table:
//!
//! ```text
//! GROUP fn NAME ( ARG: KIND [LENGTH]?, ... ) -> RETURN = PATH ( IMPLEMENTATION ARGUMENTS );
//! ```
//!
//! - GROUP: `abi` (no handle), `common` (every robot), `dynamics` (`RBSS_ERR_NO_DYNAMICS` for a
//!   robot generated without dynamics);
//! - KIND: `handle` (`rbss_robot *`), `handle_const` (`const rbss_robot *`), `input`
//!   (`const double *`), `input_or_null` (`const double *`, NULL allowed), `output`
//!   (`double *`), `int`, `size` (`size_t`), `double`;
//! - LENGTH (arrays): in doubles, from the sizes `n`, `m`, `actuated`, `outputs`, the argument
//!   `count`, numbers, `x` for a product (`m x n`, column-major), parenthesised arithmetic of
//!   them (`(2 * n) x actuated`);
//! - RETURN: `int` (an `RBSS_*` code), `size`, `u32`, `string` (`const char *`), `handle`,
//!   `void`;
//! - PATH (ARGUMENTS): the function of rbss-ffi called with the arguments (the items
//!   `RbssKernels` and `RBSS_HAS_DYNAMICS` are defined by `export!`).

use std::ffi::c_int;

/// The version of the C ABI: `rbss_abi_version()` returns it; a loader refuses another.
pub const ABI_VERSION: u32 = 4;

/// Calls `callback!` with the table: `functions!([path::to::callback] tokens...)` expands to
/// `path::to::callback! { tokens... GROUP fn NAME(...) -> RETURN = PATH(...); ... }`, in the
/// order of `rbss.h`.
#[macro_export]
macro_rules! functions {
    ([$($callback:tt)*] $($extra:tt)*) => {
        $($callback)*! { $($extra)*
            abi fn rbss_abi_version() -> u32 = abi_version();
            abi fn rbss_new() -> handle = new(RbssKernels::default());
            common fn rbss_free(h: handle) -> void = free(h);
            common fn rbss_last_error(h: handle_const) -> string = last_error(h);
            common fn rbss_size(h: handle_const, what: int) -> size = size(h, what, RBSS_HAS_DYNAMICS);
            common fn rbss_name(h: handle_const) -> string = name(h);
            common fn rbss_coordinate(h: handle_const, i: size) -> string = label(h, false, i);
            common fn rbss_constraint(h: handle_const, i: size) -> string = label(h, true, i);
            common fn rbss_actuated(h: handle_const, i: size) -> size = index(h, false, i);
            common fn rbss_output(h: handle_const, i: size) -> size = index(h, true, i);
            common fn rbss_home(h: handle, x: output[n]) -> int = kinematics::home(h, x);
            common fn rbss_ik(h: handle, pose: input[outputs], x_start: input_or_null[n], x: output[n]) -> int
                = kinematics::ik(h, pose, x_start, x);
            common fn rbss_fk(h: handle, q: input[actuated], x_start: input_or_null[n], x: output[n]) -> int
                = kinematics::fk(h, q, x_start, x);
            common fn rbss_inverse_velocity(h: handle, x: input[n], pose_dot: input[outputs], xdot: output[n]) -> int
                = kinematics::velocity(h, true, x, pose_dot, xdot);
            common fn rbss_forward_velocity(h: handle, x: input[n], qdot: input[actuated], xdot: output[n]) -> int
                = kinematics::velocity(h, false, x, qdot, xdot);
            common fn rbss_inverse_acceleration(h: handle, x: input[n], xdot: input[n], pose_ddot: input[outputs], xddot: output[n]) -> int
                = kinematics::acceleration(h, true, x, xdot, pose_ddot, xddot);
            common fn rbss_forward_acceleration(h: handle, x: input[n], xdot: input[n], qddot: input[actuated], xddot: output[n]) -> int
                = kinematics::acceleration(h, false, x, xdot, qddot, xddot);
            dynamics fn rbss_inverse_dynamics(h: handle, x: input[n], xdot: input[n], xddot: input[n], u: output[actuated], lambda: output[m]) -> int
                = dynamics::inverse_dynamics(h, x, xdot, xddot, u, lambda);
            dynamics fn rbss_forward_dynamics(h: handle, x: input[n], xdot: input[n], u: input[actuated], xddot: output[n], lambda: output[m]) -> int
                = dynamics::forward_dynamics(h, x, xdot, u, xddot, lambda);
            dynamics fn rbss_forward_dynamics_batch(h: handle, count: size, x: input[count x n], xdot: input[count x n], u: input[count x actuated], xddot: output[count x n], lambda: output[count x m]) -> int
                = dynamics::forward_dynamics_batch(h, count, x, xdot, u, xddot, lambda);
            dynamics fn rbss_simulate(h: handle, x0: input[n], xdot0: input[n], u: input_or_null[actuated], t_end: double, rtol: double, atol: double, x: output[n], xdot: output[n]) -> int
                = dynamics::simulate_dopri5(h, x0, xdot0, u, t_end, rtol, atol, x, xdot);
            dynamics fn rbss_simulate_method(h: handle, method: int, x0: input[n], xdot0: input[n], u: input_or_null[actuated], t_end: double, rtol: double, atol: double, x: output[n], xdot: output[n]) -> int
                = dynamics::simulate(h, method, x0, xdot0, u, t_end, rtol, atol, x, xdot);
            dynamics fn rbss_simulate_checked(h: handle, method: int, x0: input[n], xdot0: input[n], u: input_or_null[actuated], t_end: double, rtol: double, atol: double, state_tol: double, project: int, x: output[n], xdot: output[n], state: output[4]) -> int
                = dynamics::simulate_checked(h, method, x0, xdot0, u, t_end, rtol, atol, state_tol, project, x, xdot, state);
            dynamics fn rbss_energy(h: handle, x: input[n], xdot: input[n], out: output[2]) -> int
                = dynamics::energy(h, x, xdot, out);
            common fn rbss_constraints(h: handle, x: input[n], f: output[m]) -> int
                = kinematics::constraints(h, x, f);
            common fn rbss_jacobian(h: handle, x: input[n], g: output[m x n]) -> int
                = kinematics::jacobian(h, x, g);
            common fn rbss_gamma(h: handle, x: input[n], xdot: input[n], gamma: output[m]) -> int
                = kinematics::gamma(h, x, xdot, gamma);
            dynamics fn rbss_mass_matrix(h: handle, x: input[n], mass: output[n x n]) -> int
                = dynamics::mass_matrix(h, x, mass);
            dynamics fn rbss_psi(h: handle, x: input[n], xdot: input[n], psi: output[n]) -> int
                = dynamics::psi(h, x, xdot, psi);
            dynamics fn rbss_forward_dynamics_derivatives(h: handle, x: input[n], xdot: input[n], u: input[actuated], xddot: output[n], lambda: output[m], dxddot_dx: output[n x n], dxddot_dxdot: output[n x n], dxddot_du: output[n x actuated], dlambda_dx: output[m x n], dlambda_dxdot: output[m x n], dlambda_du: output[m x actuated]) -> int
                = derivatives::forward_dynamics_derivatives(h, x, xdot, u, xddot, lambda, dxddot_dx, dxddot_dxdot, dxddot_du, dlambda_dx, dlambda_dxdot, dlambda_du);
            dynamics fn rbss_inverse_dynamics_derivatives(h: handle, x: input[n], xdot: input[n], xddot: input[n], u: output[actuated], lambda: output[m], du_dx: output[actuated x n], du_dxdot: output[actuated x n], du_dxddot: output[actuated x n], dlambda_dx: output[m x n], dlambda_dxdot: output[m x n], dlambda_dxddot: output[m x n]) -> int
                = derivatives::inverse_dynamics_derivatives(h, x, xdot, xddot, u, lambda, du_dx, du_dxdot, du_dxddot, dlambda_dx, dlambda_dxdot, dlambda_dxddot);
            dynamics fn rbss_linearize(h: handle, coordinates: int, x: input[n], xdot: input[n], u: input[actuated], a: output[(2 * (n - m)) x (2 * (n - m))], b: output[(2 * (n - m)) x actuated]) -> int
                = derivatives::linearize(h, coordinates, x, xdot, u, a, b);
            dynamics fn rbss_step_derivatives(h: handle, method: int, x: input[n], xdot: input[n], u: input[actuated], dt: double, baumgarte: input_or_null[2], x_next: output[n], xdot_next: output[n], fx: output[(2 * n) x (2 * n)], fu: output[(2 * n) x actuated]) -> int
                = derivatives::step_derivatives(h, method, x, xdot, u, dt, baumgarte, x_next, xdot_next, fx, fu);
        }
    };
}

/// A function of the table, as data (for the checks of `rbss.h` and the Python layers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Function {
    pub name: &'static str,
    /// `abi`, `common` or `dynamics`.
    pub group: &'static str,
    pub args: &'static [Arg],
    /// The return kind.
    pub ret: &'static str,
}

/// An argument of a [`Function`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Arg {
    pub name: &'static str,
    pub kind: &'static str,
    /// The length of an array in doubles (`"n"`, `"m x n"`, `"count x n"`, `"2"`).
    pub len: Option<&'static str>,
}

#[doc(hidden)]
#[macro_export]
macro_rules! __data {
    ($(
        $group:ident fn $name:ident ( $($arg:ident : $kind:ident $([$($len:tt)*])?),* ) -> $ret:ident
            = $($path:ident)::+ ( $($call:tt)* );
    )*) => {
        &[$($crate::Function {
            name: stringify!($name),
            group: stringify!($group),
            args: &[$($crate::Arg {
                name: stringify!($arg),
                kind: stringify!($kind),
                len: $crate::__len!($($($len)*)?),
            }),*],
            ret: stringify!($ret),
        }),*]
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __len {
    () => {
        None
    };
    ($($len:tt)+) => {
        Some(stringify!($($len)+))
    };
}

/// The table as data, in the order of `rbss.h`.
pub const FUNCTIONS: &[Function] = functions!([crate::__data]);

/// The C type of an argument kind, as `rbss.h` writes it (`None`: not a kind).
pub fn c_type(kind: &str) -> Option<&'static str> {
    Some(match kind {
        "handle" => "rbss_robot *",
        "handle_const" => "const rbss_robot *",
        "input" | "input_or_null" => "const double *",
        "output" => "double *",
        "int" => "int",
        "size" => "size_t",
        "double" => "double",
        _ => return None,
    })
}

/// The C type of a return kind, as `rbss.h` writes it.
pub fn c_return_type(ret: &str) -> Option<&'static str> {
    Some(match ret {
        "int" => "int",
        "size" => "size_t",
        "u32" => "uint32_t",
        "string" => "const char *",
        "handle" => "rbss_robot *",
        "void" => "void",
        _ => return None,
    })
}

macro_rules! constants {
    ($($(#[$doc:meta])* $name:ident = $value:literal;)*) => {
        $($(#[$doc])* pub const $name: c_int = $value;)*
        /// Every `#define` of `rbss.h` but `RBSS_ABI_VERSION` ([`ABI_VERSION`]): name and value.
        pub const CONSTANTS: &[(&str, c_int)] = &[$((stringify!($name), $value)),*];
    };
}

constants! {
    /// Success.
    RBSS_OK = 0;
    /// A solver failed (singular, no convergence, non-finite values ...); the message says why.
    RBSS_ERR_SOLVER = 1;
    /// An argument is invalid: a null pointer, a non-finite number, a bad option.
    RBSS_ERR_ARGUMENT = 2;
    /// The robot was generated without dynamics (kinematics only).
    RBSS_ERR_NO_DYNAMICS = 3;
    /// A bug: a panic was caught at the boundary.
    RBSS_ERR_PANIC = 4;
    /// `rbss_simulate*`, `rbss_linearize`: the (initial) state is not consistent with the
    /// constraints (`max |f(X)|` or `max |G Ẋ|` beyond the tolerance); the message gives the
    /// residual. Project it explicitly with `rbss_simulate_checked`'s `project`.
    RBSS_ERR_STATE = 5;
    /// A raw kernel's output is not finite (inf or NaN, e.g. at `x = 1e300`): the input is
    /// outside the range the model's formulas hold in; the outputs are not written. The
    /// derivative functions (`rbss_forward_dynamics_derivatives`,
    /// `rbss_inverse_dynamics_derivatives`, `rbss_linearize`, `rbss_step_derivatives`) report a
    /// non-finite value met on the way so too.
    RBSS_ERR_NONFINITE = 6;
    /// `rbss_simulate_method`'s integrator: Dormand–Prince 5(4) (`rbss_simulate`'s).
    RBSS_METHOD_DOPRI5 = 0;
    /// `rbss_simulate_method`'s integrator: Dormand–Prince 8(5,3), fewer steps at tight
    /// tolerances.
    RBSS_METHOD_DOP853 = 1;
    /// `rbss_linearize`'s independent coordinates: the outputs (`rbss_output`'s order).
    RBSS_LINEARIZE_OUTPUTS = 0;
    /// `rbss_linearize`'s independent coordinates: the actuated ones (fully actuated robots).
    RBSS_LINEARIZE_ACTUATED = 1;
    /// `rbss_step_derivatives`'s step: classic Runge–Kutta 4.
    RBSS_STEP_RK4 = 0;
    /// `rbss_step_derivatives`'s step: semi-implicit (symplectic) Euler,
    /// `Xdot' = Xdot + dt Xddot`, `X' = X + dt Xdot'`.
    RBSS_STEP_SEMI_IMPLICIT_EULER = 1;
    /// `rbss_size`: the coordinates `n`.
    RBSS_COORDINATES = 0;
    /// `rbss_size`: the loop-closure equations `m`.
    RBSS_CONSTRAINTS = 1;
    /// `rbss_size`: the actuated coordinates.
    RBSS_ACTUATED = 2;
    /// `rbss_size`: the output (task) coordinates.
    RBSS_OUTPUTS = 3;
    /// `rbss_size`: 1 when the dynamics functions work, else 0.
    RBSS_DYNAMICS = 4;
}

/// `python/rbss/_abi.py`: the table for the ctypes layer (checked fresh by `ffi/tests/abi.rs`).
pub fn python_module() -> String {
    let mut s = String::from(
        "# The C ABI's table for the ctypes layer (python/rbss/__init__.py), written from\n\
         # ffi/abi/src/lib.rs (rbss-abi): do not edit. `RBSS_BLESS=1 cargo test --release -p\n\
         # rbss-ffi --test abi` rewrites it; that test fails when it is stale.\n\n",
    );
    s += &format!("ABI_VERSION = {ABI_VERSION}\n\n");
    for (name, value) in CONSTANTS {
        s += &format!("{name} = {value}\n");
    }
    s += "\n# name: (return kind, ((argument, kind, length or None), ...)); the kinds as in rbss-abi.\n";
    s += "FUNCTIONS = {\n";
    for f in FUNCTIONS {
        let args: Vec<String> = f
            .args
            .iter()
            .map(|a| {
                let len = a.len.map_or("None".to_string(), |l| format!("\"{l}\""));
                format!("(\"{}\", \"{}\", {len})", a.name, a.kind)
            })
            .collect();
        // A tuple of one needs its comma.
        let comma = if args.len() == 1 { "," } else { "" };
        s += &format!("    \"{}\": (\"{}\", (", f.name, f.ret);
        s += &format!("{}{comma})),\n", args.join(", "));
    }
    s += "}\n";
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_has_a_c_type_and_arrays_have_lengths() {
        let mut names: Vec<_> = FUNCTIONS.iter().map(|f| f.name).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), FUNCTIONS.len(), "a function twice");
        for f in FUNCTIONS {
            assert!(f.name.starts_with("rbss_"), "{}", f.name);
            assert!(
                c_return_type(f.ret).is_some(),
                "{}: return {}",
                f.name,
                f.ret
            );
            assert_eq!(f.group == "abi", f.args.is_empty(), "{}", f.name);
            for a in f.args {
                assert!(
                    c_type(a.kind).is_some(),
                    "{}: {}: {}",
                    f.name,
                    a.name,
                    a.kind
                );
                let array = c_type(a.kind).unwrap().contains("double *");
                assert_eq!(array, a.len.is_some(), "{}: {}", f.name, a.name);
            }
        }
        assert_eq!(FUNCTIONS.len(), 33);
    }
}
