//! `[[body]]`: frames, parents and transform steps (strings and the 12-element pose vector).

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn bodies(&mut self, v: &Value<'_>) -> Option<Vec<Body>> {
        let items = match v.get_ref() {
            DeValue::Array(a) => a,
            other => {
                self.cx.error(
                    &v.span(),
                    format!(
                        "`body` must be an array of tables `[[body]]`, found {}",
                        type_name(other)
                    ),
                    "expected `[[body]]`",
                );
                return None;
            }
        };
        // Declare the names first (loops and error messages refer to any body).
        for (i, item) in items.iter().enumerate() {
            let Some(nv) = item.get_ref().as_table().and_then(|t| get(t, "name")) else {
                continue;
            };
            let Some(name) = nv.get_ref().as_str() else {
                continue;
            };
            let line = self.cx.line(&nv.span());
            if name == "world" {
                self.cx.error(
                    &nv.span(),
                    "`world` cannot name a body",
                    "reserved for the fixed frame",
                );
                continue;
            }
            if let Some(first) = self.bodies.get(name) {
                let first_line = first.line;
                let d = self.cx.error(
                    &nv.span(),
                    format!("body `{name}` is defined twice"),
                    "redefined here",
                );
                d.help = Some(format!(
                    "body `{name}` is first defined on line {first_line}"
                ));
                continue;
            }
            self.bodies
                .insert(name.to_string(), BodyInfo { index: i, line });
            self.body_list.push((name.to_string(), line));
        }
        if items.is_empty() {
            self.cx.error(
                &v.span(),
                "the model has no bodies",
                "expected at least one `[[body]]`",
            );
            return None;
        }
        let mut out = Vec::new();
        let mut ok = true;
        for (i, item) in items.iter().enumerate() {
            let b = self.body(i, item);
            ok &= b.is_some();
            out.extend(b);
        }
        ok.then_some(out)
    }

    pub(super) fn body_suggestion(&self, name: &str) -> Option<String> {
        suggest(
            name,
            self.body_list
                .iter()
                .map(|(n, l)| (n.as_str(), Some(*l)))
                .chain(std::iter::once(("world", None))),
        )
    }

    pub(super) fn body(&mut self, i: usize, item: &Value<'_>) -> Option<Body> {
        let t = self.table(item, "a `[[body]]` entry")?;
        let span = item.span();
        self.check_keys(t, &span, BODY_KEYS, "`[[body]]`");
        let name_v = self.required(t, &span, "name", "`[[body]]`");
        let name = name_v.and_then(|v| self.name(v, "body"));
        let shown = name.clone().unwrap_or_else(|| "?".to_string());

        let parent = match get(t, "parent") {
            None => Some(None),
            Some(pv) => match self.string(pv, &format!("the parent of body `{shown}`")) {
                None => None,
                Some(p) if p == "world" => Some(None),
                Some(p) => match self.bodies.get(&p).map(|b| (b.index, b.line)) {
                    Some((j, _)) if j < i => Some(Some(j)),
                    Some((j, _)) if j == i => {
                        self.cx.error(
                            &pv.span(),
                            format!("body `{shown}` names itself as its parent"),
                            "a body cannot be its own parent",
                        );
                        None
                    }
                    Some((_, line)) => {
                        let d = self.cx.error(
                            &pv.span(),
                            format!("body `{shown}` names parent `{p}`, which is defined later (line {line})"),
                            "defined below this body",
                        );
                        d.help = Some(
                            "a parent body must come before its children: move it up".to_string(),
                        );
                        None
                    }
                    None => {
                        let help = self.body_suggestion(&p);
                        let d = self.cx.error(
                            &pv.span(),
                            format!("body `{shown}` names unknown parent `{p}`"),
                            "not defined in this model",
                        );
                        d.help = help;
                        None
                    }
                },
            },
        };

        let steps = match get(t, "transforms") {
            Some(tv) => self.steps(tv, &format!("the transforms of body `{shown}`")),
            None => Some(Vec::new()),
        };

        let inertia = self.mass_props(t, &span, &shown);
        Some(Body {
            name: name?,
            parent: parent?,
            steps: steps?,
            inertia: inertia?,
            pos: self
                .cx
                .pos(name_v.map(|v| v.span().start).unwrap_or(span.start)),
        })
    }

    /// `transforms`: an array of `Rx(..)`-style strings and 12-element pose vectors.
    pub(super) fn steps(&mut self, v: &Value<'_>, what: &str) -> Option<Vec<Step>> {
        let items = self.array(v, &format!("`transforms` ({what})"))?;
        let mut out = Vec::new();
        let mut ok = true;
        for item in items {
            match item.get_ref() {
                DeValue::String(s) => match self.step_string(item, s, what) {
                    Some(step) => out.push(step),
                    None => ok = false,
                },
                DeValue::Array(a) => match self.pose_vector(item, a, what) {
                    Some(steps) => out.extend(steps),
                    None => ok = false,
                },
                DeValue::Table(t) if poses::is_pose(t) => match self.pose_step(item, t, what) {
                    Some(steps) => out.extend(steps),
                    None => ok = false,
                },
                DeValue::Table(t) => match self.joint(item, t, what) {
                    Some(steps) => out.extend(steps),
                    None => ok = false,
                },
                other => {
                    let d = self.cx.error(
                        &item.span(),
                        format!("a transform must be a string like `Rz(angle)`, a joint such as `{{ revolute = \"q\" }}` or a 12-element pose vector, found {}", type_name(other)),
                        "expected a string, a table or an array",
                    );
                    d.help = Some(
                        "write `\"Tx(length)\"`, `\"Rz(angle)\"`, or `[x, y, z, rx, ry, rz, 1, 2, 3, 4, 5, 6]`".to_string(),
                    );
                    ok = false;
                }
            }
        }
        ok.then_some(out)
    }

    pub(super) fn step_string(&mut self, item: &Value<'_>, s: &str, what: &str) -> Option<Step> {
        let loc = self.str_loc(item, s);
        let raw = match parse_raw(s) {
            Ok(raw) => raw,
            Err(mut e) => {
                if e.message.starts_with("expected an operator, found `")
                    && STEP_NAMES
                        .iter()
                        .any(|n| s.chars().skip(e.at.0).collect::<String>().starts_with(n))
                {
                    e.help = Some(
                        "write one transform per string: `[\"Rz(a)\", \"Tx(b)\"]`".to_string(),
                    );
                }
                self.expr_error(&loc, e);
                return None;
            }
        };
        let (name, at, args) = match raw {
            Raw::Call(name, at, args) => (name, at, args),
            _ => {
                let mut e = expr_err(
                    (0, s.chars().count()),
                    "expected a transform like `Rz(angle)` or `Tx(distance)`",
                    format!(
                        "expected {}",
                        list(&["Rx(..)", "Ry(..)", "Rz(..)", "Tx(..)", "Ty(..)", "Tz(..)"])
                    ),
                );
                e.help = Some("a transform step is one elementary rotation or translation; arrays give the 12-element pose vector".to_string());
                self.expr_error(&loc, e);
                return None;
            }
        };
        let axis = |c: char| match c {
            'x' => Axis::X,
            'y' => Axis::Y,
            _ => Axis::Z,
        };
        if !STEP_NAMES.contains(&name.as_str()) {
            let mut e = expr_err(
                at,
                format!("unknown transform `{name}`"),
                format!("expected {}", list(STEP_NAMES)),
            );
            e.help = suggest(&name, STEP_NAMES.iter().map(|n| (*n, None)));
            self.expr_error(&loc, e);
            // Still check the arguments, for their own errors.
            let scope = Scope::transform(what);
            let mut tainted = false;
            for a in &args {
                self.resolve(a, &scope, &loc, &mut tainted);
            }
            return None;
        }
        if args.len() != 1 {
            self.expr_error(
                &loc,
                expr_err(
                    at,
                    format!("`{name}` takes 1 argument, found {}", args.len()),
                    "expected one argument",
                ),
            );
            return None;
        }
        let scope = Scope::transform(what);
        let mut tainted = false;
        let arg = args.into_iter().next()?;
        let e = self.resolve(&arg, &scope, &loc, &mut tainted)?;
        if let Some(bad) = self.non_finite_number(&e) {
            self.non_finite_number_error(&loc.span, bad);
            return None;
        }
        let mut chars = name.chars();
        let kind = chars.next();
        let ax = axis(chars.next().unwrap_or('z'));
        Some(if kind == Some('R') {
            Step::Rot(ax, e)
        } else {
            Step::Trans(ax, e)
        })
    }

    /// The paper's 12-element pose vector `[tx, ty, tz, rx, ry, rz, o1..o6]`: `o_k` is the
    /// (1-based) position at which elementary transform k (Tx, Ty, Tz, Rx, Ry, Rz) is applied.
    pub(super) fn pose_vector(
        &mut self,
        item: &Value<'_>,
        a: &[Value<'_>],
        what: &str,
    ) -> Option<Vec<Step>> {
        const ELEMS: [&str; 6] = ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"];
        if a.len() != 12 {
            let d = self.cx.error(
                &item.span(),
                format!("a pose vector has 12 entries, found {}", a.len()),
                "expected `[x, y, z, rx, ry, rz, o1, o2, o3, o4, o5, o6]`",
            );
            d.help = Some(
                "6 expressions for Tx, Ty, Tz, Rx, Ry, Rz, then the position at which each is applied, a permutation of 1..6: `[x, y, z, rx, ry, rz, 1, 2, 3, 4, 5, 6]` is Tx Ty Tz Rx Ry Rz"
                    .to_string(),
            );
            return None;
        }
        let scope = Scope::transform(what);
        let mut exprs = Vec::new();
        for v in &a[..6] {
            exprs.push(self.expr(v, &scope).map(|r| r.expr));
        }
        let mut order = Vec::new();
        let mut order_ok = true;
        for (k, v) in a[6..].iter().enumerate() {
            match v.get_ref() {
                DeValue::Integer(i) if i.radix() == 10 => {
                    order.push(i.as_str().parse::<i64>().unwrap_or(0))
                }
                other => {
                    self.cx.error(
                        &v.span(),
                        format!(
                            "entry {} of a pose vector's order must be an integer 1..6, found {}",
                            k + 7,
                            type_name(other)
                        ),
                        format!("position at which {} is applied", ELEMS[k]),
                    );
                    order_ok = false;
                }
            }
        }
        if order_ok {
            let mut problems = Vec::new();
            let mut count = [0usize; 6];
            for &o in &order {
                if (1..=6).contains(&o) {
                    count[(o - 1) as usize] += 1;
                } else if !problems
                    .iter()
                    .any(|p: &String| p.starts_with(&format!("{o} ")))
                {
                    problems.push(format!("{o} is out of range"));
                }
            }
            for (v, &c) in count.iter().enumerate() {
                if c == 2 {
                    problems.push(format!("{} appears twice", v + 1));
                } else if c > 2 {
                    problems.push(format!("{} appears {c} times", v + 1));
                }
            }
            let missing: Vec<String> = (0..6)
                .filter(|v| count[*v] == 0)
                .map(|v| (v + 1).to_string())
                .collect();
            match missing.len() {
                0 => {}
                1 => problems.push(format!("{} is missing", missing[0])),
                n => problems.push(format!(
                    "{} and {} are missing",
                    missing[..n - 1].join(", "),
                    missing[n - 1]
                )),
            }
            if !problems.is_empty() {
                let (first, last) = (a[6].span(), a[11].span());
                let span = if self.cx.line(&first) == self.cx.line(&last) {
                    first.start..last.end
                } else {
                    first
                };
                let shown: Vec<String> = order.iter().map(|o| o.to_string()).collect();
                let d = self.cx.error(
                    &span,
                    format!(
                        "the order `[{}]` of a pose vector is not a permutation of 1..6",
                        shown.join(", ")
                    ),
                    problems.join("; "),
                );
                d.help = Some(
                    "entry k is the position at which the k-th transform (Tx, Ty, Tz, Rx, Ry, Rz) is applied: `1, 2, 3, 4, 5, 6` is Tx Ty Tz Rx Ry Rz, `4, 5, 6, 1, 2, 3` is Rx Ry Rz Tx Ty Tz"
                        .to_string(),
                );
                order_ok = false;
            }
        }
        let exprs: Vec<Expr> = exprs.into_iter().collect::<Option<Vec<_>>>()?;
        if !order_ok {
            return None;
        }
        let mut slots: Vec<Option<Step>> = vec![None; 6];
        for (k, e) in exprs.into_iter().enumerate() {
            let ax = [Axis::X, Axis::Y, Axis::Z][k % 3];
            let step = if k < 3 {
                Step::Trans(ax, e)
            } else {
                Step::Rot(ax, e)
            };
            let slot = usize::try_from(order[k] - 1).ok()?;
            *slots.get_mut(slot)? = Some(step);
        }
        slots.into_iter().collect()
    }

    // ---- mass properties --------------------------------------------------------------------
}
