//! The kernels: one plain function per evaluator of the catalogue (`f`, `G` and its column
//! subsets, `gamma`, the bodies' frames, `M`, `psi`, the energies, the fused kernels), each
//! described by a [`KernelSpec`] here and emitted by [`crate::emit`].

use std::time::Instant;

use proc_macro2::TokenStream;
use quote::quote;

use super::{KernelReport, Selection, unlink_missing};
use crate::catalog;
use crate::derive::{Derivation, DynamicsDerivatives};
use crate::emit::{self, Consts, KernelSpec, OutArg, Target};
use crate::graph::{Graph, Id};
use crate::model::Model;

/// The emitted kernels: their items, figures and names, in emission order.
#[derive(Default)]
pub(crate) struct Emitted {
    pub items: Vec<TokenStream>,
    pub reports: Vec<KernelReport>,
    /// The names of the kernels and solves emitted.
    pub names: Vec<&'static str>,
}

/// Emits the kernels of the crate (a scene's: only those its tasks call; a full crate's without
/// `dynamics_derivatives` when `derivatives` is false), collecting the constants they read
/// into `consts`.
pub(crate) fn emit(
    model: &Model,
    d: &mut Derivation,
    sel: Option<&Selection<'_>>,
    derivatives: bool,
    consts: &mut Consts,
    progress: &mut dyn FnMut(&str),
) -> Emitted {
    // The derivatives of the equations of motion join the graph only where they are emitted.
    let derivs = if derivatives && sel.is_none_or(|s| s.kernels.contains(&"dynamics_derivatives")) {
        let t = Instant::now();
        let dd = crate::derive::dynamics_derivatives(d);
        if dd.is_some() {
            progress(&format!(
                "derived the dynamics' derivatives in {:.3} s",
                t.elapsed().as_secs_f64()
            ));
        }
        dd
    } else {
        None
    };
    let d = &*d;
    let specs = Specs {
        model,
        d,
        derivs: derivs.as_ref(),
    };
    let mut out = Emitted::default();
    for k in catalog::KERNELS.iter().filter(|k| !k.solve) {
        if sel.is_some_and(|s| !s.kernels.contains(&k.name)) {
            continue;
        }
        let Some(mut spec) = specs.spec(k.name) else {
            continue;
        };
        if let Some(s) = sel {
            spec.doc = unlink_missing(&spec.doc, &s.kernels);
        }
        let total: usize = spec.outs.iter().map(|o| o.entries.len()).sum();
        let nnz: usize = spec
            .outs
            .iter()
            .map(|o| o.entries.iter().filter(|(_, a)| *a != Graph::ZERO).count())
            .sum();
        spec.doc
            .push_str(&format!("\n\nNon-zeros written: {nnz} of {total}."));
        let tk = Instant::now();
        let e = emit::emit_kernel(&d.graph, consts, &spec);
        progress(&format!(
            "emitted `{}` in {:.3} s: {}",
            spec.name,
            tk.elapsed().as_secs_f64(),
            e.ops
        ));
        out.reports.push(KernelReport {
            name: spec.name,
            shape: spec
                .outs
                .iter()
                .map(|o| o.ty.to_string().replace(' ', ""))
                .collect::<Vec<_>>()
                .join(" + "),
            nonzeros: e.nonzeros,
            ops: e.ops,
        });
        out.items.push(e.tokens);
        out.names.push(spec.name);
    }
    out
}

/// What each kernel writes, from the derivation.
struct Specs<'a> {
    model: &'a Model,
    d: &'a Derivation,
    /// The derivatives of the equations of motion, when emitted.
    derivs: Option<&'a DynamicsDerivatives>,
}

fn mat_ty() -> TokenStream {
    quote!([[f64; M]; N])
}

fn vec_ty() -> TokenStream {
    quote!([f64; M])
}

/// The entries of a vector kernel's output.
fn vec_entries(v: &[Id]) -> Vec<(Target, Id)> {
    v.iter()
        .enumerate()
        .map(|(i, a)| (Target::Vec(i), *a))
        .collect()
}

const G_NOTE: &str = "Column-major (`out[col][row]`, the storage of nalgebra's `SMatrix<f64, M, N>`). \
                      Writes only the structural non-zeros listed above; the other entries of `out` are never \
                      written, so a buffer that starts at zero stays correct.";

impl Specs<'_> {
    /// The spec of the catalogue's kernel `name`; `None` where the robot has no such kernel
    /// (no closure check, no dynamics).
    fn spec(&self, name: &'static str) -> Option<KernelSpec> {
        let dy = self.d.dynamics.is_some();
        match name {
            "constraints" => Some(self.constraints()),
            "closure_check" => (!self.d.checks.is_empty()).then(|| self.closure_check()),
            "jacobian" => Some(self.g_columns(name, None)),
            "jacobian_p" => Some(self.g_columns(name, Some(&self.d.passive))),
            "jacobian_ik" => Some(self.g_columns(name, Some(&self.ik_cols()))),
            "gamma" => Some(self.gamma()),
            "body_frames" => Some(self.body_frames()),
            "mass_matrix" => dy.then(|| self.mass_matrix()),
            "psi" => dy.then(|| self.psi()),
            "energy" => dy.then(|| self.energy()),
            "constraints_jacobian_ik" | "constraints_jacobian_p" => Some(self.fused_newton(name)),
            "dynamics_terms" => dy.then(|| self.dynamics_terms()),
            "dynamics_derivatives" => self.derivs.map(|dd| self.dynamics_derivatives(dd)),
            _ => panic!("the catalogue's kernel `{name}` has no spec in backend::kernels"),
        }
    }

    fn coord_of(&self, js: &[usize]) -> String {
        js.iter()
            .map(|&j| self.model.coordinates[j].name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Every coordinate but the outputs: the inverse-kinematics unknowns.
    fn ik_cols(&self) -> Vec<usize> {
        let n = self.d.n;
        (0..n).filter(|j| !self.model.outputs.contains(j)).collect()
    }

    /// The entries of `G` in the columns `cols`.
    fn mat_outputs(&self, cols: &[usize]) -> Vec<(Target, Id)> {
        let mut v = Vec::new();
        for &col in cols {
            for row in 0..self.d.m {
                v.push((Target::Mat { row, col }, self.d.g[row][col]));
            }
        }
        v
    }

    /// The upper triangle of `M` (the kernel writes both).
    fn mass_upper(&self) -> Vec<(Target, Id)> {
        let dy = self
            .d
            .dynamics
            .as_ref()
            .expect("a dynamics kernel without dynamics");
        let mut upper = Vec::new();
        for col in 0..self.d.n {
            for row in 0..=col {
                upper.push((Target::Sym { row, col }, dy.mass[row][col]));
            }
        }
        upper
    }

    fn constraints(&self) -> KernelSpec {
        let m = self.d.m;
        KernelSpec {
            name: "constraints",
            doc: format!(
                "Loop closure `f(X)` (M = {m}): for each loop, the world components of origin(a) - origin(b).\n\
                 Rows: [{}].",
                self.d.constraint_names.join(", ")
            ),
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![OutArg::new("out", vec_ty(), vec_entries(&self.d.f))],
        }
    }

    fn closure_check(&self) -> KernelSpec {
        let d = self.d;
        KernelSpec {
            name: "closure_check",
            doc: format!(
                "The loop components the model does not solve (MC = {}): [{}]. Each is                      `origin(a) - origin(b)` along a world axis that its loop's `components` leave out;                      zero wherever the loop's two points coincide, so the solvers check it after a                      position solve (a root with one of them away from zero is a mirror root of the                      solved components, refused as spurious).",
                d.checks.len(),
                d.check_names.join(", ")
            ),
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![OutArg::new(
                "out",
                quote!([f64; MC]),
                vec_entries(&d.checks),
            )],
        }
    }

    /// `jacobian` (every column, `cols` `None`), `jacobian_p` or `jacobian_ik`.
    fn g_columns(&self, name: &'static str, cols: Option<&[usize]>) -> KernelSpec {
        let (n, m) = (self.d.n, self.d.m);
        let doc = match name {
            "jacobian" => format!("Constraint Jacobian `G = ∂f/∂X` ({m} × {n}).\n\n{}", G_NOTE),
            "jacobian_p" => format!(
                "`J_p`: the columns of `G` for the passive coordinates p = [{}] ({m} × {}), written into the \
                 full {m} × {n} layout.\n\n{}",
                self.coord_of(&self.d.passive),
                self.d.passive.len(),
                G_NOTE
            ),
            _ => format!(
                "The columns of `G` for the inverse-kinematics unknowns (every coordinate but the outputs): [{}], \
                 written into the full {m} × {n} layout.\n\n{}",
                self.coord_of(&self.ik_cols()),
                G_NOTE
            ),
        };
        let all: Vec<usize> = (0..n).collect();
        KernelSpec {
            name,
            doc,
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![OutArg::new(
                "out",
                mat_ty(),
                self.mat_outputs(cols.unwrap_or(&all)),
            )],
        }
    }

    fn gamma(&self) -> KernelSpec {
        let m = self.d.m;
        KernelSpec {
            name: "gamma",
            doc: format!(
                "Acceleration term `gamma(X, Xdot) = -(dG/dt) Xdot` (M = {m}), so that `G Xddot = gamma` \
                 (the paper's eqs. 11-17: `J_p pddot = gamma - J_q qddot`)."
            ),
            uses_velocity: true,
            accel_inputs: false,
            outs: vec![OutArg::new("out", vec_ty(), vec_entries(&self.d.gamma))],
        }
    }

    fn body_frames(&self) -> KernelSpec {
        let nb = self.model.bodies.len();
        let body_names: Vec<String> = self.model.bodies.iter().map(|b| b.name.clone()).collect();
        let entries = self
            .d
            .frames
            .iter()
            .enumerate()
            .flat_map(|(b, fr)| {
                let mut v = Vec::new();
                for col in 0..3 {
                    for row in 0..3 {
                        v.push((
                            Target::Mat {
                                row: 3 * col + row,
                                col: b,
                            },
                            fr.r[row][col],
                        ));
                    }
                }
                for i in 0..3 {
                    v.push((Target::Mat { row: 9 + i, col: b }, fr.p[i]));
                }
                v
            })
            .collect();
        KernelSpec {
            name: "body_frames",
            doc: format!(
                "World frames of the bodies [{}] ({nb} of them): `out[b]` = `[R (column-major, 9), p (3)]`, \
                 the rotation and origin of body b's frame.",
                body_names.join(", ")
            ),
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![OutArg::new("out", quote!([[f64; 12]; NB]), entries)],
        }
    }

    fn mass_matrix(&self) -> KernelSpec {
        let n = self.d.n;
        let dy = self.d.dynamics.as_ref().expect("dynamics");
        let blocks: Vec<String> = dy
            .mass_blocks
            .iter()
            .map(|b| format!("`[{}]`", self.coord_of(b)))
            .collect();
        KernelSpec {
            name: "mass_matrix",
            doc: format!(
                "Mass matrix `M(X) = ∂²T/∂Xdot²` ({n} × {n}, symmetric; the paper's eq. 25), assembled per body \
                 as `m J_rᵀ J_r + J_wᵀ I J_w`. Block-diagonal with the {} blocks {}: each body moves with \
                 its own chain's coordinates only.\n\nWrites both triangles of the structural non-zeros; the \
                 other entries of `out` are never written.",
                dy.mass_blocks.len(),
                blocks.join(" ")
            ),
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![OutArg::new("out", quote!([[f64; N]; N]), self.mass_upper())],
        }
    }

    /// The joints' own forces (springs, dampers, armatures) as the docs of `psi` and `energy`
    /// name them, where the model has them: `(psi, kinetic, potential)`.
    fn joint_forces(&self) -> (String, &'static str, &'static str) {
        let joint_forces: Vec<String> = self
            .model
            .coordinates
            .iter()
            .filter(|c| !c.forces.is_empty())
            .map(|c| format!("`{}`", c.name))
            .collect();
        if joint_forces.is_empty() {
            (String::new(), "", "")
        } else {
            (
                format!(
                    " It includes the joints' own forces on {}: `-stiffness (q - rest)` (from `Pi`) \
                     and `-damping q̇`; `M`'s diagonal includes their `armature`.",
                    joint_forces.join(", ")
                ),
                ", plus `½ armature q̇²` per joint",
                " and of the joints' springs (`½ stiffness (q - rest)²` each)",
            )
        }
    }

    fn psi(&self) -> KernelSpec {
        let n = self.d.n;
        let dy = self.d.dynamics.as_ref().expect("dynamics");
        let (psi_forces, _, _) = self.joint_forces();
        KernelSpec {
            name: "psi",
            doc: format!(
                "`psi(X, Xdot) = -(Christoffel terms) - ∂Pi/∂X` ({n}; the paper's eq. 21 with the Christoffel \
                 symbols of the first kind), so that `M Xddot = psi + Q + S U - Gᵀ lambda`.{psi_forces}"
            ),
            uses_velocity: true,
            accel_inputs: false,
            outs: vec![OutArg::new("out", quote!([f64; N]), vec_entries(&dy.psi))],
        }
    }

    fn energy(&self) -> KernelSpec {
        let dy = self.d.dynamics.as_ref().expect("dynamics");
        let (_, t_forces, pi_forces) = self.joint_forces();
        KernelSpec {
            name: "energy",
            doc: format!(
                "`[T, Pi]`: kinetic energy `T(X, Xdot)` summed from the bodies' centre-of-mass and angular \
                 velocities (independently of `M`){t_forces}, and potential energy `Pi(X)` of gravity{pi_forces}."
            ),
            uses_velocity: true,
            accel_inputs: false,
            outs: vec![OutArg::new(
                "out",
                quote!([f64; 2]),
                vec![(Target::Vec(0), dy.kinetic), (Target::Vec(1), dy.potential)],
            )],
        }
    }

    /// A fused kernel of one Newton step: `f` and the inverse-kinematics columns of `G`
    /// (`constraints_jacobian_ik`) or `J_p` (`constraints_jacobian_p`).
    fn fused_newton(&self, name: &'static str) -> KernelSpec {
        let (doc, cols) = if name == "constraints_jacobian_ik" {
            (
                "`f` and the inverse-kinematics columns of `G` together (one Newton step of inverse \
                 kinematics): [`constraints`] and [`jacobian_ik`] fused, sharing their subexpressions.",
                self.ik_cols(),
            )
        } else {
            (
                "`f` and `J_p` together (one Newton step of forward kinematics): [`constraints`] and \
                 [`jacobian_p`] fused, sharing their subexpressions.",
                self.d.passive.clone(),
            )
        };
        KernelSpec {
            name,
            doc: doc.to_string(),
            uses_velocity: false,
            accel_inputs: false,
            outs: vec![
                OutArg::new("f", vec_ty(), vec_entries(&self.d.f)),
                OutArg::new("g", mat_ty(), self.mat_outputs(&cols)),
            ],
        }
    }

    fn dynamics_terms(&self) -> KernelSpec {
        let dy = self.d.dynamics.as_ref().expect("dynamics");
        let all: Vec<usize> = (0..self.d.n).collect();
        KernelSpec {
            name: "dynamics_terms",
            doc: "Everything the equations of motion need at one state: `G`, `gamma`, `M` and `psi` \
                  ([`jacobian`], [`gamma`], [`mass_matrix`], [`psi`] fused, sharing their subexpressions)."
                .to_string(),
            uses_velocity: true,
            accel_inputs: false,
            outs: vec![
                OutArg::new("g", mat_ty(), self.mat_outputs(&all)),
                OutArg::new("gamma", vec_ty(), vec_entries(&dy.gamma)),
                OutArg::new("mass", quote!([[f64; N]; N]), self.mass_upper()),
                OutArg::new("psi", quote!([f64; N]), vec_entries(&dy.psi)),
            ],
        }
    }

    fn dynamics_derivatives(&self, dd: &DynamicsDerivatives) -> KernelSpec {
        let (n, m) = (self.d.n, self.d.m);
        let mat = |rows: &[Vec<Id>]| -> Vec<(Target, Id)> {
            let mut v = Vec::new();
            for col in 0..n {
                for (row, r) in rows.iter().enumerate() {
                    v.push((Target::Mat { row, col }, r[col]));
                }
            }
            v
        };
        KernelSpec {
            name: "dynamics_derivatives",
            doc: format!(
                "First derivatives of the equations of motion at one state, given `Xddot` and `lambda` \
                 (for forward dynamics: the solution of [`dynamics_terms`]' saddle-point system), by the chain \
                 rule through the same named intermediates as [`dynamics_terms`]: `dr_dx` = `∂r/∂X` ({n} × {n}) and \
                 `dr_dxdot` = `∂r/∂Xdot` = `-∂psi/∂Xdot` ({n} × {n}) of the inverse-dynamics residual \
                 `r = M(X) Xddot - psi(X, Xdot) + G(X)ᵀ lambda` (so that `r = Q + S U` on a solution); \
                 `dc_dx` = `∂c/∂X` ({m} × {n}) and `dc_dxdot` = `∂c/∂Xdot` = `-∂gamma/∂Xdot` ({m} × {n}) of the \
                 acceleration constraint `c = G(X) Xddot - gamma(X, Xdot)`. Column-major (`out[col][row]`); \
                 writes only the structural non-zeros, the other entries are never written."
            ),
            uses_velocity: true,
            accel_inputs: true,
            outs: vec![
                OutArg::new("dr_dx", quote!([[f64; N]; N]), mat(&dd.dr_dx)),
                OutArg::new("dr_dxdot", quote!([[f64; N]; N]), mat(&dd.dr_dxdot)),
                OutArg::new("dc_dx", mat_ty(), mat(&dd.dc_dx)),
                OutArg::new("dc_dxdot", mat_ty(), mat(&dd.dc_dxdot)),
            ],
        }
    }
}
