//! The mutable half of the Model/Data split: every buffer the solvers read and write.
//!
//! Each field documents its shape, who writes it and who reads it, the way MuJoCo's `mjdata.h`
//! does. `Data` holds fixed-size arrays, but for the saddle-point buffers of forward dynamics
//! with massless coordinates (`DynamicsScratch::kkt`): [`Data::new`] does not allocate, and no
//! solver call does either but the first saddle-point forward dynamics of a robot with a
//! massless frame, which sizes those buffers once (they are reused after).

use nalgebra::SMatrix;

use crate::factor::{FdFactors, FkFactors};
use crate::linalg;
use crate::model::Model;
use crate::tasks::Robot;

/// Every buffer of one robot with `N` coordinates and `M` constraints.
///
/// A `Data` may be used with any `Model` of the same `N` and `M` (its workspaces are sized by
/// `N` and `M` alone). Keep one `Data` per thread or per independent computation (Pinocchio).
#[derive(Debug, Clone)]
pub struct Data<const N: usize, const M: usize> {
    /// `X`, the coordinates (N), in the order of `Structure::coordinates`.
    /// Set to `Structure::home` by [`Data::new`] and [`Data::set_home`]. Read as the warm start
    /// by `inverse_kinematics` and `forward_kinematics`, which write the solution on success;
    /// read as the configuration by the velocity, acceleration and dynamics solvers; projected
    /// onto `f(X) = 0` by `project_position`.
    pub x: [f64; N],
    /// `Ẋ`, the coordinate velocities (N). Written by `inverse_velocity` and
    /// `forward_velocity` on success, projected by `project_velocity`; read by
    /// `inverse_acceleration` and `forward_acceleration` (through `gamma`) and by the dynamics
    /// solvers.
    pub xdot: [f64; N],
    /// `Ẍ`, the coordinate accelerations (N). Written by `inverse_acceleration` and
    /// `forward_acceleration` on success, and by `forward_dynamics` on success; read by
    /// `inverse_dynamics`.
    pub xddot: [f64; N],
    /// `U`, the control forces on the actuated coordinates, packed (N, of which the first
    /// `N - M` are used; [`Data::u`] is that slice): `u[a]` acts on coordinate
    /// `Structure::actuated[a]` (force for a prism, torque for a revolute joint); the entries
    /// `N - M..` stay zero. Written by `inverse_dynamics` on success; `forward_dynamics` copies
    /// its `u` argument here on success.
    pub u: [f64; N],
    /// `lambda`, the Lagrange multipliers (M): the constraint forces on the coordinates are
    /// `-Gᵀ lambda`. Written by `inverse_dynamics` and `forward_dynamics` on success.
    pub lambda: [f64; M],
    /// `psi(X, Ẋ)` (N): the Coriolis/centrifugal (Christoffel) terms, gravity and the joints'
    /// springs and dampers, on the
    /// right-hand side of `M Ẍ = psi + Q + S U - Gᵀ lambda`. Written by
    /// `Dynamics::dynamics_terms` in `inverse_dynamics` and `forward_dynamics`.
    pub psi: [f64; N],
    /// `f(X)`, the loop-closure residual (M). Written by the fused Newton kernels
    /// (`Kernels::constraints_jacobian_ik`, `constraints_jacobian_p`) and `Kernels::constraints`
    /// in the Newton solvers, and by `project_position`: after a successful solve it is `f(data.x)`, after a
    /// failed one `f` at the last iterate. Also written by `forward_dynamics` when Baumgarte's
    /// `beta != 0`, and by the simulator's monitoring (at the accepted state).
    pub f: [f64; M],
    /// `gamma(X, Ẋ) = -(dG/dt) Ẋ` (M), so that `G Ẍ = gamma`. Written by `Kernels::gamma` in
    /// the acceleration solvers, and by `Dynamics::dynamics_terms` in the dynamics solvers
    /// (without Baumgarte's terms).
    pub gamma: [f64; M],
    /// `G = ∂f/∂X` (M × N), column-major (`g.data.0` is the `[[f64; M]; N]` the kernels write).
    /// Written by `Kernels::jacobian` (velocity, acceleration, projections),
    /// `Dynamics::dynamics_terms` (dynamics), `constraints_jacobian_p` (forward kinematics) and
    /// `constraints_jacobian_ik` (inverse kinematics); each writes only the structural
    /// non-zeros of its columns, so the buffer starts at zero and only kernels ever write it
    /// (hence read-only from outside: [`Data::g`]). Columns a kernel does not write keep older
    /// values.
    pub(crate) g: SMatrix<f64, M, N>,
    /// `M(X)`, the mass matrix (N × N, symmetric, block diagonal by `Dynamics::mass_blocks`),
    /// column-major. Written by `Dynamics::dynamics_terms` in `inverse_dynamics` and
    /// `forward_dynamics`, which writes only the structural non-zeros of its blocks: the buffer
    /// starts at zero and only the kernel writes it (read-only from outside: [`Data::mass`]).
    pub(crate) mass: SMatrix<f64, N, N>,
    /// Solver scratch space.
    pub(crate) ws: Workspace<N, M>,
}

impl<const N: usize, const M: usize> Data<N, M> {
    /// Buffers for `model`'s robot: `x` at `Structure::home`; `G`, `M`, `psi` and `gamma` zero
    /// (the kernels write only their structural non-zeros, e.g. the five-bar's `psi` has no
    /// entry for `x`), and the other fields zero (NaN in debug builds, so that reading a value
    /// no solver wrote shows up).
    pub fn new<K: Robot<N, M>>(model: &Model<K, N, M>) -> Self {
        let unset = if cfg!(debug_assertions) {
            f64::NAN
        } else {
            0.0
        };
        let mut data = Self {
            x: [0.0; N],
            xdot: [unset; N],
            xddot: [unset; N],
            f: [unset; M],
            gamma: [0.0; M],
            u: [0.0; N],
            lambda: [unset; M],
            psi: [0.0; N],
            g: SMatrix::zeros(),
            mass: SMatrix::zeros(),
            ws: Workspace::new(),
        };
        data.set_home(model);
        data
    }

    /// Sets `x` to the model's home assembly (`Structure::home`): the cold start of the
    /// Newton solvers. Velocities and accelerations are left as they are.
    pub fn set_home<K: Robot<N, M>>(&mut self, model: &Model<K, N, M>) {
        // Model::try_new checked home.len() == N.
        for (x, &h) in self.x.iter_mut().zip(model.structure().home) {
            *x = h;
        }
    }

    /// `G = ∂f/∂X` (M × N) as last written by the kernels (see the field's documentation:
    /// only the columns of the last kernel call are current).
    pub fn g(&self) -> &SMatrix<f64, M, N> {
        &self.g
    }

    /// `M(X)` (N × N) as last written by `Dynamics::mass_matrix` (zero outside its blocks).
    pub fn mass(&self) -> &SMatrix<f64, N, N> {
        &self.mass
    }

    /// `U`: the first `N - M` entries of [`Data::u`](Data#structfield.u), in
    /// `Structure::actuated` order.
    pub fn u(&self) -> &[f64] {
        &self.u[..N.saturating_sub(M)]
    }
}

/// The state of one Newton block between kernel evaluations.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BlockState {
    /// Met the convergence test: no more updates.
    pub converged: bool,
    /// A step was taken; the next evaluation tests it for sufficient decrease.
    pub trial: bool,
    /// Newton steps taken.
    pub steps: usize,
    /// Current step length `α` of the trial.
    pub alpha: f64,
    /// Halvings of `α` so far for this step.
    pub halvings: u32,
    /// `‖f_block‖₂` at the last accepted point.
    pub norm_base: f64,
    /// Condition number of the block at the converged point.
    pub cond: f64,
}

/// Scratch buffers of the solvers, sized by `N` and `M` only, grouped by the algorithms that
/// own them; the three vectors at the top are shared by every solve.
#[derive(Debug, Clone)]
pub(crate) struct Workspace<const N: usize, const M: usize> {
    /// The result of a solve before it is committed to `Data` (N). Written and read by Newton
    /// (`algorithm::newton`: the iterate, from the warm start the position solvers copy in;
    /// committed to `data.x` by `inverse_kinematics`, `forward_kinematics`, `project_position`
    /// and by the generated solves of `algorithm::generated`), by the blockwise linear solves
    /// (`algorithm::blockwise::linear_solve`: the rates, committed to `data.xdot` or
    /// `data.xddot`) and by `project_velocity`.
    pub x: [f64; N],
    /// A second vector of length N. Newton: the full step of each block's unknowns, indexed like
    /// `X`. Blockwise linear solves: the packed solution of a block (first `k` entries).
    /// Inverse dynamics: the multipliers of the block elimination (`t`).
    pub dx: [f64; N],
    /// A vector of length M: the right-hand side of the blockwise linear solves and the
    /// projections (`mu`); inverse dynamics' `mu`; the simulator's `G Ẋ` (`integrate`).
    pub rhs: [f64; M],
    /// Newton's own state (`algorithm::newton`).
    pub newton: NewtonScratch<N, M>,
    /// The factors of `G`'s square blocks, written by `algorithm::blockwise::factor_blocks` and
    /// by Newton's general-order path, read by the blockwise linear solves and by inverse
    /// dynamics (which reuses the factors of the rate solves at the same point); the
    /// projections and the dense Schur complement of forward dynamics use the buffers for their
    /// own Gram matrices.
    pub factors: BlockFactors<M>,
    /// Forward kinematics: the factors of `J_p` by elimination onto the outputs, written by
    /// `algorithm::reduced::fk_factor` in Newton's steps and read by `fk_solve`, `fk_cond` and
    /// the rates of forward kinematics.
    pub fk: FkFactors<M>,
    /// Forward and inverse dynamics (`algorithm::forward_dynamics`,
    /// `algorithm::inverse_dynamics`).
    pub dynamics: DynamicsScratch<N, M>,
}

/// Newton's scratch (`algorithm::newton`), besides the shared `Workspace::x` and
/// `Workspace::dx`: written and read within one Newton solve only.
#[derive(Debug, Clone)]
pub(crate) struct NewtonScratch<const N: usize, const M: usize> {
    /// Last accepted Newton iterate, the base of the backtracking (N).
    pub x_base: [f64; N],
    /// Per-block Newton state (at most M blocks, each with at least one row).
    pub states: [BlockState; M],
    /// Forward kinematics' chord steps: the factors of the generated elimination kept by its
    /// last full step (`Kernels::forward_rates_keep`, at most `N²` numbers), read by the steps
    /// after it (`Kernels::forward_rates_chord`).
    pub chord: [[f64; N]; N],
}

/// The factors of `G`'s square blocks (see [`Workspace::factors`]).
#[derive(Debug, Clone)]
pub(crate) struct BlockFactors<const M: usize> {
    /// Factors of the blocks of a blockwise solve, packed one after the other (block `b` of
    /// order `k_b` at offset `Σ_{c<b} k_c²`, column-major): the explicit inverse for
    /// `k_b <= linalg::INVERT_MAX`, the LU factors otherwise (M × M, since `Σ k_b <= M`).
    /// Forward dynamics: the dense `S_c` (the projections use the pivoted QR of `Gᵀ`, no `G Gᵀ`).
    pub lu: [[f64; M]; M],
    /// Row pivots of the LU-factored blocks, packed likewise (block `b` at `Σ_{c<b} k_c`).
    pub piv: [usize; M],
    /// Work space of the condition estimator (2 M); forward dynamics: `work[0]` holds the
    /// Woodbury solve's scratch and `G Ẍ` for the residual.
    pub work: [[f64; M]; 2],
}

/// The scratch of the dynamics solvers (see [`Workspace::dynamics`]); written and read within
/// one call.
#[derive(Debug, Clone)]
pub(crate) struct DynamicsScratch<const N: usize, const M: usize> {
    /// Order-N factors, column-major in the first entries: forward dynamics (Schur complement)
    /// packs the Cholesky factors of the mass blocks one after the other (block `b` of order
    /// `k_b` at offset `Σ_{c<b} k_c²`); inverse dynamics holds the LU factors of the reduced
    /// `U` system (order `N - M`) or of the dense `[S | Gᵀ]` (order N) (N × N).
    pub lu_n: [[f64; N]; N],
    /// Row pivots of `lu_n` (N).
    pub piv_n: [usize; N],
    /// Work space of the condition estimator for `lu_n` (2 N).
    pub work_n: [[f64; N]; 2],
    /// M columns of length N: forward dynamics `Z = L⁻¹ Gᵀ` (column `i` from row `i` of `G`);
    /// inverse dynamics, flattened with leading dimension M, the columns `w_a = G_kk⁻ᵀ e_a` of
    /// the actuators (first `(N - M) M` entries) (N × M); the projections, the pivoted QR of `Gᵀ`.
    pub z: [[f64; N]; M],
    /// Scratch vector (N): the force vector `psi + Q + S U` (forward dynamics) or
    /// `M Ẍ - psi - Q` (inverse dynamics), and a gathered block.
    pub v: [f64; N],
    /// Second scratch vector (N): forward dynamics' `Ẍ` before it is committed; inverse
    /// dynamics' `U`.
    pub v2: [f64; N],
    /// Forward dynamics, the structured solve of `S_c`: `E = D⁻¹ W`, one column of length M per
    /// dense row of `Z` (at most `linalg::SMALL`).
    pub wood: [[f64; M]; linalg::SMALL],
    /// Forward dynamics: the explicit inverses of the inverse-kinematics blocks in the
    /// elimination onto the outputs (`algorithm::forward_dynamics::reduced`).
    pub fd: FdFactors<M>,
    /// Forward dynamics by the LU of the whole saddle-point matrix (`FdSolver::SaddlePointLu`):
    /// the `(N + M)²` matrix, its pivots, right-hand side and estimator work space. Empty until
    /// first needed, then reused.
    pub kkt: SaddlePointBuffers,
    /// The null-space method's factors (`forward_dynamics::null_space`), allocated at its
    /// first use.
    pub ns: crate::factor::NullSpaceBuffers,
    /// What the null-space method's last factorisation found (`None` before the first).
    pub ns_info: Option<crate::factor::Factored>,
    /// The condition estimate of the saddle-point LU's last factorisation.
    pub kkt_cond: f64,
}

/// The buffers of the saddle-point forward dynamics (see [`DynamicsScratch::kkt`]).
#[derive(Debug, Clone, Default)]
pub(crate) struct SaddlePointBuffers {
    pub a: Vec<f64>,
    pub piv: Vec<usize>,
    pub b: Vec<f64>,
    pub work: Vec<f64>,
}

impl<const N: usize, const M: usize> Workspace<N, M> {
    fn new() -> Self {
        Self {
            x: [0.0; N],
            dx: [0.0; N],
            rhs: [0.0; M],
            newton: NewtonScratch {
                x_base: [0.0; N],
                states: [BlockState::default(); M],
                chord: [[0.0; N]; N],
            },
            factors: BlockFactors {
                lu: [[0.0; M]; M],
                piv: [0; M],
                work: [[0.0; M]; 2],
            },
            fk: FkFactors::new(),
            dynamics: DynamicsScratch {
                lu_n: [[0.0; N]; N],
                piv_n: [0; N],
                work_n: [[0.0; N]; 2],
                z: [[0.0; N]; M],
                v: [0.0; N],
                v2: [0.0; N],
                wood: [[0.0; M]; linalg::SMALL],
                fd: FdFactors::new(),
                kkt: SaddlePointBuffers::default(),
                ns: Default::default(),
                ns_info: None,
                kkt_cond: f64::INFINITY,
            },
        }
    }
}
