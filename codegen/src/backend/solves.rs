//! The generated solves (see [`crate::solve`]): forward and inverse dynamics, the
//! inverse-kinematics blocks and forward kinematics' elimination, emitted over the structure
//! the generator knows, as the catalogue's solves.

use proc_macro2::TokenStream;
use quote::quote;

use super::Selection;
use super::kernels::Emitted as Kernels;
use crate::catalog;
use crate::derive::{self, Derivation};
use crate::emit::doc_attrs;
use crate::graph::{Graph, Id};
use crate::model::Model;
use crate::solve::{Emitted, Entry, Structure};

/// Emits the solves of the crate (a scene's: those its tasks call) after its kernels, into
/// `out`. A solve the structure does not allow (`None` from its emitter) is left out.
pub(crate) fn emit(
    model: &Model,
    d: &Derivation,
    home: &[f64],
    sel: Option<&Selection<'_>>,
    out: &mut Kernels,
    progress: &mut dyn FnMut(&str),
) {
    let n = d.n;
    let mut kinematic = solve_structure(model, d, None, home);
    let ops_of = |name: &str| out.reports.iter().find(|r| r.name == name).map(|r| r.ops);
    kinematic.fk_evals = ops_of("constraints").zip(ops_of("constraints_jacobian_p"));
    let dynamic = d
        .dynamics
        .as_ref()
        .map(|dy| solve_structure(model, d, Some(dy), home));
    for k in catalog::KERNELS.iter().filter(|k| k.solve) {
        let name = k.name;
        if sel.is_some_and(|s| !s.kernels.contains(&name)) {
            continue;
        }
        let (emitted, shape, nonzeros) = match (name, &dynamic) {
            ("ik_block_solve", _) => (
                crate::solve::ik_block_solve(&kinematic),
                "[f64;N] + [f64;2]",
                n - model.outputs.len(),
            ),
            ("forward_rates_solve", _) => (
                crate::solve::forward_rates_solve(&kinematic),
                "[f64;N] + [f64;2]",
                n - model.outputs.len(),
            ),
            ("forward_dynamics_solve", Some(s)) => {
                (crate::solve::forward_dynamics(s), "[f64;N] + [f64;M]", n)
            }
            ("inverse_dynamics_solve", Some(s)) => {
                (crate::solve::inverse_dynamics(s), "[f64;N-M] + [f64;M]", n)
            }
            (_, None) => continue,
            _ => panic!("the catalogue's solve `{name}` has no emitter in backend::solves"),
        };
        let Some(e) = emitted else { continue };
        progress(&format!("emitted `{name}`: {}", e.flops));
        let ops = e.flops;
        out.items.push(if k.needs_dynamics() {
            solve_item(name, e, model, d)
        } else {
            kinematic_solve_item(name, e, model, d)
        });
        out.reports.push(super::KernelReport {
            name,
            shape: shape.to_string(),
            nonzeros,
            ops,
        });
        out.names.push(name);
    }
}

/// What the solves need to know of the robot (`solve::Structure`): the entries of `G` and `M`,
/// with their values at the home (the generator's pivots are chosen there).
fn solve_structure<'a>(
    model: &'a Model,
    d: &'a Derivation,
    dy: Option<&derive::Dynamics>,
    home: &[f64],
) -> Structure<'a> {
    let (n, m) = (d.n, d.m);
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let val = d.graph.eval_all(home, &vec![0.0; n], &p);
    let entry = |id: Id| -> Entry {
        match id {
            Graph::ZERO => Entry::Zero,
            _ if d.graph.is_number(id) => Entry::Number(val[id as usize]),
            _ => Entry::Var(val[id as usize]),
        }
    };
    let pattern = |e: &Vec<Vec<Id>>, rows: usize| -> Vec<Vec<Entry>> {
        (0..rows)
            .map(|i| (0..n).map(|j| entry(e[i][j])).collect())
            .collect()
    };
    Structure {
        n,
        m,
        outputs: &model.outputs,
        actuated: &model.actuated,
        ik_blocks: &d.ik_blocks,
        g: pattern(&d.g, m),
        mass: dy.map(|dy| pattern(&dy.mass, n)).unwrap_or_default(),
        fk_evals: None,
    }
}

/// An emitted kinematic solve (`ik_block_solve`, see `solve::rates`, or `forward_rates_solve`,
/// see `solve::forward_rates`) as items (the trait methods that forward to it are the
/// catalogue's).
fn kinematic_solve_item(name: &str, e: Emitted, model: &Model, d: &Derivation) -> TokenStream {
    let orders = d.ik_blocks.iter().map(|(r, _)| r.len()).collect::<Vec<_>>();
    let (body, items) = (e.body, e.items);
    let allow = quote!(#[allow(clippy::neg_multiply, clippy::neg_cmp_op_on_partial_ord)]);
    if name == "ik_block_solve" {
        let doc = doc_attrs(&format!(
            "Solves inverse-kinematics block `block` (of {}, of orders `{orders:?}`): `K x[cols] = \
             rhs[rows] - G[rows, outputs] x[outputs]` (the last term only if `outputs`), `K = \
             G[rows, cols]`, over the structural non-zeros of `G` (see \
             `rbss_runtime::Kernels::ik_block_solve`). Writes `x[cols]` and returns `[cond(K), \
             residual]`: the exact 1-norm condition number for orders up to 3; beyond, `‖K‖₁ \
             max_c 1 / |u_cc|` from the pivots, the Hager/Higham estimate where that passes 1e3; \
             and `max |K x[cols] - rhs'|` over the block's rows. `None` where a \
             pivot fails its threshold test or the block is singular.",
            d.ik_blocks.len()
        ));
        return quote! {
                #items

                #doc
                #allow
                pub fn ik_block_solve(
                    block: usize,
                    g: &[[f64; M]; N],
                    rhs: &[f64; M],
                    outputs: bool,
                    x: &mut [f64; N],
                ) -> Option<[f64; 2]> {
                    #body
                }
        };
    }
    let doc = doc_attrs(&format!(
        "Forward kinematics' linear system `J_p x_p = rhs - J_q x_q` (the actuated entries of `x` \
         given; `x_q = 0` unless `actuated`), solved by elimination onto the {} outputs over the \
         structural non-zeros of `G` ({} inverse-kinematics block(s) of order(s) `{orders:?}`; see \
         `rbss_runtime::Kernels::forward_rates_solve`). Writes the passive entries of `x` and \
         returns `[c, residual]`: `c` the 1-norm condition number of `J_p`, exact if `exact`, \
         else a rigorous upper bound (with the blocks' estimated inverse norms beyond order 3); \
         the residual `max |J_p x_p + J_q x_q - rhs|`. `None` where a block's condition number \
         passes 1e4, a pivot fails its threshold test or the reduced system is singular.",
        model.outputs.len(),
        d.ik_blocks.len()
    ));
    quote! {
            #items

            #doc
            #allow
            pub fn forward_rates_solve(
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                actuated: bool,
                exact: bool,
                x: &mut [f64; N],
            ) -> Option<[f64; 2]> {
                forward_rates_keep(g, rhs, actuated, exact, x, None)
            }

            /// [`forward_rates_solve`], keeping its factors in `store` (its first
            /// [`FR_STORE`] entries, when it has that many) for [`forward_rates_chord`].
            #allow
            fn forward_rates_keep(
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                actuated: bool,
                exact: bool,
                x: &mut [f64; N],
                store: Option<&mut [f64]>,
            ) -> Option<[f64; 2]> {
                #body
            }
    }
}

/// An emitted solve (`forward_dynamics_solve` or `inverse_dynamics_solve`) as items (its
/// per-block functions and the function itself).
fn solve_item(name: &str, e: Emitted, model: &Model, d: &Derivation) -> TokenStream {
    let orders = d.ik_blocks.iter().map(|(r, _)| r.len()).collect::<Vec<_>>();
    let (body, items) = (e.body, e.items);
    let allow = quote! {
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            clippy::neg_cmp_op_on_partial_ord
        )]
    };
    if name == "forward_dynamics_solve" {
        let doc = doc_attrs(&format!(
            "Forward dynamics' saddle-point system `M Ẍ + Gᵀ lambda = force`, `G Ẍ = gamma`, \
             solved by elimination onto the outputs over the structural non-zeros of `G` and `M` \
             (see `rbss_runtime::Dynamics::forward_dynamics_solve`): {} inverse-kinematics \
             block(s) of order(s) `{orders:?}`, a reduced mass matrix of order {}. Returns `None` \
             where a pivot fails its threshold test, a block is singular or the reduced mass \
             matrix is not positive definite.",
            d.ik_blocks.len(),
            model.outputs.len()
        ));
        quote! {
                #items

                #doc
                #allow
                pub fn forward_dynamics_solve(
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    force: &[f64; N],
                    gamma: &[f64; M],
                    xddot: &mut [f64; N],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    #body
                }
        }
    } else {
        let doc = doc_attrs(&format!(
            "Inverse dynamics' system `[S | Gᵀ] [U; -lambda] = b` (`b = M Ẍ - psi - Q`, formed \
             here over the structural non-zeros of `M`), solved \
             by block elimination onto the {} actuators over the structural non-zeros of `G` \
             (see `rbss_runtime::Dynamics::inverse_dynamics_solve`): {} inverse-kinematics \
             block(s) of order(s) `{orders:?}`. Writes `u` (length `N - M`) and `lambda`. \
             Returns `None` where a pivot fails its threshold test or a block or the reduced \
             system is singular, or `u` has another length.",
            model.actuated.len(),
            d.ik_blocks.len(),
        ));
        quote! {
                #items

                #doc
                #allow
                pub fn inverse_dynamics_solve(
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    psi: &[f64; N],
                    xddot: &[f64; N],
                    q_forces: Option<&[f64; N]>,
                    u: &mut [f64],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    #body
                }
        }
    }
}
