//! Symbolic derivation with symbolica: frames, loop closure `f(X)`, `G = ∂f/∂X`, `gamma`.
//!
//! Symbols: coordinate `i` is `q{i}`, its velocity `v{i}`; parameter `j` is `p{j}`; the
//! constant `pi` is `pi_`. After simplification every `sin`/`cos` of a constant (parameter-only)
//! angle is replaced by a derived constant `k{l}` that the generated `Params::consts` computes
//! once, so kernels evaluate no trigonometry of parameters.
//!
//! Everything here must run on one thread, after [`crate::lock::SymbolicaLock::acquire`].

// Matrix algebra over index pairs reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

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
    /// A mass property or gravity component given as a parameter expression (e.g. `rho*pi*r^2*L`).
    Value(Expr, String),
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
    /// World frames of every body `(R, p)`, with constants substituted.
    pub frames: Vec<Frame>,
    /// The dynamics, when requested.
    pub dynamics: Option<Dynamics>,
}

/// The symbolic dynamics: `M(X)`, `psi(X, Xdot)`, the energies.
pub struct Dynamics {
    /// `M = ∂²T/∂Xdot²` (n × n, symmetric); zero atoms are structural zeros.
    pub mass: Vec<Vec<Atom>>,
    /// `psi = -(Christoffel terms) - ∂Pi/∂X` (n).
    pub psi: Vec<Atom>,
    /// Kinetic energy `T(X, Xdot)`, assembled from the bodies' velocities (not from `M`).
    pub kinetic: Atom,
    /// Potential energy `Pi(X)` of gravity.
    pub potential: Atom,
    /// Diagonal blocks of `M`: groups of coordinates coupled by inertia (ascending).
    pub mass_blocks: Vec<Vec<usize>>,
}

/// An error found during derivation (the model parses but is not well posed).
#[derive(Debug, Clone)]
pub struct DeriveError {
    pub pos: crate::model::Pos,
    pub message: String,
}

/// Symbols per family created up front by [`canonical_symbols`].
const CANONICAL: usize = 1024;

/// Creates every symbol codegen uses, in one fixed order, once per process.
///
/// symbolica orders the terms of an expression by symbol, and symbols by creation: without
/// this, a process that derived another model first (`rbss-codegen --all`, the freshness test)
/// would create this model's symbols in another order and emit different (equally correct)
/// code. Models with more than 1024 coordinates, parameters or constants stay correct but may
/// lose that byte-for-byte reproducibility.
pub fn canonical_symbols() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = pi_sym();
        let _ = parse!("sin(x_)^2");
        for i in 0..CANONICAL {
            let _ = symbol!(&format!("q{i}"));
        }
        for i in 0..CANONICAL {
            let _ = symbol!(&format!("v{i}"));
        }
        for i in 0..CANONICAL {
            let _ = symbol!(&format!("p{i}"));
        }
        for i in 0..CANONICAL {
            let _ = symbol!(&format!("k{i}"));
        }
    });
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

    /// The atom for a parameter expression of a mass property: an exact number when it uses
    /// no parameter, otherwise a new constant `k{l}` computed in `Params::consts`.
    fn value(&mut self, e: &Expr, what: &str) -> Atom {
        if !mentions_param(e) {
            return to_atom(e);
        }
        if let Expr::Param(j) = e {
            return Atom::var(p(*j));
        }
        if let Some(l) = self
            .defs
            .iter()
            .position(|d| matches!(d, ConstDef::Value(x, _) if x == e))
        {
            return Atom::var(k(l));
        }
        let l = self.defs.len();
        self.defs.push(ConstDef::Value(e.clone(), what.to_string()));
        Atom::var(k(l))
    }

    fn apply(&self, a: &Atom) -> Atom {
        let mut out = a.clone();
        for (pat, rep) in &self.subs {
            out = out.replace(pat.to_pattern()).with(rep.to_pattern());
        }
        out
    }
}

fn mentions_param(e: &Expr) -> bool {
    match e {
        Expr::Param(_) => true,
        Expr::Num { .. } | Expr::Pi | Expr::Coord(_) => false,
        Expr::Neg(a) | Expr::Call(_, a) => mentions_param(a),
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            mentions_param(a) || mentions_param(b)
        }
    }
}

/// Symbol for const slot `l`: parameters keep their `p{j}` symbol, pi is `pi_`, others `k{l}`.
pub fn const_symbol(defs: &[ConstDef], l: usize) -> Symbol {
    match defs[l] {
        ConstDef::Param(j) => p(j),
        ConstDef::Pi => pi_sym(),
        ConstDef::Call(..) | ConstDef::Value(..) => k(l),
    }
}

/// Runs the derivation (kinematics, and the dynamics when `with_dynamics`). `progress`
/// receives one line per stage.
pub fn derive(
    model: &Model,
    with_dynamics: bool,
    progress: &mut dyn FnMut(&str),
) -> Result<Derivation, Vec<DeriveError>> {
    canonical_symbols();
    let n = model.coordinates.len();
    let mut table = ConstTable::new(model);

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

    let dynamics = if with_dynamics {
        Some(dynamics(model, &frames, &mut table, progress))
    } else {
        None
    };
    let frames = frames
        .iter()
        .map(|fr| Frame {
            r: std::array::from_fn(|i| std::array::from_fn(|j| table.apply(&fr.r[i][j]))),
            p: std::array::from_fn(|i| table.apply(&fr.p[i])),
        })
        .collect();
    let dynamics = dynamics.map(|d| Dynamics {
        mass: d
            .mass
            .iter()
            .map(|row| row.iter().map(|a| table.apply(a)).collect())
            .collect(),
        psi: d.psi.iter().map(|a| table.apply(a)).collect(),
        kinetic: table.apply(&d.kinetic),
        potential: table.apply(&d.potential),
        mass_blocks: d.mass_blocks,
    });
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
        frames,
        dynamics,
    })
}

/// `vee` of a skew-symmetric 3 × 3 matrix: `(S[2][1], S[0][2], S[1][0])`.
fn vee(s: &[[Atom; 3]; 3]) -> [Atom; 3] {
    [s[2][1].clone(), s[0][2].clone(), s[1][0].clone()]
}

/// `M`, `psi` and the energies from the bodies' mass properties (paper section 3).
///
/// Per body b with world frame `(R, p)`, mass `m`, centre of mass `c` (body frame) and inertia
/// `I` about it (body axes): `r = p + R c`, `J_r = ∂r/∂X`, body angular velocity
/// `omega = J_w Xdot` with column j of `J_w` = `vee(R^T ∂R/∂X_j)` (eq. 28). Then
/// `T = Σ ½ m |J_r Xdot|² + ½ omegaᵀ I omega`, `M = ∂²T/∂Xdot² = Σ m J_rᵀ J_r + J_wᵀ I J_w`
/// (eq. 25, the exact closed form of the second derivative), `Pi = -Σ m gᵀ r`, and
/// `psi_k = -(Σ_j ∂(M Xdot)_k/∂X_j Xdot_j - ½ ∂(Xdotᵀ M Xdot)/∂X_k) - ∂Pi/∂X_k`, i.e. minus the
/// Christoffel terms of the first kind and the generalised gravity force (eq. 21).
fn dynamics(
    model: &Model,
    frames: &[Frame],
    table: &mut ConstTable,
    progress: &mut dyn FnMut(&str),
) -> Dynamics {
    let n = model.coordinates.len();
    let zero = Atom::num(0);
    let gravity: [Atom; 3] =
        std::array::from_fn(|a| table.value(&model.gravity[a], &format!("gravity[{a}]")));
    let mut mass = vec![vec![zero.clone(); n]; n];
    let mut kinetic = zero.clone();
    let mut potential = zero.clone();
    let vel: Vec<Atom> = (0..n).map(|j| Atom::var(v(j))).collect();

    for (b, body) in model.bodies.iter().enumerate() {
        let Some(mp) = &body.inertia else { continue };
        progress(&format!("kinetic energy of `{}`", body.name));
        let m = table.value(&mp.mass, &format!("mass of {}", body.name));
        let com: [Atom; 3] =
            std::array::from_fn(|a| table.value(&mp.com[a], &format!("com[{a}] of {}", body.name)));
        let names = ["Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz"];
        let ie: [Atom; 6] = std::array::from_fn(|a| {
            table.value(&mp.inertia[a], &format!("{} of {}", names[a], body.name))
        });
        let inertia = [
            [ie[0].clone(), ie[3].clone(), ie[4].clone()],
            [ie[3].clone(), ie[1].clone(), ie[5].clone()],
            [ie[4].clone(), ie[5].clone(), ie[2].clone()],
        ];
        let fr = &frames[b];
        let r: [Atom; 3] = std::array::from_fn(|i| {
            let mut acc = fr.p[i].clone();
            for (l, cl) in com.iter().enumerate() {
                if !cl.is_zero() {
                    acc += &fr.r[i][l] * cl;
                }
            }
            acc.expand()
        });
        // Coordinates this body depends on.
        let deps: Vec<usize> = (0..n)
            .filter(|&j| {
                r.iter().any(|a| a.contains_symbol(q(j)))
                    || fr.r.iter().flatten().any(|a| a.contains_symbol(q(j)))
            })
            .collect();
        let mut jr: Vec<[Atom; 3]> = Vec::new();
        let mut jw: Vec<[Atom; 3]> = Vec::new();
        for &j in &deps {
            jr.push(std::array::from_fn(|i| simplify(&r[i].derivative(q(j)))));
            let dr: [[Atom; 3]; 3] =
                std::array::from_fn(|i| std::array::from_fn(|l| fr.r[i][l].derivative(q(j))));
            // S = R^T dR
            let s: [[Atom; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|l| {
                    let mut acc = Atom::num(0);
                    for a in 0..3 {
                        if !fr.r[a][i].is_zero() && !dr[a][l].is_zero() {
                            acc += &fr.r[a][i] * &dr[a][l];
                        }
                    }
                    acc
                })
            });
            jw.push(vee(&s).map(|a| simplify(&a)));
        }
        // Body velocities, for T.
        let vr: [Atom; 3] = std::array::from_fn(|i| {
            let mut acc = Atom::num(0);
            for (c, &j) in deps.iter().enumerate() {
                acc += &jr[c][i] * &vel[j];
            }
            acc
        });
        let w: [Atom; 3] = std::array::from_fn(|i| {
            let mut acc = Atom::num(0);
            for (c, &j) in deps.iter().enumerate() {
                acc += &jw[c][i] * &vel[j];
            }
            acc
        });
        let mut t_b = &m * (&vr[0] * &vr[0] + &vr[1] * &vr[1] + &vr[2] * &vr[2]);
        for a in 0..3 {
            for c in 0..3 {
                if !inertia[a][c].is_zero() {
                    t_b += &w[a] * &inertia[a][c] * &w[c];
                }
            }
        }
        kinetic += t_b / Atom::num(2);
        for a in 0..3 {
            if !gravity[a].is_zero() {
                potential -= &m * &gravity[a] * &r[a];
            }
        }
        // M_b = m J_rᵀ J_r + J_wᵀ I J_w on the rows/cols `deps`.
        for (ci, &i) in deps.iter().enumerate() {
            for (cj, &j) in deps.iter().enumerate().skip(ci) {
                let mut acc = Atom::num(0);
                for a in 0..3 {
                    if !jr[ci][a].is_zero() && !jr[cj][a].is_zero() {
                        acc += &m * &jr[ci][a] * &jr[cj][a];
                    }
                    for c in 0..3 {
                        if !jw[ci][a].is_zero() && !inertia[a][c].is_zero() && !jw[cj][c].is_zero()
                        {
                            acc += &jw[ci][a] * &inertia[a][c] * &jw[cj][c];
                        }
                    }
                }
                let sum = &mass[i][j] + acc;
                mass[i][j] = sum;
            }
        }
    }
    progress("mass matrix M");
    for i in 0..n {
        for j in i..n {
            let e = simplify(&mass[i][j]);
            mass[j][i] = e.clone();
            mass[i][j] = e;
        }
    }
    let kinetic = simplify(&kinetic);
    let potential = simplify(&potential);

    progress("psi: Christoffel terms and gravity");
    // (M Xdot)_k and ½ Xdotᵀ M Xdot
    let mv: Vec<Atom> = (0..n)
        .map(|kk| {
            let mut acc = Atom::num(0);
            for j in 0..n {
                if !mass[kk][j].is_zero() {
                    acc += &mass[kk][j] * &vel[j];
                }
            }
            acc
        })
        .collect();
    let mut quad = Atom::num(0);
    for (kk, mvk) in mv.iter().enumerate() {
        if !mvk.is_zero() {
            quad += mvk * &vel[kk];
        }
    }
    let quad = quad / Atom::num(2);
    let psi: Vec<Atom> = (0..n)
        .map(|kk| {
            let mut acc = Atom::num(0);
            for j in 0..n {
                if mv[kk].contains_symbol(q(j)) {
                    acc += mv[kk].derivative(q(j)) * &vel[j];
                }
            }
            if quad.contains_symbol(q(kk)) {
                acc -= quad.derivative(q(kk));
            }
            if potential.contains_symbol(q(kk)) {
                acc += potential.derivative(q(kk));
            }
            simplify(&(-acc))
        })
        .collect();

    // Diagonal blocks of M: connected components of its sparsity.
    let mut comp: Vec<usize> = (0..n).collect();
    fn root(c: &mut [usize], mut x: usize) -> usize {
        while c[x] != x {
            c[x] = c[c[x]];
            x = c[x];
        }
        x
    }
    for i in 0..n {
        for j in 0..n {
            if !mass[i][j].is_zero() {
                let (a, b) = (root(&mut comp, i), root(&mut comp, j));
                if a != b {
                    comp[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut blocks: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for i in 0..n {
        let r = root(&mut comp, i);
        blocks.entry(r).or_default().push(i);
    }
    Dynamics {
        mass,
        psi,
        kinetic,
        potential,
        mass_blocks: blocks.into_values().collect(),
    }
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
