//! The `rbss` command's arguments and their dispatch (src/main.rs parses and prints): every
//! subcommand that takes a robot goes through [`run_with_model`], for a robot compiled into
//! the command (`--model NAME`) and for one loaded from its library (`--model-file PATH`, see
//! [`crate::model_file`]).

use std::io::Write as _;

use crate::robot_arg::RobotArg;
use crate::{kinematics, robots};
use clap::{Parser, Subcommand};
use rbss_runtime::{Dynamics, DynamicsDerivatives, Model};

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
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// List the robots this build knows, with their coordinates. With --model or
    /// --model-file: that robot's coordinates X, constraints f (by loop and component),
    /// actuated coordinates and outputs, by name and index (--json for programs).
    List {
        /// One robot this build knows: its full description.
        #[arg(long, value_name = "NAME", conflicts_with = "model_file")]
        model: Option<String>,
        /// A model file (models/*.toml), compiled and cached as for the other subcommands.
        #[arg(long, value_name = "PATH")]
        model_file: Option<String>,
        /// JSON instead of text (every robot's description without --model).
        #[arg(long)]
        json: bool,
    },
    /// Inverse kinematics: every coordinate from the output (task) coordinates.
    Ik {
        #[command(flatten)]
        robot: RobotArg,
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
        #[command(flatten)]
        robot: RobotArg,
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
        #[arg(long, default_value = "paper-out", value_parser = crate::output_path)]
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
        #[command(flatten)]
        robot: RobotArg,
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
        #[arg(long, value_parser = crate::output_path)]
        csv: String,
    },
    /// The round trip for any robot: inverse kinematics and dynamics along an output
    /// trajectory, then forward dynamics under those control forces U(t) (computed at every
    /// integrator stage time), the simulated outputs compared with the trajectory. Prints
    /// `round-trip max output error: E`; writes DIR/roundtrip.csv and DIR/roundtrip.png.
    Roundtrip {
        #[command(flatten)]
        robot: RobotArg,
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
        #[arg(long, default_value = "roundtrip-out", value_parser = crate::output_path)]
        out: String,
    },
    /// Evaluate the kernels at given states: reads {"states":[{"X":[..],"Xdot":[..]}]},
    /// writes {"states":[{"f":[..],"G":[[..]..],"gamma":[..],"M":[[..]..],"psi":[..]}]} to stdout.
    /// A state with "U":[..] (forces on the actuated coordinates) also gets forward dynamics:
    /// "Xddot" and "lambda" of M Xddot = psi + S U - Gᵀ lambda, G Xddot = gamma, where
    /// f = origin(a) - origin(b), G = ∂f/∂X and gamma = -(dG/dt) Xdot. psi holds gravity, the
    /// Christoffel terms and the joints' own forces: -stiffness (q - rest) - damping q̇ per
    /// coordinate; M's diagonal holds the joints' armatures (docs/model-format.md). A state
    /// whose forward dynamics fails (a singular saddle-point system) gets "error" (the message)
    /// instead of "Xddot" and "lambda", keeps its kernels, and is reported on stderr; the exit
    /// status is 0 unless --strict.
    Eval {
        #[command(flatten)]
        robot: RobotArg,
        /// The JSON file of states.
        #[arg(long)]
        states: String,
        /// Exit with status 1, naming the state, when forward dynamics fails at any state (the
        /// JSON is written all the same).
        #[arg(long)]
        strict: bool,
    },
    /// Forward dynamics at one state: reads {"X":[..n..],"Xdot":[..n..],"U":[..k..]} ("U", the
    /// forces on the actuated coordinates in `rbss list`'s order, optional: zero when absent) and
    /// writes {"Xddot":[..n..],"lambda":[..m..],"energy":[T,Pi],"residual":[r_motion,r_constraint]}.
    /// Conventions: M Xddot = psi + S U - Gᵀ lambda and G Xddot = gamma, f = origin(a) -
    /// origin(b), G = ∂f/∂X, gamma = -(dG/dt) Xdot; psi holds gravity, the Christoffel terms and
    /// the joints' springs (-stiffness (q - rest)) and dampers (-damping q̇); M's diagonal the
    /// joints' armatures; Pi gravity's and the springs' potential (½ stiffness (q - rest)²).
    /// When forward dynamics fails at the state (a singular saddle-point system), writes
    /// {"energy":[T,Pi],"error":"..."} and reports it on stderr; the exit status is 0 unless
    /// --strict.
    Fd {
        #[command(flatten)]
        robot: RobotArg,
        /// The JSON file of the state.
        #[arg(long)]
        state: String,
        #[command(flatten)]
        check: StateCheckArgs,
        /// Exit with status 1 when forward dynamics fails at the state (the JSON is written
        /// all the same).
        #[arg(long)]
        strict: bool,
    },
    /// The state-space linearisation of forward dynamics on the constraint manifold at a state
    /// (the JSON file `rbss fd` reads; its "U" is the operating point's control, zero when
    /// absent), in the robot's independent coordinates y: the outputs (default) or the
    /// actuated coordinates. Prints JSON: "A" (2d x 2d) and "B" (2d x k) of
    /// d/dt [y; ydot] = A [y; ydot] + B U, the tangent map dX/dy and dXdot/dy, "Xddot",
    /// "lambda", and the full derivatives dXddot/dX, dXddot/dXdot, dXddot/dU, dlambda/dX,
    /// dlambda/dXdot, dlambda/dU (arrays of rows). The state is checked against the
    /// constraints as by `rbss fd` (or projected with --project). Conventions as
    /// `rbss fd --help`.
    Linearize {
        #[command(flatten)]
        robot: RobotArg,
        /// The JSON file of the state.
        #[arg(long)]
        state: String,
        /// The independent coordinates: outputs (the platform's pose) or actuated.
        #[arg(long, value_enum, default_value = "outputs")]
        coordinates: CoordinatesArg,
        #[command(flatten)]
        check: StateCheckArgs,
    },
    /// The derivatives of inverse dynamics at a motion: reads {"X":[..n..],"Xdot":[..n..],
    /// "Xddot":[..n..]} and prints JSON: "U" (k) and "lambda" (m) of inverse dynamics there
    /// (`rbss inverse-dynamics`'s equations, the applied forces held) and their derivatives
    /// dU/dX, dU/dXdot, dU/dXddot (k x n), dlambda/dX, dlambda/dXdot, dlambda/dXddot (m x n),
    /// arrays of rows, with "method" and "cond" of the solve. X and Xdot are checked against
    /// the constraints as by `rbss fd` (or projected with --project; Xddot is used as given).
    /// A singular [S | Gᵀ] (a parallel singularity) is an error. Conventions as
    /// `rbss fd --help`.
    IdDerivatives {
        #[command(flatten)]
        robot: RobotArg,
        /// The JSON file of the motion.
        #[arg(long)]
        state: String,
        #[command(flatten)]
        check: StateCheckArgs,
    },
    /// Forward dynamics in time from a state (the JSON file `rbss fd` reads), under its "U"
    /// (constant; zero when absent) or "U_table":[[t,U1..Uk],..] (linear between rows, held
    /// beyond). Writes DIR/simulate.csv (t, the coordinates, their rates NAME_dot, T, Pi,
    /// E = T + Pi, one row per accepted step) and DIR/simulate.png; prints the energy at both
    /// ends. Conventions as `rbss fd --help`.
    Simulate {
        #[command(flatten)]
        robot: RobotArg,
        /// The JSON file of the initial state and the control.
        #[arg(long)]
        state: String,
        /// End time [s] (the simulation starts at t = 0).
        #[arg(long, allow_hyphen_values = true)]
        t_end: f64,
        #[command(flatten)]
        integrator: IntegratorArgs,
        #[command(flatten)]
        check: StateCheckArgs,
        /// The bound on the run's constraint violation (max |f(X)| at a step, before
        /// projection) and on its energy rise without control (relative to max(1 J, |E(0)|));
        /// beyond it the run is an error. Default: 1e4 rtol (RK4: 1e6 dt^4), within
        /// [1e-8, 1e-3].
        #[arg(long, value_name = "BOUND")]
        max_violation: Option<f64>,
        /// Output directory.
        #[arg(long, default_value = "simulate-out", value_parser = crate::output_path)]
        out: String,
    },
    /// The robot of a model file as a loadable library (the C ABI of ffi/include/rbss.h):
    /// generated, compiled and cached as for --model-file; prints the library's path.
    Library {
        /// The model file.
        #[arg(long, value_name = "PATH")]
        model_file: String,
    },
    /// The cache of --model-file libraries: `rbss cache list`, `rbss cache prune [--max-size
    /// SIZE]`, `rbss cache clear` (docs/cache.md).
    Cache {
        #[command(subcommand)]
        cmd: CacheCmd,
    },
    /// Numerical stress tests of the paper's robot (issue 5): singularities, forward-kinematics
    /// robustness, long-run drift. See `rbss stress --help`.
    #[cfg(feature = "studies")]
    #[command(subcommand)]
    Stress(crate::stress::StressCmd),
    /// Benchmarks (issue 4): `rbss bench work-precision --model stewart_6ups --out DIR`,
    /// `rbss bench solvers --model-file PATH --out DIR`.
    #[cfg(feature = "studies")]
    #[command(subcommand)]
    Bench(crate::bench::BenchCmd),
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

/// `rbss cache ...`: the --model-file cache ([`crate::model_file`], docs/cache.md).
#[derive(Subcommand, Debug, Clone)]
pub enum CacheCmd {
    /// The cached robot libraries, least recently used first: key, robot, size, last use,
    /// model file; then the total and the bound.
    List,
    /// Removes the least recently used entries until the cache holds at most SIZE (bytes, or
    /// with K, M, G; default $RBSS_CACHE_MAX_SIZE, else 2G), and the leftovers of killed
    /// builds. Every build prunes to the bound too.
    Prune {
        #[arg(long, value_name = "SIZE")]
        max_size: Option<String>,
    },
    /// Removes every entry, and cargo's build directory when it is inside the cache.
    Clear,
}

/// `rbss cache list|prune|clear`: its lines for stdout go to `stdout`.
fn cache_command(cmd: &CacheCmd, stdout: &mut String) -> Result<(), String> {
    use crate::model_file::{Cache, age_text, list_entries, max_size, parse_size, prune};
    use std::fmt::Write as _;
    let cache = Cache::from_env()?;
    let mb = |b: u64| format!("{:.1} MB", b as f64 / 1e6);
    match cmd {
        CacheCmd::List => {
            let now = std::time::SystemTime::now();
            let entries = list_entries(&cache);
            for e in &entries {
                let age = now.duration_since(e.used).map_or(0, |d| d.as_secs());
                let _ = writeln!(
                    stdout,
                    "{}  {:<20}  {:>9}  used {:>6} ago  {}",
                    e.key,
                    if e.complete {
                        e.name.as_str()
                    } else {
                        "(incomplete)"
                    },
                    mb(e.size),
                    age_text(age),
                    e.model
                );
            }
            let total: u64 = entries.iter().map(|e| e.size).sum();
            let _ = writeln!(
                stdout,
                "{} entries, {} in {} (bound {}: RBSS_CACHE_MAX_SIZE)",
                entries.len(),
                mb(total),
                cache.dir.join("robots").display(),
                mb(max_size()?)
            );
            Ok(())
        }
        CacheCmd::Prune { max_size: m } => {
            let max = match m {
                Some(s) => parse_size(s).map_err(|e| format!("--max-size: {e}"))?,
                None => max_size()?,
            };
            let removed = prune(&cache, max, None)?;
            for e in &removed {
                let _ = writeln!(stdout, "removed {}  {}  {}", e.key, e.name, mb(e.size));
            }
            let left: u64 = list_entries(&cache).iter().map(|e| e.size).sum();
            let _ = writeln!(
                stdout,
                "{} entries removed ({}); {} left (bound {})",
                removed.len(),
                mb(removed.iter().map(|e| e.size).sum()),
                mb(left),
                mb(max)
            );
            Ok(())
        }
        CacheCmd::Clear => {
            let removed = prune(&cache, 0, None)?;
            let left = list_entries(&cache).len();
            let _ = writeln!(
                stdout,
                "{} entries removed ({}){}",
                removed.len(),
                mb(removed.iter().map(|e| e.size).sum()),
                if left > 0 {
                    format!("; {left} in use by a build, kept")
                } else {
                    String::new()
                }
            );
            if cache.target.starts_with(&cache.dir) && cache.target.is_dir() {
                std::fs::remove_dir_all(&cache.target)
                    .map_err(|e| format!("{}: cannot remove: {e}", cache.target.display()))?;
                let _ = writeln!(
                    stdout,
                    "removed cargo's build directory {}",
                    cache.target.display()
                );
            }
            Ok(())
        }
    }
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
pub struct ModeArgs {
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

/// The independent coordinates of `rbss linearize`.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoordinatesArg {
    /// The outputs (`[robot] outputs`: the platform's pose).
    Outputs,
    /// The actuated coordinates (fully actuated robots).
    Actuated,
}

/// How the state of `rbss fd` and `rbss simulate` is checked against the constraints.
#[derive(clap::Args, Debug, Clone)]
pub struct StateCheckArgs {
    /// The largest max |f(X)| and max |G Xdot| of the given state accepted as it is; beyond,
    /// the command stops with the residual (or projects with --project).
    #[arg(long, value_name = "TOL", default_value_t = crate::simulate::DEFAULT_STATE_TOL)]
    state_tol: f64,
    /// Project the state onto f(X) = 0 and G Xdot = 0 first, whatever its residual; the
    /// output says by how much it moved.
    #[arg(long)]
    project: bool,
}

impl StateCheckArgs {
    fn check(&self) -> Result<crate::simulate::StateCheck, String> {
        if !(self.state_tol > 0.0 && self.state_tol.is_finite()) {
            return Err(format!(
                "--state-tol {}: must be finite and positive",
                self.state_tol
            ));
        }
        Ok(crate::simulate::StateCheck {
            tol: self.state_tol,
            project: self.project,
        })
    }
}

#[derive(clap::Args, Debug, Clone)]
pub struct IntegratorArgs {
    /// Integrator: dopri5 or dop853 (adaptive, --rtol; dop853 takes fewer steps at tight
    /// tolerances) or rk4 (fixed step --dt, the paper's).
    #[arg(long, default_value = "dopri5")]
    method: String,
    /// DOPRI5's or DOP853's relative tolerance (atol = rtol / 100).
    #[arg(long, allow_hyphen_values = true, default_value_t = 1e-10)]
    rtol: f64,
    /// RK4 step [s].
    #[arg(long, allow_hyphen_values = true, default_value_t = 1e-3)]
    dt: f64,
    /// Constraint stabilisation: none, baumgarte, projection, partitioning.
    #[arg(long, default_value = "projection")]
    stabilization: String,
}

/// A number as a message shows it: `1e308` rather than 309 digits.
fn short(v: f64) -> String {
    if v.is_finite() && v != 0.0 && (v.abs() >= 1e6 || v.abs() < 1e-4) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The largest `--rtol` accepted.
pub const MAX_RTOL: f64 = 0.1;

/// The integrator settings of `--method`, `--rtol`, `--dt` and `--stabilization`.
fn integrate_options(a: &IntegratorArgs) -> Result<rbss_runtime::IntegrateOptions, String> {
    use rbss_runtime::{IntegrateOptions, Method, Stabilization};
    let (rtol, dt) = (a.rtol, a.dt);
    // A tolerance beyond 0.1 (or a step that is not a positive number) gives no accuracy at
    // all: refused, rather than a non-physical motion (issue 37).
    let method = match a.method.as_str() {
        "dopri5" | "dop853" if !(rtol > 0.0 && rtol <= MAX_RTOL) => {
            return Err(format!(
                "--rtol {}: must be in (0, {MAX_RTOL}] (a relative tolerance; 1e-6 to 1e-12 are \
                 usual)",
                short(rtol)
            ));
        }
        "rk4" if !(dt > 0.0 && dt.is_finite()) => {
            return Err(format!("--dt {}: must be finite and positive", short(dt)));
        }
        "dopri5" => Method::dopri5(rtol, rtol / 100.0),
        "dop853" => Method::dop853(rtol, rtol / 100.0),
        "rk4" => Method::Rk4 { dt },
        other => {
            return Err(format!(
                "--method {other}: expected dopri5 or dop853 (with --rtol) or rk4 (with --dt)"
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
    crate::trajectory::check_samples(samples)?;
    if !(t_end.is_finite() && t_end > 0.0 && omega.is_finite()) {
        return Err("need a finite --t-end > 0 and a finite --omega".into());
    }
    let opts = crate::paper::PaperOptions {
        omega,
        t_end,
        samples,
        integrate,
    };
    let s = crate::paper::run(std::path::Path::new(out), &opts, &mut |m| say!("rbss: {m}"))?;
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

/// Runs the command; its results (for stdout) go to `stdout`. A subcommand with
/// `--model-file` is not run here but by the robot's library ([`crate::model_file`]; `main`
/// sends it there).
pub fn run(cli: Cli, stdout: &mut String) -> Result<(), String> {
    match cli.cmd {
        Cmd::List {
            model: Some(name),
            json,
            ..
        } => with_robot!(name.as_str(), |model| {
            out!(stdout, "{}", crate::describe::describe(&model, json)?);
            Ok::<(), String>(())
        }),
        Cmd::List { json: true, .. } => {
            let mut all = Vec::new();
            for name in robots::NAMES {
                with_robot!(*name, |model| {
                    all.push(crate::describe::describe_json(&model));
                    Ok::<(), String>(())
                })?;
            }
            let text = serde_json::to_string_pretty(&all)
                .map_err(|e| format!("cannot write JSON: {e}"))?;
            out!(stdout, "{text}");
            Ok(())
        }
        Cmd::List { .. } => {
            let width = robots::NAMES.iter().map(|n| n.len()).max().unwrap_or(0);
            for name in robots::NAMES {
                with_robot!(*name, |model| {
                    out!(stdout, "{}", list_line(name, &model, width));
                    Ok::<(), String>(())
                })?;
            }
            Ok(())
        }
        #[cfg(feature = "studies")]
        Cmd::Stress(cmd) => crate::stress::run(cmd),
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
        Cmd::Cache { cmd } => cache_command(&cmd, stdout),
        Cmd::Library { model_file } => {
            let cache = crate::model_file::Cache::from_env()?;
            let lib =
                crate::model_file::load(&cache, std::path::Path::new(&model_file), &mut |m| {
                    say!("rbss: {m}")
                })?;
            out!(stdout, "{}", lib.path.display());
            Ok(())
        }
        cmd => {
            let Some(robot) = cmd.robot() else {
                return Err("this subcommand takes no --model".to_string());
            };
            let name = robot.name()?.to_string();
            with_robot!(name.as_str(), |model| run_with_model(cmd, model, stdout))
        }
    }
}

/// `rbss list`'s line for a robot: its name (padded to `width`), sizes, actuated and output
/// coordinates.
fn list_line<K: Dynamics<N, M>, const N: usize, const M: usize>(
    name: &str,
    model: &Model<K, N, M>,
    width: usize,
) -> String {
    let s = model.structure();
    let names = |idx: &[usize]| {
        idx.iter()
            .map(|&j| s.coordinates[j])
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "{:<width$} n = {:>2}, m = {:>2}; q = [{}]; outputs = [{}]",
        name,
        s.coordinates.len(),
        s.constraints.len(),
        names(s.actuated),
        names(s.outputs)
    )
}

/// Runs a subcommand that takes `--model` (or `--model-file`) on `model`, whichever robot the
/// option named: the one place that dispatches them, for the robots compiled into the
/// command (through `with_robot!`) and for a robot's library (`export_command!`). The
/// subcommands that take derivatives (and the studies) are here; the others are
/// [`run_without_derivatives`]'s.
pub fn run_with_model<K: DynamicsDerivatives<N, M> + Clone, const N: usize, const M: usize>(
    cmd: Cmd,
    model: Model<K, N, M>,
    stdout: &mut String,
) -> Result<(), String> {
    match cmd {
        Cmd::Linearize {
            state,
            coordinates,
            check,
            ..
        } => {
            let json = crate::simulate::linearize(
                &model,
                &state,
                &check.check()?,
                coordinates == CoordinatesArg::Actuated,
            )?;
            out!(stdout, "{json}");
            Ok(())
        }
        Cmd::IdDerivatives { state, check, .. } => {
            let json = crate::simulate::id_derivatives(&model, &state, &check.check()?)?;
            out!(stdout, "{json}");
            Ok(())
        }
        #[cfg(feature = "studies")]
        Cmd::Bench(cmd) => crate::bench::command(cmd, &model),
        cmd => run_without_derivatives(cmd, model, stdout),
    }
}

/// [`run_with_model`] for a robot generated without the derivative kernel (the library `rbss
/// --model-file` builds for the subcommands that take no derivatives): every subcommand but
/// those that need it, which are an error here (the command builds the model's library with
/// derivatives for them, [`crate::model_file::Variant::Full`]).
pub fn run_without_derivatives<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(
    cmd: Cmd,
    model: Model<K, N, M>,
    stdout: &mut String,
) -> Result<(), String> {
    match cmd {
        Cmd::Ik {
            pose,
            rates,
            json,
            mode,
            ..
        } => {
            let how = mode.solve(None);
            let out = kinematics::ik(
                &kinematics::exact_cond(model),
                &pose,
                rates.as_deref(),
                json,
                how,
            )?;
            stdout.push_str(&out);
            if json {
                out!(stdout);
            }
            Ok(())
        }
        Cmd::Fk {
            q,
            near,
            max_passive_change,
            json,
            mode,
            ..
        } => {
            let how = mode.solve(max_passive_change);
            let out = kinematics::fk(
                &kinematics::exact_cond(model),
                &q,
                near.as_deref(),
                json,
                how,
            )?;
            stdout.push_str(&out);
            if json {
                out!(stdout);
            }
            Ok(())
        }
        Cmd::Eval { states, strict, .. } => {
            let text = crate::read_input(std::path::Path::new(&states))?;
            let ev = crate::eval_states(&model, &text).map_err(|e| format!("{states}: {e}"))?;
            out!(stdout, "{}", ev.json);
            failed_states(&states, &ev, strict, true)
        }
        Cmd::Linearize { .. } | Cmd::IdDerivatives { .. } => Err(format!(
            "robot `{}` was generated without its derivative kernel (`rbss-codegen \
             --no-derivatives`): this subcommand needs it",
            model.structure().name
        )),
        Cmd::Fd {
            state,
            check,
            strict,
            ..
        } => {
            let ev = crate::simulate::fd(&model, &state, &check.check()?)?;
            out!(stdout, "{}", ev.json);
            failed_states(&state, &ev, strict, false)
        }
        Cmd::Simulate {
            state,
            t_end,
            integrator,
            check,
            max_violation,
            out,
            ..
        } => {
            let req = crate::simulate::SimulateRequest {
                model: model.structure().name.to_string(),
                state,
                t_end,
                integrate: integrate_options(&integrator)?,
                out,
                check: check.check()?,
                max_violation,
            };
            out!(stdout, "{}", crate::simulate::simulate(&model, &req)?);
            Ok(())
        }
        Cmd::Roundtrip {
            trajectory,
            t_end,
            integrator,
            out,
            ..
        } => {
            let req = crate::roundtrip::RoundTripRequest {
                model: model.structure().name.to_string(),
                trajectory,
                t_end,
                integrate: integrate_options(&integrator)?,
                out,
            };
            let s = crate::roundtrip::roundtrip(&model, &req)?;
            say!("rbss: {}", s.report);
            out!(
                stdout,
                "round-trip max output error: {:.3e}",
                s.max_output_error
            );
            Ok(())
        }
        Cmd::InverseDynamics {
            trajectory,
            omega,
            t_start,
            t_end,
            samples,
            csv,
            ..
        } => {
            let req = crate::inverse_dynamics::InverseDynamicsRequest {
                model: model.structure().name.to_string(),
                trajectory,
                omega,
                t_start,
                t_end,
                samples,
                csv,
            };
            let report = crate::inverse_dynamics::inverse_dynamics_for(&model, &req)?;
            say!("rbss: {report}");
            Ok(())
        }
        Cmd::List { json, .. } => {
            out!(stdout, "{}", crate::describe::describe(&model, json)?);
            Ok(())
        }
        #[cfg(feature = "studies")]
        Cmd::Bench(_) => Err(format!(
            "robot `{}` was generated without its derivative kernel: `rbss bench` needs the \
             model's studies library",
            model.structure().name
        )),
        _ => Err("this subcommand takes no --model".to_string()),
    }
}

/// The states of `rbss eval` and `rbss fd` (file `path`) whose forward dynamics failed: with
/// `strict`, the error (exit status 1) naming the first (by its index when `indexed`, the
/// states of `rbss eval`); without, a warning on stderr for each and success.
fn failed_states(
    path: &str,
    ev: &crate::Evaluation,
    strict: bool,
    indexed: bool,
) -> Result<(), String> {
    let at = |i: usize| match indexed {
        true => format!("{path}: state {i}"),
        false => path.to_string(),
    };
    if strict {
        return match (indexed, ev.failed.first()) {
            (_, None) => Ok(()),
            (true, Some(_)) => Err(format!("{path}: {}", ev.strict_error().unwrap_or_default())),
            (false, Some((i, e))) => Err(format!("{}: {e} (--strict)", at(*i))),
        };
    }
    for (i, e) in &ev.failed {
        say!(
            "rbss: warning: {}: {e} (its \"error\" entry; --strict to fail)",
            at(*i)
        );
    }
    Ok(())
}

impl Cmd {
    /// The `--model-file` of a subcommand, if given: `main` sends the command line to that
    /// model's library.
    pub fn model_file(&self) -> Option<&str> {
        match self {
            Cmd::List { model_file, .. } => model_file.as_deref(),
            _ => self.robot().and_then(|r| r.model_file.as_deref()),
        }
    }

    /// Whether it needs the robot's derivative kernel (`rbss linearize`, `rbss id-derivatives`):
    /// then its `--model-file` library is the model's full one
    /// ([`crate::model_file::Variant::Full`]).
    pub fn needs_derivatives(&self) -> bool {
        matches!(self, Cmd::Linearize { .. } | Cmd::IdDerivatives { .. })
    }

    /// Whether its `--model-file` library needs the studies (`rbss bench`): then the
    /// library is the model's studies variant ([`crate::model_file::Variant::Studies`]).
    pub fn is_study(&self) -> bool {
        #[cfg(feature = "studies")]
        if let Cmd::Bench(_) = self {
            return true;
        }
        false
    }

    /// The robot option of a subcommand that takes one.
    pub fn robot(&self) -> Option<&RobotArg> {
        match self {
            Cmd::Ik { robot, .. }
            | Cmd::Fk { robot, .. }
            | Cmd::InverseDynamics { robot, .. }
            | Cmd::Roundtrip { robot, .. }
            | Cmd::Eval { robot, .. }
            | Cmd::Fd { robot, .. }
            | Cmd::Linearize { robot, .. }
            | Cmd::IdDerivatives { robot, .. }
            | Cmd::Simulate { robot, .. } => Some(robot),
            #[cfg(feature = "studies")]
            Cmd::Bench(cmd) => Some(cmd.robot()),
            _ => None,
        }
    }
}

/// Writes the results to stdout and the error, if any, to stderr; the exit status: 0, or 1
/// for an error or a failed write. A closed stdout (`| head`) is not a failure (the reader
/// chose to stop; src/main.rs).
pub fn finish(result: Result<(), String>, stdout: &str) -> u8 {
    let mut lock = std::io::stdout().lock();
    match lock
        .write_all(stdout.as_bytes())
        .and_then(|()| lock.flush())
    {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        Err(e) => {
            say!("rbss: error: cannot write the results to stdout: {e}");
            return 1;
        }
    }
    match result {
        Ok(()) => 0,
        Err(e) => {
            say!("rbss: error: {e}");
            1
        }
    }
}

/// The command line `args` (with the program name first) run on `model`: what a robot's
/// library does for `rbss SUBCOMMAND --model-file PATH ...` (see
/// [`crate::export_command!`]). The exit status, as the command's.
pub fn main_with_model<K: DynamicsDerivatives<N, M> + Clone, const N: usize, const M: usize>(
    args: &[String],
    model: Model<K, N, M>,
) -> u8 {
    main_with(args, |cmd, stdout| run_with_model(cmd, model, stdout))
}

/// [`main_with_model`] for a robot generated without the derivative kernel
/// ([`run_without_derivatives`]).
pub fn main_without_derivatives<K: Dynamics<N, M> + Clone, const N: usize, const M: usize>(
    args: &[String],
    model: Model<K, N, M>,
) -> u8 {
    main_with(args, |cmd, stdout| {
        run_without_derivatives(cmd, model, stdout)
    })
}

/// Parses `args` and runs the subcommand with `run`: the exit status.
fn main_with(args: &[String], run: impl FnOnce(Cmd, &mut String) -> Result<(), String>) -> u8 {
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    let mut stdout = String::new();
    let result = run(cli.cmd, &mut stdout);
    finish(result, &stdout)
}
