//! `rbss stress`: numerical stress tests of the paper's 6-UPS (issue 5): singularities,
//! forward-kinematics robustness from poor starts, and drift over long simulations. Each scene
//! prints its tables (Markdown) and writes CSV, PNG and the same tables (`.md`) to `--out`.
//! The short versions run in `tests/stress.rs`.

pub mod drift;
pub mod fk;
pub mod geometry;
pub mod singularity;

use crate::output::Outputs;
use crate::robots::stewart_6ups;
use std::path::Path;
use std::time::Instant;

/// The paper's robot with its default parameters.
pub type Robot =
    rbss_runtime::Model<stewart_6ups::Stewart6Ups, { stewart_6ups::N }, { stewart_6ups::M }>;

/// The scenes of `rbss stress`.
#[derive(Debug, clap::Subcommand)]
pub enum StressCmd {
    /// Drive the robot into a parallel (type II) and a serial (type I) singularity and record
    /// every solver's conditioning and result along the way.
    ///
    /// Paths (`pose(s)`, `s` in [0, 1], singular at `s = 1`; samples down to `1 - s = 1e-10`):
    ///
    /// - parallel: Fichter's singularity of the 3-fold symmetric Stewart platform. At
    ///   `x = y = 0`, `z = 0.94`, the platform turns about the vertical, `rotz = s pi/2`. At
    ///   90° the six leg lines are linearly dependent: with all six leg lengths fixed the
    ///   platform can still screw about the vertical axis (measured null vector of `J_p`: turn
    ///   about z while sinking 0.175 m per rad), so `J_p` (18 × 18) and the reduced 6 × 6
    ///   inverse-dynamics system lose rank together, and holding the platform against gravity
    ///   takes forces growing as 1 / (1 - s).
    ///
    /// - serial: leg 1 laid down. The platform, tilted 60° so that its joint P1 is lowest, is
    ///   lowered 0.2 m until P1 touches the base plane on the radius of base joint 1, 0.35 m
    ///   inside it: there psi1 = -90° and the universal joint's two axes line up
    ///   (`∂f_1/∂phi1 = d1 cos(psi1) (…) = 0`). Leg 1 can no longer move P1 across its own
    ///   plane, so its 3 × 3 inverse-kinematics block `∂f_1/∂(d1, phi1, psi1)` loses rank (type
    ///   I); phi1 becomes a free spin of the leg about its axis, so `J_p` loses rank as well
    ///   (its null vector is that spin alone: the platform pose stays fixed by q) and so does
    ///   `[S | Gᵀ]` (leg 1 can carry a load across its plane, the static forces are not unique
    ///   at the singular pose). Near it the actuator forces stay finite: 990 N.
    ///
    /// What a user sees (default `SolverOptions`, `cond_max = 1e7`), measured: the condition
    /// estimates of `J_p`, the worst IK block, the reduced inverse-dynamics system `A` and `S_c`
    /// at the exact pose with the threshold off, then each solver's result (static holding
    /// forces for the dynamics: `Ẋ = Ẍ = 0`):
    ///
    /// | path | 1 - s | cond J_p / IK / A / S_c | IK | FK | inverse dynamics | forward dynamics |
    /// |---|---|---|---|---|---|---|
    /// | parallel | 1e-2 | 2.7e3 / 3.2 / 1.6e3 / 13 | Ok | Ok | Ok, max U 5.4e4 N | Ok |
    /// | parallel | 1e-5 | 2.7e6 / 3.2 / 1.6e6 / 13 | Ok | Ok | Ok, 5.5e7 N (right: Ẍ ≈ 1e-9 under it) | Ok |
    /// | parallel | 5.6e-6, 3.2e-6 | 4.8e6, 8.6e6 / 3.2 / 2.9e6, 5.2e6 / 13 | Ok | NotConverged(50) | Ok, 9.7e7, 1.7e8 N | Ok |
    /// | parallel | 1.8e-6 | 1.5e7 / 3.2 / 9.2e6 / 13 | Ok | Singular(1.4e7) | Ok, 3.1e8 N (the last) | Ok |
    /// | parallel | ≤ 1e-6 | ≥ 2.7e7 / 3.2 / ≥ 1.6e7 / 13 | Ok | Singular | Singular | Ok |
    /// | serial | 1e-2 | 3.7e3 / 6.0e2 / 19 / 69 | Ok | Ok | Ok, 992 N | Ok |
    /// | serial | 1e-5 | 3.5e6 / 5.9e5 / 19 / 70 | Ok or NotConverged(50) | Ok | Ok, 990 N | Ok |
    /// | serial | 3.2e-6 to 1e-6 | 1.1e7 to 3.5e7 / ≤ 5.9e6 / 19 / 70 | Ok or NotConverged(50) | Singular | Ok, 990 N | Ok |
    /// | serial | ≤ 5.6e-7 | ≥ 6.2e7 / ≥ 1.05e7 / 19 / 70 | Singular | Singular | Singular (its dense fallback is singular too) | Ok |
    ///
    /// So: no NaN, no panic; past `cond_max` the solvers of the singular matrix return
    /// `Singular` with its estimate. Below it, the Newton solvers (IK, FK) may return
    /// `NotConverged(50)` instead, from cond of about 1e5 up: their step test
    /// `max |dx| <= tol_x (1 + max |x|)`, `tol_x = 1e-12`, is below the rounding noise of the
    /// step, about `cond ε` (measured: FK at cond 4.8e6 and 8.6e6; IK from 5.9e5 or from 1.9e6
    /// on depending on the warm start and the solver version; "Ok or NotConverged" above). Near a parallel singularity the forces inverse dynamics returns
    /// before the threshold are huge (3e8 N) but correct; forward dynamics stays regular at
    /// both singularities (`G` keeps full row rank). Writes `singularity_{parallel,serial}.csv`,
    /// `singularity.md` and `singularity.png` (conditions against 1 - s, log-log).
    #[command(verbatim_doc_comment)]
    Singularity {
        /// Output directory.
        #[arg(long, default_value = "stress-out", value_parser = crate::output_path)]
        out: String,
    },
    /// Forward kinematics from perturbed starts: Newton (`forward_kinematics`) against
    /// Levenberg–Marquardt (`forward_kinematics_lm`, with and without its mode policy).
    ///
    /// Poses uniform in x, y ±0.15 m, z 0.94 ± 0.14 m, rotations ±0.25 rad (kept if regular,
    /// cond J_p < 1e4, and legs up); the start is the IK solution with every passive coordinate
    /// perturbed by sigma·uniform(-1, 1), sigma in 0.01, 0.05, 0.1, 0.3, 0.6, 1 (m, rad). Results
    /// are classified against the IK solution: the same (angles modulo 2 pi), the same platform
    /// pose with a universal joint on its other branch, another assembly mode, or a typed
    /// failure. Writes `fk.md`, `fk_rates.csv`, `fk_iterations.csv`, `fk_rates.png`.
    ///
    /// Measured (10,000 starts, seed 2009), converged to the start's own solution:
    ///
    /// | sigma | 0.01 | 0.05 | 0.1 | 0.3 | 0.6 | 1 |
    /// |---|---|---|---|---|---|---|
    /// | Newton | 100 % | 100 % | 100 % | 99.7 % | 86.9 % | 36.0 % |
    /// | LM | 100 % | 100 % | 100 % | 100 % | 99.9 % | 89.0 % |
    ///
    /// Newton's misses at 0.6 / 1: another assembly mode 8.1 % / 36.3 %, another U-joint
    /// branch 0.2 % / 2.5 %, NotConverged 4.6 % / 24.7 %, Singular 0.1 % / 0.5 %. LM's at 1:
    /// another mode 8.4 %, NotConverged 2.6 %; its mode policy (reject a solution more than
    /// 2 sigma from the start) turns 4.6 % of them into an explicit rejection, 3.9 % pass it.
    /// Median iterations 3 to 5 for both up to sigma 0.3; at 1, Newton 13 (p95 40), LM 8 (14).
    #[command(verbatim_doc_comment)]
    Fk {
        /// Starts in all, split evenly over the noise levels.
        #[arg(long, default_value_t = 10_000)]
        samples: usize,
        /// Output directory.
        #[arg(long, default_value = "stress-out", value_parser = crate::output_path)]
        out: String,
        /// Seed of the random poses and noise.
        #[arg(long, default_value_t = 2009)]
        seed: u64,
    },
    /// Long RK4 runs along TraekP under each stabilisation: drift of the constraints, of the
    /// work–energy balance and of the tracking, and the wall time.
    ///
    /// Scenario: TraekP repeated (period 2 s) with `U = U_ff(t) + kp (d_ref - d) +
    /// kd (ḋ_ref - ḋ)`: the paper's inverse-dynamics forces (tabulated over one period at the
    /// RK4 stage times) plus a leg-length servo. The feed-forward forces alone do not stay in the
    /// workspace: legs in compression under fixed forces are unstable (negative geometric
    /// stiffness); the command first shows it, the tracking error growing from 3e-11 m at 1 s
    /// to 1.7e-3 m at 5 s (e-folding ≈ 0.2 s). With the servo the motion is a stable periodic
    /// orbit for any length of run. Writes `drift.md`, `drift_<stabilisation>.csv`,
    /// `drift_feedforward_only.csv`, `drift.png`.
    ///
    /// Measured (10^6 steps of 1e-3 s, 1000 s; cost per step from a 5e4-step run, both on the
    /// shared 2-core machine, monitoring of |f| and |G Ẋ| at every step included):
    ///
    /// | stabilisation | max \|f\| (m) | max \|G Ẋ\| (m/s) | max \|E - E0 - W\| (J) | µs/step | Newton its/step |
    /// |---|---|---|---|---|---|
    /// | none | 8.6e-6 (grows as t²) | 1.7e-8 (as t) | 3.4e-3 (as t²) | 33 | 0 |
    /// | baumgarte | 2.2e-12 (bounded) | 4.7e-11 | 3.9e-5 (as t) | 33 | 0 |
    /// | projection | 1.0e-12 (tol_f; 1.04e-12 before projecting) | 3e-16 | 4.0e-5 (as t) | 40 | 0.017 |
    /// | partitioning | 5.6e-16 | 4.4e-16 | 3.9e-5 (as t) | 111 | 8 |
    ///
    /// The balance `E = T + Pi` against the actuators' work `W = ∫ Uᵀ ḋ dt` (max kinetic
    /// energy 17.8 J): with any stabilisation it drifts linearly at 3.9e-8 J/s, RK4's own
    /// O(dt⁴) error in `W` (halving dt divides it by 16); without, the constraint drift adds a
    /// t² term. Tracking error of TraekP: 4e-11 (stabilised), 1.4e-5 after 1000 s (none).
    #[command(verbatim_doc_comment)]
    Drift {
        /// RK4 steps per stabilisation.
        #[arg(long, default_value_t = 1_000_000)]
        steps: usize,
        /// RK4 step in s (the period 2 s must be a whole number of half steps).
        #[arg(long, allow_hyphen_values = true, default_value_t = 1e-3)]
        dt: f64,
        /// Steps per recorded window (CSV row).
        #[arg(long, default_value_t = 1000)]
        window: usize,
        /// Leg servo gains kp [N/m], kd [N s/m]; `0,0` for the feed-forward U alone.
        #[arg(long, default_value = "2e4,2e3")]
        servo: String,
        /// Stabilisations to run, comma-separated (none, baumgarte, projection, partitioning).
        #[arg(long, default_value = "none,baumgarte,projection,partitioning")]
        stabilizations: String,
        /// Output directory.
        #[arg(long, default_value = "stress-out", value_parser = crate::output_path)]
        out: String,
    },
}

fn create(out: &str) -> Result<&Path, String> {
    let dir = Path::new(out);
    crate::create_output_dir(dir)?;
    Ok(dir)
}

/// A text file of the run `files` (written with the others on commit).
fn write_text(files: &mut Outputs, file: &Path, text: &str) -> Result<(), String> {
    use std::io::Write as _;
    files
        .create(file)?
        .write_all(text.as_bytes())
        .map_err(|e| format!("{}: cannot write: {e}", file.display()))
}

/// Runs one `rbss stress` scene.
pub fn run(cmd: StressCmd) -> Result<(), String> {
    match cmd {
        StressCmd::Singularity { out } => run_singularity(create(&out)?),
        StressCmd::Fk { samples, out, seed } => run_fk(create(&out)?, samples, seed),
        StressCmd::Drift {
            steps,
            dt,
            window,
            servo,
            stabilizations,
            out,
        } => {
            let g: Vec<f64> = servo
                .split(',')
                .map(|v| v.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| format!("--servo {servo}: {e}"))?;
            let [kp, kd] = g[..] else {
                return Err(format!("--servo {servo}: expected kp,kd"));
            };
            let stabs = stabilizations
                .split(',')
                .map(|name| {
                    drift::STABILIZATIONS
                        .iter()
                        .copied()
                        .find(|s| drift::name(*s) == name.trim())
                        .ok_or_else(|| {
                            format!(
                                "--stabilizations: unknown `{name}` (none, baumgarte, projection, partitioning)"
                            )
                        })
                })
                .collect::<Result<Vec<_>, _>>()?;
            if !(dt.is_finite() && dt > 0.0) || steps == 0 {
                return Err("need --dt > 0 and --steps > 0".into());
            }
            run_drift(
                create(&out)?,
                steps,
                dt,
                window.max(1),
                drift::Servo { kp, kd },
                &stabs,
            )
        }
    }
}

fn run_singularity(out: &Path) -> Result<(), String> {
    let samples = singularity::samples();
    let mut md = String::from("# rbss stress singularity\n\n");
    let mut runs = Vec::new();
    // The run's files together, or none (the old set stays).
    let mut files = Outputs::new();
    for path in [singularity::Path::parallel(), singularity::Path::serial()] {
        let pts = singularity::walk(&path, &samples);
        singularity::write_csv(
            &mut files,
            &out.join(format!("singularity_{}.csv", path.name)),
            &pts,
        )?;
        crate::outln!("{}", singularity::table(&path, &pts, true));
        md.push_str(&singularity::table(&path, &pts, false));
        md.push('\n');
        runs.push((path, pts));
    }
    write_text(&mut files, &out.join("singularity.md"), &md)?;
    singularity::plot(
        &mut files,
        &out.join("singularity.png"),
        &runs,
        rbss_runtime::SolverOptions::default().cond_max,
    )?;
    files.commit()?;
    crate::outln!(
        "wrote {}/singularity_{{parallel,serial}}.csv, singularity.md, singularity.png",
        out.display()
    );
    Ok(())
}

fn run_fk(out: &Path, samples: usize, seed: u64) -> Result<(), String> {
    let t0 = Instant::now();
    let st = fk::study(samples, &fk::SIGMAS, seed);
    let rates = fk::rates_table(&st);
    let hist = fk::histogram_table(&st);
    crate::outln!("{rates}");
    crate::outln!("iterations of the converged solves (count per bin):\n\n{hist}");
    let mut files = Outputs::new();
    write_text(
        &mut files,
        &out.join("fk.md"),
        &format!(
            "# rbss stress fk --samples {samples} --seed {seed}\n\n{rates}\niterations of the converged solves:\n\n{hist}"
        ),
    )?;
    fk::write_csv(&mut files, out, &st)?;
    fk::plot(&mut files, &out.join("fk_rates.png"), &st)?;
    files.commit()?;
    crate::outln!(
        "wrote {}/fk.md, fk_rates.csv, fk_iterations.csv, fk_rates.png ({:.1} s)",
        out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn run_drift(
    out: &Path,
    steps: usize,
    dt: f64,
    window: usize,
    servo: drift::Servo,
    stabs: &[rbss_runtime::Stabilization],
) -> Result<(), String> {
    let mut reference = drift::Reference::new(crate::paper::OMEGA, dt)?;
    let mut progress = |m: &str| crate::errln!("rbss: {m}");
    let mut md = format!(
        "# rbss stress drift --steps {steps} --dt {dt} (servo kp = {}, kd = {})\n\n",
        servo.kp, servo.kd
    );

    // Why the servo: the feed-forward forces alone, 10 s at most, stopped at 0.1 m off track.
    let ff_steps = steps.min((10.0 / dt).round() as usize).max(1);
    let ff_window = ((0.5 / dt).round() as usize).max(1);
    progress("feed-forward U alone (projection), up to 10 s");
    let ff = drift::run(
        &mut reference,
        &drift::RunOptions {
            stabilization: rbss_runtime::Stabilization::Projection,
            servo: drift::Servo::OFF,
            dt,
            steps: ff_steps,
            window: ff_window,
            stop_tracking: 0.1,
        },
        &mut progress,
    )?;
    let mut files = Outputs::new();
    drift::write_csv(&mut files, &out.join("drift_feedforward_only.csv"), &ff)?;
    let mut ff_md = String::from(
        "Feed-forward U alone (no servo, projection): tracking error max |pose - TraekP| per 0.5 s\n\n| t [s] | tracking error |\n|---|---|\n",
    );
    for s in &ff.samples {
        ff_md.push_str(&format!("| {:.1} | {:.2e} |\n", s.t, s.tracking));
    }
    if let Some(e) = &ff.error {
        ff_md.push_str(&format!("\n{e}\n"));
    }
    crate::outln!("{ff_md}");
    md.push_str(&ff_md);
    md.push('\n');

    let mut runs = Vec::new();
    for &stab in stabs {
        progress(&format!(
            "{}: {steps} RK4 steps of {dt} s",
            drift::name(stab)
        ));
        let r = drift::run(
            &mut reference,
            &drift::RunOptions {
                stabilization: stab,
                servo,
                dt,
                steps,
                window,
                stop_tracking: 1.0,
            },
            &mut progress,
        )?;
        if let Some(e) = &r.error {
            crate::outln!("{}: {e}", drift::name(stab));
        }
        drift::write_csv(
            &mut files,
            &out.join(format!("drift_{}.csv", drift::name(stab))),
            &r,
        )?;
        runs.push(r);
    }
    let table = drift::table(&runs);
    crate::outln!("{table}");
    md.push_str("With the servo:\n\n");
    md.push_str(&table);
    write_text(&mut files, &out.join("drift.md"), &md)?;
    drift::plot(&mut files, &out.join("drift.png"), &runs)?;
    files.commit()?;
    crate::outln!("wrote {}/drift.md, drift_*.csv, drift.png", out.display());
    Ok(())
}
