//! The reference derivation: the same `f`, `G`, `gamma`, `M`, `psi` as [`crate::derive`], but
//! fully expanded into the coordinates with symbolica (how rbss generated code before it kept
//! named intermediates). Independent of the graph code path, it is what the tests compare the
//! generated kernels with; its expressions grow steeply with a chain's depth, so it is for
//! small models and tests only.
//!
//! Symbols: coordinate `i` is `q{i}`, its velocity `v{i}`; parameter `j` is `p{j}`; the
//! constant `pi` is `pi_`. Everything here must run on one thread, after
//! [`crate::lock::SymbolicaLock::acquire`].

// Matrix algebra over index pairs reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use symbolica::atom::{Atom, AtomCore, FunctionBuilder, Symbol};
use symbolica::{function, parse, symbol};

use crate::model::{Attachment, Axis, Expr, Func, LoopKind, Model, Side, Step};

/// The expanded results for one model.
pub struct Derivation {
    pub n: usize,
    pub m: usize,
    /// `f(X)`, length m.
    pub f: Vec<Atom>,
    /// `G = ∂f/∂X`, row-major.
    pub g: Vec<Vec<Atom>>,
    /// `gamma = -(dG/dt) Xdot`, length m.
    pub gamma: Vec<Atom>,
    /// `M` (n × n) and `psi` (n), when requested.
    pub dynamics: Option<(Vec<Vec<Atom>>, Vec<Atom>)>,
}

pub fn q(i: usize) -> Symbol {
    symbol!(&format!("q{i}"))
}
pub fn v(i: usize) -> Symbol {
    symbol!(&format!("v{i}"))
}
pub fn p(j: usize) -> Symbol {
    symbol!(&format!("p{j}"))
}
pub fn pi_sym() -> Symbol {
    symbol!("pi_")
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
        Expr::Call(f, args) => {
            let a = args.first().map_or_else(|| Atom::num(0), to_atom);
            let s = match f {
                Func::Sin => Symbol::SIN,
                Func::Cos => Symbol::COS,
                Func::Sqrt => Symbol::SQRT,
                Func::Tan => {
                    return function!(Symbol::SIN, a.clone()) / function!(Symbol::COS, a);
                }
                Func::Hypot => {
                    let b = args.get(1).map_or_else(|| Atom::num(0), to_atom);
                    return function!(Symbol::SQRT, a.clone() * a + b.clone() * b);
                }
                // Constants (the parser refuses coordinates in their arguments): symbols of
                // their own, whose derivatives in the coordinates are zero.
                Func::Exp | Func::Ln | Func::Atan2 | Func::Asin | Func::Acos | Func::Abs => {
                    let args: Vec<Atom> = args.iter().map(to_atom).collect();
                    let mut fun = FunctionBuilder::new(symbol!(f.name()));
                    for x in &args {
                        fun = fun.add_arg(x);
                    }
                    return fun.finish();
                }
            };
            function!(s, a)
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
            Step::Rotation(m) => {
                let rot: [[Atom; 3]; 3] =
                    std::array::from_fn(|i| std::array::from_fn(|j| to_atom(&m[i][j])));
                self.rotated(&rot)
            }
            Step::Quat(qe) => {
                // R(q / |q|): with s = 2 / |q|², R = 1 - s (...), as derive writes it.
                let [w, x, y, z]: [Atom; 4] = std::array::from_fn(|i| to_atom(&qe[i]));
                let nn = &w * &w + &x * &x + &y * &y + &z * &z;
                let s = Atom::num(2) / nn;
                let o = Atom::num(1);
                let rot: [[Atom; 3]; 3] = [
                    [
                        &o - &s * (&y * &y + &z * &z),
                        &s * (&x * &y - &w * &z),
                        &s * (&x * &z + &w * &y),
                    ],
                    [
                        &s * (&x * &y + &w * &z),
                        &o - &s * (&x * &x + &z * &z),
                        &s * (&y * &z - &w * &x),
                    ],
                    [
                        &s * (&x * &z - &w * &y),
                        &s * (&y * &z + &w * &x),
                        &o - &s * (&x * &x + &y * &y),
                    ],
                ];
                self.rotated(&rot)
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
                self.rotated(&rot)
            }
        }
    }

    /// `self` turned by the rotation matrix `rot` (post-multiplied).
    fn rotated(&self, rot: &[[Atom; 3]; 3]) -> Frame {
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

fn attachment_frame(frames: &[Frame], a: &Attachment) -> Frame {
    let mut fr = match a.body {
        Some(i) => frames[i].clone(),
        None => Frame::identity(),
    };
    for st in &a.steps {
        fr = fr.then(st);
    }
    fr
}

/// Runs the expanded derivation (with the dynamics when `with_dynamics`). The model must have
/// passed [`crate::derive::derive`], which reports what is ill-posed.
pub fn derive(model: &Model, with_dynamics: bool) -> Derivation {
    let n = model.coordinates.len();
    let frames = body_frames(model);
    let mut f = Vec::new();
    for lp in &model.loops {
        if let LoopKind::Coupling { a, b, poly } = &lp.kind {
            // a - Σ_k c_k b^k, the powers written out.
            let mut row = to_atom(a);
            let xb = b.as_ref().map(to_atom);
            let mut power = Atom::num(1);
            for (k, c) in poly.iter().enumerate() {
                let term = &to_atom(c) * &power;
                row = &row - &term;
                if let Some(xb) = &xb
                    && k + 1 < poly.len()
                {
                    power = &power * xb;
                }
            }
            f.push(simplify(&row));
            continue;
        }
        if let LoopKind::UnitNorm(qs) = &lp.kind {
            let mut qq = Atom::num(0);
            for &k in qs {
                qq += Atom::var(q(k)) * Atom::var(q(k));
            }
            f.push(simplify(&((qq - Atom::num(1)) * Atom::num((1, 2)))));
            continue;
        }
        let fa = attachment_frame(&frames, &lp.a);
        let fb = attachment_frame(&frames, &lp.b);
        let d: Vec<Atom> = (0..3).map(|i| &fa.p[i] - &fb.p[i]).collect();
        // The components along the frame's axes: column i of R_c · d.
        let along = |i: usize| -> Atom {
            match lp.frame {
                None => d[i].clone(),
                Some(side) => {
                    let r = if side == Side::A { &fa.r } else { &fb.r };
                    let mut t = Atom::num(0);
                    for k in 0..3 {
                        t += &r[k][i] * &d[k];
                    }
                    t
                }
            }
        };
        for axis in &lp.components {
            f.push(simplify(&along(axis.index())));
        }
        // E = R_aᵀ R_b.
        let e = |i: usize, j: usize| -> Atom {
            let mut t = Atom::num(0);
            for k in 0..3 {
                t += &fa.r[k][i] * &fb.r[k][j];
            }
            t
        };
        match &lp.kind {
            LoopKind::Weld => {
                // e = ½ (E_21 - E_12, E_02 - E_20, E_10 - E_01), as derive writes it.
                for (p, q) in [(2, 1), (0, 2), (1, 0)] {
                    f.push(simplify(&((e(p, q) - e(q, p)) * Atom::num((1, 2)))));
                }
            }
            LoopKind::Hinge(k) => {
                let k = k.index();
                for i in (0..3).filter(|&i| i != k) {
                    f.push(simplify(&e(i, k)));
                }
            }
            LoopKind::Distance(length) => {
                let l = to_atom(length);
                let mut dd = Atom::num(0);
                for di in &d {
                    dd += di * di;
                }
                f.push(simplify(&((dd - &l * &l) / (Atom::num(2) * &l))));
            }
            LoopKind::Point
            | LoopKind::Sliding
            | LoopKind::Coupling { .. }
            | LoopKind::UnitNorm(_) => {}
        }
    }
    let m = f.len();
    let mut g = vec![vec![Atom::num(0); n]; m];
    for (i, fi) in f.iter().enumerate() {
        for (j, gij) in g[i].iter_mut().enumerate() {
            if fi.contains_symbol(q(j)) {
                *gij = simplify(&fi.derivative(q(j)));
            }
        }
    }
    let mut gamma = Vec::with_capacity(m);
    for gi in &g {
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
    let dynamics = with_dynamics.then(|| dynamics(model, &frames));
    Derivation {
        n,
        m,
        f,
        g,
        gamma,
        dynamics,
    }
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
/// Christoffel terms of the first kind and the generalised gravity force (eq. 21). The joints'
/// forces: `M_kk += armature_k`, `Pi += ½ stiffness_k (q_k - rest_k)²`,
/// `psi_k -= damping_k v_k`.
fn dynamics(model: &Model, frames: &[Frame]) -> (Vec<Vec<Atom>>, Vec<Atom>) {
    let n = model.coordinates.len();
    let zero = Atom::num(0);
    let gravity: [Atom; 3] = std::array::from_fn(|a| to_atom(&model.gravity[a]));
    let mut mass = vec![vec![zero.clone(); n]; n];
    let mut potential = zero.clone();
    let vel: Vec<Atom> = (0..n).map(|j| Atom::var(v(j))).collect();

    for (b, body) in model.bodies.iter().enumerate() {
        let Some(mp) = &body.inertia else { continue };
        let m = to_atom(&mp.mass);
        let com: [Atom; 3] = std::array::from_fn(|a| to_atom(&mp.com[a]));
        let ie: [Atom; 6] = std::array::from_fn(|a| to_atom(&mp.inertia[a]));
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
    // The joints' own forces: armature on the diagonal of M, the springs' potential
    // ½ k (q - rest)² (their force comes from -∂Pi/∂X below), the dampers -c v after.
    for (i, c) in model.coordinates.iter().enumerate() {
        if let Some(a) = &c.forces.armature {
            let sum = &mass[i][i] + to_atom(a);
            mass[i][i] = sum;
        }
        if let Some(k) = &c.forces.stiffness {
            let mut dq = Atom::var(q(i));
            if let Some(r) = &c.forces.rest {
                dq -= to_atom(r);
            }
            potential += to_atom(k) * &dq * &dq / Atom::num(2);
        }
    }
    for i in 0..n {
        for j in i..n {
            let e = simplify(&mass[i][j]);
            mass[j][i] = e.clone();
            mass[i][j] = e;
        }
    }
    let potential = simplify(&potential);

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
            if let Some(c) = &model.coordinates[kk].forces.damping {
                acc += to_atom(c) * &vel[kk];
            }
            simplify(&(-acc))
        })
        .collect();

    (mass, psi)
}
