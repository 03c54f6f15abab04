//! `M` and `psi` recursively in the joints' own frames (Featherstone's composite-rigid-body and
//! Newton-Euler algorithms over the model's elementary steps).
//!
//! Every step of a body (`Rx(a)`, `Tz(s)`, ...) is a frame; a step whose argument moves is a
//! joint, whose motion in the frame just after it is a unit vector: `(e_k, 0)` for a rotation,
//! `(0, e_k)` for a translation. Composite inertias and subtree wrenches are carried from a
//! body's frame back through its steps to its parent's, one elementary transform at a time:
//! a rotation about a coordinate axis touches two components of a vector, a translation along
//! one only the moment. Nothing is expressed in world axes, so a subtree riding on a moving
//! body (the second stage of a stacked robot, the wrist of a hybrid machine) never carries its
//! carrier's rotation.
//!
//! With `I^C_t` the inertia of everything after joint `t` and `W_t` the wrench it needs at
//! `Xddot = 0` (both in the frame after `t`): `Q_s = S_s · W_s`, and `K_st = S_s · X*(I^C_t
//! S_t)` for `s` at or above `t` (the force `I^C_t S_t` carried back step by step to `s`). Then
//! through `theta_s(X)`: `psi_k = -Σ_s ∂theta_s/∂X_k Q_s`, `M_kl = Σ_st ∂theta_s/∂X_k
//! ∂theta_t/∂X_l K_st`.

use super::steps::Piece;
use super::terms::{JointTerms, steiner};
use super::{Builder, add3, cross, dot, mat_vec, rotation};
use crate::graph::{Graph, Id};
use crate::model::Axis;

/// A body's mass properties and the wrench its motion needs at `Xddot = 0`, body axes.
#[derive(Clone, Copy)]
pub struct BodyFrame {
    pub mass: Id,
    /// Centre of mass, body axes.
    pub com: [Id; 3],
    /// Rotational inertia about the centre of mass, body axes.
    pub inertia: [[Id; 3]; 3],
    /// `(n_O, f)`: moment about the body's origin and force, body axes.
    pub wrench: ([Id; 3], [Id; 3]),
}

/// A spatial inertia about a frame's origin, in its axes: mass, first moment `h = m c` and
/// `J = Σ (I + m (|c|² 1 - c cᵀ))` (symmetric, both triangles filled).
#[derive(Clone, Copy)]
struct Inertia {
    m: Id,
    h: [Id; 3],
    j: [[Id; 3]; 3],
}

/// A force pair `(n, f)`: moment about the frame's origin and force, in its axes.
type Force = ([Id; 3], [Id; 3]);

const NONE: Inertia = Inertia {
    m: Graph::ZERO,
    h: [Graph::ZERO; 3],
    j: [[Graph::ZERO; 3]; 3],
};

fn add_inertia(g: &mut Graph, a: &Inertia, b: &Inertia) -> Inertia {
    Inertia {
        m: g.add(a.m, b.m),
        h: add3(g, &a.h, &b.h),
        j: std::array::from_fn(|i| add3(g, &a.j[i], &b.j[i])),
    }
}

fn add_force(g: &mut Graph, a: &Force, b: &Force) -> Force {
    (add3(g, &a.0, &b.0), add3(g, &a.1, &b.1))
}

/// One elementary step, resolved: a rotation matrix `E` (parent components `= E ·` child
/// components) or a translation `s` along an axis.
#[derive(Clone, Copy)]
enum Elementary {
    Rot([[Id; 3]; 3]),
    Trans(Axis, Id),
}

/// The moment and force of `x` in the frame before the step (`x` is in the frame after it).
fn force_back(g: &mut Graph, st: &Elementary, x: &Force) -> Force {
    match *st {
        Elementary::Rot(e) => (mat_vec(g, &e, &x.0), mat_vec(g, &e, &x.1)),
        Elementary::Trans(axis, s) => {
            let mut d = [Graph::ZERO; 3];
            d[axis.index()] = s;
            let dxf = cross(g, &d, &x.1);
            (add3(g, &x.0, &dxf), x.1)
        }
    }
}

/// The inertia `a` (about the frame after the step) about the frame before it.
fn inertia_back(g: &mut Graph, st: &Elementary, a: &Inertia) -> Inertia {
    match *st {
        Elementary::Rot(e) => {
            // E J Eᵀ, upper triangle, mirrored.
            let ej: [[Id; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|l| {
                    let col = [a.j[0][l], a.j[1][l], a.j[2][l]];
                    dot(g, &e[i], &col)
                })
            });
            let mut j = [[Graph::ZERO; 3]; 3];
            for r in 0..3 {
                for c in r..3 {
                    j[r][c] = dot(g, &ej[r], &e[c]);
                    j[c][r] = j[r][c];
                }
            }
            Inertia {
                m: a.m,
                h: mat_vec(g, &e, &a.h),
                j,
            }
        }
        Elementary::Trans(axis, s) => {
            // Origin moved by d = s e_k: h' = h + m d,
            // J' = J + m (|d|² 1 - d dᵀ) + 2 (d · h) 1 - d hᵀ - h dᵀ.
            let k = axis.index();
            let mut h = a.h;
            let ms = g.mul(a.m, s);
            h[k] = g.add(h[k], ms);
            let mss = g.mul(ms, s);
            let sh: [Id; 3] = std::array::from_fn(|i| g.mul(s, a.h[i]));
            let two = g.int(2);
            let two_shk = g.mul(two, sh[k]);
            let mut j = a.j;
            for r in 0..3 {
                for c in r..3 {
                    let mut terms = vec![a.j[r][c]];
                    if r == c {
                        if r != k {
                            terms.push(mss);
                        }
                        terms.push(two_shk);
                    }
                    if r == k {
                        terms.push(g.neg(sh[c]));
                    }
                    if c == k {
                        terms.push(g.neg(sh[r]));
                    }
                    j[r][c] = g.sum(&terms);
                    j[c][r] = j[r][c];
                }
            }
            Inertia { m: a.m, h, j }
        }
    }
}

/// `I^C S` for the unit motion of a joint about or along `axis`: `(J e_k, e_k × h)` for a
/// rotation, `(h × e_k, m e_k)` for a translation.
fn momentum(g: &mut Graph, a: &Inertia, axis: Axis, revolute: bool) -> Force {
    let k = axis.index();
    let mut e = [Graph::ZERO; 3];
    e[k] = Graph::ONE;
    if revolute {
        ([a.j[0][k], a.j[1][k], a.j[2][k]], cross(g, &e, &a.h))
    } else {
        let mut f = [Graph::ZERO; 3];
        f[k] = a.m;
        (cross(g, &a.h, &e), f)
    }
}

/// `S · x` for the unit motion of a joint: the moment's or the force's `axis` component.
fn project(x: &Force, axis: Axis, revolute: bool) -> Id {
    if revolute {
        x.0[axis.index()]
    } else {
        x.1[axis.index()]
    }
}

/// A step of the tree: its body, its transform, and the joint it is (when it moves).
struct Node {
    elementary: Elementary,
    axis: Axis,
    revolute: bool,
    /// `(k, ∂theta/∂X_k)` when the step's argument depends on the coordinates.
    coords: Vec<(usize, Id)>,
    /// The step before this one (in this body or an ancestor), none at the world.
    prev: Option<usize>,
}

/// `M` (upper triangle) and `psi` in the joints' own frames; `bodies[b]` is `None` for a
/// massless frame.
pub fn local(b: &mut Builder, bodies: &[Option<BodyFrame>]) -> (Vec<Vec<Id>>, Vec<Id>) {
    let model = b.model;
    let n = model.coordinates.len();
    let nb = model.bodies.len();
    // The steps, body after body; `last[b]`: the last step at or above body b's frame.
    let mut nodes: Vec<Node> = Vec::new();
    let mut first: Vec<usize> = Vec::with_capacity(nb);
    let mut last: Vec<Option<usize>> = Vec::with_capacity(nb);
    for (bi, body) in model.bodies.iter().enumerate() {
        let mut prev = body.parent.and_then(|p| last[p]);
        first.push(nodes.len());
        let pieces = b.body_pieces[bi].clone();
        for piece in &pieces {
            let (axis, theta, revolute) = match *piece {
                Piece::Rot(a, t) => (a, t, true),
                Piece::Trans(a, t) => (a, t, false),
                // A constant rotation: a frame, never a joint.
                Piece::Matrix(_) => (Axis::X, Graph::ZERO, true),
                Piece::Quat(_) => unreachable!("a model with a `free` joint has no recursive form"),
            };
            let g = &mut b.g;
            let elementary = match *piece {
                Piece::Matrix(r) => Elementary::Rot(r),
                _ if revolute => {
                    let (c, s) = (g.cos(theta), g.sin(theta));
                    Elementary::Rot(rotation(g, axis, c, s))
                }
                _ => Elementary::Trans(axis, theta),
            };
            let coords = if g.is_const(theta) {
                Vec::new()
            } else {
                super::theta_coords(g, theta, n)
            };
            nodes.push(Node {
                elementary,
                axis,
                revolute,
                coords,
                prev,
            });
            prev = Some(nodes.len() - 1);
        }
        last.push(prev);
    }

    // Backward: composite inertia and subtree wrench after every step, children before parents
    // (a parent comes first in the model).
    let g = &mut b.g;
    let mut at_body: Vec<(Inertia, Force)> = vec![(NONE, ([Graph::ZERO; 3], [Graph::ZERO; 3])); nb];
    let mut after: Vec<(Inertia, Force)> =
        vec![(NONE, ([Graph::ZERO; 3], [Graph::ZERO; 3])); nodes.len()];
    for bi in (0..nb).rev() {
        let (mut ic, mut w) = at_body[bi];
        if let Some(bf) = &bodies[bi] {
            let c = bf.com;
            let h: [Id; 3] = std::array::from_fn(|i| g.mul(bf.mass, c[i]));
            // J = I + m (|c|² 1 - c cᵀ)
            let point = steiner(g, bf.mass, &c);
            let j: [[Id; 3]; 3] = std::array::from_fn(|r| add3(g, &bf.inertia[r], &point[r]));
            let own = Inertia { m: bf.mass, h, j };
            ic = add_inertia(g, &ic, &own);
            w = add_force(g, &w, &bf.wrench);
        }
        let steps = first[bi]..first[bi] + b.body_pieces[bi].len();
        for s in steps.rev() {
            after[s] = (ic, w);
            let st = nodes[s].elementary;
            ic = inertia_back(g, &st, &ic);
            w = force_back(g, &st, &w);
        }
        if let Some(p) = model.bodies[bi].parent {
            let (pi, pw) = at_body[p];
            at_body[p] = (add_inertia(g, &pi, &ic), add_force(g, &pw, &w));
        }
    }

    // psi_k = -Σ_s ∂theta_s/∂X_k (S_s · W_s);
    // M_kl = Σ_st ∂theta_s/∂X_k ∂theta_t/∂X_l K_st, K_st = S_s · (I^C_t S_t carried back to s).
    let mut terms = JointTerms::new(n);
    for t in 0..nodes.len() {
        if nodes[t].coords.is_empty() {
            continue;
        }
        let (ic, w) = after[t];
        let q = project(&w, nodes[t].axis, nodes[t].revolute);
        terms.force(g, &nodes[t].coords, q);
        let mut force = momentum(g, &ic, nodes[t].axis, nodes[t].revolute);
        let mut s = t;
        loop {
            if !nodes[s].coords.is_empty() {
                let e = project(&force, nodes[s].axis, nodes[s].revolute);
                terms.inertia(g, &nodes[s].coords, &nodes[t].coords, s == t, e);
            }
            let Some(p) = nodes[s].prev else { break };
            force = force_back(g, &nodes[s].elementary, &force);
            s = p;
        }
    }
    terms.sum(g)
}
