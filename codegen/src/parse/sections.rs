//! The document and its sections: `[codegen]`, names, `[parameters]`, `coordinates`, `[robot]`.

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn model(&mut self, root: &DeTable<'_>) -> Option<Model> {
        // `[rename]` renames an imported source's names (crate::import::merge); a model
        // reaching here with one imports none.
        if let Some((k, _)) = root
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == crate::import::merge::RENAME)
        {
            self.skip_keys.push(k.span().start);
            let d = self.cx.error(
                &k.span(),
                "`rename` renames the joints and bodies of an imported source, but this model imports none",
                "no `urdf`, `mjcf` or `sdf` key",
            );
            d.help = Some("name the source at the top: `urdf = \"arm.urdf\"`".into());
        }
        self.check_keys(root, &(0..0), TOP_KEYS, "at the top level");
        let top = Pos { line: 1, col: 1 };

        // Names first: parameters and coordinates share one namespace, in file order.
        let params_table = match get(root, "parameters") {
            Some(v) => self.table(v, "`parameters`"),
            None => None,
        };
        let mut coords_v = get(root, "coordinates");
        if coords_v.is_none() {
            // `coordinates = [...]` written after a `[table]` header belongs to that table.
            for table in ["parameters", "robot"] {
                if let Some(t) = get(root, table).and_then(|v| v.get_ref().as_table())
                    && let Some((k, v)) = t
                        .iter()
                        .find(|(k, _)| k.get_ref().as_ref() == "coordinates")
                    && v.get_ref().is_array()
                {
                    let d = self.cx.error(
                        &k.span(),
                        format!("`coordinates` must be a top-level key, but here it is inside `[{table}]`"),
                        format!("TOML puts every key after `[{table}]` into that table"),
                    );
                    d.help = Some(
                        "move `coordinates = [...]` above the first `[table]` header".to_string(),
                    );
                    self.skip_keys.push(k.span().start);
                    coords_v = Some(v);
                    break;
                }
            }
        }
        let coord_items = match coords_v {
            Some(v) => self.array(v, "`coordinates`"),
            None => {
                let d = self.cx.error_at(top, 1, "missing `coordinates`", "");
                d.help = Some(
                    "add `coordinates = [{ name = \"q1\", unit = \"rad\", home = 0 }, ...]` above the first `[table]` header"
                        .to_string(),
                );
                None
            }
        };
        // A coordinate whose name is taken or reserved: the counts below would mislead.
        let coord_names_ok = self.declare_names(params_table, coord_items);

        let parameters = match params_table {
            Some(t) => self.parameters(t),
            None => Some(Vec::new()),
        };
        let errors_before = self.errors();
        let coordinates = coord_items
            .map(|items| self.coordinates(items))
            .unwrap_or(None);
        let coords_ok = coordinates.is_some() && self.errors() == errors_before && coord_names_ok;

        let robot = match get(root, "robot") {
            Some(v) => self.robot(v),
            None => {
                let d = self.cx.error_at(top, 1, "missing table `[robot]`", "");
                d.help = Some(
                    "add `[robot]` with `name`, `gravity` and `actuated` (and `outputs` for inverse kinematics)".to_string(),
                );
                None
            }
        };

        if let Some(v) = get(root, "frames") {
            self.frames(v);
        }
        let errors_before = self.errors();
        let bodies = match get(root, "body") {
            Some(v) => self.bodies(v),
            None => {
                let d = self.cx.error_at(top, 1, "the model has no bodies", "");
                d.help = Some("add a `[[body]]` with `name` and `transforms`".to_string());
                None
            }
        };
        // No `[[loop]]`: a serial arm or a tree (m = 0).
        let loops = match get(root, "loop") {
            Some(v) => self.loops(v),
            None => Some(Vec::new()),
        };
        // A `free` joint's quaternion has unit norm: one `unit_norm` loop per free joint, named
        // `{body}_quat`, after the model's own loops.
        let mut loops = match (loops, &bodies) {
            (Some(mut ls), Some(bs)) => {
                for b in bs {
                    for st in &b.steps {
                        let Step::Quat(q) = st else { continue };
                        let idx: Vec<usize> = q
                            .iter()
                            .filter_map(|e| match e {
                                Expr::Coord(i) => Some(*i),
                                _ => None,
                            })
                            .collect();
                        let Ok(idx) = <[usize; 4]>::try_from(idx) else {
                            continue;
                        };
                        let world = Attachment {
                            body: None,
                            steps: Vec::new(),
                        };
                        ls.push(Loop {
                            name: format!("{}_quat", b.name),
                            a: world.clone(),
                            b: world,
                            components: Vec::new(),
                            frame: None,
                            kind: LoopKind::UnitNorm(idx),
                            pos: b.pos,
                        });
                    }
                }
                Some(ls)
            }
            (l, _) => l,
        };
        // Task frames in `outputs`: their coordinates and closures, now that the bodies are known.
        let mut coordinates = coordinates;
        if !self.frame_outputs.is_empty() {
            match (&mut coordinates, &bodies, &mut loops) {
                (Some(c), Some(b), Some(l)) => {
                    self.expand_frame_outputs(c, b, l);
                }
                _ => self.frame_outputs.clear(),
            }
        }
        let structure_ok = self.errors() == errors_before;

        // Every coordinate must move something.
        if structure_ok
            && let Some(items) = coord_items
            && coords_ok
        {
            for (i, item) in items.iter().enumerate() {
                if self.coord_used.get(i).copied().unwrap_or(true) {
                    continue;
                }
                if let Some(name_v) = item.get_ref().as_table().and_then(|t| get(t, "name")) {
                    let name = name_v.get_ref().as_str().unwrap_or("").to_string();
                    let d = self.cx.error(
                        &name_v.span(),
                        format!("coordinate `{name}` is not used by any transform"),
                        "declared here, never used",
                    );
                    d.help = Some("use it in a `transforms` step of a body or a loop attachment, or remove it".to_string());
                }
            }
        }

        // Degrees of freedom.
        if let (Some(coords), Some(loops), Some(robot)) = (&coordinates, &loops, &robot)
            && coords_ok
            && structure_ok
            && let Some((actuated, span)) = &robot.actuated
        {
            let n = coords.len();
            let m: usize = loops.iter().map(|l| l.equations()).sum();
            let k = actuated.len();
            // Fewer actuated coordinates than degrees of freedom: the others are passive (a
            // spring joint with no drive); more is no mechanism.
            if n.checked_sub(m).is_none_or(|dof| k > dof) {
                let dof = n as i64 - m as i64;
                let d = self.cx.error(
                    span,
                    format!(
                        "the model has {n} coordinates and {m} constraint equations, so {dof} degree{} of freedom, but {k} actuated coordinate{}",
                        if dof == 1 { "" } else { "s" },
                        if k == 1 { "" } else { "s" }
                    ),
                    "at most one actuated coordinate per degree of freedom",
                );
                d.help = Some(
                    "each `[[loop]]` adds one equation per entry of `components` (3 by default: x, y, z), a `kind = \"weld\"` loop 3 more (its rotation), a \"hinge\" 2 more (its axis), a \"distance\" or \"coupling\" one in all".to_string(),
                );
            }
        }

        // One output per degree of freedom: inverse kinematics holds the outputs and solves the
        // loops for every other coordinate, so the others must number the equations.
        if let (Some(coords), Some(loops), Some(robot)) = (&coordinates, &loops, &robot)
            && coords_ok
            && structure_ok
            && let Some(outputs) = &robot.outputs
            && !outputs.is_empty()
        {
            let n = coords.len();
            let m: usize = loops.iter().map(|l| l.equations()).sum();
            let k = outputs.len();
            // (More equations than coordinates: reported above with the actuated ones.)
            if n.checked_sub(m).is_some_and(|dof| dof != k) {
                let dof = n as i64 - m as i64;
                let shared: Vec<String> = outputs
                    .iter()
                    .filter(|o| robot.actuated.as_ref().is_some_and(|(a, _)| a.contains(o)))
                    .map(|&o| format!("`{}`", coords[o].name))
                    .collect();
                let d = self.cx.error(
                    &robot.outputs_key,
                    format!(
                        "`outputs` names {k} coordinate{}, but the model has {n} coordinates and {m} constraint equations, so {dof} degree{} of freedom",
                        if k == 1 { "" } else { "s" },
                        if dof == 1 { "" } else { "s" }
                    ),
                    "one output per degree of freedom",
                );
                d.help = Some(if shared.is_empty() {
                    "inverse kinematics holds the outputs and solves the loops for every other coordinate: name one output per degree of freedom (an actuated coordinate in no loop, such as a hip above a knee's loop or a gripper's slide, is an output too: a coordinate may be both), or leave `outputs` out (dynamics, simulation and the energy need none)".to_string()
                } else {
                    format!(
                        "{} {} actuated as well: a coordinate may be both (inverse kinematics then takes it as given), but it still counts as an output",
                        shared.join(", "),
                        if shared.len() == 1 { "is" } else { "are" }
                    )
                });
            }
        }

        // A gear drives a coordinate through its actuator: only actuated coordinates have one.
        if let (Some(coords), Some(robot)) = (&coordinates, &robot)
            && let Some((actuated, _)) = &robot.actuated
        {
            for (name, span) in std::mem::take(&mut self.gear_at) {
                let Some(j) = coords.iter().position(|c| c.name == name) else {
                    continue;
                };
                if !actuated.contains(&j) {
                    let d = self.cx.error(
                        &span,
                        format!("coordinate `{name}` has a gear ratio but is not actuated"),
                        "no actuator to gear",
                    );
                    d.help = Some(format!(
                        "a gear scales an actuator's `U` into the force on its coordinate: add `{name}` to `actuated`, or remove `gear` (a kinematic gear between two coordinates is a `coupling` loop)"
                    ));
                }
            }
        }

        if let Some(v) = get(root, "codegen") {
            self.codegen_section(v);
        }
        let robot = robot?;
        let model = Model {
            name: robot.name?,
            description: robot.description,
            parameters: parameters?,
            coordinates: coordinates?,
            actuated: robot.actuated?.0,
            outputs: robot.outputs?,
            gravity: robot.gravity?,
            bodies: bodies?,
            loops: loops?,
            import: None,
        };
        // Without outputs, a coordinate in no loop is an independent one (a serial arm's
        // joints): only inverse kinematics needs every other coordinate reached by a loop.
        if self.errors() == 0 && !model.outputs.is_empty() {
            let sites = std::mem::take(&mut self.loop_sites);
            self.loop_structure(&model, &sites);
        }
        Some(model)
    }

    /// `[codegen]`: read by earlier versions (a Horner-search effort per model); the generator
    /// now keeps named intermediates and has no such setting, so the section is an error that
    /// says so rather than a silent no-op.
    pub(super) fn codegen_section(&mut self, v: &Value<'_>) {
        self.cx.error(
            &v.span(),
            "`[codegen]` is no longer read".to_string(),
            "remove this section: code generation keeps named intermediates and needs no Horner-search setting",
        );
    }

    /// Declares the parameter and coordinate names (one namespace), reporting duplicates.
    /// Returns `false` if a coordinate's name was rejected (reserved or already taken).
    pub(super) fn declare_names(
        &mut self,
        params: Option<&DeTable<'_>>,
        coords: Option<&[Value<'_>]>,
    ) -> bool {
        let mut coord_names_ok = true;
        // (name, span, kind, index)
        let mut defs: Vec<(String, Span, SymKind, usize)> = Vec::new();
        if let Some(t) = params {
            for (i, (k, _)) in t.iter().enumerate() {
                if self.skip_keys.contains(&k.span().start) {
                    continue;
                }
                defs.push((k.get_ref().to_string(), k.span(), SymKind::Param, i));
            }
            self.param_values = vec![f64::NAN; t.len()];
            self.param_bad = vec![true; t.len()];
        }
        if let Some(items) = coords {
            for (i, item) in items.iter().enumerate() {
                if let Some(v) = item.get_ref().as_table().and_then(|t| get(t, "name"))
                    && let DeValue::String(s) = v.get_ref()
                {
                    defs.push((s.to_string(), v.span(), SymKind::Coord, i));
                }
            }
            self.coord_count = items.len();
            self.coord_used = vec![false; items.len()];
        }
        defs.sort_by_key(|d| d.1.start);
        for (name, span, kind, index) in defs {
            let kind_name = if kind == SymKind::Param {
                "parameter"
            } else {
                "coordinate"
            };
            if name == "pi" || FUNC_NAMES.contains(&name.as_str()) {
                let what = if name == "pi" {
                    "a built-in constant"
                } else {
                    "a built-in function"
                };
                self.cx.error(
                    &span,
                    format!("`{name}` is {what} and cannot name a {kind_name}"),
                    "reserved name",
                );
                coord_names_ok &= kind != SymKind::Coord;
                continue;
            }
            let line = self.cx.line(&span);
            if let Some(first) = self.syms.get(&name) {
                let first_kind = if first.kind == SymKind::Param {
                    "parameter"
                } else {
                    "coordinate"
                };
                let help = format!(
                    "`{name}` is first defined as a {first_kind} on line {} (parameters and coordinates share one namespace)",
                    first.line
                );
                let d = self.cx.error(
                    &span,
                    format!("the name `{name}` is defined twice"),
                    format!("{kind_name} `{name}` redefined here"),
                );
                d.help = Some(help);
                coord_names_ok &= kind != SymKind::Coord;
                continue;
            }
            self.syms.insert(name.clone(), Sym { kind, index, line });
            self.sym_list.push((name, line, kind));
        }
        coord_names_ok
    }

    pub(super) fn parameters(&mut self, t: &DeTable<'_>) -> Option<Vec<Parameter>> {
        let mut out = Vec::new();
        let mut ok = true;
        for (i, (k, v)) in t.iter().enumerate() {
            if self.skip_keys.contains(&k.span().start) {
                continue;
            }
            let p = self.parameter(i, k, v);
            ok &= p.is_some();
            out.extend(p);
        }
        ok.then_some(out)
    }

    pub(super) fn parameter(
        &mut self,
        i: usize,
        k: &Spanned<std::borrow::Cow<'_, str>>,
        v: &Value<'_>,
    ) -> Option<Parameter> {
        let name = k.get_ref().to_string();
        let mut name_ok = true;
        if !is_identifier(&name) {
            let d = self.cx.error(
                &k.span(),
                format!("`{name}` is not a valid parameter name"),
                "expected an identifier",
            );
            d.help = Some(
                "a name starts with a letter or `_` and continues with letters, digits or `_`"
                    .to_string(),
            );
            name_ok = false;
        } else if RUST_KEYWORDS.contains(&name.as_str()) {
            self.cx.error(
                &k.span(),
                format!("`{name}` cannot name a parameter: it is a Rust keyword"),
                "names become Rust identifiers",
            );
            name_ok = false;
        }
        let what = format!("the value of parameter `{name}`");
        let (value_v, unit, doc) = match v.get_ref() {
            DeValue::Integer(_) | DeValue::Float(_) | DeValue::String(_) => {
                (v, String::new(), String::new())
            }
            DeValue::Table(t) => {
                self.check_keys(t, &v.span(), PARAM_KEYS, &format!("parameter `{name}`"));
                let unit = match get(t, "unit") {
                    Some(u) => self
                        .string(u, &format!("the unit of parameter `{name}`"))
                        .unwrap_or_default(),
                    None => String::new(),
                };
                let doc = match get(t, "doc") {
                    Some(u) => self
                        .string(u, &format!("the doc of parameter `{name}`"))
                        .unwrap_or_default(),
                    None => String::new(),
                };
                let value_v =
                    self.required(t, &v.span(), "value", &format!("parameter `{name}`"))?;
                (value_v, unit, doc)
            }
            other => {
                let d = self.cx.error(
                    &v.span(),
                    format!(
                        "parameter `{name}` must be a number, an expression string or a table `{{ value = ..., unit = ..., doc = ... }}`, found {}",
                        type_name(other)
                    ),
                    "expected a number, a string or a table",
                );
                if TOP_KEYS.contains(&name.as_str()) {
                    d.help = Some(format!(
                        "`{name}` belongs at the top level: TOML puts every key after `[parameters]` into that table, so move it above the first `[table]` header"
                    ));
                }
                return None;
            }
        };
        let scope = Scope {
            what: &what,
            coords: false,
            params_before: i,
            this_param: Some(i),
        };
        let (mut expr, mut value, tainted) = self.finite(value_v, &scope)?;
        if unit == "deg" {
            expr = deg_to_rad(expr);
            value = self.eval(&expr);
        }
        if let Some(slot) = self.param_values.get_mut(i) {
            *slot = value;
        }
        if let Some(slot) = self.param_bad.get_mut(i) {
            *slot = tainted;
        }
        if !name_ok {
            return None;
        }
        Some(Parameter {
            name,
            expr,
            value,
            unit,
            doc,
            pos: self.cx.pos(k.span().start),
        })
    }

    pub(super) fn coordinates(&mut self, items: &[Value<'_>]) -> Option<Vec<Coordinate>> {
        let mut out = Vec::new();
        let mut ok = true;
        for item in items {
            let c = self.coordinate(item);
            ok &= c.is_some();
            out.extend(c);
        }
        ok.then_some(out)
    }

    pub(super) fn coordinate(&mut self, item: &Value<'_>) -> Option<Coordinate> {
        let t = self.table(item, "a coordinate")?;
        self.check_keys(t, &item.span(), COORD_KEYS, "a coordinate");
        let name_v = self.required(t, &item.span(), "name", "a coordinate");
        let name = name_v.and_then(|v| self.name(v, "coordinate"));
        let shown = name.clone().unwrap_or_else(|| "?".to_string());
        let unit_v = self.required(t, &item.span(), "unit", &format!("coordinate `{shown}`"));
        let unit = match unit_v {
            Some(u) => match self.string(u, &format!("the unit of coordinate `{shown}`")) {
                Some(s) if ["m", "rad", "deg", "1"].contains(&s.as_str()) => Some(s),
                Some(s) => {
                    let d = self.cx.error(
                        &u.span(),
                        format!("unknown unit `{s}` for coordinate `{shown}`"),
                        "expected `m`, `rad`, `deg` or `1` (dimensionless: a quaternion's component)",
                    );
                    d.help = suggest(&s, ["m", "rad", "deg", "1"].iter().map(|u| (*u, None)));
                    None
                }
                None => None,
            },
            None => None,
        };
        let what = format!("the home value of coordinate `{shown}`");
        let home = match get(t, "home") {
            Some(h) => self.finite(h, &Scope::constant(&what)).map(|(_, v, _)| v),
            None => Some(0.0),
        };
        let forces = self.joint_forces(t, &shown, unit.as_deref() == Some("deg"));
        // A wrong gear is reported and left out: the coordinate stays, for the other checks.
        let gear = get(t, "gear").and_then(|v| self.gear(v, &shown));
        let (name, unit, mut home, forces) = (name?, unit?, home?, forces?);
        let unit = if unit == "deg" {
            home = home.to_radians();
            "rad".to_string()
        } else {
            unit
        };
        Some(Coordinate {
            name,
            unit,
            home,
            forces,
            gear,
            pos: self.cx.pos(name_v.map(|v| v.span().start).unwrap_or(0)),
        })
    }

    /// A coordinate's `gear`: a nonzero number, fixed when the robot is generated (it is part
    /// of the structure the solvers are built on, as `actuated` is), so it names no parameter.
    /// Where it is written is kept for the check that the coordinate is actuated.
    fn gear(&mut self, v: &Value<'_>, shown: &str) -> Option<f64> {
        let what = format!("the gear ratio of coordinate `{shown}`");
        let (e, value, _) = self.finite(v, &Scope::constant(&what))?;
        let mut params = false;
        e.for_each_param(&mut |_| params = true);
        if params {
            let d = self.cx.error(
                &v.span(),
                format!("{what} names a parameter"),
                "a parameter",
            );
            d.help = Some(
                "a gear ratio is fixed when the robot is generated (the solvers are built on it): \
                 write a number, e.g. `gear = 50`"
                    .to_string(),
            );
            return None;
        }
        if value == 0.0 {
            let d = self
                .cx
                .error(&v.span(), format!("{what} is zero"), "evaluates to 0");
            d.help = Some(
                "the force on the coordinate is `gear * U`: a nonzero ratio (negative reverses \
                 the motor)"
                    .to_string(),
            );
            return None;
        }
        self.gear_at.push((shown.to_string(), v.span()));
        Some(value)
    }

    /// A coordinate's `stiffness`, `rest`, `damping`, `armature` (see [`JointForces`]):
    /// constant expressions, the three coefficients non-negative; `rest` needs `stiffness` and
    /// is read in degrees for a coordinate with `unit = "deg"`, like `home`.
    fn joint_forces(&mut self, t: &DeTable<'_>, shown: &str, deg: bool) -> Option<JointForces> {
        let mut ok = true;
        let mut coefficient = |p: &mut Self, key: &str, what: &str| -> Option<Expr> {
            let v = get(t, key)?;
            let what = format!("the {what} of coordinate `{shown}`");
            let Some((e, value, tainted)) = p.finite(v, &Scope::constant(&what)) else {
                ok = false;
                return None;
            };
            if !tainted && value < 0.0 {
                let d = p.cx.error(
                    &v.span(),
                    format!("{what} is negative"),
                    format!("evaluates to {}", fmt_num(value)),
                );
                d.help = Some(format!(
                    "`{key}` is a coefficient >= 0 (SI, per metre or radian of the coordinate); \
                     evaluated with the parameters' default values"
                ));
                ok = false;
                return None;
            }
            Some(e)
        };
        let stiffness = coefficient(self, "stiffness", "stiffness");
        let damping = coefficient(self, "damping", "damping");
        let armature = coefficient(self, "armature", "armature");
        let mut rest = None;
        if let Some(v) = get(t, "rest") {
            let what = format!("the spring's rest value of coordinate `{shown}`");
            match self.finite(v, &Scope::constant(&what)) {
                Some(_) if get(t, "stiffness").is_none() => {
                    let d = self.cx.error(
                        &v.span(),
                        format!(
                            "coordinate `{shown}` has a spring `rest` value but no `stiffness`"
                        ),
                        "a rest value without a spring",
                    );
                    d.help = Some(
                        "add `stiffness = k` (the spring force is -k (q - rest)), or remove `rest`"
                            .to_string(),
                    );
                    ok = false;
                }
                Some((e, _, _)) => {
                    rest = Some(if deg {
                        Expr::Div(
                            Box::new(Expr::Mul(Box::new(e), Box::new(Expr::Pi))),
                            Box::new(Expr::int(180)),
                        )
                    } else {
                        e
                    });
                }
                None => ok = false,
            }
        }
        ok.then_some(JointForces {
            stiffness,
            rest,
            damping,
            armature,
        })
    }

    pub(super) fn robot(&mut self, v: &Value<'_>) -> Option<RobotSection> {
        let t = match v.get_ref() {
            DeValue::Table(t) => t,
            other => {
                self.cx.error(
                    &v.span(),
                    format!(
                        "`robot` must be a table `[robot]`, found {}",
                        type_name(other)
                    ),
                    "expected a table",
                );
                return None;
            }
        };
        let span = v.span();
        self.check_keys(t, &span, ROBOT_KEYS, "`[robot]`");
        let name = self.required(t, &span, "name", "`[robot]`").and_then(|nv| {
            let s = self.string(nv, "the robot's name")?;
            if !is_snake_case(&s) || RUST_KEYWORDS.contains(&s.as_str()) {
                let d = self.cx.error(&nv.span(), format!("robot name `{s}` is not snake_case"), "expected a snake_case name");
                let fix = to_snake_case(&s);
                d.help = Some(if is_snake_case(&fix) && !RUST_KEYWORDS.contains(&fix.as_str()) {
                    format!("the name becomes the generated crate's name: try `{fix}`")
                } else {
                    "the name becomes the generated crate's name: lowercase letters, digits and single `_`, starting with a letter".to_string()
                });
                return None;
            }
            if let Some((_, why)) = RESERVED_ROBOT_NAMES.iter().find(|(n, _)| *n == s) {
                let d = self.cx.error(
                    &nv.span(),
                    format!("robot name `{s}` cannot name a generated crate"),
                    "reserved by the generated crate",
                );
                d.help = Some(format!("{why}: choose another name, e.g. `{s}_robot`"));
                return None;
            }
            Some(s)
        });
        let description = match get(t, "description") {
            Some(d) => self
                .string(d, "the robot's description")
                .unwrap_or_default(),
            None => String::new(),
        };
        let gravity = self
            .required(t, &span, "gravity", "`[robot]`")
            .and_then(|g| self.vector(g, "the gravity vector", &["gx", "gy", "gz"]))
            .map(|g| g.map(|(e, _, _)| e));

        let actuated_v = self.required(t, &span, "actuated", "`[robot]`");
        let actuated = actuated_v.and_then(|a| self.coord_list(a, "actuated"));
        // Optional: forward and inverse dynamics, simulation, energy and the kernels need no
        // outputs; inverse kinematics and forward kinematics' outputs do.
        let outputs = match get(t, "outputs") {
            Some(o) => self.coord_list(o, "outputs"),
            None => Some((Vec::new(), true)),
        };
        // `actuated` and `outputs` may share a coordinate: inverse kinematics then takes it as
        // given (as every output), forward kinematics too (as every actuated coordinate), and
        // inverse dynamics gives its force. That is how a coordinate in no loop (a legged
        // robot's hip, a gripper's slide) is actuated while outputs are given; whether the
        // combination can be solved is checked with the loops (the number of outputs, below)
        // and by the derivation (square inverse-kinematics blocks, the rank at the home).
        let indices = |l: Option<(Vec<(usize, Span)>, bool)>| match l {
            Some((items, true)) => Some(items.into_iter().map(|(i, _)| i).collect::<Vec<_>>()),
            _ => None,
        };
        let (actuated, outputs) = (indices(actuated), indices(outputs));
        let actuated_key = key_span(t, "actuated").unwrap_or(span.clone());
        let outputs_key = key_span(t, "outputs").unwrap_or(span.clone());
        Some(RobotSection {
            name,
            description,
            gravity,
            actuated: actuated.map(|a| (a, actuated_key)),
            outputs,
            outputs_key,
        })
    }

    /// `actuated` / `outputs`: a list of distinct coordinate names. Returns the
    /// valid entries and whether all entries were valid.
    pub(super) fn coord_list(
        &mut self,
        v: &Value<'_>,
        key: &str,
    ) -> Option<(Vec<(usize, Span)>, bool)> {
        let items = self.array(v, &format!("`{key}`"))?;
        // `actuated = []`: a mechanism with no drive (every degree of freedom passive);
        // `outputs = []`: no task coordinates (as when the key is absent).
        let mut out = Vec::new();
        let mut ok = true;
        let mut seen: HashMap<String, usize> = HashMap::new();
        for item in items {
            if key == "outputs" && item.get_ref().is_table() {
                match self.frame_output(item) {
                    Some(cols) => out.extend(cols.into_iter().map(|j| (j, item.span()))),
                    None => ok = false,
                }
                continue;
            }
            let Some(name) = self.string(item, &format!("an entry of `{key}`")) else {
                ok = false;
                continue;
            };
            if let Some(first_col) = seen.get(&name) {
                let d = self.cx.error(
                    &item.span(),
                    format!("coordinate `{name}` is listed twice in `{key}`"),
                    "listed again here",
                );
                d.help = Some(format!("first listed at column {first_col}"));
                ok = false;
                continue;
            }
            seen.insert(name.clone(), self.cx.pos(item.span().start).col);
            match self.syms.get(&name) {
                Some(Sym {
                    kind: SymKind::Coord,
                    index,
                    ..
                }) => out.push((*index, item.span())),
                Some(Sym {
                    kind: SymKind::Param,
                    line,
                    ..
                }) => {
                    let line = *line;
                    self.cx.error(
                        &item.span(),
                        format!(
                            "`{name}` in `{key}` is a parameter (line {line}), not a coordinate"
                        ),
                        "expected a coordinate",
                    );
                    ok = false;
                }
                None => {
                    let help = suggest(
                        &name,
                        self.sym_list
                            .iter()
                            .filter(|s| s.2 == SymKind::Coord)
                            .map(|(n, l, _)| (n.as_str(), Some(*l))),
                    );
                    let d = self.cx.error(
                        &item.span(),
                        format!("`{key}` names unknown coordinate `{name}`"),
                        "not a coordinate of this model",
                    );
                    d.help = help;
                    ok = false;
                }
            }
        }
        Some((out, ok))
    }

    // ---- bodies -----------------------------------------------------------------------------
}

pub(super) struct RobotSection {
    pub(super) name: Option<String>,
    pub(super) description: String,
    pub(super) gravity: Option<[Expr; 3]>,
    pub(super) actuated: Option<(Vec<usize>, Span)>,
    pub(super) outputs: Option<Vec<usize>>,
    /// The `outputs` key (the `[robot]` header without one).
    pub(super) outputs_key: Span,
}
