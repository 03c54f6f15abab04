//! Joints by name in `transforms`: sugar over the elementary steps, moved by coordinates.
//!
//! | written                                        | is                          |
//! |------------------------------------------------|-----------------------------|
//! | `{ revolute = "q" }` (`axis = "z"` by default) | `"Rz(q)"`                   |
//! | `{ prismatic = "d", axis = "x" }`              | `"Tx(d)"`                   |
//! | `{ universal = ["a", "b"] }` (`axes = "xy"`)   | `"Rx(a)", "Ry(b)"`          |
//! | `{ spherical = ["a", "b", "c"] }` (`"xyz"`)    | `"Rx(a)", "Ry(b)", "Rz(c)"` |
//! | `{ free = ["x", "y", "z", "qw", "qx", "qy", "qz"] }` | `"Tx(x)", "Ty(y)", "Tz(z)"`, the rotation of the quaternion `(qw, qx, qy, qz)` |
//!
//! A `free` joint (a floating base) is a position in the axes of the frame reached so far
//! (the world's, for a root body) and a quaternion whose unit norm the parser adds as a
//! constraint (a `unit_norm` loop named `{body}_quat`, see `sections.rs`).
//! Each rotation or translation is about or along the axes of the frame reached so far, like
//! every step. A joint's variables must be coordinates (a constant turn is `"Rz(angle)"`).

use super::*;

/// Joint names, their number of coordinates, the key of their axes and the default axes.
const JOINTS: &[(&str, usize, &str, &str)] = &[
    ("revolute", 1, "axis", "z"),
    ("prismatic", 1, "axis", "z"),
    ("universal", 2, "axes", "xy"),
    ("spherical", 3, "axes", "xyz"),
    ("free", 7, "", ""),
];
const JOINT_NAMES: &[&str] = &["revolute", "prismatic", "universal", "spherical", "free"];

impl<'s> Parser<'s> {
    /// A joint written as a table in `transforms`: its elementary steps.
    pub(super) fn joint(
        &mut self,
        item: &Value<'_>,
        t: &DeTable<'_>,
        what: &str,
    ) -> Option<Vec<Step>> {
        let span = item.span();
        let named: Vec<&(&str, usize, &str, &str)> = JOINTS
            .iter()
            .filter(|(name, ..)| get(t, name).is_some())
            .collect();
        let &&(kind, count, axes_key, default_axes) = match named.as_slice() {
            [one] => one,
            [] => {
                let mut allowed: Vec<&str> = JOINT_NAMES.to_vec();
                allowed.extend(["axis", "axes"]);
                self.check_keys(t, &span, &allowed, "a joint");
                let d = self.cx.error(
                    &span,
                    format!("a joint in `transforms` ({what}) names no joint type"),
                    format!("expected one of {}", list(JOINT_NAMES)),
                );
                d.help = Some(
                    "write e.g. `{ revolute = \"q1\", axis = \"z\" }` or `{ universal = [\"a\", \"b\"] }`"
                        .to_string(),
                );
                return None;
            }
            [first, second, ..] => {
                let k = key_span(t, second.0).unwrap_or(span.clone());
                self.cx.error(
                    &k,
                    format!(
                        "a joint has one type, but this one is `{}` and `{}`",
                        first.0, second.0
                    ),
                    "a second joint type",
                );
                return None;
            }
        };
        if kind == "free" {
            self.check_keys(t, &span, &[kind], "a `free` joint");
            if !what.starts_with("the transforms of body") {
                let d = self.cx.error(
                    &span,
                    format!("a `free` joint moves a body, but this one is in {what}"),
                    "not a body's transforms",
                );
                d.help = Some(
                    "write `{ free = [...] }` in the `transforms` of the body that floats (its unit quaternion becomes a constraint)".to_string(),
                );
                return None;
            }
        } else {
            self.check_keys(t, &span, &[kind, axes_key], &format!("a `{kind}` joint"));
        }
        let axes = match get(t, axes_key) {
            _ if kind == "free" => vec![
                Axis::X,
                Axis::Y,
                Axis::Z,
                Axis::X,
                Axis::X,
                Axis::X,
                Axis::X,
            ],
            Some(v) => self.joint_axes(v, kind, count)?,
            None => default_axes.chars().map(axis_of).collect(),
        };
        let coords_v = get(t, kind)?;
        let names: Vec<&Value<'_>> = if count == 1 {
            vec![coords_v]
        } else {
            let items = match coords_v.get_ref() {
                DeValue::Array(a) => a,
                other => {
                    let d = self.cx.error(
                        &coords_v.span(),
                        format!(
                            "a `{kind}` joint takes a list of {count} coordinates, found {}",
                            type_name(other)
                        ),
                        format!("expected {count} coordinate names"),
                    );
                    d.help = Some(format!(
                        "write `{kind} = [{}]`",
                        (1..=count)
                            .map(|i| format!("\"q{i}\""))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                    return None;
                }
            };
            if items.len() != count {
                self.cx.error(
                    &coords_v.span(),
                    format!(
                        "a `{kind}` joint has {count} coordinates, found {}",
                        items.len()
                    ),
                    format!("expected {count} coordinate names, one per axis"),
                );
                return None;
            }
            items.iter().collect()
        };
        let mut steps = Vec::new();
        let mut ok = true;
        if kind == "free" {
            let mut coords = Vec::with_capacity(7);
            for v in &names {
                match self.joint_coordinate(v, kind, what) {
                    Some(e) => coords.push(e),
                    None => ok = false,
                }
            }
            if !ok {
                return None;
            }
            for (i, v) in names.iter().enumerate() {
                if coords[..i].contains(&coords[i]) {
                    self.cx.error(
                        &v.span(),
                        "a `free` joint moves by 7 different coordinates, but this one is named twice",
                        "named before in this joint",
                    );
                    return None;
                }
            }
            let quat: [Expr; 4] = std::array::from_fn(|i| coords[3 + i].clone());
            for (i, ax) in [Axis::X, Axis::Y, Axis::Z].into_iter().enumerate() {
                steps.push(Step::Trans(ax, coords[i].clone()));
            }
            steps.push(Step::Quat(Box::new(quat)));
            return Some(steps);
        }
        for (v, ax) in names.into_iter().zip(axes) {
            match self.joint_coordinate(v, kind, what) {
                Some(e) if kind == "prismatic" => steps.push(Step::Trans(ax, e)),
                Some(e) => steps.push(Step::Rot(ax, e)),
                None => ok = false,
            }
        }
        ok.then_some(steps)
    }

    /// `axis = "x"` / `axes = "zx"`: `count` letters, adjacent ones different.
    fn joint_axes(&mut self, v: &Value<'_>, kind: &str, count: usize) -> Option<Vec<Axis>> {
        let key = if count == 1 { "axis" } else { "axes" };
        let s = self.string(v, &format!("the {key} of a `{kind}` joint"))?;
        let good = s.chars().count() == count
            && s.chars().all(|c| matches!(c, 'x' | 'y' | 'z'))
            && !s.as_bytes().windows(2).any(|w| w[0] == w[1]);
        if !good {
            let example = ["z", "xy", "zyx"][count - 1];
            let d = self.cx.error(
                &v.span(),
                format!("`{s}` is not the {key} of a `{kind}` joint"),
                format!(
                    "expected {count} of `x`, `y`, `z`{}",
                    if count > 1 {
                        ", no two adjacent ones equal"
                    } else {
                        ""
                    }
                ),
            );
            d.help = Some(format!(
                "e.g. `{key} = \"{example}\"`: the axes of the frame reached so far, in order"
            ));
            return None;
        }
        Some(s.chars().map(axis_of).collect())
    }

    /// A joint's variable: the name of a coordinate.
    fn joint_coordinate(&mut self, v: &Value<'_>, kind: &str, what: &str) -> Option<Expr> {
        let name = self.string(v, &format!("a coordinate of a `{kind}` joint"))?;
        match self.syms.get(&name).cloned() {
            Some(Sym {
                kind: SymKind::Coord,
                index,
                ..
            }) => {
                if let Some(u) = self.coord_used.get_mut(index) {
                    *u = true;
                }
                Some(Expr::Coord(index))
            }
            Some(Sym {
                kind: SymKind::Param,
                ..
            }) => {
                let step = if kind == "prismatic" { "Tz" } else { "Rz" };
                let d = self.cx.error(
                    &v.span(),
                    format!("a joint moves by a coordinate, but `{name}` is a parameter ({what})"),
                    "a parameter is constant",
                );
                d.help = Some(format!(
                    "a constant turn or offset is an elementary step such as `\"{step}({name})\"`"
                ));
                None
            }
            None => {
                let candidates: Vec<(String, usize)> = self
                    .sym_list
                    .iter()
                    .filter(|(_, _, k)| *k == SymKind::Coord)
                    .map(|(n, l, _)| (n.clone(), *l))
                    .collect();
                let d = self.cx.error(
                    &v.span(),
                    format!("unknown coordinate `{name}` in a `{kind}` joint ({what})"),
                    "not a coordinate",
                );
                d.help = suggest(
                    &name,
                    candidates.iter().map(|(n, l)| (n.as_str(), Some(*l))),
                )
                .or_else(|| Some("declare it in `coordinates` first".to_string()));
                None
            }
        }
    }
}

fn axis_of(c: char) -> Axis {
    match c {
        'x' => Axis::X,
        'y' => Axis::Y,
        _ => Axis::Z,
    }
}
