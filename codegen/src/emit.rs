//! Emission: graph nodes -> straight-line Rust (proc-macro2/quote), formatted with
//! prettyplease.
//!
//! A kernel is the set of graph nodes its outputs need. Every node is computed once (the graph
//! is hash-consed, so that is common-subexpression elimination); a node used twice, a function
//! call or a named intermediate (`rot_leg1_lower_01`, `omega_platform_z`, ...) becomes a `let`,
//! the rest is written inline. Parameter-only nodes are read from `c`, the table
//! `Params::consts` computes once; `sin`/`cos` of one argument become one `sincos`.

use std::collections::HashMap;
use std::fmt::Write as _;

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};

use crate::graph::{Graph, Id, Node, children};
use crate::model::{Expr, Func, Model};

/// Operation counts of one kernel as emitted (`sincos` counts as one function, a negation as none).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ops {
    pub add: usize,
    pub mul: usize,
    pub div: usize,
    pub func: usize,
}

impl std::fmt::Display for Ops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} mul, {} add, {} div, {} fn",
            self.mul, self.add, self.div, self.func
        )
    }
}

/// Where an output value goes.
#[derive(Clone)]
pub enum Target {
    /// `out[i]`.
    Vec(usize),
    /// `out[col][row]` (column-major matrix).
    Mat { row: usize, col: usize },
    /// `out[col][row]` and `out[row][col]` (symmetric matrix, `row <= col`).
    Sym { row: usize, col: usize },
}

/// One output argument of a kernel: `name: &mut ty`, and the entries written to it.
#[derive(Clone)]
pub struct OutArg {
    pub name: &'static str,
    pub ty: TokenStream,
    pub entries: Vec<(Target, Id)>,
}

impl OutArg {
    pub fn new(name: &'static str, ty: TokenStream, entries: Vec<(Target, Id)>) -> Self {
        OutArg { name, ty, entries }
    }
}

/// One kernel to emit: the entries of all its output arguments, computed in one function (a
/// fused kernel shares its intermediates and trigonometry).
pub struct KernelSpec {
    pub name: &'static str,
    pub doc: String,
    /// Reads `xdot` as well as `x`.
    pub uses_velocity: bool,
    /// Reads `xddot: &[f64; N]` and `lambda: &[f64; M]` after `xdot` (the graph's
    /// [`Node::In`] leaves: `In(i)` is `xddot[i]` for `i < N`, then `lambda[i - N]`).
    pub accel_inputs: bool,
    pub outs: Vec<OutArg>,
}

/// The result of emitting one kernel.
pub struct EmittedKernel {
    pub tokens: TokenStream,
    pub ops: Ops,
    pub nonzeros: usize,
}

/// An f64 literal in shortest round-trip form; negative values as unary minus.
pub fn f64_tokens(x: f64) -> TokenStream {
    if x.is_sign_negative() && x != 0.0 {
        let l = Literal::f64_unsuffixed(-x);
        quote!(-#l)
    } else {
        let l = Literal::f64_unsuffixed(if x == 0.0 { 0.0 } else { x });
        quote!(#l)
    }
}

/// The parameter-only quantities the kernels read from `c`, computed once in
/// `Params::consts`: slot `l` is graph node `slots[l]`.
#[derive(Default)]
pub struct Consts {
    pub slots: Vec<Id>,
    index: HashMap<Id, usize>,
}

impl Consts {
    /// The slot of the parameter-only node `id`, allocated on first use.
    pub fn slot(&mut self, id: Id) -> usize {
        if let Some(&l) = self.index.get(&id) {
            return l;
        }
        self.slots.push(id);
        self.index.insert(id, self.slots.len() - 1);
        self.slots.len() - 1
    }
}

/// Straight-line code for some nodes of the graph: `let` statements, then one expression per
/// root. A node gets a `let` when it is used more than once, is a function call or carries a
/// name; otherwise it is written inline, with parentheses only where the evaluation order
/// needs them (so the code passes `unused_parens` and clippy).
pub struct Block {
    pub stmts: Vec<TokenStream>,
    pub roots: Vec<TokenStream>,
    pub ops: Ops,
}

/// Renders the nodes `roots` need. `cut(id)` gives the tokens of a node read from outside
/// (inputs, constants, numbers), or `None` to compute it here.
pub fn emit_block(
    g: &Graph,
    roots: &[Id],
    temp_prefix: &str,
    cut: &mut dyn FnMut(Id) -> Option<TokenStream>,
) -> Block {
    // Reachable nodes and their use counts.
    let mut cuts: HashMap<Id, TokenStream> = HashMap::new();
    let mut uses: HashMap<Id, usize> = HashMap::new();
    let mut stack: Vec<Id> = Vec::new();
    for &r in roots {
        *uses.entry(r).or_default() += 1;
        stack.push(r);
    }
    let mut seen: std::collections::HashSet<Id> = std::collections::HashSet::new();
    while let Some(id) = stack.pop() {
        if !seen.insert(id) {
            continue;
        }
        if let Some(t) = cut(id) {
            cuts.insert(id, t);
            continue;
        }
        for c in children(g.node(id)) {
            *uses.entry(c).or_default() += 1;
            stack.push(c);
        }
    }
    let mut order: Vec<Id> = seen
        .iter()
        .copied()
        .filter(|id| !cuts.contains_key(id))
        .collect();
    order.sort_unstable();
    let is_fn = |id: Id| {
        matches!(
            g.node(id),
            Node::Sin(_)
                | Node::Cos(_)
                | Node::Sqrt(_)
                | Node::Log(_)
                | Node::Pow(..)
                | Node::Exp(_)
                | Node::Atan2(..)
                | Node::Asin(_)
                | Node::Acos(_)
                | Node::Abs(_)
        )
    };
    let mut taken: std::collections::HashSet<String> = std::collections::HashSet::new();
    let mut count = 0usize;
    let mut e = Emitter {
        g,
        cuts: &cuts,
        bound: HashMap::new(),
        ops: Ops::default(),
    };
    let mut stmts = Vec::new();
    // sin and cos of one argument: one `sincos`, at the first of the two.
    let mut paired: HashMap<Id, (Id, Id)> = HashMap::new();
    let mut skip: std::collections::HashSet<Id> = std::collections::HashSet::new();
    let emitted = |id: Id| seen.contains(&id) && !cuts.contains_key(&id);
    for &id in &order {
        if let Node::Sin(a) = g.node(id)
            && let Some(c) = g.find(Node::Cos(a)).filter(|&c| emitted(c))
        {
            paired.insert(id.min(c), (id, c));
            skip.insert(id.max(c));
        }
    }
    for &id in &order {
        if uses[&id] < 2 && !is_fn(id) && g.name_of(id).is_none() {
            continue;
        }
        let mut ident_for = |id: Id| -> Ident {
            let base = match g.name_of(id) {
                Some(nm) => nm.to_string(),
                None => {
                    count += 1;
                    format!("{temp_prefix}{}", count - 1)
                }
            };
            let mut nm = base.clone();
            let mut k = 2;
            while !taken.insert(nm.clone()) {
                nm = format!("{base}_{k}");
                k += 1;
            }
            format_ident!("{}", nm)
        };
        if skip.contains(&id) {
            continue;
        }
        if let Some(&(s, c)) = paired.get(&id) {
            let (si, ci) = (ident_for(s), ident_for(c));
            let Node::Sin(a) = g.node(s) else {
                unreachable!()
            };
            let arg = e.render(a).0;
            e.ops.func += 1;
            stmts.push(quote!(let (#si, #ci) = libm::sincos(#arg);));
            e.bound.insert(s, si);
            e.bound.insert(c, ci);
            continue;
        }
        let rhs = e.render_op(id).0;
        let ident = ident_for(id);
        stmts.push(quote!(let #ident = #rhs;));
        e.bound.insert(id, ident);
    }
    let roots: Vec<TokenStream> = roots.iter().map(|&r| e.render(r).0).collect();
    Block {
        stmts,
        roots,
        ops: e.ops,
    }
}

struct Emitter<'a> {
    g: &'a Graph,
    cuts: &'a HashMap<Id, TokenStream>,
    bound: HashMap<Id, Ident>,
    ops: Ops,
}

/// Precedence of an emitted expression: 0 a sum, 1 a product, 2 a unary minus, 3 an atom.
type Prec = u8;

impl Emitter<'_> {
    /// Tokens of a node used as an operand: its name, its cut tokens, or the inline expression.
    fn render(&mut self, id: Id) -> (TokenStream, Prec) {
        if let Some(t) = self.cuts.get(&id) {
            let p = if t.to_string().starts_with('-') { 2 } else { 3 };
            return (t.clone(), p);
        }
        if let Some(i) = self.bound.get(&id) {
            return (quote!(#i), 3);
        }
        self.render_op(id)
    }

    /// `Some(x)` when `id` reads as `-x` (an unbound negation).
    fn negated(&self, id: Id) -> Option<Id> {
        if self.cuts.contains_key(&id) || self.bound.contains_key(&id) {
            return None;
        }
        match self.g.node(id) {
            Node::Neg(x) => Some(x),
            _ => None,
        }
    }

    fn wrap(t: TokenStream, p: Prec, min: Prec) -> TokenStream {
        if p < min { quote!((#t)) } else { t }
    }

    /// The expression computing the operation `id` from its operands.
    fn render_op(&mut self, id: Id) -> (TokenStream, Prec) {
        match self.g.node(id) {
            Node::Add(a, b) => {
                self.ops.add += 1;
                let (l, r, minus) = match (self.negated(a), self.negated(b)) {
                    (_, Some(y)) => (a, y, true),
                    (Some(x), None) => (b, x, true),
                    (None, None) => (a, b, false),
                };
                let (lt, _) = self.render(l);
                let (rt, rp) = self.render(r);
                let rt = Self::wrap(rt, rp, 1);
                if minus {
                    (quote!(#lt - #rt), 0)
                } else {
                    (quote!(#lt + #rt), 0)
                }
            }
            Node::Mul(a, b) | Node::Div(a, b) => {
                let div = matches!(self.g.node(id), Node::Div(..));
                if div {
                    self.ops.div += 1;
                } else {
                    self.ops.mul += 1;
                }
                let (lt, lp) = self.render(a);
                let lt = Self::wrap(lt, lp, 1);
                let (rt, rp) = self.render(b);
                let rt = Self::wrap(rt, rp, 2);
                if div {
                    (quote!(#lt / #rt), 1)
                } else {
                    (quote!(#lt * #rt), 1)
                }
            }
            Node::Neg(a) => {
                let (t, p) = self.render(a);
                match p {
                    0 => (quote!(-(#t)), 2),
                    1 => (quote!(-#t), 1),
                    _ => (quote!(-#t), 2),
                }
            }
            Node::Sin(a)
            | Node::Cos(a)
            | Node::Sqrt(a)
            | Node::Log(a)
            | Node::Exp(a)
            | Node::Asin(a)
            | Node::Acos(a)
            | Node::Abs(a) => {
                self.ops.func += 1;
                let f = match self.g.node(id) {
                    Node::Sin(_) => quote!(libm::sin),
                    Node::Cos(_) => quote!(libm::cos),
                    Node::Sqrt(_) => quote!(libm::sqrt),
                    Node::Exp(_) => quote!(libm::exp),
                    Node::Asin(_) => quote!(libm::asin),
                    Node::Acos(_) => quote!(libm::acos),
                    Node::Abs(_) => quote!(libm::fabs),
                    _ => quote!(libm::log),
                };
                let (t, _) = self.render(a);
                (quote!(#f(#t)), 3)
            }
            Node::Pow(a, b) | Node::Atan2(a, b) => {
                self.ops.func += 1;
                let (at, _) = self.render(a);
                let (bt, _) = self.render(b);
                if matches!(self.g.node(id), Node::Pow(..)) {
                    (quote!(libm::pow(#at, #bt)), 3)
                } else {
                    (quote!(libm::atan2(#at, #bt)), 3)
                }
            }
            Node::Num(_) | Node::Float(_) | Node::Pi => {
                let v = self.g.eval(id, &[], &[], &[]);
                let t = f64_tokens(v);
                let p = if v < 0.0 { 2 } else { 3 };
                (t, p)
            }
            leaf => panic!("rbss-codegen: leaf {leaf:?} reached the emitter without tokens"),
        }
    }
}

/// Emits one kernel: `pub fn NAME(c: &[f64; K], x: &[f64; N], [xdot,] out: &mut OUT)`.
/// Parameter-only nodes become slots of `consts` (read as `c[l]`), numbers literals.
pub fn emit_kernel(g: &Graph, consts: &mut Consts, spec: &KernelSpec) -> EmittedKernel {
    let name = format_ident!("{}", spec.name);
    let live: Vec<(usize, &Target, Id)> = spec
        .outs
        .iter()
        .enumerate()
        .flat_map(|(k, o)| {
            o.entries
                .iter()
                .filter(|(_, a)| *a != Graph::ZERO)
                .map(move |(t, a)| (k, t, *a))
        })
        .collect();
    let (mut uses_x, mut uses_v, mut uses_c) = (false, false, false);
    let (mut uses_a, mut uses_l) = (false, false);
    // An off-diagonal entry of a symmetric output is written twice: count it as used twice.
    let mut roots: Vec<Id> = live.iter().map(|l| l.2).collect();
    for (_, t, id) in &live {
        if let Target::Sym { row, col } = t
            && row != col
        {
            roots.push(*id);
        }
    }
    let block = emit_block(g, &roots, "t", &mut |id| match g.node(id) {
        Node::X(i) => {
            uses_x = true;
            let i = Literal::usize_unsuffixed(i as usize);
            Some(quote!(x[#i]))
        }
        Node::V(i) => {
            uses_v = true;
            let i = Literal::usize_unsuffixed(i as usize);
            Some(quote!(xdot[#i]))
        }
        Node::In(i) if (i as usize) < g.n() => {
            uses_a = true;
            let i = Literal::usize_unsuffixed(i as usize);
            Some(quote!(xddot[#i]))
        }
        Node::In(i) => {
            uses_l = true;
            let i = Literal::usize_unsuffixed(i as usize - g.n());
            Some(quote!(lambda[#i]))
        }
        _ if g.is_number(id) => Some(f64_tokens(g.eval(id, &[], &[], &[]))),
        _ if g.is_const(id) => {
            uses_c = true;
            let l = Literal::usize_unsuffixed(consts.slot(id));
            Some(quote!(c[#l]))
        }
        _ => None,
    });
    let mut out_stmts = Vec::new();
    for ((arg, target, _), rhs) in live.iter().zip(&block.roots) {
        let out = format_ident!("{}", spec.outs[*arg].name);
        match target {
            Target::Vec(i) => {
                let i = Literal::usize_unsuffixed(*i);
                out_stmts.push(quote!(#out[#i] = #rhs;));
            }
            Target::Mat { row, col } => {
                let r = Literal::usize_unsuffixed(*row);
                let c = Literal::usize_unsuffixed(*col);
                out_stmts.push(quote!(#out[#c][#r] = #rhs;));
            }
            Target::Sym { row, col } => {
                let r = Literal::usize_unsuffixed(*row);
                let c = Literal::usize_unsuffixed(*col);
                out_stmts.push(quote!(#out[#c][#r] = #rhs;));
                if row != col {
                    out_stmts.push(quote!(#out[#r][#c] = #rhs;));
                }
            }
        }
    }
    let written: Vec<bool> = (0..spec.outs.len())
        .map(|a| live.iter().any(|(arg, _, _)| *arg == a))
        .collect();
    let mut sig = signature(
        &name,
        &spec.outs,
        &written,
        spec.uses_velocity,
        uses_x,
        uses_v,
        uses_c,
    );
    if spec.accel_inputs {
        let used = [uses_c, uses_x, uses_v, uses_a, uses_l];
        let sig_inner = accel_signature(&name, &spec.outs, &written, used);
        sig = quote!(#[allow(clippy::too_many_arguments)] #sig_inner);
    }
    let doc = if live.is_empty() {
        doc_attrs(&format!(
            "{}\n\nEvery entry is a structural zero: writes nothing.",
            spec.doc
        ))
    } else {
        doc_attrs(&format!("{}\n\nCost after CSE: {}.", spec.doc, block.ops))
    };
    let stmts = &block.stmts;
    EmittedKernel {
        tokens: quote!(#doc #sig { #(#stmts)* #(#out_stmts)* }),
        ops: block.ops,
        nonzeros: live.len(),
    }
}

/// `a op b op c ...`.
fn join(items: &[TokenStream], op: TokenStream) -> TokenStream {
    let mut out = TokenStream::new();
    for (i, it) in items.iter().enumerate() {
        if i > 0 {
            out.extend(op.clone());
        }
        out.extend(it.clone());
    }
    out
}

/// The kernel's signature; an output it writes nothing to (every entry a structural zero) is
/// named `_out`, as are unused inputs.
pub fn signature(
    name: &Ident,
    outs: &[OutArg],
    written: &[bool],
    velocity: bool,
    uses_x: bool,
    uses_v: bool,
    uses_c: bool,
) -> TokenStream {
    let x = if uses_x {
        format_ident!("x")
    } else {
        format_ident!("_x")
    };
    let xd = if uses_v {
        format_ident!("xdot")
    } else {
        format_ident!("_xdot")
    };
    let c = if uses_c {
        format_ident!("c")
    } else {
        format_ident!("_c")
    };
    let outs = outs.iter().zip(written).map(|(o, &w)| {
        let n = if w {
            format_ident!("{}", o.name)
        } else {
            format_ident!("_{}", o.name)
        };
        let t = &o.ty;
        quote!(#n: &mut #t)
    });
    if velocity {
        quote!(pub fn #name(#c: &[f64; K], #x: &[f64; N], #xd: &[f64; N], #(#outs),*))
    } else {
        quote!(pub fn #name(#c: &[f64; K], #x: &[f64; N], #(#outs),*))
    }
}

/// The signature of a kernel with the inputs `xddot` and `lambda` (every input read).
/// `used`: whether it reads `c`, `x`, `xdot`, `xddot`, `lambda` (an unused one is `_name`).
fn accel_signature(
    name: &Ident,
    outs: &[OutArg],
    written: &[bool],
    used: [bool; 5],
) -> TokenStream {
    let names = ["c", "x", "xdot", "xddot", "lambda"];
    let [c, x, xd, xdd, l]: [Ident; 5] = std::array::from_fn(|i| {
        if used[i] {
            format_ident!("{}", names[i])
        } else {
            format_ident!("_{}", names[i])
        }
    });
    let outs = outs.iter().zip(written).map(|(o, &w)| {
        let n = if w {
            format_ident!("{}", o.name)
        } else {
            format_ident!("_{}", o.name)
        };
        let t = &o.ty;
        quote!(#n: &mut #t)
    });
    quote!(pub fn #name(#c: &[f64; K], #x: &[f64; N], #xd: &[f64; N], #xdd: &[f64; N], #l: &[f64; M], #(#outs),*))
}

pub fn doc_attrs(text: &str) -> TokenStream {
    let lines: Vec<TokenStream> = text
        .lines()
        .map(|l| {
            let s = format!(" {l}");
            let s = if l.is_empty() { String::new() } else { s };
            quote!(#[doc = #s])
        })
        .collect();
    quote!(#(#lines)*)
}

/// Rust tokens for a parameter expression inside `Params::consts` (`self.NAME` for literal
/// parameters, `pNAME` locals for derived ones). Parentheses only where Rust's precedence needs
/// them, so the statement lints clean (`unused_parens`); the evaluation order is the written one
/// (a right operand of the same precedence keeps its parentheses: `a + (b + c)` rounds
/// differently from `a + b + c`).
pub fn expr_tokens(e: &Expr, model: &Model) -> TokenStream {
    expr_prec(e, model).0
}

/// Precedence levels of the emitted Rust: sums, products, unary minus, atoms.
const PREC_SUM: u8 = 1;
const PREC_PRODUCT: u8 = 2;
const PREC_NEG: u8 = 3;
const PREC_ATOM: u8 = 4;

/// The tokens of `e` and the precedence of their outermost operator.
fn expr_prec(e: &Expr, model: &Model) -> (TokenStream, u8) {
    match e {
        Expr::Num { num, den } => {
            let x = *num as f64 / *den as f64;
            let prec = if x.is_sign_negative() && x != 0.0 {
                PREC_NEG
            } else {
                PREC_ATOM
            };
            (f64_tokens(x), prec)
        }
        Expr::Pi => (quote!(core::f64::consts::PI), PREC_ATOM),
        Expr::Param(j) => {
            let id = Ident::new(&model.parameters[*j].name, Span::call_site());
            (quote!(#id), PREC_ATOM)
        }
        Expr::Coord(_) => panic!("coordinate in a parameter expression (rejected by the parser)"),
        Expr::Neg(a) => {
            let a = operand(a, model, PREC_NEG + 1);
            (quote!(-#a), PREC_NEG)
        }
        Expr::Add(a, b) => bin(a, b, model, quote!(+), PREC_SUM),
        Expr::Sub(a, b) => bin(a, b, model, quote!(-), PREC_SUM),
        Expr::Mul(a, b) => bin(a, b, model, quote!(*), PREC_PRODUCT),
        Expr::Div(a, b) => bin(a, b, model, quote!(/), PREC_PRODUCT),
        Expr::Pow(a, b) => {
            if let Expr::Num { num, den: 1 } = **b
                && (0..=4).contains(&num)
            {
                if num == 0 {
                    return (quote!(1.0), PREC_ATOM);
                }
                let at = operand(a, model, PREC_PRODUCT + 1);
                let fs = vec![at; num as usize];
                let prec = if num == 1 { PREC_ATOM } else { PREC_PRODUCT };
                return (join(&fs, quote!(*)), prec);
            }
            let at = expr_tokens(a, model);
            let bt = expr_tokens(b, model);
            (quote!(libm::pow(#at, #bt)), PREC_ATOM)
        }
        Expr::Call(f, args) => {
            let at: Vec<TokenStream> = args.iter().map(|a| expr_tokens(a, model)).collect();
            let name = match f {
                Func::Ln => "log",
                Func::Abs => "fabs",
                f => f.name(),
            };
            let fun = Ident::new(name, Span::call_site());
            (quote!(libm::#fun(#(#at),*)), PREC_ATOM)
        }
    }
}

/// `e` as an operand that needs precedence at least `min`: parenthesised when lower.
fn operand(e: &Expr, model: &Model, min: u8) -> TokenStream {
    let (t, prec) = expr_prec(e, model);
    if prec < min { quote!((#t)) } else { t }
}

/// A left-associative binary operation: the left operand at the operator's precedence, the
/// right one above it (so the written grouping, hence the rounding, is kept).
fn bin(a: &Expr, b: &Expr, model: &Model, op: TokenStream, prec: u8) -> (TokenStream, u8) {
    let a = operand(a, model, prec);
    let b = operand(b, model, prec + 1);
    (quote!(#a #op #b), prec)
}

/// A readable formula of a parameter-only node, for doc comments (long ones cut short).
pub fn node_string(g: &Graph, id: Id, model: &Model) -> String {
    fn go(g: &Graph, id: Id, model: &Model, s: &mut String) {
        if s.len() > 160 {
            return;
        }
        match g.node(id) {
            Node::P(j) => s.push_str(&model.parameters[j as usize].name),
            Node::Pi => s.push_str("pi"),
            Node::In(i) => {
                let _ = write!(s, "in{i}");
            }
            Node::X(i) => s.push_str(&model.coordinates[i as usize].name),
            Node::V(i) => {
                let _ = write!(s, "{}_dot", model.coordinates[i as usize].name);
            }
            Node::Num(_) | Node::Float(_) => {
                let _ = write!(s, "{}", g.eval(id, &[], &[], &[]));
            }
            Node::Neg(a) => {
                s.push('-');
                go(g, a, model, s);
            }
            Node::Add(a, b) | Node::Mul(a, b) | Node::Div(a, b) | Node::Pow(a, b) => {
                let op = match g.node(id) {
                    Node::Add(..) => " + ",
                    Node::Mul(..) => "*",
                    Node::Div(..) => "/",
                    _ => "^",
                };
                s.push('(');
                go(g, a, model, s);
                s.push_str(op);
                go(g, b, model, s);
                s.push(')');
            }
            Node::Sin(a)
            | Node::Cos(a)
            | Node::Sqrt(a)
            | Node::Log(a)
            | Node::Exp(a)
            | Node::Asin(a)
            | Node::Acos(a)
            | Node::Abs(a) => {
                s.push_str(match g.node(id) {
                    Node::Sin(_) => "sin(",
                    Node::Cos(_) => "cos(",
                    Node::Sqrt(_) => "sqrt(",
                    Node::Exp(_) => "exp(",
                    Node::Asin(_) => "asin(",
                    Node::Acos(_) => "acos(",
                    Node::Abs(_) => "abs(",
                    _ => "log(",
                });
                go(g, a, model, s);
                s.push(')');
            }
            Node::Atan2(y, x) => {
                s.push_str("atan2(");
                go(g, y, model, s);
                s.push_str(", ");
                go(g, x, model, s);
                s.push(')');
            }
        }
    }
    let mut s = String::new();
    go(g, id, model, &mut s);
    if s.len() > 160 {
        s.truncate(s.floor_char_boundary(157));
        s.push_str("...");
    }
    s
}

pub fn expr_string(e: &Expr, model: &Model) -> String {
    let mut s = String::new();
    write_expr(&mut s, e, model);
    s
}

fn write_expr(s: &mut String, e: &Expr, model: &Model) {
    match e {
        Expr::Num { num, den } => {
            if *den == 1 {
                let _ = write!(s, "{num}");
            } else {
                let _ = write!(s, "{}", *num as f64 / *den as f64);
            }
        }
        Expr::Pi => s.push_str("pi"),
        Expr::Param(j) => s.push_str(&model.parameters[*j].name),
        Expr::Coord(i) => s.push_str(&model.coordinates[*i].name),
        Expr::Neg(a) => {
            s.push_str("-(");
            write_expr(s, a, model);
            s.push(')');
        }
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            let op = match e {
                Expr::Add(..) => " + ",
                Expr::Sub(..) => " - ",
                Expr::Mul(..) => "*",
                Expr::Div(..) => "/",
                _ => "^",
            };
            s.push('(');
            write_expr(s, a, model);
            s.push_str(op);
            write_expr(s, b, model);
            s.push(')');
        }
        Expr::Call(f, args) => {
            s.push_str(f.name());
            s.push('(');
            for (k, a) in args.iter().enumerate() {
                if k > 0 {
                    s.push_str(", ");
                }
                write_expr(s, a, model);
            }
            s.push(')');
        }
    }
}
