//! The robot's structure in a generated crate: the static `STRUCTURE` (names, index sets, the
//! inverse-kinematics blocks, the assembled home, the gear ratios), the robot's type with its
//! constants, and the names of the closure checks (`MC`) and of the bodies (`NB`).

use proc_macro2::{Ident, Literal, TokenStream};
use quote::quote;

use super::{camel, usize_list};
use crate::derive::Derivation;
use crate::emit::{doc_attrs, f64_tokens};
use crate::model::Model;

/// `STRUCTURE`, the robot's type and, where the crate has their kernels, the closure checks'
/// and the bodies' names.
pub(crate) fn tokens(
    model: &Model,
    d: &Derivation,
    home: &[f64],
    robot: &Ident,
    emitted: &[&str],
) -> TokenStream {
    let structure = structure_static(model, d, home);
    let robot_doc = doc_attrs(&format!(
        "The robot `{}` ({}), with its constants prepared for the kernels.\n\n\
         `{}::default()` uses the model's parameter values; `{}::new(&params)` others.",
        model.name,
        model.description,
        camel(&model.name),
        camel(&model.name)
    ));
    let mc_item = if emitted.contains(&"closure_check") {
        let mc_lit = Literal::usize_unsuffixed(d.checks.len());
        let check_names_ts = d.check_names.iter().map(|s| quote!(#s));
        let mc_doc =
            doc_attrs("Number of loop components checked but not solved (see [`closure_check`]).");
        let checks_doc = doc_attrs("Their names, `loop.axis`.");
        quote! {
            #mc_doc
            pub const MC: usize = #mc_lit;
            #checks_doc
            pub const CLOSURE_CHECKS: [&str; MC] = [#(#check_names_ts),*];
        }
    } else {
        quote!()
    };
    let nb_item = if emitted.contains(&"body_frames") {
        let nb_lit = Literal::usize_unsuffixed(model.bodies.len());
        let body_names_ts = model.bodies.iter().map(|b| {
            let s = &b.name;
            quote!(#s)
        });
        let nb_doc =
            doc_attrs("Number of bodies (frames) in [`BODIES`], the rows of [`body_frames`].");
        let bodies_doc = doc_attrs("Body names, in model order.");
        quote! {
            #nb_doc
            pub const NB: usize = #nb_lit;
            #bodies_doc
            pub const BODIES: [&str; NB] = [#(#body_names_ts),*];
        }
    } else {
        quote!()
    };
    quote! {
        #structure

        #robot_doc
        #[derive(Debug, Clone, Copy)]
        pub struct #robot {
            /// Constants read by the kernels, from [`Params::consts`].
            pub c: [f64; K],
        }

        impl #robot {
            /// The robot with the given parameters.
            pub fn new(params: &Params) -> Self {
                #robot { c: params.consts() }
            }
        }

        impl Default for #robot {
            fn default() -> Self {
                Self::new(&Params::default())
            }
        }

        #mc_item

        #nb_item
    }
}

/// `pub static STRUCTURE: Structure`.
fn structure_static(model: &Model, d: &Derivation, home: &[f64]) -> TokenStream {
    let coord_of = |js: &[usize]| -> String {
        js.iter()
            .map(|&j| model.coordinates[j].name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let name_str = &model.name;
    let coords_ts = model.coordinates.iter().map(|c| {
        let s = &c.name;
        quote!(#s)
    });
    let cons_ts = d.constraint_names.iter().map(|s| quote!(#s));
    let act = usize_list(&model.actuated);
    let pas = usize_list(&d.passive);
    let outs = usize_list(&model.outputs);
    let blocks = d.ik_blocks.iter().map(|(r, c)| {
        let r = usize_list(r);
        let c = usize_list(c);
        quote!(IkBlock { rows: #r, cols: #c })
    });
    let homes = home.iter().map(|&h| f64_tokens(h));
    // The actuators' gear ratios, where the model gives any (`U` in the motors' units).
    let geared = model
        .actuated
        .iter()
        .any(|&j| model.coordinates[j].gear.is_some());
    let gears: Vec<TokenStream> = model
        .actuated
        .iter()
        .filter(|_| geared)
        .map(|&j| f64_tokens(model.coordinates[j].gear.unwrap_or(1.0)))
        .collect();
    let structure_doc = doc_attrs(&format!(
        "Structure of `{}`: q = [{}], p = [{}], outputs = [{}], {} independent IK blocks.",
        model.name,
        coord_of(&model.actuated),
        coord_of(&d.passive),
        coord_of(&model.outputs),
        d.ik_blocks.len()
    ));
    quote! {
        #structure_doc
        pub static STRUCTURE: Structure = Structure {
            name: #name_str,
            coordinates: &[#(#coords_ts),*],
            constraints: &[#(#cons_ts),*],
            actuated: #act,
            passive: #pas,
            outputs: #outs,
            ik_blocks: &[#(#blocks),*],
            home: &[#(#homes),*],
            gear: &[#(#gears),*],
        };
    }
}
