//! Symbolic derivation with symbolica: frames, loop closure `f(X)`, `G = ∂f/∂X`, `gamma`.
//!
//! Symbols: coordinate `i` is `q{i}`, its velocity `v{i}`; parameter `j` is `p{j}`; the
//! constant `pi` is `pi_`. After simplification every `sin`/`cos` of a constant (parameter-only)
//! angle is replaced by a derived constant `k{l}` that the generated `Params::consts` computes
//! once, so kernels evaluate no trigonometry of parameters.
//!
//! Everything here must run on one thread, after [`crate::lock::SymbolicaLock::acquire`].

use std::collections::BTreeMap;

use symbolica::atom::{Atom, AtomCore, Symbol};
use symbolica::{function, parse, symbol};

use crate::model::{Attachment, Axis, Expr, Func, Model, Step};

/// A constant the kernels read from `Params::consts()`.
#[derive(Debug, Clone)]
pub enum ConstDef {
    /// Parameter `j` itself.
    Param(usize),
    /// `pi`.
    Pi,
    /// A built-in function of a parameter expression, e.g. `cos(alpha1)`.
    Call(Func, Expr),
}

/// The symbolic results for one model.
pub struct Derivation {
    pub n: usize,
    pub m: usize,
    /// Constants read by the kernels, in `consts` order.
    pub consts: Vec<ConstDef>,
    /// Constraint names, `loop.axis`.
    pub constraint_names: Vec<String>,
    /// `f(X)`, length m.
    pub f: Vec<Atom>,
    /// `G = ∂f/∂X`, row-major `g[i][j]`; zero atoms are structural zeros.
    pub g: Vec<Vec<Atom>>,
    /// `gamma = -(dG/dt) Xdot`, length m.
    pub gamma: Vec<Atom>,
    /// Passive coordinates (not actuated), ascending.
    pub passive: Vec<usize>,
    /// Independent IK blocks: (rows, cols).
    pub ik_blocks: Vec<(Vec<usize>, Vec<usize>)>,
}

/// An error found during derivation (the model parses but is not well posed).
#[derive(Debug, Clone)]
pub struct DeriveError {
    pub pos: crate::model::Pos,
    pub message: String,
}

pub fn q(i: usize) -> Symbol {
    symbol!(&format!("q{i}"))
}
pub fn v(i: usize) -> Symbol {
    symbol!(&format!("v{i}"))
}
fn p(j: usize) -> Symbol {
    symbol!(&format!("p{j}"))
}
fn pi_sym() -> Symbol {
    symbol!("pi_")
}
pub fn k(l: usize) -> Symbol {
    symbol!(&format!("k{l}"))
}

/// Converts a model expression to a symbolica atom.
pub fn to_atom(e: &Expr) -> Atom {
    match e {
        Expr::Num { num, den } => Atom::num((*num, *den)),
        Expr::Pi => Atom::var(pi_sym()),
        Expr::Param(j) => Atom::var(p(*j)),
        Expr::Coord(i) => Atom::var(q(*i)),
        Expr::Neg(a) => -to_atom(a),
        Expr::Add(a, b) => to_atom(a) + to_atom(b),
        Expr::Sub(a, b) => to_atom(a) - to_atom(b),
        Expr::Mul(a, b) => to_atom(a) * to_atom(b),
        Expr::Div(a, b) => to_atom(a) / to_atom(b),
        Expr::Pow(a, b) => to_atom(a).pow(to_atom(b)),
        Expr::Call(f, a) => {
            let s = match f {
                Func::Sin => Symbol::SIN,
                Func::Cos => Symbol::COS,
                Func::Sqrt => Symbol::SQRT,
                Func::Tan => {
                    return function!(Symbol::SIN, to_atom(a)) / function!(Symbol::COS, to_atom(a));
                }
            };
            function!(s, to_atom(a))
        }
    }
}

/// Expands and removes `sin^2 + cos^2` pairs: every `sin(u)^k` (k >= 2) becomes
/// `sin(u)^(k-2) (1 - cos(u)^2)`, then the result is expanded, until nothing changes.
pub fn simplify(a: &Atom) -> Atom {
    let mut cur = a.expand();
    for _ in 0..16 {
        let mut next = cur.clone();
        for kpow in (2..=8).rev() {
            let pat = parse!(&format!("sin(x_)^{kpow}"));
            let rhs = if kpow == 2 {
                parse!("1 - cos(x_)^2")
            } else {
                parse!(&format!("sin(x_)^{}*(1 - cos(x_)^2)", kpow - 2))
            };
            next = next.replace(pat.to_pattern()).with(rhs.to_pattern());
        }
        next = next.expand();
        if next == cur {
            break;
        }
        cur = next;
    }
    cur
}

/// A homogeneous transform as a rotation and a translation of atoms.
#[derive(Clone)]
pub struct Frame {
    pub r: [[Atom; 3]; 3],
    pub p: [Atom; 3],
}

impl Frame {
    pub fn identity() -> Frame {
        let z = Atom::num(0);
        let o = Atom::num(1);
        Frame {
            r: [
                [o.clone(), z.clone(), z.clone()],
                [z.clone(), o.clone(), z.clone()],
                [z.clone(), z.clone(), o],
            ],
            p: [z.clone(), z.clone(), z],
        }
    }

    /// `self * step` (post-multiplication).
    pub fn then(&self, step: &Step) -> Frame {
        match step {
            Step::Trans(axis, e) => {
                let s = to_atom(e);
                let col = axis.index();
                let mut out = self.clone();
                for i in 0..3 {
                    out.p[i] = (&self.p[i] + &self.r[i][col] * &s).expand();
                }
                out
            }
            Step::Rot(axis, e) => {
                let a = to_atom(e);
                let c = function!(Symbol::COS, &a);
                let s = function!(Symbol::SIN, &a);
                let z = Atom::num(0);
                let o = Atom::num(1);
                let rot: [[Atom; 3]; 3] = match axis {
                    Axis::X => [
                        [o, z.clone(), z.clone()],
                        [z.clone(), c.clone(), -&s],
                        [z, s, c],
                    ],
                    Axis::Y => [
                        [c.clone(), z.clone(), s.clone()],
                        [z.clone(), o, z.clone()],
                        [-&s, z, c],
                    ],
                    Axis::Z => [
                        [c.clone(), -&s, z.clone()],
                        [s, c, z.clone()],
                        [z.clone(), z, o],
                    ],
                };
                let mut out = self.clone();
                for i in 0..3 {
                    for j in 0..3 {
                        let mut acc = Atom::num(0);
                        for (l, rot_l) in rot.iter().enumerate() {
                            if !rot_l[j].is_zero() && !self.r[i][l].is_zero() {
                                acc += &self.r[i][l] * &rot_l[j];
                            }
                        }
                        out.r[i][j] = acc.expand();
                    }
                }
                out
            }
        }
    }
}

/// World frames of every body, in model order.
pub fn body_frames(model: &Model) -> Vec<Frame> {
    let mut frames: Vec<Frame> = Vec::with_capacity(model.bodies.len());
    for body in &model.bodies {
        let mut fr = match body.parent {
            Some(i) => frames[i].clone(),
            None => Frame::identity(),
        };
        for st in &body.steps {
            fr = fr.then(st);
        }
        frames.push(fr);
    }
    frames
}

fn attachment_origin(frames: &[Frame], a: &Attachment) -> [Atom; 3] {
    let mut fr = match a.body {
        Some(i) => frames[i].clone(),
        None => Frame::identity(),
    };
    for st in &a.steps {
        fr = fr.then(st);
    }
    fr.p
}

/// Collects the constant (parameter-only) angles and arguments of built-in functions.
fn collect_const_calls(e: &Expr, out: &mut Vec<(Func, Expr)>) {
    match e {
        Expr::Call(f, a) => {
            if a.is_constant() {
                let f = if *f == Func::Tan { Func::Sin } else { *f };
                push_unique(out, (f, (**a).clone()));
                if matches!(e, Expr::Call(Func::Tan, _)) {
                    push_unique(out, (Func::Cos, (**a).clone()));
                }
            } else {
                collect_const_calls(a, out);
            }
        }
        Expr::Neg(a) => collect_const_calls(a, out),
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            collect_const_calls(a, out);
            collect_const_calls(b, out);
        }
        _ => {}
    }
}

fn push_unique(out: &mut Vec<(Func, Expr)>, item: (Func, Expr)) {
    if !out.contains(&item) {
        out.push(item);
    }
}

fn collect_step_consts(steps: &[Step], out: &mut Vec<(Func, Expr)>) {
    for st in steps {
        match st {
            Step::Rot(_, e) => {
                if e.is_constant() {
                    push_unique(out, (Func::Cos, e.clone()));
                    push_unique(out, (Func::Sin, e.clone()));
                } else {
                    collect_const_calls(e, out);
                }
            }
            Step::Trans(_, e) => collect_const_calls(e, out),
        }
    }
}

/// Replaces parameter-only function calls by the constants `k{l}`; returns the constant table.
struct ConstTable {
    defs: Vec<ConstDef>,
    /// (pattern atom, replacement symbol)
    subs: Vec<(Atom, Atom)>,
}

impl ConstTable {
    fn new(model: &Model) -> ConstTable {
        let mut calls = Vec::new();
        for b in &model.bodies {
            collect_step_consts(&b.steps, &mut calls);
        }
        for l in &model.loops {
            collect_step_consts(&l.a.steps, &mut calls);
            collect_step_consts(&l.b.steps, &mut calls);
        }
        let mut defs: Vec<ConstDef> = (0..model.parameters.len()).map(ConstDef::Param).collect();
        defs.push(ConstDef::Pi);
        let mut subs = Vec::new();
        for (f, e) in calls {
            let sym = match f {
                Func::Sin => Symbol::SIN,
                Func::Cos => Symbol::COS,
                Func::Sqrt => Symbol::SQRT,
                Func::Tan => unreachable!("tan is rewritten as sin/cos"),
            };
            let pat = function!(sym, to_atom(&e));
            subs.push((pat, Atom::var(k(defs.len()))));
            defs.push(ConstDef::Call(f, e));
        }
        ConstTable { defs, subs }
    }

    fn apply(&self, a: &Atom) -> Atom {
        let mut out = a.clone();
        for (pat, rep) in &self.subs {
            out = out.replace(pat.to_pattern()).with(rep.to_pattern());
        }
        out
    }
}

/// Symbol for const slot `l`: parameters keep their `p{j}` symbol, pi is `pi_`, others `k{l}`.
pub fn const_symbol(defs: &[ConstDef], l: usize) -> Symbol {
    match defs[l] {
        ConstDef::Param(j) => p(j),
        ConstDef::Pi => pi_sym(),
        ConstDef::Call(..) => k(l),
    }
}

/// Runs the kinematic derivation. `progress` receives one line per stage.
pub fn derive(
    model: &Model,
    progress: &mut dyn FnMut(&str),
) -> Result<Derivation, Vec<DeriveError>> {
    let n = model.coordinates.len();
    let table = ConstTable::new(model);

    progress("frames");
    let frames = body_frames(model);

    progress("loop closure f(X)");
    let mut f = Vec::new();
    let mut names = Vec::new();
    let mut errors = Vec::new();
    for lp in &model.loops {
        let pa = attachment_origin(&frames, &lp.a);
        let pb = attachment_origin(&frames, &lp.b);
        for axis in &lp.components {
            let i = axis.index();
            let e = simplify(&(&pa[i] - &pb[i]));
            if e.is_zero() {
                errors.push(DeriveError {
                    pos: lp.pos,
                    message: format!(
                        "loop `{}`: component `{}` of origin(a) - origin(b) is identically zero, so it constrains nothing; \
                         remove it from `components` or check the two attachments",
                        lp.name,
                        axis.name()
                    ),
                });
            } else if !(0..n).any(|j| e.contains_symbol(q(j))) {
                errors.push(DeriveError {
                    pos: lp.pos,
                    message: format!(
                        "loop `{}`: component `{}` does not depend on any coordinate, so the loop cannot close",
                        lp.name,
                        axis.name()
                    ),
                });
            }
            f.push(e);
            names.push(format!("{}.{}", lp.name, axis.name()));
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    let m = f.len();

    progress("Jacobian G = df/dX");
    let mut g = vec![vec![Atom::num(0); n]; m];
    for (i, fi) in f.iter().enumerate() {
        for (j, gij) in g[i].iter_mut().enumerate() {
            if fi.contains_symbol(q(j)) {
                *gij = simplify(&fi.derivative(q(j)));
            }
        }
    }

    progress("acceleration term gamma = -(dG/dt) Xdot");
    let mut gamma = Vec::with_capacity(m);
    for gi in &g {
        // G_i . Xdot
        let mut gv = Atom::num(0);
        for (j, gij) in gi.iter().enumerate() {
            if !gij.is_zero() {
                gv += gij * Atom::var(v(j));
            }
        }
        let mut acc = Atom::num(0);
        for kk in 0..n {
            if gv.contains_symbol(q(kk)) {
                acc += gv.derivative(q(kk)) * Atom::var(v(kk));
            }
        }
        gamma.push(simplify(&(-acc)));
    }

    progress("structure: passive coordinates, IK blocks");
    let mut actuated = vec![false; n];
    for &a in &model.actuated {
        actuated[a] = true;
    }
    let passive: Vec<usize> = (0..n).filter(|&j| !actuated[j]).collect();
    let mut is_output = vec![false; n];
    for &o in &model.outputs {
        is_output[o] = true;
    }
    let ik_blocks = ik_blocks(&g, &is_output, &names, model, &mut errors);
    if !errors.is_empty() {
        return Err(errors);
    }

    let f = f.iter().map(|a| table.apply(a)).collect();
    let g = g
        .iter()
        .map(|row| row.iter().map(|a| table.apply(a)).collect())
        .collect();
    let gamma = gamma.iter().map(|a| table.apply(a)).collect();

    Ok(Derivation {
        n,
        m,
        consts: table.defs,
        constraint_names: names,
        f,
        g,
        gamma,
        passive,
        ik_blocks,
    })
}

/// Connected components of the bipartite graph (constraint rows, non-output coordinates)
/// given by the sparsity of G. Each must be square.
fn ik_blocks(
    g: &[Vec<Atom>],
    is_output: &[bool],
    names: &[String],
    model: &Model,
    errors: &mut Vec<DeriveError>,
) -> Vec<(Vec<usize>, Vec<usize>)> {
    let m = g.len();
    let n = is_output.len();
    // union-find over m rows + n columns
    let mut parent: Vec<usize> = (0..m + n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for (i, row) in g.iter().enumerate() {
        for (j, gij) in row.iter().enumerate() {
            if !is_output[j] && !gij.is_zero() {
                let a = find(&mut parent, i);
                let b = find(&mut parent, m + j);
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut comps: BTreeMap<usize, (Vec<usize>, Vec<usize>)> = BTreeMap::new();
    for i in 0..m {
        let r = find(&mut parent, i);
        comps.entry(r).or_default().0.push(i);
    }
    for j in (0..n).filter(|&j| !is_output[j]) {
        let r = find(&mut parent, m + j);
        comps.entry(r).or_default().1.push(j);
    }
    let blocks: Vec<(Vec<usize>, Vec<usize>)> = comps.into_values().collect();
    for (rows, cols) in &blocks {
        if rows.len() != cols.len() {
            let rn: Vec<&str> = rows.iter().map(|&i| names[i].as_str()).collect();
            let cn: Vec<&str> = cols
                .iter()
                .map(|&j| model.coordinates[j].name.as_str())
                .collect();
            let pos = cols
                .first()
                .map(|&j| model.coordinates[j].pos)
                .unwrap_or_else(|| model.loops.first().map(|l| l.pos).unwrap_or_default());
            errors.push(DeriveError {
                pos,
                message: format!(
                    "with the outputs given, inverse kinematics is not well posed: the equations [{}] involve the \
                     coordinates [{}] ({} equations, {} unknowns); choose `outputs` so that every block is square",
                    rn.join(", "),
                    cn.join(", "),
                    rows.len(),
                    cols.len()
                ),
            });
        }
    }
    blocks
}
