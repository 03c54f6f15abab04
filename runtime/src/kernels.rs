//! The trait every generated robot implements, and the static description of its structure.
//!
//! A generated crate (`generated/NAME`) writes one plain function per kernel over fixed-size
//! arrays and ends with `impl Kernels<N, M> for Robot`, which only forwards to them. Matrices
//! are column-major `[[f64; ROWS]; COLS]`, the storage of nalgebra's `SMatrix<f64, ROWS, COLS>`.
//!
//! Jacobian kernels write only the structural non-zeros of `G`; every other entry of the
//! buffer is left untouched, so a buffer that starts at zero stays correct for any number of
//! calls. The column-subset kernels (`jacobian_p`, `jacobian_ik`) write the same entries as
//! `jacobian` restricted to their columns.

/// One independent inverse-kinematics subsystem: with the output coordinates given, the
/// constraint rows `rows` involve only the coordinates `cols` (square: `rows.len() == cols.len()`).
/// For a Stewart platform there is one block per leg.
#[derive(Debug, Clone, Copy)]
pub struct IkBlock {
    /// Constraint indices (into `f`).
    pub rows: &'static [usize],
    /// Coordinate indices (into `X`), ascending.
    pub cols: &'static [usize],
}

/// The common order of the inverse-kinematics blocks, if they have one (the fixed-size paths
/// dispatch on it).
pub(crate) fn uniform_order(ik: &[IkBlock]) -> Option<usize> {
    let k = ik.first()?.rows.len();
    ik.iter().all(|b| b.rows.len() == k).then_some(k)
}

/// What codegen knows about a robot at generation time: names, index sets and sizes.
#[derive(Debug, Clone, Copy)]
pub struct Structure {
    /// Robot name, as in the model file.
    pub name: &'static str,
    /// Coordinate names in the order of `X` (length N).
    pub coordinates: &'static [&'static str],
    /// Constraint names in the order of `f` (length M), e.g. `leg1.x`.
    pub constraints: &'static [&'static str],
    /// Indices of the actuated coordinates `q` in `X`, in model order.
    pub actuated: &'static [usize],
    /// Indices of the other coordinates `p` in `X` (ascending); `J_p` has these columns. `M`
    /// of them when every degree of freedom is actuated, more when some are passive (see
    /// [`Structure::fully_actuated`]).
    pub passive: &'static [usize],
    /// Indices of the output (task) coordinates in `X`, e.g. the platform pose; one may be
    /// actuated too (a coordinate in no loop, such as a legged robot's hip: inverse kinematics
    /// takes it as given, inverse dynamics gives its force). Empty when the model names none: inverse kinematics is then unavailable
    /// ([`SolverError::NoOutputs`](crate::SolverError::NoOutputs)) and `ik_blocks` is empty.
    pub outputs: &'static [usize],
    /// Independent inverse-kinematics subsystems; together they cover every constraint row and
    /// every coordinate that is not an output (none without outputs).
    pub ik_blocks: &'static [IkBlock],
    /// A reference assembly (the model's `home` values), length N: the cold start of the solvers.
    pub home: &'static [f64],
    /// The gear ratio of each actuated coordinate, in `actuated` order (the model's `gear`):
    /// `U` is then in the motor's units and the force on the coordinate is `gear * U`
    /// (N or N m). Empty: every ratio is 1 and `U` is the force itself.
    pub gear: &'static [f64],
}

impl Structure {
    /// True when every degree of freedom is actuated (`actuated.len() == N - M`, so
    /// `passive.len() == M` and `J_p` is square). A robot with passive degrees of freedom (a
    /// spring joint with no drive) has fewer: forward dynamics, simulation, inverse kinematics
    /// and the energy work for it, the tasks that need square actuation (forward kinematics,
    /// forward rates, inverse dynamics) return [`SolverError::Underactuated`](crate::SolverError::Underactuated).
    pub fn fully_actuated(&self) -> bool {
        self.passive.len() == self.constraints.len()
    }

    /// `Err(SolverError::NoOutputs)` naming `task` when the robot has no outputs (and so no
    /// inverse-kinematics blocks).
    pub fn require_outputs(&self, task: &'static str) -> Result<(), crate::error::SolverError> {
        if self.outputs.is_empty() {
            Err(crate::error::SolverError::NoOutputs { task })
        } else {
            Ok(())
        }
    }

    /// `Err(SolverError::Underactuated)` naming `task` unless [`Self::fully_actuated`].
    pub fn require_actuated(&self, task: &'static str) -> Result<(), crate::error::SolverError> {
        if self.fully_actuated() {
            Ok(())
        } else {
            Err(crate::error::SolverError::Underactuated {
                task,
                dof: self
                    .coordinates
                    .len()
                    .saturating_sub(self.constraints.len()),
                actuated: self.actuated.len(),
            })
        }
    }
}

/// The ratio of actuator `i` in a [`Structure::gear`] list (1 where the list is empty).
#[inline]
pub fn gear_ratio(gear: &[f64], i: usize) -> f64 {
    gear.get(i).copied().unwrap_or(1.0)
}

/// The value of [`Kernels::IK_BLOCK_ORDER`] for a robot that does not declare it: the solvers
/// then read the order of the inverse-kinematics blocks from `Structure::ik_blocks` at run time,
/// and compile their fixed-size path for every order they specialise (1 to 4).
pub const IK_BLOCK_ORDER_UNDECLARED: usize = usize::MAX;

/// The kernels of one robot with N coordinates and M loop-closure equations.
///
/// Implementations are generated; every method is allocation-free and panic-free for any
/// finite input.
pub trait Kernels<const N: usize, const M: usize> {
    /// The common order of the inverse-kinematics blocks (`0` when they differ or there are
    /// none), as the generator knows it: the solvers specialise to it at compile time and
    /// compile no other block size for this robot. Must agree with `structure().ik_blocks`
    /// (`Model::new` checks it).
    const IK_BLOCK_ORDER: usize = IK_BLOCK_ORDER_UNDECLARED;
    /// The robot's structure.
    fn structure(&self) -> &'static Structure;
    /// Inverse-kinematics block `block` (`structure().ik_blocks[block]`, `K = G[rows, cols]`)
    /// solved by the code the generator emitted for it (over the structural non-zeros of `G`,
    /// with constant indices): `K x[cols] = rhs[rows] - G[rows, outputs] x[outputs]`, the last
    /// term only if `outputs`. Every linear solve of inverse kinematics is one: a Newton step
    /// (`rhs = f`, no outputs), the velocity (`rhs = 0`, `x[outputs]` the output rates), the
    /// acceleration (`rhs = gamma`). Writes `x[cols]` and returns `[cond(K), residual]`: the
    /// 1-norm condition number (exact up to order 3; beyond, `‖K‖₁ max_c 1 / |u_cc|` from the
    /// elimination's pivots, and the Hager/Higham estimate where that passes 1e3) and
    /// `max |K x[cols] - rhs'|` over the block's rows. `None` (`x` unspecified in `cols`)
    /// where a pivot fails the emitted code's threshold test, the block is singular, or the
    /// robot has none: the runtime's general paths then solve. The default has none.
    fn ik_block_solve(
        &self,
        block: usize,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        outputs: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        let _ = (block, g, rhs, outputs, x);
        None
    }
    /// Forward kinematics' linear system `J_p x_p = rhs - J_q x_q` (`J_p`, `J_q` the passive
    /// and actuated columns of `g`; the actuated entries of `x` given, and read only if
    /// `actuated`: else `x_q = 0` and `J_q` is not read) solved by the code the generator
    /// emitted for this robot: elimination onto the outputs, one function per kind of
    /// inverse-kinematics block (each completed to a square block by its actuated columns at the
    /// home), over the structural non-zeros of `G`. Every linear solve of forward kinematics is
    /// one: a Newton step (`rhs = -f`, not `actuated`: `constraints_jacobian_p` writes only
    /// `J_p`), the velocity (`rhs = 0`, `x_q = q̇`), the acceleration (`rhs = gamma`,
    /// `x_q = q̈`). Writes the passive entries of `x` and returns `[c, residual]`: with
    /// `exact`, `c = cond₁(J_p)` (to rounding: `‖J_p⁻¹‖₁` column by column through the
    /// elimination's factors), else the rigorous upper bound `‖J_p‖₁ max_b ‖K_b⁻¹‖₁ (1 + (1 +
    /// ‖T‖₁) ‖A⁻¹‖₁)` (`T = K⁻¹ G_z`, `A` the reduced system; `‖K_b⁻¹‖₁` estimated for blocks
    /// beyond order 3), free with the solve; and `max |J_p x_p + J_q x_q - rhs|`. `None` (`x`
    /// unspecified) where a completed block's condition number passes 1e4, a pivot fails its
    /// threshold test, the reduced system is singular or the robot has none: the runtime's
    /// general paths then solve. The default has none.
    fn forward_rates_solve(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        actuated: bool,
        exact: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        let _ = (g, rhs, actuated, exact, x);
        None
    }
    /// [`forward_rates_solve`](Self::forward_rates_solve) for a Newton step (`x_q = 0`) that
    /// also keeps its factors (every block's `K_b⁻¹` or elimination, `T_b = K_b⁻¹ G_z`, and
    /// `A⁻¹`) in `store`, for the chord steps after it
    /// ([`forward_rates_chord`](Self::forward_rates_chord)): `Some((forward_rates_solve's
    /// result, kept))`, `kept` false (nothing written to `store`) where `store` is too short or
    /// the robot has no chord step. The generated store has at most `N²` entries. The default
    /// solves without keeping.
    fn forward_rates_keep(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        exact: bool,
        x: &mut [f64; N],
        store: &mut [f64],
    ) -> Option<([f64; 2], bool)> {
        let _ = store;
        self.forward_rates_solve(g, rhs, false, exact, x)
            .map(|r| (r, false))
    }
    /// A chord step of forward kinematics: `J_p x_p = rhs` (`x_q = 0`) by the factors that
    /// [`forward_rates_keep`](Self::forward_rates_keep) kept in `store` (of the `J_p` of that
    /// step). Writes the passive entries of `x`, whose certificate is the caller's (Newton's
    /// next `f`); `None` where nothing was kept or the outputs' entries are not finite. The
    /// default has none.
    fn forward_rates_chord(&self, store: &[f64], rhs: &[f64; M], x: &mut [f64; N]) -> Option<()> {
        let _ = (store, rhs, x);
        None
    }
    /// Loop closure `f(X)`, length M.
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]);
    /// The names (`loop.axis`) of the loop components that the loops' `components` leave out
    /// but that depend on `X`: not among the M equations, yet zero wherever a loop's two points
    /// coincide. The solvers' certificate checks them after every position solve (see
    /// [`certify_position`](crate::certify_position)): a loop written with fewer components has
    /// mirror roots (the UR5's tool axis up or down), which only they tell apart. Empty when
    /// every loop states all its components (the default).
    fn closure_checks(&self) -> &'static [&'static str] {
        &[]
    }
    /// Those components at `x`, into `out[..closure_checks().len()]` (a shorter `out` is left
    /// untouched).
    fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
        let _ = (x, out);
    }
    /// Constraint Jacobian `G = ∂f/∂X` (M × N): writes its structural non-zeros.
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]);
    /// The columns of `G` for the passive coordinates `p` (that is, `J_p`).
    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]);
    /// The columns of `G` for every coordinate that is not an output (the IK unknowns).
    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]);
    /// Acceleration term `gamma = -(dG/dt) Xdot`, so that `G Xddot = gamma` (length M).
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], gamma: &mut [f64; M]);
    /// `constraints` and `jacobian_ik` at once (one inverse-kinematics Newton step). Generated
    /// robots override this with a fused kernel that shares their subexpressions.
    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.constraints(x, f);
        self.jacobian_ik(x, g);
    }
    /// `constraints` and `jacobian_p` at once (one forward-kinematics Newton step); fused in
    /// generated robots.
    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        self.constraints(x, f);
        self.jacobian_p(x, g);
    }
}

/// The dynamics kernels of a robot (generated when its model has masses).
///
/// Equations of motion with redundant coordinates (the paper's eqs. 29-32):
/// `M(X) Xddot = psi(X, Xdot) + Q + S U - Gᵀ lambda` and `G Xddot = gamma(X, Xdot)`,
/// where `S` places the control forces `U` on the actuated coordinates.
pub trait Dynamics<const N: usize, const M: usize>: Kernels<N, M> {
    /// The diagonal blocks of `M`: groups of coordinates coupled by inertia, each ascending;
    /// every coordinate is in exactly one block. `M` is zero outside these blocks.
    fn mass_blocks(&self) -> &'static [&'static [usize]];
    /// Mass matrix `M = ∂²T/∂Xdot²` (N × N, symmetric): writes the structural non-zeros of
    /// its blocks, both triangles; other entries are never written.
    fn mass_matrix(&self, x: &[f64; N], out: &mut [[f64; N]; N]);
    /// `psi(X, Xdot) = -(Christoffel terms) - ∂Pi/∂X` (N), with the joints' dampers
    /// `-damping q̇` (`Pi` holds gravity and the joints' springs `½ stiffness (q - rest)²`).
    fn psi(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; N]);
    /// `[T, Pi]`: kinetic energy (from the bodies' velocities, plus the joints' armatures
    /// `½ armature q̇²`) and potential energy of gravity and the joints' springs.
    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]);
    /// `G` (`jacobian`), `gamma`, `M` and `psi` at one state: everything the equations of
    /// motion need. Generated robots override this with a fused kernel.
    fn dynamics_terms(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        g: &mut [[f64; M]; N],
        gamma: &mut [f64; M],
        mass: &mut [[f64; N]; N],
        psi: &mut [f64; N],
    ) {
        self.jacobian(x, g);
        self.gamma(x, xdot, gamma);
        self.mass_matrix(x, mass);
        self.psi(x, xdot, psi);
    }
    /// Forward dynamics' saddle-point system `M Ẍ + Gᵀ lambda = force`, `G Ẍ = gamma`, solved
    /// by the code the generator emitted for this robot (the elimination onto the outputs,
    /// straight-line over the structural non-zeros of `G` and `M`), from the outputs of
    /// [`dynamics_terms`](Self::dynamics_terms): writes `xddot` and `lambda` and returns the
    /// conditioning it read off its factors, or `None` (outputs unspecified) where its
    /// structure does not hold numerically (a pivot its threshold test refuses, a singular
    /// block, `Rᵀ M R` not positive definite) or the robot has none: the runtime's general
    /// paths then solve. The default has none.
    fn forward_dynamics_solve(
        &self,
        g: &[[f64; M]; N],
        mass: &[[f64; N]; N],
        force: &[f64; N],
        gamma: &[f64; M],
        xddot: &mut [f64; N],
        lambda: &mut [f64; M],
    ) -> Option<SolveConditioning> {
        let _ = (g, mass, force, gamma, xddot, lambda);
        None
    }
    /// Inverse dynamics' system `[S | Gᵀ] [U; -lambda] = b` (`b = M Ẍ - psi - Q`, from `mass`,
    /// `psi`, `xddot` and `q_forces`), solved by the code the generator emitted for this robot (the block elimination onto the actuators,
    /// over the structural non-zeros of `G`): writes `u` (the `N - M` control forces, in
    /// `Structure::actuated` order) and `lambda`, and returns the blocks' condition, the exact
    /// condition number of the reduced system `A` (in `reduced`) and the residual of all N
    /// equations; `None` (outputs unspecified) where its structure does not hold numerically or
    /// the robot has none. The default has none.
    #[allow(clippy::too_many_arguments)]
    fn inverse_dynamics_solve(
        &self,
        g: &[[f64; M]; N],
        mass: &[[f64; N]; N],
        psi: &[f64; N],
        xddot: &[f64; N],
        q_forces: Option<&[f64; N]>,
        u: &mut [f64],
        lambda: &mut [f64; M],
    ) -> Option<SolveConditioning> {
        let _ = (g, mass, psi, xddot, q_forces, u, lambda);
        None
    }
}

/// The derivative kernel of a robot's equations of motion: generated beside [`Dynamics`]
/// unless the robot was generated without it (`rbss-codegen --no-derivatives`, the library
/// `rbss --model-file` builds for the subcommands that take no derivatives). The solvers of
/// the `derivatives` task ([`crate::tasks::Derivatives`]) need it.
pub trait DynamicsDerivatives<const N: usize, const M: usize>: Dynamics<N, M> {
    /// First derivatives of the equations of motion at one state, given `xddot` and `lambda`:
    /// `dr_dx = ∂r/∂X`, `dr_dxdot = ∂r/∂Xdot` (N × N) of the inverse-dynamics residual
    /// `r = M(X) Ẍ - psi(X, Ẋ) + G(X)ᵀ lambda`, and `dc_dx = ∂c/∂X`, `dc_dxdot = ∂c/∂Xdot`
    /// (M × N) of the acceleration constraint `c = G(X) Ẍ - gamma(X, Ẋ)`; column-major. Writes
    /// only the structural non-zeros (a buffer that starts at zero stays correct).
    #[allow(clippy::too_many_arguments)]
    fn dynamics_derivatives(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        xddot: &[f64; N],
        lambda: &[f64; M],
        dr_dx: &mut [[f64; N]; N],
        dr_dxdot: &mut [[f64; N]; N],
        dc_dx: &mut [[f64; M]; N],
        dc_dxdot: &mut [[f64; M]; N],
    );
}

/// What a generated solve read off its factors (see [`Dynamics::forward_dynamics_solve`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveConditioning {
    /// The largest 1-norm condition number of the inverse-kinematics blocks: exact for blocks
    /// of order up to 3 (explicit inverses); for larger ones, from the elimination's pivots
    /// (`‖K‖₁ max_c 1 / |u_cc|`), the Hager/Higham estimate where that passes 1e3.
    pub blocks: f64,
    /// The Cholesky pivot ratio `max d_i / min d_i` of the reduced mass matrix `Rᵀ M R`
    /// (`d_i = l_ii²`): a lower bound of its 2-norm condition number.
    pub reduced: f64,
    /// The certificate: `max_i |(G Ẍ)_i - gamma_i|`, the residual of the acceleration
    /// constraint at the solution.
    pub residual: f64,
    /// Forward dynamics: the answer's normwise relative backward error, as
    /// [`forward_dynamics`](crate::forward_dynamics) defines it (the residuals of both
    /// equations, ∞-norms), formed by the solve from its structure; NaN where the solve does
    /// not form it (inverse dynamics, or a structure it does not cover): the runtime then does.
    pub backward_error: f64,
}
