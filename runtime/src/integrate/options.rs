//! The integrators' settings ([`Method`], [`Stabilization`], [`StepControl`],
//! [`IntegrateOptions`]), what a run reports ([`IntegrateStats`]) and why it stops
//! ([`IntegrateError`]).

use core::fmt;

use crate::algorithm::Baumgarte;
use crate::error::SolverError;

/// Why a simulation ([`Simulator`]) stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IntegrateError {
    /// A solver failed at time `t`: forward dynamics in a right-hand-side evaluation, forward
    /// kinematics or velocity (coordinate partitioning), or a projection.
    Solver {
        /// Time of the failing evaluation (a stage time within the step).
        t: f64,
        /// The solver's error.
        error: SolverError,
    },
    /// The control callback returned an error at time `t`.
    Control {
        /// Time of the failing evaluation.
        t: f64,
        /// The callback's error.
        error: SolverError,
    },
    /// The adaptive step size fell below the rounding level of `t` (`16 ε |t|`): the problem
    /// is stiff or singular there.
    StepSizeTooSmall {
        /// Time of the last accepted step.
        t: f64,
        /// The step size that was too small.
        h: f64,
    },
    /// `IntegrateOptions::max_steps` steps (accepted plus rejected) did not reach the end.
    MaxSteps {
        /// Time of the last accepted step.
        t: f64,
        /// Steps taken (accepted plus rejected).
        steps: usize,
    },
    /// An integration setting is invalid (not finite, not positive, or an end time before the
    /// current time).
    InvalidOptions {
        /// Which setting, e.g. `"rtol"`.
        what: &'static str,
    },
}

/// A time for messages: as Rust prints it between 1e-4 and 1e7 (and 0), in exponent notation
/// outside (`5e299`, not 300 digits), so that a message about a huge or tiny time stays
/// readable.
#[derive(Debug, Clone, Copy)]
pub struct Time(pub f64);

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.0;
        if t != 0.0 && t.is_finite() && !(1e-4..1e7).contains(&t.abs()) {
            write!(f, "{t:e}")
        } else {
            write!(f, "{t}")
        }
    }
}

impl fmt::Display for IntegrateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            IntegrateError::Solver { t, error } => write!(f, "at t = {}: {error}", Time(t)),
            IntegrateError::Control { t, error } => {
                write!(f, "control callback failed at t = {}: {error}", Time(t))
            }
            IntegrateError::StepSizeTooSmall { t, h } => {
                write!(f, "step size {h:e} too small at t = {}", Time(t))
            }
            IntegrateError::MaxSteps { t, steps } => {
                write!(
                    f,
                    "{steps} steps did not reach the end (stopped at t = {})",
                    Time(t)
                )
            }
            IntegrateError::InvalidOptions { what } => {
                write!(f, "invalid integration option {what}")
            }
        }
    }
}

impl std::error::Error for IntegrateError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            IntegrateError::Solver { error, .. } | IntegrateError::Control { error, .. } => {
                Some(error)
            }
            _ => None,
        }
    }
}

/// How the simulation keeps the state consistent with the constraints `f(X) = 0`, `G Ẋ = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stabilization {
    /// Integrate `X, Ẋ` with the plain `G Ẍ = gamma`: the constraint violation grows with the
    /// integration error (drift).
    None,
    /// Baumgarte's stabilisation with these gains: `G Ẍ = gamma - 2 alpha G Ẋ - beta² f`.
    /// [`Stabilization::baumgarte`] uses [`Baumgarte::DEFAULT`] (`alpha = beta = 10 /s`, why
    /// there).
    Baumgarte(Baumgarte),
    /// After each accepted step, project `X` onto `f(X) = 0` (Gauss–Newton with minimum-norm
    /// corrections, to `SolverOptions::tol_f`) and then `Ẋ` onto `G Ẋ = 0`
    /// ([`project_position`], [`project_velocity`]). Restarts the FSAL stage of DOPRI5 and DOP853.
    Projection,
    /// The ODE state is only the actuated `q, q̇`: at each stage the passive coordinates `p`
    /// come from forward kinematics (Newton, warm-started from the last accepted state) and `ṗ`
    /// from forward velocity; forward dynamics then gives `q̈`. The constraints hold at every
    /// stage to Newton's tolerance; fails near singularities of `J_p` (where `q` stops being a
    /// valid chart).
    CoordinatePartitioning,
}

impl Stabilization {
    /// Baumgarte's stabilisation with the default gains [`Baumgarte::DEFAULT`].
    pub const fn baumgarte() -> Self {
        Self::Baumgarte(Baumgarte::DEFAULT)
    }
}

/// The step-size controller of DOPRI5 and DOP853.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepControl {
    /// `h_new = h · clamp(0.9 err^(-1/5), 1/5, 10)`.
    Standard,
    /// Gustafsson's PI controller as in Hairer's `DOPRI5`:
    /// `h_new = h · clamp(0.9 err^(-(1/5 - 0.75 beta)) err_prev^beta, 1/5, 10)`; Hairer's
    /// default is `beta = 0.04`. (`beta = 0` is [`StepControl::Standard`].)
    Pi {
        /// The PI gain `beta` (typically 0.04 to 0.08).
        beta: f64,
    },
}

impl Default for StepControl {
    fn default() -> Self {
        Self::Pi { beta: 0.04 }
    }
}

/// The integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Classic Runge–Kutta 4 with fixed step `dt` (the last step is shortened to land on the
    /// end time). Four right-hand-side evaluations per step.
    Rk4 {
        /// The step (s).
        dt: f64,
    },
    /// Dormand–Prince 5(4), adaptive: a step is accepted when
    /// `sqrt(mean((e_i / (atol + rtol max(|y_i|, |y_new_i|)))²)) <= 1` over the state `y`
    /// (positions and velocities; for coordinate partitioning `q, q̇` only). Six evaluations
    /// per step (FSAL), seven after a projection.
    Dopri5 {
        /// Relative tolerance.
        rtol: f64,
        /// Absolute tolerance (in the state's units: m, rad, m/s, rad/s).
        atol: f64,
        /// First step (s); `0` chooses it automatically (Hairer's `HINIT`, one extra
        /// evaluation).
        h_init: f64,
        /// Largest step (s); `f64::INFINITY` for none.
        h_max: f64,
        /// The step-size controller.
        control: StepControl,
    },
    /// Dormand–Prince 8(5,3), adaptive (Hairer's `DOP853`): eighth order, twelve evaluations
    /// per step (FSAL), the error estimated from a fifth- and a third-order embedded solution
    /// combined as Hairer's (`err = |h| err5² / sqrt(n (err5² + 0.01 err3²))`, the same norms
    /// as DOPRI5's). At tight tolerances it takes far fewer evaluations than DOPRI5 for the
    /// same error (the paper's round trip at rtol 1e-10: BENCHMARKS.md, "Work-precision").
    Dop853 {
        /// Relative tolerance.
        rtol: f64,
        /// Absolute tolerance (in the state's units).
        atol: f64,
        /// First step (s); `0` chooses it automatically (`HINIT` of order 8).
        h_init: f64,
        /// Largest step (s); `f64::INFINITY` for none.
        h_max: f64,
        /// The step-size controller; Hairer's default for DOP853 is `Standard` (the PI form
        /// here is `h_new = h · clamp(0.9 err^(-(1/8 - 0.2 beta)) err_prev^beta, 1/3, 6)`).
        control: StepControl,
    },
}

impl Method {
    /// DOPRI5 with the given tolerances, automatic first step, no step limit, PI control.
    pub fn dopri5(rtol: f64, atol: f64) -> Self {
        Self::Dopri5 {
            rtol,
            atol,
            h_init: 0.0,
            h_max: f64::INFINITY,
            control: StepControl::default(),
        }
    }

    /// DOP853 with the given tolerances, automatic first step, no step limit, Hairer's
    /// standard controller.
    pub fn dop853(rtol: f64, atol: f64) -> Self {
        Self::Dop853 {
            rtol,
            atol,
            h_init: 0.0,
            h_max: f64::INFINITY,
            control: StepControl::Standard,
        }
    }
}

/// Settings of a simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegrateOptions {
    /// The integrator.
    pub method: Method,
    /// What keeps the state on the constraint manifold.
    pub stabilization: Stabilization,
    /// Most steps (accepted plus rejected) before [`IntegrateError::MaxSteps`]. Default 10⁶.
    pub max_steps: usize,
    /// Measure `max |f(X)|` and `max |G Ẋ|` after every accepted step (before any
    /// projection) into [`IntegrateStats`]: one `constraints` and one `jacobian` call per step.
    /// Default `true`.
    pub monitor: bool,
}

impl IntegrateOptions {
    /// The given method and stabilisation, 10⁶ steps at most, monitoring on.
    pub fn new(method: Method, stabilization: Stabilization) -> Self {
        Self {
            method,
            stabilization,
            max_steps: 1_000_000,
            monitor: true,
        }
    }
}

/// What a simulation did so far.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct IntegrateStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected step attempts (DOPRI5 and DOP853 error control).
    pub rejected: usize,
    /// Right-hand-side evaluations: each is one control callback and one
    /// [`forward_dynamics()`](crate::forward_dynamics()) (plus, for coordinate partitioning, one
    /// forward kinematics and one forward velocity).
    pub rhs_evaluations: usize,
    /// Newton steps spent outside the right-hand side's forward dynamics: projections
    /// (position) or the forward kinematics of coordinate partitioning (at the stages and, for
    /// RK4, at the new state).
    pub newton_iterations: usize,
    /// The largest `max |f(X)|` seen at an accepted step, before any projection (with
    /// `IntegrateOptions::monitor`), and at the (projected) initial state.
    pub max_violation: f64,
    /// The largest `max |G Ẋ|` seen likewise.
    pub max_velocity_violation: f64,
    /// `max |ΔX|` of the projection of the initial state onto `f(X) = 0`.
    pub initial_correction: f64,
    /// `max |ΔẊ|` of the projection of the initial velocity onto `G Ẋ = 0`.
    pub initial_velocity_correction: f64,
    /// Smallest accepted step (s) (`inf` before the first step).
    pub h_min: f64,
    /// Largest accepted step (s).
    pub h_max: f64,
}

/// Checks the settings (`InvalidOptions` names the first bad one).
pub(super) fn validate(o: &IntegrateOptions) -> Result<(), IntegrateError> {
    let bad = |what| Err(IntegrateError::InvalidOptions { what });
    let positive = |v: f64| v.is_finite() && v > 0.0;
    match o.method {
        Method::Rk4 { dt } if !positive(dt) => return bad("dt"),
        Method::Dopri5 {
            rtol,
            atol,
            h_init,
            h_max,
            control,
        }
        | Method::Dop853 {
            rtol,
            atol,
            h_init,
            h_max,
            control,
        } => {
            if !(rtol.is_finite() && rtol >= 0.0) {
                return bad("rtol");
            }
            if !(atol.is_finite() && atol >= 0.0) || (atol == 0.0 && rtol == 0.0) {
                return bad("atol");
            }
            if !(h_init.is_finite() && h_init >= 0.0) {
                return bad("h_init");
            }
            if h_max.is_nan() || h_max <= 0.0 {
                return bad("h_max");
            }
            if let StepControl::Pi { beta } = control
                && !(beta.is_finite() && (0.0..0.2).contains(&beta))
            {
                return bad("PI beta (in [0, 0.2))");
            }
        }
        Method::Rk4 { .. } => {}
    }
    if let Stabilization::Baumgarte(b) = o.stabilization
        && !(b.alpha.is_finite() && b.beta.is_finite())
    {
        return bad("Baumgarte gains");
    }
    if o.max_steps == 0 {
        return bad("max_steps");
    }
    Ok(())
}
