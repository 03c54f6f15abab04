//! Mass properties: `mass`, `com`, `inertia`, `solid`, and the inertia check.

use super::*;

impl<'s> Parser<'s> {
    pub(super) fn mass_props(
        &mut self,
        t: &DeTable<'_>,
        span: &Span,
        body: &str,
    ) -> Option<Option<MassProps>> {
        let mass_v = get(t, "mass");
        let inertia_v = get(t, "inertia");
        let com_v = get(t, "com");
        let solid_v = get(t, "solid");
        let com_what = format!("the centre of mass of body `{body}`");
        let com = match com_v {
            Some(c) => self
                .vector(c, &com_what, &["x", "y", "z"])
                .map(|c| c.map(|(e, _, _)| e)),
            None => Some([Expr::int(0), Expr::int(0), Expr::int(0)]),
        };
        if let Some(sv) = solid_v {
            if mass_v.is_some() || inertia_v.is_some() {
                let k = key_span(t, if mass_v.is_some() { "mass" } else { "inertia" })
                    .unwrap_or(sv.span());
                let d = self.cx.error(
                    &k,
                    format!("body `{body}` has both `solid` and `mass`/`inertia`"),
                    "`solid` already gives the mass and inertia",
                );
                d.help = Some(
                    "give either `solid = { shape = ... }` or `mass` and `inertia`".to_string(),
                );
                return None;
            }
            let (mass, inertia) = self.solid(sv, body)?;
            return Some(Some(MassProps {
                mass,
                com: com?,
                inertia,
            }));
        }
        match (mass_v, inertia_v) {
            (None, None) => {
                if let Some(c) = com_v
                    && !self.is_typo(span, "mass")
                {
                    let k = key_span(t, "com").unwrap_or(c.span());
                    let d = self.cx.error(
                        &k,
                        format!("body `{body}` has a `com` but no mass"),
                        "a massless frame has no centre of mass",
                    );
                    d.help =
                        Some("add `mass` and `inertia`, or `solid`; or remove `com`".to_string());
                    return None;
                }
                com?;
                Some(None)
            }
            (Some(_), None) if self.is_typo(span, "inertia") => None,
            (None, Some(_)) if self.is_typo(span, "mass") => None,
            (Some(_), None) => {
                let k = key_span(t, "mass").unwrap_or_default();
                let d = self.cx.error(
                    &k,
                    format!("body `{body}` has a `mass` but no `inertia`"),
                    "inertia missing",
                );
                d.help = Some(
                    "add `inertia = [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]` (about the centre of mass) or describe the shape with `solid`"
                        .to_string(),
                );
                None
            }
            (None, Some(_)) => {
                let k = key_span(t, "inertia").unwrap_or_default();
                self.cx.error(
                    &k,
                    format!("body `{body}` has an `inertia` but no `mass`"),
                    "mass missing",
                );
                None
            }
            (Some(mv), Some(iv)) => {
                let mass_what = format!("the mass of body `{body}`");
                let mass =
                    self.finite(mv, &Scope::constant(&mass_what))
                        .and_then(|(e, m, tainted)| {
                            if !tainted && m <= 0.0 {
                                let d = self.cx.error(
                                    &mv.span(),
                                    format!("the mass of body `{body}` must be positive"),
                                    format!("evaluates to {}", fmt_num(m)),
                                );
                                d.help = Some(
                                    "evaluated with the parameters' default values".to_string(),
                                );
                                return None;
                            }
                            Some(e)
                        });
                let inertia_what = format!("the inertia of body `{body}`");
                let inertia = self.vector(
                    iv,
                    &inertia_what,
                    &["Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz"],
                );
                let inertia = inertia.and_then(|entries| {
                    if entries.iter().any(|e| e.2) {
                        return Some(entries.map(|(e, _, _)| e));
                    }
                    let vals: Vec<f64> = entries.iter().map(|e| e.1).collect();
                    let problem = check_inertia([vals[0], vals[1], vals[2], vals[3], vals[4], vals[5]]);
                    if let Some((message, label)) = problem {
                        let d = self.cx.error(&iv.span(), format!("the inertia of body `{body}` {message}"), label);
                        d.help = Some(
                            "`inertia = [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]` about the centre of mass, in the body axes; Ixy, Ixz, Iyz are entries of the inertia matrix"
                                .to_string(),
                        );
                        return None;
                    }
                    Some(entries.map(|(e, _, _)| e))
                });
                Some(Some(MassProps {
                    mass: mass?,
                    com: com?,
                    inertia: inertia?,
                }))
            }
        }
    }

    /// A positive constant dimension of a solid.
    pub(super) fn positive(&mut self, v: &Value<'_>, what: &str) -> Option<Expr> {
        let (e, value, tainted) = self.finite(v, &Scope::constant(what))?;
        if !tainted && value <= 0.0 {
            let d = self.cx.error(
                &v.span(),
                format!("{what} must be positive"),
                format!("evaluates to {}", fmt_num(value)),
            );
            d.help = Some("evaluated with the parameters' default values".to_string());
            return None;
        }
        Some(e)
    }

    /// `solid = { shape = ..., ... }` -> (mass, inertia about the centre).
    pub(super) fn solid(&mut self, v: &Value<'_>, body: &str) -> Option<(Expr, [Expr; 6])> {
        let t = self.table(v, &format!("`solid` of body `{body}`"))?;
        let span = v.span();
        let table = format!("the `solid` of body `{body}`");
        let shape_v = self.required(t, &span, "shape", &table);
        let shape = shape_v.and_then(|s| self.string(s, &format!("the shape of body `{body}`")))?;
        let allowed: &[&str] = match shape.as_str() {
            "cylinder" => &["shape", "radius", "length", "density", "mass", "axis"],
            "box" => &["shape", "size", "density", "mass"],
            "rod" => &["shape", "length", "mass", "axis"],
            _ => {
                let sv = shape_v?;
                let d = self.cx.error(
                    &sv.span(),
                    format!("unknown shape `{shape}`"),
                    format!("expected {}", list(SHAPES)),
                );
                d.help = suggest(&shape, SHAPES.iter().map(|s| (*s, None)));
                return None;
            }
        };
        self.check_keys(t, &span, allowed, &format!("a `{shape}` solid"));
        let table = format!("a `{shape}` solid");
        let zero = || Expr::int(0);
        // The axis of a cylinder or a rod (`z` unless given): index of the moment about it.
        let axis = match get(t, "axis").filter(|_| shape != "box") {
            None => Some(2),
            Some(a) => match self
                .string(a, &format!("the axis of body `{body}`"))
                .as_deref()
            {
                Some("x") => Some(0),
                Some("y") => Some(1),
                Some("z") => Some(2),
                Some(other) => {
                    let d = self.cx.error(
                        &a.span(),
                        format!("`{other}` is not an axis of the `{shape}` of body `{body}`"),
                        "expected `x`, `y` or `z`",
                    );
                    d.help = Some(format!(
                        "the {shape}'s axis in the body frame; its centre is at `com`"
                    ));
                    None
                }
                None => None,
            },
        };
        // [along, across, across] -> [Ixx, Iyy, Izz, 0, 0, 0] with `along` about `axis`.
        let about = |axis: usize, along: Expr, across: Expr| {
            let mut d = [across.clone(), across.clone(), across];
            d[axis] = along;
            let [a, b, c] = d;
            [a, b, c, zero(), zero(), zero()]
        };
        // Mass: `mass`, or `density` times the volume (a rod takes `mass` only). Every entry
        // is checked before giving up, so that all of a solid's errors are reported.
        let density_v = get(t, "density").filter(|_| shape != "rod");
        let mass_v = get(t, "mass");
        let mut ok = true;
        if let (Some(_), Some(_)) = (density_v, mass_v) {
            let k = key_span(t, "mass").unwrap_or(span.clone());
            self.cx.error(
                &k,
                format!("{table} has both `density` and `mass`"),
                "give only one of them",
            );
            ok = false;
        }
        if density_v.is_none() && mass_v.is_none() {
            let (message, label) = if shape == "rod" {
                (
                    format!("missing key `mass` in {table}"),
                    "`mass` is required here",
                )
            } else {
                (
                    format!("missing key `density` or `mass` in {table}"),
                    "one of them is required here",
                )
            };
            self.cx.error(&span, message, label);
            ok = false;
        }
        let mass_given = mass_v.map(|m| self.positive(m, &format!("the mass of body `{body}`")));
        let density = density_v.map(|d| self.positive(d, &format!("the density of body `{body}`")));
        // The mass from `mass` or from the density and the volume.
        let mass = |of_density: &dyn Fn(Expr) -> Expr| match (&mass_given, &density) {
            (Some(m), None) => m.clone(),
            (None, Some(rho)) => Some(of_density(rho.clone()?)),
            _ => None,
        };
        match shape.as_str() {
            "cylinder" => {
                let r = self
                    .required(t, &span, "radius", &table)
                    .and_then(|r| self.positive(r, &format!("the radius of body `{body}`")));
                let l = self
                    .required(t, &span, "length", &table)
                    .and_then(|l| self.positive(l, &format!("the length of body `{body}`")));
                let (r, l, axis) = (r?, l?, axis?);
                if !ok {
                    return None;
                }
                let m = mass(&|rho| mul(mul(mul(rho, Expr::Pi), sq(r.clone())), l.clone()))?;
                let across = div(
                    mul(m.clone(), add(mul(Expr::int(3), sq(r.clone())), sq(l))),
                    Expr::int(12),
                );
                let along = div(mul(m.clone(), sq(r)), Expr::int(2));
                Some((m, about(axis, along, across)))
            }
            "box" => {
                let size = self.required(t, &span, "size", &table)?;
                let items = self.array(size, &format!("the size of body `{body}`"))?;
                if items.len() != 3 {
                    self.cx.error(
                        &size.span(),
                        format!("the size of a box has 3 entries, found {}", items.len()),
                        "expected `[a, b, c]` along x, y, z",
                    );
                    return None;
                }
                let dims: Vec<Option<Expr>> = items
                    .iter()
                    .zip(["x", "y", "z"])
                    .map(|(d, ax)| self.positive(d, &format!("the size ({ax}) of body `{body}`")))
                    .collect();
                let dims: Vec<Expr> = dims.into_iter().collect::<Option<Vec<_>>>()?;
                if !ok {
                    return None;
                }
                let (a, b, c) = (dims[0].clone(), dims[1].clone(), dims[2].clone());
                let m = mass(&|rho| mul(mul(mul(rho, a.clone()), b.clone()), c.clone()))?;
                let moment = |p: &Expr, q: &Expr| {
                    div(
                        mul(m.clone(), add(sq(p.clone()), sq(q.clone()))),
                        Expr::int(12),
                    )
                };
                let (ixx, iyy, izz) = (moment(&b, &c), moment(&a, &c), moment(&a, &b));
                Some((m, [ixx, iyy, izz, zero(), zero(), zero()]))
            }
            _ => {
                // A thin rod along its axis: no inertia about it.
                let l = self
                    .required(t, &span, "length", &table)
                    .and_then(|l| self.positive(l, &format!("the length of body `{body}`")));
                let m = mass_given??;
                let (l, axis) = (l?, axis?);
                let across = div(mul(m.clone(), sq(l)), Expr::int(12));
                Some((m, about(axis, zero(), across)))
            }
        }
    }

    // ---- loops ------------------------------------------------------------------------------
}

pub(super) fn sym_eigenvalues(m: [[f64; 3]; 3]) -> [f64; 3] {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let mut e = if p1 == 0.0 {
        [m[0][0], m[1][1], m[2][2]]
    } else {
        let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
        let p2 = (m[0][0] - q).powi(2) + (m[1][1] - q).powi(2) + (m[2][2] - q).powi(2) + 2.0 * p1;
        let p = (p2 / 6.0).sqrt();
        let mut b = m;
        for (i, row) in b.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (*x - if i == j { q } else { 0.0 }) / p;
            }
        }
        let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
            - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
            + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
        let r = (det / 2.0).clamp(-1.0, 1.0);
        let phi = r.acos() / 3.0;
        let e1 = q + 2.0 * p * phi.cos();
        let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
        [e1, 3.0 * q - e1 - e3, e3]
    };
    e.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    e
}

/// Checks `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`: positive semidefinite (a thin rod has no inertia
/// about its axis, a point mass none at all; the mass matrix of the whole robot is checked at
/// the assembled home), principal moments satisfy the triangle inequality. Returns (message tail, label) on failure.
pub(super) fn check_inertia(i: [f64; 6]) -> Option<(String, String)> {
    let m = [[i[0], i[3], i[4]], [i[3], i[1], i[5]], [i[4], i[5], i[2]]];
    let e = sym_eigenvalues(m);
    let scale = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    let tol = 1e-12 * scale;
    let moments = format!(
        "principal moments {}, {}, {}",
        fmt_num(e[0]),
        fmt_num(e[1]),
        fmt_num(e[2])
    );
    if e[0] < -tol || !e.iter().all(|x| x.is_finite()) {
        return Some(("is not positive semidefinite".to_string(), moments));
    }
    if e[0] + e[1] < e[2] - 1e-9 * scale {
        return Some((
            "violates the triangle inequality".to_string(),
            format!(
                "{moments}: {} + {} < {}",
                fmt_num(e[0]),
                fmt_num(e[1]),
                fmt_num(e[2])
            ),
        ));
    }
    None
}
