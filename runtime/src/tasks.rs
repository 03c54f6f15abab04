//! What a robot can do: one trait per kernel the solvers call, and one per task of a scene.
//!
//! A full generated robot implements [`Kernels`] (and [`Dynamics`] and [`DynamicsDerivatives`]
//! when its model has masses; the last not when generated with `rbss-codegen --no-derivatives`);
//! the blanket impls below give it every trait of this module, so it offers every solver. A
//! *scene* crate (`rbss-codegen --scene FILE`) generates only the kernels its tasks need and
//! implements only the traits of those kernels and tasks. The solvers are bounded by the task
//! they serve, so asking a scene crate for a task it was not generated for is a compile error
//! that names the task:
//!
//! ```text
//! error[E0277]: the trait bound `FiveBar: rbss_runtime::tasks::ForwardDynamics<5, 4>` is not satisfied:
//!               `FiveBar` was generated without the `forward_dynamics` task
//!   = note: add "forward_dynamics" to the `tasks` of its scene file and regenerate
//! ```
//!
//! | task (scene) | trait | kernels | solvers |
//! |---|---|---|---|
//! | `ik` | [`InverseKinematics`] | `constraints`, `closure_check`, `constraints_jacobian_ik`, `ik_block_solve` | `inverse_kinematics` |
//! | `fk` | [`ForwardKinematics`] | `constraints`, `closure_check`, `constraints_jacobian_p`, `forward_rates_solve` | `forward_kinematics`, `forward_kinematics_lm` |
//! | `velocity` | [`Velocity`] | `jacobian`, `ik_block_solve`, `forward_rates_solve` | `inverse_velocity`, `forward_velocity`, `project_velocity` |
//! | `acceleration` (implies `velocity`) | [`Acceleration`] | `jacobian`, `gamma` | `inverse_acceleration`, `forward_acceleration` |
//! | `inverse_dynamics` | [`InverseDynamics`] | `dynamics_terms`, `inverse_dynamics_solve` | `inverse_dynamics`, `inverse_dynamics_dense` |
//! | `forward_dynamics` | [`ForwardDynamics`] | `dynamics_terms`, `constraints`, `forward_dynamics_solve` | `forward_dynamics`, `forward_dynamics_schur` |
//! | `simulate` | [`Simulate`] | those of `forward_dynamics`, `fk`, `velocity` | `Simulator`, `project_position` |
//! | `energy` | [`Energy`] | `energy` | `Energy::energy` |
//! | `derivatives` (implies `forward_dynamics`) | [`Derivatives`] | `dynamics_derivatives` | `forward_dynamics_derivatives`, `linearize`, `rk4_step_derivatives`, `semi_implicit_euler_step`, `semi_implicit_euler_step_derivatives`, `inverse_dynamics_derivatives` (with `inverse_dynamics`) |
//!
//! The `*_solve` entries are the solves the generator emits beside the kernels (optional trait
//! methods that default to `None`: the solvers then take their general paths).
//!
//! The combined solvers need every task they combine: `inverse_kinematics_full` needs `ik`,
//! `velocity` and `acceleration`; `inverse_dynamics_full` needs `ik`, `velocity` and
//! `inverse_dynamics`.
//!
//! A robot without the `forward_dynamics` task does not compile with forward dynamics:
//!
//! ```compile_fail,E0277
//! use rbss_runtime::tasks::{Constraints, InverseKinematics, Robot};
//! use rbss_runtime::{Baumgarte, Data, Model, Structure};
//! # static S: Structure = Structure { name: "one", coordinates: &["q", "x"], constraints: &["c"],
//! #     actuated: &[0], passive: &[1], outputs: &[1], ik_blocks: &[], home: &[0.0, 0.0],
//! #     gear: &[] };
//! struct IkOnly;
//! impl Robot<2, 1> for IkOnly {
//!     fn structure(&self) -> &'static Structure { &S }
//! }
//! impl Constraints<2, 1> for IkOnly {
//!     fn constraints(&self, x: &[f64; 2], f: &mut [f64; 1]) { f[0] = x[0] - x[1]; }
//! }
//! impl InverseKinematics<2, 1> for IkOnly {
//!     fn constraints_jacobian_ik(&self, x: &[f64; 2], f: &mut [f64; 1], g: &mut [[f64; 1]; 2]) {
//!         self.constraints(x, f);
//!         g[0][0] = 1.0;
//!     }
//! }
//! let model = Model::new(IkOnly);
//! let mut data = Data::new(&model);
//! let _ = rbss_runtime::forward_dynamics(&model, &mut data, &[0.0], None, Baumgarte::NONE);
//! ```

use crate::kernels::{
    Dynamics, DynamicsDerivatives, IK_BLOCK_ORDER_UNDECLARED, Kernels, SolveConditioning, Structure,
};

// ---- kernels shared by several tasks ----

/// Every robot: its structure (names, index sets, IK blocks, home), generated in every crate.
pub trait Robot<const N: usize, const M: usize> {
    /// The common order of the inverse-kinematics blocks; see [`Kernels::IK_BLOCK_ORDER`].
    const IK_BLOCK_ORDER: usize = IK_BLOCK_ORDER_UNDECLARED;
    /// The robot's structure.
    fn structure(&self) -> &'static Structure;
    /// The generated solve of one inverse-kinematics block (see [`Kernels::ik_block_solve`]);
    /// generated for the tasks `ik` and `velocity`.
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
    /// The generated solve of forward kinematics' linear system (see
    /// [`Kernels::forward_rates_solve`]); generated for the tasks `fk` and `velocity`.
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
    /// Forward kinematics' Newton step keeping its factors (see
    /// [`Kernels::forward_rates_keep`]); generated with `forward_rates_solve`.
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
    /// Forward kinematics' chord step (see [`Kernels::forward_rates_chord`]); generated with
    /// `forward_rates_solve`.
    fn forward_rates_chord(&self, store: &[f64], rhs: &[f64; M], x: &mut [f64; N]) -> Option<()> {
        let _ = (store, rhs, x);
        None
    }
}

/// The loop-closure kernel `f(X)`, generated for the tasks `ik`, `fk`, `forward_dynamics` and
/// `simulate`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Constraints<{N}, {M}>` is not satisfied: `{Self}` was generated without the `constraints` kernel",
    label = "needs the kernel `constraints`",
    note = "the tasks \"ik\", \"fk\", \"forward_dynamics\" and \"simulate\" generate it: add one to the `tasks` of its scene file and regenerate"
)]
pub trait Constraints<const N: usize, const M: usize>: Robot<N, M> {
    /// Loop closure `f(X)`, length M.
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]);
    /// The names of the loop components checked but not solved; see [`Kernels::closure_checks`].
    fn closure_checks(&self) -> &'static [&'static str] {
        &[]
    }
    /// Those components at `x`; see [`Kernels::closure_check`].
    fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
        let _ = (x, out);
    }
}

/// The constraint Jacobian `G = ∂f/∂X`, generated for the tasks `velocity`, `acceleration` and
/// `simulate`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Jacobian<{N}, {M}>` is not satisfied: `{Self}` was generated without the `jacobian` kernel",
    label = "needs the kernel `jacobian`",
    note = "the tasks \"velocity\", \"acceleration\" and \"simulate\" generate it: add one to the `tasks` of its scene file and regenerate"
)]
pub trait Jacobian<const N: usize, const M: usize>: Robot<N, M> {
    /// Constraint Jacobian `G` (M × N): writes its structural non-zeros.
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]);
}

/// The equations of motion at one state (`G`, `gamma`, `M`, `psi` fused), generated for the
/// tasks `inverse_dynamics`, `forward_dynamics` and `simulate`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::EquationsOfMotion<{N}, {M}>` is not satisfied: `{Self}` was generated without the `dynamics_terms` kernel",
    label = "needs the kernel `dynamics_terms`",
    note = "the tasks \"inverse_dynamics\", \"forward_dynamics\" and \"simulate\" generate it (the model needs masses): add one to the `tasks` of its scene file and regenerate"
)]
pub trait EquationsOfMotion<const N: usize, const M: usize>: Robot<N, M> {
    /// The diagonal blocks of `M` (see [`Dynamics::mass_blocks`]).
    fn mass_blocks(&self) -> &'static [&'static [usize]];
    /// `G`, `gamma`, `M` and `psi` at one state (see [`Dynamics::dynamics_terms`]).
    fn dynamics_terms(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        g: &mut [[f64; M]; N],
        gamma: &mut [f64; M],
        mass: &mut [[f64; N]; N],
        psi: &mut [f64; N],
    );
    /// The generated solve of forward dynamics (see [`Dynamics::forward_dynamics_solve`]);
    /// `None` by default.
    #[allow(clippy::too_many_arguments)]
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
    /// The generated solve of inverse dynamics (see [`Dynamics::inverse_dynamics_solve`]);
    /// `None` by default.
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

// ---- tasks ----

/// The task `ik`: inverse kinematics (`inverse_kinematics`).
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::InverseKinematics<{N}, {M}>` is not satisfied: `{Self}` was generated without the `ik` task",
    label = "needs the task `ik`",
    note = "add \"ik\" to the `tasks` of its scene file and regenerate"
)]
pub trait InverseKinematics<const N: usize, const M: usize>: Constraints<N, M> {
    /// `f` and the inverse-kinematics columns of `G` (one Newton step), fused.
    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]);
}

/// The task `fk`: forward kinematics (`forward_kinematics`, `forward_kinematics_lm`).
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::ForwardKinematics<{N}, {M}>` is not satisfied: `{Self}` was generated without the `fk` task",
    label = "needs the task `fk`",
    note = "add \"fk\" to the `tasks` of its scene file and regenerate"
)]
pub trait ForwardKinematics<const N: usize, const M: usize>: Constraints<N, M> {
    /// `f` and `J_p` (one Newton step), fused.
    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]);
}

/// The task `velocity`: `inverse_velocity`, `forward_velocity`, `project_velocity`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Velocity<{N}, {M}>` is not satisfied: `{Self}` was generated without the `velocity` task",
    label = "needs the task `velocity`",
    note = "add \"velocity\" to the `tasks` of its scene file and regenerate"
)]
pub trait Velocity<const N: usize, const M: usize>: Jacobian<N, M> {}

/// The task `acceleration`: `inverse_acceleration`, `forward_acceleration`; implies `velocity`
/// (whose solve gives the `Xdot` an acceleration needs, with the same kernel).
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Acceleration<{N}, {M}>` is not satisfied: `{Self}` was generated without the `acceleration` task",
    label = "needs the task `acceleration`",
    note = "add \"acceleration\" to the `tasks` of its scene file and regenerate"
)]
pub trait Acceleration<const N: usize, const M: usize>: Velocity<N, M> {
    /// `gamma = -(dG/dt) Xdot` (length M).
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], gamma: &mut [f64; M]);
}

/// The task `inverse_dynamics`: `inverse_dynamics`, `inverse_dynamics_dense`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::InverseDynamics<{N}, {M}>` is not satisfied: `{Self}` was generated without the `inverse_dynamics` task",
    label = "needs the task `inverse_dynamics`",
    note = "add \"inverse_dynamics\" to the `tasks` of its scene file and regenerate"
)]
pub trait InverseDynamics<const N: usize, const M: usize>: EquationsOfMotion<N, M> {}

/// The task `forward_dynamics`: `forward_dynamics`, `forward_dynamics_schur`.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::ForwardDynamics<{N}, {M}>` is not satisfied: `{Self}` was generated without the `forward_dynamics` task",
    label = "needs the task `forward_dynamics`",
    note = "add \"forward_dynamics\" to the `tasks` of its scene file and regenerate"
)]
pub trait ForwardDynamics<const N: usize, const M: usize>:
    EquationsOfMotion<N, M> + Constraints<N, M>
{
}

/// The task `simulate`: the `Simulator` (forward dynamics, with forward kinematics and the
/// velocity solve to recover from a drift and the projections onto the constraints).
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Simulate<{N}, {M}>` is not satisfied: `{Self}` was generated without the `simulate` task",
    label = "needs the task `simulate`",
    note = "add \"simulate\" to the `tasks` of its scene file and regenerate"
)]
pub trait Simulate<const N: usize, const M: usize>:
    ForwardDynamics<N, M> + ForwardKinematics<N, M> + Velocity<N, M>
{
}

/// The task `energy`: kinetic and potential energy.
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Energy<{N}, {M}>` is not satisfied: `{Self}` was generated without the `energy` task",
    label = "needs the task `energy`",
    note = "add \"energy\" to the `tasks` of its scene file and regenerate"
)]
pub trait Energy<const N: usize, const M: usize>: Robot<N, M> {
    /// `[T, Pi]`: kinetic and potential energy.
    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]);
}

/// The task `derivatives`: `forward_dynamics_derivatives`; implies `forward_dynamics` (whose
/// solution the derivatives are taken at).
#[diagnostic::on_unimplemented(
    message = "the trait bound `{Self}: rbss_runtime::tasks::Derivatives<{N}, {M}>` is not satisfied: `{Self}` was generated without the `derivatives` task",
    label = "needs the task `derivatives`",
    note = "add \"derivatives\" to the `tasks` of its scene file and regenerate (a full crate: generate it without `--no-derivatives`)"
)]
pub trait Derivatives<const N: usize, const M: usize>: ForwardDynamics<N, M> {
    /// The derivatives of the equations of motion (see [`Dynamics::dynamics_derivatives`]).
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

// ---- a full robot does everything ----

impl<T: Kernels<N, M>, const N: usize, const M: usize> Robot<N, M> for T {
    const IK_BLOCK_ORDER: usize = <T as Kernels<N, M>>::IK_BLOCK_ORDER;
    fn structure(&self) -> &'static Structure {
        Kernels::structure(self)
    }
    fn ik_block_solve(
        &self,
        block: usize,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        outputs: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        Kernels::ik_block_solve(self, block, g, rhs, outputs, x)
    }
    fn forward_rates_solve(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        actuated: bool,
        exact: bool,
        x: &mut [f64; N],
    ) -> Option<[f64; 2]> {
        Kernels::forward_rates_solve(self, g, rhs, actuated, exact, x)
    }
    fn forward_rates_keep(
        &self,
        g: &[[f64; M]; N],
        rhs: &[f64; M],
        exact: bool,
        x: &mut [f64; N],
        store: &mut [f64],
    ) -> Option<([f64; 2], bool)> {
        Kernels::forward_rates_keep(self, g, rhs, exact, x, store)
    }
    fn forward_rates_chord(&self, store: &[f64], rhs: &[f64; M], x: &mut [f64; N]) -> Option<()> {
        Kernels::forward_rates_chord(self, store, rhs, x)
    }
}

impl<T: Kernels<N, M>, const N: usize, const M: usize> Constraints<N, M> for T {
    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        Kernels::constraints(self, x, f)
    }
    fn closure_checks(&self) -> &'static [&'static str] {
        Kernels::closure_checks(self)
    }
    fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
        Kernels::closure_check(self, x, out)
    }
}

impl<T: Kernels<N, M>, const N: usize, const M: usize> Jacobian<N, M> for T {
    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        Kernels::jacobian(self, x, g)
    }
}

impl<T: Kernels<N, M>, const N: usize, const M: usize> InverseKinematics<N, M> for T {
    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        Kernels::constraints_jacobian_ik(self, x, f, g)
    }
}

impl<T: Kernels<N, M>, const N: usize, const M: usize> ForwardKinematics<N, M> for T {
    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
        Kernels::constraints_jacobian_p(self, x, f, g)
    }
}

impl<T: Kernels<N, M>, const N: usize, const M: usize> Velocity<N, M> for T {}

impl<T: Kernels<N, M>, const N: usize, const M: usize> Acceleration<N, M> for T {
    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], gamma: &mut [f64; M]) {
        Kernels::gamma(self, x, xdot, gamma)
    }
}

impl<T: Dynamics<N, M>, const N: usize, const M: usize> EquationsOfMotion<N, M> for T {
    fn mass_blocks(&self) -> &'static [&'static [usize]] {
        Dynamics::mass_blocks(self)
    }
    fn dynamics_terms(
        &self,
        x: &[f64; N],
        xdot: &[f64; N],
        g: &mut [[f64; M]; N],
        gamma: &mut [f64; M],
        mass: &mut [[f64; N]; N],
        psi: &mut [f64; N],
    ) {
        Dynamics::dynamics_terms(self, x, xdot, g, gamma, mass, psi)
    }
    fn forward_dynamics_solve(
        &self,
        g: &[[f64; M]; N],
        mass: &[[f64; N]; N],
        force: &[f64; N],
        gamma: &[f64; M],
        xddot: &mut [f64; N],
        lambda: &mut [f64; M],
    ) -> Option<SolveConditioning> {
        Dynamics::forward_dynamics_solve(self, g, mass, force, gamma, xddot, lambda)
    }
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
        Dynamics::inverse_dynamics_solve(self, g, mass, psi, xddot, q_forces, u, lambda)
    }
}

impl<T: Dynamics<N, M>, const N: usize, const M: usize> InverseDynamics<N, M> for T {}

impl<T: Dynamics<N, M>, const N: usize, const M: usize> ForwardDynamics<N, M> for T {}

impl<T: Dynamics<N, M>, const N: usize, const M: usize> Simulate<N, M> for T {}

impl<T: Dynamics<N, M>, const N: usize, const M: usize> Energy<N, M> for T {
    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]) {
        Dynamics::energy(self, x, xdot, out)
    }
}

impl<T: DynamicsDerivatives<N, M>, const N: usize, const M: usize> Derivatives<N, M> for T {
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
    ) {
        DynamicsDerivatives::dynamics_derivatives(
            self, x, xdot, xddot, lambda, dr_dx, dr_dxdot, dc_dx, dc_dxdot,
        )
    }
}
