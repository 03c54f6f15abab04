//! Forward dynamics' elimination with one function per kind of inverse-kinematics block.
//!
//! Written out as one straight line, the solve of a six-legged platform is some 30 KB of code;
//! beside its kernel (16 KB) that is more than the processor's first-level instruction cache,
//! and the solve then ran at less than half its speed (the 6-UPS: 415 ns alone, 1.1 µs right
//! after `dynamics_terms`). The legs of a parallel robot are alike: where several blocks have
//! the same pattern (the same structural zeros and the same numbers in `G` and `M`), their
//! work is one function, called once per block over index tables, and the code is a few
//! kilobytes.
//!
//! It needs the blocks not to share mass: `M` zero between the columns of two different
//! blocks (a leg's bodies move with that leg's coordinates and the outputs only). Then
//! `Rᵀ M R = M_zz + Σ_b (W_bᵀ M_b W_b - M_zb W_b - W_bᵀ M_bz)` and `Rᵀ (F - M r0) = F_z - Σ_b
//! (W_bᵀ (F_b - M_b r0_b) + M_zb r0_b)` with `W_b = K_b⁻¹ G[rows_b, z]`, `r0_b = K_b⁻¹ gamma_b`,
//! accumulated block by block; after the Cholesky solve for `z̈`, each block's `Ẍ_b = r0_b - W_b
//! z̈` and `K_bᵀ lambda_b = F_b - M_b Ẍ_b - M_bz z̈`.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use super::block::{Factor, factor, solve, solve_t};
use super::tape::{Flops, Tape, V};
use super::{Emitted, Entry, Structure, cholesky_solve, read, read_block, read_gz};

/// The pattern of an entry: what makes two blocks' code the same.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Key {
    Zero,
    Number(u64),
    Var,
}

fn key(e: Entry) -> Key {
    match e {
        Entry::Zero => Key::Zero,
        Entry::Number(x) => Key::Number(x.to_bits()),
        Entry::Var(_) => Key::Var,
    }
}

/// Blocks that share one function.
pub(super) struct Class {
    /// Indices into `Structure::ik_blocks`.
    pub blocks: Vec<usize>,
    pub k: usize,
}

/// The blocks grouped by pattern: `K`, `G[rows, outputs]`, which of the block's columns are
/// actuated, and with `mass`, `M_b`.
pub(super) fn classes(s: &Structure<'_>, mass: bool) -> Vec<(Vec<Key>, Class)> {
    let blocks = s.ik_blocks;
    let pattern = |b: usize| -> Vec<Key> {
        let (rows, cols) = &blocks[b];
        let mut p = Vec::new();
        for &r in rows {
            p.extend(cols.iter().map(|&c| key(s.g[r][c])));
            p.extend(s.outputs.iter().map(|&z| key(s.g[r][z])));
        }
        p.extend(cols.iter().map(|c| {
            if s.actuated.contains(c) {
                Key::Var
            } else {
                Key::Zero
            }
        }));
        if mass {
            for &i in cols {
                p.extend(cols.iter().map(|&j| key(s.mass[i][j])));
                p.extend(s.outputs.iter().map(|&z| key(s.mass[i][z])));
            }
        }
        p
    };
    let mut classes: Vec<(Vec<Key>, Class)> = Vec::new();
    for b in 0..blocks.len() {
        let p = pattern(b);
        match classes.iter_mut().find(|(q, _)| *q == p) {
            Some((_, c)) => c.blocks.push(b),
            None => classes.push((
                p,
                Class {
                    blocks: vec![b],
                    k: blocks[b].0.len(),
                },
            )),
        }
    }
    classes
}

/// The solve with a function per class of alike blocks, or `None` when two blocks share mass
/// (the robot then has no generated solve: the runtime's general paths solve it) or a block is
/// structurally singular.
pub fn forward_dynamics(s: &Structure<'_>) -> Option<Emitted> {
    if shares_mass(s) {
        return None;
    }
    let np = s.outputs.len();
    let classes = classes(s, true);
    let mut items = TokenStream::new();
    let mut flops = Flops::default();
    let np_lit = Literal::usize_unsuffixed(np);
    let mut pre = reduced_start(s);
    let mut post = Vec::new();
    for (ci, (_, class)) in classes.iter().enumerate() {
        let times = class.blocks.len();
        let first = block_first(s, ci, class)?;
        let (second, second_flops) = block_finish(s, ci, class, &first);
        flops = add(flops, first.flops, times);
        flops = add(flops, second_flops, times);
        let (p, q) = block_calls(s, ci, class, first.fvals.len());
        items.extend(first.item);
        items.extend(second);
        pre.push(p);
        post.push(q);
    }
    let (reduced, reduced_flops) = reduced_solve(np)?;
    flops = add(flops, reduced_flops, 1);
    items.extend(reduced);
    items.extend(fd_max_item());
    let (eta, eta_flops) = if blocks_separate(s) {
        items.extend(norms_item(s));
        backward_error(s)
    } else {
        (quote!(f64::NAN), Flops::default())
    };
    flops = add(flops, eta_flops, 1);
    let body = quote! {
        #(#pre)*
        let (zdd, ratio) = fd_reduced(&a, &rhs)?;
        for o in 0..#np_lit {
            xddot[OUT[o]] = zdd[o];
        }
        #(#post)*
        let backward_error = { #eta };
        Some(rbss_runtime::SolveConditioning {
            blocks: cond,
            reduced: ratio,
            residual,
            backward_error,
        })
    };
    Some(Emitted { items, body, flops })
}

/// Whether two different blocks share mass (a body moved by two legs' coordinates).
fn shares_mass(s: &Structure<'_>) -> bool {
    let n = s.n;
    let blocks = s.ik_blocks;
    // Mass local to each block.
    let mut owner = vec![usize::MAX; n];
    for (b, (_, cols)) in blocks.iter().enumerate() {
        for &c in cols {
            owner[c] = b;
        }
    }
    for (i, row) in s.mass.iter().enumerate() {
        for (j, &e) in row.iter().enumerate() {
            // Two different blocks sharing mass (a body moved by two legs' coordinates).
            if e != Entry::Zero
                && owner[i] != owner[j]
                && owner[i] != usize::MAX
                && owner[j] != usize::MAX
            {
                return true;
            }
        }
    }
    false
}

/// Whether every constraint row is in exactly one block and `G` is zero between a block's
/// columns and the other blocks' rows: what the blocks' shares of the backward error assume
/// (elsewhere the solve reports none, NaN, and the runtime forms it).
fn blocks_separate(s: &Structure<'_>) -> bool {
    let mut owner = vec![usize::MAX; s.m];
    for (b, (rows, _)) in s.ik_blocks.iter().enumerate() {
        for &r in rows {
            if std::mem::replace(&mut owner[r], b) != usize::MAX {
                return false;
            }
        }
    }
    owner.iter().all(|&b| b != usize::MAX)
        && s.ik_blocks.iter().enumerate().all(|(b, (_, cols))| {
            cols.iter()
                .all(|&c| (0..s.m).all(|r| owner[r] == b || s.g[r][c] == Entry::Zero))
        })
}

/// The packed upper triangle of A (order `np`), row by row: row o1 starts at Σ_{q<o1} (np - q).
fn upper(np: usize, o1: usize, o2: usize) -> usize {
    (0..o1).map(|q| np - q).sum::<usize>() + (o2 - o1)
}

/// The statements before the blocks: `OUT`, A as `M_zz` and the right-hand side as `F_z`.
fn reduced_start(s: &Structure<'_>) -> Vec<TokenStream> {
    let np = s.outputs.len();
    let np_lit = Literal::usize_unsuffixed(np);
    let na_lit = Literal::usize_unsuffixed(np * (np + 1) / 2);
    let outs = s.outputs.iter().map(|&z| Literal::usize_unsuffixed(z));
    let mut pre = vec![quote! {
        const OUT: [usize; #np_lit] = [#(#outs),*];
    }];
    let mut a_init = Vec::new();
    for o1 in 0..np {
        for o2 in o1..np {
            let (z1, z2) = (s.outputs[o1], s.outputs[o2]);
            a_init.push(match s.mass[z1][z2] {
                Entry::Zero => quote!(0.0),
                Entry::Number(x) => {
                    let l = Literal::f64_suffixed(x);
                    quote!(#l)
                }
                Entry::Var(_) => quote!(mass[#z2][#z1]),
            });
        }
    }
    pre.push(quote! {
        let mut a: [f64; #na_lit] = [#(#a_init),*];
        let mut rhs: [f64; #np_lit] = core::array::from_fn(|o| force[OUT[o]]);
        let mut cond = 0.0_f64;
        let mut residual = 0.0_f64;
        // The backward error's shares of the blocks (see `backward_error`): per output, its
        // row of `M Ẍ + Gᵀ lambda` over the blocks; the norms of the blocks' rows of `r1`,
        // of `Ẍ` and of `lambda`.
        let mut acc = [0.0_f64; #np_lit];
        let mut nrm = [0.0_f64; 3];
    });
    pre
}

/// A class's first function and what its second one reads of it.
struct Block {
    item: TokenStream,
    flops: Flops,
    /// `W = K⁻¹ G[rows, outputs]` and `r0 = K⁻¹ gamma` (k × np, k).
    w: Vec<Vec<V>>,
    r0: Vec<V>,
    f: Factor,
    /// The factor's values, kept in `fac`.
    fvals: Vec<V>,
}

/// The first function of class `ci`: factor, W, r0, and the block's share of A and the
/// right-hand side.
fn block_first(s: &Structure<'_>, ci: usize, class: &Class) -> Option<Block> {
    let np = s.outputs.len();
    let k = class.k;
    let (rows0, cols0) = &s.ik_blocks[class.blocks[0]];
    let k_lit = Literal::usize_unsuffixed(k);
    let np_lit = Literal::usize_unsuffixed(np);
    let na_lit = Literal::usize_unsuffixed(np * (np + 1) / 2);
    let mut t = Tape::default();
    let kk = read_block(&mut t, s, rows0, cols0);
    let (f, cond_b) = factor(&mut t, &kk, 0)?;
    let mut w = vec![vec![V::Zero; np]; k];
    for o in 0..np {
        let z = s.outputs[o];
        let rhs: Vec<V> = (0..k)
            .map(|j| read(&mut t, s.g[rows0[j]][z], quote!(g[#z][rows[#j]])))
            .collect();
        let x = solve(&mut t, &f, &rhs);
        for i in 0..k {
            w[i][o] = x[i];
        }
    }
    let gam: Vec<V> = (0..k)
        .map(|j| t.push(quote!(gamma[rows[#j]]), 0.0))
        .collect();
    let r0 = solve(&mut t, &f, &gam);
    let mb: Vec<Vec<V>> = (0..k)
        .map(|i| {
            (0..k)
                .map(|j| {
                    read(
                        &mut t,
                        s.mass[cols0[i]][cols0[j]],
                        quote!(mass[cols[#j]][cols[#i]]),
                    )
                })
                .collect()
        })
        .collect();
    let fb: Vec<V> = (0..k)
        .map(|i| t.push(quote!(force[cols[#i]]), 0.0))
        .collect();
    // The block's mass coupled with the outputs, M[cols, outputs] (a leg on a moving base).
    let mbz: Vec<Vec<V>> = (0..k)
        .map(|i| {
            (0..np)
                .map(|o| {
                    let z = s.outputs[o];
                    read(&mut t, s.mass[cols0[i]][z], quote!(mass[#z][cols[#i]]))
                })
                .collect()
        })
        .collect();
    // M_b W_b (k × np) and A += W_bᵀ (M_b W_b) - M_zb W_b - W_bᵀ M_bz.
    let mw: Vec<Vec<V>> = (0..k)
        .map(|i| {
            (0..np)
                .map(|o| {
                    let terms: Vec<(f64, V, V)> =
                        (0..k).map(|j| (1.0, mb[i][j], w[j][o])).collect();
                    t.sum(&terms)
                })
                .collect()
        })
        .collect();
    for o1 in 0..np {
        for o2 in o1..np {
            let mut terms: Vec<(f64, V, V)> = (0..k).map(|i| (1.0, w[i][o1], mw[i][o2])).collect();
            terms.extend((0..k).map(|i| (-1.0, mbz[i][o1], w[i][o2])));
            terms.extend((0..k).map(|i| (-1.0, w[i][o1], mbz[i][o2])));
            let v = t.sum(&terms);
            if !v.is_zero() {
                let (idx, tv) = (upper(np, o1, o2), Tape::tok(v));
                t.stmt(quote!(a[#idx] += #tv;));
            }
        }
    }
    // rhs -= W_bᵀ (F_b - M_b r0_b) + M_zb r0_b.
    let fr: Vec<V> = (0..k)
        .map(|i| {
            let mut terms = vec![(1.0, fb[i], V::One)];
            terms.extend((0..k).map(|j| (-1.0, mb[i][j], r0[j])));
            t.sum(&terms)
        })
        .collect();
    for o in 0..np {
        let mut terms: Vec<(f64, V, V)> = (0..k).map(|i| (1.0, w[i][o], fr[i])).collect();
        terms.extend((0..k).map(|i| (1.0, mbz[i][o], r0[i])));
        let v = t.sum(&terms);
        if !v.is_zero() {
            let tv = Tape::tok(v);
            t.stmt(quote!(rhs[#o] -= #tv;));
        }
    }
    // Keep W, r0 and the factor for the second function.
    for (i, row) in w.iter().enumerate() {
        for (o, &v) in row.iter().enumerate() {
            if matches!(v, V::T(_)) {
                let tv = Tape::tok(v);
                t.stmt(quote!(w[#i][#o] = #tv;));
            }
        }
    }
    for (i, &v) in r0.iter().enumerate() {
        if matches!(v, V::T(_)) {
            let tv = Tape::tok(v);
            t.stmt(quote!(r0[#i] = #tv;));
        }
    }
    let fvals = f.values();
    for (q, &v) in fvals.iter().enumerate() {
        let tv = Tape::tok(v);
        t.stmt(quote!(fac[#q] = #tv;));
    }
    let tc = Tape::tok(cond_b);
    t.stmt(quote!(Some(#tc)));
    let flops = t.flops;
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    let name = format_ident!("fd_block{}", ci);
    let body = t.into_tokens();
    let item = quote! {
        /// Forward dynamics' elimination, one inverse-kinematics block of this kind (see
        /// [`forward_dynamics_solve`]): its factor, `W = K⁻¹ G[rows, outputs]`,
        /// `r0 = K⁻¹ gamma`, and its share of the reduced mass matrix and right-hand side.
        #[inline(never)]
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            clippy::neg_cmp_op_on_partial_ord,
            unused_variables
        )]
        fn #name(
            g: &[[f64; M]; N],
            mass: &[[f64; N]; N],
            force: &[f64; N],
            gamma: &[f64; M],
            rows: &[usize; #k_lit],
            cols: &[usize; #k_lit],
            a: &mut [f64; #na_lit],
            rhs: &mut [f64; #np_lit],
            w: &mut [[f64; #np_lit]; #k_lit],
            r0: &mut [f64; #k_lit],
            fac: &mut [f64; #nf_lit],
        ) -> Option<f64> {
            #body
        }
    };
    Some(Block {
        item,
        flops,
        w,
        r0,
        f,
        fvals,
    })
}

/// The second function of class `ci`: Ẍ_b, lambda_b and the block's residual, given z̈.
fn block_finish(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    first: &Block,
) -> (TokenStream, Flops) {
    let np = s.outputs.len();
    let k = class.k;
    let (rows0, cols0) = &s.ik_blocks[class.blocks[0]];
    let k_lit = Literal::usize_unsuffixed(k);
    let np_lit = Literal::usize_unsuffixed(np);
    let Block {
        w, r0, f, fvals, ..
    } = first;
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    let mut t = Tape::default();
    let kk = read_block(&mut t, s, rows0, cols0);
    let gz = read_gz(&mut t, s, rows0);
    let w2: Vec<Vec<V>> = w
        .iter()
        .enumerate()
        .map(|(i, row)| {
            row.iter()
                .enumerate()
                .map(|(o, &v)| match v {
                    V::T(_) => t.push(quote!(w[#i][#o]), 0.0),
                    other => other,
                })
                .collect()
        })
        .collect();
    let r02: Vec<V> = r0
        .iter()
        .enumerate()
        .map(|(i, &v)| match v {
            V::T(_) => t.push(quote!(r0[#i]), 0.0),
            other => other,
        })
        .collect();
    let loaded: Vec<V> = (0..fvals.len())
        .map(|q| t.push(quote!(fac[#q]), 0.0))
        .collect();
    let f2 = f.map(&|v: V| match fvals.iter().position(|&u| u == v) {
        Some(q) => loaded[q],
        None => v,
    });
    let zdd: Vec<V> = (0..np).map(|o| t.push(quote!(zdd[#o]), 0.0)).collect();
    let mb: Vec<Vec<V>> = (0..k)
        .map(|i| {
            (0..k)
                .map(|j| {
                    read(
                        &mut t,
                        s.mass[cols0[i]][cols0[j]],
                        quote!(mass[cols[#j]][cols[#i]]),
                    )
                })
                .collect()
        })
        .collect();
    let fb: Vec<V> = (0..k)
        .map(|i| t.push(quote!(force[cols[#i]]), 0.0))
        .collect();
    let gam: Vec<V> = (0..k)
        .map(|j| t.push(quote!(gamma[rows[#j]]), 0.0))
        .collect();
    let xb: Vec<V> = (0..k)
        .map(|i| {
            let mut terms = vec![(1.0, r02[i], V::One)];
            terms.extend((0..np).map(|o| (-1.0, w2[i][o], zdd[o])));
            t.sum(&terms)
        })
        .collect();
    let mut v = Vec::with_capacity(k);
    let mut mbz = Vec::with_capacity(k);
    for i in 0..k {
        let mut terms = vec![(1.0, fb[i], V::One)];
        terms.extend((0..k).map(|j| (-1.0, mb[i][j], xb[j])));
        let mut row = Vec::with_capacity(np);
        for o in 0..np {
            let z = s.outputs[o];
            let m = read(&mut t, s.mass[cols0[i]][z], quote!(mass[#z][cols[#i]]));
            terms.push((-1.0, m, zdd[o]));
            row.push(m);
        }
        mbz.push(row);
        v.push(t.sum(&terms));
    }
    let lam = solve_t(&mut t, &f2, &v);
    let res: Vec<V> = (0..k)
        .map(|j| {
            let mut terms = vec![(-1.0, gam[j], V::One)];
            terms.extend((0..k).map(|i| (1.0, kk[j][i], xb[i])));
            terms.extend((0..np).map(|o| (1.0, gz[j][o], zdd[o])));
            t.sum(&terms)
        })
        .collect();
    let res = t.max_abs(&res);
    // The backward error's share of the block (see `backward_error`). Its columns' rows of
    // `F - M Ẍ - Gᵀ lambda`: `v - K_bᵀ lambda_b` (`G`'s columns of the block are zero outside
    // its rows, `M`'s rows zero outside its columns and the outputs).
    let r1: Vec<V> = (0..k)
        .map(|i| {
            let mut terms = vec![(1.0, v[i], V::One)];
            terms.extend((0..k).map(|j| (-1.0, kk[j][i], lam[j])));
            t.sum(&terms)
        })
        .collect();
    // The outputs' rows of `M Ẍ + Gᵀ lambda` over the block.
    for o in 0..np {
        let mut terms: Vec<(f64, V, V)> = (0..k).map(|i| (1.0, mbz[i][o], xb[i])).collect();
        terms.extend((0..k).map(|j| (1.0, gz[j][o], lam[j])));
        let sh = t.sum(&terms);
        if !sh.is_zero() {
            let ts = Tape::tok(sh);
            t.stmt(quote!(acc[#o] += #ts;));
        }
    }
    // The norms of the residual and the answer (those of `G`, `M`, `F` and `gamma`, with
    // constant indices: `backward_error`).
    let shares = [
        (0usize, fast_max(&mut t, &r1, true)),
        (1, fast_max(&mut t, &xb, true)),
        (2, fast_max(&mut t, &lam, true)),
    ];
    for (q, sh) in shares {
        if !sh.is_zero() {
            let ts = Tape::tok(sh);
            t.stmt(quote!(nrm[#q] = fd_max(nrm[#q], #ts);));
        }
    }
    for (i, &x) in xb.iter().enumerate() {
        let tx = Tape::tok(x);
        t.stmt(quote!(xddot[cols[#i]] = #tx;));
    }
    for (j, &l) in lam.iter().enumerate() {
        let tl = Tape::tok(l);
        t.stmt(quote!(lambda[rows[#j]] = #tl;));
    }
    let tr = Tape::tok(res);
    t.stmt(quote!(#tr));
    let flops = t.flops;
    let name = format_ident!("fd_block{}_finish", ci);
    let body = t.into_tokens();
    let item = quote! {
        /// Forward dynamics' elimination, one inverse-kinematics block of this kind, after
        /// the reduced solve: `Ẍ_b = r0 - W z̈`, `K_bᵀ lambda_b = F_b - M_b Ẍ_b`; returns
        /// the block's `max |G Ẍ - gamma|` and adds its share of the backward error to
        /// `acc` and `nrm`.
        #[inline(never)]
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            unused_variables
        )]
        fn #name(
            g: &[[f64; M]; N],
            mass: &[[f64; N]; N],
            force: &[f64; N],
            gamma: &[f64; M],
            rows: &[usize; #k_lit],
            cols: &[usize; #k_lit],
            w: &[[f64; #np_lit]; #k_lit],
            r0: &[f64; #k_lit],
            fac: &[f64; #nf_lit],
            zdd: &[f64; #np_lit],
            xddot: &mut [f64; N],
            lambda: &mut [f64; M],
            acc: &mut [f64; #np_lit],
            nrm: &mut [f64; 3],
        ) -> f64 {
            #body
        }
    };
    (item, flops)
}

/// The calls of class `ci`'s functions over its index tables: before the reduced solve, and
/// after it.
fn block_calls(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    nf: usize,
) -> (TokenStream, TokenStream) {
    let blocks = s.ik_blocks;
    let np_lit = Literal::usize_unsuffixed(s.outputs.len());
    let k_lit = Literal::usize_unsuffixed(class.k);
    let nb_lit = Literal::usize_unsuffixed(class.blocks.len());
    let nf_lit = Literal::usize_unsuffixed(nf.max(1));
    let (first, second) = (
        format_ident!("fd_block{}", ci),
        format_ident!("fd_block{}_finish", ci),
    );
    let rows_t = class.blocks.iter().map(|&b| {
        let r = blocks[b].0.iter().map(|&x| Literal::usize_unsuffixed(x));
        quote!([#(#r),*])
    });
    let cols_t = class.blocks.iter().map(|&b| {
        let c = blocks[b].1.iter().map(|&x| Literal::usize_unsuffixed(x));
        quote!([#(#c),*])
    });
    let (rows_c, cols_c) = (format_ident!("ROWS{}", ci), format_ident!("COLS{}", ci));
    let (w_v, r0_v, fac_v) = (
        format_ident!("w{}", ci),
        format_ident!("r0_{}", ci),
        format_ident!("fac{}", ci),
    );
    let pre = quote! {
        const #rows_c: [[usize; #k_lit]; #nb_lit] = [#(#rows_t),*];
        const #cols_c: [[usize; #k_lit]; #nb_lit] = [#(#cols_t),*];
        let mut #w_v = [[[0.0; #np_lit]; #k_lit]; #nb_lit];
        let mut #r0_v = [[0.0; #k_lit]; #nb_lit];
        let mut #fac_v = [[0.0; #nf_lit]; #nb_lit];
        for b in 0..#nb_lit {
            let c = #first(
                g, mass, force, gamma, &#rows_c[b], &#cols_c[b],
                &mut a, &mut rhs, &mut #w_v[b], &mut #r0_v[b], &mut #fac_v[b],
            )?;
            cond = cond.max(c);
        }
    };
    let post = quote! {
        for b in 0..#nb_lit {
            let r = #second(
                g, mass, force, gamma, &#rows_c[b], &#cols_c[b],
                &#w_v[b], &#r0_v[b], &#fac_v[b], &zdd, xddot, lambda, &mut acc, &mut nrm,
            );
            residual = residual.max(r);
        }
    };
    (pre, post)
}

/// The answer's normwise relative backward error, after the blocks' finishing functions
/// (their shares in `acc` and `nrm`): the expression of the body's `backward_error`, as the
/// runtime defines it (`rbss_runtime::algorithm::forward_dynamics`, ∞-norms, `‖Gᵀ‖∞` the largest
/// column sum of `G`, a zero residual exact, NaN made infinite):
///
/// `max(‖r1‖ / (‖M‖ ‖Ẍ‖ + ‖Gᵀ‖ ‖lambda‖ + ‖F‖), ‖r2‖ / (‖G‖ ‖Ẍ‖ + ‖gamma‖))` with the
/// residuals `r1 = F - M Ẍ - Gᵀ lambda`, `r2 = gamma - G Ẍ` of the answer, formed over the
/// structural non-zeros (`r2` is the blocks' `residual`). Here the outputs' rows of `r1`
/// (`M_zz z̈` and the blocks' shares) and the norms of `M`, `G`, `F` and `gamma`, straight-line
/// over the structural non-zeros with constant indices (in the per-block functions their
/// index tables cost more than the sums).
fn backward_error(s: &Structure<'_>) -> (TokenStream, Flops) {
    let np = s.outputs.len();
    let mut t = Tape::default();
    let zdd: Vec<V> = (0..np).map(|o| t.push(quote!(zdd[#o]), 0.0)).collect();
    let nrm: Vec<V> = (0..3usize).map(|q| t.push(quote!(nrm[#q]), 0.0)).collect();
    let mut r1 = Vec::with_capacity(np);
    for o in 0..np {
        let z = s.outputs[o];
        let f = t.push(quote!(force[#z]), 0.0);
        let sh = t.push(quote!(acc[#o]), 0.0);
        let mut terms = vec![(1.0, f, V::One), (-1.0, sh, V::One)];
        for o2 in 0..np {
            let z2 = s.outputs[o2];
            let mzz = read(&mut t, s.mass[z][z2], quote!(mass[#z2][#z]));
            terms.push((-1.0, mzz, zdd[o2]));
        }
        r1.push(t.sum(&terms));
    }
    let norms = t.push(quote!(fd_norms(g, mass, force, gamma)), 0.0);
    let tn = Tape::tok(norms);
    let [norm_g, norm_gt, norm_m, nf, ngam] =
        [0usize, 1, 2, 3, 4].map(|q| t.push(quote!(#tn[#q]), 0.0));
    let n1 = fast_max(&mut t, &r1, true);
    let n1 = fast_max(&mut t, &[nrm[0], n1], false);
    let nx = fast_max(&mut t, &zdd, true);
    let nx = fast_max(&mut t, &[nrm[1], nx], false);
    let nl = nrm[2];
    let [n1, nx, nl, norm_m, norm_g, norm_gt, nf, ngam] =
        [n1, nx, nl, norm_m, norm_g, norm_gt, nf, ngam].map(Tape::tok);
    t.flops.mul += 3;
    t.flops.add += 3;
    t.flops.div += 2;
    let e1 = t.push(
        quote!(if #n1 == 0.0 { 0.0 } else { #n1 / (#norm_m * #nx + #norm_gt * #nl + #nf) }),
        0.0,
    );
    let e2 = t.push(
        quote!(if residual == 0.0 { 0.0 } else { residual / (#norm_g * #nx + #ngam) }),
        0.0,
    );
    let (e1, e2) = (Tape::tok(e1), Tape::tok(e2));
    t.stmt(quote! {
        if f64::is_nan(#e1) || f64::is_nan(#e2) {
            f64::INFINITY
        } else {
            f64::max(#e1, #e2)
        }
    });
    let flops = t.flops;
    (t.into_tokens(), flops)
}

/// The item `fd_norms(g, mass, force, gamma) -> [‖G‖∞, ‖Gᵀ‖∞, ‖M‖∞, ‖force‖∞, ‖gamma‖∞]`
/// for the backward error (see `backward_error`), straight-line over the structural non-zeros
/// with constant indices, a function of its own: inside the solve's body its loads were
/// hoisted and spilled.
fn norms_item(s: &Structure<'_>) -> TokenStream {
    let (n, m, np) = (s.n, s.m, s.outputs.len());
    let mut t = Tape::default();
    // `‖G‖∞` and `‖Gᵀ‖∞` block by block (a block's rows are its columns' only non-zeros, and
    // the outputs' columns cross all blocks): few values live at a time, running maxima and
    // the outputs' column sums.
    let mut norm_g = V::Zero;
    let mut norm_gt = V::Zero;
    let mut out_cols = vec![V::Zero; np];
    for (rows, cols) in s.ik_blocks {
        let gb: Vec<Vec<V>> = rows
            .iter()
            .map(|&i| {
                let mut row: Vec<V> = cols
                    .iter()
                    .map(|&j| read(&mut t, s.g[i][j], quote!(g[#j][#i])))
                    .collect();
                row.extend(
                    s.outputs
                        .iter()
                        .map(|&z| read(&mut t, s.g[i][z], quote!(g[#z][#i]))),
                );
                row
            })
            .collect();
        let mut sums: Vec<V> = gb.iter().map(|row| t.sum_abs(row)).collect();
        sums.push(norm_g);
        norm_g = fast_max(&mut t, &sums, false);
        let mut sums: Vec<V> = (0..cols.len())
            .map(|c| {
                let col: Vec<V> = gb.iter().map(|row| row[c]).collect();
                t.sum_abs(&col)
            })
            .collect();
        sums.push(norm_gt);
        norm_gt = fast_max(&mut t, &sums, false);
        for o in 0..np {
            let col: Vec<V> = gb.iter().map(|row| row[cols.len() + o]).collect();
            let sh = t.sum_abs(&col);
            out_cols[o] = t.sum(&[(1.0, out_cols[o], V::One), (1.0, sh, V::One)]);
        }
    }
    out_cols.push(norm_gt);
    let norm_gt = fast_max(&mut t, &out_cols, false);
    // `‖M‖∞` row by row, `‖F‖∞`, `‖gamma‖∞`.
    let mut norm_m = V::Zero;
    for j in 0..n {
        let row: Vec<V> = (0..n)
            .map(|k| read(&mut t, s.mass[j][k], quote!(mass[#k][#j])))
            .collect();
        let r = t.sum_abs(&row);
        norm_m = fast_max(&mut t, &[norm_m, r], false);
    }
    let fv: Vec<V> = (0..n).map(|j| t.push(quote!(force[#j]), 0.0)).collect();
    let gam: Vec<V> = (0..m).map(|i| t.push(quote!(gamma[#i]), 0.0)).collect();
    let nf = fast_max(&mut t, &fv, true);
    let ngam = fast_max(&mut t, &gam, true);
    let out = [norm_g, norm_gt, norm_m, nf, ngam].map(Tape::tok);
    t.stmt(quote!([#(#out),*]));
    let body = t.into_tokens();
    quote! {
        /// Forward dynamics' backward error: `[‖G‖∞, ‖Gᵀ‖∞, ‖M‖∞, ‖force‖∞, ‖gamma‖∞]` over
        /// the structural non-zeros (see [`forward_dynamics_solve`]).
        #[inline(never)]
        fn fd_norms(
            g: &[[f64; M]; N],
            mass: &[[f64; N]; N],
            force: &[f64; N],
            gamma: &[f64; M],
        ) -> [f64; 5] {
            #body
        }
    }
}

/// `max_i a_i` (with `abs`, `max_i |a_i|`; 0 for none) by `fd_max`, for the backward error's
/// norms: one `maxsd` per pair where `f64::max`, which passes over a NaN, is seven
/// instructions. Its NaN handling is not needed there: the runtime accepts an answer only with
/// `Ẍ` and `lambda` finite, and a NaN or an infinity in the solve's inputs ends in them.
fn fast_max(t: &mut Tape, a: &[V], abs: bool) -> V {
    let live: Vec<V> = a.iter().copied().filter(|v| !v.is_zero()).collect();
    let tok = |v: V| {
        let tv = Tape::tok(v);
        if abs && v != V::One {
            quote!(f64::abs(#tv))
        } else {
            tv
        }
    };
    let Some((&first, rest)) = live.split_first() else {
        return V::Zero;
    };
    if rest.is_empty() && !abs {
        return first;
    }
    let mut e = tok(first);
    for &v in rest {
        let tv = tok(v);
        e = quote!(fd_max(#e, #tv));
    }
    let val = live.iter().map(|&v| t.val(v).abs()).fold(0.0, f64::max);
    t.push(e, val)
}

/// The item `fd_max` the backward error's norms call (see `fast_max`).
fn fd_max_item() -> TokenStream {
    quote! {
        /// The larger of `a` and `b` (`b` where either is NaN): one `maxsd`, for the norms of
        /// forward dynamics' backward error, whose operands are finite wherever the runtime
        /// uses them (see `forward_dynamics_solve`).
        #[inline(always)]
        fn fd_max(a: f64, b: f64) -> f64 {
            if a > b { a } else { b }
        }
    }
}

/// The reduced solve, straight-line (np small): `fd_reduced`.
fn reduced_solve(np: usize) -> Option<(TokenStream, Flops)> {
    let np_lit = Literal::usize_unsuffixed(np);
    let na_lit = Literal::usize_unsuffixed(np * (np + 1) / 2);
    let mut main = Tape::default();
    let av: Vec<Vec<V>> = (0..np)
        .map(|o1| {
            (0..np)
                .map(|o2| {
                    if o2 >= o1 {
                        let idx = upper(np, o1, o2);
                        main.push(quote!(a[#idx]), 0.0)
                    } else {
                        V::Zero
                    }
                })
                .collect()
        })
        .collect();
    let rv: Vec<V> = (0..np).map(|o| main.push(quote!(rhs[#o]), 0.0)).collect();
    let (zdd, ratio) = cholesky_solve(&mut main, &av, &rv)?;
    let zs: Vec<TokenStream> = zdd.iter().map(|&v| Tape::tok(v)).collect();
    let tr = Tape::tok(ratio);
    main.stmt(quote!(Some(([#(#zs),*], #tr))));
    let flops = main.flops;
    let chol = main.into_tokens();
    let item = quote! {
        /// Forward dynamics' reduced system `(Rᵀ M R) z̈ = rhs` (see [`forward_dynamics_solve`]),
        /// by Cholesky on the packed upper triangle `a`: `z̈` and the pivot ratio, or `None` for
        /// a pivot that is not positive.
        #[inline(never)]
        #[allow(clippy::neg_cmp_op_on_partial_ord, unused_variables)]
        fn fd_reduced(a: &[f64; #na_lit], rhs: &[f64; #np_lit]) -> Option<([f64; #np_lit], f64)> {
            #chol
        }
    };
    Some((item, flops))
}

/// `a + times b`: a block function's operations count once per call.
pub(super) fn add(a: Flops, b: Flops, times: usize) -> Flops {
    Flops {
        add: a.add + times * b.add,
        mul: a.mul + times * b.mul,
        div: a.div + times * b.div,
        func: a.func + times * b.func,
    }
}
