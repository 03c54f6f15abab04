//! Emission: symbolica evaluators -> straight-line Rust (proc-macro2/quote), formatted with
//! prettyplease.
//!
//! Each kernel is one `ExpressionEvaluator` over all of its outputs (so CSE and Horner
//! schemes act across them). Its exported instruction list is translated to single-assignment
//! Rust: every instruction defines a fresh `t{k}` (numbered in emission order), dead
//! definitions are dropped, and the outputs are written last (the exported list reuses output
//! slots as scratch).

use std::collections::HashMap;
use std::fmt::Write as _;

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};
use symbolica::atom::{Atom, AtomCore, Symbol};
use symbolica::evaluate::{Instruction, Slot};

use crate::derive::{ConstDef, Derivation, const_symbol, q, v};
use crate::model::{Expr, Func, Model};

/// Operation counts of one kernel after CSE, as emitted (`sincos` counts as one function).
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
    pub entries: Vec<(Target, Atom)>,
}

impl OutArg {
    pub fn new(name: &'static str, ty: TokenStream, entries: Vec<(Target, Atom)>) -> Self {
        OutArg { name, ty, entries }
    }
}

/// One kernel to emit: one evaluator over the entries of all its output arguments, so that
/// CSE and the Horner schemes act across them (a fused kernel shares its trigonometry).
pub struct KernelSpec {
    pub name: &'static str,
    pub doc: String,
    /// Reads `xdot` as well as `x`.
    pub uses_velocity: bool,
    pub outs: Vec<OutArg>,
}

/// The result of emitting one kernel.
pub struct EmittedKernel {
    pub tokens: TokenStream,
    pub ops: Ops,
    pub nonzeros: usize,
}

/// The expression for one input parameter of an evaluator.
fn input_tokens(i: usize, n: usize, frozen: bool) -> TokenStream {
    if i < n {
        let idx = Literal::usize_unsuffixed(i);
        quote!(x[#idx])
    } else if i < 2 * n {
        let idx = Literal::usize_unsuffixed(i - n);
        quote!(xdot[#idx])
    } else {
        let idx = Literal::usize_unsuffixed(i - 2 * n);
        if frozen {
            quote!(FROZEN[#idx])
        } else {
            quote!(c[#idx])
        }
    }
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

enum Val {
    /// A reference to an input or a local: used as is.
    Tok(TokenStream),
    /// A constant value.
    Num(f64),
}

impl Val {
    fn tokens(&self) -> TokenStream {
        match self {
            Val::Tok(t) => t.clone(),
            Val::Num(x) => f64_tokens(*x),
        }
    }
}

/// Emits one kernel: `pub fn NAME(c: &[f64; K], x: &[f64; N], [xdot,] out: &mut OUT)`.
///
/// `horner_iterations` is symbolica's search effort for Horner schemes: on the 6-UPS, 10 gives
/// `psi` in 333 mul / 140 add, 1000 in 194 / 83 (measured; the search costs seconds).
pub fn emit_kernel(
    d: &Derivation,
    spec: &KernelSpec,
    frozen: bool,
    horner_iterations: usize,
) -> EmittedKernel {
    let n = d.n;
    let name = format_ident!("{}", spec.name);
    let live: Vec<(usize, &Target, &Atom)> = spec
        .outs
        .iter()
        .enumerate()
        .flat_map(|(k, o)| {
            o.entries
                .iter()
                .filter(|(_, a)| !a.is_zero())
                .map(move |(t, a)| (k, t, a))
        })
        .collect();
    let exprs: Vec<Atom> = live.iter().map(|(_, _, a)| (*a).clone()).collect();

    let mut params: Vec<Atom> = Vec::new();
    for i in 0..n {
        params.push(Atom::var(q(i)));
    }
    for i in 0..n {
        params.push(Atom::var(v(i)));
    }
    for l in 0..d.consts.len() {
        params.push(Atom::var(const_symbol(&d.consts, l)));
    }

    let mut body: Vec<(usize, TokenStream, Vec<usize>)> = Vec::new(); // (local id, rhs, locals used)
    let mut ops = Ops::default();
    let mut slot_val: HashMap<Slot, (Val, Option<usize>)> = HashMap::new();
    let mut next_local = 0usize;
    let mut uses_x = false;
    let mut uses_v = false;
    let mut uses_c = false;
    // local id -> (is sin, argument): sin/cos pairs of one argument become one `sincos`.
    let mut trig: HashMap<usize, (bool, String)> = HashMap::new();

    if !exprs.is_empty() {
        let ev = Atom::evaluator_multiple(&exprs, &params)
            .horner_iterations(horner_iterations)
            .build()
            .expect("every symbol of a kernel is an evaluator input");
        let ex = ev.export_instructions();
        let consts: Vec<f64> = ex.constants.iter().map(|c| c.re.to_f64()).collect();

        let mut read = |s: &Slot,
                        slot_val: &HashMap<Slot, (Val, Option<usize>)>,
                        used: &mut Vec<usize>|
         -> Val {
            match s {
                Slot::Param(i) => {
                    if *i < n {
                        uses_x = true;
                    } else if *i < 2 * n {
                        uses_v = true;
                    } else {
                        uses_c = true;
                    }
                    Val::Tok(input_tokens(*i, n, frozen))
                }
                Slot::Const(i) => Val::Num(consts[*i]),
                Slot::Temp(_) | Slot::Out(_) => {
                    let (val, local) = slot_val.get(s).expect("slot written before it is read");
                    if let Some(l) = local {
                        used.push(*l);
                    }
                    match val {
                        Val::Tok(t) => Val::Tok(t.clone()),
                        Val::Num(x) => Val::Num(*x),
                    }
                }
            }
        };

        for ins in &ex.instructions {
            let mut used = Vec::new();
            let (dst, rhs): (Slot, TokenStream) = match ins {
                Instruction::Add(o, args, _) => {
                    let vals: Vec<Val> =
                        args.iter().map(|a| read(a, &slot_val, &mut used)).collect();
                    ops.add += vals.len().saturating_sub(1);
                    let toks: Vec<TokenStream> = vals.iter().map(Val::tokens).collect();
                    (*o, join(&toks, quote!(+)))
                }
                Instruction::Mul(o, args, _) => {
                    let vals: Vec<Val> =
                        args.iter().map(|a| read(a, &slot_val, &mut used)).collect();
                    // A factor -1 becomes a negation.
                    let neg = vals
                        .iter()
                        .filter(|v| matches!(v, Val::Num(x) if *x == -1.0))
                        .count()
                        % 2
                        == 1;
                    let rest: Vec<&Val> = vals
                        .iter()
                        .filter(|v| !matches!(v, Val::Num(x) if *x == -1.0))
                        .collect();
                    ops.mul += rest.len().saturating_sub(1);
                    let toks: Vec<TokenStream> = rest.iter().map(|v| v.tokens()).collect();
                    let prod = if toks.is_empty() {
                        quote!(1.0)
                    } else {
                        join(&toks, quote!(*))
                    };
                    if neg {
                        if toks.len() > 1 {
                            (*o, quote!(-(#prod)))
                        } else {
                            (*o, quote!(-#prod))
                        }
                    } else {
                        (*o, prod)
                    }
                }
                Instruction::Pow(o, b, e, _) => {
                    let b = read(b, &slot_val, &mut used).tokens();
                    let e = *e;
                    let k = e.unsigned_abs();
                    let pos = if k <= 4 {
                        ops.mul += (k as usize).saturating_sub(1);
                        let fs = vec![b.clone(); k as usize];
                        join(&fs, quote!(*))
                    } else {
                        ops.func += 1;
                        let kk = f64_tokens(k as f64);
                        quote!(libm::pow(#b, #kk))
                    };
                    if e < 0 {
                        ops.div += 1;
                        if k == 1 {
                            (*o, quote!(1.0 / #b))
                        } else {
                            (*o, quote!(1.0 / (#pos)))
                        }
                    } else {
                        (*o, pos)
                    }
                }
                Instruction::Powf(o, b, e, _) => {
                    let b = read(b, &slot_val, &mut used).tokens();
                    let ev = read(e, &slot_val, &mut used);
                    ops.func += 1;
                    match ev {
                        Val::Num(0.5) => (*o, quote!(libm::sqrt(#b))),
                        Val::Num(-0.5) => {
                            ops.div += 1;
                            (*o, quote!(1.0 / libm::sqrt(#b)))
                        }
                        other => {
                            let et = other.tokens();
                            (*o, quote!(libm::pow(#b, #et)))
                        }
                    }
                }
                Instruction::Fun(o, call, _) => {
                    let (sym, _tags, args) = &**call;
                    let a: Vec<TokenStream> = args
                        .iter()
                        .map(|a| read(a, &slot_val, &mut used).tokens())
                        .collect();
                    ops.func += 1;
                    let f = if *sym == Symbol::SIN {
                        quote!(libm::sin)
                    } else if *sym == Symbol::COS {
                        quote!(libm::cos)
                    } else if *sym == Symbol::SQRT {
                        quote!(libm::sqrt)
                    } else if *sym == Symbol::EXP {
                        quote!(libm::exp)
                    } else if *sym == Symbol::LOG {
                        quote!(libm::log)
                    } else {
                        panic!("rbss-codegen: unsupported function `{sym}` in a kernel")
                    };
                    if (*sym == Symbol::SIN || *sym == Symbol::COS) && a.len() == 1 {
                        trig.insert(next_local, (*sym == Symbol::SIN, a[0].to_string()));
                    }
                    (*o, quote!(#f(#(#a),*)))
                }
                Instruction::Assign(o, s) => {
                    let val = read(s, &slot_val, &mut used);
                    // Aliases need no statement.
                    let local = match s {
                        Slot::Temp(_) | Slot::Out(_) => slot_val.get(s).and_then(|x| x.1),
                        _ => None,
                    };
                    slot_val.insert(*o, (val, local));
                    continue;
                }
                other => panic!("rbss-codegen: unsupported evaluator instruction {other:?}"),
            };
            let id = next_local;
            next_local += 1;
            let ident = format_ident!("t{}", id);
            slot_val.insert(dst, (Val::Tok(quote!(#ident)), Some(id)));
            body.push((id, rhs, used));
        }

        // Outputs: which locals they read.
        let mut out_stmts = Vec::new();
        let mut live_locals = vec![false; next_local];
        for (j, (arg, target, _)) in live.iter().enumerate() {
            let out = format_ident!("{}", spec.outs[*arg].name);
            let (val, local) = slot_val
                .get(&Slot::Out(j))
                .expect("every output is written");
            if let Some(l) = local {
                live_locals[*l] = true;
            }
            if let Val::Tok(t) = val {
                let s = t.to_string();
                if s.starts_with("x [") {
                    uses_x = true;
                }
            }
            let lhs = match target {
                Target::Vec(i) => {
                    let i = Literal::usize_unsuffixed(*i);
                    quote!(#out[#i])
                }
                Target::Mat { row, col } => {
                    let r = Literal::usize_unsuffixed(*row);
                    let c = Literal::usize_unsuffixed(*col);
                    quote!(#out[#c][#r])
                }
                Target::Sym { row, col } => {
                    let r = Literal::usize_unsuffixed(*row);
                    let c = Literal::usize_unsuffixed(*col);
                    let rhs = val.tokens();
                    out_stmts.push(quote!(#out[#c][#r] = #rhs;));
                    if row != col {
                        out_stmts.push(quote!(#out[#r][#c] = #rhs;));
                    }
                    continue;
                }
            };
            let rhs = val.tokens();
            out_stmts.push(quote!(#lhs = #rhs;));
        }
        // Backward liveness: drop definitions nobody reads.
        for (id, _, used) in body.iter().rev() {
            if live_locals[*id] {
                for u in used {
                    live_locals[*u] = true;
                }
            }
        }
        // Renumber the live locals in emission order.
        let mut renum = vec![usize::MAX; next_local];
        let mut cnt = 0;
        for (id, _, _) in &body {
            if live_locals[*id] {
                renum[*id] = cnt;
                cnt += 1;
            }
        }
        // Pair live sin/cos of the same (single-assignment, so stable) argument.
        let mut by_arg: HashMap<&str, [Option<usize>; 2]> = HashMap::new();
        for (id, (is_sin, arg)) in &trig {
            if live_locals[*id] {
                by_arg.entry(arg.as_str()).or_default()[usize::from(!*is_sin)] = Some(*id);
            }
        }
        let mut partner: HashMap<usize, (usize, usize)> = HashMap::new(); // first id -> (sin, cos)
        let mut skip = vec![false; next_local];
        for pair in by_arg.values() {
            if let [Some(s_id), Some(c_id)] = *pair {
                let (first, second) = if s_id < c_id {
                    (s_id, c_id)
                } else {
                    (c_id, s_id)
                };
                partner.insert(first, (s_id, c_id));
                skip[second] = true;
                ops.func -= 1;
            }
        }
        let mut stmts = Vec::new();
        for (id, rhs, _) in &body {
            if live_locals[*id] && !skip[*id] {
                if let Some(&(s_id, c_id)) = partner.get(id) {
                    let si = format_ident!("t{}", renum[s_id]);
                    let ci = format_ident!("t{}", renum[c_id]);
                    let arg: TokenStream = trig[id].1.parse().expect("an argument re-parses");
                    let arg = renumber(arg, &renum);
                    stmts.push(quote!(let (#si, #ci) = libm::sincos(#arg);));
                    continue;
                }
                let ident = format_ident!("t{}", renum[*id]);
                let rhs = renumber(rhs.clone(), &renum);
                stmts.push(quote!(let #ident = #rhs;));
            }
        }
        let out_stmts: Vec<TokenStream> =
            out_stmts.into_iter().map(|s| renumber(s, &renum)).collect();
        let body_ts = quote!(#(#stmts)* #(#out_stmts)*);
        let sig = signature(
            &name,
            &spec.outs,
            spec.uses_velocity,
            uses_x,
            uses_v,
            uses_c,
            frozen,
        );
        let doc = doc_attrs(&format!("{}\n\nCost after CSE: {}.", spec.doc, ops));
        return EmittedKernel {
            tokens: quote!(#doc #sig { #body_ts }),
            ops,
            nonzeros: live.len(),
        };
    }
    let sig = signature(
        &name,
        &spec.outs,
        spec.uses_velocity,
        false,
        false,
        false,
        frozen,
    );
    let doc = doc_attrs(&format!(
        "{}\n\nEvery entry is a structural zero: writes nothing.",
        spec.doc
    ));
    EmittedKernel {
        tokens: quote!(#doc #sig {}),
        ops,
        nonzeros: 0,
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

/// Replaces every `t{old}` identifier by `t{new}`.
fn renumber(ts: TokenStream, renum: &[usize]) -> TokenStream {
    use proc_macro2::{Group, TokenTree};
    ts.into_iter()
        .map(|tt| match tt {
            TokenTree::Ident(id) => {
                let s = id.to_string();
                if let Some(num) = s.strip_prefix('t').and_then(|r| r.parse::<usize>().ok()) {
                    TokenTree::Ident(Ident::new(&format!("t{}", renum[num]), id.span()))
                } else {
                    TokenTree::Ident(id)
                }
            }
            TokenTree::Group(g) => {
                let mut ng = Group::new(g.delimiter(), renumber(g.stream(), renum));
                ng.set_span(g.span());
                TokenTree::Group(ng)
            }
            other => other,
        })
        .collect()
}

fn signature(
    name: &Ident,
    outs: &[OutArg],
    velocity: bool,
    uses_x: bool,
    uses_v: bool,
    uses_c: bool,
    frozen: bool,
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
    let c = if uses_c && !frozen {
        format_ident!("c")
    } else {
        format_ident!("_c")
    };
    let outs = outs.iter().map(|o| {
        let n = format_ident!("{}", o.name);
        let t = &o.ty;
        quote!(#n: &mut #t)
    });
    if velocity {
        quote!(pub fn #name(#c: &[f64; K], #x: &[f64; N], #xd: &[f64; N], #(#outs),*))
    } else {
        quote!(pub fn #name(#c: &[f64; K], #x: &[f64; N], #(#outs),*))
    }
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
/// parameters, `pNAME` locals for derived ones).
pub fn expr_tokens(e: &Expr, model: &Model) -> TokenStream {
    match e {
        Expr::Num { num, den } => f64_tokens(*num as f64 / *den as f64),
        Expr::Pi => quote!(core::f64::consts::PI),
        Expr::Param(j) => {
            let id = Ident::new(&model.parameters[*j].name, Span::call_site());
            quote!(#id)
        }
        Expr::Coord(_) => panic!("coordinate in a parameter expression (rejected by the parser)"),
        Expr::Neg(a) => {
            let a = expr_tokens(a, model);
            quote!((-#a))
        }
        Expr::Add(a, b) => bin(a, b, model, quote!(+)),
        Expr::Sub(a, b) => bin(a, b, model, quote!(-)),
        Expr::Mul(a, b) => bin(a, b, model, quote!(*)),
        Expr::Div(a, b) => bin(a, b, model, quote!(/)),
        Expr::Pow(a, b) => {
            let at = expr_tokens(a, model);
            if let Expr::Num { num, den: 1 } = **b
                && (0..=4).contains(&num)
            {
                if num == 0 {
                    return quote!(1.0);
                }
                let fs = vec![at; num as usize];
                let prod = join(&fs, quote!(*));
                return quote!((#prod));
            }
            let bt = expr_tokens(b, model);
            quote!(libm::pow(#at, #bt))
        }
        Expr::Call(f, a) => {
            let at = expr_tokens(a, model);
            match f {
                Func::Sin => quote!(libm::sin(#at)),
                Func::Cos => quote!(libm::cos(#at)),
                Func::Tan => quote!(libm::tan(#at)),
                Func::Sqrt => quote!(libm::sqrt(#at)),
            }
        }
    }
}

fn bin(a: &Expr, b: &Expr, model: &Model, op: TokenStream) -> TokenStream {
    let a = expr_tokens(a, model);
    let b = expr_tokens(b, model);
    quote!((#a #op #b))
}

/// Human-readable formula of a const slot, for doc comments.
pub fn const_doc(def: &ConstDef, model: &Model) -> String {
    match def {
        ConstDef::Param(j) => model.parameters[*j].name.clone(),
        ConstDef::Pi => "pi".to_string(),
        ConstDef::Call(f, e) => format!("{}({})", f.name(), expr_string(e, model)),
        ConstDef::Value(e, what) => format!("{what} = {}", expr_string(e, model)),
    }
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
        Expr::Call(f, a) => {
            s.push_str(f.name());
            s.push('(');
            write_expr(s, a, model);
            s.push(')');
        }
    }
}
