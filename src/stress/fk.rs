//! Forward-kinematics robustness of the paper's 6-UPS from perturbed starts (see
//! `rbss stress fk`): how often Newton (`forward_kinematics`) and Levenberg–Marquardt
//! (`forward_kinematics_lm`) converge, to which solution, in how many iterations.

use crate::robots::stewart_6ups;
use std::f64::consts::{PI, TAU};
use std::time::Instant;

use crate::robots::stewart_6ups::{N, Stewart6Ups};
use rbss_runtime::{
    Data, FkRobustError, LmOptions, Model, SolverError, SolverOptions, forward_kinematics,
    forward_kinematics_lm, inverse_kinematics,
};

use super::Robot;
use super::geometry::Geometry;

/// A small deterministic generator (xorshift64*).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in `[-1, 1)`.
    pub fn sym(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// The sampled workspace: uniform `x, y` in `±0.15 m`, `z` in `0.94 ± 0.14 m`, each rotation in
/// `±0.25 rad` (TraekP's envelope, `±0.1` m and rad around `z = 0.94`, enlarged), keeping only
/// poses whose `J_p` has a condition estimate below [`MAX_COND`] (clear of singularities) and
/// whose legs point up with `|phi_i|, |psi_i| < 1.2 rad`.
pub const HALF_WIDTHS: [f64; 6] = [0.15, 0.15, 0.14, 0.25, 0.25, 0.25];
pub const CENTRE: [f64; 6] = [0.0, 0.0, 0.94, 0.0, 0.0, 0.0];
pub const MAX_COND: f64 = 1e4;

/// Noise amplitudes: every passive coordinate of the start is the IK solution plus
/// `sigma * uniform(-1, 1)` (m for x, y, z; rad for the angles).
pub const SIGMAS: [f64; 6] = [0.01, 0.05, 0.1, 0.3, 0.6, 1.0];

/// The mode policy of the LM variant in this study: a passive coordinate may move at most
/// `POLICY_FACTOR * sigma` from the start (m or rad). The start's own solution is within `sigma`
/// of it in every coordinate (uniform noise), so the policy never rejects it; a universal-joint
/// branch flip moves `phi_i` by `pi`.
pub const POLICY_FACTOR: f64 = 2.0;

/// Where a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Outcome {
    /// The IK solution the start was made from (angles compared modulo 2 pi).
    Same,
    /// The same platform pose with some leg's universal joint on its other branch
    /// (`phi + pi, pi - psi`: the same leg axis, the lower link turned half a turn about it).
    Branch,
    /// A different platform pose: another assembly mode of the same `q`.
    OtherMode,
    /// LM's mode policy rejected a solution that moved more than [`POLICY_FACTOR`] `sigma`.
    Rejected,
    NotConverged,
    Singular,
    NonFinite,
    OtherError,
}

pub const OUTCOMES: [Outcome; 8] = [
    Outcome::Same,
    Outcome::Branch,
    Outcome::OtherMode,
    Outcome::Rejected,
    Outcome::NotConverged,
    Outcome::Singular,
    Outcome::NonFinite,
    Outcome::OtherError,
];

impl Outcome {
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Same => "same",
            Outcome::Branch => "U-branch",
            Outcome::OtherMode => "other mode",
            Outcome::Rejected => "rejected",
            Outcome::NotConverged => "NotConverged",
            Outcome::Singular => "Singular",
            Outcome::NonFinite => "NonFinite",
            Outcome::OtherError => "other error",
        }
    }
    pub fn converged(self) -> bool {
        matches!(self, Outcome::Same | Outcome::Branch | Outcome::OtherMode)
    }
}

/// The solvers compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// `forward_kinematics`: Newton with backtracking on `‖f‖`.
    Newton,
    /// `forward_kinematics_lm` with the default options (mode change reported, not rejected).
    Lm,
    /// `forward_kinematics_lm` with `max_passive_change = POLICY_FACTOR * sigma`.
    LmPolicy,
}

pub const SOLVERS: [Solver; 3] = [Solver::Newton, Solver::Lm, Solver::LmPolicy];

impl Solver {
    pub fn name(self) -> &'static str {
        match self {
            Solver::Newton => "Newton (forward_kinematics)",
            Solver::Lm => "LM (forward_kinematics_lm)",
            Solver::LmPolicy => "LM + mode policy (2 sigma)",
        }
    }
}

/// The tally of one solver at one noise level.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    pub count: usize,
    pub by_outcome: [usize; 8],
    /// Iterations of the converged solves (any solution).
    pub iterations: Vec<usize>,
    pub secs: f64,
}

impl Tally {
    pub fn rate(&self, o: Outcome) -> f64 {
        self.by_outcome[o as usize] as f64 / self.count.max(1) as f64
    }
    pub fn converged_rate(&self) -> f64 {
        OUTCOMES
            .iter()
            .filter(|o| o.converged())
            .map(|&o| self.rate(o))
            .sum()
    }
    /// The `q`-quantile of the iterations of converged solves.
    pub fn iteration_quantile(&self, q: f64) -> usize {
        let mut it = self.iterations.clone();
        it.sort_unstable();
        if it.is_empty() {
            return 0;
        }
        let k = ((it.len() - 1) as f64 * q).round() as usize;
        it[k.min(it.len() - 1)]
    }
}

/// The whole study: one tally per (noise level, solver).
#[derive(Debug, Clone)]
pub struct Study {
    pub sigmas: Vec<f64>,
    /// `tallies[level][solver]`.
    pub tallies: Vec<[Tally; 3]>,
    /// Poses drawn and poses kept (the others were near a singularity or had a leg too flat).
    pub poses_drawn: usize,
    pub poses_kept: usize,
}

fn wrap(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r <= -PI { r + TAU } else { r }
}

/// Classifies a converged `x` against the reference solution `x_ref` (same `q`).
pub fn classify(x: &[f64; N], x_ref: &[f64; N]) -> Outcome {
    let tol = 1e-6;
    // Platform position plain, rotations modulo 2 pi.
    let pose_same = (18..21).all(|j| (x[j] - x_ref[j]).abs() <= tol)
        && (21..24).all(|j| wrap(x[j] - x_ref[j]).abs() <= tol);
    if !pose_same {
        return Outcome::OtherMode;
    }
    if (6..18).all(|j| wrap(x[j] - x_ref[j]).abs() <= tol) {
        Outcome::Same
    } else {
        Outcome::Branch
    }
}

fn outcome_of_error(e: &SolverError) -> Outcome {
    match e {
        SolverError::NotConverged { .. } => Outcome::NotConverged,
        SolverError::Singular { .. } => Outcome::Singular,
        SolverError::NonFinite { .. } => Outcome::NonFinite,
        _ => Outcome::OtherError,
    }
}

/// A random reachable pose in the sampled workspace, with its IK solution, or `None` if the
/// drawn pose was rejected (near a singularity, a leg too flat, IK failed).
pub fn random_pose(
    model: &Robot,
    geo: &Geometry,
    data: &mut Data<N, { stewart_6ups::M }>,
    rng: &mut Rng,
) -> Option<[f64; N]> {
    let pose: [f64; 6] = std::array::from_fn(|i| CENTRE[i] + HALF_WIDTHS[i] * rng.sym());
    let closed = geo.x_of_pose(&pose);
    if (6..18).any(|j| closed[j].abs() >= 1.2) {
        return None;
    }
    data.set_home(model);
    inverse_kinematics(model, data, &pose).ok()?;
    let x = data.x;
    // IK from home lands on the closed-form assembly (legs up).
    if (0..N).any(|j| (x[j] - closed[j]).abs() > 1e-9) {
        return None;
    }
    // Regular: forward kinematics from the exact solution reports cond(J_p).
    let rep = forward_kinematics(model, data, &x[..6]).ok()?;
    (rep.cond <= MAX_COND).then_some(x)
}

/// Runs the study: `samples` starts in all, split evenly over the noise levels `sigmas`; each
/// start is solved by every solver of [`SOLVERS`].
pub fn study(samples: usize, sigmas: &[f64], seed: u64) -> Study {
    study_with(samples, sigmas, seed, &LmOptions::default())
}

/// [`study`] with other LM settings (`max_passive_change` is set per noise level).
pub fn study_with(samples: usize, sigmas: &[f64], seed: u64, lm: &LmOptions) -> Study {
    // `regular` selects on the exact cond(J_p), not forward kinematics' default bound.
    let model: Robot = Model::new(Stewart6Ups::default()).with_options(SolverOptions {
        exact_cond: true,
        ..SolverOptions::default()
    });
    let geo = Geometry::default();
    let mut rng = Rng::new(seed);
    let mut data = Data::new(&model);
    let levels = sigmas.len().max(1);
    let mut tallies: Vec<[Tally; 3]> = sigmas.iter().map(|_| Default::default()).collect();
    let (mut drawn, mut kept) = (0, 0);
    let lm = LmOptions {
        max_passive_change: f64::INFINITY,
        ..*lm
    };
    for (level, &sigma) in sigmas.iter().enumerate() {
        let lm_policy = LmOptions {
            max_passive_change: POLICY_FACTOR * sigma,
            ..lm
        };
        // `samples` in all: the first `samples % levels` levels take one more.
        let per_level = samples / levels + usize::from(level < samples % levels);
        let mut done = 0;
        while done < per_level {
            drawn += 1;
            let Some(x_ref) = random_pose(&model, &geo, &mut data, &mut rng) else {
                continue;
            };
            kept += 1;
            done += 1;
            let mut start = x_ref;
            for v in start.iter_mut().skip(6) {
                *v += sigma * rng.sym();
            }
            let q = &x_ref[..6];
            for (k, solver) in SOLVERS.iter().enumerate() {
                data.x = start;
                let t0 = Instant::now();
                let (outcome, iterations) = match solver {
                    Solver::Newton => match forward_kinematics(&model, &mut data, q) {
                        Ok(rep) => (classify(&data.x, &x_ref), Some(rep.iterations)),
                        Err(e) => (outcome_of_error(&e), None),
                    },
                    Solver::Lm | Solver::LmPolicy => {
                        let o = if *solver == Solver::Lm {
                            &lm
                        } else {
                            &lm_policy
                        };
                        match forward_kinematics_lm(&model, &mut data, q, o) {
                            Ok(rep) => (classify(&data.x, &x_ref), Some(rep.iterations)),
                            Err(FkRobustError::ModeChange { .. }) => (Outcome::Rejected, None),
                            Err(FkRobustError::Solver(e)) => (outcome_of_error(&e), None),
                        }
                    }
                };
                let t = &mut tallies[level][k];
                t.secs += t0.elapsed().as_secs_f64();
                t.count += 1;
                t.by_outcome[outcome as usize] += 1;
                if let Some(it) = iterations {
                    t.iterations.push(it);
                }
            }
        }
    }
    Study {
        sigmas: sigmas.to_vec(),
        tallies,
        poses_drawn: drawn,
        poses_kept: kept,
    }
}

fn pct(v: f64) -> String {
    format!("{:.1}%", 100.0 * v)
}

/// The rates table (Markdown).
pub fn rates_table(s: &Study) -> String {
    let mut out = String::new();
    out.push_str(&format!(
        "{} starts (about {} per noise level); poses: {} drawn, {} kept (regular, legs up)\n\n",
        s.tallies.iter().map(|t| t[0].count).sum::<usize>(),
        s.tallies.first().map_or(0, |t| t[0].count),
        s.poses_drawn,
        s.poses_kept
    ));
    out.push_str("| noise | solver | same | U-branch | other mode | rejected | NotConverged | Singular | NonFinite | iterations median / p95 / max | µs per solve |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (sigma, row) in s.sigmas.iter().zip(&s.tallies) {
        for (solver, t) in SOLVERS.iter().zip(row) {
            out.push_str(&format!(
                "| {sigma} | {} | {} | {} | {} | {} | {} | {} | {} | {} / {} / {} | {:.1} |\n",
                solver.name(),
                pct(t.rate(Outcome::Same)),
                pct(t.rate(Outcome::Branch)),
                pct(t.rate(Outcome::OtherMode)),
                pct(t.rate(Outcome::Rejected)),
                pct(t.rate(Outcome::NotConverged)),
                pct(t.rate(Outcome::Singular)),
                pct(t.rate(Outcome::NonFinite) + t.rate(Outcome::OtherError)),
                t.iteration_quantile(0.5),
                t.iteration_quantile(0.95),
                t.iterations.iter().max().copied().unwrap_or(0),
                1e6 * t.secs / t.count.max(1) as f64,
            ));
        }
    }
    out
}

/// Histogram bins of the iteration counts.
pub const BINS: [(usize, usize); 10] = [
    (0, 1),
    (2, 2),
    (3, 3),
    (4, 4),
    (5, 5),
    (6, 7),
    (8, 10),
    (11, 20),
    (21, 50),
    (51, usize::MAX),
];

/// The iteration histogram (Markdown), converged solves of each solver and noise level.
pub fn histogram_table(s: &Study) -> String {
    let mut out = String::from("| noise | solver |");
    for (lo, hi) in BINS {
        if hi == usize::MAX {
            out.push_str(&format!(" >{} |", lo - 1));
        } else if lo == hi {
            out.push_str(&format!(" {lo} |"));
        } else {
            out.push_str(&format!(" {lo}-{hi} |"));
        }
    }
    out.push('\n');
    out.push_str(&"|---".repeat(2 + BINS.len()));
    out.push_str("|\n");
    for (sigma, row) in s.sigmas.iter().zip(&s.tallies) {
        for (solver, t) in SOLVERS.iter().zip(row).take(2) {
            out.push_str(&format!("| {sigma} | {} |", solver.name()));
            for (lo, hi) in BINS {
                let n = t.iterations.iter().filter(|&&i| i >= lo && i <= hi).count();
                out.push_str(&format!(" {n} |"));
            }
            out.push('\n');
        }
    }
    out
}

/// `fk_rates.csv`: per noise level and solver (0 Newton, 1 LM, 2 LM + policy), the count, the
/// fraction of each outcome, the iteration median, p95 and max of the converged solves and the
/// mean time per solve (µs).
pub fn write_csv(
    files: &mut crate::output::Outputs,
    dir: &std::path::Path,
    s: &Study,
) -> Result<(), String> {
    let mut header: Vec<String> = vec!["sigma".into(), "solver".into(), "count".into()];
    header.extend(OUTCOMES.iter().map(|o| o.name().replace([' ', '-'], "_")));
    header.extend(
        [
            "iterations_median",
            "iterations_p95",
            "iterations_max",
            "us_per_solve",
        ]
        .iter()
        .map(|h| h.to_string()),
    );
    let mut rows = Vec::new();
    let mut hist_rows = Vec::new();
    for (sigma, row) in s.sigmas.iter().zip(&s.tallies) {
        for (k, t) in row.iter().enumerate() {
            let mut r = vec![*sigma, k as f64, t.count as f64];
            r.extend(OUTCOMES.iter().map(|&o| t.rate(o)));
            r.extend_from_slice(&[
                t.iteration_quantile(0.5) as f64,
                t.iteration_quantile(0.95) as f64,
                t.iterations.iter().max().copied().unwrap_or(0) as f64,
                1e6 * t.secs / t.count.max(1) as f64,
            ]);
            rows.push(r);
            let mut h = vec![*sigma, k as f64];
            for it in 0..=50 {
                h.push(t.iterations.iter().filter(|&&i| i == it).count() as f64);
            }
            hist_rows.push(h);
        }
    }
    crate::csv::write_to(files, &dir.join("fk_rates.csv"), &header, &rows)?;
    let mut hh: Vec<String> = vec!["sigma".into(), "solver".into()];
    hh.extend((0..=50).map(|i| format!("it{i}")));
    crate::csv::write_to(files, &dir.join("fk_iterations.csv"), &hh, &hist_rows)
}

/// `fk_rates.png`: the outcome rates against the noise (log x), one curve per solver, and the
/// iteration counts.
pub fn plot(
    files: &mut crate::output::Outputs,
    file: &std::path::Path,
    s: &Study,
) -> Result<(), String> {
    use crate::plot::{Panel, Series, write_png_to};
    let x = s.sigmas.clone();
    let per = |f: &dyn Fn(&Tally) -> f64, k: usize| -> Vec<f64> {
        s.tallies.iter().map(|row| f(&row[k])).collect()
    };
    let mut panels = Vec::new();
    for (title, f) in [
        (
            "converged to the start's own solution [%]",
            &(|t: &Tally| 100.0 * t.rate(Outcome::Same)) as &dyn Fn(&Tally) -> f64,
        ),
        (
            "converged to another solution (mode or U-branch) [%]",
            &|t: &Tally| 100.0 * (t.rate(Outcome::OtherMode) + t.rate(Outcome::Branch)),
        ),
        (
            "failed: NotConverged / Singular / NonFinite, or rejected by the policy [%]",
            &|t: &Tally| 100.0 * (1.0 - t.converged_rate()),
        ),
        ("iterations of converged solves: median", &|t: &Tally| {
            t.iteration_quantile(0.5) as f64
        }),
    ] {
        let mut p = Panel::new(title, "start noise sigma [m, rad]", "").log_x();
        for (k, solver) in SOLVERS.iter().enumerate() {
            p = p.with(Series::new(solver.name(), x.clone(), per(f, k)).markers());
        }
        panels.push(p);
    }
    write_png_to(
        files,
        file,
        "rbss stress fk: forward kinematics of the 6-UPS from perturbed starts",
        &panels,
        2,
        1500,
        1000,
    )
}
