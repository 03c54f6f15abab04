//! A worked use of the manifold linearisation (issue 36, item 5): the 6-UPS tracks the paper's
//! platform motion `TraekP` from a perturbed start under a time-varying LQR.
//!
//! - The reference: inverse kinematics and inverse dynamics along TraekP at the knots
//!   `t_k = k dt` (`X_ref`, `Ẋ_ref`, `U_ref`), the paper's feed-forward.
//! - At every knot, [`linearize`] in the outputs' coordinates (the platform pose `y`, 6): the
//!   continuous `A` (12 × 12), `B` (12 × 6) of `d/dt [y; ẏ]` on the constraint manifold at the
//!   reference state and force.
//! - Discretisation: zero-order hold of the control over `[t_k, t_k+1)`, by the matrix
//!   exponential `exp([A B; 0 0] dt) = [A_d B_d; 0 I]` of `A`, `B` at `t_k` (the step's own
//!   Jacobians are not used).
//! - One backward Riccati pass over the horizon: `K_k = (R + B_dᵀ P B_d)⁻¹ B_dᵀ P A_d`,
//!   `P ← Q + A_dᵀ P (A_d - B_d K_k)`, `P_K = Q`.
//! - The closed loop on the real nonlinear closed-chain model: the runtime's `Simulator`
//!   (DOPRI5, projection onto the manifold) under `U(t) = U_ref(t) - K_k e_k`, where `U_ref(t)`
//!   is the exact feed-forward at every stage time (`rbss::paper::round_trip_control`) and
//!   `e_k = [y - y_ref; ẏ - ẏ_ref]` is sampled at `t_k` and held. Open loop: the same start
//!   under `U_ref(t)` alone.
//!
//! ```text
//! cargo run --release --example mpc_traekp -- --out docs
//! ```
//! prints the tracking errors and the timings and writes `mpc_traekp.png` (and
//! `mpc_traekp.csv`) to the directory. `--t-end T` and `--dt DT` change the horizon and the
//! knot spacing. tests/mpc_example.rs runs it on a short horizon.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::{SMatrix, SVector};
use rbss::paper::{self, OMEGA, Robot};
use rbss::plot::{Panel, Series, write_png};
use rbss::robots::stewart_6ups;
use rbss_runtime::{
    Coordinates, Data, IntegrateOptions, Linearization, Method, Model, Simulator, Stabilization,
    inverse_kinematics, inverse_velocity, linearize,
};

const N: usize = stewart_6ups::N;
const M: usize = stewart_6ups::M;
/// Independent coordinates (the platform pose) and control forces.
const D: usize = 6;
/// The error state `[y - y_ref; ẏ - ẏ_ref]`.
const NX: usize = 2 * D;

type MatX = SMatrix<f64, NX, NX>;
type MatB = SMatrix<f64, NX, D>;
type Gain = SMatrix<f64, D, NX>;
type VecX = SVector<f64, NX>;

/// The smallest `|e_k|` at which the one-step prediction is compared (see
/// [`Report::prediction_residual`]).
const PREDICTION_FLOOR: f64 = 1e-6;

/// The settings of a run.
#[derive(Debug, Clone)]
pub struct Options {
    /// The horizon (s); TraekP's period is 2 s.
    pub t_end: f64,
    /// Knot spacing: the controller's sampling period (s).
    pub dt: f64,
    /// The start's offset from TraekP at `t = 0`: `[dy (m, rad); dẏ (m/s, rad/s)]`.
    pub perturbation: [f64; NX],
    /// State weight on the position error (1/m²; rotations scaled by `length²`).
    pub q_position: f64,
    /// State weight on the velocity error (s²/m²; likewise).
    pub q_velocity: f64,
    /// The length (m) that turns a rotation into a displacement in the weights: the platform's
    /// joint radius `rp`.
    pub length: f64,
    /// Control weight (1/N²).
    pub r: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            t_end: paper::T_END,
            dt: 0.005,
            perturbation: [
                0.01, -0.01, 0.01, 0.02, -0.02, 0.02, 0.05, 0.05, -0.05, 0.1, 0.1, -0.1,
            ],
            q_position: 1e6,
            q_velocity: 1e3,
            length: 0.389,
            r: 1e-4,
        }
    }
}

/// The tracking error at one time: max |x, y, z - TraekP| (m), max |rotx, roty, rotz -
/// TraekP| (rad).
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    pub t: f64,
    pub position: f64,
    pub rotation: f64,
}

/// What a run measured.
#[derive(Debug, Clone)]
pub struct Report {
    /// Knots (the horizon's intervals).
    pub knots: usize,
    /// The closed loop's and the open loop's errors at every accepted step of the integrator.
    pub closed: Vec<Sample>,
    pub open: Vec<Sample>,
    /// The closed loop's error at the knots.
    pub closed_knots: Vec<Sample>,
    /// Wall time of one `linearize` call: mean and least over the knots (s).
    pub linearize_mean: f64,
    pub linearize_min: f64,
    /// Wall time of one zero-order hold (an 18 × 18 matrix exponential), mean (s).
    pub discretize_mean: f64,
    /// Wall time of the backward Riccati pass over the whole horizon (s), and per knot.
    pub riccati: f64,
    pub riccati_per_knot: f64,
    /// Largest one-step prediction residual of the discrete linear model along the closed
    /// loop, relative to the step's error change: `max_k |e_k+1 - (A_d e_k + B_d du_k)| / |e_k+1
    /// - e_k|` (Euclidean norms), over the knots where `|e_k| > 1e-6`.
    pub prediction_residual: f64,
    /// Largest feedback force `|K_k e_k|` (N).
    pub max_feedback: f64,
    /// Largest `|f(X)|` after a closed-loop step.
    pub max_violation: f64,
}

fn sample(t: f64, x: &[f64; N]) -> Sample {
    let (p, _, _) = paper::traek_p(t, OMEGA);
    let y = &x[18..24];
    let e = |r: std::ops::Range<usize>| r.map(|i| (y[i] - p[i]).abs()).fold(0.0, f64::max);
    Sample {
        t,
        position: e(0..3),
        rotation: e(3..6),
    }
}

/// The error state at `t`: `[y - y_ref; ẏ - ẏ_ref]`, `y` the outputs.
fn error_state(model: &Robot, t: f64, x: &[f64; N], xdot: &[f64; N]) -> VecX {
    let (p, v, _) = paper::traek_p(t, OMEGA);
    let out = model.structure().outputs;
    VecX::from_fn(|i, _| {
        if i < D {
            x[out[i]] - p[i]
        } else {
            xdot[out[i - D]] - v[i - D]
        }
    })
}

fn integrator() -> IntegrateOptions {
    IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::Projection)
}

/// Runs the example; writes `mpc_traekp.png` and `mpc_traekp.csv` to `out` if given.
pub fn run(opts: &Options, out: Option<&Path>) -> Result<Report, String> {
    if !(opts.dt > 0.0 && opts.t_end >= opts.dt && opts.t_end.is_finite()) {
        return Err(format!(
            "need 0 < dt <= t_end (dt = {}, t_end = {})",
            opts.dt, opts.t_end
        ));
    }
    let model: Robot = Model::new(stewart_6ups::Stewart6Ups::default());
    let knots = (opts.t_end / opts.dt).round() as usize;
    let times: Vec<f64> = (0..=knots).map(|k| k as f64 * opts.dt).collect();
    let traek = paper::TraekP { omega: OMEGA };

    // --- the reference: X_ref, Ẋ_ref, U_ref at the knots ---
    let (kin, _) = paper::inverse_kinematics_along(&model, &traek, &times)?;
    let forces = paper::inverse_dynamics_along(&model, &kin)?;

    // --- linearise and discretise at every knot ---
    let mut lin = Linearization::<N, M>::new();
    let mut data = Data::new(&model);
    let (mut a, mut b) = ([0.0; NX * NX], [0.0; NX * D]);
    let mut ad = Vec::with_capacity(knots);
    let mut bd = Vec::with_capacity(knots);
    let (mut lin_sum, mut lin_min, mut exp_sum) = (0.0, f64::INFINITY, 0.0);
    for k in 0..knots {
        data.x = kin[k].x;
        data.xdot = kin[k].xdot;
        let started = Instant::now();
        linearize(
            &model,
            &mut data,
            &mut lin,
            forces[k].u(),
            None,
            Coordinates::Outputs,
        )
        .map_err(|e| format!("t = {}: linearize: {e}", times[k]))?;
        let secs = started.elapsed().as_secs_f64();
        lin_sum += secs;
        lin_min = f64::min(lin_min, secs);
        lin.state_space(&mut a, &mut b)
            .map_err(|e| format!("state_space: {e}"))?;
        let started = Instant::now();
        // Zero-order hold: exp([A B; 0 0] dt) = [A_d B_d; 0 I].
        let mut aug = SMatrix::<f64, { NX + D }, { NX + D }>::zeros();
        for i in 0..NX {
            for j in 0..NX {
                aug[(i, j)] = a[i * NX + j] * opts.dt;
            }
            for j in 0..D {
                aug[(i, NX + j)] = b[i * D + j] * opts.dt;
            }
        }
        let e = aug.exp();
        ad.push(MatX::from_fn(|i, j| e[(i, j)]));
        bd.push(MatB::from_fn(|i, j| e[(i, NX + j)]));
        exp_sum += started.elapsed().as_secs_f64();
    }

    // --- the backward Riccati pass ---
    let l2 = opts.length * opts.length;
    let q = MatX::from_diagonal(&VecX::from_fn(|i, _| {
        let w = if i % D < 3 { 1.0 } else { l2 };
        w * if i < D {
            opts.q_position
        } else {
            opts.q_velocity
        }
    }));
    let r = SMatrix::<f64, D, D>::identity() * opts.r;
    let started = Instant::now();
    let mut gains = vec![Gain::zeros(); knots];
    let mut p = q;
    for k in (0..knots).rev() {
        let (a, b) = (&ad[k], &bd[k]);
        let pb = p * b;
        let s = r + b.transpose() * pb;
        let chol = s
            .cholesky()
            .ok_or_else(|| format!("t = {}: R + BᵀPB is not positive definite", times[k]))?;
        let gain = chol.solve(&(pb.transpose() * a));
        let next = q + a.transpose() * p * (a - b * gain);
        p = (next + next.transpose()) * 0.5;
        gains[k] = gain;
    }
    let riccati = started.elapsed().as_secs_f64();

    // --- the perturbed start, on the manifold ---
    let (p0, v0, _) = paper::traek_p(0.0, OMEGA);
    let pose: Vec<f64> = (0..D).map(|i| p0[i] + opts.perturbation[i]).collect();
    let rate: Vec<f64> = (0..D).map(|i| v0[i] + opts.perturbation[D + i]).collect();
    data.x = kin[0].x;
    inverse_kinematics(&model, &mut data, &pose).map_err(|e| format!("start: {e}"))?;
    inverse_velocity(&model, &mut data, &rate).map_err(|e| format!("start: {e}"))?;
    let (x0, xdot0) = (data.x, data.xdot);

    // --- closed loop: U_ref(t) - K_k e_k, e_k sampled at t_k and held ---
    let mut feed_forward = paper::round_trip_control(&model, OMEGA, &kin[0].x);
    let mut sim_data = Data::new(&model);
    let mut sim = Simulator::new(&model, &mut sim_data, 0.0, &x0, &xdot0, integrator())
        .map_err(|e| format!("closed loop: {e}"))?;
    let mut closed = vec![sample(0.0, &x0)];
    let mut closed_knots = vec![closed[0]];
    let (mut residual, mut max_feedback) = (0.0_f64, 0.0_f64);
    let mut rows = Vec::new();
    for k in 0..knots {
        let e = error_state(&model, times[k], sim.x(), sim.xdot());
        let du = -gains[k] * e;
        max_feedback = max_feedback.max(du.norm());
        let mut control = |t: f64,
                           x: &[f64; N],
                           xd: &[f64; N],
                           u: &mut [f64]|
         -> Result<(), rbss_runtime::SolverError> {
            feed_forward(t, x, xd, u)?;
            for (ui, d) in u.iter_mut().zip(du.iter()) {
                *ui += d;
            }
            Ok(())
        };
        sim.run(&model, &mut sim_data, times[k + 1], &mut control, |s| {
            closed.push(sample(s.t(), s.x()))
        })
        .map_err(|err| format!("closed loop, t = {}: {err}", times[k]))?;
        let next = error_state(&model, times[k + 1], sim.x(), sim.xdot());
        let predicted = ad[k] * e + bd[k] * du;
        let change = (next - e).norm();
        // Where the error is well above the integrator's tolerance (rtol 1e-10 on a state of
        // order 1): below it the residual measures the integration's noise, not the model.
        if e.norm() > PREDICTION_FLOOR && change > 0.0 {
            residual = residual.max((next - predicted).norm() / change);
        }
        closed_knots.push(sample(times[k + 1], sim.x()));
        let mut row = vec![times[k], e.norm()];
        row.extend(du.iter());
        rows.push(row);
    }
    let max_violation = sim.stats().max_violation;

    // --- open loop: the feed-forward alone ---
    let open_run = paper::integrate(
        &model,
        &x0,
        &xdot0,
        OMEGA,
        times[knots],
        integrator(),
        false,
    )?;
    let open: Vec<Sample> = open_run.states.iter().map(|s| sample(s.t, &s.x)).collect();

    let report = Report {
        knots,
        closed,
        open,
        closed_knots,
        linearize_mean: lin_sum / knots as f64,
        linearize_min: lin_min,
        discretize_mean: exp_sum / knots as f64,
        riccati,
        riccati_per_knot: riccati / knots as f64,
        prediction_residual: residual,
        max_feedback,
        max_violation,
    };
    if let Some(dir) = out {
        write_files(dir, &report, &rows)?;
    }
    Ok(report)
}

fn write_files(dir: &Path, report: &Report, rows: &[Vec<f64>]) -> Result<(), String> {
    rbss::create_output_dir(dir)?;
    // The position (0) or rotation (1) errors; on a log axis an exact zero is left out.
    let series = |s: &[Sample], which: usize| -> (Vec<f64>, Vec<f64>) {
        s.iter()
            .map(|p| (p.t, if which == 0 { p.position } else { p.rotation }))
            .filter(|&(_, e)| e > 0.0)
            .unzip()
    };
    let mut panels = Vec::new();
    for (which, what, unit) in [
        (0, "platform position error max |x, y, z - TraekP|", "m"),
        (
            1,
            "platform rotation error max |rotx, roty, rotz - TraekP|",
            "rad",
        ),
    ] {
        let (to, yo) = series(&report.open, which);
        let (tc, yc) = series(&report.closed, which);
        panels.push(
            Panel::new(what, "t [s]", unit)
                .log_y()
                .with(Series::new("feed-forward U_ref(t) only", to, yo).reference())
                .with(Series::new("time-varying LQR + feed-forward", tc, yc)),
        );
    }
    let mut pu = Panel::new("LQR feedback force -K_k e_k", "t [s]", "N");
    for i in 0..D {
        pu = pu.with(Series::new(
            format!("dU{}", i + 1),
            rows.iter().map(|r| r[0]).collect(),
            rows.iter().map(|r| r[2 + i]).collect(),
        ));
    }
    panels.push(pu);
    write_png(
        &dir.join("mpc_traekp.png"),
        &format!(
            "6-UPS tracking TraekP from a perturbed start: time-varying LQR on linearize's A, B \
             ({} knots, zero-order hold)",
            report.knots
        ),
        &panels,
        3,
        1800,
        560,
    )?;
    let mut header = vec!["t".to_string(), "error_norm".to_string()];
    header.extend(rbss::csv::numbered("dU", D));
    rbss::csv::write(&dir.join("mpc_traekp.csv"), &header, rows)
}

/// `args`: `--out DIR`, `--t-end T`, `--dt DT`.
fn main() {
    let mut opts = Options::default();
    let mut out: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .unwrap_or_else(|| fail(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--out" => out = Some(PathBuf::from(value())),
            "--t-end" => opts.t_end = number(&value()),
            "--dt" => opts.dt = number(&value()),
            _ => fail(&format!(
                "unknown argument {a} (--out DIR, --t-end T, --dt DT)"
            )),
        }
    }
    let rep = run(&opts, out.as_deref()).unwrap_or_else(|e| fail(&e));
    let at = |s: &[Sample], t: f64| {
        let i = s.partition_point(|p| p.t < t - 1e-12).min(s.len() - 1);
        s[i]
    };
    println!(
        "6-UPS along TraekP, {} knots of {} s, start perturbed by {:?}",
        rep.knots, opts.dt, opts.perturbation
    );
    println!(
        "| t (s) | closed loop: position (m) | rotation (rad) | open loop: position (m) | rotation (rad) |"
    );
    println!("|---|---|---|---|---|");
    let t_end = rep.knots as f64 * opts.dt;
    for f in [0.0, 0.1, 0.25, 0.5, 0.75, 1.0] {
        let (c, o) = (at(&rep.closed, f * t_end), at(&rep.open, f * t_end));
        println!(
            "| {:.3} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
            c.t, c.position, c.rotation, o.position, o.rotation
        );
    }
    println!(
        "linearize: {:.2} us mean, {:.2} us least; zero-order hold (expm 18x18): {:.2} us; \
         Riccati pass: {:.3} ms ({:.2} us per knot)",
        rep.linearize_mean * 1e6,
        rep.linearize_min * 1e6,
        rep.discretize_mean * 1e6,
        rep.riccati * 1e3,
        rep.riccati_per_knot * 1e6
    );
    println!(
        "one-step prediction residual of (A_d, B_d) along the closed loop: {:.2e} of the \
         step's change; largest feedback force {:.1} N; max |f(X)| {:.1e}",
        rep.prediction_residual, rep.max_feedback, rep.max_violation
    );
}

fn number(s: &str) -> f64 {
    s.parse()
        .unwrap_or_else(|_| fail(&format!("not a number: {s}")))
}

fn fail(msg: &str) -> ! {
    eprintln!("mpc_traekp: {msg}");
    std::process::exit(2)
}
