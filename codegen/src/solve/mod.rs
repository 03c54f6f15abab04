//! The robot's solves, emitted: the linear algebra of the runtime's solvers written out over
//! the structure the generator knows (the inverse-kinematics blocks, the outputs, the
//! structural non-zeros of `G` and `M`), as straight-line code with constant indices.
//!
//! The runtime's general paths find that structure at every call (blocks of run-time orders,
//! supports, dense rows); the emitted code has it in its indices. It declines (returns `None`)
//! where the structure it was written for does not hold numerically (a pivot the threshold
//! test refuses, a block that is singular, a reduced mass matrix that is not positive
//! definite), and the runtime's general path then solves as before.

// Matrix code: the indices say which entry, so loops over them read better than iterators.
#![allow(clippy::needless_range_loop)]

pub mod block;
mod blocked;
mod forward_rates;
mod inverse;
mod rates;
mod square;
pub mod tape;

use proc_macro2::TokenStream;
use quote::quote;

use block::require;
use tape::{Flops, Tape, V};

/// An entry of `G` or `M` as the generator knows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Entry {
    /// A structural zero.
    Zero,
    /// A number, the same at every state (a `1` of a translation's Jacobian, a body's mass when
    /// the parameters are constants): emitted as a literal, folded by the compiler.
    Number(f64),
    /// A value of the state, with its value at the reference state (the home).
    Var(f64),
}

/// What the generator knows of a robot for its solves: sizes, outputs, inverse-kinematics
/// blocks, and the entries of `G` (`M × N`) and `M` (`N × N`; empty for a robot without
/// dynamics).
pub struct Structure<'a> {
    pub n: usize,
    pub m: usize,
    pub outputs: &'a [usize],
    /// The actuated coordinates, in the order of `U`.
    pub actuated: &'a [usize],
    pub ik_blocks: &'a [(Vec<usize>, Vec<usize>)],
    pub g: Vec<Vec<Entry>>,
    pub mass: Vec<Vec<Entry>>,
    /// The operation counts of the kernels `constraints` and `constraints_jacobian_p`, where
    /// the robot has them: forward kinematics' chord steps are emitted to run only where
    /// they cost less than full Newton steps (see `forward_rates`).
    pub fk_evals: Option<(Flops, Flops)>,
}

/// The tape's value of an entry read as `src`.
fn read(t: &mut Tape, e: Entry, src: TokenStream) -> V {
    match e {
        Entry::Zero => V::Zero,
        Entry::Number(x) => t.constant(x),
        Entry::Var(v) => t.push(src, v),
    }
}

/// A block `K = G[rows, cols]` of a per-block function, read from its arguments `g`, `rows`,
/// `cols` (`k[j][i]`: row `j`, column `i`) with the pattern of the block `rows0`, `cols0`.
fn read_block(t: &mut Tape, s: &Structure<'_>, rows0: &[usize], cols0: &[usize]) -> Vec<Vec<V>> {
    (0..rows0.len())
        .map(|j| {
            (0..cols0.len())
                .map(|i| read(t, s.g[rows0[j]][cols0[i]], quote!(g[cols[#i]][rows[#j]])))
                .collect()
        })
        .collect()
}

/// `G[rows, outputs]` of a per-block function (`gz[j][o]`), as [`read_block`].
fn read_gz(t: &mut Tape, s: &Structure<'_>, rows0: &[usize]) -> Vec<Vec<V>> {
    (0..rows0.len())
        .map(|j| {
            s.outputs
                .iter()
                .map(|&z| read(t, s.g[rows0[j]][z], quote!(g[#z][rows[#j]])))
                .collect()
        })
        .collect()
}

/// An emitted solve: the items it calls (per-block functions), the body of the function, and
/// its operation counts (every block once).
pub struct Emitted {
    /// Items the body calls (per-block functions), emitted beside it.
    pub items: TokenStream,
    pub body: TokenStream,
    pub flops: Flops,
}

/// Forward dynamics by elimination onto the outputs (the runtime's `reduced` path, see its
/// documentation): with `R = [-G_y⁻¹ G_z; I]` and `r0 = [G_y⁻¹ gamma; 0]`,
/// `(Rᵀ M R) z̈ = Rᵀ (F - M r0)` by Cholesky, `Ẍ = R z̈ + r0`, and the multipliers of each
/// block from `K_bᵀ lambda_b = (F - M Ẍ)` on its columns, one function per kind of block
/// (`blocked`). `None` when the robot does not have that structure (no outputs, as many outputs
/// as degrees of freedom, blocks covering every other coordinate), two blocks share mass or a
/// block is structurally singular: the runtime's general paths then solve.
pub fn forward_dynamics(s: &Structure<'_>) -> Option<Emitted> {
    if !structured(s) {
        return None;
    }
    blocked::forward_dynamics(s)
}

/// Inverse dynamics' block elimination (see `inverse`): the body of
/// `fn(g, b, u, lambda) -> Option<SolveConditioning>` with its per-block functions, or `None`
/// when the robot does not have the structure (or has an actuated output) or a block is
/// structurally singular.
pub fn inverse_dynamics(s: &Structure<'_>) -> Option<Emitted> {
    // An actuated output (a coordinate in no loop, say) is not emitted for: the runtime's
    // elimination takes it (its row of the reduced system holds its own force).
    if !structured(s)
        || s.actuated.len() != s.outputs.len()
        || s.actuated.iter().any(|a| s.outputs.contains(a))
    {
        return None;
    }
    inverse::inverse_dynamics(s)
}

/// The inverse-kinematics blocks' linear solves (see `rates`): the items and the body of
/// `fn ik_block_solve(block, g, rhs, outputs, x) -> Option<[f64; 2]>`, or `None` when a block is
/// not square or is structurally singular.
pub fn ik_block_solve(s: &Structure<'_>) -> Option<Emitted> {
    rates::ik_block_solve(s)
}

/// Forward kinematics' linear solves (see `forward_rates`): the items and the body of
/// `fn forward_rates_solve(g, rhs, x) -> Option<[f64; 2]>`, or `None` when the robot does not
/// have the structure of the elimination or a block is structurally singular.
pub fn forward_rates_solve(s: &Structure<'_>) -> Option<Emitted> {
    forward_rates::forward_rates_solve(s)
}

/// Whether the robot has the structure of the elimination: outputs, as many as its degrees of
/// freedom, and square blocks covering every other coordinate once.
fn structured(s: &Structure<'_>) -> bool {
    let (n, m) = (s.n, s.m);
    let np = s.outputs.len();
    if np == 0 || np + m != n {
        return false;
    }
    let mut covered = vec![false; n];
    for &o in s.outputs {
        covered[o] = true;
    }
    for (rows, cols) in s.ik_blocks {
        if rows.len() != cols.len() {
            return false;
        }
        for &c in cols {
            if std::mem::replace(&mut covered[c], true) {
                return false;
            }
        }
    }
    covered.iter().all(|&c| c)
}

/// `A z = rhs` by Cholesky (`A` symmetric, its upper triangle `a[o1][o2]`, `o1 <= o2`), each
/// pivot checked positive (else the emitted function returns `None`); gives `z` and the pivot
/// ratio `max d_i / min d_i` (`d_i = l_ii²`). `None` when a pivot is a structural zero.
fn cholesky_solve(t: &mut Tape, a: &[Vec<V>], rhs: &[V]) -> Option<(Vec<V>, V)> {
    let np = rhs.len();
    let mut l = vec![vec![V::Zero; np]; np];
    let mut rl = vec![V::Zero; np];
    let mut pivots = Vec::with_capacity(np);
    for o in 0..np {
        let mut terms = vec![(1.0, a[o][o], V::One)];
        terms.extend((0..o).map(|q| (-1.0, l[o][q], l[o][q])));
        let d = t.sum(&terms);
        if d.is_zero() {
            return None;
        }
        let td = Tape::tok(d);
        require(t, quote!(#td > 0.0));
        pivots.push(d);
        let lo = t.sqrt(d);
        l[o][o] = lo;
        rl[o] = t.recip(lo);
        for o2 in o + 1..np {
            let mut terms = vec![(1.0, a[o][o2], V::One)];
            terms.extend((0..o).map(|q| (-1.0, l[o2][q], l[o][q])));
            let s2 = t.sum(&terms);
            l[o2][o] = t.mul(s2, rl[o]);
        }
    }
    let pmax = t.max(&pivots);
    let pmin = t.min(&pivots);
    let (tmax, tmin) = (Tape::tok(pmax), Tape::tok(pmin));
    // One pivot (a robot of one degree of freedom): the ratio is 1.
    let ratio = if pmax == pmin {
        V::One
    } else {
        t.push(quote!(#tmax / #tmin), 0.0)
    };
    let mut y = vec![V::Zero; np];
    for o in 0..np {
        let mut terms = vec![(1.0, rhs[o], V::One)];
        terms.extend((0..o).map(|q| (-1.0, l[o][q], y[q])));
        let s2 = t.sum(&terms);
        y[o] = t.mul(s2, rl[o]);
    }
    let mut zdd = vec![V::Zero; np];
    for o in (0..np).rev() {
        let mut terms = vec![(1.0, y[o], V::One)];
        terms.extend((o + 1..np).map(|q| (-1.0, l[q][o], zdd[q])));
        let s2 = t.sum(&terms);
        zdd[o] = t.mul(s2, rl[o]);
    }

    Some((zdd, ratio))
}
