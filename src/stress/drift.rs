//! Long runs of the paper's 6-UPS under each constraint stabilisation (see `rbss stress drift`):
//! constraint and velocity violation, the work–energy balance, and the wall time.

use std::cell::Cell;
use std::time::Instant;

use crate::robots::stewart_6ups::{M, N, Stewart6Ups};
use rbss_runtime::{
    Data, Dynamics, IntegrateOptions, Kernels, Method, Model, Simulator, SolverError,
    Stabilization, inverse_acceleration, inverse_dynamics, inverse_kinematics, inverse_velocity,
};

use super::Robot;
use crate::paper::traek_p;

/// The period of TraekP (s): its components have angular frequencies `w, 2w, 3w, 4w`.
pub fn period(omega: f64) -> f64 {
    std::f64::consts::TAU / omega
}

/// Leg-length servo around the feed-forward forces: `U = U_ff(t) + kp (d_ref - d) +
/// kd (ḋ_ref - ḋ)` per leg. `kp = 2e4 N/m`, `kd = 2e3 N s/m` give a leg, whose effective mass is
/// about 45 kg (upper link 31 kg plus a share of the 74 kg platform), a natural frequency of
/// about 21 rad/s and a damping ratio of about 1: far inside RK4's stability region at
/// `dt = 1e-3` (`|lambda| dt` about 0.05).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Servo {
    pub kp: f64,
    pub kd: f64,
}

impl Servo {
    pub const DEFAULT: Servo = Servo { kp: 2e4, kd: 2e3 };
    pub const OFF: Servo = Servo { kp: 0.0, kd: 0.0 };
}

/// `(U_ff, d_ref, ḋ_ref)` at one time.
pub type RefSample = ([f64; 6], [f64; 6], [f64; 6]);

/// The control along TraekP, tabulated over one period at the RK4 stage times: `U_ff` from the
/// paper's inverse dynamics (IK, velocity, acceleration, inverse dynamics), `d_ref`, `ḋ_ref`.
/// Stage times `t_n`, `t_n + dt/2`, `t_n + dt` are multiples of `dt/2`, so the table holds the
/// exact values at every stage; another time falls back to the exact computation.
pub struct Reference {
    omega: f64,
    step: f64,
    u: Vec<[f64; 6]>,
    d: Vec<[f64; 6]>,
    ddot: Vec<[f64; 6]>,
    model: Robot,
    data: Data<N, M>,
    /// The largest kinetic energy along TraekP (J), over the table's times.
    pub t_max: f64,
}

impl Reference {
    pub fn new(omega: f64, dt: f64) -> Result<Self, String> {
        let model: Robot = Model::new(Stewart6Ups::default());
        let step = dt / 2.0;
        let n = (period(omega) / step).round() as usize;
        if n == 0 || ((n as f64) * step - period(omega)).abs() > 1e-9 {
            return Err(format!(
                "dt = {dt}: the period {} s is not a whole number of half steps",
                period(omega)
            ));
        }
        let mut r = Reference {
            omega,
            step,
            u: Vec::with_capacity(n),
            d: Vec::with_capacity(n),
            ddot: Vec::with_capacity(n),
            data: Data::new(&model),
            model,
            t_max: 0.0,
        };
        for k in 0..n {
            let (u, d, v) = r
                .exact(k as f64 * step)
                .map_err(|e| format!("reference at t = {}: {e}", k as f64 * step))?;
            r.u.push(u);
            r.d.push(d);
            r.ddot.push(v);
            let mut e = [0.0; 2];
            r.model.kernels().energy(&r.data.x, &r.data.xdot, &mut e);
            r.t_max = r.t_max.max(e[0]);
        }
        Ok(r)
    }

    /// `(U_ff, d_ref, ḋ_ref)` at `t` by inverse kinematics and dynamics (warm-started).
    fn exact(&mut self, t: f64) -> Result<RefSample, SolverError> {
        let (p, v, a) = traek_p(t, self.omega);
        inverse_kinematics(&self.model, &mut self.data, &p)?;
        inverse_velocity(&self.model, &mut self.data, &v)?;
        inverse_acceleration(&self.model, &mut self.data, &a)?;
        inverse_dynamics(&self.model, &mut self.data, None)?;
        let mut u = [0.0; 6];
        u.copy_from_slice(self.data.u());
        let d: [f64; 6] = std::array::from_fn(|i| self.data.x[i]);
        let dd: [f64; 6] = std::array::from_fn(|i| self.data.xdot[i]);
        Ok((u, d, dd))
    }

    /// `(U_ff, d_ref, ḋ_ref)` at `t`: the table entry when `t` is within a thousandth of a half
    /// step of the grid (the simulator's clock, a running sum of steps, drifts by rounding:
    /// 1.5e-8 s after 10^6 steps of 1e-3 s, 3e-5 half steps; the time is snapped to the grid, so
    /// the reference clock is exactly `n dt`), else the exact computation at `t`.
    pub fn at(&mut self, t: f64) -> Result<RefSample, SolverError> {
        let kf = t / self.step;
        let k = kf.round();
        if (kf - k).abs() <= 1e-3 {
            let i = (k as i64).rem_euclid(self.u.len() as i64) as usize;
            return Ok((self.u[i], self.d[i], self.ddot[i]));
        }
        self.exact(t)
    }

    /// The state of TraekP at `t = 0` (from inverse kinematics and velocity).
    pub fn start(&self) -> Result<([f64; N], [f64; N]), String> {
        let mut d = Data::new(&self.model);
        let (p, v, _) = traek_p(0.0, self.omega);
        inverse_kinematics(&self.model, &mut d, &p).map_err(|e| e.to_string())?;
        inverse_velocity(&self.model, &mut d, &v).map_err(|e| e.to_string())?;
        Ok((d.x, d.xdot))
    }
}

/// One recorded window of a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sample {
    /// End of the window (s).
    pub t: f64,
    /// `max |f(X)|` over the accepted states of the window (after the stabilisation acted).
    pub violation: f64,
    /// `max |G Ẋ|` likewise.
    pub velocity_violation: f64,
    /// The simulator's running `max |f|` before any projection, since the start.
    pub violation_before_projection: f64,
    /// `T + Pi` at the end of the window (J).
    pub energy: f64,
    /// The work of the control forces since the start, `∫ Uᵀ ḋ dt` (J), by the RK4 weights of
    /// the stage powers.
    pub work: f64,
    /// The work–energy balance `|E(t) - E(0) - W(t)|` at the window's end (J), `E = T + Pi`.
    pub balance: f64,
    /// `max |platform pose - TraekP|` over the window (m and rad).
    pub tracking: f64,
}

/// A whole run under one stabilisation.
#[derive(Debug, Clone)]
pub struct Run {
    pub stabilization: Stabilization,
    pub steps: usize,
    pub samples: Vec<Sample>,
    /// Wall time of the integration (s), monitoring included.
    pub secs: f64,
    pub stats: rbss_runtime::IntegrateStats,
    /// Set when the run stopped early.
    pub error: Option<String>,
    /// The largest kinetic energy along TraekP (J), the scale of the balance.
    pub t_max: f64,
}

pub fn name(s: Stabilization) -> &'static str {
    match s {
        Stabilization::None => "none",
        Stabilization::Baumgarte(_) => "baumgarte",
        Stabilization::Projection => "projection",
        Stabilization::CoordinatePartitioning => "partitioning",
    }
}

pub const STABILIZATIONS: [Stabilization; 4] = [
    Stabilization::None,
    Stabilization::Baumgarte(rbss_runtime::Baumgarte::DEFAULT),
    Stabilization::Projection,
    Stabilization::CoordinatePartitioning,
];

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// What [`run`] simulates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    pub stabilization: Stabilization,
    pub servo: Servo,
    /// RK4 step (s) and number of steps.
    pub dt: f64,
    pub steps: usize,
    /// Steps per recorded [`Sample`].
    pub window: usize,
    /// Stop (with `Run::error`) when the platform is farther than this from TraekP (m or rad).
    pub stop_tracking: f64,
}

/// Runs `o.steps` RK4 steps of `o.dt` along TraekP from its `t = 0` state, with `U` from
/// `reference` and the servo, recording a [`Sample`] every `o.window` steps; stops early (with
/// `Run::error`) when the platform is farther than `o.stop_tracking` from TraekP or a step fails.
pub fn run(
    reference: &mut Reference,
    o: &RunOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Run, String> {
    let RunOptions {
        stabilization,
        servo,
        dt,
        steps,
        window,
        stop_tracking,
    } = *o;
    let model: Robot = Model::new(Stewart6Ups::default());
    let k = *model.kernels();
    let (x0, v0) = reference.start()?;
    let mut options = IntegrateOptions::new(Method::Rk4 { dt }, stabilization);
    options.max_steps = steps.saturating_add(1);
    let mut data = Data::new(&model);
    let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &v0, options)
        .map_err(|e| format!("cannot start: {e}"))?;
    let omega = reference.omega;

    // Stage powers Uᵀ ḋ of the current step, in call order (RK4: t, t + h/2, t + h/2, t + h).
    let powers: [Cell<f64>; 4] = Default::default();
    let calls = Cell::new(0usize);
    let mut control = |t: f64, x: &[f64; N], xdot: &[f64; N], u: &mut [f64]| {
        let (uff, d, dd) = reference.at(t)?;
        let mut p = 0.0;
        for i in 0..6 {
            u[i] = uff[i] + servo.kp * (d[i] - x[i]) + servo.kd * (dd[i] - xdot[i]);
            p += u[i] * xdot[i];
        }
        let c = calls.get();
        if let Some(slot) = powers.get(c) {
            slot.set(p);
        }
        calls.set(c + 1);
        Ok(())
    };

    let energy = |x: &[f64; N], v: &[f64; N]| {
        let mut e = [0.0; 2];
        k.energy(x, v, &mut e);
        e
    };
    let e0 = energy(&x0, &v0);
    let e0 = e0[0] + e0[1];
    let mut work = 0.0;
    let t_end = steps as f64 * dt;
    let mut samples = Vec::with_capacity(steps / window.max(1) + 1);
    let mut cur = Sample::default();
    let mut f = [0.0; M];
    let mut g = [[0.0; M]; N];
    let mut error = None;
    let start = Instant::now();
    let mut next_note = 0.1;
    let mut t_prev = 0.0;
    for n in 1..=steps {
        calls.set(0);
        if let Err(e) = sim.step(&model, &mut data, t_end, &mut control) {
            error = Some(format!("step {n}: {e}"));
            break;
        }
        let p: [f64; 4] = std::array::from_fn(|i| powers[i].get());
        let h = sim.t() - t_prev;
        t_prev = sim.t();
        work += h / 6.0 * (p[0] + 2.0 * p[1] + 2.0 * p[2] + p[3]);
        let (x, v) = (sim.x(), sim.xdot());
        k.constraints(x, &mut f);
        k.jacobian(x, &mut g);
        let mut gv = [0.0; M];
        for (j, col) in g.iter().enumerate() {
            for (o, &gij) in gv.iter_mut().zip(col) {
                *o += gij * v[j];
            }
        }
        cur.violation = cur.violation.max(max_abs(&f));
        cur.velocity_violation = cur.velocity_violation.max(max_abs(&gv));
        // The reference clock is n dt: the control snaps the stage times to the table's grid,
        // while the simulator's t accumulates rounding (1.5e-8 s after 10^6 steps).
        let (pose, _, _) = traek_p(n as f64 * dt, omega);
        for i in 0..6 {
            cur.tracking = cur.tracking.max((x[18 + i] - pose[i]).abs());
        }
        if n % window.max(1) == 0 || n == steps {
            let e = energy(x, v);
            cur.t = sim.t();
            cur.energy = e[0] + e[1];
            cur.work = work;
            cur.balance = (cur.energy - e0 - work).abs();
            cur.violation_before_projection = sim.stats().max_violation;
            samples.push(cur);
            cur = Sample::default();
            if n as f64 >= next_note * steps as f64 {
                progress(&format!(
                    "  {}: t = {:.0} s, max |f| {:.2e}, balance {:.2e} J, {:.1} s",
                    name(stabilization),
                    sim.t(),
                    samples.last().map_or(0.0, |s| s.violation),
                    samples.last().map_or(0.0, |s| s.balance),
                    start.elapsed().as_secs_f64()
                ));
                next_note += 0.1;
            }
        }
        if cur.tracking > stop_tracking {
            error = Some(format!(
                "stopped at t = {} s: the platform is {:.3e} from TraekP",
                sim.t(),
                cur.tracking
            ));
            cur.t = sim.t();
            samples.push(cur);
            break;
        }
    }
    let secs = start.elapsed().as_secs_f64();
    Ok(Run {
        stabilization,
        steps: sim.stats().steps,
        samples,
        secs,
        stats: *sim.stats(),
        error,
        t_max: reference.t_max,
    })
}

/// `drift_<stabilisation>.csv`: one row per window.
pub fn write_csv(
    files: &mut crate::output::Outputs,
    file: &std::path::Path,
    r: &Run,
) -> Result<(), String> {
    let header: Vec<String> = [
        "t",
        "max_f",
        "max_G_xdot",
        "running_max_f_before_projection",
        "energy",
        "work",
        "balance",
        "tracking",
    ]
    .iter()
    .map(|h| h.to_string())
    .collect();
    let rows: Vec<Vec<f64>> = r
        .samples
        .iter()
        .map(|s| {
            vec![
                s.t,
                s.violation,
                s.velocity_violation,
                s.violation_before_projection,
                s.energy,
                s.work,
                s.balance,
                s.tracking,
            ]
        })
        .collect();
    crate::csv::write_to(files, file, &header, &rows)
}

/// Summary numbers of a run.
#[derive(Debug, Clone, Copy)]
pub struct Summary {
    pub max_violation: f64,
    pub final_violation: f64,
    pub max_velocity_violation: f64,
    pub max_balance: f64,
    pub max_tracking: f64,
    pub us_per_step: f64,
}

pub fn summary(r: &Run) -> Summary {
    let m = |f: &dyn Fn(&Sample) -> f64| r.samples.iter().map(f).fold(0.0, f64::max);
    Summary {
        max_violation: m(&|s| s.violation).max(r.stats.max_violation),
        final_violation: r.samples.last().map_or(f64::NAN, |s| s.violation),
        max_velocity_violation: m(&|s| s.velocity_violation),
        max_balance: m(&|s| s.balance),
        max_tracking: m(&|s| s.tracking),
        us_per_step: 1e6 * r.secs / r.steps.max(1) as f64,
    }
}

/// The Markdown table of the runs.
pub fn table(runs: &[Run]) -> String {
    let mut out = String::from(
        "| stabilisation | steps | wall [s] | µs/step | rhs evals | Newton its | max \\|f\\| (before projection) [m] | \\|f\\| at the end [m] | max \\|G Ẋ\\| [m/s] | max \\|E - E0 - W\\| [J] | (relative to max T) | max tracking error [m, rad] |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in runs {
        let s = summary(r);
        out.push_str(&format!(
            "| {} | {} | {:.1} | {:.1} | {} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.1e} | {:.2e} |\n",
            name(r.stabilization),
            r.steps,
            r.secs,
            s.us_per_step,
            r.stats.rhs_evaluations,
            r.stats.newton_iterations,
            s.max_violation,
            s.final_violation,
            s.max_velocity_violation,
            s.max_balance,
            s.max_balance / r.t_max,
            s.max_tracking,
        ));
    }
    out
}

/// `drift.png`: per window, `max |f|`, `max |G Ẋ|`, the work–energy balance and the tracking
/// error against time, log y, one curve per stabilisation.
pub fn plot(
    files: &mut crate::output::Outputs,
    file: &std::path::Path,
    runs: &[Run],
) -> Result<(), String> {
    use crate::plot::{Panel, Series, write_png_to};
    let mut panels = Vec::new();
    for (title, unit, f) in [
        (
            "constraint violation max |f(X)| per window (after the stabilisation)",
            "m",
            &(|s: &Sample| s.violation) as &dyn Fn(&Sample) -> f64,
        ),
        (
            "velocity violation max |G Ẋ| per window",
            "m/s",
            &|s: &Sample| s.velocity_violation,
        ),
        (
            "work–energy balance |T + Pi - E(0) - ∫ Uᵀ ḋ dt|",
            "J",
            &|s: &Sample| s.balance,
        ),
        (
            "tracking error max |pose - TraekP| per window",
            "m, rad",
            &|s: &Sample| s.tracking,
        ),
    ] {
        let mut p = Panel::new(title, "t [s]", unit).log_y();
        for r in runs {
            p = p.with(Series::new(
                name(r.stabilization),
                r.samples.iter().map(|s| s.t).collect(),
                r.samples.iter().map(f).collect(),
            ));
        }
        panels.push(p);
    }
    write_png_to(
        files,
        file,
        "rbss stress drift: RK4 along TraekP (feed-forward U + leg servo) under each stabilisation",
        &panels,
        2,
        1800,
        1000,
    )
}
