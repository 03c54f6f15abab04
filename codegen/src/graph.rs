//! The expression graph of the derivation: every quantity is a node, built once and shared.
//!
//! Nodes are hash-consed (a sub-expression built twice is one node: common-subexpression
//! elimination as the derivation goes) and folded as they are built: exact rational
//! arithmetic, `0 * x = 0`, `1 * x = x`, `x - x = 0`, `sin`/`cos` of rational multiples of
//! pi to their exact values (`cos(pi/2) = 0`), functions of numbers to numbers. Structural
//! zeros therefore never reach the kernels.
//!
//! Derivatives go through the graph by the chain rule ([`Graph::diff`]), memoised per
//! variable, so `G = ∂f/∂X`, `d/dt` at `Xddot = 0` and the Jacobian columns of the bodies
//! are expressions in the named intermediates of the frames, never expansions of them.
//!
//! Leaves: coordinates `x[i]`, velocities `xdot[i]`, parameters `p[j]`, exact numbers,
//! inexact numbers (`Float`, e.g. `cos(pi/5)`), and pi.

use std::collections::HashMap;

/// A node of the graph.
pub type Id = u32;

/// An exact rational `num / den`, `den > 0`, in lowest terms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Rat {
    pub num: i128,
    pub den: i128,
}

fn gcd(mut a: i128, mut b: i128) -> i128 {
    a = a.abs();
    b = b.abs();
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

impl Rat {
    pub const ZERO: Rat = Rat { num: 0, den: 1 };
    pub const ONE: Rat = Rat { num: 1, den: 1 };

    /// `num / den` in lowest terms; `None` for a zero denominator.
    pub fn new(num: i128, den: i128) -> Option<Rat> {
        if den == 0 {
            return None;
        }
        let g = gcd(num, den).max(1);
        let s = if den < 0 { -1 } else { 1 };
        Some(Rat {
            num: s * num / g,
            den: s * den / g,
        })
    }
    pub fn int(n: i128) -> Rat {
        Rat { num: n, den: 1 }
    }
    pub fn to_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }
    pub fn checked_add(self, o: Rat) -> Option<Rat> {
        let num = self
            .num
            .checked_mul(o.den)?
            .checked_add(o.num.checked_mul(self.den)?)?;
        Rat::new(num, self.den.checked_mul(o.den)?)
    }
    pub fn checked_mul(self, o: Rat) -> Option<Rat> {
        Rat::new(self.num.checked_mul(o.num)?, self.den.checked_mul(o.den)?)
    }
    fn recip(self) -> Option<Rat> {
        Rat::new(self.den, self.num)
    }
    fn is_int(self) -> bool {
        self.den == 1
    }
}

/// A node: a leaf or an operation on earlier nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Node {
    Num(Rat),
    /// An inexact constant, by its bits.
    Float(u64),
    Pi,
    /// Coordinate `x[i]`.
    X(u32),
    /// Velocity `xdot[i]`.
    V(u32),
    /// Parameter `j`.
    P(u32),
    /// Input `i` of a kernel beyond `x` and `xdot` (the derivative kernel's `xddot`, then
    /// `lambda`): constant in `X` and `Xdot`, but never folded into the parameters' constants.
    In(u32),
    Add(Id, Id),
    Mul(Id, Id),
    Neg(Id),
    Div(Id, Id),
    Sin(Id),
    Cos(Id),
    Sqrt(Id),
    /// `a ^ b` for an exponent that is not a small integer.
    Pow(Id, Id),
    Log(Id),
    Exp(Id),
    /// `atan2(y, x)`.
    Atan2(Id, Id),
    Asin(Id),
    Acos(Id),
    Abs(Id),
}

/// What a derivative is taken with respect to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Seed {
    /// `∂/∂x[i]`.
    X(u32),
    /// `∂/∂xdot[i]`.
    V(u32),
    /// The time derivative with `Xddot = 0`: `Σ_k ∂/∂x[k] xdot[k]`.
    Time,
}

/// The graph: nodes, their dependencies, and the memoised derivatives.
#[derive(Clone)]
pub struct Graph {
    n: usize,
    words: usize,
    nodes: Vec<Node>,
    index: HashMap<Node, Id>,
    /// Per node, bitset over `x[0..n]` then `xdot[0..n]`.
    deps: Vec<u64>,
    /// Per node: depends on a parameter.
    has_p: Vec<bool>,
    /// Per node: depends on a kernel input [`Node::In`].
    has_in: Vec<bool>,
    /// A readable name for the node, when the derivation gave it one.
    names: Vec<Option<String>>,
    memo: HashMap<(Seed, Id), Id>,
}

impl Graph {
    /// An empty graph over `n` coordinates.
    pub fn new(n: usize) -> Graph {
        let words = (2 * n).div_ceil(64).max(1);
        let mut g = Graph {
            n,
            words,
            nodes: Vec::new(),
            index: HashMap::new(),
            deps: Vec::new(),
            has_p: Vec::new(),
            has_in: Vec::new(),
            names: Vec::new(),
            memo: HashMap::new(),
        };
        g.intern(Node::Num(Rat::ZERO));
        g.intern(Node::Num(Rat::ONE));
        g
    }

    pub const ZERO: Id = 0;
    pub const ONE: Id = 1;

    pub fn len(&self) -> usize {
        self.nodes.len()
    }
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    pub fn node(&self, id: Id) -> Node {
        self.nodes[id as usize]
    }
    /// The node `node`, if the graph has it.
    pub fn find(&self, node: Node) -> Option<Id> {
        self.index.get(&node).copied()
    }
    pub fn name_of(&self, id: Id) -> Option<&str> {
        self.names[id as usize].as_deref()
    }

    /// Gives `id` a readable name in the emitted code (the first name given wins; leaves and
    /// numbers keep theirs).
    pub fn name(&mut self, id: Id, name: &str) {
        let is_op = !matches!(
            self.nodes[id as usize],
            Node::Num(_)
                | Node::Float(_)
                | Node::Pi
                | Node::X(_)
                | Node::V(_)
                | Node::P(_)
                | Node::In(_)
        );
        if is_op && self.names[id as usize].is_none() {
            self.names[id as usize] = Some(name.to_string());
        }
    }

    fn intern(&mut self, node: Node) -> Id {
        if let Some(&id) = self.index.get(&node) {
            return id;
        }
        let id = self.nodes.len() as Id;
        let w = self.words;
        let base = self.deps.len();
        self.deps.resize(base + w, 0);
        let mut has_p = false;
        let mut has_in = false;
        match node {
            Node::X(i) => self.deps[base + i as usize / 64] |= 1 << (i % 64),
            Node::V(i) => {
                let b = self.n + i as usize;
                self.deps[base + b / 64] |= 1 << (b % 64);
            }
            Node::P(_) => has_p = true,
            Node::In(_) => has_in = true,
            _ => {
                for c in children(node) {
                    let cb = c as usize * w;
                    for k in 0..w {
                        self.deps[base + k] |= self.deps[cb + k];
                    }
                    has_p |= self.has_p[c as usize];
                    has_in |= self.has_in[c as usize];
                }
            }
        }
        self.nodes.push(node);
        self.has_p.push(has_p);
        self.has_in.push(has_in);
        self.names.push(None);
        self.index.insert(node, id);
        id
    }

    // ----- leaves -----

    pub fn num(&mut self, r: Rat) -> Id {
        self.intern(Node::Num(r))
    }
    pub fn int(&mut self, k: i128) -> Id {
        self.num(Rat::int(k))
    }
    pub fn float(&mut self, x: f64) -> Id {
        if x == 0.0 {
            return Graph::ZERO;
        }
        if x == x.trunc() && x.abs() < 1e15 {
            return self.int(x as i128);
        }
        self.intern(Node::Float(x.to_bits()))
    }
    pub fn pi(&mut self) -> Id {
        self.intern(Node::Pi)
    }
    pub fn x(&mut self, i: usize) -> Id {
        self.intern(Node::X(i as u32))
    }
    pub fn v(&mut self, i: usize) -> Id {
        self.intern(Node::V(i as u32))
    }
    pub fn p(&mut self, j: usize) -> Id {
        self.intern(Node::P(j as u32))
    }
    /// Kernel input `i` (see [`Node::In`]).
    pub fn input(&mut self, i: usize) -> Id {
        self.intern(Node::In(i as u32))
    }
    /// The number of coordinates.
    pub fn n(&self) -> usize {
        self.n
    }

    // ----- queries -----

    pub fn is_zero(&self, id: Id) -> bool {
        id == Graph::ZERO
    }
    fn rat(&self, id: Id) -> Option<Rat> {
        match self.nodes[id as usize] {
            Node::Num(r) => Some(r),
            _ => None,
        }
    }
    /// True when the node depends on no coordinate, velocity or kernel input.
    pub fn is_const(&self, id: Id) -> bool {
        let b = id as usize * self.words;
        !self.has_in[id as usize] && self.deps[b..b + self.words].iter().all(|&w| w == 0)
    }
    /// True when the node involves no coordinate, velocity or parameter: a number.
    pub fn is_number(&self, id: Id) -> bool {
        self.is_const(id) && !self.has_p[id as usize]
    }
    pub fn has_param(&self, id: Id) -> bool {
        self.has_p[id as usize]
    }
    /// How many coordinates and velocities the node depends on.
    pub fn dependencies(&self, id: Id) -> u32 {
        let b = id as usize * self.words;
        self.deps[b..b + self.words]
            .iter()
            .map(|w| w.count_ones())
            .sum()
    }
    /// True when the node depends on coordinate `i`.
    pub fn depends_x(&self, id: Id, i: usize) -> bool {
        self.deps[id as usize * self.words + i / 64] >> (i % 64) & 1 == 1
    }
    fn depends_v(&self, id: Id, i: usize) -> bool {
        let b = self.n + i;
        self.deps[id as usize * self.words + b / 64] >> (b % 64) & 1 == 1
    }
    fn depends_any_x(&self, id: Id) -> bool {
        let base = id as usize * self.words;
        (0..self.n).step_by(64).any(|s| {
            let w = self.deps[base + s / 64];
            let bits = (self.n - s).min(64);
            let mask = if bits == 64 {
                u64::MAX
            } else {
                (1 << bits) - 1
            };
            w & mask != 0
        })
    }
    /// `pi * r` when the node is a rational multiple of pi (0 included).
    fn pi_coeff(&self, id: Id) -> Option<Rat> {
        match self.nodes[id as usize] {
            Node::Num(r) if r.num == 0 => Some(Rat::ZERO),
            Node::Pi => Some(Rat::ONE),
            Node::Mul(a, b) if self.nodes[b as usize] == Node::Pi => self.rat(a),
            Node::Neg(a) => self.pi_coeff(a).and_then(|r| r.checked_mul(Rat::int(-1))),
            _ => None,
        }
    }

    /// The value of a number node (no coordinate, velocity or parameter), or of any node with
    /// the given leaf values.
    pub fn eval(&self, id: Id, x: &[f64], v: &[f64], p: &[f64]) -> f64 {
        let mut memo = HashMap::new();
        self.eval_memo(id, x, v, p, &mut memo)
    }

    fn eval_memo(
        &self,
        id: Id,
        x: &[f64],
        v: &[f64],
        p: &[f64],
        memo: &mut HashMap<Id, f64>,
    ) -> f64 {
        if let Some(&r) = memo.get(&id) {
            return r;
        }
        let r = apply(self.nodes[id as usize], x, v, p, &mut |c| {
            self.eval_memo(c, x, v, p, memo)
        });
        memo.insert(id, r);
        r
    }

    /// The values of every node (in one pass, in creation order: operands come first) with the
    /// given coordinates, velocities and parameters.
    pub fn eval_all(&self, x: &[f64], v: &[f64], p: &[f64]) -> Vec<f64> {
        let mut val: Vec<f64> = Vec::with_capacity(self.nodes.len());
        for &node in &self.nodes {
            let r = apply(node, x, v, p, &mut |c| val[c as usize]);
            val.push(r);
        }
        val
    }

    /// A number node holding the value of the number `id` (exact nodes stay exact).
    fn fold_float(&mut self, id: Id) -> Id {
        let v = self.eval(id, &[], &[], &[]);
        self.float(v)
    }

    // ----- operations, folded as they are built -----

    pub fn add(&mut self, a: Id, b: Id) -> Id {
        if a == Graph::ZERO {
            return b;
        }
        if b == Graph::ZERO {
            return a;
        }
        if let (Some(x), Some(y)) = (self.rat(a), self.rat(b))
            && let Some(s) = x.checked_add(y)
        {
            return self.num(s);
        }
        if let (Some(x), Some(y)) = (self.pi_coeff(a), self.pi_coeff(b))
            && let Some(s) = x.checked_add(y)
        {
            let c = self.num(s);
            let pi = self.pi();
            return self.mul(c, pi);
        }
        // x + (-x) = 0
        if self.nodes[a as usize] == Node::Neg(b) || self.nodes[b as usize] == Node::Neg(a) {
            return Graph::ZERO;
        }
        if self.is_number(a) && self.is_number(b) {
            let s = self.intern(Node::Add(a.min(b), a.max(b)));
            return self.fold_float(s);
        }
        // (-x) + (-y) = -(x + y)
        if let (Node::Neg(x), Node::Neg(y)) = (self.nodes[a as usize], self.nodes[b as usize]) {
            let s = self.add(x, y);
            return self.neg(s);
        }
        if a == b {
            let two = self.int(2);
            return self.mul(two, a);
        }
        if !self.is_const(a) && !self.is_const(b) {
            let (ka, xa) = self.split_signed(a);
            let (kb, xb) = self.split_signed(b);
            // Like terms: k1 x + k2 x = (k1 + k2) x.
            if xa == xb {
                let k = self.add(ka, kb);
                return self.mul(k, xa);
            }
            // A common constant factor: k x + k y = k (x + y), k x - k y = k (x - y).
            if ka != Graph::ONE && kb != Graph::ONE && self.is_const(ka) {
                if ka == kb {
                    let s = self.add(xa, xb);
                    return self.mul(ka, s);
                }
                if self.nodes[kb as usize] == Node::Neg(ka) {
                    let s = self.sub(xa, xb);
                    return self.mul(ka, s);
                }
            }
        }
        self.intern(Node::Add(a.min(b), a.max(b)))
    }

    /// [`Graph::split`] through a negation: `-(k x)` is `(-k, x)`.
    fn split_signed(&mut self, id: Id) -> (Id, Id) {
        match self.nodes[id as usize] {
            Node::Neg(y) => {
                let (k, x) = self.split(y);
                (self.neg(k), x)
            }
            _ => self.split(id),
        }
    }

    pub fn sub(&mut self, a: Id, b: Id) -> Id {
        let nb = self.neg(b);
        self.add(a, nb)
    }

    pub fn neg(&mut self, a: Id) -> Id {
        match self.nodes[a as usize] {
            Node::Num(r) => {
                let r = Rat::new(-r.num, r.den).expect("den > 0");
                self.num(r)
            }
            Node::Float(b) => self.float(-f64::from_bits(b)),
            Node::Neg(x) => x,
            _ => self.intern(Node::Neg(a)),
        }
    }

    /// `a * b`. A product keeps its constant (parameter-only) factor first and apart:
    /// `(k1 x) (k2 y) = (k1 k2) (x y)`, so the constant part is computed once, in
    /// `Params::consts`, and [`Graph::sum`] can collect like terms.
    pub fn mul(&mut self, a: Id, b: Id) -> Id {
        if a == Graph::ZERO || b == Graph::ZERO {
            return Graph::ZERO;
        }
        if a == Graph::ONE {
            return b;
        }
        if b == Graph::ONE {
            return a;
        }
        // Negations out: (-x) y = -(x y).
        if let Node::Neg(x) = self.nodes[a as usize] {
            let m = self.mul(x, b);
            return self.neg(m);
        }
        if let Node::Neg(y) = self.nodes[b as usize] {
            let m = self.mul(a, y);
            return self.neg(m);
        }
        for (r, other) in [(a, b), (b, a)] {
            if let Some(x) = self.rat(r) {
                if x == Rat::int(-1) {
                    return self.neg(other);
                }
                if x.num < 0 {
                    let pos = self.num(Rat::new(-x.num, x.den).expect("den > 0"));
                    let m = self.mul(pos, other);
                    return self.neg(m);
                }
            }
        }
        if self.is_const(a) && self.is_const(b) {
            return self.mul_const(a, b);
        }
        let (ka, xa) = self.split(a);
        let (kb, xb) = self.split(b);
        let k = if ka == Graph::ONE {
            kb
        } else if kb == Graph::ONE {
            ka
        } else {
            self.mul(ka, kb)
        };
        let x = if xa == Graph::ONE {
            xb
        } else if xb == Graph::ONE {
            xa
        } else {
            self.intern(Node::Mul(xa.min(xb), xa.max(xb)))
        };
        if k == Graph::ONE {
            return x;
        }
        if k == Graph::ZERO {
            return Graph::ZERO;
        }
        if let Node::Neg(kk) = self.nodes[k as usize] {
            let m = self.mul(kk, x);
            return self.neg(m);
        }
        if let Some(r) = self.rat(k)
            && r.num < 0
        {
            let m = self.mul(k, x);
            return m;
        }
        self.intern(Node::Mul(k, x))
    }

    /// A product of two constants (parameter-only or numbers).
    fn mul_const(&mut self, a: Id, b: Id) -> Id {
        // Numbers to the left.
        let (a, b) = if self.rat(b).is_some() && self.rat(a).is_none() {
            (b, a)
        } else {
            (a, b)
        };
        if let Some(x) = self.rat(a) {
            if let Some(y) = self.rat(b)
                && let Some(p) = x.checked_mul(y)
            {
                return self.num(p);
            }
            // r * (s * y) = (r s) * y
            if let Node::Mul(c, y) = self.nodes[b as usize]
                && let Some(s) = self.rat(c)
                && let Some(p) = x.checked_mul(s)
            {
                let pc = self.num(p);
                return self.mul(pc, y);
            }
            return self.intern(Node::Mul(a, b));
        }
        if self.is_number(a) && self.is_number(b) && a != self.pi() && b != self.pi() {
            let p = self.intern(Node::Mul(a.min(b), a.max(b)));
            return self.fold_float(p);
        }
        self.intern(Node::Mul(a.min(b), a.max(b)))
    }

    /// `(k, x)` with `id = k x`, `k` constant, `x` free of constant factors (`x` may be 1).
    fn split(&self, id: Id) -> (Id, Id) {
        if self.is_const(id) {
            return (id, Graph::ONE);
        }
        match self.nodes[id as usize] {
            Node::Mul(k, x) if self.is_const(k) => (k, x),
            _ => (Graph::ONE, id),
        }
    }

    /// `Σ terms`, like terms collected: `k1 x + k2 x = (k1 + k2) x` (the sum of constants is
    /// computed once, in `Params::consts`).
    pub fn sum(&mut self, terms: &[Id]) -> Id {
        let mut order: Vec<Id> = Vec::new();
        let mut coef: HashMap<Id, Id> = HashMap::new();
        for &t in terms {
            let (t, sign) = match self.nodes[t as usize] {
                Node::Neg(y) => (y, true),
                _ => (t, false),
            };
            let (k, x) = self.split(t);
            let k = if sign { self.neg(k) } else { k };
            match coef.get(&x) {
                Some(&old) => {
                    let s = self.add(old, k);
                    coef.insert(x, s);
                }
                None => {
                    order.push(x);
                    coef.insert(x, k);
                }
            }
        }
        let mut acc = Graph::ZERO;
        for x in order {
            let t = self.mul(coef[&x], x);
            acc = self.add(acc, t);
        }
        acc
    }

    pub fn div(&mut self, a: Id, b: Id) -> Id {
        if a == Graph::ZERO {
            return Graph::ZERO;
        }
        if let Some(r) = self.rat(b)
            && let Some(inv) = r.recip()
        {
            let i = self.num(inv);
            return self.mul(i, a);
        }
        if a == b {
            return Graph::ONE;
        }
        if let Node::Neg(x) = self.nodes[a as usize] {
            let d = self.div(x, b);
            return self.neg(d);
        }
        if let Node::Neg(y) = self.nodes[b as usize] {
            let d = self.div(a, y);
            return self.neg(d);
        }
        let d = self.intern(Node::Div(a, b));
        if self.is_number(a) && self.is_number(b) {
            return self.fold_float(d);
        }
        d
    }

    pub fn sin(&mut self, a: Id) -> Id {
        if let Some(r) = self.pi_coeff(a)
            && let Some(v) = exact_sin_pi(r)
        {
            return self.num(v);
        }
        if let Node::Neg(x) = self.nodes[a as usize] {
            let s = self.sin(x);
            return self.neg(s);
        }
        let s = self.intern(Node::Sin(a));
        if self.is_number(a) {
            return self.fold_float(s);
        }
        s
    }

    pub fn cos(&mut self, a: Id) -> Id {
        if let Some(r) = self.pi_coeff(a)
            && let Some(v) = r
                .checked_add(Rat::new(1, 2).expect("1/2"))
                .and_then(exact_sin_pi)
        {
            return self.num(v);
        }
        if let Node::Neg(x) = self.nodes[a as usize] {
            return self.cos(x);
        }
        let c = self.intern(Node::Cos(a));
        if self.is_number(a) {
            return self.fold_float(c);
        }
        c
    }

    pub fn sqrt(&mut self, a: Id) -> Id {
        if let Some(r) = self.rat(a)
            && r.num >= 0
            && let (Some(s), Some(t)) = (isqrt(r.num), isqrt(r.den))
        {
            return self.num(Rat::new(s, t).expect("den > 0"));
        }
        let s = self.intern(Node::Sqrt(a));
        if self.is_number(a) {
            return self.fold_float(s);
        }
        s
    }

    pub fn log(&mut self, a: Id) -> Id {
        if a == Graph::ONE {
            return Graph::ZERO;
        }
        let l = self.intern(Node::Log(a));
        if self.is_number(a) {
            return self.fold_float(l);
        }
        l
    }

    pub fn exp(&mut self, a: Id) -> Id {
        if a == Graph::ZERO {
            return Graph::ONE;
        }
        self.number_op(Node::Exp(a), &[a])
    }

    /// `asin(a)`: exact at 0, ±1/2, ±1 (multiples of pi / 6), odd.
    pub fn asin(&mut self, a: Id) -> Id {
        if let Some(r) = self.rat(a)
            && let Some(k) = exact_asin_pi(r)
        {
            return self.pi_times(k);
        }
        if let Node::Neg(x) = self.nodes[a as usize] {
            let s = self.asin(x);
            return self.neg(s);
        }
        self.number_op(Node::Asin(a), &[a])
    }

    /// `acos(a) = pi / 2 - asin(a)`: exact where `asin` is.
    pub fn acos(&mut self, a: Id) -> Id {
        if let Some(r) = self.rat(a)
            && let Some(k) = exact_asin_pi(r)
            && let Some(c) = Rat::new(1, 2).and_then(|h| h.checked_add(Rat::new(-k.num, k.den)?))
        {
            return self.pi_times(c);
        }
        self.number_op(Node::Acos(a), &[a])
    }

    /// `atan2(y, x)`: exact on the axes and the diagonals of rational points.
    pub fn atan2(&mut self, y: Id, x: Id) -> Id {
        if let (Some(ry), Some(rx)) = (self.rat(y), self.rat(x)) {
            let (sy, sx) = (ry.num.signum(), rx.num.signum());
            // Quarters of pi (lowest terms: |y| = |x| when numerators and denominators agree).
            let quarters = match (sy, sx) {
                (0, 0) => None,
                (0, 1) => Some(0),
                (0, _) => Some(4),
                (_, 0) => Some(2 * sy),
                _ if ry.num.abs() == rx.num.abs() && ry.den == rx.den => {
                    Some(if sx > 0 { sy } else { 3 * sy })
                }
                _ => None,
            };
            if let Some(k) = quarters.and_then(|k| Rat::new(k, 4)) {
                return self.pi_times(k);
            }
        }
        self.number_op(Node::Atan2(y, x), &[y, x])
    }

    pub fn abs(&mut self, a: Id) -> Id {
        if let Some(r) = self.rat(a) {
            return self.num(Rat::new(r.num.abs(), r.den).expect("den > 0"));
        }
        if let Some(k) = self.pi_coeff(a) {
            return self.pi_times(Rat::new(k.num.abs(), k.den).expect("den > 0"));
        }
        if let Node::Neg(x) = self.nodes[a as usize] {
            return self.abs(x);
        }
        self.number_op(Node::Abs(a), &[a])
    }

    /// `hypot(a, b) = sqrt(a² + b²)` (exact where the root is: `hypot(3, 4) = 5`).
    pub fn hypot(&mut self, a: Id, b: Id) -> Id {
        let (aa, bb) = (self.mul(a, a), self.mul(b, b));
        let s = self.add(aa, bb);
        self.sqrt(s)
    }

    /// The function `f` of the model language applied to `args` (`tan` as `sin / cos`).
    pub fn call(&mut self, f: crate::model::Func, args: &[Id]) -> Id {
        use crate::model::Func;
        let a = args.first().copied().unwrap_or(Graph::ZERO);
        let b = args.get(1).copied().unwrap_or(Graph::ZERO);
        match f {
            Func::Sin => self.sin(a),
            Func::Cos => self.cos(a),
            Func::Tan => {
                let (s, c) = (self.sin(a), self.cos(a));
                self.div(s, c)
            }
            Func::Exp => self.exp(a),
            Func::Ln => self.log(a),
            Func::Sqrt => self.sqrt(a),
            Func::Atan2 => self.atan2(a, b),
            Func::Asin => self.asin(a),
            Func::Acos => self.acos(a),
            Func::Hypot => self.hypot(a, b),
            Func::Abs => self.abs(a),
        }
    }

    /// `pi * k`.
    fn pi_times(&mut self, k: Rat) -> Id {
        let c = self.num(k);
        let pi = self.pi();
        self.mul(c, pi)
    }

    /// The node `node` of the operands `args`, folded to an f64 number when they are numbers.
    fn number_op(&mut self, node: Node, args: &[Id]) -> Id {
        let id = self.intern(node);
        if args.iter().all(|&a| self.is_number(a)) {
            return self.fold_float(id);
        }
        id
    }

    /// `a ^ b`: small integer powers as products, `^(1/2)` as `sqrt`.
    pub fn pow(&mut self, a: Id, b: Id) -> Id {
        if let Some(e) = self.rat(b) {
            if e.is_int() && e.num.abs() <= 64 {
                if e.num < 0 {
                    let p = self.pow_int(a, -e.num as u32);
                    return self.div(Graph::ONE, p);
                }
                return self.pow_int(a, e.num as u32);
            }
            if e == Rat::new(1, 2).expect("1/2") {
                return self.sqrt(a);
            }
            if e == Rat::new(-1, 2).expect("-1/2") {
                let s = self.sqrt(a);
                return self.div(Graph::ONE, s);
            }
        }
        let p = self.intern(Node::Pow(a, b));
        if self.is_number(a) && self.is_number(b) {
            return self.fold_float(p);
        }
        p
    }

    fn pow_int(&mut self, a: Id, k: u32) -> Id {
        match k {
            0 => Graph::ONE,
            1 => a,
            _ => {
                let h = self.pow_int(a, k / 2);
                let sq = self.mul(h, h);
                if k % 2 == 1 { self.mul(sq, a) } else { sq }
            }
        }
    }

    /// The number of operations computing `roots` needs beyond what `given` already computes
    /// (numbers and parameter-only nodes are free: the kernels read them).
    pub fn cost(&self, roots: &[Id], given: &[Id]) -> usize {
        let mut free = std::collections::HashSet::new();
        let mut stack: Vec<Id> = given.to_vec();
        while let Some(id) = stack.pop() {
            if !self.is_const(id) && free.insert(id) {
                stack.extend(children(self.nodes[id as usize]));
            }
        }
        let mut seen = std::collections::HashSet::new();
        let mut stack: Vec<Id> = roots.to_vec();
        let mut n = 0;
        while let Some(id) = stack.pop() {
            if self.is_const(id) || free.contains(&id) || !seen.insert(id) {
                continue;
            }
            let node = self.nodes[id as usize];
            if !matches!(node, Node::X(_) | Node::V(_) | Node::In(_) | Node::Neg(_)) {
                n += 1;
            }
            stack.extend(children(node));
        }
        n
    }

    /// The number of operations computing `roots` needs in nodes created at or after `since`
    /// (older nodes are taken as computed already; numbers and parameter-only nodes are free).
    pub fn cost_since(&self, roots: &[Id], since: Id) -> usize {
        let mut seen = std::collections::HashSet::new();
        let mut stack: Vec<Id> = roots.to_vec();
        let mut n = 0;
        while let Some(id) = stack.pop() {
            if id < since || self.is_const(id) || !seen.insert(id) {
                continue;
            }
            let node = self.nodes[id as usize];
            if !matches!(node, Node::X(_) | Node::V(_) | Node::In(_) | Node::Neg(_)) {
                n += 1;
            }
            stack.extend(children(node));
        }
        n
    }

    // ----- derivatives -----

    /// The derivative of `id` for `seed`, by the chain rule through the graph (memoised).
    pub fn diff(&mut self, id: Id, seed: Seed) -> Id {
        let relevant = match seed {
            Seed::X(i) => self.depends_x(id, i as usize),
            Seed::V(i) => self.depends_v(id, i as usize),
            Seed::Time => self.depends_any_x(id),
        };
        if !relevant {
            return Graph::ZERO;
        }
        if let Some(&d) = self.memo.get(&(seed, id)) {
            return d;
        }
        let d = match self.nodes[id as usize] {
            Node::X(i) => match seed {
                Seed::X(_) => Graph::ONE,
                Seed::Time => self.v(i as usize),
                Seed::V(_) => Graph::ZERO,
            },
            Node::V(_) => match seed {
                Seed::V(_) => Graph::ONE,
                _ => Graph::ZERO,
            },
            Node::Num(_) | Node::Float(_) | Node::Pi | Node::P(_) | Node::In(_) => Graph::ZERO,
            Node::Add(a, b) => {
                let (da, db) = (self.diff(a, seed), self.diff(b, seed));
                self.add(da, db)
            }
            Node::Mul(a, b) => {
                let (da, db) = (self.diff(a, seed), self.diff(b, seed));
                let l = self.mul(da, b);
                let r = self.mul(a, db);
                self.add(l, r)
            }
            Node::Neg(a) => {
                let da = self.diff(a, seed);
                self.neg(da)
            }
            Node::Div(a, b) => {
                // (a / b)' = (a' - (a / b) b') / b
                let (da, db) = (self.diff(a, seed), self.diff(b, seed));
                let q = self.mul(id, db);
                let num = self.sub(da, q);
                self.div(num, b)
            }
            Node::Sin(a) => {
                let da = self.diff(a, seed);
                let c = self.cos(a);
                self.mul(c, da)
            }
            Node::Cos(a) => {
                let da = self.diff(a, seed);
                let s = self.sin(a);
                let m = self.mul(s, da);
                self.neg(m)
            }
            Node::Sqrt(a) => {
                // sqrt(a)' = a' / (2 sqrt(a))
                let da = self.diff(a, seed);
                let two = self.int(2);
                let den = self.mul(two, id);
                self.div(da, den)
            }
            Node::Log(a) => {
                let da = self.diff(a, seed);
                self.div(da, a)
            }
            Node::Exp(a) => {
                let da = self.diff(a, seed);
                self.mul(id, da)
            }
            Node::Asin(a) | Node::Acos(a) => {
                // ±a' / sqrt(1 - a²)
                let da = self.diff(a, seed);
                let aa = self.mul(a, a);
                let one_minus = self.sub(Graph::ONE, aa);
                let root = self.sqrt(one_minus);
                let d = self.div(da, root);
                if matches!(self.nodes[id as usize], Node::Acos(_)) {
                    self.neg(d)
                } else {
                    d
                }
            }
            Node::Atan2(y, x) => {
                // (x y' - y x') / (x² + y²)
                let (dy, dx) = (self.diff(y, seed), self.diff(x, seed));
                let l = self.mul(x, dy);
                let r = self.mul(y, dx);
                let num = self.sub(l, r);
                let (xx, yy) = (self.mul(x, x), self.mul(y, y));
                let den = self.add(xx, yy);
                self.div(num, den)
            }
            Node::Abs(a) => {
                // a a' / |a|
                let da = self.diff(a, seed);
                let m = self.mul(a, da);
                self.div(m, id)
            }
            Node::Pow(a, b) => {
                // (a^b)' = a^b (b' log a + b a' / a)
                let (da, db) = (self.diff(a, seed), self.diff(b, seed));
                let la = self.log(a);
                let t1 = self.mul(db, la);
                let ba = self.mul(b, da);
                let t2 = self.div(ba, a);
                let s = self.add(t1, t2);
                self.mul(id, s)
            }
        };
        self.memo.insert((seed, id), d);
        d
    }
}

/// The value of `node` with the given leaves, its operands' values from `e`.
fn apply(node: Node, x: &[f64], v: &[f64], p: &[f64], e: &mut dyn FnMut(Id) -> f64) -> f64 {
    match node {
        Node::Num(r) => r.to_f64(),
        Node::Float(b) => f64::from_bits(b),
        Node::Pi => std::f64::consts::PI,
        Node::X(i) => x[i as usize],
        Node::V(i) => v[i as usize],
        Node::P(j) => p[j as usize],
        // The graph's evaluation knows no kernel inputs (only the kernels read them).
        Node::In(_) => f64::NAN,
        Node::Add(a, b) => e(a) + e(b),
        Node::Mul(a, b) => e(a) * e(b),
        Node::Neg(a) => -e(a),
        Node::Div(a, b) => e(a) / e(b),
        Node::Sin(a) => e(a).sin(),
        Node::Cos(a) => e(a).cos(),
        Node::Sqrt(a) => e(a).sqrt(),
        Node::Pow(a, b) => e(a).powf(e(b)),
        Node::Log(a) => e(a).ln(),
        Node::Exp(a) => e(a).exp(),
        Node::Atan2(y, x) => e(y).atan2(e(x)),
        Node::Asin(a) => e(a).asin(),
        Node::Acos(a) => e(a).acos(),
        Node::Abs(a) => e(a).abs(),
    }
}

/// The operands of a node (none for a leaf).
pub fn children(node: Node) -> Vec<Id> {
    match node {
        Node::Add(a, b)
        | Node::Mul(a, b)
        | Node::Div(a, b)
        | Node::Pow(a, b)
        | Node::Atan2(a, b) => {
            vec![a, b]
        }
        Node::Neg(a)
        | Node::Sin(a)
        | Node::Cos(a)
        | Node::Sqrt(a)
        | Node::Log(a)
        | Node::Exp(a)
        | Node::Asin(a)
        | Node::Acos(a)
        | Node::Abs(a) => vec![a],
        _ => Vec::new(),
    }
}

/// `sin(r pi)` when it is rational: r a multiple of 1/6 with a value in {0, ±1/2, ±1}.
fn exact_sin_pi(r: Rat) -> Option<Rat> {
    let six = r.checked_mul(Rat::int(6))?;
    if !six.is_int() {
        return None;
    }
    let k = six.num.rem_euclid(12);
    let (num, den) = match k {
        0 | 6 => (0, 1),
        1 | 5 => (1, 2),
        3 => (1, 1),
        7 | 11 => (-1, 2),
        9 => (-1, 1),
        _ => return None,
    };
    Rat::new(num, den)
}

/// `asin(r) / pi` when it is rational: r in {0, ±1/2, ±1}.
fn exact_asin_pi(r: Rat) -> Option<Rat> {
    let k = match (r.num, r.den) {
        (0, _) => 0,
        (1, 2) => 1,
        (-1, 2) => -1,
        (1, 1) => 3,
        (-1, 1) => -3,
        _ => return None,
    };
    Rat::new(k, 6)
}

fn isqrt(n: i128) -> Option<i128> {
    if n < 0 {
        return None;
    }
    let s = (n as f64).sqrt().round() as i128;
    (s.checked_mul(s)? == n).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_exact_trigonometry_and_structure() {
        let mut g = Graph::new(2);
        let pi = g.pi();
        let half = g.num(Rat::new(1, 2).unwrap());
        let a = g.mul(half, pi);
        assert_eq!(g.cos(a), Graph::ZERO);
        assert_eq!(g.sin(a), Graph::ONE);
        let third = g.num(Rat::new(-1, 3).unwrap());
        let b = g.mul(third, pi);
        let cb = g.cos(b);
        assert_eq!(g.node(cb), Node::Num(Rat::new(1, 2).unwrap()));
        let x = g.x(0);
        let nx = g.neg(x);
        assert_eq!(g.add(x, nx), Graph::ZERO);
        let s = g.sin(x);
        let c = g.cos(x);
        let sc = g.mul(s, c);
        assert_eq!(g.mul(c, s), sc, "products are hash-consed up to order");
        // d/dx sin(x) cos(x) = cos^2 - sin^2 at 0.3
        let d = g.diff(sc, Seed::X(0));
        let want = 0.3f64.cos().powi(2) - 0.3f64.sin().powi(2);
        assert!((g.eval(d, &[0.3, 0.0], &[0.0; 2], &[]) - want).abs() < 1e-15);
        // d/dt at Xddot = 0 of sin(x0) x1 = cos(x0) v0 x1 + sin(x0) v1
        let x1 = g.x(1);
        let e = g.mul(s, x1);
        let dt = g.diff(e, Seed::Time);
        let got = g.eval(dt, &[0.3, 2.0], &[0.5, -1.0], &[]);
        assert!((got - (0.3f64.cos() * 0.5 * 2.0 - 0.3f64.sin())).abs() < 1e-15);
    }
}
