//! `[[loop]]`: loop closures, their attachments and components.

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn loops(&mut self, v: &Value<'_>) -> Option<Vec<Loop>> {
        let items = match v.get_ref() {
            DeValue::Array(a) => a,
            other => {
                self.cx.error(
                    &v.span(),
                    format!(
                        "`loop` must be an array of tables `[[loop]]`, found {}",
                        type_name(other)
                    ),
                    "expected `[[loop]]`",
                );
                return None;
            }
        };
        if items.is_empty() {
            self.cx.error(
                &v.span(),
                "the model has no loop closure",
                "expected at least one `[[loop]]`",
            );
            return None;
        }
        let mut names: HashMap<String, usize> = HashMap::new();
        let mut out = Vec::new();
        let mut ok = true;
        for item in items {
            let l = self.one_loop(item, &mut names);
            ok &= l.is_some();
            out.extend(l);
        }
        ok.then_some(out)
    }

    pub(super) fn one_loop(
        &mut self,
        item: &Value<'_>,
        names: &mut HashMap<String, usize>,
    ) -> Option<Loop> {
        let t = self.table(item, "a `[[loop]]` entry")?;
        let span = item.span();
        self.check_keys(t, &span, LOOP_KEYS, "`[[loop]]`");
        let name_v = self.required(t, &span, "name", "`[[loop]]`");
        let mut name = name_v.and_then(|v| self.name(v, "loop"));
        if let (Some(n), Some(nv)) = (&name, name_v) {
            if let Some(first) = names.get(n) {
                let d = self.cx.error(
                    &nv.span(),
                    format!("loop `{n}` is defined twice"),
                    "redefined here",
                );
                d.help = Some(format!("loop `{n}` is first defined on line {first}"));
                name = None;
            } else {
                names.insert(n.clone(), self.cx.line(&nv.span()));
            }
        }
        let shown = name.clone().unwrap_or_else(|| "?".to_string());
        let a_v = self.required(t, &span, "a", &format!("loop `{shown}`"));
        let b_v = self.required(t, &span, "b", &format!("loop `{shown}`"));
        let a = a_v.and_then(|a| self.attachment(a, &shown, "a"));
        let b = b_v.and_then(|b| self.attachment(b, &shown, "b"));
        let components = match get(t, "components") {
            None => Some(vec![Axis::X, Axis::Y, Axis::Z]),
            Some(cv) => self.components(cv, &shown),
        };
        let weld = match get(t, "kind") {
            None => Some(false),
            Some(kv) => match self.string(kv, &format!("the kind of loop `{shown}`")) {
                Some(k) if k == "point" => Some(false),
                Some(k) if k == "weld" => Some(true),
                Some(k) => {
                    let d = self.cx.error(
                        &kv.span(),
                        format!("loop `{shown}` has unknown kind `{k}`"),
                        "expected \"point\" or \"weld\"",
                    );
                    d.help = Some(
                        "\"point\" (the default): the two points coincide; \"weld\": the two \
                         frames coincide, their orientations too (three more equations)"
                            .to_string(),
                    );
                    None
                }
                None => None,
            },
        };
        let (a, b) = (a?, b?);
        if a.body == b.body
            && a.steps.len() == b.steps.len()
            && a.steps.iter().zip(&b.steps).all(|(x, y)| step_eq(x, y))
        {
            let bv = b_v?;
            let a_line = a_v.map(|a| self.cx.line(&a.span())).unwrap_or(0);
            let d = self.cx.error(
                &bv.span(),
                format!("both sides of loop `{shown}` are the same point"),
                format!("the same attachment as `a` (line {a_line})"),
            );
            d.help = Some(
                "`a` and `b` must be two different points (the origin of `body * transforms`) that the loop makes coincide"
                    .to_string(),
            );
            return None;
        }
        let site = |v: Option<&Value<'_>>| {
            v.and_then(|v| v.get_ref().as_table())
                .and_then(|t| get(t, "body"))
                .map_or(span.clone(), |b| b.span())
        };
        let sites = [site(a_v), site(b_v)];
        let l = Loop {
            name: name?,
            a,
            b,
            components: components?,
            weld: weld?,
            pos: self
                .cx
                .pos(name_v.map(|v| v.span().start).unwrap_or(span.start)),
        };
        self.loop_sites.push(sites);
        Some(l)
    }

    pub(super) fn attachment(
        &mut self,
        v: &Value<'_>,
        loop_name: &str,
        side: &str,
    ) -> Option<Attachment> {
        let what = format!("`{side}` of loop `{loop_name}`");
        let t = self.table(v, &what)?;
        self.check_keys(t, &v.span(), ATTACH_KEYS, &what);
        let body_v = self.required(t, &v.span(), "body", &what)?;
        let body = self.string(body_v, &format!("the body of {what}"));
        let body = body.and_then(|b| {
            if b == "world" {
                return Some(None);
            }
            match self.bodies.get(&b) {
                Some(info) => Some(Some(info.index)),
                None => {
                    let help = self.body_suggestion(&b);
                    let d = self.cx.error(
                        &body_v.span(),
                        format!("{what} names unknown body `{b}`"),
                        "not defined in this model",
                    );
                    d.help = help;
                    None
                }
            }
        });
        let steps = match get(t, "transforms") {
            Some(tv) => self.steps(tv, &format!("the transforms of {what}")),
            None => Some(Vec::new()),
        };
        Some(Attachment {
            body: body?,
            steps: steps?,
        })
    }

    pub(super) fn components(&mut self, v: &Value<'_>, loop_name: &str) -> Option<Vec<Axis>> {
        let items = self.array(v, &format!("the components of loop `{loop_name}`"))?;
        if items.is_empty() {
            self.cx.error(
                &v.span(),
                format!("the components of loop `{loop_name}` are empty"),
                "expected some of `x`, `y`, `z`",
            );
            return None;
        }
        let mut out = Vec::new();
        let mut ok = true;
        for item in items {
            let Some(s) = self.string(item, &format!("a component of loop `{loop_name}`")) else {
                ok = false;
                continue;
            };
            let axis = match s.as_str() {
                "x" => Axis::X,
                "y" => Axis::Y,
                "z" => Axis::Z,
                _ => {
                    let d = self.cx.error(
                        &item.span(),
                        format!("unknown component `{s}`"),
                        "expected `x`, `y` or `z`",
                    );
                    d.help = Some(
                        "components are the world axes along which the two points must coincide"
                            .to_string(),
                    );
                    ok = false;
                    continue;
                }
            };
            if out.contains(&axis) {
                self.cx.error(
                    &item.span(),
                    format!("component `{s}` is listed twice"),
                    "listed again here",
                );
                ok = false;
                continue;
            }
            out.push(axis);
        }
        ok.then_some(out)
    }
}
