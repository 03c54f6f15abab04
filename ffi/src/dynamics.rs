//! The functions of a robot with dynamics; see [`crate::kinematics`].

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
            outputs_given(&[(u, "u"), (lambda, "lambda")])?;
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
            outputs_given(&[(xddot, "xddot"), (lambda, "lambda")])?;
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
            // A null output fails before any state is written (a failed state still leaves
            // the states before it written, as documented).
            if count > 0 {
                outputs_given(&[(xddot, "xddot"), (lambda, "lambda")])?;
            }
            let k = h.actuated();
            for i in 0..count {
                let at = |e: Failure| (e.0, format!("state {i}: {}", e.1));
                let xi = read_n(ptr(x, i * N), "x").map_err(at)?;
                let vi = read_n(ptr(xdot, i * N), "xdot").map_err(at)?;
                let ui = read(ptr(u, i * k), k, "u").map_err(at)?;
                h.data.x = xi;
                h.data.xdot = vi;
                rbss_runtime::forward_dynamics(&h.model, &mut h.data, &ui, None, Baumgarte::NONE)
                    .map_err(solver)
                    .map_err(at)?;
                write(ptr_mut(xddot, i * N), &h.data.xddot, "xddot").map_err(at)?;
                write(ptr_mut(lambda, i * M), &h.data.lambda, "lambda").map_err(at)?;
            }
            Ok(())
        })
    }
}

/// The initial state's tolerance of `rbss_simulate` and `rbss_simulate_method`: the command's
/// default `--state-tol`.
pub const STATE_TOL: f64 = 1e-6;

/// `rbss_simulate_method(h, method, x0, xdot0, u, t_end, rtol, atol, x, xdot)`:
/// [`simulate_checked`] with the tolerance [`STATE_TOL`], without projecting an inconsistent
/// state; `rbss_simulate` is this with DOPRI5.
///
/// # Safety
/// See [`kinematics`].
#[allow(clippy::too_many_arguments)]
pub unsafe fn simulate<K: Dynamics<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
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
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            run_simulation(
                h, method, x0, xdot0, u, t_end, rtol, atol, STATE_TOL, false, x, xdot, None,
            )
        })
    }
}

/// `rbss_simulate_checked(h, method, x0, xdot0, u, t_end, rtol, atol, state_tol, project, x,
/// xdot, state)`: the adaptive integrator `method` ([`RBSS_METHOD_DOPRI5`] or
/// [`RBSS_METHOD_DOP853`]) with projection onto the constraints from `t = 0` to `t_end` under
/// the constant forces `u` (null: zero). The initial state's residuals `[max |f(x0)|,
/// max |G xdot0|]` ([`rbss_runtime::state_residual`]) above `state_tol` are
/// [`RBSS_ERR_STATE`] unless `project` is nonzero; `state` receives the residuals and the
/// projection's moves `[max |dX|, max |dXdot|]`, also with `RBSS_ERR_STATE` (moves 0).
///
/// # Safety
/// See [`kinematics`]; `state` points to 4 writable doubles.
#[allow(clippy::too_many_arguments)]
pub unsafe fn simulate_checked<K: Dynamics<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    method: c_int,
    x0: *const f64,
    xdot0: *const f64,
    u: *const f64,
    t_end: f64,
    rtol: f64,
    atol: f64,
    state_tol: f64,
    project: c_int,
    x: *mut f64,
    xdot: *mut f64,
    state: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            run_simulation(
                h,
                method,
                x0,
                xdot0,
                u,
                t_end,
                rtol,
                atol,
                state_tol,
                project != 0,
                x,
                xdot,
                Some(state),
            )
        })
    }
}

/// The simulation of [`simulate`] and [`simulate_checked`] (`state`: where the check's
/// numbers go, if anywhere).
///
/// # Safety
/// See [`kinematics`]; `state` is `None` or points to 4 writable doubles.
#[allow(clippy::too_many_arguments)]
unsafe fn run_simulation<K: Dynamics<N, M>, const N: usize, const M: usize>(
    h: &mut Handle<K, N, M>,
    method: c_int,
    x0: *const f64,
    xdot0: *const f64,
    u: *const f64,
    t_end: f64,
    rtol: f64,
    atol: f64,
    state_tol: f64,
    project: bool,
    x: *mut f64,
    xdot: *mut f64,
    state: Option<*mut f64>,
) -> Result<(), Failure> {
    // SAFETY: the caller's contract.
    unsafe {
        // Every output checked before anything is written (`state` too, also written with
        // `RBSS_ERR_STATE`).
        let mut outs = vec![(x, "x"), (xdot, "xdot")];
        if let Some(p) = state {
            outs.push((p, "state"));
        }
        outputs_given(&outs)?;
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
        if !(state_tol.is_finite() && state_tol > 0.0) {
            return Err((
                RBSS_ERR_ARGUMENT,
                format!("`state_tol` = {state_tol}: a finite number > 0"),
            ));
        }
        let method = match method {
            RBSS_METHOD_DOPRI5 => Method::dopri5(rtol, atol),
            RBSS_METHOD_DOP853 => Method::dop853(rtol, atol),
            other => {
                return Err((
                    RBSS_ERR_ARGUMENT,
                    format!(
                        "`method` = {other}: RBSS_METHOD_DOPRI5 ({RBSS_METHOD_DOPRI5}) or \
                         RBSS_METHOD_DOP853 ({RBSS_METHOD_DOP853})"
                    ),
                ));
            }
        };
        // The given state's consistency, before anything moves it (issue 37: an inconsistent
        // state is refused, or projected on request with the move reported, never silently).
        let residual = rbss_runtime::state_residual(&h.model, &x0, &xdot0);
        let consistent = residual[0] <= state_tol && residual[1] <= state_tol;
        if !(project || consistent) {
            if let Some(p) = state {
                write(p, &[residual[0], residual[1], 0.0, 0.0], "state")?;
            }
            return Err((
                RBSS_ERR_STATE,
                format!(
                    "the initial state is not consistent with the constraints: max |f(x0)| = \
                     {:.3e}, max |G xdot0| = {:.3e}, beyond state_tol {state_tol:.1e}; give a \
                     consistent state, or project it (rbss_simulate_checked's `project`, \
                     Python's project=True), which reports how far it moved",
                    residual[0], residual[1]
                ),
            ));
        }
        let options = IntegrateOptions::new(method, Stabilization::Projection);
        let mut sim =
            Simulator::new(&h.model, &mut h.data, 0.0, &x0, &xdot0, options).map_err(solver)?;
        let moved = [
            sim.stats().initial_correction,
            sim.stats().initial_velocity_correction,
        ];
        let mut control = |_t: f64, _x: &[f64; N], _v: &[f64; N], out: &mut [f64]| {
            out.copy_from_slice(&u);
            Ok(())
        };
        sim.run(&h.model, &mut h.data, t_end, &mut control, |_| {})
            .map_err(solver)?;
        write(x, sim.x(), "x")?;
        write(xdot, sim.xdot(), "xdot")?;
        if let Some(p) = state {
            write(p, &[residual[0], residual[1], moved[0], moved[1]], "state")?;
        }
        Ok(())
    }
}

/// `rbss_simulate(h, x0, xdot0, u, t_end, rtol, atol, x, xdot)`: [`simulate`] with
/// [`RBSS_METHOD_DOPRI5`].
///
/// # Safety
/// See [`kinematics`].
#[allow(clippy::too_many_arguments)]
pub unsafe fn simulate_dopri5<K: Dynamics<N, M>, const N: usize, const M: usize>(
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
        simulate(
            h,
            RBSS_METHOD_DOPRI5,
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
            write_finite(out, &e, "energy", &[&x, &xdot])
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
            write_finite(mass, out.as_flattened(), "mass", &[&x])
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
            write_finite(psi, &out, "psi", &[&x, &xdot])
        })
    }
}
