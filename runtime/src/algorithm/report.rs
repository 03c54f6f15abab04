//! What the solvers report on success: [`SolveReport`] (kinematics), [`DynamicsReport`] and
//! [`DynamicsMethod`] (dynamics).

/// What a successful solve reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    /// Newton steps taken (inverse kinematics: by the slowest block; forward kinematics: its
    /// chord steps included, which converge linearly and so take one or two steps more than
    /// full ones, each far cheaper); `0` for the velocity and acceleration solves, which are
    /// direct.
    pub iterations: usize,
    /// Kernel evaluations. Newton solves: `constraints` + Jacobian pairs, line-search trials
    /// included, so `evaluations - iterations - 1` steps were shortened by backtracking (one
    /// more `constraints` call, not counted, measures the final residual). Direct solves: `1`.
    pub evaluations: usize,
    /// The residual at the returned solution: `max |f(X)|` for the position solvers,
    /// `max |G Ẋ|` for velocity, `max |G Ẍ - gamma|` for acceleration.
    pub residual: f64,
    /// The largest 1-norm condition number among the matrices factored at the returned
    /// solution (`J_p`, or the worst inverse-kinematics block): exact for blocks of order up to
    /// 3, and up to 16 where the runtime's own factorisation ran; for larger blocks solved by
    /// the generated code (`Kernels::ik_block_solve`) the pivots' value `‖K‖₁ max_c 1 / |u_cc|`,
    /// the Hager/Higham estimate where that passes 1e3; the Hager/Higham estimate for the dense
    /// paths (see `SolverOptions::cond_max`). For `J_p` solved by the generated elimination onto
    /// the outputs (forward kinematics and its rates): its rigorous upper bound, free with the
    /// solve (6 to 90 times the exact value at the states measured), unless
    /// `SolverOptions::exact_cond` asks for the exact value; the runtime's own elimination
    /// reports the exact value.
    pub cond: f64,
}

/// Which algorithm a dynamics solve used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DynamicsMethod {
    /// Inverse dynamics by block elimination: one transposed solve per inverse-kinematics
    /// block `G_kk`, then the small reduced system in `U` (order `N - M`).
    BlockElimination,
    /// Inverse dynamics by a dense LU of the N × N matrix `[S | Gᵀ]`.
    DenseLu,
    /// Forward dynamics by the Schur complement `G M⁻¹ Gᵀ` on the block-diagonal `M`.
    SchurComplement,
    /// Forward dynamics by elimination onto the outputs' coordinates: the inverse-kinematics
    /// blocks of `G` eliminated, the small reduced mass matrix `Rᵀ M R` (order: the number of
    /// outputs, 6 for the 6-UPS) solved explicitly.
    Reduced,
    /// Forward dynamics by a dense LU with partial pivoting of the whole saddle-point system
    /// `[M Gᵀ; G 0]` (only on request: `FdSolver::SaddlePointLu`).
    SaddlePoint,
    /// Forward dynamics by the null-space method (the fallback, see
    /// [`forward_dynamics()`](crate::forward_dynamics())): a rank-revealing QR of `Gᵀ`, the
    /// projected mass matrix `Q₂ᵀ M Q₂` by Cholesky, the multipliers (minimum-norm when `G` has
    /// dependent rows) from the orthogonal factor. Takes massless coordinates, redundant
    /// constraints and an `M` whose eigenvalues spread over many decades.
    NullSpace,
}

/// What a successful dynamics solve ([`inverse_dynamics()`](crate::inverse_dynamics()), [`forward_dynamics()`](crate::forward_dynamics())) reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicsReport {
    /// The algorithm used.
    pub method: DynamicsMethod,
    /// Conditioning of the small blocks.
    ///
    /// - Inverse dynamics: the largest 1-norm condition number of the inverse-kinematics
    ///   blocks `G_kk` (block elimination; exact for blocks up to 16 × 16). When a block was
    ///   singular and the solve fell back to the dense LU, the value of that block (`inf` for a
    ///   zero pivot).
    /// - Forward dynamics by elimination onto the outputs ([`DynamicsMethod::Reduced`]): the
    ///   largest 1-norm condition number of the inverse-kinematics blocks `K_b` (exact: they are
    ///   inverted explicitly). By the Schur complement: `max l_ii² / min l_ii²` over the
    ///   Cholesky pivots of all blocks of `M`, a lower bound of the 2-norm condition number of
    ///   `M` (exact for a diagonal `M`). By the null-space method: `|r_00| / |r_(r-1)(r-1)|` of
    ///   the pivoted QR of `Gᵀ`, a lower bound of `G`'s condition number on its range.
    ///   By the LU of the saddle-point system: `inf`.
    pub cond_blocks: f64,
    /// The 1-norm condition number of the main system: the reduced `U` system (block
    /// elimination) or `[S | Gᵀ]` (dense LU) of inverse dynamics, exact for orders up to 16
    /// (`linalg::INVERT_MAX`, the 6 × 6 reduced system of the 6-UPS), else the Hager/Higham
    /// estimate; for forward dynamics `S_c = G M⁻¹ Gᵀ`: exact after its structured solve, the
    /// estimate after the dense one (see [`forward_dynamics()`](crate::forward_dynamics())), and after the elimination
    /// onto the outputs ([`DynamicsMethod::Reduced`]) that of the reduced mass matrix `Rᵀ M R`
    /// that path solves with: its Cholesky pivot ratio `(max l_ii / min l_ii)²` (a lower bound
    /// of the 2-norm value, free with the factor), the Hager/Higham 1-norm estimate when that
    /// ratio passes `cond_max / 100` or 1e6 (the elimination declines above `cond_max`, and the
    /// Schur complement decides `Singular` on the constraints' rank). By the null-space method
    /// ([`DynamicsMethod::NullSpace`]): the Hager/Higham 1-norm estimate of the condition
    /// number of the Jacobi-scaled projected mass matrix `D Q₂ᵀ M Q₂ D`; by the LU of the
    /// saddle-point system, that of the whole matrix.
    /// Above `SolverOptions::cond_max` the solve fails with `Singular` instead.
    pub cond: f64,
    /// The residual of the solved equations at the result. Inverse dynamics:
    /// `max |M Ẍ - psi - Q - S U + Gᵀ lambda|` (forces). Forward dynamics:
    /// `max |G Ẍ - gamma_stab|` (the acceleration constraint, with Baumgarte's terms).
    pub residual: f64,
    /// The numerical rank of `G` the solve used: `M` except after the null-space method with
    /// redundant constraints (dependent rows of `G`, `RANK_TOL` 1e-12 relative), where the
    /// accelerations are still unique but the multipliers are not: `lambda` is then the
    /// minimum-norm one.
    pub rank: usize,
    /// The normwise relative backward error of the answer (∞-norms): forward dynamics
    /// `max(‖F - M Ẍ - Gᵀ lambda‖ / (‖M‖ ‖Ẍ‖ + ‖Gᵀ‖ ‖lambda‖ + ‖F‖),
    /// ‖gamma_stab - G Ẍ‖ / (‖G‖ ‖Ẍ‖ + ‖gamma_stab‖))`, after any refinement (see
    /// [`forward_dynamics()`](crate::forward_dynamics())); the answer is the exact solution of a
    /// system whose data differ from `M, G, F, gamma_stab` by this much relative. Inverse
    /// dynamics: `‖residual‖ / (‖M‖ ‖Ẍ‖ + ‖psi + Q‖ + ‖S‖ ‖U‖ + ‖Gᵀ‖ ‖lambda‖)` of its one
    /// equation.
    pub backward_error: f64,
}
