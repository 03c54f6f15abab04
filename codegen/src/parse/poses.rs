//! Pose steps in `transforms` (tables, like the joints) and `[frames]`, named constant frames.
//!
//! | written                                             | is                                  |
//! |-----------------------------------------------------|-------------------------------------|
//! | `{ rpy = [r, p, y] }` (`unit = "deg"` optional)     | `Rz(y) Ry(p) Rx(r)` (URDF's rpy)    |
//! | `{ quat = [w, x, y, z] }`                           | its rotation matrix, normalised     |
//! | `{ axis_angle = [ax, ay, az, angle] }`              | Rodrigues' matrix (`Rz(angle)` for `[0, 0, 1, angle]`) |
//! | `{ pose = { xyz = [x, y, z], rpy = [..] } }`        | `Tx Ty Tz`, then the rotation       |
//! | `{ inverse = [steps...] }`                          | the steps undone, in reverse order  |
//! | `{ frame = "name" }`                                | the steps of `[frames] name`        |
//!
//! `rpy` angles may be coordinates (they are elementary rotations); `quat`, `axis_angle` and
//! named frames are constant (numbers and parameters). The derivation folds runs of constant
//! steps into one transform (`derive/steps.rs`).

use super::*;

/// The keys that make a table in `transforms` a pose step (not a joint).
pub(super) const POSE_KEYS: &[&str] = &["rpy", "quat", "axis_angle", "pose", "inverse", "frame"];
const ROTATION_KEYS: &[&str] = &["rpy", "quat", "axis_angle"];
/// A quaternion whose norm is further than this from 1 (relative) gets a warning.
const QUAT_NORM_TOLERANCE: f64 = 1e-3;

pub(super) fn is_pose(t: &DeTable<'_>) -> bool {
    POSE_KEYS.iter().any(|k| get(t, k).is_some())
}

fn is_zero(e: &Expr) -> bool {
    matches!(e, Expr::Num { num: 0, .. })
}

fn neg(e: Expr) -> Expr {
    match e {
        Expr::Num { num, den } => Expr::Num { num: -num, den },
        Expr::Neg(a) => *a,
        e => Expr::Neg(bx(e)),
    }
}

fn sub(a: Expr, b: Expr) -> Expr {
    Expr::Sub(bx(a), bx(b))
}

/// The steps of `steps` undone: reverse order, each step inverted.
pub(super) fn inverse(steps: Vec<Step>) -> Vec<Step> {
    steps
        .into_iter()
        .rev()
        .map(|s| match s {
            Step::Rot(a, e) => Step::Rot(a, neg(e)),
            Step::Trans(a, e) => Step::Trans(a, neg(e)),
            Step::Rotation(m) => Step::Rotation(Box::new(std::array::from_fn(|i| {
                std::array::from_fn(|j| m[j][i].clone())
            }))),
            // The conjugate quaternion: the inverse rotation.
            Step::Quat(q) => {
                let [w, x, y, z] = *q;
                Step::Quat(Box::new([w, neg(x), neg(y), neg(z)]))
            }
        })
        .collect()
}

/// The rotation matrix of the quaternion `w + x i + y j + z k`, normalised: with
/// `s = 2 / (w² + x² + y² + z²)`, `R = 1 - s (...)` (exact for rational entries).
fn quat_matrix(q: [Expr; 4]) -> [[Expr; 3]; 3] {
    let [w, x, y, z] = q;
    let n = add(
        add(sq(w.clone()), sq(x.clone())),
        add(sq(y.clone()), sq(z.clone())),
    );
    let s = div(Expr::int(2), n);
    let p = |a: &Expr, b: &Expr| mul(a.clone(), b.clone());
    let sp = |e: Expr| mul(s.clone(), e);
    let one = || Expr::int(1);
    [
        [
            sub(one(), sp(add(p(&y, &y), p(&z, &z)))),
            sp(sub(p(&x, &y), p(&z, &w))),
            sp(add(p(&x, &z), p(&y, &w))),
        ],
        [
            sp(add(p(&x, &y), p(&z, &w))),
            sub(one(), sp(add(p(&x, &x), p(&z, &z)))),
            sp(sub(p(&y, &z), p(&x, &w))),
        ],
        [
            sp(sub(p(&x, &z), p(&y, &w))),
            sp(add(p(&y, &z), p(&x, &w))),
            sub(one(), sp(add(p(&x, &x), p(&y, &y)))),
        ],
    ]
}

/// Rodrigues' matrix of the angle `t` about the axis `a` (any length, not zero):
/// `R = cos t 1 + sin t [u]x + (1 - cos t) u uᵀ`, `u = a / |a|`.
fn axis_angle_matrix(a: [Expr; 3], t: Expr) -> [[Expr; 3]; 3] {
    let n2 = add(add(sq(a[0].clone()), sq(a[1].clone())), sq(a[2].clone()));
    let norm = Expr::Call(Func::Sqrt, vec![n2.clone()]);
    let c = Expr::Call(Func::Cos, vec![t.clone()]);
    let s = Expr::Call(Func::Sin, vec![t]);
    let one_c = sub(Expr::int(1), c.clone());
    // sin t u_k
    let su = |k: usize| div(mul(s.clone(), a[k].clone()), norm.clone());
    let outer = |i: usize, j: usize| {
        div(
            mul(one_c.clone(), mul(a[i].clone(), a[j].clone())),
            n2.clone(),
        )
    };
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let o = outer(i, j);
            match (i, j) {
                _ if i == j => add(c.clone(), o),
                (0, 1) => sub(o, su(2)),
                (1, 0) => add(o, su(2)),
                (0, 2) => add(o, su(1)),
                (2, 0) => sub(o, su(1)),
                (1, 2) => sub(o, su(0)),
                _ => add(o, su(0)),
            }
        })
    })
}

impl<'s> Parser<'s> {
    /// `[frames]`: name -> steps, constant. Each may use the frames above it.
    pub(super) fn frames(&mut self, v: &Value<'_>) {
        let Some(t) = self.table(v, "`frames`") else {
            return;
        };
        for (k, fv) in t.iter() {
            let name = k.get_ref().as_ref().to_string();
            let line = self.cx.line(&k.span());
            if !is_identifier(&name) {
                let d = self.cx.error(
                    &k.span(),
                    format!("`{name}` is not a valid frame name"),
                    "expected an identifier",
                );
                d.help = Some(
                    "a name starts with a letter or `_` and continues with letters, digits or `_`"
                        .to_string(),
                );
                continue;
            }
            let what = format!("frame `{name}`");
            let steps = self.steps(fv, &what);
            let steps = steps.filter(|st| self.constant_steps(fv, st, &what));
            self.frames.insert(name.clone(), (steps, line));
            self.frame_list.push((name, line));
        }
    }

    /// True when `steps` use no coordinate; otherwise reports it at `v`.
    fn constant_steps(&mut self, v: &Value<'_>, steps: &[Step], what: &str) -> bool {
        let moving = steps.iter().any(|s| match s {
            Step::Rot(_, e) | Step::Trans(_, e) => !e.is_constant(),
            Step::Rotation(_) => false,
            Step::Quat(_) => true,
        });
        if moving {
            let d = self.cx.error(
                &v.span(),
                format!("{what} uses a coordinate"),
                "a named frame is constant",
            );
            d.help = Some(
                "named frames hold fixed offsets (numbers and parameters); write joints in the body's `transforms`"
                    .to_string(),
            );
        }
        !moving
    }

    /// A pose step written as a table in `transforms`: its steps.
    pub(super) fn pose_step(
        &mut self,
        item: &Value<'_>,
        t: &DeTable<'_>,
        what: &str,
    ) -> Option<Vec<Step>> {
        let span = item.span();
        let named: Vec<&str> = POSE_KEYS
            .iter()
            .copied()
            .filter(|k| get(t, k).is_some())
            .collect();
        if let [first, second, ..] = named.as_slice() {
            let k = key_span(t, second).unwrap_or(span.clone());
            let d = self.cx.error(
                &k,
                format!("a step has one kind, but this one is `{first}` and `{second}`"),
                "a second kind of step",
            );
            d.help = Some(
                "write one step per table, or `{ pose = { xyz = [..], rpy = [..] } }` for a translation and a rotation"
                    .to_string(),
            );
            return None;
        }
        let kind = named[0];
        let v = get(t, kind)?;
        match kind {
            "rpy" | "axis_angle" => {
                self.check_keys(t, &span, &[kind, "unit"], &format!("an `{kind}` step"));
                let deg = self.angle_unit(t)?;
                self.rotation(kind, v, deg, what)
            }
            "quat" => {
                self.check_keys(t, &span, &[kind], "a `quat` step");
                self.rotation(kind, v, false, what)
            }
            "pose" => {
                self.check_keys(t, &span, &[kind], "a `pose` step");
                self.pose(v, what)
            }
            "inverse" => {
                self.check_keys(t, &span, &[kind], "an `inverse` step");
                let steps = self.steps(v, &format!("the inverse in {what}"))?;
                Some(inverse(steps))
            }
            _ => {
                self.check_keys(t, &span, &[kind], "a `frame` step");
                let name = self.string(v, "the name of a frame")?;
                match self.frames.get(&name) {
                    Some((steps, _)) => steps.clone(),
                    None => {
                        let help = suggest(
                            &name,
                            self.frame_list.iter().map(|(n, l)| (n.as_str(), Some(*l))),
                        );
                        let d = self.cx.error(
                            &v.span(),
                            format!("unknown frame `{name}`"),
                            "not defined in `[frames]` above this use",
                        );
                        d.help = help.or_else(|| {
                            Some(format!(
                                "define it in `[frames]`: `{name} = [{{ pose = {{ xyz = [..], rpy = [..] }} }}]`"
                            ))
                        });
                        None
                    }
                }
            }
        }
    }

    /// `unit = "deg"` (true) or `"rad"` (false, the default) of a step's angles.
    fn angle_unit(&mut self, t: &DeTable<'_>) -> Option<bool> {
        let Some(u) = get(t, "unit") else {
            return Some(false);
        };
        match self.string(u, "the unit of a step's angles")?.as_str() {
            "rad" => Some(false),
            "deg" => Some(true),
            other => {
                self.cx.error(
                    &u.span(),
                    format!("unknown angle unit `{other}`"),
                    "expected `\"rad\"` or `\"deg\"`",
                );
                None
            }
        }
    }

    /// `{ pose = { xyz = [..], rpy | quat | axis_angle = [..], unit = ".." } }`.
    fn pose(&mut self, v: &Value<'_>, what: &str) -> Option<Vec<Step>> {
        let t = self.table(v, "a `pose`")?;
        let span = v.span();
        let mut allowed = vec!["xyz", "unit"];
        allowed.extend(ROTATION_KEYS);
        self.check_keys(t, &span, &allowed, "a `pose`");
        let rotations: Vec<&str> = ROTATION_KEYS
            .iter()
            .copied()
            .filter(|k| get(t, k).is_some())
            .collect();
        if let [first, second, ..] = rotations.as_slice() {
            let k = key_span(t, second).unwrap_or(span.clone());
            self.cx.error(
                &k,
                format!("a pose has one rotation, but this one has `{first}` and `{second}`"),
                "a second rotation",
            );
            return None;
        }
        if rotations.is_empty() && get(t, "xyz").is_none() {
            let d = self.cx.error(
                &span,
                "an empty pose",
                "expected `xyz` and one of `rpy`, `quat`, `axis_angle`",
            );
            d.help = Some(
                "write e.g. `{ pose = { xyz = [0.1, 0, 0], rpy = [0, 0, \"pi / 2\"] } }`"
                    .to_string(),
            );
            return None;
        }
        let deg = self.angle_unit(t)?;
        let mut out = Vec::new();
        let mut ok = true;
        if let Some(xyz) = get(t, "xyz") {
            match self.three(
                xyz,
                &format!("the `xyz` of a pose in {what}"),
                true,
                "[x, y, z]",
            ) {
                Some(p) => {
                    for (k, e) in p.into_iter().enumerate() {
                        if !is_zero(&e) {
                            out.push(Step::Trans([Axis::X, Axis::Y, Axis::Z][k], e));
                        }
                    }
                }
                None => ok = false,
            }
        }
        if let Some(kind) = rotations.first() {
            match self.rotation(kind, get(t, kind)?, deg, what) {
                Some(steps) => out.extend(steps),
                None => ok = false,
            }
        }
        ok.then_some(out)
    }

    /// Three expressions (`coords`: coordinates allowed).
    fn three(
        &mut self,
        v: &Value<'_>,
        what: &str,
        coords: bool,
        expected: &str,
    ) -> Option<[Expr; 3]> {
        let items = self.array(v, what)?;
        if items.len() != 3 {
            self.cx.error(
                &v.span(),
                format!("{what} must have 3 entries, found {}", items.len()),
                format!("expected {expected}"),
            );
            return None;
        }
        let scope = if coords {
            Scope::transform(what)
        } else {
            Scope::constant(what)
        };
        let out: Vec<Option<Expr>> = items
            .iter()
            .map(|i| self.expr(i, &scope).map(|r| r.expr))
            .collect();
        out.into_iter().collect::<Option<Vec<_>>>()?.try_into().ok()
    }

    /// `rpy`, `quat` or `axis_angle`: the steps of the rotation.
    fn rotation(&mut self, kind: &str, v: &Value<'_>, deg: bool, what: &str) -> Option<Vec<Step>> {
        let angle = |e: Expr| {
            if deg && !is_zero(&e) {
                deg_to_rad(e)
            } else {
                e
            }
        };
        match kind {
            "rpy" => {
                let [r, p, y] = self.three(
                    v,
                    &format!("the `rpy` in {what}"),
                    true,
                    "[roll, pitch, yaw]",
                )?;
                // URDF: fixed axes x, y, z, i.e. R = Rz(yaw) Ry(pitch) Rx(roll).
                Some(
                    [(Axis::Z, y), (Axis::Y, p), (Axis::X, r)]
                        .into_iter()
                        .filter(|(_, e)| !is_zero(e))
                        .map(|(a, e)| Step::Rot(a, angle(e)))
                        .collect(),
                )
            }
            "quat" => {
                let q = self.vector(
                    v,
                    &format!("the quaternion in {what}"),
                    &["w", "x", "y", "z"],
                )?;
                let values: Vec<f64> = q.iter().map(|(_, v, _)| *v).collect();
                let tainted = q.iter().any(|(_, _, t)| *t);
                let norm = values.iter().map(|v| v * v).sum::<f64>().sqrt();
                if !tainted && norm == 0.0 {
                    self.cx.error(
                        &v.span(),
                        "a quaternion cannot be zero",
                        "all four components are 0",
                    );
                    return None;
                }
                if !tainted && (norm - 1.0).abs() > QUAT_NORM_TOLERANCE {
                    let span = v.span();
                    let d = Diagnostic::new(
                        self.cx.pos(span.start),
                        self.cx.len(&span),
                        format!(
                            "quaternion in {what} has norm {}, not 1: it is normalised",
                            fmt_num(norm)
                        ),
                        "not a unit quaternion",
                    )
                    .with_help(
                        "a rotation's quaternion has norm 1; check the order `[w, x, y, z]` (w first) and the digits"
                            .to_string(),
                    );
                    self.warnings.push(d);
                }
                let [w, x, y, z] = q.map(|(e, _, _)| e);
                Some(vec![Step::Rotation(Box::new(quat_matrix([w, x, y, z])))])
            }
            _ => {
                let a = self.vector(
                    v,
                    &format!("the `axis_angle` in {what}"),
                    &["ax", "ay", "az", "angle"],
                )?;
                let tainted = a.iter().any(|(_, _, t)| *t);
                if !tainted && a[..3].iter().all(|(_, v, _)| *v == 0.0) {
                    self.cx.error(
                        &v.span(),
                        "the axis of an `axis_angle` cannot be zero",
                        "expected `[ax, ay, az, angle]` with a non-zero axis",
                    );
                    return None;
                }
                let [ax, ay, az, t] = a.map(|(e, _, _)| e);
                let t = angle(t);
                // An axis along x, y or z (written with literal numbers): the elementary step.
                let axis = [ax, ay, az];
                let literal: Vec<Option<(i128, i128)>> = axis
                    .iter()
                    .map(|e| match e {
                        Expr::Num { num, den } => Some((*num, *den)),
                        _ => None,
                    })
                    .collect();
                if literal.iter().all(Option::is_some) {
                    let nonzero: Vec<usize> = (0..3)
                        .filter(|&k| literal[k].is_some_and(|(n, _)| n != 0))
                        .collect();
                    if let [k] = nonzero.as_slice() {
                        let positive = literal[*k].is_some_and(|(n, _)| n > 0);
                        let t = if positive { t } else { neg(t) };
                        return Some(vec![Step::Rot([Axis::X, Axis::Y, Axis::Z][*k], t)]);
                    }
                }
                Some(vec![Step::Rotation(Box::new(axis_angle_matrix(axis, t)))])
            }
        }
    }
}
