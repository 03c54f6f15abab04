//! The inverse-kinematics blocks' linear solves, emitted: one function per kind of block (as
//! forward dynamics' `blocked`), and `ik_block_solve`, which dispatches a block to its kind's
//! function over constant index tables.
//!
//! Block `b` (rows `R_b`, columns `C_b`, `K_b = G[R_b, C_b]`) solves
//!
//! ```text
//! K_b x[C_b] = rhs[R_b] - G[R_b, outputs] x[outputs]      (the last term only if `outputs`)
//! ```
//!
//! which is every linear solve of inverse kinematics: a Newton step (`rhs = f`, no outputs:
//! they are fixed), the velocity (`rhs = 0`, `x[outputs]` the output rates) and the
//! acceleration (`rhs = gamma`). The function factors the block (the adjugate up to order 3,
//! elimination in a pivot order chosen at the home beyond, see `block`), writes `x[C_b]`, and
//! returns the block's condition number and the residual `max |K_b x[C_b] - (rhs[R_b] - ...)|`
//! of its rows; `None` where the threshold test refuses a pivot or the block is singular.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use super::block::{factor, solve};
use super::blocked::{add, classes};
use super::tape::{Flops, Tape, V};
use super::{Emitted, Structure, read_block, read_gz};

/// `ik_block_solve`'s items and body, or `None` when a block is not square or is structurally
/// singular (the runtime's general paths then solve every block).
pub fn ik_block_solve(s: &Structure<'_>) -> Option<Emitted> {
    let blocks = s.ik_blocks;
    if blocks.is_empty() || blocks.iter().any(|(r, c)| r.len() != c.len()) {
        return None;
    }
    let np = s.outputs.len();
    let mut items = TokenStream::new();
    let mut flops = Flops::default();
    let mut tables = Vec::new();
    let mut arms = Vec::new();
    for (ci, (_, class)) in classes(s, false).iter().enumerate() {
        let k = class.k;
        let (rows0, cols0) = &blocks[class.blocks[0]];
        let mut t = Tape::default();
        let kk = read_block(&mut t, s, rows0, cols0);
        let (f, cond) = factor(&mut t, &kk, 0)?;
        // rhs[R_b] - G[R_b, outputs] x[outputs], the product only when asked for.
        let gz = read_gz(&mut t, s, rows0);
        let xz: Vec<V> = s
            .outputs
            .iter()
            .map(|&z| t.push(quote!(x[#z]), 0.0))
            .collect();
        let r: Vec<V> = (0..k)
            .map(|j| {
                let base = t.push(quote!(rhs[rows[#j]]), 0.0);
                let terms: Vec<(f64, V, V)> = (0..np).map(|o| (1.0, gz[j][o], xz[o])).collect();
                match t.sum(&terms) {
                    V::Zero => base,
                    gx => {
                        let (tb, tg) = (Tape::tok(base), Tape::tok(gx));
                        t.push(quote!(if outputs { #tb - #tg } else { #tb }), 0.0)
                    }
                }
            })
            .collect();
        let xb = solve(&mut t, &f, &r);
        let res: Vec<V> = (0..k)
            .map(|j| {
                let mut terms = vec![(-1.0, r[j], V::One)];
                terms.extend((0..k).map(|i| (1.0, kk[j][i], xb[i])));
                t.sum(&terms)
            })
            .collect();
        let res = t.max_abs(&res);
        for (i, &v) in xb.iter().enumerate() {
            let tv = Tape::tok(v);
            t.stmt(quote!(x[cols[#i]] = #tv;));
        }
        let (tc, tr) = (Tape::tok(cond), Tape::tok(res));
        t.stmt(quote!(Some([#tc, #tr])));
        flops = add(flops, t.flops, class.blocks.len());
        let name = format_ident!("ik_block{}", ci);
        let k_lit = Literal::usize_unsuffixed(k);
        let body = t.into_tokens();
        items.extend(quote! {
            /// One inverse-kinematics block of this kind (see [`ik_block_solve`]): `K x[cols] =
            /// rhs[rows] - G[rows, outputs] x[outputs]`, the last term only if `outputs`.
            /// Returns `[cond(K), residual]`.
            #[inline(never)]
            #[allow(
                clippy::neg_multiply,
                clippy::neg_cmp_op_on_partial_ord,
                unused_variables
            )]
            fn #name(
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                outputs: bool,
                x: &mut [f64; N],
                rows: &[usize; #k_lit],
                cols: &[usize; #k_lit],
            ) -> Option<[f64; 2]> {
                #body
            }
        });
        let usizes = |v: &[usize]| {
            let l = v.iter().map(|&x| Literal::usize_unsuffixed(x));
            quote!([#(#l),*])
        };
        let nb_lit = Literal::usize_unsuffixed(class.blocks.len());
        let rows_t = class.blocks.iter().map(|&b| usizes(&blocks[b].0));
        let cols_t = class.blocks.iter().map(|&b| usizes(&blocks[b].1));
        let (rows_c, cols_c) = (format_ident!("ROWS{}", ci), format_ident!("COLS{}", ci));
        tables.push(quote! {
            const #rows_c: [[usize; #k_lit]; #nb_lit] = [#(#rows_t),*];
            const #cols_c: [[usize; #k_lit]; #nb_lit] = [#(#cols_t),*];
        });
        for (q, &b) in class.blocks.iter().enumerate() {
            arms.push((
                b,
                quote!(#b => #name(g, rhs, outputs, x, &#rows_c[#q], &#cols_c[#q]),),
            ));
        }
    }
    arms.sort_by_key(|(b, _)| *b);
    let arms = arms.into_iter().map(|(_, a)| a);
    let body = quote! {
        #(#tables)*
        match block {
            #(#arms)*
            _ => None,
        }
    };
    Some(Emitted { items, body, flops })
}
