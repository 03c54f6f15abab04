//! The loop closure `f(X)`, row by row for each kind of loop (see `docs/model-format.md`):
//!
//! - a point component: `origin(a) - origin(b)` along a world axis, or along an axis of the
//!   frame of `a` or `b` (`frame`): `(R_cᵀ (p_a - p_b))_k`;
//! - a weld's rotation: the axial vector of the skew part of `E = R_aᵀ R_b`;
//! - a hinge's axis: `E_ik` for the two axes `i` other than the hinge axis `k` (axis `k` of `b`
//!   has no component along the other axes of `a`);
//! - a distance: `(|d|² - L²) / (2 L)`, `d = p_a - p_b` (metres, `|d| - L` to first order);
//! - a coupling: `a - p(b)`, `p(b) = c0 + c1 b + c2 b² + …` (`ratio b + offset`), `a` and `b`
//!   expressions of the coordinates.
//!
//! What the equations leave open is checked after every position solve (`checks`): a point's
//! components left out (not for `point_in_plane` / `point_on_line`, whose other components are
//! free), a weld's half-turn (`3 - trace E`), a hinge's reversed axis (`1 - E_kk`).

use super::*;
use crate::model::{LoopKind, Side};

/// The rows of `f` with what `G` and `gamma` need of them.
pub(super) struct Rows {
    pub f: Vec<Id>,
    /// `loop.component`.
    pub names: Vec<String>,
    /// Per row: the two loop points with the joints that move them (for G by screws).
    pub ends: Vec<[([Id; 3], Vec<Joint>); 2]>,
    /// Per row: the two loop points' world accelerations at Xddot = 0, through their body-axes
    /// velocities, `R (d/dt v + omega × v)` (for gamma).
    pub accelerations: Vec<[[Id; 3]; 2]>,
    /// Per row: the world axis of a point component (G by screws, gamma through the points'
    /// accelerations), or `None` (G by the chain rule).
    pub axis: Vec<Option<usize>>,
    /// Per row without an axis: a third way to its gamma (through the frames' velocities).
    pub gamma_w: Vec<Option<Id>>,
    pub checks: Vec<Id>,
    pub check_names: Vec<String>,
}

impl Rows {
    fn push(&mut self, f: Id, name: String, ends: &[([Id; 3], Vec<Joint>); 2], acc: [[Id; 3]; 2]) {
        self.f.push(f);
        self.names.push(name);
        self.ends.push(ends.clone());
        self.accelerations.push(acc);
        self.axis.push(None);
        self.gamma_w.push(None);
    }
}

/// One attachment, built: its frame and velocities, and the joints that move its origin.
struct End {
    cur: Moving,
    path: Vec<Joint>,
    /// World acceleration of the origin at Xddot = 0.
    acc: [Id; 3],
    /// The rate of the body-axes angular velocity at Xddot = 0 (for a relative rotation).
    alpha: [Id; 3],
}

fn end(
    b: &mut Builder,
    moving: &[Moving],
    joints: &[Joint],
    a: &Attachment,
    rotation: bool,
) -> End {
    let model = b.model;
    let start = match a.body {
        Some(i) => moving[i],
        None => world(),
    };
    // The joints of the attachment's body and its ancestors, then of its own steps.
    let mut path: Vec<Joint> = Vec::new();
    let mut body = a.body;
    while let Some(x) = body {
        path.extend(joints.iter().filter(|j| j.body == x));
        body = model.bodies[x].parent;
    }
    let mut cur = start;
    for pc in &b.pieces(&cur, &a.steps) {
        if let Some(j) = b.joint(&cur, pc, usize::MAX) {
            path.push(j);
        }
        cur = b.apply(&cur, pc);
    }
    let vdot: [Id; 3] = std::array::from_fn(|i| b.g.diff(cur.vel[i], Seed::Time));
    let wv = cross(&mut b.g, &cur.omega, &cur.vel);
    let a_b = add3(&mut b.g, &vdot, &wv);
    let acc = mat_vec(&mut b.g, &cur.frame.r, &a_b);
    let alpha = if rotation {
        std::array::from_fn(|i| b.g.diff(cur.omega[i], Seed::Time))
    } else {
        [Graph::ZERO; 3]
    };
    End {
        cur,
        path,
        acc,
        alpha,
    }
}

/// `E = R_aᵀ R_b` (`E_ij` = column i of `R_a` · column j of `R_b`) and, at Xddot = 0, its second
/// time derivative through the frames' body-axes angular velocities: with `R' = R [Omega]x`,
/// `E' = -A E + E B` and `E'' = -A' E + A A E - 2 A E B + E B B + E B'`, where `A = [Omega_a]x`,
/// `B = [Omega_b]x`, `A' = [alpha_a]x`, `B' = [alpha_b]x` (the omegas are shared with psi).
fn relative_rotation(g: &mut Graph, ends: &[End; 2]) -> ([[Id; 3]; 3], [[Id; 3]; 3]) {
    let (ra, rb) = (&ends[0].cur.frame.r, &ends[1].cur.frame.r);
    let mut e = [[Graph::ZERO; 3]; 3];
    for (i, row) in e.iter_mut().enumerate() {
        for (j, eij) in row.iter_mut().enumerate() {
            let terms: Vec<Id> = (0..3).map(|k| g.mul(ra[k][i], rb[k][j])).collect();
            *eij = g.sum(&terms);
        }
    }
    let [wa, wb] = [ends[0].cur.omega, ends[1].cur.omega];
    let (aa, ab) = (ends[0].alpha, ends[1].alpha);
    let (sa, sb) = (skew(g, &wa), skew(g, &wb));
    let (da, db) = (skew(g, &aa), skew(g, &ab));
    let ae = mat_mul(g, &sa, &e);
    let aae = mat_mul(g, &sa, &ae);
    let aeb = mat_mul(g, &ae, &sb);
    let eb = mat_mul(g, &e, &sb);
    let ebb = mat_mul(g, &eb, &sb);
    let dae = mat_mul(g, &da, &e);
    let edb = mat_mul(g, &e, &db);
    let two = g.int(2);
    let mut edd = [[Graph::ZERO; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let twice = g.mul(two, aeb[i][j]);
            let plus = g.sum(&[aae[i][j], ebb[i][j], edb[i][j]]);
            let minus = g.add(dae[i][j], twice);
            edd[i][j] = g.sub(plus, minus);
        }
    }
    (e, edd)
}

/// The rows of every loop (see the module documentation), or what makes a loop ill-posed.
pub(super) fn closure(
    b: &mut Builder,
    moving: &[Moving],
    joints: &[Joint],
) -> Result<Rows, Vec<DeriveError>> {
    let model = b.model;
    let mut rows = Rows {
        f: Vec::new(),
        names: Vec::new(),
        ends: Vec::new(),
        accelerations: Vec::new(),
        axis: Vec::new(),
        gamma_w: Vec::new(),
        checks: Vec::new(),
        check_names: Vec::new(),
    };
    let mut errors = Vec::new();
    let mut constant = |g: &Graph, e: Id, lp: &crate::model::Loop, what: &str| {
        let point = what.starts_with("component");
        let message = match (g.is_zero(e), g.is_const(e), point) {
            (true, _, true) => format!(
                "loop `{}`: {what} of origin(a) - origin(b) is identically zero, so it \
                 constrains nothing; remove it from `components` or check the two attachments",
                lp.name
            ),
            (false, true, true) => format!(
                "loop `{}`: {what} does not depend on any coordinate, so the loop cannot close",
                lp.name
            ),
            (_, true, false) => format!(
                "loop `{}`: {what} does not depend on any coordinate, so it constrains nothing \
                 or cannot close; check the two attachments",
                lp.name
            ),
            _ => return,
        };
        errors.push(DeriveError {
            pos: lp.pos,
            message,
        });
    };
    let zero3 = [Graph::ZERO; 3];
    for lp in &model.loops {
        if let LoopKind::Coupling { a, b: side_b, poly } = &lp.kind {
            // a - p(b), p by Horner's rule from the highest coefficient down (`ratio * b +
            // offset` for a linear coupling); G and gamma follow by the chain rule (gamma =
            // p''(b) ḃ² + p'(b) (b̈ at Xddot = 0) - (ä at Xddot = 0)).
            let xa = b.expr(a);
            let xb = side_b.as_ref().map(|e| b.expr(e));
            let coefs: Vec<Id> = poly.iter().rev().map(|c| b.expr(c)).collect();
            let mut rhs = coefs[0];
            if let Some(xb) = xb {
                for &c in &coefs[1..] {
                    let px = b.g.mul(rhs, xb);
                    rhs = b.g.add(px, c);
                }
            }
            let e = b.g.sub(xa, rhs);
            constant(&b.g, e, lp, "the coupling");
            let none = [(zero3, Vec::new()), (zero3, Vec::new())];
            rows.push(e, format!("{}.coupling", lp.name), &none, [zero3; 2]);
            continue;
        }
        if let LoopKind::UnitNorm(q) = &lp.kind {
            // (qᵀq - 1) / 2: its gradient is qᵀ (unit length on the constraint).
            let terms: Vec<Id> = q
                .iter()
                .map(|&k| {
                    let x = b.g.x(k);
                    b.g.mul(x, x)
                })
                .collect();
            let qq = b.g.sum(&terms);
            let d = b.g.sub(qq, Graph::ONE);
            let half = b.g.num(crate::graph::Rat::new(1, 2).expect("1/2"));
            let e = b.g.mul(half, d);
            let none = [(zero3, Vec::new()), (zero3, Vec::new())];
            rows.push(e, format!("{}.norm", lp.name), &none, [zero3; 2]);
            continue;
        }
        let rotation = matches!(lp.kind, LoopKind::Weld | LoopKind::Hinge(_)) || lp.frame.is_some();
        let ends = [
            end(b, moving, joints, &lp.a, rotation),
            end(b, moving, joints, &lp.b, rotation),
        ];
        let pts: [([Id; 3], Vec<Joint>); 2] = [
            (ends[0].cur.frame.p, ends[0].path.clone()),
            (ends[1].cur.frame.p, ends[1].path.clone()),
        ];
        let acc = [ends[0].acc, ends[1].acc];
        let d: [Id; 3] = std::array::from_fn(|i| b.g.sub(pts[0].0[i], pts[1].0[i]));
        // The point components along the frame's axes.
        let along: [Id; 3] = match lp.frame {
            None => d,
            Some(side) => {
                let r = ends[usize::from(side == Side::B)].cur.frame.r;
                mat_t_vec(&mut b.g, &r, &d)
            }
        };
        // In a moving frame c, a third way to gamma through the frames' velocities: with
        // u = R_cᵀ d and omega, alpha the body-axes angular velocity of c and its rate,
        // u' = R_cᵀ d' - omega × u and u'' = R_cᵀ d'' - alpha × u - omega × (u' + R_cᵀ d').
        let frame_gamma: Option<[Id; 3]> = lp.frame.map(|side| {
            let c = &ends[usize::from(side == Side::B)];
            let (r, w, al) = (c.cur.frame.r, c.cur.omega, c.alpha);
            let g = &mut b.g;
            let va = mat_vec(g, &ends[0].cur.frame.r, &ends[0].cur.vel);
            let vb = mat_vec(g, &ends[1].cur.frame.r, &ends[1].cur.vel);
            let dv: [Id; 3] = std::array::from_fn(|i| g.sub(va[i], vb[i]));
            let da: [Id; 3] = std::array::from_fn(|i| g.sub(acc[0][i], acc[1][i]));
            let dv_c = mat_t_vec(g, &r, &dv);
            let da_c = mat_t_vec(g, &r, &da);
            let wu = cross(g, &w, &along);
            let u_dot: [Id; 3] = std::array::from_fn(|i| g.sub(dv_c[i], wu[i]));
            let both = add3(g, &u_dot, &dv_c);
            let w_both = cross(g, &w, &both);
            let al_u = cross(g, &al, &along);
            std::array::from_fn(|i| {
                let minus = g.add(al_u[i], w_both[i]);
                let u_dd = g.sub(da_c[i], minus);
                g.neg(u_dd)
            })
        });
        for axis in &lp.components {
            let i = axis.index();
            let e = along[i];
            let what = format!("component `{}`", axis.name());
            constant(&b.g, e, lp, &what);
            rows.push(e, format!("{}.{}", lp.name, axis.name()), &pts, acc);
            match frame_gamma {
                None => *rows.axis.last_mut().expect("a row") = Some(i),
                Some(gam) => *rows.gamma_w.last_mut().expect("a row") = Some(gam[i]),
            }
        }
        match &lp.kind {
            LoopKind::Weld => {
                // e = ½ (E_21 - E_12, E_02 - E_20, E_10 - E_01) = sin(angle) · axis (in frame a,
                // rad for small angles). They vanish at a rotation by pi too: `3 - trace E` (0 at
                // the identity, 4 there) is the loop's closure check.
                let (e, edd) = relative_rotation(&mut b.g, &ends);
                let half = b.g.num(crate::graph::Rat::new(1, 2).expect("1/2"));
                for (axis, (p, q)) in ["rx", "ry", "rz"].into_iter().zip([(2, 1), (0, 2), (1, 0)]) {
                    let dpq = b.g.sub(e[p][q], e[q][p]);
                    let row = b.g.mul(half, dpq);
                    constant(&b.g, row, lp, &format!("rotation component `{axis}`"));
                    rows.push(row, format!("{}.{axis}", lp.name), &pts, acc);
                    let dd = b.g.sub(edd[p][q], edd[q][p]);
                    let gam = b.g.mul(half, dd);
                    *rows.gamma_w.last_mut().expect("a row") = Some(b.g.neg(gam));
                }
                let trace = b.g.sum(&[e[0][0], e[1][1], e[2][2]]);
                let three = b.g.int(3);
                rows.checks.push(b.g.sub(three, trace));
                rows.check_names.push(format!("{}.rot", lp.name));
            }
            LoopKind::Hinge(k) => {
                // Axis k of b has no component along the other two axes of a: E_ik = 0, i != k.
                // They vanish with the axes anti-parallel too: `1 - E_kk` (0 when the axes agree,
                // 2 there) is the closure check.
                let (e, edd) = relative_rotation(&mut b.g, &ends);
                let k = k.index();
                for i in (0..3).filter(|&i| i != k) {
                    let name = ["x", "y", "z"][i];
                    let what = format!("axis component `axis_{name}`");
                    constant(&b.g, e[i][k], lp, &what);
                    rows.push(e[i][k], format!("{}.axis_{name}", lp.name), &pts, acc);
                    *rows.gamma_w.last_mut().expect("a row") = Some(b.g.neg(edd[i][k]));
                }
                let one = Graph::ONE;
                rows.checks.push(b.g.sub(one, e[k][k]));
                rows.check_names.push(format!("{}.axis", lp.name));
            }
            LoopKind::Distance(length) => {
                // (|d|² - L²) / (2 L): d·d is a polynomial (no square root, regular at d = 0);
                // at |d| = L its gradient is the unit direction's, as of |d| - L.
                let l = b.expr(length);
                let two_l = {
                    let two = b.g.int(2);
                    b.g.mul(two, l)
                };
                let inv = b.g.div(Graph::ONE, two_l);
                let dd = dot(&mut b.g, &d, &d);
                let ll = b.g.mul(l, l);
                let diff = b.g.sub(dd, ll);
                let row = b.g.mul(inv, diff);
                constant(&b.g, row, lp, "the distance");
                rows.push(row, format!("{}.distance", lp.name), &pts, acc);
                // gamma = -(ḋ·ḋ + d·d̈) / L, ḋ through the body-axes velocities and d̈ through the
                // points' accelerations.
                let va = mat_vec(&mut b.g, &ends[0].cur.frame.r, &ends[0].cur.vel);
                let vb = mat_vec(&mut b.g, &ends[1].cur.frame.r, &ends[1].cur.vel);
                let dv: [Id; 3] = std::array::from_fn(|i| b.g.sub(va[i], vb[i]));
                let da: [Id; 3] = std::array::from_fn(|i| b.g.sub(acc[0][i], acc[1][i]));
                let vv = dot(&mut b.g, &dv, &dv);
                let dacc = dot(&mut b.g, &d, &da);
                let s = b.g.add(vv, dacc);
                let two = b.g.int(2);
                let ns = b.g.neg(s);
                let t = b.g.mul(two, ns);
                *rows.gamma_w.last_mut().expect("a row") = Some(b.g.mul(inv, t));
            }
            LoopKind::Point
            | LoopKind::Sliding
            | LoopKind::Coupling { .. }
            | LoopKind::UnitNorm(_) => {}
        }
        // The components left out: checked after a solve where they depend on X (a constant
        // one, such as `z` of a planar mechanism, is nothing a solve can change). Free for a
        // point in a plane or on a line; a distance has no components.
        if matches!(
            lp.kind,
            LoopKind::Point | LoopKind::Weld | LoopKind::Hinge(_)
        ) {
            for axis in [Axis::X, Axis::Y, Axis::Z] {
                if lp.components.contains(&axis) {
                    continue;
                }
                let e = along[axis.index()];
                if !b.g.is_const(e) {
                    rows.checks.push(e);
                    rows.check_names
                        .push(format!("{}.{}", lp.name, axis.name()));
                }
            }
        }
    }
    if errors.is_empty() {
        Ok(rows)
    } else {
        Err(errors)
    }
}
