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
        /// 1-norm condition number of the matrix: exact (explicit inverse) for orders up to
        /// 16 (`linalg::INVERT_MAX`), else the Hager/Higham estimate (see
        /// `SolverOptions::cond_max`).
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
    /// A position solve converged to a root of the equations solved that does not close a loop
    /// component the model leaves out of them (`Kernels::closure_checks`): a mirror root, not the
    /// configuration asked for (see `certify_position`).
    SpuriousRoot {
        /// The component, an index into `Kernels::closure_checks`.
        check: usize,
        /// Its value there (in the loop's units, m for a position loop).
        residual: f64,
    },
    /// A solution, or a step of a continuation, in another assembly mode than the start: the
    /// sign of a part of the `ModeSignature` changed.
    ModeChange {
        /// The part whose determinant changed sign.
        part: ModePart,
        /// Its sign at the start.
        start: i8,
        /// Its sign at the solution (or at the end of the failing step).
        found: i8,
        /// For a continuation, the fraction of the way where it happened (1 for a direct solve).
        t: f64,
    },
    /// A continuation could not go on: steps of the shortest length still fail to converge
    /// quickly (a singularity of `J_p` or of an inverse-kinematics block, or the limit of the
    /// reach, lies on the straight path from the start).
    PathStalled {
        /// The fraction of the way reached.
        t: f64,
        /// `max |f|` at the last failing try.
        residual: f64,
    },
    /// The robot has passive degrees of freedom (fewer actuated coordinates than degrees of
    /// freedom: [`Structure::fully_actuated`](crate::Structure::fully_actuated) is false), and
    /// the task needs one actuated coordinate per degree of freedom: forward kinematics (the
    /// actuated values do not determine the configuration), forward velocity and acceleration,
    /// inverse dynamics (`[S | Gᵀ]` is not square: the outputs' motion is not reachable by
    /// the actuators in general), coordinate partitioning. Forward dynamics, simulation with
    /// projection or Baumgarte stabilisation, inverse kinematics and the energy need no
    /// actuation and work.
    Underactuated {
        /// The task refused, e.g. `"forward kinematics"`.
        task: &'static str,
        /// Degrees of freedom, `N - M`.
        dof: usize,
        /// Actuated coordinates.
        actuated: usize,
    },
    /// The robot has no outputs (its model names none: a serial arm or a tree imported as
    /// it comes, a model for dynamics only), and the task solves for the other coordinates
    /// given the outputs: inverse kinematics, velocity and acceleration, and their paths.
    /// Forward and inverse dynamics, simulation, forward kinematics and the energy need none.
    NoOutputs {
        /// The task refused, e.g. `"inverse kinematics"`.
        task: &'static str,
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
    /// Forward dynamics: no algorithm (iterative refinement included) met
    /// `SolverOptions::backward_error_max`; the best answer's normwise relative backward error
    /// (see `DynamicsReport::backward_error`) was `backward_error`. The answer is not returned.
    Inaccurate {
        /// The achieved relative backward error.
        backward_error: f64,
        /// The bound it exceeds (`SolverOptions::backward_error_max`).
        bound: f64,
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
            SolverError::SpuriousRoot { check, residual } => write!(
                f,
                "converged to a spurious root: unsolved loop component {check} is {residual:e} \
                 from closing (a mirror root of the equations solved)"
            ),
            SolverError::ModeChange {
                part,
                start,
                found,
                t,
            } => write!(
                f,
                "another assembly mode than the start: the sign of det({part}) changed from \
                 {start:+} to {found:+} (at {t} of the way)"
            ),
            SolverError::PathStalled { t, residual } => write!(
                f,
                "the continuation stalled at {t} of the way (max |f| = {residual:e}): a \
                 singularity or the limit of the reach lies on the straight path from the start"
            ),
            SolverError::Dimension {
                what,
                expected,
                found,
            } => write!(f, "{what} has length {found}, expected {expected}"),
            SolverError::Inaccurate {
                backward_error,
                bound,
            } => write!(
                f,
                "forward dynamics reached a relative backward error of only {backward_error:.2e} \
                 (bound {bound:.0e}, SolverOptions::backward_error_max), after iterative \
                 refinement and the null-space method"
            ),
            SolverError::NoOutputs { task } => write!(
                f,
                "{task} is unavailable: the robot has no outputs, and {task} solves for the \
                 other coordinates given them; name them in the model's `[robot] outputs` \
                 (forward and inverse dynamics, simulation and the energy need none)"
            ),
            SolverError::Underactuated {
                task,
                dof,
                actuated,
            } => write!(
                f,
                "{task} is unavailable: the robot has {dof} degrees of freedom but {actuated} \
                 actuated coordinate{} (the others are passive), and {task} needs one actuated \
                 coordinate per degree of freedom; forward dynamics, simulation and the energy \
                 do not",
                if actuated == 1 { "" } else { "s" }
            ),
        }
    }
}

impl std::error::Error for SolverError {}

/// A part of an assembly-mode signature (`ModeSignature`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModePart {
    /// The inverse-kinematics block of this index in `Structure::ik_blocks` (one leg).
    Block(usize),
    /// `J_p`, the Jacobian of forward kinematics.
    Jp,
}

impl fmt::Display for ModePart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModePart::Block(b) => write!(f, "IK block {b}"),
            ModePart::Jp => write!(f, "J_p"),
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
