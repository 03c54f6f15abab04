//! `rbss fd` (forward dynamics at one state), `rbss linearize` and `rbss id-derivatives` (the
//! derivatives of forward and inverse dynamics at one state) and `rbss simulate` (forward
//! dynamics in time under a given control, or none), for any robot.
//!
//! The state file (JSON) is the one `rbss eval` reads, for one state:
//!
//! ```json
//! {"X": [..N..], "Xdot": [..N..], "U": [..k..]}
//! ```
//!
//! `U` (the forces on the actuated coordinates, in `[robot] actuated` order, N or N m) is
//! optional: zero when absent. `rbss simulate` also takes `"U_table": [[t, U1..Uk], ...]`
//! (times increasing; `U` linear between the rows and held beyond the first and the last)
//! instead of a constant `U`.
//!
//! Conventions (as `rbss eval`): `M Xddot = psi + S U - Gᵀ lambda`, `G Xddot = gamma`, with
//! `f = origin(a) - origin(b)`, `G = ∂f/∂X`, `gamma = -(dG/dt) Xdot`; `psi` holds gravity, the
//! Christoffel terms and the joints' springs and dampers; the energies `T` (with the joints'
//! armatures) and `Pi` (gravity and the springs).

use std::path::Path;

use rbss_runtime::{
    Baumgarte, Data, Dynamics, DynamicsDerivatives, IntegrateOptions, Method, Model, Simulator,
    gear_ratio,
};
use serde::{Deserialize, Serialize};

use crate::Evaluation;
use crate::plot::{Panel, Series, write_png_to};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StateIn {
    #[serde(rename = "X")]
    x: Vec<f64>,
    #[serde(rename = "Xdot")]
    xdot: Vec<f64>,
    #[serde(rename = "U", default)]
    u: Option<Vec<f64>>,
    #[serde(rename = "U_table", default)]
    u_table: Option<Vec<Vec<f64>>>,
}

#[derive(Serialize)]
struct FdOut {
    #[serde(rename = "Xddot", skip_serializing_if = "Option::is_none")]
    xddot: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lambda: Option<Vec<f64>>,
    /// `[T, Pi]` at the state.
    energy: [f64; 2],
    /// `max |M Xddot - psi - S U + Gᵀ lambda|` and `max |G Xddot - gamma|`, recomputed.
    #[serde(skip_serializing_if = "Option::is_none")]
    residual: Option<[f64; 2]>,
    /// The given state's consistency, `[max |f(X)|, max |G Ẋ|]` (before any projection).
    state_residual: [f64; 2],
    /// With `--project`: how far the state moved, `[max |ΔX|, max |ΔẊ|]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    projected: Option<[f64; 2]>,
    /// When forward dynamics fails at the state: the error's message, in place of `Xddot`,
    /// `lambda` and `residual`.
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// How a state file's state is checked against the constraints before it is used (issue 37:
/// an inconsistent state is never moved silently).
#[derive(Debug, Clone, Copy)]
pub struct StateCheck {
    /// The largest `max |f(X)|` and `max |G Ẋ|` accepted as they are.
    pub tol: f64,
    /// Project the state onto the constraints whatever its residual (and report the move).
    pub project: bool,
}

impl Default for StateCheck {
    fn default() -> Self {
        Self {
            tol: DEFAULT_STATE_TOL,
            project: false,
        }
    }
}

/// The default of `--state-tol`.
pub const DEFAULT_STATE_TOL: f64 = 1e-6;

/// `[max |f(X)|, max |G Ẋ|]` at the state ([`rbss_runtime::state_residual`], the C ABI's
/// check too).
fn consistency<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
    xdot: &[f64; N],
) -> [f64; 2] {
    rbss_runtime::state_residual(model, x, xdot)
}

/// The state's residual against `check` (see [`StateCheck`]): an error beyond the tolerance
/// unless projecting was asked.
fn check_state(path: &str, residual: [f64; 2], check: &StateCheck) -> Result<(), String> {
    if check.project || (residual[0] <= check.tol && residual[1] <= check.tol) {
        return Ok(());
    }
    Err(format!(
        "{path}: the state is not consistent with the constraints: max |f(X)| = {:.3e}, \
         max |G Xdot| = {:.3e}, beyond --state-tol {:.1e}; give a consistent state, or pass \
         --project to project it onto the constraints (the output reports by how much it moved)",
        residual[0], residual[1], check.tol
    ))
}

/// The control of a state file: none (zero), constant, or a table.
enum Control {
    Constant(Vec<f64>),
    Table(Vec<Vec<f64>>),
}

impl Control {
    fn at(&self, t: f64, u: &mut [f64]) {
        match self {
            Control::Constant(c) => u.copy_from_slice(c),
            Control::Table(rows) => {
                let i = rows.partition_point(|r| r[0] <= t);
                if i == 0 {
                    u.copy_from_slice(&rows[0][1..]);
                } else if i == rows.len() {
                    u.copy_from_slice(&rows[i - 1][1..]);
                } else {
                    let (a, b) = (&rows[i - 1], &rows[i]);
                    let s = (t - a[0]) / (b[0] - a[0]);
                    for (k, uk) in u.iter_mut().enumerate() {
                        *uk = a[k + 1] + s * (b[k + 1] - a[k + 1]);
                    }
                }
            }
        }
    }
}

/// Reads and checks a state file for a robot with `n` coordinates and `k` actuated ones.
fn read_state(
    path: &str,
    n: usize,
    k: usize,
    table: bool,
) -> Result<(Vec<f64>, Vec<f64>, Control), String> {
    let text = crate::read_input(Path::new(path))?;
    let st: StateIn =
        serde_json::from_str(&text).map_err(|e| format!("{path}: bad state file: {e}"))?;
    for (what, v) in [("X", &st.x), ("Xdot", &st.xdot)] {
        if v.len() != n {
            return Err(format!(
                "{path}: \"{what}\" has {} values, the robot has {n} coordinates",
                v.len()
            ));
        }
    }
    let control = match (st.u, st.u_table) {
        (Some(_), Some(_)) => {
            return Err(format!("{path}: give \"U\" or \"U_table\", not both"));
        }
        (Some(u), None) => {
            if u.len() != k {
                return Err(format!(
                    "{path}: \"U\" has {} values, the robot has {k} actuated coordinates",
                    u.len()
                ));
            }
            Control::Constant(u)
        }
        (None, Some(_)) if !table => {
            return Err(format!(
                "{path}: \"U_table\" is for `rbss simulate`; `rbss fd` takes \"U\" at the state"
            ));
        }
        (None, Some(rows)) => {
            if rows.is_empty() {
                return Err(format!("{path}: \"U_table\" is empty"));
            }
            for (i, r) in rows.iter().enumerate() {
                if r.len() != k + 1 {
                    return Err(format!(
                        "{path}: \"U_table\" row {i} has {} values, expected {} (t and {k} forces)",
                        r.len(),
                        k + 1
                    ));
                }
                if i > 0 && r[0] <= rows[i - 1][0] {
                    return Err(format!(
                        "{path}: \"U_table\" row {i}: t = {} does not increase",
                        r[0]
                    ));
                }
            }
            Control::Table(rows)
        }
        (None, None) => Control::Constant(vec![0.0; k]),
    };
    let all = st.x.iter().chain(&st.xdot);
    let all = all.chain(match &control {
        Control::Constant(u) => u.iter(),
        Control::Table(rows) => rows.first().map(|r| r.iter()).unwrap_or([].iter()),
    });
    if let Some(v) = all.clone().find(|v| !v.is_finite()) {
        return Err(format!("{path}: {v} is not a finite number"));
    }
    if let Control::Table(rows) = &control
        && let Some(v) = rows.iter().flatten().find(|v| !v.is_finite())
    {
        return Err(format!("{path}: \"U_table\": {v} is not a finite number"));
    }
    Ok((st.x, st.xdot, control))
}

/// `rbss fd --model NAME --state FILE`: forward dynamics at the state, as JSON.
pub fn fd_named(model: &str, path: &str) -> Result<Evaluation, String> {
    with_robot!(model, |m| fd(&m, path, &StateCheck::default()))
}

/// Forward dynamics at the state of `path` (see the module documentation): `Xddot`, `lambda`,
/// `[T, Pi]` and the residuals of both equations, recomputed from the kernels. When forward
/// dynamics fails there (a singular saddle-point system), the JSON has `"error"` (the message)
/// and `energy`, and [`Evaluation::failed`] lists the state as index 0; a bad state file is an
/// error.
pub fn fd<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    path: &str,
    check: &StateCheck,
) -> Result<Evaluation, String> {
    let s = model.structure();
    let (x, xdot, control) = read_state(path, N, s.actuated.len(), false)?;
    let Control::Constant(u) = control else {
        unreachable!("read_state refuses a table for fd")
    };
    let mut data = Data::new(model);
    data.x.copy_from_slice(&x);
    data.xdot.copy_from_slice(&xdot);
    let state_residual = consistency(model, &data.x, &data.xdot);
    check_state(path, state_residual, check)?;
    let projected = if check.project {
        let (x0, v0) = (data.x, data.xdot);
        rbss_runtime::project_position(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        rbss_runtime::project_velocity(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        Some([max_diff(&data.x, &x0), max_diff(&data.xdot, &v0)])
    } else {
        None
    };
    let k = model.kernels();
    if let Err(e) = rbss_runtime::forward_dynamics(model, &mut data, &u, None, Baumgarte::NONE) {
        let mut energy = [0.0; 2];
        k.energy(&data.x, &data.xdot, &mut energy);
        let e = format!("forward dynamics: {e}");
        let out = FdOut {
            xddot: None,
            lambda: None,
            energy,
            residual: None,
            state_residual,
            projected,
            error: Some(e.clone()),
        };
        let json = serde_json::to_string(&out).map_err(|e| format!("cannot write JSON: {e}"))?;
        return Ok(Evaluation {
            json,
            failed: vec![(0, e)],
        });
    }
    let (mut g, mut gamma, mut mass, mut psi) = ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
    k.dynamics_terms(&data.x, &data.xdot, &mut g, &mut gamma, &mut mass, &mut psi);
    let mut force = psi;
    for (a, &j) in s.actuated.iter().enumerate() {
        force[j] += gear_ratio(s.gear, a) * u[a];
    }
    let mut r_motion = 0.0_f64;
    for (i, (fi, gi)) in force.iter().zip(&g).enumerate() {
        let m_xddot: f64 = mass
            .iter()
            .zip(&data.xddot)
            .map(|(col, a)| col[i] * a)
            .sum();
        let g_lambda: f64 = gi.iter().zip(&data.lambda).map(|(gc, l)| gc * l).sum();
        r_motion = r_motion.max((m_xddot + g_lambda - fi).abs());
    }
    let mut r_constraint = 0.0_f64;
    for c in 0..M {
        let r: f64 = (0..N).map(|j| g[j][c] * data.xddot[j]).sum::<f64>() - gamma[c];
        r_constraint = r_constraint.max(r.abs());
    }
    let mut energy = [0.0; 2];
    k.energy(&data.x, &data.xdot, &mut energy);
    let out = FdOut {
        xddot: Some(data.xddot.to_vec()),
        lambda: Some(data.lambda.to_vec()),
        energy,
        residual: Some([r_motion, r_constraint]),
        state_residual,
        projected,
        error: None,
    };
    let json = serde_json::to_string(&out).map_err(|e| format!("cannot write JSON: {e}"))?;
    Ok(Evaluation {
        json,
        failed: Vec::new(),
    })
}

/// `max |a - b|`.
fn max_diff<const N: usize>(a: &[f64; N], b: &[f64; N]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0_f64, |m, (p, q)| m.max((p - q).abs()))
}

/// What `rbss simulate` was asked.
pub struct SimulateRequest {
    pub model: String,
    pub state: String,
    pub t_end: f64,
    pub integrate: IntegrateOptions,
    pub out: String,
    /// The initial state's check (`--state-tol`, `--project`).
    pub check: StateCheck,
    /// The bound on the run's errors (`--max-violation`; `None`: [`default_bound`] of the
    /// integrator's tolerance).
    pub max_violation: Option<f64>,
}

/// The bound on a run's constraint violation (`max |f(X)|` at an accepted step, before any
/// projection, in m or rad) and on its energy rise without control (relative to `max(1 J,
/// |E(0)|)`), tied to the integrator's tolerance: `10⁴ rtol` for DOPRI5 and DOP853, `10⁶ dt⁴`
/// for RK4 (its local error's order), within [1e-8, 1e-3].
pub fn default_bound(method: &Method) -> f64 {
    let b = match *method {
        Method::Dopri5 { rtol, .. } | Method::Dop853 { rtol, .. } => 1e4 * rtol,
        Method::Rk4 { dt } => 1e6 * dt.powi(4),
    };
    b.clamp(1e-8, 1e-3)
}

/// `rbss simulate`: runs the named robot (see [`simulate`]) and returns the report line.
pub fn simulate_command(req: &SimulateRequest) -> Result<String, String> {
    with_robot!(req.model.as_str(), |model| simulate(&model, req))
}

/// Forward dynamics from the state of `req.state` over `[0, t_end]` under its control; writes
/// `simulate.csv` (`t`, the coordinates, their rates `NAME_dot`, `T`, `Pi`, `E = T + Pi`, one
/// row per accepted step) and `simulate.png` (the coordinates and the energy), committed
/// together ([`crate::output`]).
pub fn simulate<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    req: &SimulateRequest,
) -> Result<String, String> {
    let started = std::time::Instant::now();
    let s = model.structure();
    let t_end = req.t_end;
    if !(t_end.is_finite() && t_end > 0.0) {
        return Err(format!("--t-end {t_end}: must be finite and positive"));
    }
    let bound = match req.max_violation {
        Some(b) if b > 0.0 && b.is_finite() => b,
        Some(b) => return Err(format!("--max-violation {b}: must be finite and positive")),
        None => default_bound(&req.integrate.method),
    };
    let (x, xdot, control) = read_state(&req.state, N, s.actuated.len(), true)?;
    let x0: [f64; N] = std::array::from_fn(|i| x[i]);
    let xdot0: [f64; N] = std::array::from_fn(|i| xdot[i]);
    check_state(&req.state, consistency(model, &x0, &xdot0), &req.check)?;
    let mut data = Data::new(model);
    let mut sim = Simulator::new(model, &mut data, 0.0, &x0, &xdot0, req.integrate)
        .map_err(|e| format!("{}: cannot start: {e}", req.state))?;
    let k = model.kernels();
    let row = |t: f64, x: &[f64; N], v: &[f64; N]| -> Vec<f64> {
        let mut e = [0.0; 2];
        k.energy(x, v, &mut e);
        let mut r = Vec::with_capacity(2 * N + 4);
        r.push(t);
        r.extend_from_slice(x);
        r.extend_from_slice(v);
        r.extend_from_slice(&[e[0], e[1], e[0] + e[1]]);
        r
    };
    let mut rows = vec![row(0.0, sim.x(), sim.xdot())];
    let mut u_of_t = |t: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
        control.at(t, u);
        Ok(())
    };
    let stats = sim
        .run(model, &mut data, t_end, &mut u_of_t, |sim| {
            rows.push(row(sim.t(), sim.x(), sim.xdot()));
        })
        .map_err(|e| format!("forward dynamics: {e}"))?;
    let initial = [
        sim.stats().initial_correction,
        sim.stats().initial_velocity_correction,
    ];
    // Never a non-physical result with exit 0: the violation, and the energy's rise when no
    // force does work (the joints' dampers only take energy away).
    let relax = format!(
        "tighten --rtol (or --dt), or relax the bound with --max-violation (now {bound:.1e})"
    );
    if stats.max_violation.is_nan() || stats.max_violation > bound {
        return Err(format!(
            "the constraint violation reached max |f(X)| = {:.3e} (before projection), beyond \
             the bound {bound:.1e} tied to the integrator's tolerance: the motion is not \
             physical; {relax}",
            stats.max_violation
        ));
    }
    let e_col = 3 + 2 * N;
    let e0 = rows[0][e_col];
    if matches!(&control, Control::Constant(u) if u.iter().all(|&v| v == 0.0)) {
        let scale = e0.abs().max(1.0);
        let rise = rows
            .iter()
            .map(|r| r[e_col] - e0)
            .fold(f64::NEG_INFINITY, f64::max);
        if rise.is_nan() || rise > bound * scale {
            return Err(format!(
                "the energy rose by {rise:.3e} J from {e0:.6e} J without any force doing work, \
                 beyond the bound {bound:.1e} x {scale:.3e} J tied to the integrator's \
                 tolerance: the motion is not physical; {relax}"
            ));
        }
    }

    let out = Path::new(&req.out);
    crate::create_output_dir(out)?;
    let mut header = vec!["t".to_string()];
    header.extend(s.coordinates.iter().map(|c| c.to_string()));
    header.extend(s.coordinates.iter().map(|c| format!("{c}_dot")));
    header.extend(["T", "Pi", "E"].map(String::from));
    let mut files = crate::output::Outputs::new();
    crate::csv::write_to(&mut files, &out.join("simulate.csv"), &header, &rows)?;
    let t: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let col = |c: usize| rows.iter().map(|r| r[c]).collect::<Vec<f64>>();
    let mut coords = Panel::new("coordinates", "t [s]", "m or rad");
    for (i, c) in s.coordinates.iter().enumerate() {
        coords = coords.with(Series::new(c.to_string(), t.clone(), col(1 + i)));
    }
    let energy = Panel::new("energy", "t [s]", "J")
        .with(Series::new("T", t.clone(), col(1 + 2 * N)))
        .with(Series::new("Pi", t.clone(), col(2 + 2 * N)))
        .with(Series::new("E = T + Pi", t.clone(), col(3 + 2 * N)));
    write_png_to(
        &mut files,
        &out.join("simulate.png"),
        &format!("{}: forward dynamics from {}", s.name, req.state),
        &[coords, energy],
        2,
        1600,
        600,
    )?;
    files.commit()?;
    let e1 = rows[rows.len() - 1][e_col];
    Ok(format!(
        "{}: {} steps over [0, {t_end}] s, max constraint violation {:.1e} (bound {bound:.1e}), \
         energy {e0:.9} -> {e1:.9} J; initial state projected by max |dX| {:.1e}, max |dXdot| \
         {:.1e}{}; wrote {}/simulate.csv and simulate.png ({:.2} s)",
        s.name,
        stats.steps,
        stats.max_violation,
        initial[0],
        initial[1],
        if req.check.project {
            " (--project)"
        } else {
            ""
        },
        out.display(),
        started.elapsed().as_secs_f64()
    ))
}

/// The JSON of `rbss linearize` (see [`linearize`]): matrices as arrays of rows.
#[derive(Serialize)]
struct LinearizeOut {
    /// `"outputs"` or `"actuated"`.
    coordinates: &'static str,
    /// The independent coordinates `y`: their names and indices into `X`.
    names: Vec<&'static str>,
    index: Vec<usize>,
    /// `d/dt [y; ẏ] = A [y; ẏ] + B U` linearised: `A` (2d × 2d), `B` (2d × k).
    #[serde(rename = "A")]
    a: Vec<Vec<f64>>,
    #[serde(rename = "B")]
    b: Vec<Vec<f64>>,
    /// The tangent map `∂X/∂y` (N × d) and `∂Ẋ/∂y` at fixed `ẏ` (N × d).
    tangent: Vec<Vec<f64>>,
    #[serde(rename = "dXdot_dy")]
    dxdot_dy: Vec<Vec<f64>>,
    #[serde(rename = "Xddot")]
    xddot: Vec<f64>,
    lambda: Vec<f64>,
    /// The full derivatives of forward dynamics.
    #[serde(rename = "dXddot_dX")]
    dxddot_dx: Vec<Vec<f64>>,
    #[serde(rename = "dXddot_dXdot")]
    dxddot_dxdot: Vec<Vec<f64>>,
    #[serde(rename = "dXddot_dU")]
    dxddot_du: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dX")]
    dlambda_dx: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dXdot")]
    dlambda_dxdot: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dU")]
    dlambda_du: Vec<Vec<f64>>,
    /// The given state's consistency, `[max |f(X)|, max |G Ẋ|]` (before any projection).
    state_residual: [f64; 2],
    /// With `--project`: how far the state moved, `[max |ΔX|, max |ΔẊ|]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    projected: Option<[f64; 2]>,
}

/// The rows `0..rows` of the first `cols` columns of a matrix.
fn rows_of(
    m: &impl std::ops::Index<(usize, usize), Output = f64>,
    rows: usize,
    cols: usize,
) -> Vec<Vec<f64>> {
    (0..rows)
        .map(|i| (0..cols).map(|j| m[(i, j)]).collect())
        .collect()
}

/// `rbss linearize --model NAME --state FILE [--coordinates outputs|actuated]`: the
/// state-space linearisation of forward dynamics on the constraint manifold at the state of
/// `path` (the file `rbss fd` reads; its `U` is the operating point's control), in the outputs'
/// or the actuated coordinates (`actuated`), as JSON: `A`, `B`, the tangent map and the full
/// derivatives of `Xddot` and `lambda` with respect to `X`, `Xdot` and `U`. The state is
/// checked (or projected) as `rbss fd` does; a failure (a singular saddle-point system, a
/// singularity of the chosen coordinates) is an error.
pub fn linearize<K: DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    path: &str,
    check: &StateCheck,
    actuated: bool,
) -> Result<String, String> {
    let s = model.structure();
    let (x, xdot, control) = read_state(path, N, s.actuated.len(), false)?;
    let Control::Constant(u) = control else {
        unreachable!("read_state refuses a table for linearize")
    };
    let mut data = Data::new(model);
    data.x.copy_from_slice(&x);
    data.xdot.copy_from_slice(&xdot);
    let state_residual = consistency(model, &data.x, &data.xdot);
    check_state(path, state_residual, check)?;
    let projected = if check.project {
        let (x0, v0) = (data.x, data.xdot);
        rbss_runtime::project_position(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        rbss_runtime::project_velocity(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        Some([max_diff(&data.x, &x0), max_diff(&data.xdot, &v0)])
    } else {
        None
    };
    let coordinates = if actuated {
        rbss_runtime::Coordinates::Actuated
    } else {
        rbss_runtime::Coordinates::Outputs
    };
    let mut lin = rbss_runtime::Linearization::new();
    lin.full_derivatives = true; // written out below
    rbss_runtime::linearize(model, &mut data, &mut lin, &u, None, coordinates)
        .map_err(|e| format!("{path}: linearize: {e}"))?;
    let (d, k) = (lin.d, lin.na);
    let (mut a, mut b) = (vec![0.0; 4 * d * d], vec![0.0; 2 * d * k]);
    lin.state_space(&mut a, &mut b)
        .map_err(|e| format!("linearize: {e}"))?;
    let fd = &lin.derivatives;
    let out = LinearizeOut {
        coordinates: if actuated { "actuated" } else { "outputs" },
        names: lin.index[..d].iter().map(|&j| s.coordinates[j]).collect(),
        index: lin.index[..d].to_vec(),
        a: a.chunks(2 * d).map(<[f64]>::to_vec).collect(),
        b: if k == 0 {
            vec![Vec::new(); 2 * d]
        } else {
            b.chunks(k).map(<[f64]>::to_vec).collect()
        },
        tangent: rows_of(&lin.tangent, N, d),
        dxdot_dy: rows_of(&lin.dxdot_dy, N, d),
        xddot: data.xddot.to_vec(),
        lambda: data.lambda.to_vec(),
        dxddot_dx: rows_of(&fd.dxddot_dx, N, N),
        dxddot_dxdot: rows_of(&fd.dxddot_dxdot, N, N),
        dxddot_du: rows_of(&fd.dxddot_du, N, k),
        dlambda_dx: rows_of(&fd.dlambda_dx, M, N),
        dlambda_dxdot: rows_of(&fd.dlambda_dxdot, M, N),
        dlambda_du: rows_of(&fd.dlambda_du, M, k),
        state_residual,
        projected,
    };
    serde_json::to_string(&out).map_err(|e| format!("cannot write JSON: {e}"))
}

/// The motion file of `rbss id-derivatives`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MotionIn {
    #[serde(rename = "X")]
    x: Vec<f64>,
    #[serde(rename = "Xdot")]
    xdot: Vec<f64>,
    #[serde(rename = "Xddot")]
    xddot: Vec<f64>,
}

/// The JSON of `rbss id-derivatives` (see [`id_derivatives`]): matrices as arrays of rows.
#[derive(Serialize)]
struct IdDerivativesOut {
    #[serde(rename = "U")]
    u: Vec<f64>,
    lambda: Vec<f64>,
    #[serde(rename = "dU_dX")]
    du_dx: Vec<Vec<f64>>,
    #[serde(rename = "dU_dXdot")]
    du_dxdot: Vec<Vec<f64>>,
    #[serde(rename = "dU_dXddot")]
    du_dxddot: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dX")]
    dlambda_dx: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dXdot")]
    dlambda_dxdot: Vec<Vec<f64>>,
    #[serde(rename = "dlambda_dXddot")]
    dlambda_dxddot: Vec<Vec<f64>>,
    /// `"block_elimination"` or `"dense_lu"`.
    method: String,
    /// The condition estimate of the solve (the reduced system's, or `[S | Gᵀ]`'s).
    cond: f64,
    /// The given state's consistency, `[max |f(X)|, max |G Ẋ|]` (before any projection).
    state_residual: [f64; 2],
    /// With `--project`: how far the state moved, `[max |ΔX|, max |ΔẊ|]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    projected: Option<[f64; 2]>,
}

/// `rbss id-derivatives --model NAME --state FILE`: inverse dynamics at the motion of `path`
/// (`{"X", "Xdot", "Xddot"}`) and its derivatives with respect to `X`, `Xdot` and `Xddot` (the
/// runtime's [`rbss_runtime::inverse_dynamics_derivatives`], the applied forces held), as JSON.
/// `X` and `Xdot` are checked (or projected) as `rbss fd` does; `Xddot` is used as given (the
/// derivatives hold off the acceleration constraint too). A singular `[S | Gᵀ]` is an error.
pub fn id_derivatives<K: DynamicsDerivatives<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    path: &str,
    check: &StateCheck,
) -> Result<String, String> {
    let s = model.structure();
    let text = crate::read_input(Path::new(path))?;
    let st: MotionIn =
        serde_json::from_str(&text).map_err(|e| format!("{path}: bad motion file: {e}"))?;
    for (what, v) in [("X", &st.x), ("Xdot", &st.xdot), ("Xddot", &st.xddot)] {
        if v.len() != N {
            return Err(format!(
                "{path}: \"{what}\" has {} values, the robot has {N} coordinates",
                v.len()
            ));
        }
        if let Some(e) = v.iter().find(|e| !e.is_finite()) {
            return Err(format!("{path}: \"{what}\": {e} is not a finite number"));
        }
    }
    let mut data = Data::new(model);
    data.x.copy_from_slice(&st.x);
    data.xdot.copy_from_slice(&st.xdot);
    data.xddot.copy_from_slice(&st.xddot);
    let state_residual = consistency(model, &data.x, &data.xdot);
    check_state(path, state_residual, check)?;
    let projected = if check.project {
        let (x0, v0) = (data.x, data.xdot);
        rbss_runtime::project_position(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        rbss_runtime::project_velocity(model, &mut data)
            .map_err(|e| format!("{path}: cannot project the state: {e}"))?;
        Some([max_diff(&data.x, &x0), max_diff(&data.xdot, &v0)])
    } else {
        None
    };
    let mut d = rbss_runtime::InverseDynamicsDerivatives::new();
    rbss_runtime::inverse_dynamics_derivatives(model, &mut data, &mut d, None)
        .map_err(|e| format!("{path}: inverse-dynamics derivatives: {e}"))?;
    let k = s.actuated.len();
    let out = IdDerivativesOut {
        u: data.u[..k].to_vec(),
        lambda: data.lambda.to_vec(),
        du_dx: rows_of(&d.du_dx, k, N),
        du_dxdot: rows_of(&d.du_dxdot, k, N),
        du_dxddot: rows_of(&d.du_dxddot, k, N),
        dlambda_dx: rows_of(&d.dlambda_dx, M, N),
        dlambda_dxdot: rows_of(&d.dlambda_dxdot, M, N),
        dlambda_dxddot: rows_of(&d.dlambda_dxddot, M, N),
        method: match d.method {
            rbss_runtime::DynamicsMethod::BlockElimination => "block_elimination".into(),
            rbss_runtime::DynamicsMethod::DenseLu => "dense_lu".into(),
            other => format!("{other:?}"),
        },
        cond: d.cond,
        state_residual,
        projected,
    };
    serde_json::to_string(&out).map_err(|e| format!("cannot write JSON: {e}"))
}
