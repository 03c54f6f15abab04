//! `M` and `psi` recursively in world axes, with moments about the world origin (composite
//! inertias and subtree wrenches over the joints): no transport between frames, but every
//! quantity carries the rotations of all the frames above it (see `local.rs` for the
//! form in the joints' own frames).

use super::terms::{JointTerms, steiner};
use super::{Joint, add3, cross, dot, mat_vec, theta_coords};
use crate::graph::{Graph, Id};
use crate::model::Model;

/// A body's mass properties in world axes and the wrench its motion needs at `Xddot = 0`.
#[derive(Clone, Copy)]
pub struct Spatial {
    pub mass: Id,
    /// Centre of mass, world.
    pub com: [Id; 3],
    /// Rotational inertia about the centre of mass, world axes (`R I Rᵀ`).
    pub inertia: [[Id; 3]; 3],
    /// `(n_O, f)`: moment about the world origin and force, `m (a0_c - g)` and its moment
    /// plus `R (I alpha0 + omega × I omega)`.
    pub wrench: ([Id; 3], [Id; 3]),
}

/// The terms of a 3-vector, summed at the end.
type Terms3 = [Vec<Id>; 3];

/// `M` and `psi` by the recursive (composite-rigid-body and Newton-Euler) form, in world axes
/// with moments about the world origin, so no transport between frames is needed. A joint `s`
/// has the motion `S_s = (a, o × a)` (revolute, axis `a` through `o`) or `(0, a)` (prismatic).
/// With `W(b)` the wrench summed over the subtree of body `b` and `I^C(b)` its composite
/// inertia: `Q_s = S_s · W(body(s))`, `K_st = S_s · I^C(body(t)) S_t` for `s` at or above `t`,
/// and through `theta_s(X)`: `psi_k = -Σ_s ∂theta_s/∂X_k Q_s`,
/// `M_kl = Σ_st ∂theta_s/∂X_k ∂theta_t/∂X_l K_st`.
pub fn recursive(
    g: &mut Graph,
    model: &Model,
    joints: &[Joint],
    spatial: &[Option<Spatial>],
) -> (Vec<Vec<Id>>, Vec<Id>) {
    let n = model.coordinates.len();
    let nb = model.bodies.len();
    // Subtree sums, children before parents (a parent comes first in the model).
    let mut wrench: Vec<(Terms3, Terms3)> = vec![Default::default(); nb];
    // Composite inertia about the world origin: mass, first moment h = Σ m c,
    // J = Σ (R I Rᵀ + m (|c|² 1 - c cᵀ)).
    let mut mass: Vec<Vec<Id>> = vec![Vec::new(); nb];
    let mut first: Vec<[Vec<Id>; 3]> = vec![Default::default(); nb];
    let mut rot: Vec<[[Vec<Id>; 3]; 3]> = vec![Default::default(); nb];
    let mut sums_w: Vec<([Id; 3], [Id; 3])> = vec![([Graph::ZERO; 3], [Graph::ZERO; 3]); nb];
    let mut sums_i: Vec<(Id, [Id; 3], [[Id; 3]; 3])> =
        vec![(Graph::ZERO, [Graph::ZERO; 3], [[Graph::ZERO; 3]; 3]); nb];
    for bi in (0..nb).rev() {
        if let Some(sp) = &spatial[bi] {
            let (nw, fw) = sp.wrench;
            for i in 0..3 {
                wrench[bi].0[i].push(nw[i]);
                wrench[bi].1[i].push(fw[i]);
            }
            mass[bi].push(sp.mass);
            let c = sp.com;
            for i in 0..3 {
                let h = g.mul(sp.mass, c[i]);
                first[bi][i].push(h);
            }
            let point = steiner(g, sp.mass, &c);
            for i in 0..3 {
                for j in i..3 {
                    rot[bi][i][j].push(sp.inertia[i][j]);
                    rot[bi][i][j].push(point[i][j]);
                }
            }
        }
        let w = (
            std::array::from_fn(|i| g.sum(&wrench[bi].0[i])),
            std::array::from_fn(|i| g.sum(&wrench[bi].1[i])),
        );
        let m = g.sum(&mass[bi]);
        let h: [Id; 3] = std::array::from_fn(|i| g.sum(&first[bi][i]));
        let mut jm = [[Graph::ZERO; 3]; 3];
        for i in 0..3 {
            for j in i..3 {
                jm[i][j] = g.sum(&rot[bi][i][j]);
                jm[j][i] = jm[i][j];
            }
        }
        sums_w[bi] = w;
        sums_i[bi] = (m, h, jm);
        if let Some(p) = model.bodies[bi].parent {
            for i in 0..3 {
                wrench[p].0[i].push(w.0[i]);
                wrench[p].1[i].push(w.1[i]);
                first[p][i].push(h[i]);
                for j in i..3 {
                    rot[p][i][j].push(jm[i][j]);
                }
            }
            mass[p].push(m);
        }
    }
    // Joint motions S = (omega, v_O) and their coordinates.
    let motion: Vec<([Id; 3], [Id; 3])> = joints
        .iter()
        .map(|j| {
            if j.revolute {
                (j.axis, cross(g, &j.point, &j.axis))
            } else {
                ([Graph::ZERO; 3], j.axis)
            }
        })
        .collect();
    let coords: Vec<Vec<(usize, Id)>> =
        joints.iter().map(|j| theta_coords(g, j.theta, n)).collect();
    // s is at or above t: s's body is t's body (s first) or one of its ancestors.
    let above = |s: usize, t: usize| -> bool {
        let (bs, bt) = (joints[s].body, joints[t].body);
        if bs == bt {
            return s <= t;
        }
        let mut b = model.bodies[bt].parent;
        while let Some(x) = b {
            if x == bs {
                return true;
            }
            b = model.bodies[x].parent;
        }
        false
    };
    let mut terms = JointTerms::new(n);
    for (t, jt) in joints.iter().enumerate() {
        let (wt, vt) = motion[t];
        let (nw, fw) = sums_w[jt.body];
        let q = {
            let a = dot(g, &wt, &nw);
            let b = dot(g, &vt, &fw);
            g.add(a, b)
        };
        terms.force(g, &coords[t], q);
        // F = I^C S_t = (J omega + h × v, m v + omega × h)
        let (m, h, jm) = sums_i[jt.body];
        let jw = mat_vec(g, &jm, &wt);
        let hv = cross(g, &h, &vt);
        let fl = add3(g, &jw, &hv);
        let wh = cross(g, &wt, &h);
        let fp: [Id; 3] = std::array::from_fn(|i| {
            let mv = g.mul(m, vt[i]);
            g.add(mv, wh[i])
        });
        for s in 0..=t {
            if !above(s, t) {
                continue;
            }
            let (ws, vs) = motion[s];
            let e = {
                let a = dot(g, &ws, &fl);
                let b = dot(g, &vs, &fp);
                g.add(a, b)
            };
            terms.inertia(g, &coords[s], &coords[t], s == t, e);
        }
    }
    terms.sum(g)
}
