//! The derivative functions of a robot with dynamics (issue 36): forward and inverse dynamics'
//! derivatives, the state-space linearisation on the constraint manifold and the Jacobians of
//! one discrete step, over the runtime's `forward_dynamics_derivatives`,
//! `inverse_dynamics_derivatives`, `linearize`, `rk4_step_derivatives` and
//! `semi_implicit_euler_step_derivatives`.
//!
//! Their buffers ([`Workspace`]) are made once per handle, by the first call of one of them;
//! later calls allocate nothing for them. Matrices are written column-major (`rbss.h`'s
//! convention), every output only on success: the pointers are checked before anything runs.

use rbss_runtime::{
    Coordinates, DynamicsDerivatives, ForwardDynamicsDerivatives, InverseDynamicsDerivatives,
    Linearization, SolverError, StepDerivatives,
};

use super::dynamics::STATE_TOL;
use super::*;
use rbss_abi::{
    RBSS_LINEARIZE_ACTUATED, RBSS_LINEARIZE_OUTPUTS, RBSS_STEP_RK4, RBSS_STEP_SEMI_IMPLICIT_EULER,
};

/// The buffers of the derivative functions of one handle.
pub struct Workspace<const N: usize, const M: usize> {
    derivatives: ForwardDynamicsDerivatives<N, M>,
    inverse: InverseDynamicsDerivatives<N, M>,
    linearization: Linearization<N, M>,
    step: StepDerivatives<N, M>,
    /// `A` and `B` row-major (`Linearization::state_space`), before the transposition.
    a: Vec<f64>,
    b: Vec<f64>,
    /// `A` or `B` column-major, as written.
    t: Vec<f64>,
    /// The first `actuated` rows of an N × N matrix, column-major (`∂U/∂(X, Ẋ, Ẍ)`).
    rows: Vec<f64>,
}

impl<const N: usize, const M: usize> Workspace<N, M> {
    fn new() -> Self {
        // `linearize` needs `d = N - M` independent coordinates; `A` is 2d × 2d, `B` 2d × na
        // with na <= N.
        let w = 2 * N.saturating_sub(M);
        Self {
            derivatives: ForwardDynamicsDerivatives::new(),
            inverse: InverseDynamicsDerivatives::new(),
            linearization: Linearization::new(),
            step: StepDerivatives::new(),
            a: vec![0.0; w * w],
            b: vec![0.0; w * N],
            t: vec![0.0; w * w.max(N)],
            rows: vec![0.0; N * N],
        }
    }
}

/// The handle's workspace, made on first use.
fn workspace<const N: usize, const M: usize>(
    w: &mut Option<Box<Workspace<N, M>>>,
) -> &mut Workspace<N, M> {
    w.get_or_insert_with(|| Box::new(Workspace::new()))
}

/// The code of a runtime error of the derivative functions: a non-finite value
/// [`RBSS_ERR_NONFINITE`], coordinates the robot does not have (`linearize` in the actuated
/// coordinates of an underactuated robot, in the outputs of one without)
/// [`RBSS_ERR_ARGUMENT`], any other (a singular saddle-point system, a singularity of the
/// chosen coordinates) [`RBSS_ERR_SOLVER`].
fn derivative_error(e: SolverError) -> Failure {
    let code = match e {
        SolverError::NonFinite { .. } => RBSS_ERR_NONFINITE,
        SolverError::Underactuated { .. } | SolverError::NoOutputs { .. } => RBSS_ERR_ARGUMENT,
        _ => RBSS_ERR_SOLVER,
    };
    (code, e.to_string())
}

/// The actuated forces `u` (`k <= N` of them, finite) into the first `k` entries of an array:
/// no allocation.
///
/// # Safety
/// `p` is null or points to `k` doubles.
unsafe fn read_u<const N: usize>(p: *const f64, k: usize) -> Result<[f64; N], Failure> {
    if p.is_null() {
        return Err((RBSS_ERR_ARGUMENT, "`u` is a null pointer".to_string()));
    }
    // SAFETY: the caller's contract.
    let given = unsafe { std::slice::from_raw_parts(p, k) };
    if let Some(i) = given.iter().position(|v| !v.is_finite()) {
        return Err((
            RBSS_ERR_ARGUMENT,
            format!("`u`[{i}] is not finite ({})", given[i]),
        ));
    }
    let mut u = [0.0; N];
    u[..k].copy_from_slice(given);
    Ok(u)
}

/// `X` and `Ẋ` (finite) into `data`.
///
/// # Safety
/// `x` and `xdot` are null or point to `N` doubles.
unsafe fn read_state<K, const N: usize, const M: usize>(
    h: &mut Handle<K, N, M>,
    x: *const f64,
    xdot: *const f64,
) -> Result<(), Failure> {
    // SAFETY: the caller's contract.
    unsafe {
        h.data.x = read_n(x, "x")?;
        h.data.xdot = read_n(xdot, "xdot")?;
    }
    Ok(())
}

/// `rbss_forward_dynamics_derivatives(h, x, xdot, u, xddot, lambda, dxddot_dx, dxddot_dxdot,
/// dxddot_du, dlambda_dx, dlambda_dxdot, dlambda_du)`: forward dynamics at `(x, xdot, u)` and
/// its derivatives with respect to `X`, `Xdot` and `U` (the runtime's
/// `forward_dynamics_derivatives`, without stabilisation), column-major.
///
/// # Safety
/// See [`kinematics`]; every array holds the length of `rbss.h`.
#[allow(clippy::too_many_arguments)]
pub unsafe fn forward_dynamics_derivatives<
    K: DynamicsDerivatives<N, M>,
    const N: usize,
    const M: usize,
>(
    h: *mut Handle<K, N, M>,
    x: *const f64,
    xdot: *const f64,
    u: *const f64,
    xddot: *mut f64,
    lambda: *mut f64,
    dxddot_dx: *mut f64,
    dxddot_dxdot: *mut f64,
    dxddot_du: *mut f64,
    dlambda_dx: *mut f64,
    dlambda_dxdot: *mut f64,
    dlambda_du: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let outs = [
                (xddot, "xddot"),
                (lambda, "lambda"),
                (dxddot_dx, "dxddot_dx"),
                (dxddot_dxdot, "dxddot_dxdot"),
                (dxddot_du, "dxddot_du"),
                (dlambda_dx, "dlambda_dx"),
                (dlambda_dxdot, "dlambda_dxdot"),
                (dlambda_du, "dlambda_du"),
            ];
            outputs_given(&outs)?;
            read_state(h, x, xdot)?;
            let k = h.actuated();
            let u = read_u::<N>(u, k)?;
            let ws = workspace(&mut h.derivatives);
            let d = &mut ws.derivatives;
            rbss_runtime::forward_dynamics_derivatives(&h.model, &mut h.data, d, &u[..k], None)
                .map_err(derivative_error)?;
            // nalgebra's storage is column-major: the first `k` columns of the N × N (M × N)
            // storage are the N × k (M × k) matrix.
            write(xddot, &h.data.xddot, "xddot")?;
            write(lambda, &h.data.lambda, "lambda")?;
            write(dxddot_dx, d.dxddot_dx.as_slice(), "dxddot_dx")?;
            write(dxddot_dxdot, d.dxddot_dxdot.as_slice(), "dxddot_dxdot")?;
            write(dxddot_du, &d.dxddot_du.as_slice()[..N * k], "dxddot_du")?;
            write(dlambda_dx, d.dlambda_dx.as_slice(), "dlambda_dx")?;
            write(dlambda_dxdot, d.dlambda_dxdot.as_slice(), "dlambda_dxdot")?;
            write(dlambda_du, &d.dlambda_du.as_slice()[..M * k], "dlambda_du")
        })
    }
}

/// `rbss_inverse_dynamics_derivatives(h, x, xdot, xddot, u, lambda, du_dx, du_dxdot, du_dxddot,
/// dlambda_dx, dlambda_dxdot, dlambda_dxddot)`: inverse dynamics at `(x, xdot, xddot)` (`u`,
/// `lambda` as `rbss_inverse_dynamics`) and its derivatives with respect to `X`, `Xdot` and
/// `Xddot` (the runtime's `inverse_dynamics_derivatives`), column-major: `dU/d*` actuated × n,
/// `dlambda/d*` m × n.
///
/// # Safety
/// See [`kinematics`]; every array holds the length of `rbss.h`.
#[allow(clippy::too_many_arguments)]
pub unsafe fn inverse_dynamics_derivatives<
    K: DynamicsDerivatives<N, M>,
    const N: usize,
    const M: usize,
>(
    h: *mut Handle<K, N, M>,
    x: *const f64,
    xdot: *const f64,
    xddot: *const f64,
    u: *mut f64,
    lambda: *mut f64,
    du_dx: *mut f64,
    du_dxdot: *mut f64,
    du_dxddot: *mut f64,
    dlambda_dx: *mut f64,
    dlambda_dxdot: *mut f64,
    dlambda_dxddot: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            let outs = [
                (u, "u"),
                (lambda, "lambda"),
                (du_dx, "du_dx"),
                (du_dxdot, "du_dxdot"),
                (du_dxddot, "du_dxddot"),
                (dlambda_dx, "dlambda_dx"),
                (dlambda_dxdot, "dlambda_dxdot"),
                (dlambda_dxddot, "dlambda_dxddot"),
            ];
            outputs_given(&outs)?;
            read_state(h, x, xdot)?;
            h.data.xddot = read_n(xddot, "xddot")?;
            let k = h.actuated();
            let ws = workspace(&mut h.derivatives);
            let d = &mut ws.inverse;
            rbss_runtime::inverse_dynamics_derivatives(&h.model, &mut h.data, d, None)
                .map_err(derivative_error)?;
            write(u, &h.data.u[..k], "u")?;
            write(lambda, &h.data.lambda, "lambda")?;
            // The first `k` rows of the N × N storage (column-major), k × N column-major.
            let rows = &mut ws.rows[..k * N];
            for (m, p, what) in [
                (&d.du_dx, du_dx, "du_dx"),
                (&d.du_dxdot, du_dxdot, "du_dxdot"),
                (&d.du_dxddot, du_dxddot, "du_dxddot"),
            ] {
                for j in 0..N {
                    rows[j * k..(j + 1) * k].copy_from_slice(&m.as_slice()[j * N..j * N + k]);
                }
                write(p, rows, what)?;
            }
            write(dlambda_dx, d.dlambda_dx.as_slice(), "dlambda_dx")?;
            write(dlambda_dxdot, d.dlambda_dxdot.as_slice(), "dlambda_dxdot")?;
            write(
                dlambda_dxddot,
                d.dlambda_dxddot.as_slice(),
                "dlambda_dxddot",
            )
        })
    }
}

/// `rbss_linearize(h, coordinates, x, xdot, u, a, b)`: the state-space linearisation
/// `d/dt [y; ydot] = A [y; ydot] + B U` of forward dynamics on the constraint manifold at
/// `(x, xdot, u)`, in the independent coordinates `y` ([`RBSS_LINEARIZE_OUTPUTS`] or
/// [`RBSS_LINEARIZE_ACTUATED`]; `d = n - m` of them): `A` (2d × 2d) and `B` (2d × actuated),
/// column-major. The state must be on the manifold: `max |f(X)|` or `max |G Xdot|` above
/// [`STATE_TOL`] is [`RBSS_ERR_STATE`].
///
/// # Safety
/// See [`kinematics`]; every array holds the length of `rbss.h`.
#[allow(clippy::too_many_arguments)]
pub unsafe fn linearize<K: DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    coordinates: c_int,
    x: *const f64,
    xdot: *const f64,
    u: *const f64,
    a: *mut f64,
    b: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            outputs_given(&[(a, "a"), (b, "b")])?;
            let coordinates = match coordinates {
                RBSS_LINEARIZE_OUTPUTS => Coordinates::Outputs,
                RBSS_LINEARIZE_ACTUATED => Coordinates::Actuated,
                other => {
                    return Err((
                        RBSS_ERR_ARGUMENT,
                        format!(
                            "`coordinates` = {other}: RBSS_LINEARIZE_OUTPUTS \
                             ({RBSS_LINEARIZE_OUTPUTS}) or RBSS_LINEARIZE_ACTUATED \
                             ({RBSS_LINEARIZE_ACTUATED})"
                        ),
                    ));
                }
            };
            read_state(h, x, xdot)?;
            let k = h.actuated();
            let u = read_u::<N>(u, k)?;
            let residual = rbss_runtime::state_residual(&h.model, &h.data.x, &h.data.xdot);
            if !(residual[0] <= STATE_TOL && residual[1] <= STATE_TOL) {
                return Err((
                    RBSS_ERR_STATE,
                    format!(
                        "the state is not on the constraint manifold: max |f(x)| = {:.3e}, \
                         max |G xdot| = {:.3e}, beyond {STATE_TOL:.1e}; the linearisation is \
                         that of the dynamics restricted to it (solve the positions and \
                         velocities first: rbss_ik, rbss_inverse_velocity)",
                        residual[0], residual[1]
                    ),
                ));
            }
            let ws = workspace(&mut h.derivatives);
            let lin = &mut ws.linearization;
            rbss_runtime::linearize(&h.model, &mut h.data, lin, &u[..k], None, coordinates)
                .map_err(derivative_error)?;
            let w = 2 * lin.d;
            let (ra, rb) = (&mut ws.a[..w * w], &mut ws.b[..w * k]);
            lin.state_space(ra, rb).map_err(derivative_error)?;
            // Row-major to column-major.
            let t = &mut ws.t;
            for i in 0..w {
                for j in 0..w {
                    t[i + j * w] = ra[i * w + j];
                }
            }
            write(a, &t[..w * w], "a")?;
            for i in 0..w {
                for j in 0..k {
                    t[i + j * w] = rb[i * k + j];
                }
            }
            write(b, &t[..w * k], "b")
        })
    }
}

/// `rbss_step_derivatives(h, method, x, xdot, u, dt, baumgarte, x_next, xdot_next, fx, fu)`:
/// one step of `dt` ([`RBSS_STEP_RK4`] or [`RBSS_STEP_SEMI_IMPLICIT_EULER`]) from the state
/// `s = (x, xdot)` under `u` held over it, with Baumgarte's gains `[alpha, beta]` (null: none),
/// and its Jacobians `F_x = ds'/ds` (2n × 2n) and `F_u = ds'/dU` (2n × actuated),
/// column-major; the new state in `x_next`, `xdot_next`.
///
/// # Safety
/// See [`kinematics`]; every array holds the length of `rbss.h`.
#[allow(clippy::too_many_arguments)]
pub unsafe fn step_derivatives<K: DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    method: c_int,
    x: *const f64,
    xdot: *const f64,
    u: *const f64,
    dt: f64,
    baumgarte: *const f64,
    x_next: *mut f64,
    xdot_next: *mut f64,
    fx: *mut f64,
    fu: *mut f64,
) -> c_int {
    // SAFETY: the caller's contract.
    unsafe {
        call(h, |h| {
            outputs_given(&[
                (x_next, "x_next"),
                (xdot_next, "xdot_next"),
                (fx, "fx"),
                (fu, "fu"),
            ])?;
            if method != RBSS_STEP_RK4 && method != RBSS_STEP_SEMI_IMPLICIT_EULER {
                return Err((
                    RBSS_ERR_ARGUMENT,
                    format!(
                        "`method` = {method}: RBSS_STEP_RK4 ({RBSS_STEP_RK4}) or \
                         RBSS_STEP_SEMI_IMPLICIT_EULER ({RBSS_STEP_SEMI_IMPLICIT_EULER})"
                    ),
                ));
            }
            if !(dt.is_finite() && dt > 0.0) {
                return Err((
                    RBSS_ERR_ARGUMENT,
                    format!("`dt` = {dt}: a finite number > 0"),
                ));
            }
            let gains = if baumgarte.is_null() {
                Baumgarte::NONE
            } else {
                let [alpha, beta] = read_n::<2>(baumgarte, "baumgarte")?;
                if alpha < 0.0 || beta < 0.0 {
                    return Err((
                        RBSS_ERR_ARGUMENT,
                        format!("`baumgarte` = [{alpha}, {beta}]: gains >= 0"),
                    ));
                }
                Baumgarte { alpha, beta }
            };
            read_state(h, x, xdot)?;
            let k = h.actuated();
            let u = read_u::<N>(u, k)?;
            let ws = workspace(&mut h.derivatives);
            let st = &mut ws.step;
            let step = if method == RBSS_STEP_RK4 {
                rbss_runtime::rk4_step_derivatives
            } else {
                rbss_runtime::semi_implicit_euler_step_derivatives
            };
            step(&h.model, &mut h.data, st, &u[..k], dt, gains).map_err(derivative_error)?;
            // `jacobian` is [F_x F_u], 2N × (2N + k), column-major.
            let n2 = 2 * N;
            write(x_next, &st.x, "x_next")?;
            write(xdot_next, &st.xdot, "xdot_next")?;
            write(fx, &st.jacobian[..n2 * n2], "fx")?;
            write(fu, &st.jacobian[n2 * n2..n2 * (n2 + k)], "fu")
        })
    }
}
