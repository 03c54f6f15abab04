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
        let kind_v = get(t, "kind");
        let tag = match kind_v {
            None => Some(Tag::Point),
            Some(kv) => match self.string(kv, &format!("the kind of loop `{shown}`")) {
                Some(k) => match Tag::from_name(&k) {
                    Some(tag) => Some(tag),
                    None => {
                        let d = self.cx.error(
                            &kv.span(),
                            format!("loop `{shown}` has unknown kind `{k}`"),
                            format!("expected {}", list(Tag::NAMES)),
                        );
                        d.help = Some(
                            "\"point\" (the default, alias \"ball\"): the two points coincide; \
                             \"weld\": the two frames coincide; \"hinge\": a point and an axis; \
                             \"distance\": a rod of `length`; \"coupling\": two coordinates \
                             geared (`ratio`, `offset`, or a polynomial `poly`); \"point_in_plane\", \"point_on_line\": \
                             `components` constrained, the others free"
                                .to_string(),
                        );
                        None
                    }
                },
                None => None,
            },
        };
        // Keys that belong to other kinds.
        if let Some(tag) = tag {
            for key in [
                "components",
                "frame",
                "length",
                "ratio",
                "offset",
                "poly",
                "axis",
            ] {
                if !tag.allows(key) {
                    let Some(ks) = key_span(t, key) else { continue };
                    let d = self.cx.error(
                        &ks,
                        format!("loop `{shown}` of kind \"{}\" has no `{key}`", tag.name()),
                        "not used by this kind",
                    );
                    d.help = Some(format!("`{key}` belongs to {}", Tag::owners(key)));
                }
            }
        }
        if tag == Some(Tag::Coupling) {
            return self.coupling(t, &span, name, name_v, &shown);
        }
        let a_v = self.required(t, &span, "a", &format!("loop `{shown}`"));
        let b_v = self.required(t, &span, "b", &format!("loop `{shown}`"));
        let a = a_v.and_then(|a| self.attachment(a, &shown, "a"));
        let b = b_v.and_then(|b| self.attachment(b, &shown, "b"));
        let components = match (get(t, "components"), tag) {
            (_, Some(Tag::Distance)) => Some(Vec::new()),
            (Some(cv), _) => self.components(cv, &shown),
            (None, Some(Tag::InPlane)) => Some(vec![Axis::Z]),
            (None, Some(Tag::OnLine)) => Some(vec![Axis::X, Axis::Y]),
            (None, _) => Some(vec![Axis::X, Axis::Y, Axis::Z]),
        };
        // A plane is one equation, a line two.
        if let (Some(c), Some(cv), Some(tag @ (Tag::InPlane | Tag::OnLine))) =
            (&components, get(t, "components"), tag)
        {
            let want = if tag == Tag::InPlane { 1 } else { 2 };
            if c.len() != want {
                let d = self.cx.error(
                    &cv.span(),
                    format!(
                        "loop `{shown}` of kind \"{}\" constrains {want} component{}, found {}",
                        tag.name(),
                        if want == 1 { "" } else { "s" },
                        c.len()
                    ),
                    format!("expected {want}"),
                );
                d.help = Some(
                    "\"point_in_plane\": the plane's normal (`components = [\"z\"]`: the plane \
                     x-y of `frame`); \"point_on_line\": the two axes across the line \
                     (`[\"x\", \"y\"]`: the line along z)"
                        .to_string(),
                );
            }
        }
        let frame = match get(t, "frame") {
            None => Some(None),
            Some(fv) => match self.string(fv, &format!("the frame of loop `{shown}`")) {
                Some(f) if f == "world" => Some(None),
                Some(f) if f == "a" => Some(Some(Side::A)),
                Some(f) if f == "b" => Some(Some(Side::B)),
                Some(f) => {
                    let d = self.cx.error(
                        &fv.span(),
                        format!("loop `{shown}` has unknown frame `{f}`"),
                        "expected \"world\", \"a\" or \"b\"",
                    );
                    d.help = Some(
                        "`components` are taken along the axes of the world (the default) or of \
                         the frame of attachment `a` or `b` (`body * transforms`)"
                            .to_string(),
                    );
                    None
                }
                None => None,
            },
        };
        let kind = match tag? {
            Tag::Point => Some(LoopKind::Point),
            Tag::InPlane | Tag::OnLine => Some(LoopKind::Sliding),
            Tag::Weld => Some(LoopKind::Weld),
            Tag::Hinge => match get(t, "axis") {
                None => Some(LoopKind::Hinge(Axis::Z)),
                Some(av) => self
                    .axis_name(av, &format!("the axis of loop `{shown}`"))
                    .map(LoopKind::Hinge),
            },
            Tag::Distance => {
                let what = format!("the length of loop `{shown}`");
                self.required(t, &span, "length", &format!("loop `{shown}`"))
                    .and_then(|lv| {
                        self.finite(lv, &Scope::constant(&what)).and_then(|(e, l, bad)| {
                            if !bad && l <= 0.0 {
                                let d = self.cx.error(
                                    &lv.span(),
                                    format!("{what} must be positive"),
                                    format!("evaluates to {}", fmt_num(l)),
                                );
                                d.help = Some(
                                    "a rod between the two points: `|origin(a) - origin(b)| = length`, \
                                     evaluated with the parameters' default values"
                                        .to_string(),
                                );
                                return None;
                            }
                            Some(LoopKind::Distance(e))
                        })
                    })
            }
            Tag::Coupling => unreachable!("handled above"),
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
            frame: frame?,
            kind: kind?,
            pos: self
                .cx
                .pos(name_v.map(|v| v.span().start).unwrap_or(span.start)),
        };
        self.loop_sites.push(sites);
        Some(l)
    }

    /// A `kind = "coupling"` loop: `a = p(b)` between two expressions of the coordinates, `p`
    /// from `ratio` and `offset` (`ratio * b + offset`) or from `poly` (`c0 + c1 b + …`).
    fn coupling(
        &mut self,
        t: &DeTable<'_>,
        span: &Span,
        name: Option<String>,
        name_v: Option<&Value<'_>>,
        shown: &str,
    ) -> Option<Loop> {
        let a_v = self.required(t, span, "a", &format!("loop `{shown}`"));
        let b_v = get(t, "b");
        let ca = a_v.and_then(|v| self.coupling_side(v, shown, "a"));
        let cb = b_v.map(|v| self.coupling_side(v, shown, "b"));
        let poly_v = get(t, "poly");
        let mut ok = true;
        // `poly` or `ratio` and `offset`: one spelling of the polynomial.
        if poly_v.is_some() {
            for key in ["ratio", "offset"] {
                let Some(ks) = key_span(t, key) else { continue };
                let d = self.cx.error(
                    &ks,
                    format!("loop `{shown}` has both `poly` and `{key}`"),
                    "give one or the other",
                );
                d.help = Some(
                    "`poly = [c0, c1, c2, …]` is `a = c0 + c1 b + c2 b² + …`; `ratio` and \
                     `offset` are its linear case, `poly = [offset, ratio]`"
                        .to_string(),
                );
                ok = false;
            }
        }
        let what = format!("the ratio of loop `{shown}`");
        let ratio = match get(t, "ratio") {
            None => Some(Expr::int(1)),
            Some(rv) => self
                .finite(rv, &Scope::constant(&what))
                .and_then(|(e, r, bad)| {
                    if !bad && r == 0.0 {
                        let d =
                            self.cx
                                .error(&rv.span(), format!("{what} is zero"), "evaluates to 0");
                        d.help = Some(
                            "`a = ratio * b + offset`: with a zero ratio `a` is a constant; \
                             remove the coordinate instead"
                                .to_string(),
                        );
                        return None;
                    }
                    Some(e)
                }),
        };
        let what = format!("the offset of loop `{shown}`");
        let offset = match get(t, "offset") {
            None => Some(Expr::int(0)),
            Some(ov) => self.finite(ov, &Scope::constant(&what)).map(|r| r.0),
        };
        let poly = match poly_v {
            None => match (ratio, offset) {
                // Without `b`, `a = offset` (a ratio is reported below).
                (Some(r), Some(o)) if b_v.is_some() => Some(vec![o, r]),
                (_, Some(o)) => Some(vec![o]),
                _ => None,
            },
            Some(pv) => self.poly(pv, shown, b_v.is_some()),
        };
        if b_v.is_none() {
            let extra = match (get(t, "ratio"), poly_v) {
                (Some(rv), _) => Some((rv.span(), "a `ratio`".to_string())),
                (None, Some(pv)) => match pv.get_ref() {
                    DeValue::Array(items) if items.len() > 1 => {
                        Some((pv.span(), format!("{} coefficients", items.len())))
                    }
                    _ => None,
                },
                (None, None) => None,
            };
            if let Some((at, what)) = extra {
                let d = self.cx.error(
                    &at,
                    format!("coupling `{shown}` has {what} but no `b`"),
                    "nothing to multiply",
                );
                d.help = Some(
                    "without `b` a coupling holds `a` at a constant: `a = offset` (or \
                     `poly = [c0]`); name the other side with `b`"
                        .to_string(),
                );
                ok = false;
            }
        }
        let ca = ca?;
        let cb = match cb {
            Some(side) => Some(side?),
            None => None,
        };
        if let (Some(cb), Some(bv)) = (&cb, b_v)
            && ca == *cb
        {
            let what = if matches!(ca, Expr::Coord(_)) {
                "coordinate"
            } else {
                "expression"
            };
            self.cx.error(
                &bv.span(),
                format!("both sides of coupling `{shown}` are the same {what}"),
                format!("the same {what} as `a`"),
            );
            return None;
        }
        let here = name_v.map(|v| v.span()).unwrap_or(span.clone());
        self.loop_sites.push([here.clone(), here]);
        let poly = poly?;
        if !ok {
            return None;
        }
        Some(Loop {
            name: name?,
            a: Attachment {
                body: None,
                steps: Vec::new(),
            },
            b: Attachment {
                body: None,
                steps: Vec::new(),
            },
            components: Vec::new(),
            frame: None,
            kind: LoopKind::Coupling { a: ca, b: cb, poly },
            pos: self
                .cx
                .pos(name_v.map(|v| v.span().start).unwrap_or(span.start)),
        })
    }

    /// A coupling's `poly`: one or more constant expressions, `c0` first; with `b`, not all of
    /// `c1, c2, …` zero.
    fn poly(&mut self, v: &Value<'_>, shown: &str, with_b: bool) -> Option<Vec<Expr>> {
        let what = format!("the polynomial of loop `{shown}`");
        let items = self.array(v, &what)?;
        if items.is_empty() {
            let d = self.cx.error(
                &v.span(),
                format!("{what} is empty"),
                "expected [c0, c1, …]",
            );
            d.help = Some("`poly = [c0, c1, c2, …]`: `a = c0 + c1 b + c2 b² + …`".to_string());
            return None;
        }
        let mut out = Vec::with_capacity(items.len());
        let mut constant_b = with_b && items.len() > 1;
        for (k, item) in items.iter().enumerate() {
            let what_k = format!("{what} (c{k})");
            let (e, value, bad) = self.finite(item, &Scope::constant(&what_k))?;
            if k > 0 && (bad || value != 0.0) {
                constant_b = false;
            }
            out.push(e);
        }
        if constant_b || (with_b && items.len() == 1) {
            let d = self.cx.error(
                &v.span(),
                format!("{what} does not depend on `b`"),
                "c1, c2, … evaluate to 0",
            );
            d.help = Some(
                "`a = c0 + c1 b + c2 b² + …`: with no term in `b`, `a` is a constant; remove \
                 `b` (the coupling then holds `a` at `c0`)"
                    .to_string(),
            );
            return None;
        }
        Some(out)
    }

    /// A coupling's side: a coordinate's name, or an expression of the coordinates (`"2 * q1 +
    /// 0.5 * q3"`, a fixed tendon's length).
    fn coupling_side(&mut self, v: &Value<'_>, loop_name: &str, side: &str) -> Option<Expr> {
        let is_name = v.get_ref().as_str().is_some_and(|s| {
            s.chars()
                .next()
                .is_some_and(|c| c.is_alphabetic() || c == '_')
                && s.chars().all(|c| c.is_alphanumeric() || c == '_')
        });
        if is_name {
            return self.coordinate_ref(v, loop_name, side).map(Expr::Coord);
        }
        let what = format!("`{side}` of coupling `{loop_name}`");
        let r = self.expr(v, &Scope::transform(&what))?;
        if r.expr.is_constant() {
            let d = self.cx.error(
                &v.span(),
                format!("{what} does not depend on any coordinate"),
                "a constant",
            );
            d.help = Some(
                "a coupling relates two expressions of the coordinates: a coordinate's name, \
                 or e.g. `\"2 * q1 + 0.5 * q3\"`; a constant side is the `offset`"
                    .to_string(),
            );
            return None;
        }
        Some(r.expr)
    }

    /// A coupling's side: the name of a coordinate.
    fn coordinate_ref(&mut self, v: &Value<'_>, loop_name: &str, side: &str) -> Option<usize> {
        let what = format!("`{side}` of coupling `{loop_name}`");
        let name = self.string(v, &what)?;
        match self.syms.get(&name) {
            Some(Sym {
                kind: SymKind::Coord,
                index,
                ..
            }) => {
                let index = *index;
                if let Some(u) = self.coord_used.get_mut(index) {
                    *u = true;
                }
                Some(index)
            }
            _ => {
                let candidates: Vec<(String, Option<usize>)> = self
                    .sym_list
                    .iter()
                    .filter(|(_, _, k)| *k == SymKind::Coord)
                    .map(|(n, l, _)| (n.clone(), Some(*l)))
                    .collect();
                let help = suggest(&name, candidates.iter().map(|(n, l)| (n.as_str(), *l)));
                let d = self.cx.error(
                    &v.span(),
                    format!("{what} names unknown coordinate `{name}`"),
                    "not a coordinate",
                );
                d.help = help.or(Some(
                    "a coupling relates two coordinates: `a = ratio * b + offset`".to_string(),
                ));
                None
            }
        }
    }

    /// `"x"`, `"y"` or `"z"`.
    fn axis_name(&mut self, v: &Value<'_>, what: &str) -> Option<Axis> {
        let s = self.string(v, what)?;
        match s.as_str() {
            "x" => Some(Axis::X),
            "y" => Some(Axis::Y),
            "z" => Some(Axis::Z),
            _ => {
                self.cx.error(
                    &v.span(),
                    format!("{what} is `{s}`"),
                    "expected `x`, `y` or `z`",
                );
                None
            }
        }
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
                        "components are the axes (of the world, or of `frame`) along which the two \
                         points must coincide"
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

/// The `kind` of a `[[loop]]` as written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tag {
    Point,
    InPlane,
    OnLine,
    Weld,
    Hinge,
    Distance,
    Coupling,
}

impl Tag {
    const NAMES: &'static [&'static str] = &[
        "point",
        "ball",
        "weld",
        "hinge",
        "distance",
        "coupling",
        "point_in_plane",
        "point_on_line",
    ];

    fn from_name(s: &str) -> Option<Tag> {
        Some(match s {
            "point" | "ball" => Tag::Point,
            "point_in_plane" => Tag::InPlane,
            "point_on_line" => Tag::OnLine,
            "weld" => Tag::Weld,
            "hinge" => Tag::Hinge,
            "distance" => Tag::Distance,
            "coupling" => Tag::Coupling,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Tag::Point => "point",
            Tag::InPlane => "point_in_plane",
            Tag::OnLine => "point_on_line",
            Tag::Weld => "weld",
            Tag::Hinge => "hinge",
            Tag::Distance => "distance",
            Tag::Coupling => "coupling",
        }
    }

    /// Whether a loop of this kind takes the optional key `key`.
    fn allows(self, key: &str) -> bool {
        match key {
            "components" | "frame" => !matches!(self, Tag::Distance | Tag::Coupling),
            "length" => self == Tag::Distance,
            "ratio" | "offset" | "poly" => self == Tag::Coupling,
            "axis" => self == Tag::Hinge,
            _ => true,
        }
    }

    /// The kinds that take `key`, for a message.
    fn owners(key: &str) -> String {
        let all = [
            Tag::Point,
            Tag::Weld,
            Tag::Hinge,
            Tag::InPlane,
            Tag::OnLine,
            Tag::Distance,
            Tag::Coupling,
        ];
        let names: Vec<String> = all
            .into_iter()
            .filter(|t| t.allows(key))
            .map(|t| format!("\"{}\"", t.name()))
            .collect();
        format!("kind {}", names.join(", "))
    }
}
