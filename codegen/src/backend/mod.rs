//! The back end: the generated crate's module from the derivation, one file per emitted item
//! (in the manner of prost-build's `code_generator`):
//!
//! | file | items |
//! |---|---|
//! | `params` | `N`, `M`, `K`, `Params`, `Params::consts` |
//! | `structure` | `STRUCTURE`, the robot's type, `MC`/`CLOSURE_CHECKS`, `NB`/`BODIES` |
//! | `kernels` | the kernels (`constraints`, `jacobian`, ..., `dynamics_terms`) |
//! | `solves` | the generated solves (`ik_block_solve`, ..., `inverse_dynamics_solve`) |
//! | `impls` | the trait `impl`s, full crate and scenes alike, from the catalogue |
//! | `crate_files` | the module's header, `Cargo.toml`, `src/lib.rs`, the manifest |
//!
//! What is emitted, in which order and behind which trait methods is the catalogue's
//! ([`crate::catalog`]); `module_tokens` assembles the items.

pub(crate) mod crate_files;
pub(crate) mod impls;
pub(crate) mod kernels;
pub(crate) mod params;
pub(crate) mod solves;
pub(crate) mod structure;

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use crate::catalog;
use crate::derive::Derivation;
use crate::emit::{Consts, Ops, doc_attrs};
use crate::model::Model;
use crate::scene::Scene;

/// Generation options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Options {
    /// Fold the model's parameter values into the kernels (exactly where they can be: `cos` of
    /// a frozen zero angle is 1) instead of reading them from `Params` at run time.
    pub freeze: bool,
    /// Emit only the kinematics kernels (no `M`, `psi`, energies), for scenes that need no
    /// dynamics. Models without masses are always kinematics-only.
    pub kinematics_only: bool,
    /// Leave out the derivative kernel `dynamics_derivatives` (and the robot's
    /// `DynamicsDerivatives` impl): the library `rbss --model-file` builds for the subcommands
    /// that take no derivatives compiles in a third of the time for a legged robot.
    pub no_derivatives: bool,
}

/// Per-kernel figures.
#[derive(Debug, Clone)]
pub struct KernelReport {
    pub name: &'static str,
    pub shape: String,
    pub nonzeros: usize,
    pub ops: Ops,
}

/// What a scene selects: its frozen parameters and kernels, and where the crate finds the
/// runtime.
pub(crate) struct Selection<'a> {
    pub scene: &'a Scene,
    pub frozen: Vec<bool>,
    pub kernels: Vec<&'static str>,
    pub runtime_dep: String,
}

/// The generated module: every item of the crate (a scene's: only what its tasks need), and
/// the kernels' figures.
pub(crate) fn module_tokens(
    model: &Model,
    d: &mut Derivation,
    home: &[f64],
    opts: &Options,
    sel: Option<&Selection<'_>>,
    model_path: &str,
    progress: &mut dyn FnMut(&str),
) -> (TokenStream, Vec<KernelReport>) {
    let robot = format_ident!("{}", camel(&model.name));
    let params = params::Params::new(model, opts, sel, model_path);
    let mut consts = Consts::default();
    let derivatives = sel.is_some() || !opts.no_derivatives;
    let mut emitted = kernels::emit(model, d, sel, derivatives, &mut consts, progress);
    let d = &*d;
    solves::emit(model, d, home, sel, &mut emitted, progress);
    let params = params.tokens(model, d, &consts);
    let structure = structure::tokens(model, d, home, &robot, &emitted.names);
    let impls = impls::impls(
        &impls::Robot {
            ty: &robot,
            d,
            ik_order: Literal::usize_unsuffixed(ik_block_order(&d.ik_blocks)),
            emitted: &emitted.names,
        },
        sel,
    );
    let desc = match sel {
        Some(s) => format!(
            " Kernels of `{}` ({}) for the scene `{}`: {}.",
            model.name,
            model.description,
            s.scene.name,
            s.scene.summary()
        ),
        None => format!(" Kernels of `{}`: {}.", model.name, model.description),
    };
    let uses = match sel {
        Some(_) => quote!(
            use rbss_runtime::{IkBlock, Structure};
        ),
        None => quote!(
            use rbss_runtime::{IkBlock, Kernels, Structure};
        ),
    };
    let items = &emitted.items;
    let tokens = quote! {
        #![doc = #desc]

        #uses

        #params

        #structure

        #(#items)*

        #impls
    };
    (tokens, emitted.reports)
}

/// A doc text with the intra-doc links to kernels a scene does not emit made plain code.
pub(crate) fn unlink_missing(doc: &str, kernels: &[&str]) -> String {
    let mut out = doc.to_string();
    for k in catalog::KERNELS.iter().map(|k| k.name) {
        if !kernels.contains(&k) {
            out = out.replace(&format!("[`{k}`]"), &format!("`{k}`"));
        }
    }
    out
}

/// The common order of the inverse-kinematics blocks (`0` when they differ or there are none):
/// the robot's `IK_BLOCK_ORDER`, so that the solvers compile one block size for it.
fn ik_block_order(blocks: &[(Vec<usize>, Vec<usize>)]) -> usize {
    match blocks.first() {
        Some((rows, _)) if blocks.iter().all(|(r, _)| r.len() == rows.len()) => rows.len(),
        _ => 0,
    }
}

fn ik_order_doc() -> TokenStream {
    doc_attrs(
        "The order of every inverse-kinematics block (0: they differ), known at generation: the solvers compile only this size.",
    )
}

/// `stewart_6ups` -> `Stewart6Ups`.
pub fn camel(name: &str) -> String {
    let mut out = String::new();
    let mut upper = true;
    for ch in name.chars() {
        if ch == '_' {
            upper = true;
            continue;
        }
        if upper && ch.is_ascii_alphabetic() {
            out.push(ch.to_ascii_uppercase());
            upper = false;
        } else {
            out.push(ch);
            upper = ch.is_ascii_digit();
        }
    }
    out
}

fn usize_list(xs: &[usize]) -> TokenStream {
    let l = xs.iter().map(|&x| Literal::usize_unsuffixed(x));
    quote!(&[#(#l),*])
}

fn names_list(xs: &[String]) -> String {
    xs.join(", ")
}
