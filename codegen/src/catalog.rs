//! The catalogue of what a generated crate offers: the kernels and the generated solves, in
//! emission order, the runtime traits whose methods forward to them, and the tasks of a scene
//! with the kernels each one needs.
//!
//! Everything else is derived from it or checked against it: the back end emits the kernels in
//! [`KERNELS`] order and writes every trait `impl` from [`Kernel::methods`] (the same
//! forwarding for the full crate and for a scene); the scene reader's tasks and their kernels
//! are [`Task`]; `codegen/tests/catalog.rs` checks the runtime's traits
//! (`runtime/src/kernels.rs`, `runtime/src/tasks.rs`), the `rbss` command's counting robot
//! (`src/solver_table.rs`) and the tests' wrapping robots method by method against it. Adding a
//! kernel means: an entry in [`KERNELS`] (and in [`Task::kernels`] for the tasks that call it),
//! the code that computes it (`backend::kernels` or `solve`), and its method in the runtime's
//! trait, which the test checks.

/// A task of a scene: a group of runtime solvers, and the kernels they call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Task {
    Ik,
    Fk,
    Velocity,
    Acceleration,
    InverseDynamics,
    ForwardDynamics,
    Simulate,
    Energy,
    Derivatives,
}

impl Task {
    /// Every task, in the order of the scene format's documentation.
    pub const ALL: [Task; 9] = [
        Task::Ik,
        Task::Fk,
        Task::Velocity,
        Task::Acceleration,
        Task::InverseDynamics,
        Task::ForwardDynamics,
        Task::Simulate,
        Task::Energy,
        Task::Derivatives,
    ];

    /// The task's name in a scene file.
    pub fn name(self) -> &'static str {
        match self {
            Task::Ik => "ik",
            Task::Fk => "fk",
            Task::Velocity => "velocity",
            Task::Acceleration => "acceleration",
            Task::InverseDynamics => "inverse_dynamics",
            Task::ForwardDynamics => "forward_dynamics",
            Task::Simulate => "simulate",
            Task::Energy => "energy",
            Task::Derivatives => "derivatives",
        }
    }

    /// The task of a name in a scene file.
    pub fn from_name(s: &str) -> Option<Task> {
        Task::ALL.into_iter().find(|t| t.name() == s)
    }

    /// The trait of `rbss_runtime::tasks` that offers the task's solvers.
    pub fn trait_name(self) -> &'static str {
        match self {
            Task::Ik => "InverseKinematics",
            Task::Fk => "ForwardKinematics",
            Task::Velocity => "Velocity",
            Task::Acceleration => "Acceleration",
            Task::InverseDynamics => "InverseDynamics",
            Task::ForwardDynamics => "ForwardDynamics",
            Task::Simulate => "Simulate",
            Task::Energy => "Energy",
            Task::Derivatives => "Derivatives",
        }
    }

    /// The other tasks this one implies: the simulator recovers with forward kinematics and
    /// the velocity solve, and steps with forward dynamics; an acceleration needs the velocity
    /// (the same kernel, `jacobian`); the derivatives of forward dynamics solve it first.
    pub fn implies(self) -> &'static [Task] {
        match self {
            Task::Simulate => &[Task::ForwardDynamics, Task::Fk, Task::Velocity],
            Task::Derivatives => &[Task::ForwardDynamics],
            Task::Acceleration => &[Task::Velocity],
            _ => &[],
        }
    }

    /// The generated kernels the task's own solvers call (without those of [`Task::implies`]).
    pub fn kernels(self) -> &'static [&'static str] {
        match self {
            Task::Ik => &[
                "constraints",
                "closure_check",
                "constraints_jacobian_ik",
                "ik_block_solve",
            ],
            Task::Fk => &[
                "constraints",
                "closure_check",
                "constraints_jacobian_p",
                "forward_rates_solve",
            ],
            Task::Velocity => &["jacobian", "ik_block_solve", "forward_rates_solve"],
            Task::Acceleration => &["jacobian", "gamma"],
            Task::InverseDynamics => &["dynamics_terms", "inverse_dynamics_solve"],
            Task::ForwardDynamics => &["dynamics_terms", "constraints", "forward_dynamics_solve"],
            Task::Simulate => &[],
            Task::Energy => &["energy"],
            Task::Derivatives => &["dynamics_derivatives"],
        }
    }

    /// Whether the task needs the model's masses.
    pub fn needs_dynamics(self) -> bool {
        matches!(
            self,
            Task::InverseDynamics
                | Task::ForwardDynamics
                | Task::Simulate
                | Task::Energy
                | Task::Derivatives
        )
    }
}

/// A trait of the runtime that a generated crate implements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trait {
    /// `rbss_runtime::Kernels`, of a full crate.
    Kernels,
    /// `rbss_runtime::Dynamics`, of a full crate whose model has masses.
    Dynamics,
    /// `rbss_runtime::DynamicsDerivatives`, of a full crate whose model has masses, unless it
    /// was generated without the derivative kernel.
    DynamicsDerivatives,
    /// `rbss_runtime::tasks::Robot`, of every scene.
    Robot,
    /// `rbss_runtime::tasks::Constraints`, of a scene with the kernel `constraints`.
    Constraints,
    /// `rbss_runtime::tasks::Jacobian`, of a scene with the kernel `jacobian`.
    Jacobian,
    /// `rbss_runtime::tasks::EquationsOfMotion`, of a scene with `dynamics_terms`.
    EquationsOfMotion,
    /// The trait of a task (`rbss_runtime::tasks::InverseKinematics`, ...).
    Task(Task),
}

/// The traits of a full crate, in the order of their `impl`s.
pub const FULL_TRAITS: [Trait; 3] = [Trait::Dynamics, Trait::DynamicsDerivatives, Trait::Kernels];

/// The kernels' traits of a scene, in the order of their `impl`s (the tasks' traits follow, in
/// [`Task::ALL`] order).
pub const SCENE_TRAITS: [Trait; 4] = [
    Trait::Robot,
    Trait::Constraints,
    Trait::Jacobian,
    Trait::EquationsOfMotion,
];

impl Trait {
    /// The trait's name in the runtime's source.
    pub fn name(self) -> &'static str {
        match self {
            Trait::Kernels => "Kernels",
            Trait::Dynamics => "Dynamics",
            Trait::DynamicsDerivatives => "DynamicsDerivatives",
            Trait::Robot => "Robot",
            Trait::Constraints => "Constraints",
            Trait::Jacobian => "Jacobian",
            Trait::EquationsOfMotion => "EquationsOfMotion",
            Trait::Task(t) => t.trait_name(),
        }
    }

    /// The trait's path in a generated crate (which imports `Kernels`).
    pub fn path(self) -> String {
        match self {
            Trait::Kernels => "Kernels".to_string(),
            Trait::Dynamics => "rbss_runtime::Dynamics".to_string(),
            Trait::DynamicsDerivatives => "rbss_runtime::DynamicsDerivatives".to_string(),
            t => format!("rbss_runtime::tasks::{}", t.name()),
        }
    }

    /// The runtime file that defines the trait, relative to the workspace root.
    pub fn source(self) -> &'static str {
        match self {
            Trait::Kernels | Trait::Dynamics | Trait::DynamicsDerivatives => {
                "runtime/src/kernels.rs"
            }
            _ => "runtime/src/tasks.rs",
        }
    }

    /// The methods the back end writes at the head of the trait's `impl` from the robot's
    /// structure, not from a kernel: `structure` (after the constant `IK_BLOCK_ORDER`) and
    /// `mass_blocks`.
    pub fn head(self) -> &'static [Method] {
        match self {
            Trait::Kernels | Trait::Robot => &[STRUCTURE],
            Trait::Dynamics | Trait::EquationsOfMotion => &[MASS_BLOCKS],
            _ => &[],
        }
    }

    /// Every trait of the catalogue.
    pub fn all() -> Vec<Trait> {
        let mut all = FULL_TRAITS.to_vec();
        all.extend(SCENE_TRAITS);
        all.extend(Task::ALL.map(Trait::Task));
        all
    }
}

/// One method of a runtime trait, as a generated crate writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Method {
    pub name: &'static str,
    /// The arguments after `&self`: name and type, as Rust source.
    pub args: &'static [(&'static str, &'static str)],
    /// The return type as Rust source; empty for `()`.
    pub ret: &'static str,
    pub body: Body,
}

/// What a generated trait method does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Body {
    /// Calls the kernel of the same name with the robot's constants: `NAME(&self.c, args...)`.
    Kernel,
    /// Calls the generated solve of the same name: `NAME(args...)`.
    Solve,
    /// This code.
    Code(&'static str),
    /// Written by the back end from the robot's structure (see [`Trait::head`]).
    Structure,
}

/// A kernel or a generated solve: one plain function of a generated crate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Kernel {
    pub name: &'static str,
    /// A solve emitted over the structure (`solve`), not an evaluator of the model's terms.
    pub solve: bool,
    /// The trait of a full crate whose methods forward to it (`None`: called directly only).
    pub full: Option<Trait>,
    /// The trait of a scene whose methods forward to it (`None`: not in scenes).
    pub scene: Option<Trait>,
    /// The trait methods that forward to it, in order.
    pub methods: &'static [Method],
}

impl Kernel {
    /// Whether the kernel needs the model's masses (the dynamics' kernels and solves).
    pub fn needs_dynamics(&self) -> bool {
        matches!(
            self.full,
            Some(Trait::Dynamics | Trait::DynamicsDerivatives)
        )
    }
}

/// The kernel of a name in the catalogue.
pub fn kernel(name: &str) -> Option<&'static Kernel> {
    KERNELS.iter().find(|k| k.name == name)
}

const X: (&str, &str) = ("x", "&[f64; N]");
const XDOT: (&str, &str) = ("xdot", "&[f64; N]");
const G_OUT: (&str, &str) = ("g", "&mut [[f64; M]; N]");
const F_OUT: (&str, &str) = ("f", "&mut [f64; M]");
const G_IN: (&str, &str) = ("g", "&[[f64; M]; N]");
const RHS: (&str, &str) = ("rhs", "&[f64; M]");
const X_OUT: (&str, &str) = ("x", "&mut [f64; N]");
const MASS_IN: (&str, &str) = ("mass", "&[[f64; N]; N]");
const LAMBDA: (&str, &str) = ("lambda", "&mut [f64; M]");
const CONDITIONING: &str = "Option<rbss_runtime::SolveConditioning>";

const STRUCTURE: Method = Method {
    name: "structure",
    args: &[],
    ret: "&'static Structure",
    body: Body::Structure,
};

const MASS_BLOCKS: Method = Method {
    name: "mass_blocks",
    args: &[],
    ret: "&'static [&'static [usize]]",
    body: Body::Structure,
};

/// A method that calls the kernel of its name.
const fn kernel_method(
    name: &'static str,
    args: &'static [(&'static str, &'static str)],
) -> Method {
    Method {
        name,
        args,
        ret: "",
        body: Body::Kernel,
    }
}

/// An evaluator of the model's terms.
const fn evaluator(
    name: &'static str,
    full: Option<Trait>,
    scene: Option<Trait>,
    methods: &'static [Method],
) -> Kernel {
    Kernel {
        name,
        solve: false,
        full,
        scene,
        methods,
    }
}

/// The kernels and solves of a full crate, in emission order (a scene emits those of its
/// tasks, in the same order).
pub static KERNELS: [Kernel; 18] = [
    evaluator(
        "constraints",
        Some(Trait::Kernels),
        Some(Trait::Constraints),
        &[kernel_method("constraints", &[X, F_OUT])],
    ),
    evaluator(
        "closure_check",
        Some(Trait::Kernels),
        Some(Trait::Constraints),
        &[
            Method {
                name: "closure_checks",
                args: &[],
                ret: "&'static [&'static str]",
                body: Body::Code("&CLOSURE_CHECKS"),
            },
            Method {
                name: "closure_check",
                args: &[X, ("out", "&mut [f64]")],
                ret: "",
                body: Body::Code(
                    "if let Some(out) = out.first_chunk_mut::<MC>() { closure_check(&self.c, x, out) }",
                ),
            },
        ],
    ),
    evaluator(
        "jacobian",
        Some(Trait::Kernels),
        Some(Trait::Jacobian),
        &[kernel_method("jacobian", &[X, G_OUT])],
    ),
    evaluator(
        "jacobian_p",
        Some(Trait::Kernels),
        None,
        &[kernel_method("jacobian_p", &[X, G_OUT])],
    ),
    evaluator(
        "jacobian_ik",
        Some(Trait::Kernels),
        None,
        &[kernel_method("jacobian_ik", &[X, G_OUT])],
    ),
    evaluator(
        "gamma",
        Some(Trait::Kernels),
        Some(Trait::Task(Task::Acceleration)),
        &[kernel_method("gamma", &[X, XDOT, ("out", "&mut [f64; M]")])],
    ),
    evaluator("body_frames", None, None, &[]),
    evaluator(
        "mass_matrix",
        Some(Trait::Dynamics),
        None,
        &[kernel_method(
            "mass_matrix",
            &[X, ("out", "&mut [[f64; N]; N]")],
        )],
    ),
    evaluator(
        "psi",
        Some(Trait::Dynamics),
        None,
        &[kernel_method("psi", &[X, XDOT, ("out", "&mut [f64; N]")])],
    ),
    evaluator(
        "energy",
        Some(Trait::Dynamics),
        Some(Trait::Task(Task::Energy)),
        &[kernel_method(
            "energy",
            &[X, XDOT, ("out", "&mut [f64; 2]")],
        )],
    ),
    evaluator(
        "constraints_jacobian_ik",
        Some(Trait::Kernels),
        Some(Trait::Task(Task::Ik)),
        &[kernel_method("constraints_jacobian_ik", &[X, F_OUT, G_OUT])],
    ),
    evaluator(
        "constraints_jacobian_p",
        Some(Trait::Kernels),
        Some(Trait::Task(Task::Fk)),
        &[kernel_method("constraints_jacobian_p", &[X, F_OUT, G_OUT])],
    ),
    evaluator(
        "dynamics_terms",
        Some(Trait::Dynamics),
        Some(Trait::EquationsOfMotion),
        &[kernel_method(
            "dynamics_terms",
            &[
                X,
                XDOT,
                G_OUT,
                ("gamma", "&mut [f64; M]"),
                ("mass", "&mut [[f64; N]; N]"),
                ("psi", "&mut [f64; N]"),
            ],
        )],
    ),
    evaluator(
        "dynamics_derivatives",
        Some(Trait::DynamicsDerivatives),
        Some(Trait::Task(Task::Derivatives)),
        &[kernel_method(
            "dynamics_derivatives",
            &[
                X,
                XDOT,
                ("xddot", "&[f64; N]"),
                ("lambda", "&[f64; M]"),
                ("dr_dx", "&mut [[f64; N]; N]"),
                ("dr_dxdot", "&mut [[f64; N]; N]"),
                ("dc_dx", "&mut [[f64; M]; N]"),
                ("dc_dxdot", "&mut [[f64; M]; N]"),
            ],
        )],
    ),
    Kernel {
        name: "ik_block_solve",
        solve: true,
        full: Some(Trait::Kernels),
        scene: Some(Trait::Robot),
        methods: &[Method {
            name: "ik_block_solve",
            args: &[("block", "usize"), G_IN, RHS, ("outputs", "bool"), X_OUT],
            ret: "Option<[f64; 2]>",
            body: Body::Solve,
        }],
    },
    Kernel {
        name: "forward_rates_solve",
        solve: true,
        full: Some(Trait::Kernels),
        scene: Some(Trait::Robot),
        methods: &[
            Method {
                name: "forward_rates_solve",
                args: &[G_IN, RHS, ("actuated", "bool"), ("exact", "bool"), X_OUT],
                ret: "Option<[f64; 2]>",
                body: Body::Solve,
            },
            Method {
                name: "forward_rates_keep",
                args: &[G_IN, RHS, ("exact", "bool"), X_OUT, ("store", "&mut [f64]")],
                ret: "Option<([f64; 2], bool)>",
                body: Body::Code(
                    "let kept = FR_CHORD && store.len() >= FR_STORE; \
                     forward_rates_keep(g, rhs, false, exact, x, kept.then_some(store)).map(|r| (r, kept))",
                ),
            },
            Method {
                name: "forward_rates_chord",
                args: &[("store", "&[f64]"), RHS, X_OUT],
                ret: "Option<()>",
                body: Body::Solve,
            },
        ],
    },
    Kernel {
        name: "forward_dynamics_solve",
        solve: true,
        full: Some(Trait::Dynamics),
        scene: Some(Trait::EquationsOfMotion),
        methods: &[Method {
            name: "forward_dynamics_solve",
            args: &[
                G_IN,
                MASS_IN,
                ("force", "&[f64; N]"),
                ("gamma", "&[f64; M]"),
                ("xddot", "&mut [f64; N]"),
                LAMBDA,
            ],
            ret: CONDITIONING,
            body: Body::Solve,
        }],
    },
    Kernel {
        name: "inverse_dynamics_solve",
        solve: true,
        full: Some(Trait::Dynamics),
        scene: Some(Trait::EquationsOfMotion),
        methods: &[Method {
            name: "inverse_dynamics_solve",
            args: &[
                G_IN,
                MASS_IN,
                ("psi", "&[f64; N]"),
                ("xddot", "&[f64; N]"),
                ("q_forces", "Option<&[f64; N]>"),
                ("u", "&mut [f64]"),
                LAMBDA,
            ],
            ret: CONDITIONING,
            body: Body::Solve,
        }],
    },
];

/// The methods of a trait's `impl`, in order, when `emitted` holds the kernels the crate
/// has: the head ([`Trait::head`]), then the forwarding methods of its emitted kernels in
/// [`KERNELS`] order. `Kernels` of a full crate holds those of `tasks::Robot` (the generated
/// kinematic solves) first, as the runtime's trait declares them.
pub fn impl_methods(t: Trait, emitted: &[&str]) -> Vec<&'static Method> {
    let of = |k: &Kernel| match t {
        Trait::Kernels | Trait::Dynamics | Trait::DynamicsDerivatives => k.full == Some(t),
        _ => k.scene == Some(t),
    };
    let mut kernels: Vec<&Kernel> = KERNELS
        .iter()
        .filter(|k| of(k) && emitted.contains(&k.name))
        .collect();
    if t == Trait::Kernels {
        kernels.sort_by_key(|k| k.scene != Some(Trait::Robot));
    }
    t.head()
        .iter()
        .chain(kernels.into_iter().flat_map(|k| k.methods))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_task_kernel_is_in_the_catalogue_and_every_method_named_once() {
        for t in Task::ALL {
            for k in t.kernels() {
                assert!(kernel(k).is_some(), "{} calls `{k}`", t.name());
            }
        }
        for t in Trait::all() {
            let names: Vec<&str> = KERNELS
                .iter()
                .filter(|k| k.full == Some(t) || k.scene == Some(t))
                .flat_map(|k| k.methods)
                .chain(t.head())
                .map(|m| m.name)
                .collect();
            for (i, n) in names.iter().enumerate() {
                assert!(!names[..i].contains(n), "`{n}` twice in {}", t.name());
            }
        }
        // The full crate's `Kernels`: the robot's head and solves, then the kernels.
        let all: Vec<&str> = KERNELS.iter().map(|k| k.name).collect();
        let kernels: Vec<&str> = impl_methods(Trait::Kernels, &all)
            .iter()
            .map(|m| m.name)
            .collect();
        assert_eq!(
            kernels[..6],
            [
                "structure",
                "ik_block_solve",
                "forward_rates_solve",
                "forward_rates_keep",
                "forward_rates_chord",
                "constraints"
            ]
        );
    }
}
