//! Algebraic re-simplification of the kernels' outputs, after the derivation.
//!
//! The derivation builds every output from named intermediates (frames, body velocities,
//! forces), which keeps it linear in the bodies but leaves algebra on the table: `x - (x - y)`,
//! `a b + a c` with `a` written twice, `I_s sin²ψ + I_c cos²ψ` where one term and one
//! constant would do, Lagrangian terms that cancel across bodies. Here each output is expanded
//! into a polynomial over *atoms* (coordinates, velocities, `sin`/`cos`/`sqrt`/quotients, and
//! the parameter-only quantities), with exact rational coefficients, as far as it stays small
//! (a node whose expansion would pass `TERM_CAP` terms is an atom itself, so deep chains are
//! expanded only locally). `sin² = 1 - cos²` (or the reverse) is applied, like terms cancel,
//! and the polynomial is rebuilt by a greedy multivariate Horner scheme (the common monomial
//! factor first, then the atom in most terms), the constant coefficients going to
//! `Params::consts`. The result replaces the output only when the kernel needs fewer
//! operations with it, counted with the sharing of everything else the kernel computes.

use std::collections::{BTreeMap, HashMap};
use std::rc::Rc;

use crate::graph::{Graph, Id, Node, Rat, children};

/// The most terms an expansion may have before its node is kept as an atom.
const TERM_CAP: usize = 64;
/// The largest product (terms of one factor times terms of the other) expanded.
const PRODUCT_CAP: usize = 1024;
/// A node depending on more coordinates and velocities than this is an atom (deep in a long
/// chain nothing small comes out, and expanding there would cost the time saved elsewhere).
const DEPENDENCY_CAP: u32 = 24;

/// A monomial: atoms with exponents, sorted by atom.
type Mono = Vec<(Id, u32)>;
/// A polynomial: monomials with non-zero coefficients, sorted by monomial.
type Poly = Vec<(Mono, Rat)>;

fn mono_mul(a: &[(Id, u32)], b: &[(Id, u32)]) -> Mono {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].0.cmp(&b[j].0) {
            std::cmp::Ordering::Less => {
                out.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                out.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                out.push((a[i].0, a[i].1 + b[j].1));
                i += 1;
                j += 1;
            }
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

fn collect(terms: impl IntoIterator<Item = (Mono, Rat)>) -> Option<Poly> {
    let mut map: BTreeMap<Mono, Rat> = BTreeMap::new();
    for (m, r) in terms {
        match map.get_mut(&m) {
            Some(old) => *old = old.checked_add(r)?,
            None => {
                map.insert(m, r);
            }
        }
    }
    Some(map.into_iter().filter(|(_, r)| r.num != 0).collect())
}

/// Expansions of the graph's nodes into polynomials over atoms (memoised).
struct Expander<'a> {
    g: &'a Graph,
    memo: HashMap<Id, Rc<Poly>>,
}

impl Expander<'_> {
    fn atom(id: Id) -> Poly {
        vec![(vec![(id, 1)], Rat::ONE)]
    }

    fn expand(&mut self, root: Id) -> Rc<Poly> {
        // Children first, without recursion (the graphs of long chains are deep).
        let mut stack = vec![(root, false)];
        while let Some((id, ready)) = stack.pop() {
            if self.memo.contains_key(&id) {
                continue;
            }
            let node = self.g.node(id);
            let expandable = matches!(node, Node::Add(..) | Node::Mul(..) | Node::Neg(_))
                && self.g.dependencies(id) <= DEPENDENCY_CAP;
            if !ready && expandable {
                stack.push((id, true));
                for c in children(node) {
                    if !self.memo.contains_key(&c) {
                        stack.push((c, false));
                    }
                }
                continue;
            }
            let p = if expandable || matches!(node, Node::Num(_)) {
                self.expand_node(node)
            } else {
                None
            };
            let p = p.unwrap_or_else(|| Self::atom(id));
            self.memo.insert(id, Rc::new(p));
        }
        self.memo[&root].clone()
    }

    fn expand_node(&self, node: Node) -> Option<Poly> {
        let p = match node {
            Node::Num(r) => {
                if r.num == 0 {
                    Vec::new()
                } else {
                    vec![(Vec::new(), r)]
                }
            }
            Node::Add(a, b) => {
                let (pa, pb) = (&self.memo[&a], &self.memo[&b]);
                if pa.len() + pb.len() > 2 * TERM_CAP {
                    return None;
                }
                collect(pa.iter().chain(pb.iter()).cloned())?
            }
            Node::Neg(a) => self.memo[&a]
                .iter()
                .map(|(m, r)| Rat::new(-r.num, r.den).map(|r| (m.clone(), r)))
                .collect::<Option<Poly>>()?,
            Node::Mul(a, b) => {
                let (pa, pb) = (&self.memo[&a], &self.memo[&b]);
                if pa.len() * pb.len() > PRODUCT_CAP {
                    return None;
                }
                let mut terms = Vec::with_capacity(pa.len() * pb.len());
                for (ma, ra) in pa.iter() {
                    for (mb, rb) in pb.iter() {
                        terms.push((mono_mul(ma, mb), ra.checked_mul(*rb)?));
                    }
                }
                collect(terms)?
            }
            _ => return None,
        };
        (p.len() <= TERM_CAP).then_some(p)
    }
}

/// Which of `sin²` and `cos²` of one argument is rewritten through the other.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pythagoras {
    None,
    Sin,
    Cos,
}

/// `p` with every `s²` (`s` a `sin`, or a `cos` for [`Pythagoras::Cos`]) rewritten as
/// `1 - c²`, `c` its partner, when the graph has the partner.
fn pythagoras(g: &Graph, p: &Poly, which: Pythagoras) -> Option<Poly> {
    if which == Pythagoras::None {
        return Some(p.clone());
    }
    let partner = |a: Id| -> Option<Id> {
        match (g.node(a), which) {
            (Node::Sin(x), Pythagoras::Sin) => g.find(Node::Cos(x)),
            (Node::Cos(x), Pythagoras::Cos) => g.find(Node::Sin(x)),
            _ => None,
        }
    };
    let mut work: Vec<(Mono, Rat)> = p.clone();
    let mut out: Vec<(Mono, Rat)> = Vec::new();
    while let Some((m, r)) = work.pop() {
        let hit = m.iter().position(|&(a, e)| e >= 2 && partner(a).is_some());
        let Some(k) = hit else {
            out.push((m, r));
            continue;
        };
        let (a, e) = m[k];
        let c = partner(a)?;
        let mut rest = m.clone();
        if e == 2 {
            rest.remove(k);
        } else {
            rest[k].1 -= 2;
        }
        // s^e m' = s^(e-2) m' - s^(e-2) c² m'
        let with_c = mono_mul(&rest, &[(c, 2)]);
        work.push((rest, r));
        work.push((with_c, Rat::new(-r.num, r.den)?));
        if work.len() + out.len() > 4 * TERM_CAP {
            return None;
        }
    }
    collect(out)
}

/// The product of a monomial's atoms, in atom order (so equal products are one node).
fn product(g: &mut Graph, m: &[(Id, u32)]) -> Id {
    let mut acc = Graph::ONE;
    for &(a, e) in m {
        let p = power(g, a, e);
        acc = g.mul(acc, p);
    }
    acc
}

fn power(g: &mut Graph, a: Id, e: u32) -> Id {
    match e {
        0 => Graph::ONE,
        1 => a,
        _ => {
            let h = power(g, a, e / 2);
            let sq = g.mul(h, h);
            if e % 2 == 1 { g.mul(sq, a) } else { sq }
        }
    }
}

/// Rebuilds a polynomial as a graph node: constant atoms into each monomial's coefficient
/// (a parameter-only node), the rest by [`horner`].
fn rebuild(g: &mut Graph, p: &Poly) -> Id {
    let mut groups: BTreeMap<Mono, Vec<Id>> = BTreeMap::new();
    for (m, r) in p {
        let (cm, vm): (Mono, Mono) = m.iter().partition(|&&(a, _)| g.is_const(a));
        let k = g.num(*r);
        let cp = product(g, &cm);
        let t = g.mul(k, cp);
        groups.entry(vm).or_default().push(t);
    }
    let terms: Vec<(Mono, Id)> = groups
        .into_iter()
        .map(|(vm, ts)| (vm, g.sum(&ts)))
        .filter(|(_, k)| *k != Graph::ZERO)
        .collect();
    horner(g, terms)
}

/// A greedy multivariate Horner scheme over `Σ k_i m_i` (`k_i` constant nodes, `m_i` distinct
/// monomials): the monomial common to every term out first, then the atom in the most terms.
fn horner(g: &mut Graph, mut terms: Vec<(Mono, Id)>) -> Id {
    if terms.is_empty() {
        return Graph::ZERO;
    }
    // Common monomial factor.
    let mut common: Mono = terms[0].0.clone();
    for (m, _) in &terms[1..] {
        common.retain_mut(|(a, e)| match m.iter().find(|(b, _)| *b == *a) {
            Some(&(_, f)) => {
                *e = (*e).min(f);
                true
            }
            None => false,
        });
    }
    if !common.is_empty() {
        for (m, _) in terms.iter_mut() {
            for &(a, e) in &common {
                let k = m.iter().position(|(b, _)| *b == a).expect("common atom");
                if m[k].1 == e {
                    m.remove(k);
                } else {
                    m[k].1 -= e;
                }
            }
        }
        let f = product(g, &common);
        let rest = horner(g, terms);
        return g.mul(f, rest);
    }
    // The atom in the most terms.
    let mut count: BTreeMap<Id, usize> = BTreeMap::new();
    for (m, _) in &terms {
        for &(a, _) in m {
            *count.entry(a).or_default() += 1;
        }
    }
    let best = count
        .iter()
        .max_by_key(|&(&a, &c)| (c, std::cmp::Reverse(a)))
        .map(|(&a, &c)| (a, c));
    match best {
        Some((a, c)) if c >= 2 => {
            let (mut with, mut without) = (Vec::new(), Vec::new());
            for (mut m, k) in terms {
                match m.iter().position(|(b, _)| *b == a) {
                    Some(i) => {
                        if m[i].1 == 1 {
                            m.remove(i);
                        } else {
                            m[i].1 -= 1;
                        }
                        with.push((m, k));
                    }
                    None => without.push((m, k)),
                }
            }
            let q = horner(g, with);
            let aq = g.mul(a, q);
            let r = horner(g, without);
            g.add(aq, r)
        }
        _ => {
            let ts: Vec<Id> = terms
                .into_iter()
                .map(|(m, k)| {
                    let p = product(g, &m);
                    g.mul(k, p)
                })
                .collect();
            g.sum(&ts)
        }
    }
}

/// Reference counts of the nodes a kernel computes, to price a change of one output with the
/// sharing of the others (numbers and parameter-only nodes are free: `Params::consts`).
struct Live {
    rc: Vec<u32>,
}

impl Live {
    fn weight(g: &Graph, id: Id) -> usize {
        match g.node(id) {
            Node::X(_) | Node::V(_) | Node::In(_) | Node::Neg(_) => 0,
            _ => 1,
        }
    }

    /// Takes `root` (once more); returns the operations that became needed.
    fn add(&mut self, g: &Graph, root: Id) -> usize {
        if self.rc.len() < g.len() {
            self.rc.resize(g.len(), 0);
        }
        let mut n = 0;
        let mut stack = vec![root];
        while let Some(id) = stack.pop() {
            if g.is_const(id) {
                continue;
            }
            self.rc[id as usize] += 1;
            if self.rc[id as usize] == 1 {
                n += Self::weight(g, id);
                stack.extend(children(g.node(id)));
            }
        }
        n
    }

    /// Drops `root` once; returns the operations no longer needed.
    fn remove(&mut self, g: &Graph, root: Id) -> usize {
        let mut n = 0;
        let mut stack = vec![root];
        while let Some(id) = stack.pop() {
            if g.is_const(id) {
                continue;
            }
            self.rc[id as usize] -= 1;
            if self.rc[id as usize] == 0 {
                n += Self::weight(g, id);
                stack.extend(children(g.node(id)));
            }
        }
        n
    }
}

/// Replaces each of `roots` by the cheapest of itself and its candidates, priced with the
/// sharing of the other roots (greedily, in order); returns the operations saved.
fn improve(
    g: &mut Graph,
    roots: &mut [Id],
    candidates: &mut dyn FnMut(&mut Graph, usize, Id) -> Vec<Id>,
) -> usize {
    let mut live = Live { rc: Vec::new() };
    for &r in roots.iter() {
        live.add(g, r);
    }
    let mut saved = 0;
    for (i, root) in roots.iter_mut().enumerate() {
        let old = *root;
        if g.is_const(old) {
            continue;
        }
        let cands = candidates(g, i, old);
        if cands.is_empty() {
            continue;
        }
        let freed = live.remove(g, old);
        let (mut best, mut best_cost) = (old, freed);
        for c in cands {
            let cost = live.add(g, c);
            live.remove(g, c);
            if cost < best_cost {
                (best, best_cost) = (c, cost);
            }
        }
        live.add(g, best);
        saved += freed - best_cost;
        *root = best;
    }
    saved
}

/// Each of `roots` replaced by `alternatives[i]` (the same quantity computed another way) where
/// that makes the set cheaper; returns the operations saved.
pub fn choose(g: &mut Graph, roots: &mut [Id], alternatives: &[Id]) -> usize {
    improve(g, roots, &mut |_, i, _| vec![alternatives[i]])
}

/// Rewrites outputs where the rebuilt polynomial is cheaper, remembering the expansions of
/// the graph's nodes from one set of outputs to the next.
#[derive(Default)]
pub struct Simplifier {
    memo: HashMap<Id, Rc<Poly>>,
    done: HashMap<Id, Vec<Id>>,
}

impl Simplifier {
    /// Rewrites the outputs `roots` (one kernel's, priced together) where the rebuilt
    /// polynomial is cheaper; returns how many operations that saved.
    pub fn simplify(&mut self, g: &mut Graph, roots: &mut [Id]) -> usize {
        improve(g, roots, &mut |g, _, old| {
            if let Some(c) = self.done.get(&old) {
                return c.clone();
            }
            let mut ex = Expander {
                g: &*g,
                memo: std::mem::take(&mut self.memo),
            };
            let p = ex.expand(old);
            self.memo = ex.memo;
            // An atom: too large to expand, nothing to gain here.
            let cands = if p.len() == 1 && p[0].0 == [(old, 1)] {
                Vec::new()
            } else {
                let variants: Vec<Poly> = [Pythagoras::None, Pythagoras::Sin, Pythagoras::Cos]
                    .iter()
                    .filter_map(|&w| pythagoras(g, &p, w))
                    .collect();
                variants.iter().map(|v| rebuild(g, v)).collect()
            };
            self.done.insert(old, cands.clone());
            cands
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pythagoras_common_factors_and_cancellation() {
        let mut g = Graph::new(2);
        let (x0, x1, v0) = (g.x(0), g.x(1), g.v(0));
        let (p0, p1) = (g.p(0), g.p(1));
        let (s, c) = (g.sin(x0), g.cos(x0));
        // p0 sin² + p1 cos²: 4 mul, 1 add -> p0 + (p1 - p0) cos²: 2 mul, 1 add.
        let s2 = g.mul(s, s);
        let c2 = g.mul(c, c);
        let a = g.mul(p0, s2);
        let b = g.mul(p1, c2);
        let e1 = g.add(a, b);
        // x1 v0 c - (x1 v0 c - v0 s): cancels to v0 s.
        let t = g.mul(x1, v0);
        let t = g.mul(t, c);
        let u = g.mul(v0, s);
        let inner = g.sub(t, u);
        let e2 = g.sub(t, inner);
        let mut roots = [e1, e2];
        let before = g.cost(&roots, &[]);
        let saved = Simplifier::default().simplify(&mut g, &mut roots);
        let after = g.cost(&roots, &[]);
        assert_eq!(before - after, saved);
        assert!(after <= 6, "{before} -> {after}");
        assert_eq!(roots[1], u, "x - (x - y) = y");
        for (x, p) in [([0.3, -1.2], [2.0, 5.0]), ([2.1, 0.4], [-0.5, 0.25])] {
            let v = [0.7, 0.0];
            for (k, &r) in roots.iter().enumerate() {
                let old = g.eval([e1, e2][k], &x, &v, &p);
                let new = g.eval(r, &x, &v, &p);
                assert!((old - new).abs() < 1e-14, "{old} vs {new}");
            }
        }
    }
}
