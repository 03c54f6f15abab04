//! `rbss`: solve a generated robot's kinematic problems from the command line.
//!
//! ```text
//! rbss list
//! rbss ik   --model stewart_6ups --pose 0.1,0,0.94,0.1,0,0
//! rbss ik   --model five_bar --pose 0.05,0.32 --rates 0.1,-0.2 --json
//! rbss fk   --model stewart_6ups --q 0.93,0.98,1.04,0.98,0.96,0.97
//! rbss fk   --model five_bar --q 2.0,1.2 --max-passive-change 0.5
//! rbss eval --model stewart_6ups --states states.json > kernels.json
//! rbss inverse-dynamics --model five_bar --trajectory models/trajectories/five_bar_figure_eight.csv --csv u.csv
//! rbss roundtrip --model ur5 --out DIR          # any robot, along models/trajectories/NAME.toml
//! ```
//!
//! A command's results go to stdout when it has finished; progress and errors to stderr. A
//! closed stdout (`rbss list | head -c1`) ends the command quietly with status 0, as when the
//! reader had read everything: the reader chose to stop. Any other failure to write stdout is
//! an error (status 1). A closed stderr drops the messages.

use std::io::Write as _;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use rbss::{kinematics, robots};

/// A line of the command's results, into the text `run` returns for stdout.
macro_rules! out {
    ($out:expr) => {
        $out.push('\n')
    };
    ($out:expr, $($t:tt)*) => {{
        use std::fmt::Write as _;
        let _ = writeln!($out, $($t)*);
    }};
}

/// `eprintln!` that drops the line when stderr is closed instead of panicking.
macro_rules! say {
    ($($t:tt)*) => {{
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

#[derive(Parser)]
#[command(
    name = "rbss",
    version,
    about = "Parallel-robot kinematics from generated kernels"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// List the robots this build knows, with their coordinates.
    List,
    /// Inverse kinematics: every coordinate from the output (task) coordinates.
    Ik {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// Output coordinates, comma-separated, in the model's `outputs` order
        /// (stewart_6ups: x,y,z,rotx,roty,rotz in m and rad).
        #[arg(long, allow_hyphen_values = true)]
        pose: String,
        /// Output rates, comma-separated: also solve the inverse velocity (every coordinate's
        /// rate; the actuated rates are the joint speeds).
        #[arg(long, allow_hyphen_values = true)]
        rates: Option<String>,
        /// Print JSON (every value with full precision: it parses back to the same f64).
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        mode: ModeArgs,
    },
    /// Forward kinematics: every coordinate from the actuated ones.
    Fk {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// Actuated coordinates, comma-separated, in the model's `actuated` order.
        #[arg(long, allow_hyphen_values = true)]
        q: String,
        /// The start: `home` (the model's reference assembly, the default) or the solution of
        /// inverse kinematics (by continuation from home) at the pose given with --near.
        #[arg(long, allow_hyphen_values = true)]
        near: Option<String>,
        /// Solve by Levenberg–Marquardt and refuse a solution whose passive coordinates moved
        /// more than this from the start (m or rad): another assembly mode.
        #[arg(long, allow_hyphen_values = true)]
        max_passive_change: Option<f64>,
        /// Print JSON (every value with full precision: it parses back to the same f64).
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        mode: ModeArgs,
    },
    /// The paper's section 4 end to end on stewart_6ups: inverse kinematics along TraekP, inverse
    /// dynamics, forward dynamics under U(t); CSV files and PNG figures 4-8 in --out.
    Paper {
        /// Output directory.
        #[arg(long, default_value = "paper-out", value_parser = rbss::output_path)]
        out: String,
        /// Angular frequency w of TraekP [rad/s].
        #[arg(long, allow_hyphen_values = true, default_value_t = std::f64::consts::PI)]
        omega: f64,
        /// End time [s].
        #[arg(long, allow_hyphen_values = true, default_value_t = 2.0)]
        t_end: f64,
        /// Kinematic / inverse-dynamics samples (figures 4, 5): 2 to 1 000 000 (all held in
        /// memory).
        #[arg(long, default_value_t = 2001)]
        samples: usize,
        #[command(flatten)]
        integrator: IntegratorArgs,
    },
    /// Inverse dynamics along an output trajectory: writes the control forces U (and the
    /// Lagrange multipliers) to a CSV file. The trajectory is --trajectory FILE (.csv samples
    /// `t,<outputs>`, .toml expressions in t; see models/trajectories/), or for stewart_6ups
    /// by default the paper's TraekP.
    InverseDynamics {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// Trajectory of the outputs: a .csv file of samples or a .toml file of expressions.
        #[arg(long)]
        trajectory: Option<String>,
        /// Angular frequency w of TraekP [rad/s] (default pi; stewart_6ups without --trajectory).
        #[arg(long, allow_hyphen_values = true)]
        omega: Option<f64>,
        /// First time [s] (default: the first sample of a .csv trajectory, else 0).
        #[arg(long, allow_hyphen_values = true)]
        t_start: Option<f64>,
        /// End time T [s] (default: the last sample of a .csv trajectory, else 2);
        /// samples at t_k = t_start + k (T - t_start) / (N - 1).
        #[arg(long, allow_hyphen_values = true)]
        t_end: Option<f64>,
        /// Number of samples N: 2 to 1 000 000 (all held in memory).
        #[arg(long, default_value_t = 201)]
        samples: usize,
        /// Output CSV: t,U1..Uk,lambda1..lambdam (k actuated, m constraints).
        #[arg(long, value_parser = rbss::output_path)]
        csv: String,
    },
    /// The round trip for any robot: inverse kinematics and dynamics along an output
    /// trajectory, then forward dynamics under those control forces U(t) (computed at every
    /// integrator stage time), the simulated outputs compared with the trajectory. Prints
    /// `round-trip max output error: E`; writes DIR/roundtrip.csv and DIR/roundtrip.png.
    Roundtrip {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// Trajectory of the outputs (.toml expressions or .csv samples); default
        /// models/trajectories/NAME.toml.
        #[arg(long)]
        trajectory: Option<String>,
        /// End time [s] (default: the trajectory's last sample, else 2).
        #[arg(long, allow_hyphen_values = true)]
        t_end: Option<f64>,
        #[command(flatten)]
        integrator: IntegratorArgs,
        /// Output directory.
        #[arg(long, default_value = "roundtrip-out", value_parser = rbss::output_path)]
        out: String,
    },
    /// Evaluate the kernels at given states: reads {"states":[{"X":[..],"Xdot":[..]}]},
    /// writes {"states":[{"f":[..],"G":[[..]..],"gamma":[..],"M":[[..]..],"psi":[..]}]} to stdout.
    /// A state with "U":[..] (forces on the actuated coordinates) also gets forward dynamics:
    /// "Xddot" and "lambda" of M Xddot = psi + S U - Gᵀ lambda, G Xddot = gamma, where
    /// f = origin(a) - origin(b), G = ∂f/∂X and gamma = -(dG/dt) Xdot. psi holds gravity, the
    /// Christoffel terms and the joints' own forces: -stiffness (q - rest) - damping q̇ per
    /// coordinate; M's diagonal holds the joints' armatures (docs/model-format.md).
    Eval {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// The JSON file of states.
        #[arg(long)]
        states: String,
    },
    /// Forward dynamics at one state: reads {"X":[..n..],"Xdot":[..n..],"U":[..k..]} ("U", the
    /// forces on the actuated coordinates in `rbss list`'s order, optional: zero when absent) and
    /// writes {"Xddot":[..n..],"lambda":[..m..],"energy":[T,Pi],"residual":[r_motion,r_constraint]}.
    /// Conventions: M Xddot = psi + S U - Gᵀ lambda and G Xddot = gamma, f = origin(a) -
    /// origin(b), G = ∂f/∂X, gamma = -(dG/dt) Xdot; psi holds gravity, the Christoffel terms and
    /// the joints' springs (-stiffness (q - rest)) and dampers (-damping q̇); M's diagonal the
    /// joints' armatures; Pi gravity's and the springs' potential (½ stiffness (q - rest)²).
    Fd {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// The JSON file of the state.
        #[arg(long)]
        state: String,
    },
    /// Forward dynamics in time from a state (the JSON file `rbss fd` reads), under its "U"
    /// (constant; zero when absent) or "U_table":[[t,U1..Uk],..] (linear between rows, held
    /// beyond). Writes DIR/simulate.csv (t, the coordinates, their rates NAME_dot, T, Pi,
    /// E = T + Pi, one row per accepted step) and DIR/simulate.png; prints the energy at both
    /// ends. Conventions as `rbss fd --help`.
    Simulate {
        /// Robot name (see `rbss list`).
        #[arg(long)]
        model: String,
        /// The JSON file of the initial state and the control.
        #[arg(long)]
        state: String,
        /// End time [s] (the simulation starts at t = 0).
        #[arg(long, allow_hyphen_values = true)]
        t_end: f64,
        #[command(flatten)]
        integrator: IntegratorArgs,
        /// Output directory.
        #[arg(long, default_value = "simulate-out", value_parser = rbss::output_path)]
        out: String,
    },
    /// Numerical stress tests of the paper's robot (issue 5): singularities, forward-kinematics
    /// robustness, long-run drift. See `rbss stress --help`.
    #[cfg(feature = "studies")]
    #[command(subcommand)]
    Stress(rbss::stress::StressCmd),
    /// Benchmarks (issue 4): `rbss bench work-precision --model stewart_6ups --out DIR`.
    #[cfg(feature = "studies")]
    #[command(subcommand)]
    Bench(rbss::bench::BenchCmd),
    /// Numerical stress tests (a study: build with `--features studies`).
    #[cfg(not(feature = "studies"))]
    #[command(disable_help_flag = true)]
    Stress {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<String>,
    },
    /// Benchmarks (a study: build with `--features studies`).
    #[cfg(not(feature = "studies"))]
    #[command(disable_help_flag = true)]
    Bench {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<String>,
    },
}

/// `rbss stress|bench ...` in a build without the studies: what to run instead.
#[cfg(not(feature = "studies"))]
fn without_studies(cmd: &str, args: &[String]) -> Result<(), String> {
    Err(format!(
        "`rbss {cmd}` is a study, left out of the default build (it compiles every solver again \
         for every robot); build it with the feature `studies`:\n  \
         cargo run --release --features studies -- {cmd} {}",
        args.join(" ")
    ))
}

/// The integrator of `rbss paper` and `rbss roundtrip`.
/// How `rbss ik` and `rbss fk` find the solution and guard its assembly mode.
#[derive(clap::Args, Debug, Clone)]
struct ModeArgs {
    /// One Newton solve from the start instead of the default continuation (which walks from
    /// the start to the target in steps and keeps the start's assembly mode). Faster; a
    /// solution in another mode than the start's (by the signs of det(G_r) per IK block and of
    /// det(J_p)) is still refused, but an even number of flips is invisible to the signs.
    #[arg(long)]
    direct: bool,
    /// Accept a solution in another assembly mode than the start's (a sign of the mode
    /// signature changed, or the path crossed a singularity); by default that is an error
    /// (exit 1) that names the leg.
    #[arg(long)]
    allow_mode_change: bool,
    /// The mode the answer must be in, as the mode line prints it: one sign per IK block (`+`,
    /// `-`, or `?` for either), `/`, the sign of det(J_p); e.g. `--mode "+-?/+"`. An answer in
    /// another mode is an error (exit 1) naming the leg.
    #[arg(long, allow_hyphen_values = true, value_parser = kinematics::parse_mode)]
    mode: Option<kinematics::NamedMode>,
}

impl ModeArgs {
    fn solve(&self, max_passive_change: Option<f64>) -> kinematics::Solve {
        kinematics::Solve {
            direct: self.direct,
            allow_mode_change: self.allow_mode_change,
            max_passive_change,
            mode: self.mode,
        }
    }
}

#[derive(clap::Args, Debug, Clone)]
struct IntegratorArgs {
    /// Integrator: dopri5 (adaptive, --rtol) or rk4 (fixed step --dt, the paper's).
    #[arg(long, default_value = "dopri5")]
    method: String,
    /// DOPRI5 relative tolerance (atol = rtol / 100).
    #[arg(long, allow_hyphen_values = true, default_value_t = 1e-10)]
    rtol: f64,
    /// RK4 step [s].
    #[arg(long, allow_hyphen_values = true, default_value_t = 1e-3)]
    dt: f64,
    /// Constraint stabilisation: none, baumgarte, projection, partitioning.
    #[arg(long, default_value = "projection")]
    stabilization: String,
}

/// The integrator settings of `--method`, `--rtol`, `--dt` and `--stabilization`.
fn integrate_options(a: &IntegratorArgs) -> Result<rbss_runtime::IntegrateOptions, String> {
    use rbss_runtime::{IntegrateOptions, Method, Stabilization};
    let (rtol, dt) = (a.rtol, a.dt);
    let method = match a.method.as_str() {
        "dopri5" if rtol > 0.0 && rtol.is_finite() => Method::dopri5(rtol, rtol / 100.0),
        "rk4" if dt > 0.0 && dt.is_finite() => Method::Rk4 { dt },
        other => {
            return Err(format!(
                "--method {other}: expected dopri5 (with --rtol > 0) or rk4 (with --dt > 0)"
            ));
        }
    };
    let stabilization = match a.stabilization.as_str() {
        "none" => Stabilization::None,
        "baumgarte" => Stabilization::baumgarte(),
        "projection" => Stabilization::Projection,
        "partitioning" => Stabilization::CoordinatePartitioning,
        other => {
            return Err(format!(
                "--stabilization {other}: expected none, baumgarte, projection or partitioning"
            ));
        }
    };
    Ok(IntegrateOptions::new(method, stabilization))
}

fn paper(
    stdout: &mut String,
    out: &str,
    omega: f64,
    t_end: f64,
    samples: usize,
    integrator: &IntegratorArgs,
) -> Result<(), String> {
    let integrate = integrate_options(integrator)?;
    rbss::trajectory::check_samples(samples)?;
    if !(t_end.is_finite() && t_end > 0.0 && omega.is_finite()) {
        return Err("need a finite --t-end > 0 and a finite --omega".into());
    }
    let opts = rbss::paper::PaperOptions {
        omega,
        t_end,
        samples,
        integrate,
    };
    let s = rbss::paper::run(std::path::Path::new(out), &opts, &mut |m| say!("rbss: {m}"))?;
    out!(
        stdout,
        "rbss paper: the 6-UPS of Phan Bui Khoi (2009), section 4, w = {omega} rad/s, t in [0, {t_end}] s"
    );
    out!(
        stdout,
        "inverse kinematics: {samples} samples, max |f| = {:.1e}",
        s.max_ik_residual
    );
    out!(
        stdout,
        "inverse dynamics: max |U| = {:.3} N, worst condition estimate {:.3e}",
        s.max_u,
        s.max_id_cond
    );
    out!(
        stdout,
        "forward dynamics: {:?}, {:?}: {} steps ({} rejected), {} right-hand sides",
        opts.integrate.method,
        opts.integrate.stabilization,
        s.stats.steps,
        s.stats.rejected,
        s.stats.rhs_evaluations
    );
    out!(
        stdout,
        "round-trip max platform position error: {:.3e} m",
        s.position_error
    );
    out!(
        stdout,
        "round-trip max platform rotation error: {:.3e} rad",
        s.rotation_error
    );
    out!(
        stdout,
        "round-trip max platform velocity error: {:.3e} (m/s, rad/s)",
        s.velocity_error
    );
    out!(
        stdout,
        "round-trip max platform acceleration error: {:.3e} (m/s², rad/s²)",
        s.acceleration_error
    );
    out!(
        stdout,
        "max constraint violation: {:.3e} m",
        s.max_violation
    );
    out!(
        stdout,
        "run time: {:.3} s total (kinematics {:.3} s, inverse dynamics {:.3} s, integration {:.3} s)",
        s.total_secs,
        s.kinematics_secs,
        s.inverse_dynamics_secs,
        s.integration_secs
    );
    out!(
        stdout,
        "wrote {out}/{{inverse_kinematics,inverse_dynamics,forward_dynamics}}.csv and fig4..fig8 PNG files"
    );
    Ok(())
}

/// Runs the command; its results (for stdout) go to `stdout`.
fn run(cli: Cli, stdout: &mut String) -> Result<(), String> {
    match cli.cmd {
        Cmd::List => {
            let width = robots::NAMES.iter().map(|n| n.len()).max().unwrap_or(0);
            for name in robots::NAMES {
                rbss::with_robot!(*name, |model| {
                    let s = model.structure();
                    out!(
                        stdout,
                        "{:<width$} n = {:>2}, m = {:>2}; q = [{}]; outputs = [{}]",
                        name,
                        s.coordinates.len(),
                        s.constraints.len(),
                        s.actuated
                            .iter()
                            .map(|&j| s.coordinates[j])
                            .collect::<Vec<_>>()
                            .join(", "),
                        s.outputs
                            .iter()
                            .map(|&j| s.coordinates[j])
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                    Ok::<(), String>(())
                })?;
            }
            Ok(())
        }
        Cmd::Ik {
            model,
            pose,
            rates,
            json,
            mode,
        } => {
            let how = mode.solve(None);
            let out = kinematics::ik_named(&model, &pose, rates.as_deref(), json, how)?;
            stdout.push_str(&out);
            if json {
                out!(stdout);
            }
            Ok(())
        }
        Cmd::Fk {
            model,
            q,
            near,
            max_passive_change,
            json,
            mode,
        } => {
            let how = mode.solve(max_passive_change);
            let out = kinematics::fk_named(&model, &q, near.as_deref(), json, how)?;
            stdout.push_str(&out);
            if json {
                out!(stdout);
            }
            Ok(())
        }
        Cmd::Eval { model, states } => {
            out!(stdout, "{}", rbss::eval_named(&model, &states)?);
            Ok(())
        }
        Cmd::Fd { model, state } => {
            out!(stdout, "{}", rbss::simulate::fd_named(&model, &state)?);
            Ok(())
        }
        Cmd::Simulate {
            model,
            state,
            t_end,
            integrator,
            out,
        } => {
            let req = rbss::simulate::SimulateRequest {
                model,
                state,
                t_end,
                integrate: integrate_options(&integrator)?,
                out,
            };
            out!(stdout, "{}", rbss::simulate::simulate_command(&req)?);
            Ok(())
        }
        #[cfg(feature = "studies")]
        Cmd::Stress(cmd) => rbss::stress::run(cmd),
        #[cfg(feature = "studies")]
        Cmd::Bench(cmd) => rbss::bench::command(cmd),
        #[cfg(not(feature = "studies"))]
        Cmd::Stress { args } => without_studies("stress", &args),
        #[cfg(not(feature = "studies"))]
        Cmd::Bench { args } => without_studies("bench", &args),
        Cmd::Paper {
            out,
            omega,
            t_end,
            samples,
            integrator,
        } => paper(stdout, &out, omega, t_end, samples, &integrator),
        Cmd::Roundtrip {
            model,
            trajectory,
            t_end,
            integrator,
            out,
        } => {
            let req = rbss::roundtrip::RoundTripRequest {
                model,
                trajectory,
                t_end,
                integrate: integrate_options(&integrator)?,
                out,
            };
            let s = rbss::roundtrip::roundtrip_command(&req)?;
            say!("rbss: {}", s.report);
            out!(
                stdout,
                "round-trip max output error: {:.3e}",
                s.max_output_error
            );
            Ok(())
        }
        Cmd::InverseDynamics {
            model,
            trajectory,
            omega,
            t_start,
            t_end,
            samples,
            csv,
        } => {
            let req = rbss::trajectory::InverseDynamicsRequest {
                model,
                trajectory,
                omega,
                t_start,
                t_end,
                samples,
                csv,
            };
            let report = rbss::trajectory::inverse_dynamics_command(&req)?;
            say!("rbss: {report}");
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    let mut stdout = String::new();
    let result = run(Cli::parse(), &mut stdout);
    let mut lock = std::io::stdout().lock();
    match lock
        .write_all(stdout.as_bytes())
        .and_then(|()| lock.flush())
    {
        Ok(()) => {}
        // The reader stopped reading (`| head`): nothing more to say (module documentation).
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => {
            say!("rbss: error: cannot write the results to stdout: {e}");
            return ExitCode::FAILURE;
        }
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            say!("rbss: error: {e}");
            ExitCode::FAILURE
        }
    }
}
