//! The walker over the TOML tree: names in scope, its state, and the typed accessors and the
//! expression resolver every section uses.

use super::*;
use crate::graph::{Graph, Id, Rat};

// Names in scope

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum SymKind {
    Param,
    Coord,
}

#[derive(Debug, Clone)]
pub(super) struct Sym {
    pub(super) kind: SymKind,
    pub(super) index: usize,
    pub(super) line: usize,
}

/// Where an expression may be used.
pub(super) struct Scope<'a> {
    /// "the mass of body `leg1_lower`".
    pub(super) what: &'a str,
    /// Coordinates are allowed (transforms only).
    pub(super) coords: bool,
    /// Parameters with an index below this are allowed.
    pub(super) params_before: usize,
    /// The parameter being defined, if any.
    pub(super) this_param: Option<usize>,
}

impl<'a> Scope<'a> {
    pub(super) fn constant(what: &'a str) -> Self {
        Scope {
            what,
            coords: false,
            params_before: usize::MAX,
            this_param: None,
        }
    }
    pub(super) fn transform(what: &'a str) -> Self {
        Scope {
            what,
            coords: true,
            params_before: usize::MAX,
            this_param: None,
        }
    }
}

/// Maps character offsets inside an expression to file positions.
pub(super) struct StrLoc {
    pub(super) span: Span,
    /// Position of the first character of the string's content, when offsets map one to one
    /// (a one-line string without escapes); otherwise errors point at the whole value.
    pub(super) first: Option<Pos>,
    /// For a string of a repeated entry (`{i}` replaced by the copy's index): the column in
    /// the written string of every character of the expanded one, and one past the end.
    pub(super) cols: Option<Vec<usize>>,
}

// ---------------------------------------------------------------------------------------------
// The walker

/// A resolved value: the expression and whether it depends on a parameter that had an error
/// (then its numeric checks are skipped, to avoid follow-up errors).
pub(super) struct Resolved {
    pub(super) expr: Expr,
    pub(super) tainted: bool,
    pub(super) span: Span,
}

pub(super) struct BodyInfo {
    pub(super) index: usize,
    pub(super) line: usize,
}

pub(super) struct Parser<'s> {
    pub(super) cx: Cx<'s>,
    pub(super) syms: HashMap<String, Sym>,
    /// Names in definition order, for suggestions.
    pub(super) sym_list: Vec<(String, usize, SymKind)>,
    pub(super) param_values: Vec<f64>,
    pub(super) param_bad: Vec<bool>,
    pub(super) coord_count: usize,
    pub(super) coord_used: Vec<bool>,
    pub(super) bodies: HashMap<String, BodyInfo>,
    pub(super) body_list: Vec<(String, usize)>,
    /// Table span start -> keys that an unknown key of that table is a misspelling of.
    pub(super) typos: HashMap<usize, Vec<String>>,
    /// Key spans (start) not to report as unknown (a misplaced `coordinates`).
    pub(super) skip_keys: Vec<usize>,
    /// Spans of repeated entries (their copies' shared errors are reported once).
    pub(super) templates: Vec<Span>,
    /// Spans of every loop's `a.body` and `b.body` values, in loop order.
    pub(super) loop_sites: Vec<[Span; 2]>,
    /// Warnings (the model compiles, but probably says something else than meant).
    pub(super) warnings: Vec<Diagnostic>,
    /// `[frames]`: name -> (its steps, `None` after an error; line).
    pub(super) frames: HashMap<String, (Option<Vec<Step>>, usize)>,
    /// Frame names in definition order, for suggestions.
    pub(super) frame_list: Vec<(String, usize)>,
    /// Coordinates with a `gear`, and where it is written (a gear needs an actuator).
    pub(super) gear_at: Vec<(String, Span)>,
    /// `outputs` entries that name a task frame (`task_frames`), expanded after the bodies.
    pub(super) frame_outputs: Vec<task_frames::FrameOutput>,
    /// Where the imported model starts in the text (`usize::MAX`: nothing imported); its
    /// bodies and loops come before the model file's (`crate::import::merge`).
    pub(super) imported_from: usize,
}

/// Keys of other robot formats (theirs, ours, whose) for the hint of an unknown key: a user
/// transcribing a MuJoCo or SDF joint writes their names.
const FOREIGN_KEYS: &[(&str, &str, &str)] = &[
    ("springref", "rest", "MuJoCo's"),
    ("spring_reference", "rest", "SDF's"),
    ("spring_stiffness", "stiffness", "SDF's"),
];

pub(super) const TOP_KEYS: &[&str] = &[
    "coordinates",
    "robot",
    "parameters",
    "body",
    "loop",
    "leg",
    "frames",
    "codegen",
];
pub(super) const ROBOT_KEYS: &[&str] = &["name", "description", "gravity", "actuated", "outputs"];
pub(super) const PARAM_KEYS: &[&str] = &["value", "unit", "doc", "count"];
pub(super) const COORD_KEYS: &[&str] = &[
    "name",
    "unit",
    "home",
    "count",
    "stiffness",
    "rest",
    "damping",
    "armature",
    "gear",
];
pub(super) const BODY_KEYS: &[&str] = &[
    "name",
    "parent",
    "transforms",
    "mass",
    "com",
    "inertia",
    "solid",
    "count",
];
pub(super) const LOOP_KEYS: &[&str] = &[
    "name",
    "a",
    "b",
    "kind",
    "components",
    "frame",
    "length",
    "ratio",
    "offset",
    "poly",
    "axis",
    "count",
];
pub(super) const ATTACH_KEYS: &[&str] = &["body", "transforms"];
pub(super) const SHAPES: &[&str] = &["cylinder", "box", "rod"];

impl<'s> Parser<'s> {
    pub(super) fn new(src: &'s str) -> Self {
        Parser {
            cx: Cx::new(src),
            syms: HashMap::new(),
            sym_list: Vec::new(),
            param_values: Vec::new(),
            param_bad: Vec::new(),
            coord_count: 0,
            coord_used: Vec::new(),
            bodies: HashMap::new(),
            body_list: Vec::new(),
            typos: HashMap::new(),
            skip_keys: Vec::new(),
            templates: Vec::new(),
            loop_sites: Vec::new(),
            warnings: Vec::new(),
            frames: HashMap::new(),
            frame_list: Vec::new(),
            gear_at: Vec::new(),
            frame_outputs: Vec::new(),
            imported_from: usize::MAX,
        }
    }

    /// True when an unknown key of the table at `span` was reported as a misspelling of `key`
    /// (then `key` is not reported missing as well).
    pub(super) fn is_typo(&self, span: &Span, key: &str) -> bool {
        self.typos
            .get(&span.start)
            .is_some_and(|t| t.iter().any(|k| k == key))
    }

    pub(super) fn errors(&self) -> usize {
        self.cx.diags.len()
    }

    // ---- generic helpers --------------------------------------------------------------------

    /// Reports keys of `t` that are not in `allowed`.
    pub(super) fn check_keys(
        &mut self,
        t: &DeTable<'_>,
        table_span: &Span,
        allowed: &[&str],
        table: &str,
    ) {
        for (k, _) in t.iter() {
            let key = k.get_ref().as_ref();
            if allowed.contains(&key) || self.skip_keys.contains(&k.span().start) {
                continue;
            }
            let help = suggest(key, allowed.iter().map(|a| (*a, None)));
            let label = format!("expected {}", list(allowed));
            let message = if table.starts_with("at ") {
                format!("unknown key `{key}` {table}")
            } else {
                format!("unknown key `{key}` in {table}")
            };
            if let Some(target) = allowed
                .iter()
                .find(|a| help.as_ref().is_some_and(|h| h.contains(&format!("`{a}`"))))
            {
                self.typos
                    .entry(table_span.start)
                    .or_default()
                    .push(target.to_string());
            }
            let d = self.cx.error(&k.span(), message, label);
            d.help = help.or_else(|| {
                FOREIGN_KEYS
                    .iter()
                    .find(|(theirs, ours, _)| *theirs == key && allowed.contains(ours))
                    .map(|(theirs, ours, whose)| {
                        format!("`{theirs}` is {whose} name: rbss calls it `{ours}`")
                    })
            });
            if d.help.is_none() && TOP_KEYS.contains(&key) && !table.starts_with("at ") {
                d.help = Some(format!(
                    "`{key}` belongs at the top level: TOML puts every key after a `[table]` header into that table"
                ));
            }
        }
    }

    pub(super) fn table<'b, 'a>(
        &mut self,
        v: &'b Value<'a>,
        what: &str,
    ) -> Option<&'b DeTable<'a>> {
        match v.get_ref() {
            DeValue::Table(t) => Some(t),
            other => {
                self.cx.error(
                    &v.span(),
                    format!("{what} must be a table, found {}", type_name(other)),
                    "expected a table",
                );
                None
            }
        }
    }

    pub(super) fn array<'b, 'a>(
        &mut self,
        v: &'b Value<'a>,
        what: &str,
    ) -> Option<&'b [Value<'a>]> {
        match v.get_ref() {
            DeValue::Array(a) => Some(a),
            other => {
                self.cx.error(
                    &v.span(),
                    format!("{what} must be an array, found {}", type_name(other)),
                    "expected an array",
                );
                None
            }
        }
    }

    pub(super) fn string(&mut self, v: &Value<'_>, what: &str) -> Option<String> {
        match v.get_ref() {
            DeValue::String(s) => Some(s.to_string()),
            other => {
                self.cx.error(
                    &v.span(),
                    format!("{what} must be a string, found {}", type_name(other)),
                    "expected a string",
                );
                None
            }
        }
    }

    /// A required key; a missing one is reported at `span` (the table's header or braces).
    pub(super) fn required<'b, 'a>(
        &mut self,
        t: &'b DeTable<'a>,
        span: &Span,
        key: &str,
        table: &str,
    ) -> Option<&'b Value<'a>> {
        let v = get(t, key);
        if v.is_none() && !self.is_typo(span, key) {
            self.cx.error(
                span,
                format!("missing key `{key}` in {table}"),
                format!("`{key}` is required here"),
            );
        }
        v
    }

    /// A name (identifier, not a keyword).
    pub(super) fn name(&mut self, v: &Value<'_>, kind: &str) -> Option<String> {
        let s = self.string(v, &format!("the name of a {kind}"))?;
        if !is_identifier(&s) {
            let d = self.cx.error(
                &v.span(),
                format!("`{s}` is not a valid {kind} name"),
                "expected an identifier",
            );
            d.help = Some(
                "a name starts with a letter or `_` and continues with letters, digits or `_`"
                    .to_string(),
            );
            return None;
        }
        if RUST_KEYWORDS.contains(&s.as_str()) {
            self.cx.error(
                &v.span(),
                format!("`{s}` cannot name a {kind}: it is a Rust keyword"),
                "names become Rust identifiers",
            );
            return None;
        }
        Some(s)
    }

    pub(super) fn str_loc(&self, v: &Value<'_>, decoded: &str) -> StrLoc {
        let span = v.span();
        let raw = self.cx.text(&span);
        let simple = (raw.starts_with('"') && !raw.starts_with("\"\"\""))
            || (raw.starts_with('\'') && !raw.starts_with("'''"));
        let inner = raw.get(1..raw.len().saturating_sub(1)).unwrap_or("");
        let one_line = simple && raw.len() >= 2 && !decoded.contains('\n');
        let mut cols = None;
        let first = if one_line && inner == decoded {
            Some(self.cx.pos(span.start + 1))
        } else if one_line && let Some(map) = index_cols(inner, decoded) {
            cols = Some(map);
            Some(self.cx.pos(span.start + 1))
        } else {
            None
        };
        StrLoc { span, first, cols }
    }

    pub(super) fn expr_error(&mut self, loc: &StrLoc, e: ExprError) {
        let d = match loc.first {
            Some(p) => {
                let (at, len) = match &loc.cols {
                    Some(cols) => {
                        let col = |k: usize| cols.get(k).or(cols.last()).copied().unwrap_or(0);
                        let a = col(e.at.0);
                        (a, col(e.at.0.saturating_add(e.at.1)).saturating_sub(a))
                    }
                    None => e.at,
                };
                let pos = Pos {
                    line: p.line,
                    col: p.col.saturating_add(at),
                };
                Diagnostic::new(pos, len, e.message, e.label)
            }
            None => Diagnostic::new(
                self.cx.pos(loc.span.start),
                self.cx.len(&loc.span),
                e.message,
                e.label,
            ),
        };
        let d = self.cx.push(d);
        d.help = e.help;
    }

    /// An expression value: a TOML number or an expression string.
    pub(super) fn expr(&mut self, v: &Value<'_>, scope: &Scope<'_>) -> Option<Resolved> {
        let span = v.span();
        let loc = StrLoc {
            span: span.clone(),
            first: None,
            cols: None,
        };
        match v.get_ref() {
            DeValue::Integer(i) => {
                let text = i.as_str();
                let parsed = if i.radix() == 10 {
                    parse_decimal(text)
                } else {
                    i128::from_str_radix(text, i.radix())
                        .map(|n| (n, 1))
                        .map_err(|_| NumError::TooLarge)
                };
                match parsed {
                    Ok((num, den)) => Some(Resolved {
                        expr: Expr::Num { num, den },
                        tainted: false,
                        span,
                    }),
                    Err(_) => {
                        let at = (0, 1);
                        self.expr_error(&loc, number_too_large(at, text));
                        None
                    }
                }
            }
            DeValue::Float(f) => {
                let text = f.as_str();
                match parse_decimal(text) {
                    Ok((num, den)) => Some(Resolved {
                        expr: Expr::Num { num, den },
                        tainted: false,
                        span,
                    }),
                    Err(NumError::TooLarge) => {
                        self.expr_error(&loc, number_too_large((0, 1), text));
                        None
                    }
                    Err(NumError::Syntax) => {
                        self.cx.error(
                            &span,
                            format!("{} must be finite, found `{text}`", scope.what),
                            "not a finite number",
                        );
                        None
                    }
                }
            }
            DeValue::String(s) => {
                let s = s.to_string();
                let loc = self.str_loc(v, &s);
                match parse_raw(&s) {
                    Err(e) => {
                        self.expr_error(&loc, e);
                        None
                    }
                    Ok(raw) => {
                        let mut tainted = false;
                        let expr = self.resolve(&raw, scope, &loc, &mut tainted)?;
                        if let Some(bad) = self.non_finite_number(&expr) {
                            self.non_finite_number_error(&span, bad);
                            return None;
                        }
                        Some(Resolved {
                            expr,
                            tainted,
                            span,
                        })
                    }
                }
            }
            other => {
                self.cx.error(
                    &span,
                    format!(
                        "{} must be a number or an expression string, found {}",
                        scope.what,
                        type_name(other)
                    ),
                    "expected a number or a string",
                );
                None
            }
        }
    }

    /// Resolves names; reports every unknown or misplaced name of the tree.
    pub(super) fn resolve(
        &mut self,
        raw: &Raw,
        scope: &Scope<'_>,
        loc: &StrLoc,
        tainted: &mut bool,
    ) -> Option<Expr> {
        match raw {
            Raw::Num(num, den) => Some(Expr::Num {
                num: *num,
                den: *den,
            }),
            Raw::Neg(a) => Some(Expr::Neg(bx(self.resolve(a, scope, loc, tainted)?))),
            Raw::Bin(op, a, b) => {
                let a = self.resolve(a, scope, loc, tainted);
                let b = self.resolve(b, scope, loc, tainted);
                let (a, b) = (bx(a?), bx(b?));
                Some(match op {
                    BinOp::Add => Expr::Add(a, b),
                    BinOp::Sub => Expr::Sub(a, b),
                    BinOp::Mul => Expr::Mul(a, b),
                    BinOp::Div => Expr::Div(a, b),
                    BinOp::Pow => Expr::Pow(a, b),
                })
            }
            Raw::Call(name, at, args) => {
                let resolved: Vec<Option<Expr>> = args
                    .iter()
                    .map(|a| self.resolve(a, scope, loc, tainted))
                    .collect();
                let Some(func) = Func::from_name(name) else {
                    let mut e = if STEP_NAMES.contains(&name.as_str()) {
                        expr_err(
                            *at,
                            format!("`{name}` is a transform, not a function"),
                            "a transform step must be a string of its own",
                        )
                    } else if self.syms.contains_key(name) || name == "pi" {
                        expr_err(
                            *at,
                            format!("`{name}` is not a function"),
                            "cannot be called",
                        )
                    } else {
                        expr_err(
                            *at,
                            format!("unknown function `{name}`"),
                            format!("expected {}", list(FUNC_NAMES)),
                        )
                    };
                    e.help = suggest(name, FUNC_NAMES.iter().map(|f| (*f, None)));
                    self.expr_error(loc, e);
                    return None;
                };
                let n = func.arity();
                if args.len() != n {
                    let mut e = expr_err(
                        *at,
                        format!(
                            "`{name}` takes {n} argument{}, found {}",
                            if n == 1 { "" } else { "s" },
                            args.len()
                        ),
                        if n == 1 {
                            "expected one argument".to_string()
                        } else {
                            format!("expected {n} arguments")
                        },
                    );
                    if n > 1 {
                        e.help = Some(format!("write `{}`", func.signature()));
                    }
                    self.expr_error(loc, e);
                    return None;
                }
                let args: Vec<Expr> = resolved.into_iter().collect::<Option<Vec<_>>>()?;
                if !COORD_FUNCS.contains(&func) && !args.iter().all(Expr::is_constant) {
                    let mut e = expr_err(
                        *at,
                        format!("`{name}` takes constant arguments: numbers and parameters"),
                        "an argument depends on a coordinate",
                    );
                    e.help = Some(format!(
                        "only {} may take coordinates; compute `{name}` of constants, or write the \
                         frame with those",
                        list(&COORD_FUNCS.iter().map(|f| f.name()).collect::<Vec<_>>())
                    ));
                    self.expr_error(loc, e);
                    return None;
                }
                if let Some(why) = self.domain_error(func, &args) {
                    self.expr_error(loc, expr_err(*at, why, "outside the function's domain"));
                    return None;
                }
                Some(Expr::Call(func, args))
            }
            Raw::Ident(name, at) => {
                if name == "pi" {
                    return Some(Expr::Pi);
                }
                match self.syms.get(name).cloned() {
                    Some(Sym {
                        kind: SymKind::Param,
                        index,
                        line,
                    }) => {
                        if scope.this_param == Some(index) {
                            self.expr_error(
                                loc,
                                expr_err(
                                    *at,
                                    format!("parameter `{name}` refers to itself"),
                                    "used in its own value",
                                ),
                            );
                            return None;
                        }
                        if index >= scope.params_before {
                            let mut e = expr_err(
                                *at,
                                format!("parameter `{name}` is used before it is defined"),
                                format!("defined later, on line {line}"),
                            );
                            e.help = Some(
                                "a parameter's value may use only the parameters defined above it: move it down"
                                    .to_string(),
                            );
                            self.expr_error(loc, e);
                            return None;
                        }
                        if self.param_bad.get(index).copied().unwrap_or(true) {
                            *tainted = true;
                        }
                        Some(Expr::Param(index))
                    }
                    Some(Sym {
                        kind: SymKind::Coord,
                        index,
                        ..
                    }) => {
                        if !scope.coords {
                            self.expr_error(
                                loc,
                                expr_err(
                                    *at,
                                    format!("coordinate `{name}` cannot be used in {}", scope.what),
                                    "only parameters and `pi` are allowed here",
                                ),
                            );
                            return None;
                        }
                        if let Some(u) = self.coord_used.get_mut(index) {
                            *u = true;
                        }
                        Some(Expr::Coord(index))
                    }
                    None => {
                        let label = if scope.coords {
                            "not a parameter or coordinate"
                        } else {
                            "not a parameter"
                        };
                        let candidates: Vec<(String, Option<usize>)> = self
                            .sym_list
                            .iter()
                            .filter(|(_, _, k)| scope.coords || *k == SymKind::Param)
                            .map(|(n, l, _)| (n.clone(), Some(*l)))
                            .chain(std::iter::once(("pi".to_string(), None)))
                            .collect();
                        let mut e = expr_err(
                            *at,
                            format!("unknown name `{name}` in {}", scope.what),
                            label,
                        );
                        e.help = suggest(name, candidates.iter().map(|(n, l)| (n.as_str(), *l)));
                        self.expr_error(loc, e);
                        None
                    }
                }
            }
        }
    }

    /// Evaluates a constant expression with the parameters' default values (NaN when unknown).
    pub(super) fn eval(&self, e: &Expr) -> f64 {
        match e {
            Expr::Num { num, den } => *num as f64 / *den as f64,
            Expr::Pi => std::f64::consts::PI,
            Expr::Param(i) => self.param_values.get(*i).copied().unwrap_or(f64::NAN),
            Expr::Coord(_) => f64::NAN,
            Expr::Neg(a) => -self.eval(a),
            Expr::Add(a, b) => self.eval(a) + self.eval(b),
            Expr::Sub(a, b) => self.eval(a) - self.eval(b),
            Expr::Mul(a, b) => self.eval(a) * self.eval(b),
            Expr::Div(a, b) => self.eval(a) / self.eval(b),
            Expr::Pow(a, b) => self.eval(a).powf(self.eval(b)),
            Expr::Call(f, args) => {
                let v: Vec<f64> = args.iter().map(|a| self.eval(a)).collect();
                f.eval(&v)
            }
        }
    }

    /// Why the arguments of `f` (constants, evaluated with the parameters' default values) are
    /// outside its domain: `asin(2)`, `atan2(0, 0)`. Arguments that depend on a parameter with
    /// an error, or on a coordinate, are not checked.
    fn domain_error(&self, f: Func, args: &[Expr]) -> Option<String> {
        if !args.iter().all(Expr::is_constant) {
            return None;
        }
        let v: Vec<f64> = args.iter().map(|a| self.eval(a)).collect();
        if v.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let why = f.domain_error(&v)?;
        let depends = args.iter().any(|a| {
            let mut any = false;
            a.for_each_param(&mut |_| any = true);
            any
        });
        Some(if depends {
            format!("{why} (with the parameters' values)")
        } else {
            why
        })
    }

    /// The smallest part of `e` made of numbers and pi alone (what the generator folds to one
    /// f64 constant) whose value is not finite, with why: `10^400` in `l1 / 10^400`, although
    /// the whole is a finite 0. The parts are folded as the derivation folds them (exactly:
    /// `cos(pi / 2)` is 0, so `tan(pi / 2)` has no value, where f64 would give 1.6e16).
    pub(super) fn non_finite_number<'e>(&self, e: &'e Expr) -> Option<NonFinite<'e>> {
        let mut g = Graph::new(0);
        let mut found = None;
        fold_numbers(&mut g, e, &mut found);
        found
    }

    /// The name of a parameter or coordinate, for messages.
    fn sym_name(&self, kind: SymKind, index: usize) -> String {
        self.syms
            .iter()
            .find(|(_, s)| s.kind == kind && s.index == index)
            .map_or_else(|| "?".to_string(), |(n, _)| n.clone())
    }

    pub(super) fn non_finite_number_error(&mut self, span: &Range<usize>, bad: NonFinite<'_>) {
        let text = number_text(bad.part, &|k, i| self.sym_name(k, i));
        let (message, help) = match bad.why {
            Why::DividesByZero => (
                format!("the constant `{text}` divides by zero"),
                "a divisor must not be zero (nor the base of a negative power)".to_string(),
            ),
            Why::Pole => (
                format!("the constant `{text}` is at a pole of tan"),
                "tan has no value at odd multiples of pi / 2".to_string(),
            ),
            Why::NotReal => (
                format!("the constant `{text}` is not a real number"),
                "the kernels compute in real f64 arithmetic".to_string(),
            ),
            Why::Overflows => (
                format!("the constant `{text}` overflows f64"),
                "the kernels compute in f64, whose magnitudes end at about 1.8e308: rescale the \
                 quantity (other units) or simplify the expression"
                    .to_string(),
            ),
        };
        let d = self.cx.error(
            span,
            message,
            format!("has a part that evaluates to {}", fmt_num(bad.value)),
        );
        d.help = Some(help);
    }

    /// A constant expression that must evaluate to a finite number.
    pub(super) fn finite(&mut self, v: &Value<'_>, scope: &Scope<'_>) -> Option<(Expr, f64, bool)> {
        let r = self.expr(v, scope)?;
        let value = self.eval(&r.expr);
        if !r.tainted && !value.is_finite() {
            self.cx.error(
                &r.span,
                format!("{} is not finite", scope.what),
                format!("evaluates to {}", fmt_num(value)),
            );
            return None;
        }
        Some((r.expr, value, r.tainted))
    }

    /// An array of `N` constant expressions.
    pub(super) fn vector<const N: usize>(
        &mut self,
        v: &Value<'_>,
        what: &str,
        names: &[&str; N],
    ) -> Option<[(Expr, f64, bool); N]> {
        let items = self.array(v, what)?;
        if items.len() != N {
            self.cx.error(
                &v.span(),
                format!("{what} must have {N} entries, found {}", items.len()),
                format!("expected [{}]", names.join(", ")),
            );
            return None;
        }
        let mut out = Vec::with_capacity(N);
        for (item, name) in items.iter().zip(names) {
            let what_i = format!("{what} ({name})");
            out.push(self.finite(item, &Scope::constant(&what_i)));
        }
        let out: Option<Vec<_>> = out.into_iter().collect();
        out?.try_into().ok()
    }

    // ---- the document -----------------------------------------------------------------------
}

/// Maps the characters of `decoded`, which is `raw` with every `{i}` replaced by one index (a
/// string of a repeated entry), to columns of `raw`; `None` if it is not such a string.
pub(super) fn index_cols(raw: &str, decoded: &str) -> Option<Vec<usize>> {
    let k = raw.matches(INDEX).count();
    let (rc, dc) = (raw.chars().count(), decoded.chars().count());
    if k == 0 || (dc + 3 * k) <= rc || !(dc + 3 * k - rc).is_multiple_of(k) {
        return None;
    }
    let width = (dc + 3 * k - rc) / k;
    let start = raw.split(INDEX).next()?.chars().count();
    let index: String = decoded.chars().skip(start).take(width).collect();
    if raw.replace(INDEX, &index) != decoded {
        return None;
    }
    let chars: Vec<char> = raw.chars().collect();
    let mut cols = Vec::with_capacity(dc + 1);
    let mut j = 0;
    while j < chars.len() {
        if chars[j..].starts_with(&['{', 'i', '}']) {
            cols.extend(std::iter::repeat_n(j, width));
            j += 3;
        } else {
            cols.push(j);
            j += 1;
        }
    }
    cols.push(chars.len());
    Some(cols)
}

/// An expression as written in a model (`10^400`, `1 / (2 - 2)`, `(l1 * 0)^-400`), for
/// messages; `name` gives the names of parameters and coordinates.
fn number_text(e: &Expr, name: &dyn Fn(SymKind, usize) -> String) -> String {
    let operand = |e: &Expr| match e {
        Expr::Num { num, den: 1 } if *num >= 0 => number_text(e, name),
        Expr::Pi | Expr::Param(_) | Expr::Coord(_) | Expr::Call(..) => number_text(e, name),
        _ => format!("({})", number_text(e, name)),
    };
    match e {
        Expr::Num { num, den: 1 } => format!("{num}"),
        Expr::Num { num, den } => format!("{num}/{den}"),
        Expr::Pi => "pi".to_string(),
        Expr::Param(j) => name(SymKind::Param, *j),
        Expr::Coord(i) => name(SymKind::Coord, *i),
        Expr::Neg(a) => format!("-{}", operand(a)),
        Expr::Add(a, b) => format!("{} + {}", operand(a), operand(b)),
        Expr::Sub(a, b) => format!("{} - {}", operand(a), operand(b)),
        Expr::Mul(a, b) => format!("{} * {}", operand(a), operand(b)),
        Expr::Div(a, b) => format!("{} / {}", operand(a), operand(b)),
        Expr::Pow(a, b) => format!("{}^{}", operand(a), operand(b)),
        Expr::Call(f, args) => {
            let args: Vec<String> = args.iter().map(|a| number_text(a, name)).collect();
            format!("{}({})", f.name(), args.join(", "))
        }
    }
}

/// A part of an expression made of numbers alone whose value is not finite.
pub(super) struct NonFinite<'e> {
    part: &'e Expr,
    value: f64,
    why: Why,
}

enum Why {
    DividesByZero,
    Pole,
    NotReal,
    Overflows,
}

/// Folds `e` into `g` as `derive::expr` builds it (exact rational arithmetic, exact
/// trigonometry at rational multiples of pi, `tan` as `sin / cos`, `0 * x = 0`), parameters and
/// coordinates as leaves; records in `found` the first (so the smallest) part that folds to a
/// number (no parameter, no coordinate) whose value is not finite: the constant the kernels
/// would hold.
fn fold_numbers<'e>(g: &mut Graph, e: &'e Expr, found: &mut Option<NonFinite<'e>>) -> Id {
    /// Coordinates as parameter leaves past any parameter: only "is it a number" matters here.
    const COORD: usize = 1 << 30;
    let id = match e {
        Expr::Num { num, den } => match Rat::new(*num, *den) {
            Some(r) => g.num(r),
            None => g.float(f64::NAN),
        },
        Expr::Pi => g.pi(),
        Expr::Param(j) => g.p(*j),
        Expr::Coord(i) => g.p(COORD + *i),
        Expr::Neg(a) => {
            let a = fold_numbers(g, a, found);
            g.neg(a)
        }
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            let x = fold_numbers(g, a, found);
            let y = fold_numbers(g, b, found);
            match e {
                Expr::Add(..) => g.add(x, y),
                Expr::Sub(..) => g.sub(x, y),
                Expr::Mul(..) => g.mul(x, y),
                Expr::Div(..) => g.div(x, y),
                _ => g.pow(x, y),
            }
        }
        Expr::Call(f, args) => {
            let args: Vec<Id> = args.iter().map(|a| fold_numbers(g, a, found)).collect();
            g.call(*f, &args)
        }
    };
    if found.is_some() || !g.is_number(id) {
        return id;
    }
    let value = g.eval(id, &[], &[], &[]);
    if !value.is_finite() {
        let zero = |g: &mut Graph, b: &Expr| {
            let mut ignore = None;
            let b = fold_numbers(g, b, &mut ignore);
            g.is_number(b) && g.eval(b, &[], &[], &[]) == 0.0
        };
        let why = match e {
            // `x / 0`, and `0^-k`, which is `1 / 0^k`.
            Expr::Div(_, b) | Expr::Pow(b, _) if zero(g, b) => Why::DividesByZero,
            Expr::Call(Func::Tan, _) => Why::Pole,
            _ if value.is_nan() => Why::NotReal,
            _ => Why::Overflows,
        };
        *found = Some(NonFinite {
            part: e,
            value,
            why,
        });
    }
    id
}
