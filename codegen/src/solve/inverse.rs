//! Inverse dynamics' block elimination, emitted (the runtime's `inverse_dynamics`, see its
//! documentation): with `b = M Ẍ - psi - Q` (formed over the structural non-zeros of `M`), each inverse-kinematics block `k` gives
//! `mu⁰_k = K_k⁻ᵀ b_k` and, for each of its actuators `a`, `w_a = K_k⁻ᵀ e_a`; the outputs' rows
//! give the square system `A U = G_oᵀ mu⁰ - b_o`, `A[o, a] = G[rows_k, o]ᵀ w_a`, solved by
//! elimination in a pivot order chosen at the home (see `square`; exact condition number);
//! then `mu_k = mu⁰_k - Σ_a w_a U_a` and `lambda = -mu`. One function per kind of block, as for
//! forward dynamics (`blocked`), and the residual of all N equations as the certificate.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use super::block::{factor, solve_t};
use super::blocked::{add, classes};
use super::square::square_solve;
use super::tape::{Flops, Tape, V};
use super::{Emitted, Structure, read, read_block, read_gz};

/// The emitted body of
/// `fn(g, mass, psi, xddot, q_forces, u, lambda) -> Option<SolveConditioning>` (`u` the `N - M`
/// control forces), with its per-block functions; `None` when a block is structurally
/// singular. The caller checks the structure (`solve::structured`).
pub fn inverse_dynamics(s: &Structure<'_>) -> Option<Emitted> {
    let np = s.outputs.len();
    let blocks = s.ik_blocks;
    let np_lit = Literal::usize_unsuffixed(np);
    let mut items = TokenStream::new();
    let mut flops = Flops::default();
    let outs = s.outputs.iter().map(|&z| Literal::usize_unsuffixed(z));
    let mut pre = vec![quote! {
        const OUT: [usize; #np_lit] = [#(#outs),*];
        // A (column-major: a[actuator][output]) and G_oᵀ mu⁰, accumulated block by block.
        let mut a = [[0.0_f64; #np_lit]; #np_lit];
        let mut rhs = [0.0_f64; #np_lit];
        let mut cond = 0.0_f64;
        // The outputs' rows of Gᵀ lambda, accumulated in the second pass.
        let mut glz = [0.0_f64; #np_lit];
        let mut residual = 0.0_f64;
    }];
    let mut post = Vec::new();
    let mut a_nz = vec![vec![false; np]; np];
    let mut a_home = vec![vec![0.0; np]; np];
    for (ci, (_, class)) in classes(s, false).iter().enumerate() {
        let k = class.k;
        let (rows0, cols0) = &blocks[class.blocks[0]];
        // The block's actuators: their positions in the block (the same for the class).
        let act_pos: Vec<usize> = (0..k).filter(|&c| s.actuated.contains(&cols0[c])).collect();
        let na = act_pos.len();
        let (k_lit, na_lit, nb_lit) = (
            Literal::usize_unsuffixed(k),
            Literal::usize_unsuffixed(na.max(1)),
            Literal::usize_unsuffixed(class.blocks.len()),
        );

        // First function: mu⁰, the w_a, and the block's share of A and the right-hand side.
        let mut t = Tape::default();
        let kk = read_block(&mut t, s, rows0, cols0);
        let (f, cond_b) = factor(&mut t, &kk, 0)?;
        let bb: Vec<V> = (0..k).map(|i| t.push(quote!(b[cols[#i]]), 0.0)).collect();
        let mu0 = solve_t(&mut t, &f, &bb);
        let ws: Vec<Vec<V>> = act_pos
            .iter()
            .map(|&p| {
                let e: Vec<V> = (0..k)
                    .map(|c| if c == p { V::One } else { V::Zero })
                    .collect();
                solve_t(&mut t, &f, &e)
            })
            .collect();
        let gz = read_gz(&mut t, s, rows0);
        // A's structural non-zeros and its values at the home, for the pivot order of the
        // reduced elimination (each actuator's column from its own block).
        for &b in &class.blocks {
            let (rows, cols) = &blocks[b];
            let home = block_columns_of_a(s, rows, cols, &act_pos)?;
            for (q, &p) in act_pos.iter().enumerate() {
                let slot = s.actuated.iter().position(|&a| a == cols[p])?;
                for o in 0..np {
                    let terms: Vec<(f64, V, V)> =
                        (0..k).map(|j| (1.0, gz[j][o], ws[q][j])).collect();
                    a_nz[slot][o] = terms.iter().any(|(_, x, y)| !x.is_zero() && !y.is_zero());
                    a_home[slot][o] = home[q][o];
                }
            }
        }
        for o in 0..np {
            let terms: Vec<(f64, V, V)> = (0..k).map(|j| (1.0, gz[j][o], mu0[j])).collect();
            let v = t.sum(&terms);
            if !v.is_zero() {
                let tv = Tape::tok(v);
                t.stmt(quote!(rhs[#o] += #tv;));
            }
            for (q, w) in ws.iter().enumerate() {
                let terms: Vec<(f64, V, V)> = (0..k).map(|j| (1.0, gz[j][o], w[j])).collect();
                let v = t.sum(&terms);
                if !v.is_zero() {
                    let tv = Tape::tok(v);
                    t.stmt(quote!(a[act[#q]][#o] += #tv;));
                }
            }
        }
        for (j, &v) in mu0.iter().enumerate() {
            let tv = Tape::tok(v);
            t.stmt(quote!(mu0[#j] = #tv;));
        }
        for (q, w) in ws.iter().enumerate() {
            for (j, &v) in w.iter().enumerate() {
                let tv = Tape::tok(v);
                t.stmt(quote!(w[#q][#j] = #tv;));
            }
        }
        let tc = Tape::tok(cond_b);
        t.stmt(quote!(Some(#tc)));
        flops = add(flops, t.flops, class.blocks.len());
        let first = format_ident!("id_block{}", ci);
        let body = t.into_tokens();
        items.extend(quote! {
            /// Inverse dynamics' block elimination, one inverse-kinematics block of this kind
            /// (see [`inverse_dynamics_solve`]): `mu⁰ = K⁻ᵀ b`, `w_a = K⁻ᵀ e_a` for its
            /// actuators, and its share of `A` and `G_oᵀ mu⁰`.
            #[inline(never)]
            #[allow(
                clippy::too_many_arguments,
                clippy::neg_multiply,
                clippy::neg_cmp_op_on_partial_ord,
                unused_variables
            )]
            fn #first(
                g: &[[f64; M]; N],
                b: &[f64; N],
                rows: &[usize; #k_lit],
                cols: &[usize; #k_lit],
                act: &[usize; #na_lit],
                a: &mut [[f64; #np_lit]; #np_lit],
                rhs: &mut [f64; #np_lit],
                mu0: &mut [f64; #k_lit],
                w: &mut [[f64; #k_lit]; #na_lit],
            ) -> Option<f64> {
                #body
            }
        });

        // Second function: lambda_k = -(mu⁰ - Σ_a w_a U_a), the block's residuals, and its
        // share of the outputs' rows of Gᵀ lambda.
        let mut t = Tape::default();
        let kk = read_block(&mut t, s, rows0, cols0);
        let mu0v: Vec<V> = (0..k).map(|j| t.push(quote!(mu0[#j]), 0.0)).collect();
        let wv: Vec<Vec<V>> = (0..na)
            .map(|q| (0..k).map(|j| t.push(quote!(w[#q][#j]), 0.0)).collect())
            .collect();
        let uv: Vec<V> = (0..na).map(|q| t.push(quote!(u[act[#q]]), 0.0)).collect();
        let lam: Vec<V> = (0..k)
            .map(|j| {
                let mut terms = vec![(-1.0, mu0v[j], V::One)];
                terms.extend((0..na).map(|q| (1.0, wv[q][j], uv[q])));
                t.sum(&terms)
            })
            .collect();
        // Residuals of the block's columns: b_c - S_c U + Σ_r G[r, c] lambda_r.
        let mut res = Vec::with_capacity(k);
        for c in 0..k {
            let bc = t.push(quote!(b[cols[#c]]), 0.0);
            let mut terms = vec![(1.0, bc, V::One)];
            if let Some(q) = act_pos.iter().position(|&p| p == c) {
                terms.push((-1.0, uv[q], V::One));
            }
            terms.extend((0..k).map(|j| (1.0, kk[j][c], lam[j])));
            res.push(t.sum(&terms));
        }
        let res = t.max_abs(&res);
        for o in 0..np {
            let z = s.outputs[o];
            let terms: Vec<(f64, V, V)> = (0..k)
                .map(|j| {
                    let gzo = read(&mut t, s.g[rows0[j]][z], quote!(g[#z][rows[#j]]));
                    (1.0, gzo, lam[j])
                })
                .collect();
            let v = t.sum(&terms);
            if !v.is_zero() {
                let tv = Tape::tok(v);
                t.stmt(quote!(glz[#o] += #tv;));
            }
        }
        for (j, &l) in lam.iter().enumerate() {
            let tl = Tape::tok(l);
            t.stmt(quote!(lambda[rows[#j]] = #tl;));
        }
        let tr = Tape::tok(res);
        t.stmt(quote!(#tr));
        flops = add(flops, t.flops, class.blocks.len());
        let second = format_ident!("id_block{}_finish", ci);
        let body = t.into_tokens();
        items.extend(quote! {
            /// Inverse dynamics' block elimination, one block of this kind, once `U` is known:
            /// its multipliers, its residuals, its share of `G_oᵀ lambda`.
            #[inline(never)]
            #[allow(clippy::too_many_arguments, clippy::neg_multiply, unused_variables)]
            fn #second(
                g: &[[f64; M]; N],
                b: &[f64; N],
                rows: &[usize; #k_lit],
                cols: &[usize; #k_lit],
                act: &[usize; #na_lit],
                mu0: &[f64; #k_lit],
                w: &[[f64; #k_lit]; #na_lit],
                u: &[f64; #np_lit],
                lambda: &mut [f64; M],
                glz: &mut [f64; #np_lit],
            ) -> f64 {
                #body
            }
        });

        let table = |f: &dyn Fn(usize) -> Vec<usize>| {
            let rows = class.blocks.iter().map(|&b| {
                let r = f(b).into_iter().map(Literal::usize_unsuffixed);
                quote!([#(#r),*])
            });
            quote!([#(#rows),*])
        };
        let rows_t = table(&|b| blocks[b].0.clone());
        let cols_t = table(&|b| blocks[b].1.clone());
        let act_t = table(&|b| {
            let cols = &blocks[b].1;
            let v: Vec<usize> = act_pos
                .iter()
                .map(|&p| s.actuated.iter().position(|&a| a == cols[p]).unwrap_or(0))
                .collect();
            if v.is_empty() { vec![0] } else { v }
        });
        let (rows_c, cols_c, act_c) = (
            format_ident!("ROWS{}", ci),
            format_ident!("COLS{}", ci),
            format_ident!("ACT{}", ci),
        );
        let (mu_v, w_v) = (format_ident!("mu0_{}", ci), format_ident!("w{}", ci));
        pre.push(quote! {
            const #rows_c: [[usize; #k_lit]; #nb_lit] = #rows_t;
            const #cols_c: [[usize; #k_lit]; #nb_lit] = #cols_t;
            const #act_c: [[usize; #na_lit]; #nb_lit] = #act_t;
            let mut #mu_v = [[0.0; #k_lit]; #nb_lit];
            let mut #w_v = [[[0.0; #k_lit]; #na_lit]; #nb_lit];
            for blk in 0..#nb_lit {
                let c = #first(
                    g, b, &#rows_c[blk], &#cols_c[blk], &#act_c[blk],
                    &mut a, &mut rhs, &mut #mu_v[blk], &mut #w_v[blk],
                )?;
                cond = cond.max(c);
            }
        });
        post.push(quote! {
            for blk in 0..#nb_lit {
                let r = #second(
                    g, b, &#rows_c[blk], &#cols_c[blk], &#act_c[blk],
                    &#mu_v[blk], &#w_v[blk], u, lambda, &mut glz,
                );
                residual = residual.max(r);
            }
        });
    }
    // b = M Ẍ - psi - Q over the structural non-zeros of M.
    let mut t = Tape::default();
    let n = s.n;
    let xdd: Vec<V> = (0..n).map(|i| t.push(quote!(xddot[#i]), 0.0)).collect();
    let bs: Vec<TokenStream> = (0..n)
        .map(|j| {
            let psi_j = t.push(quote!(psi[#j] + q[#j]), 0.0);
            let mut terms = vec![(-1.0, psi_j, V::One)];
            for i in 0..n {
                let m = read(&mut t, s.mass[j][i], quote!(mass[#i][#j]));
                terms.push((1.0, m, xdd[i]));
            }
            Tape::tok(t.sum(&terms))
        })
        .collect();
    let n_lit = Literal::usize_unsuffixed(n);
    t.stmt(quote!(let b: [f64; #n_lit] = [#(#bs),*];));
    flops = add(flops, t.flops, 1);
    let b_stmts = t.into_tokens();
    let (reduced_item, reduced_flops) =
        square_solve(&format_ident!("id_reduced"), &a_nz, &a_home, false)?;
    items.extend(reduced_item);
    flops = add(flops, reduced_flops, 1);
    let body = quote! {
        let u: &mut [f64; #np_lit] = u.try_into().ok()?;
        const NO_FORCES: [f64; N] = [0.0; N];
        let q = q_forces.unwrap_or(&NO_FORCES);
        #b_stmts
        let b = &b;
        #(#pre)*
        for o in 0..#np_lit {
            rhs[o] -= b[OUT[o]];
        }
        // A U = rhs by elimination in the pivot order chosen at the home (see `square`), with
        // A's exact condition number.
        let mut inv = [[0.0; #np_lit]; #np_lit];
        let anorm = rbss_runtime::linalg::norm1_fixed(&a);
        let inv_norm = id_reduced(&a, &rhs, u, &mut inv)?;
        let cond_a = anorm * inv_norm;
        #(#post)*
        for o in 0..#np_lit {
            residual = residual.max((b[OUT[o]] + glz[o]).abs());
        }
        Some(rbss_runtime::SolveConditioning {
            blocks: cond,
            reduced: cond_a,
            residual,
            backward_error: f64::NAN,
        })
    };
    Some(Emitted { items, body, flops })
}

/// The columns of `A` of one block (`rows`, `cols`) at the home, `[q][o]` for its actuators at
/// local positions `act` (`q`) and the outputs (`o`): `G[rows, o]ᵀ K⁻ᵀ e_act`, on a tape of its
/// own whose reference values are the block's.
fn block_columns_of_a(
    s: &Structure<'_>,
    rows: &[usize],
    cols: &[usize],
    act: &[usize],
) -> Option<Vec<Vec<f64>>> {
    let mut t = Tape::default();
    let k = rows.len();
    let kk = read_block(&mut t, s, rows, cols);
    let (f, _) = factor(&mut t, &kk, 0)?;
    let gz = read_gz(&mut t, s, rows);
    let out = act
        .iter()
        .map(|&p| {
            let e: Vec<V> = (0..k)
                .map(|c| if c == p { V::One } else { V::Zero })
                .collect();
            let w = solve_t(&mut t, &f, &e);
            (0..s.outputs.len())
                .map(|o| {
                    let terms: Vec<(f64, V, V)> = (0..k).map(|j| (1.0, gz[j][o], w[j])).collect();
                    let v = t.sum(&terms);
                    t.val(v)
                })
                .collect()
        })
        .collect();
    Some(out)
}
