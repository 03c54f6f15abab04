//! A tape of straight-line floating-point code: the solvers' linear algebra written once, here,
//! over values whose structure the generator knows, and emitted as one `let` per operation.
//!
//! A value is a structural zero, the constant one, or a temporary `tK`. Operations on zeros and
//! ones are folded away as the tape is written, so an elimination traced over the structural
//! non-zeros of `G` and `M` emits only the products that can be non-zero, with every index a
//! constant: what a sparse factorisation finds at run time from its pattern, the tape finds
//! once. Beside its code, every temporary carries its value at a reference state (the robot's
//! home), from which the generator chooses pivots.
//!
//! Functions of a temporary are emitted as path calls (`f64::abs(t7)`, `f64::max(t3, t9)`), never
//! as method calls (`t7.abs()`): Clippy's type-certainty walk, which some of its default lints run
//! on a method call's receiver, follows every `let` the receiver depends on, without memo. Over
//! an elimination's chains of temporaries that walk is exponential: a 12 × 12 elimination
//! written with method calls kept `cargo clippy` busy for more than 28 CPU-minutes on one crate,
//! against 9 s for the same crate without it.

use proc_macro2::TokenStream;
use quote::{format_ident, quote};

pub use crate::emit::Ops as Flops;

/// A value on the tape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum V {
    /// A structural zero: never emitted, products with it vanish.
    Zero,
    /// The constant 1.
    One,
    /// The temporary `t{k}`.
    T(usize),
}

impl V {
    pub fn is_zero(self) -> bool {
        self == V::Zero
    }
}

/// The tape: statements in order, and the reference value of every temporary.
#[derive(Default)]
pub struct Tape {
    /// Statements, with the temporary each defines (`None`: a check or a store, always kept).
    stmts: Vec<(Option<usize>, TokenStream)>,
    vals: Vec<f64>,
    pub flops: Flops,
}

impl Tape {
    /// The value of `v` at the reference state.
    pub fn val(&self, v: V) -> f64 {
        match v {
            V::Zero => 0.0,
            V::One => 1.0,
            V::T(k) => self.vals[k],
        }
    }

    /// The tokens of `v` in an expression.
    pub fn tok(v: V) -> TokenStream {
        match v {
            V::Zero => quote!(0.0),
            V::One => quote!(1.0),
            V::T(k) => {
                let t = format_ident!("t{}", k);
                quote!(#t)
            }
        }
    }

    /// A new temporary `let tK = expr;` with reference value `val`.
    pub fn push(&mut self, expr: TokenStream, val: f64) -> V {
        let k = self.vals.len();
        let t = format_ident!("t{}", k);
        self.stmts.push((Some(k), quote!(let #t = #expr;)));
        self.vals.push(val);
        V::T(k)
    }

    /// A statement that defines no temporary (a check, a store).
    pub fn stmt(&mut self, s: TokenStream) {
        self.stmts.push((None, s));
    }

    /// `a * b`.
    pub fn mul(&mut self, a: V, b: V) -> V {
        match (a, b) {
            (V::Zero, _) | (_, V::Zero) => V::Zero,
            (V::One, x) | (x, V::One) => x,
            _ => {
                self.flops.mul += 1;
                let (ta, tb) = (Self::tok(a), Self::tok(b));
                let v = self.val(a) * self.val(b);
                self.push(quote!(#ta * #tb), v)
            }
        }
    }

    /// `1 / a` (`a` must not be a structural zero).
    pub fn recip(&mut self, a: V) -> V {
        match a {
            V::One => V::One,
            _ => {
                self.flops.div += 1;
                let ta = Self::tok(a);
                let v = 1.0 / self.val(a);
                self.push(quote!(1.0 / #ta), v)
            }
        }
    }

    /// `-a`.
    pub fn neg(&mut self, a: V) -> V {
        self.sum(&[(-1.0, a, V::One)])
    }

    /// `Σ s_i a_i b_i` with signs `s_i = ±1`, as one expression evaluated left to right; terms
    /// with a structural zero are dropped, products with one are not multiplied.
    pub fn sum(&mut self, terms: &[(f64, V, V)]) -> V {
        let live: Vec<(f64, V, V)> = terms
            .iter()
            .copied()
            .filter(|(_, a, b)| !a.is_zero() && !b.is_zero())
            .map(|(s, a, b)| match (a, b) {
                (V::One, x) | (x, V::One) => (s, x, V::One),
                _ => (s, a, b),
            })
            .collect();
        match live.as_slice() {
            [] => return V::Zero,
            [(s, x, V::One)] if *s > 0.0 => return *x,
            _ => {}
        }
        let val = live
            .iter()
            .map(|&(s, a, b)| s * self.val(a) * self.val(b))
            .sum();
        let expr = self.tree(&live);
        self.push(expr, val)
    }

    /// The expression of a signed sum of products, summed as a balanced tree (`(a + b) + (c +
    /// d)`): its dependency chain is `log2` of the terms long, not their number, so the
    /// processor overlaps the additions of long dot products.
    fn tree(&mut self, live: &[(f64, V, V)]) -> TokenStream {
        if live.len() > 2 {
            // `l + (r)`: the left sum needs no parentheses (addition associates to the left).
            let (l, r) = live.split_at(live.len() / 2);
            let grouped = r.len() > 1;
            let (l, r) = (self.tree(l), self.tree(r));
            self.flops.add += 1;
            return if grouped {
                quote!(#l + (#r))
            } else {
                quote!(#l + #r)
            };
        }
        let mut expr = TokenStream::new();
        for (i, &(s, a, b)) in live.iter().enumerate() {
            let term = if b == V::One {
                Self::tok(a)
            } else {
                self.flops.mul += 1;
                let (ta, tb) = (Self::tok(a), Self::tok(b));
                quote!(#ta * #tb)
            };
            expr = match (i, s > 0.0) {
                (0, true) => term,
                (0, false) if b == V::One => quote!(-#term),
                (0, false) => quote!(-(#term)),
                (_, true) => {
                    self.flops.add += 1;
                    quote!(#expr + #term)
                }
                (_, false) => {
                    self.flops.add += 1;
                    quote!(#expr - #term)
                }
            };
        }
        expr
    }

    /// The statements, in order, without the temporaries nothing reads (a value whose only
    /// use was multiplied by a structural zero after it was read); [`Tape::flops`] still counts
    /// their operations, an upper bound.
    pub fn into_tokens(self) -> TokenStream {
        let mut live = vec![false; self.vals.len()];
        let mut keep = vec![false; self.stmts.len()];
        for (i, (def, ts)) in self.stmts.iter().enumerate().rev() {
            if def.is_none_or(|k| live[k]) {
                keep[i] = true;
                mark_uses(ts.clone(), &mut live);
            }
        }
        let s = self
            .stmts
            .into_iter()
            .zip(keep)
            .filter(|(_, k)| *k)
            .map(|((_, ts), _)| ts);
        quote!(#(#s)*)
    }

    /// `let tR = if cond { body } else { alt };`: what `body` records runs only where `cond`
    /// (tokens over earlier temporaries; a NaN must make it true where that matters) holds, and
    /// its value is then the result; elsewhere `alt`. The body's temporaries are numbered after
    /// this tape's and live only inside it (those nothing reads are dropped); the result's
    /// reference value is the body's, and the body's operations count in [`Tape::flops`].
    pub fn branch(&mut self, cond: TokenStream, alt: V, body: impl FnOnce(&mut Tape) -> V) -> V {
        let mut sub = Tape {
            stmts: Vec::new(),
            vals: std::mem::take(&mut self.vals),
            flops: Flops::default(),
        };
        let r = body(&mut sub);
        let val = sub.val(r);
        // The block's value: the expression of its last statement when that defines the
        // result (`{ ..; expr }`, not `{ ..; let tK = expr; tK }`), else the temporary.
        let tail = match (sub.stmts.last(), r) {
            (Some((Some(k), _)), V::T(kr)) if *k == kr => {
                let (_, ts) = sub.stmts.pop().expect("a last statement");
                let tt: Vec<proc_macro2::TokenTree> = ts.into_iter().collect();
                // `let tK = expr ;`
                tt[3..tt.len() - 1].iter().cloned().collect()
            }
            _ => Self::tok(r),
        };
        sub.stmt(tail);
        self.flops.add += sub.flops.add;
        self.flops.mul += sub.flops.mul;
        self.flops.div += sub.flops.div;
        self.flops.func += sub.flops.func;
        self.vals.clone_from(&sub.vals);
        let body = sub.into_tokens();
        let alt = Self::tok(alt);
        self.push(quote!(if #cond { #body } else { #alt }), val)
    }

    /// The number of statements so far.
    pub fn len(&self) -> usize {
        self.stmts.len()
    }

    pub fn is_empty(&self) -> bool {
        self.stmts.is_empty()
    }
}

/// Marks the temporaries `tK` that `ts` mentions.
fn mark_uses(ts: TokenStream, live: &mut [bool]) {
    for tt in ts {
        match tt {
            proc_macro2::TokenTree::Ident(id) => {
                let s = id.to_string();
                if let Some(k) = s.strip_prefix('t').and_then(|d| d.parse::<usize>().ok())
                    && let Some(l) = live.get_mut(k)
                {
                    *l = true;
                }
            }
            proc_macro2::TokenTree::Group(g) => mark_uses(g.stream(), live),
            _ => {}
        }
    }
}

impl Tape {
    /// `sqrt(a)` (its check is the caller's).
    pub fn sqrt(&mut self, a: V) -> V {
        match a {
            V::Zero | V::One => a,
            _ => {
                self.flops.func += 1;
                let ta = Self::tok(a);
                let v = self.val(a).sqrt();
                self.push(quote!(f64::sqrt(#ta)), v)
            }
        }
    }

    /// A literal constant.
    pub fn constant(&mut self, x: f64) -> V {
        if x == 0.0 {
            return V::Zero;
        }
        if x == 1.0 {
            return V::One;
        }
        // Typed (`2.5f64`): a temporary bound to a bare literal has no type for `.abs()`.
        let l = proc_macro2::Literal::f64_suffixed(x.abs());
        let l = if x < 0.0 { quote!(-#l) } else { quote!(#l) };
        self.push(l, x)
    }

    /// `|v|` in an expression (`1.0` for the constant one).
    fn abs_tok(v: V) -> TokenStream {
        match v {
            V::One => quote!(1.0),
            _ => {
                let t = Self::tok(v);
                quote!(f64::abs(#t))
            }
        }
    }

    /// `max_i |a_i|` (0 for none): checks and norms, whose reference values do not matter.
    pub fn max_abs(&mut self, a: &[V]) -> V {
        let live: Vec<V> = a.iter().copied().filter(|v| !v.is_zero()).collect();
        let Some((&first, rest)) = live.split_first() else {
            return V::Zero;
        };
        let mut e = Self::abs_tok(first);
        for &v in rest {
            let t = Self::abs_tok(v);
            e = quote!(f64::max(#e, #t));
        }
        let val = live.iter().map(|&v| self.val(v).abs()).fold(0.0, f64::max);
        self.push(e, val)
    }

    /// `Σ_i |a_i|`.
    pub fn sum_abs(&mut self, a: &[V]) -> V {
        let live: Vec<V> = a.iter().copied().filter(|v| !v.is_zero()).collect();
        let Some((&first, rest)) = live.split_first() else {
            return V::Zero;
        };
        let mut e = Self::abs_tok(first);
        for &v in rest {
            self.flops.add += 1;
            let t = Self::abs_tok(v);
            e = quote!(#e + #t);
        }
        let val = live.iter().map(|&v| self.val(v).abs()).sum();
        self.push(e, val)
    }

    /// `max_i a_i` of values known to be non-negative (0 for none).
    pub fn max(&mut self, a: &[V]) -> V {
        let live: Vec<V> = a.iter().copied().filter(|v| !v.is_zero()).collect();
        let Some((&first, rest)) = live.split_first() else {
            return V::Zero;
        };
        if rest.is_empty() {
            return first;
        }
        let mut e = Self::tok(first);
        for &v in rest {
            let t = Self::tok(v);
            e = quote!(f64::max(#e, #t));
        }
        let val = live
            .iter()
            .map(|&v| self.val(v))
            .fold(f64::NEG_INFINITY, f64::max);
        self.push(e, val)
    }

    /// `min_i a_i` (`a` not empty, no structural zeros).
    pub fn min(&mut self, a: &[V]) -> V {
        let (&first, rest) = a.split_first().expect("min of nothing");
        if rest.is_empty() {
            return first;
        }
        let mut e = Self::tok(first);
        for &v in rest {
            let t = Self::tok(v);
            e = quote!(f64::min(#e, #t));
        }
        let val = a.iter().map(|&v| self.val(v)).fold(f64::INFINITY, f64::min);
        self.push(e, val)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeros_and_ones_fold_away() {
        let mut t = Tape::default();
        let a = t.push(quote!(x[0]), 2.0);
        let b = t.push(quote!(x[1]), 3.0);
        assert_eq!(t.mul(a, V::Zero), V::Zero);
        assert_eq!(t.mul(V::One, b), b);
        assert_eq!(t.sum(&[(1.0, a, V::One), (-1.0, V::Zero, b)]), a);
        assert_eq!(t.flops, Flops::default());
        let c = t.sum(&[(1.0, a, b), (-1.0, b, V::One), (-1.0, a, a)]);
        assert_eq!(t.val(c), 2.0 * 3.0 - 3.0 - 4.0);
        assert_eq!(t.flops.mul, 2);
        assert_eq!(t.flops.add, 2);
        let dead = t.mul(a, b);
        assert_eq!(dead, V::T(3));
        let tc = Tape::tok(c);
        t.stmt(quote!(y = #tc;));
        let code = t.into_tokens().to_string();
        assert!(
            code.contains("let t2 = t0 * t1 + (- t1 - t0 * t0) ;"),
            "{code}"
        );
        // What nothing reads is not emitted.
        assert!(!code.contains("let t3"), "{code}");
    }

    #[test]
    fn a_branch_runs_its_body_only_where_its_condition_holds() {
        let mut t = Tape::default();
        let a = t.push(quote!(x[0]), 2.0);
        let b = t.push(quote!(x[1]), 3.0);
        let ta = Tape::tok(a);
        let r = t.branch(quote!(#ta > 1.0), b, |s| {
            let dead = s.mul(a, a);
            let _ = dead;
            let p = s.mul(a, b);
            s.sum(&[(1.0, p, V::One), (1.0, b, V::One)])
        });
        assert_eq!(t.val(r), 2.0 * 3.0 + 3.0);
        assert_eq!(t.flops.mul, 2);
        let tr = Tape::tok(r);
        t.stmt(quote!(y = #tr;));
        let code = t.into_tokens().to_string();
        // The body's temporaries follow the tape's; the one nothing reads is dropped.
        assert!(
            code.contains("let t5 = if t0 > 1.0 { let t3 = t0 * t1 ; t3 + t1 } else { t1 } ;"),
            "{code}"
        );
        assert!(!code.contains("let t2"), "{code}");
    }
}
