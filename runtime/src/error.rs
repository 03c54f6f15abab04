//! Typed errors of the solvers and of model construction.
//!
//! A solver never returns a silent NaN and never panics: every failure is one of the
//! [`SolverError`] variants, carrying the numbers that explain it.

use core::fmt;

/// Why a solver call failed. On error the solver's outputs (`data.x`, `data.xdot` or
/// `data.xddot`; for the dynamics `data.xddot`, `data.u` and `data.lambda`) are left as they
/// were on entry; `data.f`, `data.gamma`, `data.g`, `data.mass` and `data.psi` hold the last
/// kernel evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SolverError {
    /// Newton's method used up `SolverOptions::max_iterations` without meeting the convergence
    /// test.
    NotConverged {
        /// Newton steps taken (for inverse kinematics: by the slowest block).
        iterations: usize,
        /// `max |f|` over all constraints at the last iterate.
        residual: f64,
    },
    /// The linear system to solve is (numerically) singular: its 1-norm condition number
    /// exceeds `SolverOptions::cond_max`, or a pivot was exactly zero (`cond` is then
    /// infinite). At a robot singularity the solution is not locally unique.
    Singular {
        /// 1-norm condition number of the matrix: exact for orders up to 4, else the
        /// Hager/Higham estimate (see `SolverOptions::cond_max`).
        cond: f64,
        /// Which matrix, e.g. `"J_p"` or `"IK block G_r"`.
        what: &'static str,
        /// For inverse kinematics: the index of the block in `Structure::ik_blocks`.
        block: Option<usize>,
    },
    /// Inverse kinematics: the pose is out of reach of a leg. Newton failed, and the least
    /// squares of the block's constraints from the same start stop at a minimum that is not a
    /// root (`max |f_b|` there well above `tol_f`).
    Unreachable {
        /// The index of the block in `Structure::ik_blocks` (its `rows` name the constraints,
        /// e.g. `leg3.x, leg3.y, leg3.z`); of several unreachable blocks, the one with the
        /// largest least residual.
        block: usize,
        /// The least `max |f_b|` found: how far the leg stays from closing (in the
        /// constraints' units, metres for a position loop).
        residual: f64,
    },
    /// A NaN or infinity in an input or an intermediate value.
    NonFinite {
        /// Which value, e.g. `"q"`, `"data.x"` or `"f"`.
        what: &'static str,
    },
    /// A matrix that must be symmetric positive definite is not: a block of the mass matrix
    /// `M` (a bug in the model or its kernels: a body without mass or inertia along some
    /// coordinate), or the Gram matrix `G Gᵀ` / `G M⁻¹ Gᵀ` of a rank-deficient `G` (reported as
    /// `Singular` instead, since that is a singularity of the mechanism).
    NotPositiveDefinite {
        /// Which matrix, e.g. `"mass block"`.
        what: &'static str,
        /// The index of the block (for `M`: in `Dynamics::mass_blocks`).
        block: Option<usize>,
        /// The pivot column, within the block, that was not positive.
        column: usize,
    },
    /// An input slice has the wrong length.
    Dimension {
        /// Which input, e.g. `"outputs"`.
        what: &'static str,
        /// Its required length (from the model's `Structure`).
        expected: usize,
        /// The length given.
        found: usize,
    },
}

impl fmt::Display for SolverError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SolverError::NotConverged {
                iterations,
                residual,
            } => write!(
                f,
                "Newton did not converge in {iterations} iterations (max |f| = {residual:e})"
            ),
            SolverError::Singular { cond, what, block } => {
                write!(f, "singular {what}")?;
                if let Some(b) = block {
                    write!(f, " (block {b})")?;
                }
                write!(f, ": estimated condition number {cond:e}")
            }
            SolverError::Unreachable { block, residual } => write!(
                f,
                "the pose is out of reach: IK block {block} cannot close (its least max |f| is \
                 {residual:e})"
            ),
            SolverError::NonFinite { what } => write!(f, "non-finite value (NaN or inf) in {what}"),
            SolverError::NotPositiveDefinite {
                what,
                block,
                column,
            } => {
                write!(f, "{what}")?;
                if let Some(b) = block {
                    write!(f, " {b}")?;
                }
                write!(
                    f,
                    " is not positive definite (pivot {column} is not positive)"
                )
            }
            SolverError::Dimension {
                what,
                expected,
                found,
            } => write!(f, "{what} has length {found}, expected {expected}"),
        }
    }
}

impl std::error::Error for SolverError {}

/// Why a simulation ([`Simulator`](crate::integrate::Simulator)) stopped.
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

impl fmt::Display for IntegrateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            IntegrateError::Solver { t, error } => write!(f, "at t = {t}: {error}"),
            IntegrateError::Control { t, error } => {
                write!(f, "control callback failed at t = {t}: {error}")
            }
            IntegrateError::StepSizeTooSmall { t, h } => {
                write!(f, "step size {h:e} too small at t = {t}")
            }
            IntegrateError::MaxSteps { t, steps } => {
                write!(
                    f,
                    "{steps} steps did not reach the end (stopped at t = {t})"
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

/// A kernels value whose `Structure` is inconsistent (a bug in the generator or in a
/// hand-written robot), found by `Model::try_new`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StructureError {
    /// The robot's name (`Structure::name`).
    pub robot: &'static str,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for StructureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "invalid structure of robot `{}`: {}",
            self.robot, self.message
        )
    }
}

impl std::error::Error for StructureError {}
