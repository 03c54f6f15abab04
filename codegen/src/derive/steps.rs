//! The model's transform steps as the derivation applies them ([`Piece`]s), and constant
//! folding: a run of consecutive constant steps (no coordinate in them: fixed offsets, `rpy`,
//! `quat`, inverse chains, named frames) becomes one constant transform when that is cheaper.
//!
//! The constant transform `(R, p)` of a run is computed once in the graph: its entries are
//! numbers (exact where the expressions allow: rationals, `cos(pi / 3)`, `sqrt(4)`; f64
//! otherwise) or parameter-only nodes, which the kernels read from `Params::consts`. Applied to
//! a moving frame it costs one product with `R`'s non-zero entries and one translation, instead
//! of one product per step. Which is cheaper depends on the steps (an elementary rotation
//! touches two columns, a full constant matrix three): for every run the derivation builds
//! four candidates on the frame they apply to (the steps as written; the same with adjacent rotations
//! about one axis and translations along one axis merged; `p` then `R`; `R` then `Rᵀ p`) and
//! keeps the one needing the fewest new operations for the frame and its velocities (nodes the
//! graph holds already, such as a point another loop reaches by the same steps, are free), the
//! steps as written on a tie, so a model with nothing to gain keeps its code.

use super::{Builder, Joint, Moving, add3, cross, mat_t_vec, rotation, world};
use crate::graph::{Graph, Id, Seed};
use crate::model::{Axis, Step};

/// A step as the derivation applies it.
#[derive(Clone, Copy, Debug)]
pub(super) enum Piece {
    /// `Rx`, `Ry`, `Rz` of an angle (moving or constant).
    Rot(Axis, Id),
    /// `Tx`, `Ty`, `Tz` of a distance (moving or constant).
    Trans(Axis, Id),
    /// A constant rotation matrix.
    Matrix([[Id; 3]; 3]),
    /// The rotation of a moving quaternion `[w, x, y, z]` (a `free` joint), normalised.
    Quat([Id; 4]),
}

/// How a constant run is applied (see the module's doc).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Fold {
    /// The steps as written.
    Written,
    /// The steps as written, adjacent rotations about one axis and translations along one
    /// axis merged, repeatedly (`Rz(a) Tx(b) Tx(-b) Rz(-a)` is nothing).
    Merged,
    /// `p` in the parent's axes, then `R`.
    Before,
    /// `R`, then `Rᵀ p` in the child's axes.
    After,
}

fn is_constant(st: &Step) -> bool {
    match st {
        Step::Rot(_, e) | Step::Trans(_, e) => e.is_constant(),
        Step::Rotation(_) => true,
        Step::Quat(_) => false,
    }
}

impl Builder<'_> {
    /// The pieces of `steps` applied after the frame `m`, constant runs folded where cheaper.
    /// They are also applied here, in the order the caller applies them again (the graph
    /// shares every node), so a model with nothing to fold builds the same graph as before
    /// folding existed.
    pub(super) fn pieces(&mut self, m: &Moving, steps: &[Step]) -> Vec<Piece> {
        let mut out = Vec::with_capacity(steps.len());
        let mut cur = *m;
        let mut i = 0;
        while i < steps.len() {
            if !is_constant(&steps[i]) {
                let p = self.piece(&steps[i]);
                cur = self.apply(&cur, &p);
                out.push(p);
                i += 1;
                continue;
            }
            let end = (i..steps.len())
                .find(|&k| !is_constant(&steps[k]))
                .unwrap_or(steps.len());
            let run = &steps[i..end];
            let fold = if run.len() < 2 {
                Fold::Written
            } else {
                // The candidates are tried on a copy of the graph: only the one kept is built.
                let mut scratch = Builder {
                    g: self.g.clone(),
                    model: self.model,
                    frozen: self.frozen,
                    body_pieces: Vec::new(),
                };
                // What the graph holds already (the frames and points built so far) is free.
                let since = scratch.g.len() as Id;
                let mut best = (usize::MAX, Fold::Written);
                for fold in [Fold::Written, Fold::Merged, Fold::Before, Fold::After] {
                    let (_, after) = scratch.build(fold, &cur, run);
                    let c = scratch.g.cost_since(&moving_ids(&after), since);
                    if c < best.0 {
                        best = (c, fold);
                    }
                }
                best.1
            };
            let (pieces, after) = self.build(fold, &cur, run);
            cur = after;
            out.extend(pieces);
            i = end;
        }
        out
    }

    fn piece(&mut self, st: &Step) -> Piece {
        match st {
            Step::Rot(a, e) => Piece::Rot(*a, self.expr(e)),
            Step::Trans(a, e) => Piece::Trans(*a, self.expr(e)),
            Step::Rotation(m) => {
                let r = std::array::from_fn(|i| std::array::from_fn(|j| self.expr(&m[i][j])));
                Piece::Matrix(r)
            }
            Step::Quat(q) => Piece::Quat(std::array::from_fn(|i| self.expr(&q[i]))),
        }
    }

    /// The pieces of the constant run `run` in the form `fold`, applied after `m` as they are
    /// built; and the frame after them.
    fn build(&mut self, fold: Fold, m: &Moving, run: &[Step]) -> (Vec<Piece>, Moving) {
        let mut out = Vec::with_capacity(run.len());
        let mut cur = *m;
        if fold == Fold::Written {
            for st in run {
                let p = self.piece(st);
                cur = self.apply(&cur, &p);
                out.push(p);
            }
            return (out, cur);
        }
        if fold == Fold::Merged {
            // A stack: a step about (along) the axis of the one before adds to it, and a sum
            // of zero leaves, so `T R R⁻¹ T⁻¹` (an inverse chain after its chain) is nothing.
            for st in run {
                let p = self.piece(st);
                match (out.last_mut(), p) {
                    (Some(Piece::Rot(a, s)), Piece::Rot(b, t))
                    | (Some(Piece::Trans(a, s)), Piece::Trans(b, t))
                        if *a == b =>
                    {
                        *s = self.g.add(*s, t);
                        if *s == Graph::ZERO {
                            out.pop();
                        }
                    }
                    _ => out.push(p),
                }
            }
            for pc in &out {
                cur = self.apply(&cur, pc);
            }
            return (out, cur);
        }
        // The run's transform (R, p): the run applied to the world frame.
        let mut total = world();
        for st in run {
            let p = self.piece(st);
            total = self.apply(&total, &p);
        }
        let (r, p) = (total.frame.r, total.frame.p);
        let matrix = (r != world().frame.r).then_some(Piece::Matrix(r));
        let translations = |v: [Id; 3]| {
            (0..3)
                .filter(|&k| v[k] != Graph::ZERO)
                .map(|k| Piece::Trans([Axis::X, Axis::Y, Axis::Z][k], v[k]))
                .collect::<Vec<_>>()
        };
        if fold == Fold::Before {
            out.extend(translations(p));
            out.extend(matrix);
        } else {
            let rtp = mat_t_vec(&mut self.g, &r, &p);
            out.extend(matrix);
            out.extend(translations(rtp));
        }
        for pc in &out {
            cur = self.apply(&cur, pc);
        }
        (out, cur)
    }

    /// `m * piece`: the frame and its body-axes velocities.
    pub(super) fn apply(&mut self, m: &Moving, piece: &Piece) -> Moving {
        let g = &mut self.g;
        let mut out = *m;
        match *piece {
            Piece::Rot(axis, th) => {
                let (c, s) = (g.cos(th), g.sin(th));
                let rot = rotation(g, axis, c, s);
                rotate(g, m, &mut out, &rot);
                let k = axis.index();
                let thdot = g.diff(th, Seed::Time);
                out.omega[k] = g.add(out.omega[k], thdot);
                out.vel = mat_t_vec(g, &rot, &m.vel);
            }
            Piece::Matrix(rot) => {
                rotate(g, m, &mut out, &rot);
                out.vel = mat_t_vec(g, &rot, &m.vel);
            }
            Piece::Quat(q) => {
                // R(q / |q|) with s = 2 / |q|²; its body-axes angular velocity is exactly
                // s Im(q* q̇) = s (w v̇ - ẇ v - v × v̇), v = (x, y, z).
                let [w, x, y, z] = q;
                let sq: [Id; 4] = std::array::from_fn(|i| g.mul(q[i], q[i]));
                let nn = g.sum(&sq);
                let two = g.int(2);
                let s = g.div(two, nn);
                let mut prod = |a: Id, b: Id, c: Id, d: Id, sign: bool| {
                    let ab = g.mul(a, b);
                    let cd = g.mul(c, d);
                    let t = if sign { g.add(ab, cd) } else { g.sub(ab, cd) };
                    g.mul(s, t)
                };
                let r01 = prod(x, y, w, z, false);
                let r10 = prod(x, y, w, z, true);
                let r02 = prod(x, z, w, y, true);
                let r20 = prod(x, z, w, y, false);
                let r12 = prod(y, z, w, x, false);
                let r21 = prod(y, z, w, x, true);
                let mut diag = |a: Id, b: Id| {
                    let t = g.add(a, b);
                    let st = g.mul(s, t);
                    g.sub(Graph::ONE, st)
                };
                let r00 = diag(sq[2], sq[3]);
                let r11 = diag(sq[1], sq[3]);
                let r22 = diag(sq[1], sq[2]);
                let rot = [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]];
                rotate(g, m, &mut out, &rot);
                out.vel = mat_t_vec(g, &rot, &m.vel);
                let v = [x, y, z];
                let wd = g.diff(w, Seed::Time);
                let vd: [Id; 3] = std::array::from_fn(|i| g.diff(v[i], Seed::Time));
                let vxvd = cross(g, &v, &vd);
                let rel: [Id; 3] = std::array::from_fn(|k| {
                    let a = g.mul(w, vd[k]);
                    let b = g.mul(wd, v[k]);
                    let t = g.sub(a, b);
                    let t = g.sub(t, vxvd[k]);
                    g.mul(s, t)
                });
                for (o, r) in out.omega.iter_mut().zip(rel) {
                    *o = g.add(*o, r);
                }
            }
            Piece::Trans(axis, s) => {
                let k = axis.index();
                out.frame.p = std::array::from_fn(|i| {
                    let t = g.mul(m.frame.r[i][k], s);
                    g.add(m.frame.p[i], t)
                });
                let mut se = [Graph::ZERO; 3];
                se[k] = s;
                let wx = cross(g, &m.omega, &se);
                out.vel = add3(g, &m.vel, &wx);
                let sdot = g.diff(s, Seed::Time);
                out.vel[k] = g.add(out.vel[k], sdot);
            }
        }
        out
    }

    /// The joint a piece is, when its argument depends on the coordinates: its axis and point
    /// in world axes (taken before the step; a rotation leaves both unchanged).
    pub(super) fn joint(&mut self, m: &Moving, piece: &Piece, body: usize) -> Option<Joint> {
        let (theta, axis, revolute) = match *piece {
            Piece::Rot(a, t) => (t, a, true),
            Piece::Trans(a, t) => (t, a, false),
            Piece::Matrix(_) | Piece::Quat(_) => return None,
        };
        if self.g.is_const(theta) {
            return None;
        }
        let k = axis.index();
        Some(Joint {
            body,
            revolute,
            axis: [m.frame.r[0][k], m.frame.r[1][k], m.frame.r[2][k]],
            point: m.frame.p,
            theta,
        })
    }
}

/// `out = m` turned by the constant-or-moving rotation `rot` (post-multiplied): the frame and
/// the body-axes angular velocity `omega' = rotᵀ omega` (the caller turns `v' = rotᵀ v`).
fn rotate(g: &mut Graph, m: &Moving, out: &mut Moving, rot: &[[Id; 3]; 3]) {
    out.frame.r = std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let mut acc = Graph::ZERO;
            for l in 0..3 {
                let t = g.mul(m.frame.r[i][l], rot[l][j]);
                acc = g.add(acc, t);
            }
            acc
        })
    });
    out.omega = mat_t_vec(g, rot, &m.omega);
}

fn moving_ids(m: &Moving) -> Vec<Id> {
    let mut v: Vec<Id> = m.frame.r.iter().flatten().copied().collect();
    v.extend(m.frame.p);
    v.extend(m.omega);
    v.extend(m.vel);
    v
}
