//! The parameters and constants of a generated crate: `N`, `M`, `K`, the struct `Params` with
//! the model's values as its default, and `Params::consts`, which computes the parameter-only
//! quantities the kernels read.

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::quote;

use super::{Options, Selection, names_list};
use crate::derive::Derivation;
use crate::emit::{self, Consts, doc_attrs, f64_tokens};
use crate::graph::{Graph, Id, Node};
use crate::model::Model;

/// The parameters' items before the kernels are emitted (the constants they read are known
/// only after): the fields, their defaults and the `let`s that compute each parameter.
pub(crate) struct Params {
    fields: Vec<TokenStream>,
    defaults: Vec<TokenStream>,
    lets: Vec<(usize, TokenStream)>,
    doc: TokenStream,
}

impl Params {
    pub(crate) fn new(
        model: &Model,
        opts: &Options,
        sel: Option<&Selection<'_>>,
        model_path: &str,
    ) -> Self {
        let mut fields = Vec::new();
        let mut defaults = Vec::new();
        let mut lets = Vec::new();
        for (j, p) in model.parameters.iter().enumerate() {
            let id = Ident::new(&p.name, Span::call_site());
            if mentions_param(&p.expr) {
                let e = emit::expr_tokens(&p.expr, model);
                lets.push((j, quote!(let #id = #e;)));
                continue;
            }
            let unit = if p.unit.is_empty() {
                String::new()
            } else {
                format!(" \\[{}\\]", if p.unit == "deg" { "rad" } else { &p.unit })
            };
            // The model's text in a doc comment: brackets escaped, or rustdoc reads `[m]` as a
            // link.
            let mut doc = format!(
                "{}{unit}, {model_path}:{}",
                if p.doc.is_empty() {
                    format!("`{}`", p.name)
                } else {
                    p.doc.replace('[', "\\[").replace(']', "\\]")
                },
                p.pos.line
            );
            if p.unit == "deg" {
                doc.push_str(&format!(
                    " (written in degrees: {})",
                    emit::expr_string(&p.expr, model)
                ));
            }
            let doc = doc_attrs(&doc);
            fields.push(quote!(#doc pub #id: f64,));
            let v = f64_tokens(p.value);
            defaults.push(quote!(#id: #v,));
            lets.push((j, quote!(let #id = self.#id;)));
        }
        Params {
            fields,
            defaults,
            lets,
            doc: params_doc(model, opts, sel),
        }
    }

    /// `N`, `M`, `K`, `Params`, its default and `Params::consts`, once the kernels have
    /// collected the constants they read into `consts`.
    pub(crate) fn tokens(self, model: &Model, d: &Derivation, consts: &Consts) -> TokenStream {
        let n_lit = Literal::usize_unsuffixed(d.n);
        let m_lit = Literal::usize_unsuffixed(d.m);
        let coord_names: Vec<String> = model.coordinates.iter().map(|c| c.name.clone()).collect();
        let doc_n = doc_attrs(&format!(
            "Number of coordinates: `X = [{}]`.",
            names_list(&coord_names)
        ));
        let doc_m = doc_attrs(&format!(
            "Number of loop-closure equations `f(X) = 0`: [{}].",
            d.constraint_names.join(", ")
        ));
        let doc_k = doc_attrs("Number of constants the kernels read (see [`Params::consts`]).");
        // The model's parameter names are the fields' names, as written (`R`, `L1`).
        let snake = if model
            .parameters
            .iter()
            .any(|p| p.name.chars().any(|ch| ch.is_ascii_uppercase()))
        {
            quote!(#[allow(non_snake_case)])
        } else {
            quote!()
        };
        let (const_stmts, const_items, consts_doc, k_lit) =
            consts_tokens(model, &d.graph, consts, self.lets);
        let (params_doc, fields, defaults) = (self.doc, self.fields, self.defaults);
        quote! {
            #doc_n
            pub const N: usize = #n_lit;
            #doc_m
            pub const M: usize = #m_lit;
            #doc_k
            pub const K: usize = #k_lit;

            #params_doc
            #snake
            #[derive(Debug, Clone, Copy, PartialEq)]
            pub struct Params {
                #(#fields)*
            }

            impl Default for Params {
                fn default() -> Self {
                    Params { #(#defaults)* }
                }
            }

            #snake
            impl Params {
                #consts_doc
                pub fn consts(&self) -> [f64; K] {
                    #(#const_stmts)*
                    [#(#const_items),*]
                }
            }
        }
    }
}

/// The doc of `Params`: which parameters are derived, which frozen.
fn params_doc(model: &Model, opts: &Options, sel: Option<&Selection<'_>>) -> TokenStream {
    let derived_note = if model.parameters.iter().any(|p| mentions_param(&p.expr)) {
        "\n\nParameters whose value in the model is an expression of other parameters are not fields: \
         they are recomputed from the fields in [`Params::consts`]."
    } else {
        ""
    };
    let frozen_note = if let Some(s) = sel {
        match &s.scene.freeze {
            crate::scene::Freeze::None => String::new(),
            _ => format!(
                "\n\nScene `{}` freezes {}: their values are folded into the kernels, which do not \
                 read them; their fields only document them.",
                s.scene.name,
                model
                    .parameters
                    .iter()
                    .zip(&s.frozen)
                    .filter(|(_, f)| **f)
                    .map(|(p, _)| format!("`{}`", p.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    } else if opts.freeze {
        "\n\nGenerated with `--freeze`: the model's values are folded into the kernels, which read \
         no parameter; these fields only document them."
            .to_string()
    } else {
        String::new()
    };
    doc_attrs(&format!(
        "Parameters of `{}` in SI units (angles in rad). `Params::default()` holds the model file's values; \
         the line numbers point into the model file.{derived_note}{frozen_note}",
        model.name
    ))
}

/// `Params::consts`: the statements computing every slot of `consts` from the parameters it
/// needs (only those get a `let`), the slots' expressions, their documentation and `K`.
fn consts_tokens(
    model: &Model,
    g: &Graph,
    consts: &Consts,
    lets: Vec<(usize, TokenStream)>,
) -> (Vec<TokenStream>, Vec<TokenStream>, TokenStream, Literal) {
    // The parameters the slots read, and those the derived ones among them read.
    let mut needed = vec![false; model.parameters.len()];
    let mut stack: Vec<Id> = consts.slots.clone();
    let mut seen = std::collections::HashSet::new();
    while let Some(id) = stack.pop() {
        if !seen.insert(id) {
            continue;
        }
        match g.node(id) {
            Node::P(j) => needed[j as usize] = true,
            node => stack.extend(crate::graph::children(node)),
        }
    }
    for j in (0..needed.len()).rev() {
        if needed[j] {
            let mut mark = |k: usize| needed[k] = true;
            model.parameters[j].expr.for_each_param(&mut mark);
        }
    }
    // Temporaries must not shadow a parameter's name.
    let prefix = if model.parameters.iter().any(|p| {
        p.name
            .strip_prefix("k")
            .is_some_and(|r| !r.is_empty() && r.bytes().all(|b| b.is_ascii_digit()))
    }) {
        "k_"
    } else {
        "k"
    };
    let block = emit::emit_block(g, &consts.slots, prefix, &mut |id| match g.node(id) {
        Node::P(j) => {
            let id = Ident::new(&model.parameters[j as usize].name, Span::call_site());
            Some(quote!(#id))
        }
        _ if g.is_number(id) => Some(f64_tokens(g.eval(id, &[], &[], &[]))),
        _ => None,
    });
    let mut stmts: Vec<TokenStream> = lets
        .into_iter()
        .filter(|(j, _)| needed[*j])
        .map(|(_, t)| t)
        .collect();
    stmts.extend(block.stmts);
    let mut doc = String::from(
        "The parameter-only quantities the kernels read, computed once from the parameters:\n",
    );
    for (l, &id) in consts.slots.iter().enumerate() {
        doc.push_str(&format!(
            "\n- `c[{l}]` = {}",
            emit::node_string(g, id, model)
        ));
    }
    if consts.slots.is_empty() {
        doc = "The kernels read no parameter: this table is empty.".to_string();
    }
    (
        stmts,
        block.roots,
        doc_attrs(&doc),
        Literal::usize_unsuffixed(consts.slots.len()),
    )
}

/// True when the expression reads a parameter (a derived parameter).
fn mentions_param(e: &crate::model::Expr) -> bool {
    let mut any = false;
    e.for_each_param(&mut |_| any = true);
    any
}
