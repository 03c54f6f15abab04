//! The trait `impl`s of a generated crate, from the catalogue: `Dynamics`, `DynamicsDerivatives`
//! (when the derivative kernel is emitted) and `Kernels` for a full crate; for a scene, the traits of `rbss_runtime::tasks` of its kernels and of its tasks
//! (with those they imply), and nothing else, so a solver of another task does not compile with
//! it. Each method is the catalogue's ([`catalog::Method`]), written once for both.

use proc_macro2::{Ident, Literal, TokenStream};
use quote::{format_ident, quote};

use super::{Selection, ik_order_doc, usize_list};
use crate::catalog::{self, Body, Method, Trait};
use crate::derive::Derivation;

/// What the `impl`s read of the robot.
pub(crate) struct Robot<'a> {
    pub ty: &'a Ident,
    pub d: &'a Derivation,
    /// `IK_BLOCK_ORDER`.
    pub ik_order: Literal,
    /// The kernels and solves the crate has.
    pub emitted: &'a [&'static str],
}

/// Every trait `impl` of the crate.
pub(crate) fn impls(r: &Robot<'_>, sel: Option<&Selection<'_>>) -> TokenStream {
    let traits: Vec<Trait> = match sel {
        None => catalog::FULL_TRAITS
            .into_iter()
            .filter(|&t| match t {
                Trait::Dynamics => r.d.dynamics.is_some(),
                Trait::DynamicsDerivatives => r.emitted.contains(&"dynamics_derivatives"),
                _ => true,
            })
            .collect(),
        Some(s) => {
            let mut traits: Vec<Trait> = catalog::SCENE_TRAITS
                .into_iter()
                .filter(|&t| t == Trait::Robot || has_kernel_of(t, r.emitted))
                .collect();
            traits.extend(s.scene.all_tasks().into_iter().map(Trait::Task));
            traits
        }
    };
    let items = traits.into_iter().map(|t| trait_impl(t, r));
    quote!(#(#items)*)
}

/// Whether the crate has one of the kernels (not only a solve) whose methods `t` holds.
fn has_kernel_of(t: Trait, emitted: &[&str]) -> bool {
    catalog::KERNELS
        .iter()
        .any(|k| !k.solve && k.scene == Some(t) && emitted.contains(&k.name))
}

fn trait_impl(t: Trait, r: &Robot<'_>) -> TokenStream {
    let path: TokenStream = parse(&t.path());
    let ty = r.ty;
    let ik = if matches!(t, Trait::Kernels | Trait::Robot) {
        let doc = ik_order_doc();
        let order = &r.ik_order;
        quote! {
            #doc
            const IK_BLOCK_ORDER: usize = #order;
        }
    } else {
        quote!()
    };
    let methods = catalog::impl_methods(t, r.emitted)
        .into_iter()
        .map(|m| method(m, r.d));
    quote! {
        impl #path<N, M> for #ty {
            #ik
            #(#methods)*
        }
    }
}

/// One method: its signature and what it does.
fn method(m: &Method, d: &Derivation) -> TokenStream {
    let name = format_ident!("{}", m.name);
    let args = m.args.iter().map(|(a, ty)| {
        let a = format_ident!("{a}");
        let ty: TokenStream = parse(ty);
        quote!(#a: #ty)
    });
    let ret = if m.ret.is_empty() {
        quote!()
    } else {
        let ty: TokenStream = parse(m.ret);
        quote!(-> #ty)
    };
    let names = m.args.iter().map(|(a, _)| format_ident!("{a}"));
    let body = match m.body {
        Body::Kernel => quote!(#name(&self.c, #(#names),*)),
        Body::Solve => quote!(#name(#(#names),*)),
        Body::Code(code) => parse(code),
        Body::Structure if m.name == "structure" => quote!(&STRUCTURE),
        Body::Structure => {
            let dy = d.dynamics.as_ref().expect("`mass_blocks` without dynamics");
            let blocks = dy.mass_blocks.iter().map(|b| usize_list(b));
            quote!(&[#(#blocks),*])
        }
    };
    quote! {
        fn #name(&self, #(#args),*) #ret {
            #body
        }
    }
}

/// Rust source of the catalogue as tokens.
fn parse(src: &str) -> TokenStream {
    src.parse()
        .unwrap_or_else(|e| panic!("the catalogue holds invalid Rust `{src}`: {e}"))
}
