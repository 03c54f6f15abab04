//! `rbss bench work-precision`: a robot's round trip (`rbss roundtrip`; for `stewart_6ups`
//! compiled in, `rbss paper`'s along TraekP) integrated with every constraint stabilisation
//! crossed with every integrator setting, timed, and measured against the trajectory: a
//! work-precision diagram in the manner of SciMLBenchmarks.
//!
//! The trajectory of the outputs: `--trajectory FILE` (`.toml` expressions or `.csv` samples,
//! as `rbss roundtrip` reads them); without it, TraekP for the paper's `--model stewart_6ups`
//! (w = pi rad/s over `[0, 2]` s, the figures of BENCHMARKS.md) and for any other robot,
//! `--model-file` included, its default `models/trajectories/NAME.toml` (in the current
//! directory, else in the rbss sources), over its first to last sample, else `[0, 2]` s.
//!
//! Each run is the forward dynamics of the robot from the trajectory's start state (inverse
//! kinematics and velocity) under the control forces `U(t)` of inverse dynamics along the
//! trajectory (evaluated exactly at every stage time, [`crate::trajectory::control`]) over the
//! time span. Recorded per run:
//!
//! - `time_s`: median wall time of the integration alone over the repeats (the setup, the
//!   projection of the start and the error measurement excluded);
//! - right-hand-side evaluations, accepted and rejected steps, Newton iterations of the
//!   stabilisation (`IntegrateStats`);
//! - `output_error`: max |output - trajectory| over the outputs and the accepted steps (each in
//!   its unit, m or rad: `rbss roundtrip`'s measure); split by the outputs' units from the model
//!   file (`unit = "m"` or `"rad"`/`"deg"`), `position_error_m` over the translations (the
//!   diagram's precision axis where there are any; else `output_error`) and
//!   `rotation_error_rad` over the rotations, empty where the robot has no such output or
//!   the model file does not list its coordinates (an imported model);
//! - `max_violation_m`: max |f(X)| at the accepted steps before any projection;
//! - `energy_error_j`: the work-energy balance `max_t |E(t) - E(0) - W(t)|` over the accepted
//!   steps, `E = T + Pi` from the generated `energy` kernel and `W(t) = ∫ U · q̇ dt` the work
//!   of the control forces along the simulated motion (the constraint forces do no work on the
//!   manifold; a robot with joint dampers also dissipates, which the balance then shows). The
//!   maximum over time, not only the end: TraekP is periodic over `[0, 2]` s, so
//!   `E(t_end) - E(0)` and `W(t_end)` both vanish for the exact motion, while `E` swings by
//!   `energy_swing_j` in between. `W` is integrated
//!   step by step with 4-point Gauss–Legendre, `U` exact at the nodes and `q̇` from the quintic
//!   Hermite interpolant of `q, q̇, q̈` at the step's ends (`q̈` by forward dynamics at the
//!   accepted states): an `O(h⁶)` local quadrature, far below the integrators' own errors.
//!   It applies to every stabilisation; it measures how far the discrete motion is from
//!   satisfying the balance (projection and Baumgarte's feedback change the energy too).
//!
//! A run that fails (an integrator error, a solver failure in coordinate partitioning, a
//! non-finite state from an unstable step) is recorded as failed with its message.

use std::path::Path;

use rbss_runtime::{
    Baumgarte, Data, Dynamics, IntegrateOptions, Method, Model, Stabilization, Structure,
    gear_ratio,
};

use crate::robot_arg::RobotArg;
use crate::trajectory::{SimState, Trajectory};

/// `rbss bench ...`.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCmd {
    /// Work-precision diagram of a robot's round trip: every stabilisation (none, baumgarte,
    /// projection, partitioning) with fixed-step RK4 over a sweep of steps and DOPRI5 and
    /// DOP853 over a sweep of tolerances; writes DIR/work_precision.csv and
    /// DIR/work_precision.png and prints the Pareto front (runs not dominated in error and
    /// time).
    WorkPrecision {
        #[command(flatten)]
        robot: RobotArg,
        /// Trajectory of the outputs (.toml expressions or .csv samples); default: TraekP for
        /// `--model stewart_6ups` (the paper's), else models/trajectories/NAME.toml.
        #[arg(long)]
        trajectory: Option<String>,
        /// Output directory.
        #[arg(long, value_parser = crate::output_path)]
        out: String,
        /// Timed repeats per run; the median is reported.
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// A reduced sweep (two steps, two tolerances) for CI.
        #[arg(long)]
        quick: bool,
    },
    /// Every solver call timed beside the generated kernels it calls, in one run: writes
    /// DIR/solvers.csv (`solver,ns_per_call,kernels_ns,ratio,kernel_calls`) and prints the
    /// table. `ratio = ns_per_call / kernels_ns`; see `src/solver_table.rs` for the method.
    Solvers {
        #[command(flatten)]
        robot: RobotArg,
        /// Output directory.
        #[arg(long, value_parser = crate::output_path)]
        out: String,
        /// Timed batches (~1 ms each) per measurement; the median is reported.
        #[arg(long, default_value_t = 31)]
        batches: usize,
    },
}

impl BenchCmd {
    /// The robot it runs on (`--model` or `--model-file`).
    pub fn robot(&self) -> &RobotArg {
        match self {
            BenchCmd::WorkPrecision { robot, .. } | BenchCmd::Solvers { robot, .. } => robot,
        }
    }
}

/// Runs a `rbss bench` subcommand on `model` (the robot its `--model` or `--model-file` names:
/// [`crate::cli::run_with_model`]), printing to stdout (results) and stderr (progress).
pub fn command<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(
    cmd: BenchCmd,
    model: &Model<K, N, M>,
) -> Result<(), String> {
    match cmd {
        BenchCmd::WorkPrecision {
            robot,
            trajectory,
            out,
            repeats,
            quick,
        } => {
            if repeats == 0 {
                return Err("--repeats must be at least 1".into());
            }
            let opts = WorkPrecisionOptions {
                repeats,
                quick,
                ..Default::default()
            };
            let s = model.structure();
            // The paper's run: TraekP, exactly as before there were trajectory files.
            let paper = robot.model_file.is_none()
                && trajectory.is_none()
                && s.name == "stewart_6ups"
                && crate::trajectory::output_names(s) == ["x", "y", "z", "rotx", "roty", "rotz"];
            let traek = crate::paper::TraekP { omega: opts.omega };
            let loaded;
            let reference = if paper {
                Reference {
                    trajectory: &traek,
                    label: "TraekP".to_string(),
                    t0: 0.0,
                    t1: opts.t_end,
                    units: [OutputUnit::Length; 3]
                        .into_iter()
                        .chain([OutputUnit::Angle; 3])
                        .collect(),
                }
            } else {
                let file = match &trajectory {
                    Some(f) => std::path::PathBuf::from(f),
                    None => crate::roundtrip::default_trajectory(s)?,
                };
                loaded = crate::trajectory::load(&file, &crate::trajectory::output_names(s))?;
                let (t0, t1) = crate::roundtrip::time_span(loaded.as_ref(), None)?;
                let model_path = match &robot.model_file {
                    Some(p) => std::path::PathBuf::from(p),
                    None => Path::new(env!("CARGO_MANIFEST_DIR"))
                        .join("models")
                        .join(format!("{}.toml", s.name)),
                };
                Reference {
                    trajectory: loaded.as_ref(),
                    label: file.display().to_string(),
                    t0,
                    t1,
                    units: output_units(&model_path, s),
                }
            };
            let runs = work_precision(model, &reference, Path::new(&out), &opts, &mut |m| {
                crate::errln!("rbss: {m}")
            })?;
            print_summary(model.structure().name, &runs);
            crate::outln!("wrote {out}/work_precision.csv and {out}/work_precision.png");
            Ok(())
        }
        BenchCmd::Solvers { out, batches, .. } => {
            crate::solver_table::command(model, Path::new(&out), batches)
        }
    }
}

/// The unit of an output coordinate, from its model file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputUnit {
    /// `unit = "m"`: a translation.
    Length,
    /// `unit = "rad"` or `"deg"`: a rotation.
    Angle,
    /// Not listed in the model file (an imported model), or the file cannot be read.
    Unknown,
}

/// The units of the robot's outputs (in `Structure::outputs` order) from the `coordinates`
/// of its model file; `Unknown` where the file does not give them.
pub fn output_units(model_file: &Path, s: &Structure) -> Vec<OutputUnit> {
    use toml::de::{DeTable, DeValue};
    let mut by_name = std::collections::BTreeMap::new();
    if let Ok(text) = std::fs::read_to_string(model_file)
        && let Ok(doc) = DeTable::parse(&text)
    {
        let coordinates = doc
            .get_ref()
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == "coordinates")
            .map(|(_, v)| v.get_ref());
        if let Some(DeValue::Array(list)) = coordinates {
            for c in list {
                let field = |k: &str| c.get_ref().get(k).and_then(|v| v.get_ref().as_str());
                if let (Some(name), Some(unit)) = (field("name"), field("unit")) {
                    let unit = match unit {
                        "m" => OutputUnit::Length,
                        "rad" | "deg" => OutputUnit::Angle,
                        _ => OutputUnit::Unknown,
                    };
                    by_name.insert(name.to_string(), unit);
                }
            }
        }
    }
    crate::trajectory::output_names(s)
        .iter()
        .map(|n| by_name.get(*n).copied().unwrap_or(OutputUnit::Unknown))
        .collect()
}

/// What a sweep measures against: the outputs' trajectory over `[t0, t1]`, and the outputs'
/// units.
pub struct Reference<'t> {
    pub trajectory: &'t dyn Trajectory,
    /// Its name in the figure (`TraekP`, the file).
    pub label: String,
    pub t0: f64,
    pub t1: f64,
    pub units: Vec<OutputUnit>,
}

/// Settings of the work-precision sweep.
#[derive(Debug, Clone)]
pub struct WorkPrecisionOptions {
    pub omega: f64,
    pub t_end: f64,
    pub repeats: usize,
    pub quick: bool,
}

impl Default for WorkPrecisionOptions {
    fn default() -> Self {
        WorkPrecisionOptions {
            omega: crate::paper::OMEGA,
            t_end: crate::paper::T_END,
            repeats: 3,
            quick: false,
        }
    }
}

/// The stabilisations, by their `--stabilization` names.
pub const STABILIZATIONS: [&str; 4] = ["none", "baumgarte", "projection", "partitioning"];

fn stabilization(name: &str) -> Stabilization {
    match name {
        "none" => Stabilization::None,
        "baumgarte" => Stabilization::baumgarte(),
        "projection" => Stabilization::Projection,
        _ => Stabilization::CoordinatePartitioning,
    }
}

/// The integrators of the sweep, by their `--method` names.
pub const METHODS: [&str; 3] = ["rk4", "dopri5", "dop853"];

/// RK4 steps (s) and the relative tolerances of DOPRI5 and DOP853 (atol = rtol / 100, as
/// `rbss paper`).
pub fn sweep(quick: bool) -> (Vec<f64>, Vec<f64>) {
    if quick {
        (vec![5e-3, 1e-3], vec![1e-5, 1e-8])
    } else {
        (
            vec![1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4],
            (4..=14).map(|k| 10f64.powi(-k)).collect(),
        )
    }
}

/// One run's figures.
#[derive(Debug, Clone)]
pub struct Measured {
    /// Median, smallest and largest wall time of the integration over the repeats (s).
    pub time_s: f64,
    pub time_min_s: f64,
    pub time_max_s: f64,
    pub stats: rbss_runtime::IntegrateStats,
    /// Max |output - trajectory| over the outputs (m or rad each).
    pub output_error: f64,
    /// The same over the outputs that are translations (m), if any.
    pub position_error: Option<f64>,
    /// The same over the outputs that are rotations (rad), if any.
    pub rotation_error: Option<f64>,
    /// `max_t |E(t) - E(0) - W(t)|` (J).
    pub energy_error: f64,
    /// `max_t |E(t) - E(0)|` (J): the scale of the balance.
    pub energy_swing: f64,
}

impl Measured {
    /// The precision axis: the position error, else (no translation among the outputs, or
    /// units unknown) the outputs' error.
    pub fn error(&self) -> f64 {
        self.position_error.unwrap_or(self.output_error)
    }
}

/// One point of the sweep.
#[derive(Debug, Clone)]
pub struct Run {
    /// `rk4`, `dopri5` or `dop853`.
    pub method: &'static str,
    pub stabilization: &'static str,
    /// The step (RK4, s) or the relative tolerance (DOPRI5, DOP853).
    pub parameter: f64,
    pub outcome: Result<Measured, String>,
}

impl Run {
    /// `rk4 dt=1e-3`, `dopri5 rtol=1e-8` or `dop853 rtol=1e-8`.
    pub fn setting(&self) -> String {
        match self.method {
            "rk4" => format!("rk4 dt={:e}", self.parameter),
            m => format!("{m} rtol={:e}", self.parameter),
        }
    }
}

/// Runs the sweep of `model` along `reference`, writes `out/work_precision.csv` and
/// `out/work_precision.png`.
pub fn work_precision<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    reference: &Reference<'_>,
    out: &Path,
    opts: &WorkPrecisionOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Run>, String> {
    crate::create_output_dir(out)?;
    let s = model.structure();
    if reference.trajectory.dim() != s.outputs.len() || reference.units.len() != s.outputs.len() {
        return Err(format!(
            "{} moves {} coordinates, `{}` has {} outputs",
            reference.trajectory.describe(),
            reference.trajectory.dim(),
            s.name,
            s.outputs.len()
        ));
    }
    // The start: the trajectory's state at t0 (inverse kinematics and velocity).
    let start = {
        let k = s.outputs.len();
        let (mut p, mut v, mut a) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
        reference
            .trajectory
            .eval(reference.t0, &mut p, &mut v, &mut a);
        let mut d = Data::new(model);
        rbss_runtime::inverse_kinematics(model, &mut d, &p).map_err(|e| {
            format!(
                "t = {}: inverse kinematics: {e}",
                rbss_runtime::integrate::Time(reference.t0)
            )
        })?;
        rbss_runtime::inverse_velocity(model, &mut d, &v).map_err(|e| {
            format!(
                "t = {}: inverse velocity: {e}",
                rbss_runtime::integrate::Time(reference.t0)
            )
        })?;
        (d.x, d.xdot)
    };

    let (steps, tols) = sweep(opts.quick);
    let mut plan: Vec<(&'static str, &'static str, f64, Method)> = Vec::new();
    for stab in STABILIZATIONS {
        for &dt in &steps {
            plan.push(("rk4", stab, dt, Method::Rk4 { dt }));
        }
        for &rtol in &tols {
            plan.push(("dopri5", stab, rtol, Method::dopri5(rtol, rtol / 100.0)));
        }
        for &rtol in &tols {
            plan.push(("dop853", stab, rtol, Method::dop853(rtol, rtol / 100.0)));
        }
    }
    progress(&format!(
        "work-precision: {} round trip over [{}, {}] s, {} runs x {} repeats",
        s.name,
        reference.t0,
        reference.t1,
        plan.len(),
        opts.repeats
    ));
    let mut runs = Vec::with_capacity(plan.len());
    for (i, &(method, stab, parameter, m)) in plan.iter().enumerate() {
        let options = IntegrateOptions::new(m, stabilization(stab));
        let outcome = measure(model, reference, &start, opts.repeats, options);
        let run = Run {
            method,
            stabilization: stab,
            parameter,
            outcome,
        };
        let line = match &run.outcome {
            Ok(r) => format!(
                "error {:.3e}{}, {:.4} s, {} rhs, {} steps ({} rejected), violation {:.1e} m, energy {:.1e} J",
                r.error(),
                if r.position_error.is_some() { " m" } else { "" },
                r.time_s,
                r.stats.rhs_evaluations,
                r.stats.steps,
                r.stats.rejected,
                r.stats.max_violation,
                r.energy_error
            ),
            Err(e) => format!("FAILED: {e}"),
        };
        progress(&format!(
            "[{:>2}/{}] {:<18} {:<12} {line}",
            i + 1,
            plan.len(),
            run.setting(),
            stab
        ));
        runs.push(run);
    }
    // The CSV and the figure together, or neither.
    let mut files = crate::output::Outputs::new();
    write_csv(&mut files, &out.join("work_precision.csv"), &runs)?;
    plot(
        &mut files,
        &out.join("work_precision.png"),
        &runs,
        s.name,
        reference,
        opts,
    )?;
    files.commit()?;
    Ok(runs)
}

/// One run: `repeats` timed integrations, then the errors of the first one's states.
fn measure<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    reference: &Reference<'_>,
    start: &([f64; N], [f64; N]),
    repeats: usize,
    options: IntegrateOptions,
) -> Result<Measured, String> {
    let mut times = Vec::with_capacity(repeats);
    let mut first = None;
    for _ in 0..repeats {
        let sim = crate::trajectory::integrate(
            model,
            reference.trajectory,
            reference.t0,
            &start.0,
            &start.1,
            reference.t1,
            options,
            false,
        )?;
        times.push(sim.secs);
        if first.is_none() {
            first = Some(sim);
        }
    }
    let sim = first.ok_or("no repeat")?;
    times.sort_by(f64::total_cmp);
    let errors =
        crate::trajectory::output_errors(model.structure(), reference.trajectory, &sim.states);
    let max_of = |unit: OutputUnit| {
        errors
            .iter()
            .zip(&reference.units)
            .filter(|(_, u)| **u == unit)
            .map(|(e, _)| *e)
            .reduce(f64::max)
    };
    let (energy_error, energy_swing) = energy_balance(model, &sim.states, reference.trajectory)?;
    Ok(Measured {
        time_s: times[times.len() / 2],
        time_min_s: times[0],
        time_max_s: times[times.len() - 1],
        stats: sim.stats,
        output_error: errors.iter().copied().fold(0.0, f64::max),
        position_error: max_of(OutputUnit::Length),
        rotation_error: max_of(OutputUnit::Angle),
        energy_error,
        energy_swing,
    })
}

/// 4-point Gauss–Legendre nodes on [0, 1] and their weights.
fn gauss4() -> ([f64; 4], [f64; 4]) {
    let a = (3.0 / 7.0 - 2.0 / 7.0 * (6.0_f64 / 5.0).sqrt()).sqrt();
    let b = (3.0 / 7.0 + 2.0 / 7.0 * (6.0_f64 / 5.0).sqrt()).sqrt();
    let wa = (18.0 + 30.0_f64.sqrt()) / 36.0;
    let wb = (18.0 - 30.0_f64.sqrt()) / 36.0;
    let x = [-b, -a, a, b].map(|x| 0.5 * (1.0 + x));
    let w = [wb, wa, wa, wb].map(|w| 0.5 * w);
    (x, w)
}

/// `dq/dt` at `s` in [0, 1] of the quintic Hermite interpolant on a step of length `h` with
/// values, rates and accelerations `(q0, v0, a0)`, `(q1, v1, a1)` at its ends.
pub fn hermite5_rate(h: f64, q: [f64; 2], v: [f64; 2], a: [f64; 2], s: f64) -> f64 {
    // p(s) = c0 + c1 s + ... + c5 s⁵ in the scaled variable s = (t - t0) / h.
    let (c1, c2) = (h * v[0], 0.5 * h * h * a[0]);
    let r0 = q[1] - q[0] - c1 - c2;
    let r1 = h * v[1] - c1 - 2.0 * c2;
    let r2 = h * h * a[1] - 2.0 * c2;
    let c3 = 10.0 * r0 - 4.0 * r1 + 0.5 * r2;
    let c4 = -15.0 * r0 + 7.0 * r1 - r2;
    let c5 = 6.0 * r0 - 3.0 * r1 + 0.5 * r2;
    (c1 + s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)))) / h
}

/// The work-energy balance of a simulated motion: `(max_t |E(t) - E(0) - W(t)|, max_t |E(t) -
/// E(0)|)` over the states, with `E = T + Pi` and `W(t) = ∫₀ᵗ U · q̇ dt` (see the module
/// documentation); the control follows `trajectory`.
pub fn energy_balance<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    states: &[SimState<N>],
    trajectory: &dyn Trajectory,
) -> Result<(f64, f64), String> {
    let act = model.structure().actuated;
    let n_act = act.len();
    let mut control = crate::trajectory::control(model, trajectory, &states[0].x);
    let mut data = Data::new(model);
    let mut u = [0.0; N];
    // q̈ at every state: forward dynamics under U(t) (without Baumgarte's feedback).
    let mut acc = Vec::with_capacity(states.len());
    for s in states {
        control(s.t, &s.x, &s.xdot, &mut u[..n_act])
            .map_err(|e| format!("t = {}: control: {e}", rbss_runtime::integrate::Time(s.t)))?;
        data.x = s.x;
        data.xdot = s.xdot;
        rbss_runtime::forward_dynamics(model, &mut data, &u[..n_act], None, Baumgarte::NONE)
            .map_err(|e| {
                format!(
                    "t = {}: forward dynamics: {e}",
                    rbss_runtime::integrate::Time(s.t)
                )
            })?;
        acc.push(data.xddot);
    }
    let energy = |s: &SimState<N>| {
        let mut e = [0.0; 2];
        model.kernels().energy(&s.x, &s.xdot, &mut e);
        e[0] + e[1]
    };
    let (nodes, weights) = gauss4();
    let e0 = energy(&states[0]);
    let (mut work, mut worst, mut swing) = (0.0, 0.0_f64, 0.0_f64);
    for k in 0..states.len().saturating_sub(1) {
        let (s0, s1) = (&states[k], &states[k + 1]);
        let h = s1.t - s0.t;
        if h > 0.0 {
            let mut step = 0.0;
            for (&node, &w) in nodes.iter().zip(&weights) {
                let t = s0.t + node * h;
                control(t, &s0.x, &s0.xdot, &mut u[..n_act]).map_err(|e| {
                    format!("t = {}: control: {e}", rbss_runtime::integrate::Time(t))
                })?;
                let mut power = 0.0;
                for (a, &j) in act.iter().enumerate() {
                    let rate = hermite5_rate(
                        h,
                        [s0.x[j], s1.x[j]],
                        [s0.xdot[j], s1.xdot[j]],
                        [acc[k][j], acc[k + 1][j]],
                        node,
                    );
                    power += gear_ratio(model.structure().gear, a) * u[a] * rate;
                }
                step += w * power;
            }
            work += h * step;
        }
        let change = energy(s1) - e0;
        swing = swing.max(change.abs());
        worst = worst.max((change - work).abs());
    }
    Ok((worst, swing))
}

/// Indices of the successful runs not dominated in (error, time) ([`Measured::error`]): no other run is
/// at least as good in both and better in one. Sorted by error, ascending.
pub fn pareto_front(runs: &[Run]) -> Vec<usize> {
    let ok: Vec<(usize, f64, f64)> = runs
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.outcome.as_ref().ok().map(|m| (i, m.error(), m.time_s)))
        .collect();
    let mut front: Vec<(usize, f64, f64)> = ok
        .iter()
        .filter(|&&(i, e, t)| {
            !ok.iter()
                .any(|&(j, e2, t2)| j != i && e2 <= e && t2 <= t && (e2 < e || t2 < t))
        })
        .copied()
        .collect();
    front.sort_by(|a, b| a.1.total_cmp(&b.1));
    front.into_iter().map(|(i, _, _)| i).collect()
}

fn print_summary(robot: &str, runs: &[Run]) {
    let failed = runs.iter().filter(|r| r.outcome.is_err()).count();
    crate::outln!(
        "rbss bench work-precision: {robot} round trip, {} runs ({} failed)",
        runs.len(),
        failed
    );
    for r in runs.iter().filter(|r| r.outcome.is_err()) {
        if let Err(e) = &r.outcome {
            crate::outln!("  failed: {} {}: {e}", r.setting(), r.stabilization);
        }
    }
    let ok = || runs.iter().filter_map(|r| r.outcome.as_ref().ok());
    // The columns: position [m] (else the outputs' error) and rotation [rad], as the robot has.
    let lengths = ok().any(|m| m.position_error.is_some());
    let angles = ok().any(|m| m.rotation_error.is_some());
    let opt = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.3e}"));
    crate::outln!("Pareto front (not dominated in error and time), by error:");
    crate::outln!(
        "  {:<20} {:<13} {:>11} {:>11} {:>10} {:>8} {:>7} {:>11} {:>10}",
        "setting",
        "stabilization",
        if lengths { "error [m]" } else { "error" },
        if angles { "rot. [rad]" } else { "" },
        "time [s]",
        "rhs",
        "steps",
        "violation",
        "energy [J]"
    );
    for i in pareto_front(runs) {
        let r = &runs[i];
        if let Ok(m) = &r.outcome {
            crate::outln!(
                "  {:<20} {:<13} {:>11.3e} {:>11} {:>10.4} {:>8} {:>7} {:>11.2e} {:>10.2e}",
                r.setting(),
                r.stabilization,
                m.error(),
                if angles {
                    opt(m.rotation_error)
                } else {
                    String::new()
                },
                m.time_s,
                m.stats.rhs_evaluations,
                m.stats.steps,
                m.stats.max_violation,
                m.energy_error
            );
        }
    }
}

/// The CSV: one row per run; failed runs keep their message in `error` and leave the figures
/// empty.
pub const CSV_HEADER: &str = "method,stabilization,parameter,status,time_s,time_min_s,time_max_s,\
rhs_evaluations,steps,rejected,newton_iterations,position_error_m,rotation_error_rad,\
max_violation_m,max_velocity_violation,energy_error_j,energy_swing_j,output_error,error";

fn write_csv(files: &mut crate::output::Outputs, path: &Path, runs: &[Run]) -> Result<(), String> {
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:?}"));
    for r in runs {
        let head = format!("{},{},{:e}", r.method, r.stabilization, r.parameter);
        let row = match &r.outcome {
            Ok(m) => format!(
                "{head},ok,{:?},{:?},{:?},{},{},{},{},{},{},{:?},{:?},{:?},{:?},{:?},",
                m.time_s,
                m.time_min_s,
                m.time_max_s,
                m.stats.rhs_evaluations,
                m.stats.steps,
                m.stats.rejected,
                m.stats.newton_iterations,
                opt(m.position_error),
                opt(m.rotation_error),
                m.stats.max_violation,
                m.stats.max_velocity_violation,
                m.energy_error,
                m.energy_swing,
                m.output_error
            ),
            Err(e) => format!(
                "{head},failed{}\"{}\"",
                ",".repeat(CSV_HEADER.split(',').count() - 4),
                e.replace('"', "'").replace('\n', " ")
            ),
        };
        text.push_str(&row);
        text.push('\n');
    }
    std::io::Write::write_all(&mut files.create(path)?, text.as_bytes())
        .map_err(|e| format!("{}: cannot write: {e}", path.display()))
}

fn plot(
    files: &mut crate::output::Outputs,
    path: &Path,
    runs: &[Run],
    robot: &str,
    reference: &Reference<'_>,
    opts: &WorkPrecisionOptions,
) -> Result<(), String> {
    use crate::plot::{Panel, Series, write_png_to};
    let ok = |method: &'static str, stab: &'static str| {
        runs.iter()
            .filter(move |r| r.method == method && r.stabilization == stab)
            .filter_map(|r| r.outcome.as_ref().ok().map(|m| (r.parameter, m)))
    };
    let all = || runs.iter().filter_map(|r| r.outcome.as_ref().ok());
    let (lengths, angles) = (
        all().any(|m| m.position_error.is_some()),
        all().any(|m| m.rotation_error.is_some()),
    );
    // The axes' names: the paper's platform, or the robot's outputs.
    let whose = if reference.label == "TraekP" {
        "platform "
    } else {
        "outputs' "
    };
    let axis =
        |what: &str, unit: &str| format!("max {whose}{what} error vs {} [{unit}]", reference.label);
    let (main_title, main_label) = if lengths {
        ("position", axis("position", "m"))
    } else {
        ("outputs", axis("", "m or rad").replace("  ", " "))
    };
    // Work-precision: error against wall time, one curve per integrator and stabilisation, for
    // the position and the rotation of the platform (the robot's outputs).
    let work = |title: &str, label: &str, err: &dyn Fn(&Measured) -> Option<f64>| {
        let mut panel = Panel::new(title, label, "integration wall time [s]")
            .log_x()
            .log_y();
        for method in METHODS {
            for stab in STABILIZATIONS {
                let (x, y): (Vec<f64>, Vec<f64>) = ok(method, stab)
                    .filter_map(|(_, m)| err(m).map(|e| (e, m.time_s)))
                    .unzip();
                if !x.is_empty() {
                    panel = panel.with(Series::new(format!("{method} {stab}"), x, y).markers());
                }
            }
        }
        panel
    };
    let position = work(
        &format!(
            "{main_title}: one curve per integrator and stabilisation (RK4: dt; DOPRI5, DOP853: \
             rtol)"
        ),
        &main_label,
        &|m| Some(m.error()),
    );
    let rotation = if angles {
        work("rotation: the same runs", &axis("rotation", "rad"), &|m| {
            m.rotation_error
        })
    } else {
        work(
            "every output: the same runs",
            &axis("", "m or rad").replace("  ", " "),
            &|m| Some(m.output_error),
        )
    };
    // Convergence without stabilisation: error against the step of RK4 (with the slope of a
    // fourth-order method through its largest step) and against right-hand-side evaluations.
    let mut by_dt = Panel::new(
        "RK4 (no stabilisation): error against the step",
        "step dt [s]",
        format!("max error vs {} [m, rad]", reference.label),
    )
    .log_x()
    .log_y();
    let rk4: Vec<(f64, &Measured)> = ok("rk4", "none").collect();
    let (dts, ep): (Vec<f64>, Vec<f64>) = rk4.iter().map(|(d, m)| (*d, m.error())).unzip();
    if let (Some(&d0), Some(&e0)) = (dts.first(), ep.first()) {
        let slope: Vec<f64> = dts.iter().map(|d| e0 * (d / d0).powi(4)).collect();
        by_dt = by_dt.with(
            Series::new(
                if lengths { "position [m]" } else { "outputs" },
                dts.clone(),
                ep,
            )
            .markers(),
        );
        if angles {
            let er: Vec<f64> = rk4
                .iter()
                .map(|(_, m)| m.rotation_error.unwrap_or(f64::NAN))
                .collect();
            by_dt = by_dt.with(Series::new("rotation [rad]", dts.clone(), er).markers());
        }
        by_dt = by_dt.with(Series::new("dt^4 through the first point", dts, slope).reference());
    }
    let mut by_rhs = Panel::new(
        format!("no stabilisation: {main_title} error against right-hand sides"),
        "right-hand-side evaluations",
        main_label.clone(),
    )
    .log_x()
    .log_y();
    for method in METHODS {
        let (x, y): (Vec<f64>, Vec<f64>) = ok(method, "none")
            .map(|(_, m)| (m.stats.rhs_evaluations as f64, m.error()))
            .unzip();
        if !x.is_empty() {
            by_rhs = by_rhs.with(Series::new(method, x, y).markers());
        }
    }
    write_png_to(
        files,
        path,
        &format!(
            "Work-precision: {robot} round trip over [{}, {}] s (time: median of {} repeats)",
            reference.t0, reference.t1, opts.repeats
        ),
        &[position, rotation, by_dt, by_rhs],
        2,
        1800,
        1400,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_rate_is_exact_for_quintics() {
        let p =
            |t: f64| 1.0 + 2.0 * t - t * t + 0.5 * t.powi(3) - 0.3 * t.powi(4) + 0.1 * t.powi(5);
        let v = |t: f64| 2.0 - 2.0 * t + 1.5 * t * t - 1.2 * t.powi(3) + 0.5 * t.powi(4);
        let a = |t: f64| -2.0 + 3.0 * t - 3.6 * t * t + 2.0 * t.powi(3);
        let (t0, h) = (0.3, 0.7);
        for s in [0.0, 0.2, 0.5, 0.9, 1.0] {
            let got = hermite5_rate(
                h,
                [p(t0), p(t0 + h)],
                [v(t0), v(t0 + h)],
                [a(t0), a(t0 + h)],
                s,
            );
            assert!((got - v(t0 + s * h)).abs() < 1e-12, "s = {s}");
        }
    }

    #[test]
    fn gauss4_integrates_degree_7() {
        let (x, w) = gauss4();
        let sum: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(7)).sum();
        assert!((sum - 1.0 / 8.0).abs() < 1e-15);
    }

    /// A run that fails is an `Err` with the integrator's message, not a panic.
    #[test]
    fn a_failing_run_is_recorded() {
        use crate::robots::stewart_6ups;
        let model: crate::paper::Robot = Model::new(stewart_6ups::Stewart6Ups::default());
        let x = stewart_6ups::STRUCTURE.home.try_into().unwrap();
        let traek = crate::paper::TraekP {
            omega: crate::paper::OMEGA,
        };
        let reference = Reference {
            trajectory: &traek,
            label: "TraekP".into(),
            t0: 0.0,
            t1: 2.0,
            units: vec![OutputUnit::Length; 6],
        };
        let mut options = IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::None);
        options.max_steps = 3;
        let r = measure(&model, &reference, &(x, [0.0; 24]), 1, options);
        assert!(r.unwrap_err().contains("forward dynamics"));
    }

    #[test]
    fn csv_rows_have_the_header_fields() {
        let mut ok = run_with(1e-3, 1.0);
        ok.parameter = 2e-3;
        let failed = Run {
            outcome: Err("forward dynamics: t = 1: \"x\", y".into()),
            ..run_with(0.0, 0.0)
        };
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let path = dir.join("wp.csv");
        let mut files = crate::output::Outputs::new();
        write_csv(&mut files, &path, &[ok, failed]).unwrap();
        files.commit().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let fields = CSV_HEADER.split(',').count();
        for line in text.lines() {
            // Count the fields outside the quoted message.
            let mut n = 1;
            let mut quoted = false;
            for c in line.chars() {
                match c {
                    '"' => quoted = !quoted,
                    ',' if !quoted => n += 1,
                    _ => {}
                }
            }
            assert_eq!(n, fields, "{line}");
        }
        assert!(text.contains(",failed,"));
        assert!(text.contains("\"forward dynamics: t = 1: 'x', y\""));
    }

    fn run_with(e: f64, t: f64) -> Run {
        Run {
            method: "rk4",
            stabilization: "none",
            parameter: 0.0,
            outcome: Ok(Measured {
                time_s: t,
                time_min_s: t,
                time_max_s: t,
                stats: Default::default(),
                output_error: e,
                position_error: Some(e),
                rotation_error: Some(0.0),
                energy_error: 0.0,
                energy_swing: 0.0,
            }),
        }
    }

    #[test]
    fn pareto_front_drops_dominated_runs() {
        let run = run_with;
        let runs = vec![
            run(1e-3, 1.0),
            run(1e-6, 2.0),
            run(1e-5, 3.0),
            run(1e-2, 0.5),
        ];
        assert_eq!(pareto_front(&runs), vec![1, 0, 3]);
    }
}
