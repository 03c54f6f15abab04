//! The immutable half of the Model/Data split (Pinocchio, MuJoCo, Drake): a robot's kernels,
//! its structure and the solver settings. Buffers live in [`Data`](crate::Data).

use nalgebra::SMatrix;

use crate::error::StructureError;
use crate::kernels::{IK_BLOCK_ORDER_UNDECLARED, Structure, uniform_order};
use crate::tasks::Robot;

/// Settings shared by the Newton solvers and the linear (velocity, acceleration) solves.
///
/// Convergence test of Newton (forward kinematics on all M equations, inverse kinematics on
/// each block separately), evaluated at the current iterate `x` with its Newton step `dx`:
///
/// ```text
/// max |f(x)| <= tol_f   AND   max |dx| <= tol_x * (1 + max |x|)
/// ```
///
/// where the maxima run over the block's rows and unknown coordinates. The step that passes the
/// test is applied (Newton's quadratic convergence makes it nearly free accuracy), and the
/// residual reported is measured at the returned point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    /// Absolute tolerance on the constraint residual `max |f|`, in the constraints' units
    /// (metres for position loops). Default `1e-12`.
    pub tol_f: f64,
    /// Relative tolerance on the Newton step: `max |dx| <= tol_x * (1 + max |x|)`.
    /// Default `1e-12`.
    pub tol_x: f64,
    /// Most Newton steps per solve (per block for inverse kinematics). Default `50`.
    pub max_iterations: usize,
    /// A matrix whose 1-norm condition number exceeds this is treated as singular
    /// (`SolverError::Singular`), in every Newton step and every velocity/acceleration solve.
    ///
    /// How the condition number is obtained (the same rule for every solver):
    ///
    /// - Matrices of order at most 16 (`linalg::INVERT_MAX`: the inverse-kinematics blocks,
    ///   3 × 3 for the 6-UPS, 2 × 2 for the five-bar, 9 × 9 for the 3-RPS tripod, 14 × 14 for
    ///   the hybrid Tricept, the reduced 6 × 6 system of inverse dynamics, the five-bar's 4 × 4
    ///   `J_p`) are inverted explicitly; their condition number is exact
    ///   up to rounding, and the test is on that value (so it fires no later than a test on an
    ///   estimate, which is a lower bound).
    /// - Larger matrices get the Hager/Higham estimate (LAPACK's `dlacon`: a lower bound,
    ///   almost always within a factor 3), and the test is on the estimate. Where the value is
    ///   not reported (the intermediate iterates of Newton) or can be had exactly from a
    ///   structure (`S_c` of forward dynamics, see `DynamicsReport::cond`), a cheap rigorous
    ///   upper bound is computed first; when it is at most `cond_max / 2` the matrix is
    ///   certified and the estimator is skipped. This gives the decision the estimator would
    ///   give (a certified matrix's estimate is below `cond_max`) at a fraction of its cost.
    ///
    /// Default `1e7`. Why not higher: at an exact singularity the position solution is a
    /// multiple root, which `f64` resolves only to about `sqrt(ε) ≈ 1.5e-8`, where the condition
    /// number is of order `1/sqrt(ε) ≈ 7e7` (the five-bar test fixture, fully stretched arm:
    /// 2e8 to 1.5e10). A threshold above that lets Newton "converge" at a singular pose instead
    /// of reporting it. Why not lower: a solve at `1e7` still keeps 9 of 16 digits, and regular
    /// poses sit orders of magnitude below it (five-bar: IK blocks at most 12 over the
    /// workspace, `J_p` at most 60 along the test trajectory and about 1e4 a few millimetres
    /// from a parallel singularity).
    ///
    /// The dynamics solvers use the same threshold for the inverse-kinematics blocks and the
    /// reduced system of inverse dynamics, `[S | Gᵀ]`, `S_c = G M⁻¹ Gᵀ` of forward dynamics and
    /// `G Gᵀ` of the projections. On the paper's robot near home (200 random poses,
    /// `runtime/tests/dynamics.rs`) they stay below 2.9 (exact), 23 (exact), 80, 14 (exact)
    /// and 53.
    pub cond_max: f64,
    /// Backtracking: when a Newton step does not decrease `‖f‖₂` of its block by the Armijo
    /// factor `1 - 1e-4 α`, the step length `α` is halved, at most this many times (after which
    /// the shortest step is taken anyway). A trial point with `max |f| <= tol_f` is always
    /// accepted. Default `10`; values above 60 act as 60.
    pub max_step_halvings: u32,
    /// Whether the reports carry the condition number itself where a solve certified its matrix
    /// by a bound. Forward kinematics' elimination onto the outputs (its Newton steps, forward
    /// velocity and acceleration) gets a rigorous upper bound of `cond₁(J_p)` free with the
    /// solve; with `false` (the default) a bound of at most `cond_max / 2` certifies `J_p`, and
    /// the report carries that bound (at least the true value; 6 to 90 times it at the states
    /// measured, see `SolveReport::cond`), the exact value costing a fifth to two fifths of the
    /// solve more. With `true` the exact value is computed for the report. A bound above
    /// `cond_max / 2` always leads to the exact value, so `Singular` is decided on the same
    /// number either way. The `rbss` command asks for the exact value.
    pub exact_cond: bool,
    /// Forward dynamics: the largest normwise relative backward error an answer may carry
    /// (`DynamicsReport::backward_error`). Every answer's backward error is measured; above
    /// `1e-14` it is refined (at most two steps, on the answering path's factors), and if it
    /// is still above this bound the null-space method is tried; if that too stays above,
    /// the solve fails with `SolverError::Inaccurate`. Default `1e-12`: a backward-stable
    /// solve with refinement reaches a few ε (below 1e-15 on every robot measured), so an
    /// answer above 1e-12 means a system at the edge of `cond_max`, not rounding.
    pub backward_error_max: f64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        Self {
            tol_f: 1e-12,
            tol_x: 1e-12,
            max_iterations: 50,
            cond_max: 1e7,
            max_step_halvings: 10,
            exact_cond: false,
            backward_error_max: 1e-12,
        }
    }
}

/// A robot: its kernels `K`, its `Structure` (checked once, at construction) and the solver
/// settings. Immutable in the solvers; `N` coordinates, `M` loop-closure equations.
#[derive(Debug, Clone)]
pub struct Model<K, const N: usize, const M: usize> {
    kernels: K,
    structure: &'static Structure,
    /// Solver settings; change them freely between calls.
    pub options: SolverOptions,
    /// `0..M`: the rows of the forward-kinematics system.
    pub(crate) all_rows: [usize; M],
    /// For each coordinate, its index in `Structure::actuated`, or `usize::MAX` (N).
    pub(crate) actuator_of: [usize; N],
    /// For each coordinate, the index of its inverse-kinematics block in `Structure::ik_blocks`,
    /// or `usize::MAX` for an output (N). Column `j` of `G` is zero outside the rows of
    /// `ik_block_of[j]` (the blocks' rows involve only their columns and the outputs).
    pub(crate) ik_block_of: [usize; N],
}

impl<K: Robot<N, M>, const N: usize, const M: usize> Model<K, N, M> {
    /// Wraps a robot's kernels with default [`SolverOptions`].
    ///
    /// # Panics
    /// If the kernels' `Structure` is inconsistent (see [`Model::try_new`]): a bug in the
    /// generator or the robot, never a matter of run-time input.
    pub fn new(kernels: K) -> Self {
        match Self::try_new(kernels) {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        }
    }

    /// Wraps a robot's kernels, checking that its `Structure` is consistent with `N` and `M`:
    /// name lists of lengths N and M; `actuated` and `passive` disjoint, in range, covering
    /// every coordinate, with `passive.len() >= M` (`== M`, `J_p` square, unless some degrees of
    /// freedom are passive: [`Structure::fully_actuated`](crate::Structure::fully_actuated)); `outputs` a subset of
    /// `passive`; IK blocks square and non-empty, their rows a partition of `0..M` and their
    /// columns a partition of the non-output coordinates (no block without outputs); `home` of length N and finite; the
    /// declared `IK_BLOCK_ORDER`, if any, that of the blocks.
    ///
    /// After this check the solvers index with these sets without any bounds failure.
    pub fn try_new(kernels: K) -> Result<Self, StructureError> {
        let structure = kernels.structure();
        check_structure(structure, N, M)
            .and_then(|()| check_declared_order(structure, K::IK_BLOCK_ORDER))
            .map_err(|message| StructureError {
                robot: structure.name,
                message,
            })?;
        let mut actuator_of = [usize::MAX; N];
        for (a, &j) in structure.actuated.iter().enumerate() {
            // In range: checked above.
            if let Some(slot) = actuator_of.get_mut(j) {
                *slot = a;
            }
        }
        let mut ik_block_of = [usize::MAX; N];
        for (b, blk) in structure.ik_blocks.iter().enumerate() {
            for &j in blk.cols {
                // In range: checked above.
                if let Some(slot) = ik_block_of.get_mut(j) {
                    *slot = b;
                }
            }
        }
        Ok(Self {
            kernels,
            structure,
            options: SolverOptions::default(),
            all_rows: core::array::from_fn(|i| i),
            actuator_of,
            ik_block_of,
        })
    }

    /// Replaces the solver settings (builder style).
    pub fn with_options(mut self, options: SolverOptions) -> Self {
        self.options = options;
        self
    }

    /// The robot's kernels.
    pub fn kernels(&self) -> &K {
        &self.kernels
    }

    /// The robot's structure (checked).
    pub fn structure(&self) -> &'static Structure {
        self.structure
    }
}

/// The block order a robot declares (`Kernels::IK_BLOCK_ORDER`) is the one its structure has:
/// the solvers compile only the declared size, so a wrong one would leave blocks unsolved.
fn check_declared_order(s: &Structure, declared: usize) -> Result<(), String> {
    let actual = uniform_order(s.ik_blocks).unwrap_or(0);
    if declared == IK_BLOCK_ORDER_UNDECLARED || declared == actual {
        Ok(())
    } else {
        Err(format!(
            "IK_BLOCK_ORDER is {declared} but the inverse-kinematics blocks have order {}",
            if actual == 0 {
                "that differs between blocks or is missing (declare 0)".to_string()
            } else {
                actual.to_string()
            }
        ))
    }
}

fn check_structure(s: &Structure, n: usize, m: usize) -> Result<(), String> {
    let len = |what: &str, found: usize, expected: usize| {
        if found == expected {
            Ok(())
        } else {
            Err(format!("{what} has length {found}, expected {expected}"))
        }
    };
    len("coordinates", s.coordinates.len(), n)?;
    len("constraints", s.constraints.len(), m)?;
    len("home", s.home.len(), n)?;
    // At least M passive coordinates (M when every degree of freedom is actuated, more with
    // passive degrees of freedom).
    if s.passive.len() < m {
        return Err(format!(
            "passive has length {}, expected at least M = {m}",
            s.passive.len()
        ));
    }
    len("actuated + passive", s.actuated.len() + s.passive.len(), n)?;
    if let Some(i) = s.home.iter().position(|v| !v.is_finite()) {
        return Err(format!("home[{i}] is not finite"));
    }
    // Gear ratios: none, or one per actuator, finite and nonzero.
    if !s.gear.is_empty() {
        len("gear", s.gear.len(), s.actuated.len())?;
        if let Some(i) = s.gear.iter().position(|g| !g.is_finite() || *g == 0.0) {
            return Err(format!(
                "gear[{i}] = {} is not a finite nonzero ratio",
                s.gear[i]
            ));
        }
    }

    // Every coordinate is exactly one of actuated / passive.
    let mut role = vec![0u8; n];
    for (what, set, tag) in [("actuated", s.actuated, 1u8), ("passive", s.passive, 2u8)] {
        for &j in set {
            match role.get_mut(j) {
                None => return Err(format!("{what} index {j} out of range (N = {n})")),
                Some(r) if *r != 0 => {
                    return Err(format!("coordinate {j} listed twice in actuated/passive"));
                }
                Some(r) => *r = tag,
            }
        }
    }
    let mut is_output = vec![false; n];
    for &j in s.outputs {
        // An output may be actuated too (inverse kinematics takes it as given).
        match role.get(j) {
            Some(1 | 2) if !is_output[j] => is_output[j] = true,
            Some(1 | 2) => return Err(format!("output {j} listed twice")),
            _ => return Err(format!("output {j} out of range (N = {n})")),
        }
    }

    // IK blocks: square, rows partition 0..m, cols partition the non-outputs.
    let mut row_seen = vec![false; m];
    let mut col_seen = vec![false; n];
    for (b, blk) in s.ik_blocks.iter().enumerate() {
        if blk.rows.is_empty() || blk.rows.len() != blk.cols.len() {
            return Err(format!(
                "ik block {b} is not square and non-empty ({} rows, {} cols)",
                blk.rows.len(),
                blk.cols.len()
            ));
        }
        for &i in blk.rows {
            match row_seen.get_mut(i) {
                Some(seen) if !*seen => *seen = true,
                Some(_) => return Err(format!("constraint {i} in two ik blocks")),
                None => return Err(format!("ik block {b}: row {i} out of range (M = {m})")),
            }
        }
        for &j in blk.cols {
            match col_seen.get_mut(j) {
                Some(_) if is_output[j] => {
                    return Err(format!("ik block {b}: column {j} is an output"));
                }
                Some(seen) if !*seen => *seen = true,
                Some(_) => return Err(format!("coordinate {j} in two ik blocks")),
                None => return Err(format!("ik block {b}: column {j} out of range (N = {n})")),
            }
        }
    }
    // Without outputs there is no inverse kinematics and no block (a serial arm, a tree).
    if s.outputs.is_empty() {
        if s.ik_blocks.is_empty() {
            return Ok(());
        }
        return Err("ik blocks without outputs".to_string());
    }
    if let Some(i) = row_seen.iter().position(|s| !s) {
        return Err(format!("constraint {i} is in no ik block"));
    }
    if let Some(j) = (0..n).find(|&j| !is_output[j] && !col_seen[j]) {
        return Err(format!(
            "coordinate {j} is neither an output nor in an ik block"
        ));
    }
    Ok(())
}

/// `out = G v` by columns, using the structure of `G`: column `j` is zero outside the rows of
/// its inverse-kinematics block (`Model::ik_block_of`; a dense column for an output).
pub(crate) fn mat_vec_structured<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    v: &[f64; N],
    out: &mut [f64; M],
) {
    let blocks = model.structure().ik_blocks;
    out.fill(0.0);
    for ((col, &vj), &b) in g.data.0.iter().zip(v).zip(&model.ik_block_of) {
        match blocks.get(b) {
            Some(blk) => {
                for &i in blk.rows {
                    out[i] += col[i] * vj;
                }
            }
            None => {
                for (o, &gij) in out.iter_mut().zip(col) {
                    *o += gij * vj;
                }
            }
        }
    }
}

/// `(Gᵀ l)_j`, using the structure of `G` as [`mat_vec_structured`] does.
pub(crate) fn col_dot_structured<K: Robot<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    g: &SMatrix<f64, M, N>,
    j: usize,
    l: &[f64; M],
) -> f64 {
    let col = &g.data.0[j];
    match model
        .ik_block_of
        .get(j)
        .and_then(|&b| model.structure().ik_blocks.get(b))
    {
        Some(blk) => blk.rows.iter().map(|&i| col[i] * l[i]).sum(),
        None => crate::linalg::dot4(col, l),
    }
}
