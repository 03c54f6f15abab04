//! Forward kinematics' linear solves, emitted: `J_p x_p = rhs - J_q x_q` (the passive columns of
//! `G` and the given actuated entries of `x`), by elimination onto the outputs with one
//! function per kind of inverse-kinematics block (as forward dynamics' `blocked`).
//!
//! Every robot registered has its actuated coordinates inside its blocks and none among its
//! outputs. A block's passive columns alone are not square: its square `K_b` is completed with
//! the actuated columns **at the home** (constants of the generated code, the same at every
//! call), the true actuated columns only entering the right-hand side with `x_q`. Any completion
//! that makes `K_b` invertible gives the same solution, so a Newton step of forward kinematics,
//! whose kernel (`constraints_jacobian_p`) writes only the passive columns, needs no other
//! kernel. Block `b` (rows `R_b`, columns `C_b`) gives `x[C_b] = s_b - T_b z` with
//! `s_b = K_b⁻¹ (rhs - J_q x_q)[R_b]`, `T_b = K_b⁻¹ G[R_b, outputs]` and `z` the outputs; the
//! entries of the completed (actuated) columns must vanish, which makes the reduced system
//! `A z = s_A` (`A = T_A`, one row per actuator, square when there are as many actuators as
//! outputs), solved by elimination in a pivot order chosen at the home (see `square`: it
//! declines where the threshold test refuses a pivot), with `A⁻¹` for the condition numbers.
//! Then every block's passive columns follow, and the residual of its rows.
//!
//! A Newton step can keep the elimination's factors (`forward_rates_keep`: every block's
//! factor and `T_b`, and `A⁻¹`, `FR_STORE <= N²` numbers) for the chord steps after it
//! (`forward_rates_chord`: `s_b = K_b⁻¹ rhs[R_b]`, `z = A⁻¹ s_A`, `x[C_b] = s_b - T_b z`, no
//! factorisation); `FR_CHORD` says whether the runtime takes them, from the operation counts of
//! a chord step (`constraints` and the apply) against a full one (`constraints_jacobian_p` and
//! the elimination).
//!
//! The condition number returned is, when the caller asks for it (`exact`: the rates and the
//! Newton step that can converge, whose reports give it), the exact `‖J_p‖₁ ‖J_p⁻¹‖₁`: `‖J_p‖₁`
//! from the column sums over the structural non-zeros, `‖J_p⁻¹‖₁` column by column through the
//! elimination (see `exact_cond`: with one actuator per block, every column's sum needs only
//! its own block's entries and one number per actuator). Otherwise it is the rigorous upper
//! bound
//!
//! ```text
//! cond₁(J_p) <= ‖J_p‖₁ · max_b ‖K_b⁻¹‖₁ (1 + (1 + ‖T‖₁) ‖A⁻¹‖₁)
//! ```
//!
//! (`T` all blocks' `T_b` stacked; `‖K_b⁻¹‖₁` exact for blocks up to order 3, beyond the
//! estimate of `block::factor_norms`, from the pivots or Hager/Higham's), free with the solve, that the runtime's own elimination
//! (`reduced::fk_factor`) certifies with: enough to decide `Singular` in the Newton steps before
//! the last. The solve declines (`None`) where a completed block's condition passes
//! `K_COND_MAX` (the elimination's rounding grows with it; far from the home the constant
//! completion may no longer fit), a pivot fails its threshold test or `A` is singular.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use super::block::Factor;
use super::block::{factor_norms, require, solve};
use super::blocked::{Class, add, classes};
use super::square::square_solve;
use super::tape::{Flops, Tape, V};
use super::{Emitted, Entry, Structure, read, read_gz, structured};

/// The largest condition number of a block `K_b` for which the elimination runs (the runtime's
/// `reduced::K_COND_MAX`).
const K_COND_MAX: f64 = 1e4;

/// `forward_rates_solve`'s items and body, or `None` when the robot does not have the structure
/// (actuators inside the blocks, as many as the outputs, none of them an output) or a block is
/// structurally singular.
pub fn forward_rates_solve(s: &Structure<'_>) -> Option<Emitted> {
    let np = s.outputs.len();
    let blocks = s.ik_blocks;
    if !structured(s)
        || s.actuated.len() != np
        || s.actuated.iter().any(|a| s.outputs.contains(a))
        || np > 16
    {
        return None;
    }
    let classes = classes(s, false);
    // The exact condition number: a single block, or blocks of one actuator each.
    let single = blocks.len() == 1;
    if !single
        && classes.iter().any(|(_, c)| {
            let cols = &blocks[c.blocks[0]].1;
            cols.iter().filter(|j| s.actuated.contains(j)).count() != 1
        })
    {
        return None;
    }
    let mut acc = Acc::new(s);
    for (ci, (_, class)) in classes.iter().enumerate() {
        class_functions(s, ci, class, single, &mut acc)?;
    }
    finish(s, single, acc)
}

/// What the classes of blocks add to the solve, in order.
struct Acc {
    items: TokenStream,
    flops: Flops,
    /// The statements before the reduced solve, and after it.
    pre: Vec<TokenStream>,
    post: Vec<TokenStream>,
    /// The exact condition number (see `exact_cond`): the calls of the blocks' shares, the
    /// column sums with several blocks, the functions and their operations.
    cond_calls: Vec<TokenStream>,
    col_sums: Vec<TokenStream>,
    cond_items: TokenStream,
    cond_mul: usize,
    cond_total: Flops,
    /// A's structural non-zeros and its values at the home, for the pivot order of the reduced
    /// elimination.
    a_nz: Vec<Vec<bool>>,
    a_home: Vec<Vec<f64>>,
    /// The chord steps (see `chord_block`): the factors kept in `store`, laid out class by
    /// class (`T_b` of every block, then their factors), `A⁻¹` last; the per-class statements
    /// of the keeping solve and of the chord step, and its operations.
    store_len: usize,
    keep: Vec<TokenStream>,
    chord: Vec<TokenStream>,
    chord_post: Vec<TokenStream>,
    chord_cost: Flops,
}

impl Acc {
    fn new(s: &Structure<'_>) -> Self {
        let np = s.outputs.len();
        let np_lit = Literal::usize_unsuffixed(np);
        let outs = s.outputs.iter().map(|&z| Literal::usize_unsuffixed(z));
        let pre = vec![quote! {
            const OUT: [usize; #np_lit] = [#(#outs),*];
            // A column-major (`a[o][q]`: output `o`, actuator `q`), its right-hand side, and the
            // column sums of |G[:, outputs]| and |T|.
            let mut a = [[0.0_f64; #np_lit]; #np_lit];
            let mut r = [0.0_f64; #np_lit];
            let mut zsum = [0.0_f64; #np_lit];
            let mut tsum = [0.0_f64; #np_lit];
            let (mut kinv, mut jcol, mut residual) = (0.0_f64, 0.0_f64, 0.0_f64);
        }];
        Acc {
            items: TokenStream::new(),
            flops: Flops::default(),
            pre,
            post: Vec::new(),
            cond_calls: Vec::new(),
            col_sums: Vec::new(),
            cond_items: TokenStream::new(),
            cond_mul: 0,
            cond_total: Flops::default(),
            a_nz: vec![vec![false; np]; np],
            a_home: vec![vec![0.0; np]; np],
            store_len: 0,
            keep: Vec::new(),
            chord: Vec::new(),
            chord_post: Vec::new(),
            chord_cost: Flops::default(),
        }
    }
}

/// The functions of one class of alike blocks (`ci`) and their calls.
fn class_functions(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    single: bool,
    acc: &mut Acc,
) -> Option<()> {
    let np = s.outputs.len();
    let np_lit = Literal::usize_unsuffixed(np);
    let blocks = s.ik_blocks;
    let k = class.k;
    let cols0 = &blocks[class.blocks[0]].1;
    let act_local: Vec<usize> = (0..k).filter(|&i| s.actuated.contains(&cols0[i])).collect();
    let na = act_local.len();
    let (k_lit, na_lit) = (Literal::usize_unsuffixed(k), Literal::usize_unsuffixed(na));
    let times = class.blocks.len();
    let b1 = block_first(s, ci, class, &act_local, &mut acc.a_nz, &mut acc.a_home)?;
    acc.flops = add(acc.flops, b1.flops, times);
    acc.items.extend(b1.item);
    let (item, flops) = block_finish(s, ci, class, &act_local, &b1.sb, &b1.tb);
    acc.flops = add(acc.flops, flops, times);
    acc.items.extend(item);
    let (item, flops) = block_x(s, ci, class, &act_local, &b1.sb, &b1.tb);
    acc.chord_cost = add(acc.chord_cost, flops, times);
    acc.items.extend(item);
    let First {
        f, fvals, tb, sb, ..
    } = b1;
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    let (first, second, fifth) = (
        format_ident!("fr_block{}", ci),
        format_ident!("fr_block{}_finish", ci),
        format_ident!("fr_block{}_x", ci),
    );

    // The third function: the exact condition number's share of this block (see
    // `exact_cond`).
    let third = format_ident!("fr_block{}_cond", ci);
    let (cond_item, cond_flops) = exact_cond(
        &third,
        &f,
        &fvals,
        &tb,
        &act_local,
        np,
        single,
        &class_acts(s, class),
    );
    acc.cond_items.extend(cond_item);
    acc.cond_mul += cond_flops.mul * class.blocks.len();
    let fourth = format_ident!("fr_block{}_chord", ci);
    let (chord_item, chord_flops) = chord_block(&fourth, &f, &fvals, &sb, &act_local);
    acc.items.extend(chord_item);
    acc.chord_cost = add(acc.chord_cost, chord_flops, class.blocks.len());
    acc.cond_total = add(acc.cond_total, cond_flops, class.blocks.len());

    let usizes = |v: &[usize]| {
        let l = v.iter().map(|&x| Literal::usize_unsuffixed(x));
        quote!([#(#l),*])
    };
    let nb_lit = Literal::usize_unsuffixed(class.blocks.len());
    let rows_t: Vec<TokenStream> = class.blocks.iter().map(|&b| usizes(&blocks[b].0)).collect();
    let cols_t: Vec<TokenStream> = class.blocks.iter().map(|&b| usizes(&blocks[b].1)).collect();
    let acts_t: Vec<TokenStream> = class
        .blocks
        .iter()
        .map(|&b| {
            let cols = &blocks[b].1;
            let q: Vec<usize> = act_local
                .iter()
                .map(|&i| s.actuated.iter().position(|&a| a == cols[i]).unwrap_or(0))
                .collect();
            usizes(&q)
        })
        .collect();
    // The completion: each block's actuated columns at the home, `home_cols[q][j]`.
    let kc_t = class.blocks.iter().map(|&b| {
        let (rows, cols) = &blocks[b];
        let cs = act_local.iter().map(|&i| {
            let v = rows.iter().map(|&r| {
                let x = match s.g[r][cols[i]] {
                    Entry::Zero => 0.0,
                    Entry::Number(x) | Entry::Var(x) => x,
                };
                Literal::f64_suffixed(x)
            });
            quote!([#(#v),*])
        });
        quote!([#(#cs),*])
    });
    let (rows_c, cols_c, acts_c, kc_c) = (
        format_ident!("ROWS{}", ci),
        format_ident!("COLS{}", ci),
        format_ident!("ACTS{}", ci),
        format_ident!("KC{}", ci),
    );
    let (t_v, s_v, fac_v, sb_v, out_v) = (
        format_ident!("t{}", ci),
        format_ident!("s{}", ci),
        format_ident!("fac{}", ci),
        format_ident!("sb{}", ci),
        format_ident!("out{}", ci),
    );
    acc.pre.push(quote! {
        const #rows_c: [[usize; #k_lit]; #nb_lit] = [#(#rows_t),*];
        const #cols_c: [[usize; #k_lit]; #nb_lit] = [#(#cols_t),*];
        const #acts_c: [[usize; #na_lit]; #nb_lit] = [#(#acts_t),*];
        const #kc_c: [[[f64; #k_lit]; #na_lit]; #nb_lit] = [#(#kc_t),*];
        let mut #t_v = [[[0.0_f64; #np_lit]; #k_lit]; #nb_lit];
        let mut #s_v = [[0.0_f64; #k_lit]; #nb_lit];
        let mut #fac_v = [[0.0_f64; #nf_lit]; #nb_lit];
        for b in 0..#nb_lit {
            let [ki, jc] = #first(
                g, rhs, x, actuated, &#rows_c[b], &#cols_c[b], &#acts_c[b], &#kc_c[b],
                &mut a, &mut r, &mut zsum, &mut tsum, &mut #t_v[b], &mut #s_v[b],
                &mut #fac_v[b],
            )?;
            kinv = kinv.max(ki);
            jcol = jcol.max(jc);
        }
    });
    if single {
        acc.cond_calls.push(quote! {
            let inv_norm = #third(&inv, &#t_v[0], &#fac_v[0]);
        });
    } else {
        acc.cond_calls.push(quote! {
            let mut #sb_v = [0.0_f64; #nb_lit];
            let mut #out_v = [[[0.0_f64; 2]; #k_lit]; #nb_lit];
            for b in 0..#nb_lit {
                #sb_v[b] = #third(
                    &inv, &#t_v[b], &#fac_v[b], &#acts_c[b], &mut other_sums, &mut #out_v[b],
                );
            }
        });
        acc.col_sums.push(quote! {
            for b in 0..#nb_lit {
                let own = other_sums[#acts_c[b][0]] - #sb_v[b];
                for [w, local] in #out_v[b] {
                    inv_norm = inv_norm.max(w * own + local);
                }
            }
        });
    }
    acc.post.push(quote! {
        for b in 0..#nb_lit {
            let res = #second(
                g, rhs, actuated, &#rows_c[b], &#cols_c[b], &#t_v[b], &#s_v[b], &z, x,
            );
            residual = residual.max(res);
        }
    });
    let (t_len, f_len) = (
        class.blocks.len() * k * np,
        class.blocks.len() * fvals.len().max(1),
    );
    let (t_off, t_end) = (acc.store_len, acc.store_len + t_len);
    let (f_off, f_end) = (t_end, t_end + f_len);
    acc.store_len = f_end;
    acc.keep.push(quote! {
        st[#t_off..#t_end].copy_from_slice(#t_v.as_flattened().as_flattened());
        st[#f_off..#f_end].copy_from_slice(#fac_v.as_flattened());
    });
    acc.chord.push(quote! {
        const #rows_c: [[usize; #k_lit]; #nb_lit] = [#(#rows_t),*];
        const #cols_c: [[usize; #k_lit]; #nb_lit] = [#(#cols_t),*];
        const #acts_c: [[usize; #na_lit]; #nb_lit] = [#(#acts_t),*];
        let mut #t_v = [[[0.0_f64; #np_lit]; #k_lit]; #nb_lit];
        #t_v.as_flattened_mut().as_flattened_mut().copy_from_slice(&store[#t_off..#t_end]);
        let mut #fac_v = [[0.0_f64; #nf_lit]; #nb_lit];
        #fac_v.as_flattened_mut().copy_from_slice(&store[#f_off..#f_end]);
        let mut #s_v = [[0.0_f64; #k_lit]; #nb_lit];
        for b in 0..#nb_lit {
            #fourth(rhs, &#rows_c[b], &#acts_c[b], &#fac_v[b], &mut #s_v[b], &mut r);
        }
    });
    acc.chord_post.push(quote! {
        for b in 0..#nb_lit {
            #fifth(&#cols_c[b], &#t_v[b], &#s_v[b], &z, x);
        }
    });
    Some(())
}

/// A class's first function and what the others read of it.
struct First {
    item: TokenStream,
    flops: Flops,
    f: Factor,
    /// The factor's values, kept in `factors`.
    fvals: Vec<V>,
    /// `T = K⁻¹ G[rows, outputs]` and `s = K⁻¹ rhs[rows]`.
    tb: Vec<Vec<V>>,
    sb: Vec<V>,
}

/// The first function of class `ci`: factor, s, T, the block's rows of A and r, the norms;
/// records A's structure and its values at the home.
fn block_first(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    act_local: &[usize],
    a_nz: &mut [Vec<bool>],
    a_home: &mut [Vec<f64>],
) -> Option<First> {
    let np = s.outputs.len();
    let blocks = s.ik_blocks;
    let k = class.k;
    let (rows0, cols0) = &blocks[class.blocks[0]];
    let (k_lit, na_lit) = (
        Literal::usize_unsuffixed(k),
        Literal::usize_unsuffixed(act_local.len()),
    );
    let np_lit = Literal::usize_unsuffixed(np);
    let mut t = Tape::default();
    let kk = completed(&mut t, s, rows0, cols0, act_local);
    let (f, norm_k, norm_inv) = factor_norms(&mut t, &kk, 0)?;
    let cond = t.mul(norm_k, norm_inv);
    let tc = Tape::tok(cond);
    require(&mut t, quote!(#tc <= #K_COND_MAX));
    let gz = read_gz(&mut t, s, rows0);
    let rb = right_side(&mut t, s, rows0, cols0, act_local);
    let sb = solve(&mut t, &f, &rb);
    let mut tb = vec![vec![V::Zero; np]; k];
    for o in 0..np {
        let col: Vec<V> = (0..k).map(|j| gz[j][o]).collect();
        for (i, v) in solve(&mut t, &f, &col).into_iter().enumerate() {
            tb[i][o] = v;
        }
        let zs = t.sum_abs(&col);
        let ts = t.sum_abs(&(0..k).map(|i| tb[i][o]).collect::<Vec<_>>());
        let (tz, tt) = (Tape::tok(zs), Tape::tok(ts));
        t.stmt(quote!(zsum[#o] += #tz; tsum[#o] += #tt;));
    }
    // A's structural non-zeros and its values at the home, for the pivot order of the
    // reduced elimination.
    for &b in &class.blocks {
        let (rows, cols) = &blocks[b];
        let home = block_rows_of_a(s, rows, cols, act_local)?;
        for (q, &i) in act_local.iter().enumerate() {
            let slot = s.actuated.iter().position(|&a| a == cols[i])?;
            for o in 0..np {
                a_nz[o][slot] = !tb[i][o].is_zero();
                a_home[o][slot] = home[q][o];
            }
        }
    }
    for (q, &i) in act_local.iter().enumerate() {
        for o in 0..np {
            let v = Tape::tok(tb[i][o]);
            t.stmt(quote!(a[#o][acts[#q]] = #v;));
        }
        let si = Tape::tok(sb[i]);
        t.stmt(quote!(r[acts[#q]] = #si;));
    }
    // The largest column sum of |J_p| over the block's passive columns.
    let sums: Vec<V> = (0..k)
        .filter(|i| !act_local.contains(i))
        .map(|i| t.sum_abs(&(0..k).map(|j| kk[j][i]).collect::<Vec<_>>()))
        .collect();
    let colmax = t.max(&sums);
    for (i, row) in tb.iter().enumerate() {
        for (o, &v) in row.iter().enumerate() {
            if matches!(v, V::T(_)) {
                let tv = Tape::tok(v);
                t.stmt(quote!(tm[#i][#o] = #tv;));
            }
        }
    }
    for (i, &v) in sb.iter().enumerate() {
        if matches!(v, V::T(_)) {
            let tv = Tape::tok(v);
            t.stmt(quote!(sv[#i] = #tv;));
        }
    }
    // The factor, for the exact condition number.
    let fvals = f.values();
    for (q, &v) in fvals.iter().enumerate() {
        let tv = Tape::tok(v);
        t.stmt(quote!(factors[#q] = #tv;));
    }
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    let (tn, tcol) = (Tape::tok(norm_inv), Tape::tok(colmax));
    t.stmt(quote!(Some([#tn, #tcol])));
    let flops = t.flops;
    let name = format_ident!("fr_block{}", ci);
    let body = t.into_tokens();
    let item = quote! {
        /// Forward kinematics' elimination, one inverse-kinematics block of this kind (see
        /// [`forward_rates_solve`]): `s = K⁻¹ rhs[rows]`, `T = K⁻¹ G[rows, outputs]`, the
        /// block's rows of `A` and its right-hand side; returns `[‖K⁻¹‖₁, the largest
        /// column sum of |K| over the passive columns]`.
        #[inline(never)]
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            clippy::neg_cmp_op_on_partial_ord,
            unused_variables
        )]
        fn #name(
            g: &[[f64; M]; N],
            rhs: &[f64; M],
            x: &[f64; N],
            actuated: bool,
            rows: &[usize; #k_lit],
            cols: &[usize; #k_lit],
            acts: &[usize; #na_lit],
            home_cols: &[[f64; #k_lit]; #na_lit],
            a: &mut [[f64; #np_lit]; #np_lit],
            r: &mut [f64; #np_lit],
            zsum: &mut [f64; #np_lit],
            tsum: &mut [f64; #np_lit],
            tm: &mut [[f64; #np_lit]; #k_lit],
            sv: &mut [f64; #k_lit],
            factors: &mut [f64; #nf_lit],
        ) -> Option<[f64; 2]> {
            #body
        }
    };
    Some(First {
        item,
        flops,
        f,
        fvals,
        tb,
        sb,
    })
}

/// The second function of class `ci`: the block's passive columns and the residual of its
/// rows.
fn block_finish(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    act_local: &[usize],
    sb: &[V],
    tb: &[Vec<V>],
) -> (TokenStream, Flops) {
    let np = s.outputs.len();
    let k = class.k;
    let (rows0, cols0) = &s.ik_blocks[class.blocks[0]];
    let (k_lit, np_lit) = (Literal::usize_unsuffixed(k), Literal::usize_unsuffixed(np));
    let mut t = Tape::default();
    let gz = read_gz(&mut t, s, rows0);
    let z: Vec<V> = (0..np).map(|o| t.push(quote!(z[#o]), 0.0)).collect();
    let xb = passive_x(&mut t, sb, tb, &z, act_local);
    // The residual of the block's rows: J_p x_p - (rhs - J_q x_q) there.
    let rb = right_side(&mut t, s, rows0, cols0, act_local);
    let res: Vec<V> = (0..k)
        .map(|j| {
            let mut terms = vec![(-1.0, rb[j], V::One)];
            for i in (0..k).filter(|i| !act_local.contains(i)) {
                let gji = read(
                    &mut t,
                    s.g[rows0[j]][cols0[i]],
                    quote!(g[cols[#i]][rows[#j]]),
                );
                terms.push((1.0, gji, xb[i]));
            }
            terms.extend((0..np).map(|o| (1.0, gz[j][o], z[o])));
            t.sum(&terms)
        })
        .collect();
    let res = t.max_abs(&res);
    for (i, &v) in xb.iter().enumerate() {
        if !act_local.contains(&i) {
            let tv = Tape::tok(v);
            t.stmt(quote!(x[cols[#i]] = #tv;));
        }
    }
    let tr = Tape::tok(res);
    t.stmt(quote!(#tr));
    let flops = t.flops;
    let name = format_ident!("fr_block{}_finish", ci);
    let body = t.into_tokens();
    let item = quote! {
        /// Forward kinematics' elimination, one inverse-kinematics block of this kind, after
        /// the reduced solve: `x[cols] = s - T z` on its passive columns; returns the
        /// residual of its rows.
        #[inline(never)]
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            clippy::let_and_return,
            unused_variables
        )]
        fn #name(
            g: &[[f64; M]; N],
            rhs: &[f64; M],
            actuated: bool,
            rows: &[usize; #k_lit],
            cols: &[usize; #k_lit],
            tm: &[[f64; #np_lit]; #k_lit],
            sv: &[f64; #k_lit],
            z: &[f64; #np_lit],
            x: &mut [f64; N],
        ) -> f64 {
            #body
        }
    };
    (item, flops)
}

/// The chord step's function of class `ci`: the passive columns alone (its certificate is
/// Newton's next `f`).
fn block_x(
    s: &Structure<'_>,
    ci: usize,
    class: &Class,
    act_local: &[usize],
    sb: &[V],
    tb: &[Vec<V>],
) -> (TokenStream, Flops) {
    let np = s.outputs.len();
    let (k_lit, np_lit) = (
        Literal::usize_unsuffixed(class.k),
        Literal::usize_unsuffixed(np),
    );
    let mut t = Tape::default();
    let z: Vec<V> = (0..np).map(|o| t.push(quote!(z[#o]), 0.0)).collect();
    let xb = passive_x(&mut t, sb, tb, &z, act_local);
    for (i, &v) in xb.iter().enumerate() {
        if !act_local.contains(&i) {
            let tv = Tape::tok(v);
            t.stmt(quote!(x[cols[#i]] = #tv;));
        }
    }
    let flops = t.flops;
    let name = format_ident!("fr_block{}_x", ci);
    let body = t.into_tokens();
    let item = quote! {
        /// Forward kinematics' chord step, one inverse-kinematics block of this kind, after
        /// the reduced solve: `x[cols] = s - T z` on its passive columns.
        #[inline(never)]
        #[allow(clippy::neg_multiply, unused_variables)]
        fn #name(
            cols: &[usize; #k_lit],
            tm: &[[f64; #np_lit]; #k_lit],
            sv: &[f64; #k_lit],
            z: &[f64; #np_lit],
            x: &mut [f64; N],
        ) {
            #body
        }
    };
    (item, flops)
}

/// The solve's tail once every class is emitted: the reduced elimination, the condition number
/// (exact or the bound), the chord step and whether to take it, the body.
fn finish(s: &Structure<'_>, single: bool, acc: Acc) -> Option<Emitted> {
    let Acc {
        mut items,
        mut flops,
        pre,
        post,
        cond_calls,
        col_sums,
        cond_items,
        cond_mul,
        cond_total,
        a_nz,
        a_home,
        store_len,
        keep,
        chord,
        chord_post,
        chord_cost,
    } = acc;
    let np = s.outputs.len();
    let np_lit = Literal::usize_unsuffixed(np);
    // The exact condition number where it costs less than the dense inverse of `J_p` the
    // runtime's general path forms (about M³ multiplications): a single block of a serial arm
    // (the UR5's 6 × 6) is cheaper inverted densely, and the request then declines at once.
    let exact_here = !single || cond_mul < s.m.pow(3);
    let exact_norm = if single {
        quote!(#(#cond_calls)*)
    } else {
        quote! {
            let mut inv_norm = 0.0_f64;
            let mut other_sums = [0.0_f64; #np_lit];
            #(#cond_calls)*
            for (q, sq) in other_sums.iter_mut().enumerate() {
                *sq += inv[q].iter().map(|v| v.abs()).sum::<f64>();
            }
            #(#col_sums)*
        }
    };
    // The blocks' and their finishing functions' operations: a full step's, with the reduced
    // solve below.
    let solve_flops = flops;
    let decline = if exact_here {
        items.extend(cond_items);
        flops = add(flops, cond_total, 1);
        quote!()
    } else {
        quote! {
            // The exact condition number is not emitted for this robot (see the generator).
            if exact {
                return None;
            }
        }
    };
    let bound = quote! {
        let tnorm = tsum.iter().fold(0.0_f64, |m, &v| m.max(v));
        Some([jnorm * kinv * (1.0 + (1.0 + tnorm) * ainv), residual])
    };
    let tail = if exact_here {
        quote! {
            if !exact {
                #bound
            } else {
                // ‖J_p⁻¹‖₁, column by column (see `exact_cond`): the blocks' shares, then, with
                // several blocks, the other blocks' and the outputs' shares through
                // `other_sums`.
                #exact_norm
                Some([jnorm * inv_norm, residual])
            }
        }
    } else {
        bound
    };
    let (reduced_item, reduced_flops) =
        square_solve(&format_ident!("fr_reduced"), &a_nz, &a_home, true)?;
    items.extend(reduced_item);
    flops = add(flops, reduced_flops, 1);
    let (inv_off, inv_end) = (store_len, store_len + np * np);
    // Chord steps where one costs at most half a full step: they converge linearly, so they
    // take one to three steps more than Newton from a warm start. A full step evaluates
    // `constraints_jacobian_p` and factors, a chord step evaluates `constraints` and applies
    // the kept factors (`A⁻¹ r`: `np²` multiply-adds); both pay Newton's own iteration. The
    // weights are instructions as callgrind counts them (`bench/instructions.sh`): a kernel's
    // operation about 1, a `sincos` of the kernels' libm about 70, an emitted solve's
    // operation about 3 (its loads and stores), Newton's iteration about 500 (the planar
    // 3-RRR, 2026-11-26). By these, the 6-UPS's chord step costs 0.39 of a full one; the delta's
    // 0.59 and the planar 3-RRR's 0.68 (whose Jacobian comes almost free with `f`) do not take
    // chord steps.
    let full_cost = add(solve_flops, reduced_flops, 1);
    let chord_cost = add(
        chord_cost,
        Flops {
            mul: np * np,
            add: np * np,
            ..Flops::default()
        },
        1,
    );
    let weight = |o: Flops| (o.mul + o.add + 4 * o.div + 70 * o.func) as f64;
    let chord_pays = s.fk_evals.is_some_and(|(c, cjp)| {
        let chord_step = weight(c) + 3.0 * weight(chord_cost) + 500.0;
        let full_step = weight(cjp) + 3.0 * weight(full_cost) + 500.0;
        chord_step <= 0.5 * full_step
    });
    flops = add(flops, chord_cost, 1);
    let outs_chord = s.outputs.iter().map(|&z| Literal::usize_unsuffixed(z));
    let body = quote! {
        #decline
        #(#pre)*
        // z = A⁻¹ r, the inverse (column-major) and ‖A⁻¹‖₁.
        let mut inv = [[0.0_f64; #np_lit]; #np_lit];
        let mut z = [0.0_f64; #np_lit];
        let ainv = fr_reduced(&a, &r, &mut z, &mut inv)?;
        for o in 0..#np_lit {
            x[OUT[o]] = z[o];
        }
        #(#post)*
        // The factors of this step, for the chord steps after it (`forward_rates_chord`).
        if let Some(st) = store.filter(|st| st.len() >= FR_STORE) {
            #(#keep)*
            st[#inv_off..#inv_end].copy_from_slice(inv.as_flattened());
        }
        let jnorm = zsum.iter().fold(jcol, |m, &v| m.max(v));
        #tail
    };
    items.extend(quote! {
        /// The length of the factors `forward_rates_keep` keeps for `forward_rates_chord`: every
        /// block's `T_b` and factor, and `A⁻¹`.
        pub const FR_STORE: usize = #inv_end;

        /// Whether forward kinematics takes chord steps here: one costs at most half a full
        /// Newton step (the generator's estimate from the operation counts).
        pub const FR_CHORD: bool = #chord_pays;

        /// A chord step of forward kinematics: `J_p x_p = rhs` (`x_q = 0`) by the factors that
        /// `forward_rates_keep` kept in `store` for the `J_p` of its step: the
        /// blocks' `s_b = K_b⁻¹ rhs[rows]`, `z = A⁻¹ s_A`, then the blocks' passive columns as
        /// in the keeping solve. Writes the passive entries of `x` (the caller checks them:
        /// Newton's next evaluation of `f` is the step's certificate). `None` where `store` is
        /// too short or the outputs' entries are not finite.
        #[allow(clippy::needless_range_loop, unused_variables)]
        fn forward_rates_chord(
            store: &[f64],
            rhs: &[f64; M],
            x: &mut [f64; N],
        ) -> Option<()> {
            if store.len() < FR_STORE {
                return None;
            }
            const OUT: [usize; #np_lit] = [#(#outs_chord),*];
            let mut r = [0.0_f64; #np_lit];
            #(#chord)*
            let mut inv = [[0.0_f64; #np_lit]; #np_lit];
            inv.as_flattened_mut().copy_from_slice(&store[#inv_off..#inv_end]);
            // z = A⁻¹ r (`inv` column-major: inv[q][o] = (A⁻¹)_{oq}).
            let mut z = [0.0_f64; #np_lit];
            for (o, zo) in z.iter_mut().enumerate() {
                *zo = inv.iter().zip(&r).map(|(col, &rq)| col[o] * rq).sum::<f64>();
            }
            for o in 0..#np_lit {
                x[OUT[o]] = z[o];
            }
            #(#chord_post)*
            z.iter().all(|v| v.is_finite()).then_some(())
        }
    });
    Some(Emitted { items, body, flops })
}

/// The factor `f` read back from the function's argument `factors` (its values `fvals`, in
/// order, as the full step stored them).
fn stored_factor(t: &mut Tape, f: &super::block::Factor, fvals: &[V]) -> super::block::Factor {
    let loaded: Vec<V> = (0..fvals.len())
        .map(|q| t.push(quote!(factors[#q]), 0.0))
        .collect();
    f.map(&|v: V| match fvals.iter().position(|&u| u == v) {
        Some(q) => loaded[q],
        None => v,
    })
}

/// `x_b = s_b - T_b z` on a block's passive columns (local `i` not in `act`), reading `sv[i]`
/// and `tm[i][o]` where the full step's `sb` and `tb` are temporaries.
fn passive_x(t: &mut Tape, sb: &[V], tb: &[Vec<V>], z: &[V], act: &[usize]) -> Vec<V> {
    (0..sb.len())
        .map(|i| {
            if act.contains(&i) {
                return V::Zero;
            }
            let base = match sb[i] {
                V::T(_) => t.push(quote!(sv[#i]), 0.0),
                other => other,
            };
            let mut terms = vec![(1.0, base, V::One)];
            for (o, &zo) in z.iter().enumerate() {
                let tio = match tb[i][o] {
                    V::T(_) => t.push(quote!(tm[#i][#o]), 0.0),
                    other => other,
                };
                terms.push((-1.0, tio, zo));
            }
            t.sum(&terms)
        })
        .collect()
}

/// The function `name(rhs, rows, acts, factors, sv, r)` of a chord step, one block of a kind:
/// `s = K⁻¹ rhs[rows]` by the factor kept from the last full step (`factors`, the values
/// `fvals` of `f` in order), written to `sv`, and its actuated entries to the reduced system's
/// right-hand side `r[acts]`.
fn chord_block(
    name: &proc_macro2::Ident,
    f: &super::block::Factor,
    fvals: &[V],
    sb0: &[V],
    act: &[usize],
) -> (TokenStream, Flops) {
    let k = sb0.len();
    let mut t = Tape::default();
    let f2 = stored_factor(&mut t, f, fvals);
    let rb: Vec<V> = (0..k).map(|j| t.push(quote!(rhs[rows[#j]]), 0.0)).collect();
    let sb = solve(&mut t, &f2, &rb);
    for (i, &v) in sb.iter().enumerate() {
        // The finishing function reads `sv[i]` where the full step's `s_b` was a temporary.
        if matches!(sb0[i], V::T(_)) {
            let tv = Tape::tok(v);
            t.stmt(quote!(sv[#i] = #tv;));
        }
    }
    for (q, &i) in act.iter().enumerate() {
        let tv = Tape::tok(sb[i]);
        t.stmt(quote!(r[acts[#q]] = #tv;));
    }
    let flops = t.flops;
    let body = t.into_tokens();
    let (k_lit, na_lit) = (
        Literal::usize_unsuffixed(k),
        Literal::usize_unsuffixed(act.len()),
    );
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    let item = quote! {
        /// Forward kinematics' chord step, one inverse-kinematics block of this kind (see
        /// [`forward_rates_chord`]): `s = K⁻¹ rhs[rows]` by the kept factor, and the block's
        /// entries of the reduced right-hand side.
        #[inline(never)]
        #[allow(clippy::neg_multiply, unused_variables)]
        fn #name(
            rhs: &[f64; M],
            rows: &[usize; #k_lit],
            acts: &[usize; #na_lit],
            factors: &[f64; #nf_lit],
            sv: &mut [f64; #k_lit],
            r: &mut [f64],
        ) {
            #body
        }
    };
    (item, flops)
}

/// The rows of `A` of one block (`rows`, `cols`) at the home, `[q][o]` for its local actuated
/// columns `act` (`q`) and the outputs (`o`): `(K_b⁻¹ G[rows, outputs])[act]`, on a tape of
/// its own whose reference values are the block's.
fn block_rows_of_a(
    s: &Structure<'_>,
    rows: &[usize],
    cols: &[usize],
    act: &[usize],
) -> Option<Vec<Vec<f64>>> {
    let mut t = Tape::default();
    let kk = completed(&mut t, s, rows, cols, act);
    let (f, _, _) = factor_norms(&mut t, &kk, 0)?;
    let gz = read_gz(&mut t, s, rows);
    let np = s.outputs.len();
    let mut out = vec![vec![0.0; np]; act.len()];
    for o in 0..np {
        let col: Vec<V> = (0..rows.len()).map(|j| gz[j][o]).collect();
        let x = solve(&mut t, &f, &col);
        for (q, &i) in act.iter().enumerate() {
            out[q][o] = t.val(x[i]);
        }
    }
    Some(out)
}

/// The block `K[j][i]` completed: its passive columns read from `g`, its actuated ones (local
/// `act`) from the function's table `home_cols` of their values at the home (structural zeros
/// and numbers stay what they are).
fn completed(
    t: &mut Tape,
    s: &Structure<'_>,
    rows0: &[usize],
    cols0: &[usize],
    act: &[usize],
) -> Vec<Vec<V>> {
    (0..rows0.len())
        .map(|j| {
            (0..cols0.len())
                .map(|i| {
                    let e = s.g[rows0[j]][cols0[i]];
                    match (act.iter().position(|&a| a == i), e) {
                        (Some(q), Entry::Var(v)) => t.push(quote!(home_cols[#q][#j]), v),
                        _ => read(t, e, quote!(g[cols[#i]][rows[#j]])),
                    }
                })
                .collect()
        })
        .collect()
}

/// `(rhs - J_q x_q)[rows]`, the actuated columns' term only if `actuated` (a Newton step has
/// `x_q = 0`, and `constraints_jacobian_p` does not write those columns).
fn right_side(
    t: &mut Tape,
    s: &Structure<'_>,
    rows0: &[usize],
    cols0: &[usize],
    act: &[usize],
) -> Vec<V> {
    (0..rows0.len())
        .map(|j| {
            let base = t.push(quote!(rhs[rows[#j]]), 0.0);
            let terms: Vec<(f64, V, V)> = act
                .iter()
                .map(|&i| {
                    let gji = read(t, s.g[rows0[j]][cols0[i]], quote!(g[cols[#i]][rows[#j]]));
                    let xi = t.push(quote!(x[cols[#i]]), 0.0);
                    (1.0, gji, xi)
                })
                .collect();
            match t.sum(&terms) {
                V::Zero => base,
                qx => {
                    let (tb, tq) = (Tape::tok(base), Tape::tok(qx));
                    t.push(quote!(if actuated { #tb - #tq } else { #tb }), 0.0)
                }
            }
        })
        .collect()
}

/// The actuator slots (indices into `Structure::actuated`) of a kind of block's actuated
/// columns, read off its first block: constants when the robot has that one block.
fn class_acts(s: &Structure<'_>, class: &super::blocked::Class) -> Vec<usize> {
    let cols = &s.ik_blocks[class.blocks[0]].1;
    cols.iter()
        .filter_map(|c| s.actuated.iter().position(|a| a == c))
        .collect()
}

/// The function `name` giving one kind of block's share of the exact `‖J_p⁻¹‖₁`.
///
/// Column `r` of `J_p⁻¹` (row `j` of block `b`) is, with `u = K_b⁻¹ e_j` (the completed block)
/// and `w = u_A` its actuated entries: `A⁻¹ w` on the outputs, `-V_b' w` on every other block's
/// passive coordinates and `u_P - V_b w` on block `b`'s own, `V = T A⁻¹`. With a single block
/// the function returns `‖J_p⁻¹‖₁` itself. With several blocks of one actuator each (slot
/// `c_b`, `w` a number) it adds `Σ_p |V_b[p][q]|` to `other_sums[q]` for every slot `q`, writes
/// `out[j] = [|w|, Σ_p |u_p - V_b[p][c_b] w|]` and returns `Σ_p |V_b[p][c_b]|`: once every block
/// has added its share and `other_sums[q]` has `‖A⁻¹ e_q‖₁` too, column `r`'s sum is
/// `|w| (other_sums[c_b] - that) + out[j][1]`.
#[allow(clippy::too_many_arguments)]
fn exact_cond(
    name: &proc_macro2::Ident,
    f: &super::block::Factor,
    fvals: &[V],
    tb: &[Vec<V>],
    act: &[usize],
    np: usize,
    single: bool,
    slots: &[usize],
) -> (TokenStream, Flops) {
    let k = tb.len();
    let mut t = Tape::default();
    let f2 = stored_factor(&mut t, f, fvals);
    let pass: Vec<usize> = (0..k).filter(|i| !act.contains(i)).collect();
    let tm: Vec<Vec<V>> = (0..k)
        .map(|i| {
            (0..np)
                .map(|o| match tb[i][o] {
                    V::T(_) if pass.contains(&i) => t.push(quote!(tm[#i][#o]), 0.0),
                    V::T(_) => V::Zero,
                    other => other,
                })
                .collect()
        })
        .collect();
    let inv: Vec<Vec<V>> = (0..np)
        .map(|q| (0..np).map(|o| t.push(quote!(inv[#q][#o]), 0.0)).collect())
        .collect();
    let column = |t: &mut Tape, j: usize| -> Vec<V> {
        let e: Vec<V> = (0..k)
            .map(|i| if i == j { V::One } else { V::Zero })
            .collect();
        solve(t, &f2, &e)
    };
    let (k_lit, np_lit) = (Literal::usize_unsuffixed(k), Literal::usize_unsuffixed(np));
    let allow = quote! {
        #[inline(never)]
        #[allow(
            clippy::neg_multiply,
            clippy::let_and_return,
            clippy::too_many_arguments,
            unused_variables
        )]
    };
    let nf_lit = Literal::usize_unsuffixed(fvals.len().max(1));
    if single {
        let mut sums = Vec::with_capacity(k);
        for j in 0..k {
            let u = column(&mut t, j);
            let z: Vec<V> = (0..np)
                .map(|o| {
                    let terms: Vec<(f64, V, V)> = act
                        .iter()
                        .zip(slots)
                        .map(|(&i, &q)| (1.0, inv[q][o], u[i]))
                        .collect();
                    t.sum(&terms)
                })
                .collect();
            let zs = t.sum_abs(&z);
            let own: Vec<V> = pass
                .iter()
                .map(|&p| {
                    let mut terms = vec![(1.0, u[p], V::One)];
                    terms.extend((0..np).map(|o| (-1.0, tm[p][o], z[o])));
                    t.sum(&terms)
                })
                .collect();
            let os = t.sum_abs(&own);
            sums.push(t.sum(&[(1.0, zs, V::One), (1.0, os, V::One)]));
        }
        let m = t.max(&sums);
        let tm_ = Tape::tok(m);
        t.stmt(quote!(#tm_));
        let flops = t.flops;
        let body = t.into_tokens();
        let item = quote! {
            /// Forward kinematics' exact condition number, this (single) block: `‖J_p⁻¹‖₁`,
            /// column by column through the factors of the elimination (see
            /// [`forward_rates_solve`]).
            #allow
            fn #name(
                inv: &[[f64; #np_lit]; #np_lit],
                tm: &[[f64; #np_lit]; #k_lit],
                factors: &[f64; #nf_lit],
            ) -> f64 {
                #body
            }
        };
        return (item, flops);
    }
    let a = act[0];
    // V_b = T_b A⁻¹ on the passive rows: V[p][q] = Σ_o T[p][o] (A⁻¹)[o][q], (A⁻¹)[o][q] =
    // inv[q][o].
    let v: Vec<Vec<V>> = pass
        .iter()
        .map(|&p| {
            (0..np)
                .map(|q| {
                    let terms: Vec<(f64, V, V)> =
                        (0..np).map(|o| (1.0, tm[p][o], inv[q][o])).collect();
                    t.sum(&terms)
                })
                .collect()
        })
        .collect();
    for q in 0..np {
        let col: Vec<V> = v.iter().map(|row| row[q]).collect();
        let sq = Tape::tok(t.sum_abs(&col));
        t.stmt(quote!(other_sums[#q] += #sq;));
    }
    let kp_lit = Literal::usize_unsuffixed(pass.len());
    let rows = v.iter().map(|row| {
        let r = row.iter().map(|&x| Tape::tok(x));
        quote!([#(#r),*])
    });
    t.stmt(quote! {
        let c = acts[0];
        let vb: [[f64; #np_lit]; #kp_lit] = [#(#rows),*];
    });
    for j in 0..k {
        let u = column(&mut t, j);
        let w = Tape::tok(u[a]);
        let w_abs = match u[a] {
            V::T(_) => quote!(f64::abs(#w)),
            _ => w.clone(),
        };
        let terms = pass.iter().enumerate().map(|(pi, &p)| {
            let up = Tape::tok(u[p]);
            quote!(f64::abs(#up - vb[#pi][c] * #w))
        });
        t.stmt(quote!(out[#j] = [#w_abs, 0.0 #(+ #terms)*];));
    }
    t.stmt(quote!(vb.iter().map(|row| row[c].abs()).sum::<f64>()));
    let flops = t.flops;
    let body = t.into_tokens();
    let item = quote! {
        /// Forward kinematics' exact condition number, one block of this kind: its share of
        /// `‖J_p⁻¹‖₁`'s column sums (see [`forward_rates_solve`]).
        #allow
        fn #name(
            inv: &[[f64; #np_lit]; #np_lit],
            tm: &[[f64; #np_lit]; #k_lit],
            factors: &[f64; #nf_lit],
            acts: &[usize; 1],
            other_sums: &mut [f64; #np_lit],
            out: &mut [[f64; 2]; #k_lit],
        ) -> f64 {
            #body
        }
    };
    (item, flops)
}
