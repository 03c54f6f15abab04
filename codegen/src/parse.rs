//! Model file (TOML) -> validated [`Model`], collecting every error with its exact position.
//!
//! The TOML text is parsed by `toml::de::DeTable::parse`, which keeps the byte span of every
//! key and value; this module then walks the document itself so that it can report *all* the
//! semantic errors of a file at once, each at the key, value or expression token it is about.
//! A TOML syntax error stops there (no tree exists to walk).
//!
//! # File format
//!
//! ```toml
//! coordinates = [                 # top-level key: must come before the first [table] header
//!   { name = "d1", unit = "m", home = 0.9 },     # unit: "m", "rad" or "deg" (home converted)
//! ]
//!
//! [robot]
//! name = "stewart_6ups"           # snake_case, the generated crate's name
//! description = "..."             # optional
//! gravity = [0, 0, -9.81]         # parameter expressions
//! actuated = ["d1"]               # coordinates q
//! outputs = ["x"]                 # task coordinates, disjoint from `actuated`
//!
//! [parameters]                    # in order: a value may use only parameters above it
//! r0 = { value = 0.489, unit = "m", doc = "..." }
//! rho = 7800
//! alpha1 = { value = -15, unit = "deg" }   # stored as -15 * (pi / 180)
//!
//! [[body]]
//! name = "leg1_lower"
//! parent = "world"                # optional; "world" or a body defined above
//! transforms = ["Rz(alpha1)", "Tx(r0)", ["x", "y", "z", 0, 0, 0, 1, 2, 3, 4, 5, 6]]
//! mass = "m"                      # with `inertia`, or instead of both: `solid`
//! com = [0, 0, 0.25]              # optional, body frame
//! inertia = [1, 1, 1, 0, 0, 0]    # [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] about the com, body axes
//! solid = { shape = "cylinder", radius = 0.05, length = 0.5, density = "rho" }
//!
//! [[loop]]
//! name = "leg1"
//! a = { body = "leg1_upper" }
//! b = { body = "platform", transforms = ["Rz(beta1)", "Tx(rp)"] }
//! components = ["x", "y", "z"]    # optional
//! ```
//!
//! Decisions beyond the basics:
//!
//! - `inertia` entries `Ixy, Ixz, Iyz` are the off-diagonal *entries of the inertia matrix*
//!   (`I_xy = -∫ x y dm`), as in URDF and MuJoCo's `fullinertia`.
//! - Solids (homogeneous, centred on the centre of mass, which still comes from `com`):
//!   `cylinder` (`radius`, `length`, axis `z`), `box` (`size = [a, b, c]` along `x, y, z`),
//!   each with either `density` or `mass`; `rod` (a thin rod along `z`: `length` and `mass`,
//!   `Ixx = Iyy = m L^2 / 12`, `Izz = 0`).
//! - A coordinate unit is `m`, `rad` or `deg`; `home` is optional (default 0) and may be a
//!   parameter expression.
//! - Names of parameters, coordinates, bodies and loops are identifiers that are not Rust
//!   keywords (they become Rust names); `pi` and the function names are reserved.
//! - Every coordinate must be used by at least one transform (otherwise the mass matrix and
//!   the constraint Jacobian would have a zero column).
//! - A unary minus directly in front of a number literal is folded into the number.

use std::collections::HashMap;
use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::diagnostics::{Diagnostic, Diagnostics};
use crate::model::{
    Attachment, Axis, Body, Coordinate, Expr, Func, Loop, MassProps, Model, Parameter, Pos, Step,
};

type Value<'a> = Spanned<DeValue<'a>>;
type Span = Range<usize>;

/// Parses and validates a model file. `path` is only used in messages.
pub fn parse_model(path: &str, source: &str) -> Result<Model, Diagnostics> {
    let doc = match DeTable::parse(source) {
        Ok(doc) => doc,
        Err(e) => {
            let cx = Cx::new(source);
            return Err(Diagnostics::new(path, source, vec![toml_error(&cx, &e)]));
        }
    };
    let mut p = Parser::new(source);
    let model = p.model(doc.get_ref());
    match model {
        Some(model) if p.cx.diags.is_empty() => Ok(model),
        _ => {
            let mut items = std::mem::take(&mut p.cx.diags);
            if items.is_empty() {
                // Cannot happen: every `None` comes with an error. Stay total anyway.
                items.push(Diagnostic::new(
                    Pos { line: 1, col: 1 },
                    1,
                    "internal error: incomplete model",
                    "",
                ));
            }
            Err(Diagnostics::new(path, source, items))
        }
    }
}

/// Reads and parses a model file. An unreadable file is reported as one error at 1:1; a file
/// that is not UTF-8 at the first invalid byte.
pub fn parse_model_file(path: &std::path::Path) -> Result<Model, Diagnostics> {
    let shown = path.display().to_string();
    match std::fs::read(path) {
        Err(e) => Err(Diagnostics::new(
            shown.clone(),
            String::new(),
            vec![Diagnostic::new(
                Pos { line: 1, col: 1 },
                1,
                format!("cannot read `{shown}`: {e}"),
                "",
            )],
        )),
        Ok(bytes) => match std::str::from_utf8(&bytes) {
            Ok(source) => parse_model(&shown, source),
            Err(e) => {
                let good = &bytes[..e.valid_up_to()];
                let text = String::from_utf8_lossy(&bytes).into_owned();
                // The valid prefix is unchanged by the lossy conversion.
                let cx = Cx::new(&text);
                let pos = cx.pos(good.len());
                let d =
                    Diagnostic::new(pos, 1, "the model file is not valid UTF-8", "invalid byte");
                Err(Diagnostics::new(shown, text.clone(), vec![d]))
            }
        },
    }
}

fn toml_error(cx: &Cx<'_>, e: &toml::de::Error) -> Diagnostic {
    let span = e.span().unwrap_or(0..0);
    let text = e.message().trim();
    let first = text.lines().next().unwrap_or("").trim();
    let (mut message, label) = match first.split_once(", expected ") {
        Some((m, exp)) => (m.to_string(), format!("expected {exp}")),
        None => (first.to_string(), String::new()),
    };
    if message == "duplicate key" {
        let key = cx.text(&span);
        if !key.is_empty() && !key.contains('\n') && key.chars().count() <= 60 {
            message = format!("duplicate key `{key}`");
        }
    }
    if message.is_empty() {
        message = "invalid TOML".to_string();
    }
    Diagnostic::new(
        cx.pos(span.start),
        cx.len(&span),
        format!("TOML syntax: {message}"),
        label,
    )
}

// ---------------------------------------------------------------------------------------------
// Positions and error collection

struct Cx<'s> {
    src: &'s str,
    line_starts: Vec<usize>,
    diags: Vec<Diagnostic>,
}

impl<'s> Cx<'s> {
    fn new(src: &'s str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(
            src.bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(i, _)| i + 1),
        );
        Cx {
            src,
            line_starts,
            diags: Vec::new(),
        }
    }

    fn floor(&self, mut byte: usize) -> usize {
        byte = byte.min(self.src.len());
        while byte > 0 && !self.src.is_char_boundary(byte) {
            byte -= 1;
        }
        byte
    }

    fn pos(&self, byte: usize) -> Pos {
        let mut byte = self.floor(byte);
        // The `\n` of a CRLF line ending, or the end of a file that ends in a lone `\r`, is
        // reported at the `\r`: one column past the end of the line's text, as for LF files
        // (the `\r` is not shown when the line is quoted).
        let rest = &self.src.as_bytes()[byte..];
        if byte > 0
            && self.src.as_bytes()[byte - 1] == b'\r'
            && (rest.is_empty() || rest[0] == b'\n')
        {
            byte -= 1;
        }
        let line = match self.line_starts.binary_search(&byte) {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        };
        let start = self.line_starts.get(line).copied().unwrap_or(0).min(byte);
        let col = self
            .src
            .get(start..byte)
            .map(|s| s.chars().count())
            .unwrap_or(0)
            + 1;
        Pos {
            line: line + 1,
            col,
        }
    }

    fn text(&self, span: &Span) -> &'s str {
        let (a, b) = (self.floor(span.start), self.floor(span.end));
        self.src.get(a..b.max(a)).unwrap_or("")
    }

    /// Characters in `span` (at least 1).
    fn len(&self, span: &Span) -> usize {
        self.text(span).chars().count().max(1)
    }

    fn line(&self, span: &Span) -> usize {
        self.pos(span.start).line
    }

    fn error(
        &mut self,
        span: &Span,
        message: impl Into<String>,
        label: impl Into<String>,
    ) -> &mut Diagnostic {
        let d = Diagnostic::new(self.pos(span.start), self.len(span), message, label);
        self.push(d)
    }

    fn error_at(
        &mut self,
        pos: Pos,
        len: usize,
        message: impl Into<String>,
        label: impl Into<String>,
    ) -> &mut Diagnostic {
        self.push(Diagnostic::new(pos, len, message, label))
    }

    fn push(&mut self, d: Diagnostic) -> &mut Diagnostic {
        self.diags.push(d);
        let last = self.diags.len() - 1;
        &mut self.diags[last]
    }
}

/// "a string", "an integer"...
fn type_name(v: &DeValue<'_>) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

fn get<'b, 'a>(t: &'b DeTable<'a>, key: &str) -> Option<&'b Value<'a>> {
    t.iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(_, v)| v)
}

fn key_span(t: &DeTable<'_>, key: &str) -> Option<Span> {
    t.iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(k, _)| k.span())
}

fn list(items: &[&str]) -> String {
    let quoted: Vec<String> = items.iter().map(|s| format!("`{s}`")).collect();
    match quoted.len() {
        0 => String::new(),
        1 => quoted[0].clone(),
        n => format!("{} or {}", quoted[..n - 1].join(", "), quoted[n - 1]),
    }
}

// ---------------------------------------------------------------------------------------------
// Names

/// Levenshtein distance, `None` when either string is too long to bother.
fn edit_distance(a: &str, b: &str) -> Option<usize> {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    if a.len() > 64 || b.len() > 64 {
        return None;
    }
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for i in 1..=a.len() {
        cur[0] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    Some(prev[b.len()])
}

/// `did you mean `x` (line N)?` for the closest candidate within edit distance 2.
fn suggest<'c>(
    name: &str,
    candidates: impl IntoIterator<Item = (&'c str, Option<usize>)>,
) -> Option<String> {
    let mut best: Option<(usize, &str, Option<usize>)> = None;
    for (cand, line) in candidates {
        if cand == name || cand.is_empty() {
            continue;
        }
        let Some(d) = edit_distance(name, cand) else {
            continue;
        };
        let close = d <= 2 && d < name.chars().count().max(cand.chars().count());
        // A difference in case only is the closest match of all.
        let d = if name.to_lowercase() == cand.to_lowercase() {
            0
        } else {
            d
        };
        if (close || d == 0) && best.is_none_or(|(bd, _, _)| d < bd) {
            best = Some((d, cand, line));
        }
    }
    best.map(|(_, cand, line)| match line {
        Some(l) => format!("did you mean `{cand}` (line {l})?"),
        None => format!("did you mean `{cand}`?"),
    })
}

fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "_",
];

const FUNCS: &[(&str, Func)] = &[
    ("sin", Func::Sin),
    ("cos", Func::Cos),
    ("tan", Func::Tan),
    ("sqrt", Func::Sqrt),
];
const FUNC_NAMES: &[&str] = &["sin", "cos", "tan", "sqrt"];
const STEP_NAMES: &[&str] = &["Rx", "Ry", "Rz", "Tx", "Ty", "Tz"];

fn is_snake_case(s: &str) -> bool {
    !s.is_empty()
        && s.starts_with(|c: char| c.is_ascii_lowercase())
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !s.ends_with('_')
        && !s.contains("__")
}

/// A snake_case spelling of `s` (for the help of a bad robot name).
fn to_snake_case(s: &str) -> String {
    let mut out = String::new();
    let chars: Vec<char> = s.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if c.is_ascii_uppercase() {
            let prev_lower =
                i > 0 && (chars[i - 1].is_ascii_lowercase() || chars[i - 1].is_ascii_digit());
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_ascii_lowercase());
            let prev_upper = i > 0 && chars[i - 1].is_ascii_uppercase();
            if prev_lower || (prev_upper && next_lower) {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else if c.is_ascii_alphanumeric() {
            out.push(c);
        } else {
            out.push('_');
        }
    }
    let mut parts: Vec<&str> = out.split('_').filter(|p| !p.is_empty()).collect();
    while parts
        .first()
        .is_some_and(|p| p.starts_with(|c: char| c.is_ascii_digit()))
    {
        parts.remove(0);
    }
    parts.join("_")
}

// ---------------------------------------------------------------------------------------------
// Exact numbers

#[derive(Debug, PartialEq)]
enum NumError {
    Syntax,
    TooLarge,
}

fn gcd(mut a: i128, mut b: i128) -> i128 {
    a = a.checked_abs().unwrap_or(i128::MAX);
    b = b.checked_abs().unwrap_or(i128::MAX);
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

/// An exact rational from a decimal literal: `[+-]digits[.digits][(e|E)[+-]digits]`
/// (at least one digit in the mantissa; `.5` and `5.` are accepted).
fn parse_decimal(s: &str) -> Result<(i128, i128), NumError> {
    let (neg, rest) = match s.as_bytes().first() {
        Some(b'-') => (true, &s[1..]),
        Some(b'+') => (false, &s[1..]),
        _ => (false, s),
    };
    let (mant, exp) = match rest.find(['e', 'E']) {
        Some(i) => (&rest[..i], Some(&rest[i + 1..])),
        None => (rest, None),
    };
    let (int, frac) = match mant.find('.') {
        Some(i) => (&mant[..i], &mant[i + 1..]),
        None => (mant, ""),
    };
    if int.is_empty() && frac.is_empty() {
        return Err(NumError::Syntax);
    }
    if !int.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) {
        return Err(NumError::Syntax);
    }
    let mut e10: i64 = 0;
    if let Some(exp) = exp {
        let (eneg, edigits) = match exp.as_bytes().first() {
            Some(b'-') => (true, &exp[1..]),
            Some(b'+') => (false, &exp[1..]),
            _ => (false, exp),
        };
        if edigits.is_empty() || !edigits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(NumError::Syntax);
        }
        let edigits = edigits.trim_start_matches('0');
        if edigits.len() > 6 {
            return Err(NumError::TooLarge);
        }
        let v: i64 = edigits.parse().unwrap_or(0);
        e10 = if eneg { -v } else { v };
    }
    let mut digits: String = int.chars().chain(frac.chars()).collect();
    e10 -= frac.len() as i64;
    let lead = digits.len() - digits.trim_start_matches('0').len();
    digits.drain(..lead);
    while digits.ends_with('0') {
        digits.pop();
        e10 += 1;
    }
    if digits.is_empty() {
        return Ok((0, 1));
    }
    if digits.len() > 38 || e10.abs() > 38 {
        return Err(NumError::TooLarge);
    }
    let d: i128 = digits.parse().map_err(|_| NumError::TooLarge)?;
    let scale = 10i128
        .checked_pow(e10.unsigned_abs() as u32)
        .ok_or(NumError::TooLarge)?;
    let (mut num, mut den) = if e10 >= 0 {
        (d.checked_mul(scale).ok_or(NumError::TooLarge)?, 1)
    } else {
        (d, scale)
    };
    let g = gcd(num, den);
    if g > 1 {
        num /= g;
        den /= g;
    }
    Ok((if neg { -num } else { num }, den))
}

// ---------------------------------------------------------------------------------------------
// Expressions: lexer and parser into a raw tree (names unresolved)

/// Maximal nesting (parentheses, unary minus, exponents) and number of tokens of one
/// expression: deeper input is an error, never a stack overflow.
const MAX_DEPTH: usize = 64;
const MAX_TOKENS: usize = 1000;

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(String),
    Ident(String),
    Op(char),
    End,
}

/// A character range inside an expression string: (offset, length) in characters.
type At = (usize, usize);

#[derive(Debug)]
struct ExprError {
    at: At,
    message: String,
    label: String,
    help: Option<String>,
}

fn expr_err(at: At, message: impl Into<String>, label: impl Into<String>) -> ExprError {
    ExprError {
        at,
        message: message.into(),
        label: label.into(),
        help: None,
    }
}

fn lex(s: &str) -> Result<Vec<(Tok, At)>, ExprError> {
    let chars: Vec<char> = s.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let start = i;
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        if out.len() >= MAX_TOKENS {
            return Err(expr_err(
                (start, 1),
                format!("expression is too long (more than {MAX_TOKENS} tokens)"),
                "",
            ));
        }
        if c.is_ascii_digit() || (c == '.' && chars.get(i + 1).is_some_and(|d| d.is_ascii_digit()))
        {
            while i < chars.len() && chars[i].is_ascii_digit() {
                i += 1;
            }
            if i < chars.len() && chars[i] == '.' {
                i += 1;
                while i < chars.len() && chars[i].is_ascii_digit() {
                    i += 1;
                }
            }
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    while j < chars.len() && chars[j].is_ascii_digit() {
                        j += 1;
                    }
                    i = j;
                }
            }
            out.push((
                Tok::Num(chars[start..i].iter().collect()),
                (start, i - start),
            ));
        } else if c.is_ascii_alphabetic() || c == '_' {
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push((
                Tok::Ident(chars[start..i].iter().collect()),
                (start, i - start),
            ));
        } else if "+-*/^(),".contains(c) {
            i += 1;
            out.push((Tok::Op(c), (start, 1)));
        } else {
            let mut e = expr_err(
                (start, 1),
                format!("unexpected character `{c}` in expression"),
                "not allowed here",
            );
            if matches!(c, '[' | '{') {
                e.help = Some("group with `(` and `)`".to_string());
            }
            return Err(e);
        }
    }
    out.push((Tok::End, (chars.len(), 1)));
    Ok(out)
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

#[derive(Debug)]
enum Raw {
    Num(i128, i128),
    Ident(String, At),
    Call(String, At, Vec<Raw>),
    Neg(Box<Raw>),
    Bin(BinOp, Box<Raw>, Box<Raw>),
}

struct ExprParser {
    toks: Vec<(Tok, At)>,
    i: usize,
    depth: usize,
}

fn describe(t: &Tok) -> String {
    match t {
        Tok::Num(s) => format!("number `{s}`"),
        Tok::Ident(s) => format!("`{s}`"),
        Tok::Op(c) => format!("`{c}`"),
        Tok::End => "the end of the expression".to_string(),
    }
}

/// Parses an expression: `+ -` < `* /` < unary `-` < `^` (right-associative), calls
/// `name(args)`, parentheses.
fn parse_raw(s: &str) -> Result<Raw, ExprError> {
    let toks = lex(s)?;
    if toks.len() == 1 {
        return Err(expr_err(
            (0, s.chars().count().max(1)),
            "empty expression",
            "expected a number or an expression",
        ));
    }
    let mut p = ExprParser {
        toks,
        i: 0,
        depth: 0,
    };
    let e = p.sum()?;
    let (t, at) = p.peek();
    if *t != Tok::End {
        let t = t.clone();
        let mut err = expr_err(
            at,
            format!("expected an operator, found {}", describe(&t)),
            "expected `+`, `-`, `*`, `/` or `^`",
        );
        if t == Tok::Op(')') {
            err.label = "no matching `(`".to_string();
            err.message = "unmatched `)`".to_string();
        }
        return Err(err);
    }
    Ok(e)
}

impl ExprParser {
    fn peek(&self) -> (&Tok, At) {
        let (t, at) = &self.toks[self.i.min(self.toks.len() - 1)];
        (t, *at)
    }
    fn bump(&mut self) {
        if self.i < self.toks.len() - 1 {
            self.i += 1;
        }
    }
    fn sum(&mut self) -> Result<Raw, ExprError> {
        let mut lhs = self.product()?;
        loop {
            let op = match self.peek().0 {
                Tok::Op('+') => BinOp::Add,
                Tok::Op('-') => BinOp::Sub,
                _ => return Ok(lhs),
            };
            self.bump();
            let rhs = self.product()?;
            lhs = Raw::Bin(op, Box::new(lhs), Box::new(rhs));
        }
    }
    fn product(&mut self) -> Result<Raw, ExprError> {
        let mut lhs = self.unary()?;
        loop {
            let op = match self.peek().0 {
                Tok::Op('*') => BinOp::Mul,
                Tok::Op('/') => BinOp::Div,
                _ => return Ok(lhs),
            };
            self.bump();
            let rhs = self.unary()?;
            lhs = Raw::Bin(op, Box::new(lhs), Box::new(rhs));
        }
    }
    fn unary(&mut self) -> Result<Raw, ExprError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(expr_err(
                self.peek().1,
                "expression is nested too deeply",
                format!("more than {MAX_DEPTH} levels"),
            ));
        }
        let r = match self.peek().0 {
            Tok::Op('-') => {
                self.bump();
                match self.unary()? {
                    Raw::Num(n, d) => Raw::Num(-n, d),
                    e => Raw::Neg(Box::new(e)),
                }
            }
            Tok::Op('+') => {
                self.bump();
                self.unary()?
            }
            _ => self.power()?,
        };
        self.depth -= 1;
        Ok(r)
    }
    fn power(&mut self) -> Result<Raw, ExprError> {
        let base = self.atom()?;
        if *self.peek().0 == Tok::Op('^') {
            self.bump();
            let exp = self.unary()?;
            return Ok(Raw::Bin(BinOp::Pow, Box::new(base), Box::new(exp)));
        }
        Ok(base)
    }
    fn atom(&mut self) -> Result<Raw, ExprError> {
        let (t, at) = self.peek();
        let t = t.clone();
        match t {
            Tok::Num(s) => {
                self.bump();
                match parse_decimal(&s) {
                    Ok((n, d)) => Ok(Raw::Num(n, d)),
                    Err(NumError::TooLarge) => Err(number_too_large(at, &s)),
                    Err(NumError::Syntax) => Err(expr_err(at, format!("invalid number `{s}`"), "")),
                }
            }
            Tok::Ident(name) => {
                self.bump();
                if *self.peek().0 != Tok::Op('(') {
                    return Ok(Raw::Ident(name, at));
                }
                let open = self.peek().1;
                self.bump();
                let mut args = Vec::new();
                if *self.peek().0 != Tok::Op(')') {
                    loop {
                        args.push(self.sum()?);
                        match self.peek().0 {
                            Tok::Op(',') => self.bump(),
                            Tok::Op(')') => break,
                            _ => return Err(self.unclosed(open)),
                        }
                    }
                }
                self.bump();
                Ok(Raw::Call(name, at, args))
            }
            Tok::Op('(') => {
                self.bump();
                let e = self.sum()?;
                if *self.peek().0 != Tok::Op(')') {
                    return Err(self.unclosed(at));
                }
                self.bump();
                Ok(e)
            }
            t => {
                let mut e = expr_err(
                    at,
                    format!("expected a number, a name or `(`, found {}", describe(&t)),
                    "expected an operand",
                );
                let after_star = self.i > 0 && self.toks[self.i - 1].0 == Tok::Op('*');
                if t == Tok::Op('*') && after_star {
                    e.help = Some("`**` is not an operator: write `a^b` for powers".to_string());
                }
                Err(e)
            }
        }
    }
    fn unclosed(&self, open: At) -> ExprError {
        let (t, at) = self.peek();
        if *t == Tok::End {
            expr_err(open, "unclosed `(`", "this `(` is never closed")
        } else {
            expr_err(
                at,
                format!("expected `)`, found {}", describe(t)),
                format!("to close the `(` at offset {}", open.0 + 1),
            )
        }
    }
}

fn number_too_large(at: At, s: &str) -> ExprError {
    let mut e = expr_err(
        at,
        format!("number `{s}` cannot be represented exactly"),
        "too large or too precise",
    );
    e.help = Some(
        "numbers are exact rationals with at most 38 significant digits and exponents up to 38"
            .to_string(),
    );
    e
}

// ---------------------------------------------------------------------------------------------
// Expression building helpers

fn bx(e: Expr) -> Box<Expr> {
    Box::new(e)
}
fn mul(a: Expr, b: Expr) -> Expr {
    Expr::Mul(bx(a), bx(b))
}
fn add(a: Expr, b: Expr) -> Expr {
    Expr::Add(bx(a), bx(b))
}
fn div(a: Expr, b: Expr) -> Expr {
    Expr::Div(bx(a), bx(b))
}
fn sq(a: Expr) -> Expr {
    Expr::Pow(bx(a), bx(Expr::int(2)))
}
fn deg_to_rad(e: Expr) -> Expr {
    mul(e, div(Expr::Pi, Expr::int(180)))
}

fn step_eq(a: &Step, b: &Step) -> bool {
    match (a, b) {
        (Step::Rot(x, e), Step::Rot(y, f)) | (Step::Trans(x, e), Step::Trans(y, f)) => {
            x == y && e == f
        }
        _ => false,
    }
}

/// Short display of a number for messages (6 significant digits).
fn fmt_num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    let r: f64 = format!("{v:.5e}").parse().unwrap_or(v);
    if r == 0.0 || (1e-4..1e7).contains(&r.abs()) {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

// ---------------------------------------------------------------------------------------------
// Names in scope

#[derive(Debug, Clone, Copy, PartialEq)]
enum SymKind {
    Param,
    Coord,
}

#[derive(Debug, Clone)]
struct Sym {
    kind: SymKind,
    index: usize,
    line: usize,
}

/// Where an expression may be used.
struct Scope<'a> {
    /// "the mass of body `leg1_lower`".
    what: &'a str,
    /// Coordinates are allowed (transforms only).
    coords: bool,
    /// Parameters with an index below this are allowed.
    params_before: usize,
    /// The parameter being defined, if any.
    this_param: Option<usize>,
}

impl<'a> Scope<'a> {
    fn constant(what: &'a str) -> Self {
        Scope {
            what,
            coords: false,
            params_before: usize::MAX,
            this_param: None,
        }
    }
    fn transform(what: &'a str) -> Self {
        Scope {
            what,
            coords: true,
            params_before: usize::MAX,
            this_param: None,
        }
    }
}

/// Maps character offsets inside an expression to file positions.
struct StrLoc {
    span: Span,
    /// Position of the first character of the string's content, when offsets map one to one
    /// (a one-line string without escapes); otherwise errors point at the whole value.
    first: Option<Pos>,
}

// ---------------------------------------------------------------------------------------------
// The walker

/// A resolved value: the expression and whether it depends on a parameter that had an error
/// (then its numeric checks are skipped, to avoid follow-up errors).
struct Resolved {
    expr: Expr,
    tainted: bool,
    span: Span,
}

struct BodyInfo {
    index: usize,
    line: usize,
}

struct Parser<'s> {
    cx: Cx<'s>,
    syms: HashMap<String, Sym>,
    /// Names in definition order, for suggestions.
    sym_list: Vec<(String, usize, SymKind)>,
    param_values: Vec<f64>,
    param_bad: Vec<bool>,
    coord_count: usize,
    coord_used: Vec<bool>,
    bodies: HashMap<String, BodyInfo>,
    body_list: Vec<(String, usize)>,
    /// Table span start -> keys that an unknown key of that table is a misspelling of.
    typos: HashMap<usize, Vec<String>>,
    /// Key spans (start) not to report as unknown (a misplaced `coordinates`).
    skip_keys: Vec<usize>,
}

const TOP_KEYS: &[&str] = &[
    "coordinates",
    "robot",
    "parameters",
    "body",
    "loop",
    "codegen",
];
const ROBOT_KEYS: &[&str] = &["name", "description", "gravity", "actuated", "outputs"];
const PARAM_KEYS: &[&str] = &["value", "unit", "doc"];
const COORD_KEYS: &[&str] = &["name", "unit", "home"];
const BODY_KEYS: &[&str] = &[
    "name",
    "parent",
    "transforms",
    "mass",
    "com",
    "inertia",
    "solid",
];
const LOOP_KEYS: &[&str] = &["name", "a", "b", "components"];
const ATTACH_KEYS: &[&str] = &["body", "transforms"];
const SHAPES: &[&str] = &["cylinder", "box", "rod"];

impl<'s> Parser<'s> {
    fn new(src: &'s str) -> Self {
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
        }
    }

    /// True when an unknown key of the table at `span` was reported as a misspelling of `key`
    /// (then `key` is not reported missing as well).
    fn is_typo(&self, span: &Span, key: &str) -> bool {
        self.typos
            .get(&span.start)
            .is_some_and(|t| t.iter().any(|k| k == key))
    }

    fn errors(&self) -> usize {
        self.cx.diags.len()
    }

    // ---- generic helpers --------------------------------------------------------------------

    /// Reports keys of `t` that are not in `allowed`.
    fn check_keys(&mut self, t: &DeTable<'_>, table_span: &Span, allowed: &[&str], table: &str) {
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
            d.help = help;
            if d.help.is_none() && TOP_KEYS.contains(&key) && !table.starts_with("at ") {
                d.help = Some(format!(
                    "`{key}` belongs at the top level: TOML puts every key after a `[table]` header into that table"
                ));
            }
        }
    }

    fn table<'b, 'a>(&mut self, v: &'b Value<'a>, what: &str) -> Option<&'b DeTable<'a>> {
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

    fn array<'b, 'a>(&mut self, v: &'b Value<'a>, what: &str) -> Option<&'b [Value<'a>]> {
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

    fn string(&mut self, v: &Value<'_>, what: &str) -> Option<String> {
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
    fn required<'b, 'a>(
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
    fn name(&mut self, v: &Value<'_>, kind: &str) -> Option<String> {
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

    fn str_loc(&self, v: &Value<'_>, decoded: &str) -> StrLoc {
        let span = v.span();
        let raw = self.cx.text(&span);
        let simple = (raw.starts_with('"') && !raw.starts_with("\"\"\""))
            || (raw.starts_with('\'') && !raw.starts_with("'''"));
        let first = if simple
            && raw.len() >= 2
            && raw.get(1..raw.len() - 1) == Some(decoded)
            && !decoded.contains('\n')
        {
            Some(self.cx.pos(span.start + 1))
        } else {
            None
        };
        StrLoc { span, first }
    }

    fn expr_error(&mut self, loc: &StrLoc, e: ExprError) {
        let d = match loc.first {
            Some(p) => {
                let pos = Pos {
                    line: p.line,
                    col: p.col.saturating_add(e.at.0),
                };
                Diagnostic::new(pos, e.at.1, e.message, e.label)
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
    fn expr(&mut self, v: &Value<'_>, scope: &Scope<'_>) -> Option<Resolved> {
        let span = v.span();
        let loc = StrLoc {
            span: span.clone(),
            first: None,
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
    fn resolve(
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
                let Some(&(_, func)) = FUNCS.iter().find(|(n, _)| n == name) else {
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
                if args.len() != 1 {
                    self.expr_error(
                        loc,
                        expr_err(
                            *at,
                            format!("`{name}` takes 1 argument, found {}", args.len()),
                            "expected one argument",
                        ),
                    );
                    return None;
                }
                let arg = resolved.into_iter().next().flatten()?;
                Some(Expr::Call(func, bx(arg)))
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
    fn eval(&self, e: &Expr) -> f64 {
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
            Expr::Call(f, a) => {
                let v = self.eval(a);
                match f {
                    Func::Sin => v.sin(),
                    Func::Cos => v.cos(),
                    Func::Tan => v.tan(),
                    Func::Sqrt => v.sqrt(),
                }
            }
        }
    }

    /// A constant expression that must evaluate to a finite number.
    fn finite(&mut self, v: &Value<'_>, scope: &Scope<'_>) -> Option<(Expr, f64, bool)> {
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
    fn vector<const N: usize>(
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

    fn model(&mut self, root: &DeTable<'_>) -> Option<Model> {
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
                    "add `[robot]` with `name`, `gravity`, `actuated` and `outputs`".to_string(),
                );
                None
            }
        };

        let errors_before = self.errors();
        let bodies = match get(root, "body") {
            Some(v) => self.bodies(v),
            None => {
                let d = self.cx.error_at(top, 1, "the model has no bodies", "");
                d.help = Some("add a `[[body]]` with `name` and `transforms`".to_string());
                None
            }
        };
        let loops = match get(root, "loop") {
            Some(v) => self.loops(v),
            None => {
                let d = self
                    .cx
                    .error_at(top, 1, "the model has no loop closure", "");
                d.help = Some("add a `[[loop]]` with `name`, `a` and `b`: a parallel robot closes at least one loop".to_string());
                None
            }
        };
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
            let m: usize = loops.iter().map(|l| l.components.len()).sum();
            let k = actuated.len();
            if n.checked_sub(m) != Some(k) {
                let dof = n as i64 - m as i64;
                let d = self.cx.error(
                    span,
                    format!(
                        "the model has {n} coordinates and {m} constraint equations, so {dof} degree{} of freedom, but {k} actuated coordinate{}",
                        if dof == 1 { "" } else { "s" },
                        if k == 1 { "" } else { "s" }
                    ),
                    "one actuated coordinate per degree of freedom",
                );
                d.help = Some(
                    "each `[[loop]]` adds one equation per entry of `components` (3 by default: x, y, z)".to_string(),
                );
            }
        }

        if let Some(v) = get(root, "codegen") {
            self.codegen_section(v);
        }
        let robot = robot?;
        Some(Model {
            name: robot.name?,
            description: robot.description,
            parameters: parameters?,
            coordinates: coordinates?,
            actuated: robot.actuated?.0,
            outputs: robot.outputs?,
            gravity: robot.gravity?,
            bodies: bodies?,
            loops: loops?,
        })
    }

    /// `[codegen]`: read by earlier versions (a Horner-search effort per model); the generator
    /// now keeps named intermediates and has no such setting, so the section is an error that
    /// says so rather than a silent no-op.
    fn codegen_section(&mut self, v: &Value<'_>) {
        self.cx.error(
            &v.span(),
            "`[codegen]` is no longer read".to_string(),
            "remove this section: code generation keeps named intermediates and needs no Horner-search setting",
        );
    }

    /// Declares the parameter and coordinate names (one namespace), reporting duplicates.
    /// Returns `false` if a coordinate's name was rejected (reserved or already taken).
    fn declare_names(
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

    fn parameters(&mut self, t: &DeTable<'_>) -> Option<Vec<Parameter>> {
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

    fn parameter(
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

    fn coordinates(&mut self, items: &[Value<'_>]) -> Option<Vec<Coordinate>> {
        let mut out = Vec::new();
        let mut ok = true;
        for item in items {
            let c = self.coordinate(item);
            ok &= c.is_some();
            out.extend(c);
        }
        ok.then_some(out)
    }

    fn coordinate(&mut self, item: &Value<'_>) -> Option<Coordinate> {
        let t = self.table(item, "a coordinate")?;
        self.check_keys(t, &item.span(), COORD_KEYS, "a coordinate");
        let name_v = self.required(t, &item.span(), "name", "a coordinate");
        let name = name_v.and_then(|v| self.name(v, "coordinate"));
        let shown = name.clone().unwrap_or_else(|| "?".to_string());
        let unit_v = self.required(t, &item.span(), "unit", &format!("coordinate `{shown}`"));
        let unit = match unit_v {
            Some(u) => match self.string(u, &format!("the unit of coordinate `{shown}`")) {
                Some(s) if ["m", "rad", "deg"].contains(&s.as_str()) => Some(s),
                Some(s) => {
                    let d = self.cx.error(
                        &u.span(),
                        format!("unknown unit `{s}` for coordinate `{shown}`"),
                        "expected `m`, `rad` or `deg`",
                    );
                    d.help = suggest(&s, ["m", "rad", "deg"].iter().map(|u| (*u, None)));
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
        let (name, unit, mut home) = (name?, unit?, home?);
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
            pos: self.cx.pos(name_v.map(|v| v.span().start).unwrap_or(0)),
        })
    }

    fn robot(&mut self, v: &Value<'_>) -> Option<RobotSection> {
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
        let outputs_v = self.required(t, &span, "outputs", "`[robot]`");
        let outputs = outputs_v.and_then(|o| self.coord_list(o, "outputs"));
        // Disjoint.
        let mut clash = false;
        if let (Some((act, _)), Some((out, _))) = (&actuated, &outputs) {
            for (c, c_span) in out {
                if let Some((_, a_span)) = act.iter().find(|(a, _)| a == c) {
                    let name = self.cx.text(c_span).trim_matches(['"', '\'']).to_string();
                    let first = self.cx.line(a_span);
                    let d = self.cx.error(
                        c_span,
                        format!("coordinate `{name}` is both actuated and an output"),
                        "also listed in `actuated`",
                    );
                    d.help = Some(format!(
                        "`actuated` (line {first}) and `outputs` must be disjoint: an output is solved for, an actuated coordinate is given"
                    ));
                    clash = true;
                }
            }
        }
        let indices = |l: Option<(Vec<(usize, Span)>, bool)>| match l {
            Some((items, true)) if !clash => {
                Some(items.into_iter().map(|(i, _)| i).collect::<Vec<_>>())
            }
            _ => None,
        };
        let (actuated, outputs) = (indices(actuated), indices(outputs));
        let actuated_key = key_span(t, "actuated").unwrap_or(span.clone());
        Some(RobotSection {
            name,
            description,
            gravity,
            actuated: actuated.map(|a| (a, actuated_key)),
            outputs,
        })
    }

    /// `actuated` / `outputs`: a non-empty list of distinct coordinate names. Returns the
    /// valid entries and whether all entries were valid.
    fn coord_list(&mut self, v: &Value<'_>, key: &str) -> Option<(Vec<(usize, Span)>, bool)> {
        let items = self.array(v, &format!("`{key}`"))?;
        if items.is_empty() {
            let d = self.cx.error(
                &v.span(),
                format!("`{key}` is empty"),
                "expected at least one coordinate",
            );
            d.help = Some(if key == "actuated" {
                "list the actuated coordinates q, one per degree of freedom".to_string()
            } else {
                "list the task coordinates (for example the platform's pose)".to_string()
            });
            return None;
        }
        let mut out = Vec::new();
        let mut ok = true;
        let mut seen: HashMap<String, usize> = HashMap::new();
        for item in items {
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

    fn bodies(&mut self, v: &Value<'_>) -> Option<Vec<Body>> {
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

    fn body_suggestion(&self, name: &str) -> Option<String> {
        suggest(
            name,
            self.body_list
                .iter()
                .map(|(n, l)| (n.as_str(), Some(*l)))
                .chain(std::iter::once(("world", None))),
        )
    }

    fn body(&mut self, i: usize, item: &Value<'_>) -> Option<Body> {
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
    fn steps(&mut self, v: &Value<'_>, what: &str) -> Option<Vec<Step>> {
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
                other => {
                    let d = self.cx.error(
                        &item.span(),
                        format!("a transform must be a string like `Rz(angle)` or a 12-element pose vector, found {}", type_name(other)),
                        "expected a string or an array",
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

    fn step_string(&mut self, item: &Value<'_>, s: &str, what: &str) -> Option<Step> {
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
    fn pose_vector(&mut self, item: &Value<'_>, a: &[Value<'_>], what: &str) -> Option<Vec<Step>> {
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

    fn mass_props(
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
    fn positive(&mut self, v: &Value<'_>, what: &str) -> Option<Expr> {
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
    fn solid(&mut self, v: &Value<'_>, body: &str) -> Option<(Expr, [Expr; 6])> {
        let t = self.table(v, &format!("`solid` of body `{body}`"))?;
        let span = v.span();
        let table = format!("the `solid` of body `{body}`");
        let shape_v = self.required(t, &span, "shape", &table);
        let shape = shape_v.and_then(|s| self.string(s, &format!("the shape of body `{body}`")))?;
        let allowed: &[&str] = match shape.as_str() {
            "cylinder" => &["shape", "radius", "length", "density", "mass"],
            "box" => &["shape", "size", "density", "mass"],
            "rod" => &["shape", "length", "mass"],
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
                let (r, l) = (r?, l?);
                if !ok {
                    return None;
                }
                let m = mass(&|rho| mul(mul(mul(rho, Expr::Pi), sq(r.clone())), l.clone()))?;
                let ixx = div(
                    mul(m.clone(), add(mul(Expr::int(3), sq(r.clone())), sq(l))),
                    Expr::int(12),
                );
                let izz = div(mul(m.clone(), sq(r)), Expr::int(2));
                Some((m, [ixx.clone(), ixx, izz, zero(), zero(), zero()]))
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
                // A thin rod along z.
                let l = self
                    .required(t, &span, "length", &table)
                    .and_then(|l| self.positive(l, &format!("the length of body `{body}`")));
                let m = mass_given??;
                let l = l?;
                let ixx = div(mul(m.clone(), sq(l)), Expr::int(12));
                Some((m, [ixx.clone(), ixx, zero(), zero(), zero(), zero()]))
            }
        }
    }

    // ---- loops ------------------------------------------------------------------------------

    fn loops(&mut self, v: &Value<'_>) -> Option<Vec<Loop>> {
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

    fn one_loop(&mut self, item: &Value<'_>, names: &mut HashMap<String, usize>) -> Option<Loop> {
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
        Some(Loop {
            name: name?,
            a,
            b,
            components: components?,
            pos: self
                .cx
                .pos(name_v.map(|v| v.span().start).unwrap_or(span.start)),
        })
    }

    fn attachment(&mut self, v: &Value<'_>, loop_name: &str, side: &str) -> Option<Attachment> {
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

    fn components(&mut self, v: &Value<'_>, loop_name: &str) -> Option<Vec<Axis>> {
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

struct RobotSection {
    name: Option<String>,
    description: String,
    gravity: Option<[Expr; 3]>,
    actuated: Option<(Vec<usize>, Span)>,
    outputs: Option<Vec<usize>>,
}

/// Eigenvalues of a symmetric 3x3 matrix, ascending.
fn sym_eigenvalues(m: [[f64; 3]; 3]) -> [f64; 3] {
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

/// Checks `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`: positive definite, principal moments satisfy the
/// triangle inequality. Returns (message tail, label) on failure.
fn check_inertia(i: [f64; 6]) -> Option<(String, String)> {
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
    if e[0] <= tol || !e.iter().all(|x| x.is_finite()) {
        return Some(("is not positive definite".to_string(), moments));
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

#[cfg(test)]
mod tests {
    use super::*;

    const STEWART: &str = include_str!("../../models/stewart_6ups.toml");
    const FIVE_BAR: &str = include_str!("../../models/five_bar.toml");

    fn parse_ok(path: &str, src: &str) -> Model {
        match parse_model(path, src) {
            Ok(m) => m,
            Err(d) => panic!("{path} should parse:\n{d}"),
        }
    }

    fn values(m: &Model) -> Vec<f64> {
        m.parameters.iter().map(|p| p.value).collect()
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    /// Resolves one expression string with parameters `a`, `b` (and coordinate `q`).
    fn expr(text: &str) -> Result<Expr, Vec<Diagnostic>> {
        let mut p = Parser::new("");
        for (i, (name, kind)) in [
            ("a", SymKind::Param),
            ("b", SymKind::Param),
            ("q", SymKind::Coord),
        ]
        .iter()
        .enumerate()
        {
            let index = if *kind == SymKind::Param { i } else { 0 };
            p.syms.insert(
                name.to_string(),
                Sym {
                    kind: *kind,
                    index,
                    line: 1,
                },
            );
            p.sym_list.push((name.to_string(), 1, *kind));
        }
        p.param_values = vec![2.0, 3.0];
        p.param_bad = vec![false, false];
        p.coord_used = vec![false];
        let loc = StrLoc {
            span: 0..0,
            first: Some(Pos { line: 1, col: 1 }),
        };
        let raw = parse_raw(text).map_err(|e| {
            p.expr_error(&loc, e);
            p.cx.diags.clone()
        })?;
        let mut tainted = false;
        match p.resolve(&raw, &Scope::transform("a test"), &loc, &mut tainted) {
            Some(e) if p.cx.diags.is_empty() => Ok(e),
            _ => Err(p.cx.diags),
        }
    }

    fn num(n: i128, d: i128) -> Expr {
        Expr::Num { num: n, den: d }
    }
    fn param(i: usize) -> Expr {
        Expr::Param(i)
    }

    #[test]
    fn stewart_model_matches_the_paper_example() {
        let m = parse_ok("models/stewart_6ups.toml", STEWART);
        assert_eq!(m.name, "stewart_6ups");
        let names: Vec<&str> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
        let mut expected: Vec<String> = Vec::new();
        for prefix in ["d", "phi", "psi"] {
            expected.extend((1..=6).map(|i| format!("{prefix}{i}")));
        }
        expected.extend(["x", "y", "z", "rotx", "roty", "rotz"].map(String::from));
        assert_eq!(names, expected);
        assert_eq!(m.actuated, (0..6).collect::<Vec<_>>());
        assert_eq!(m.outputs, (18..24).collect::<Vec<_>>());
        assert_eq!(m.bodies.len(), 13);
        assert_eq!(m.loops.len(), 6);
        assert!(
            m.loops
                .iter()
                .all(|l| l.components == [Axis::X, Axis::Y, Axis::Z])
        );
        let g: Vec<f64> = m.gravity.iter().map(|e| e.eval(&[], &[])).collect();
        assert_eq!(g, [0.0, 0.0, -9.81]);

        let p = values(&m);
        let r0 = m.parameters.iter().find(|p| p.name == "r0").unwrap();
        assert_eq!(r0.expr, num(489, 1000));
        assert_eq!(r0.value, 0.489);
        let alpha1 = m.parameters.iter().find(|p| p.name == "alpha1").unwrap();
        assert_eq!(
            alpha1.expr,
            mul(Expr::int(-15), div(Expr::Pi, Expr::int(180)))
        );
        assert!(close(alpha1.value, -15f64.to_radians(), 1e-15));
        assert_eq!(alpha1.unit, "deg");

        let mass = |name: &str| {
            let b = m.bodies.iter().find(|b| b.name == name).unwrap();
            b.inertia.as_ref().unwrap().mass.eval(&p, &[])
        };
        for i in 1..=6 {
            assert!(close(mass(&format!("leg{i}_lower")), 30.630528372500, 1e-9));
            assert!(close(mass(&format!("leg{i}_upper")), 31.365661053441, 1e-9));
        }
        assert!(close(mass("platform"), 74.160674941682, 1e-9));

        // Cylinder inertia of the lower link, and the centres of mass.
        let lower = &m.bodies[0];
        assert_eq!(lower.name, "leg1_lower");
        assert_eq!(lower.parent, None);
        let mp = lower.inertia.as_ref().unwrap();
        let mm = 30.630528372500;
        let ixx = mm * (3.0 * 0.05f64.powi(2) + 0.25) / 12.0;
        assert!(close(mp.inertia[0].eval(&p, &[]), ixx, 1e-9));
        assert!(close(mp.inertia[1].eval(&p, &[]), ixx, 1e-9));
        assert!(close(mp.inertia[2].eval(&p, &[]), mm * 0.0025 / 2.0, 1e-9));
        assert_eq!(
            mp.com.iter().map(|c| c.eval(&p, &[])).collect::<Vec<_>>(),
            [0.0, 0.0, 0.25]
        );
        let upper = &m.bodies[1];
        assert_eq!((upper.name.as_str(), upper.parent), ("leg1_upper", Some(0)));
        let com = &upper.inertia.as_ref().unwrap().com;
        assert!(close(com[2].eval(&p, &[]), -0.4, 1e-15));
        assert!(matches!(
            &upper.steps[..],
            [Step::Trans(Axis::Z, Expr::Coord(0))]
        ));

        // Leg 1 lower: Rz(alpha1) Tx(r0) Rx(phi1) Ry(psi1).
        let ai = m
            .parameters
            .iter()
            .position(|p| p.name == "alpha1")
            .unwrap();
        let ri = m.parameters.iter().position(|p| p.name == "r0").unwrap();
        match &lower.steps[..] {
            [
                Step::Rot(Axis::Z, Expr::Param(a)),
                Step::Trans(Axis::X, Expr::Param(r)),
                Step::Rot(Axis::X, Expr::Coord(6)),
                Step::Rot(Axis::Y, Expr::Coord(12)),
            ] => {
                assert_eq!((*a, *r), (ai, ri));
            }
            other => panic!("unexpected steps {other:?}"),
        }
        // The home values as written (rbss-codegen assembles them: max |f| 1.4e-12 before).
        assert!(close(m.coordinates[0].home, 0.92942819753, 1e-12));
        assert!(close(m.coordinates[21].home, 0.1, 0.0));
    }

    /// Origin of `body * steps` in the world frame, with plain f64 matrices.
    fn origin(m: &Model, body: Option<usize>, extra: &[Step], p: &[f64], x: &[f64]) -> [f64; 3] {
        let mut chain: Vec<&Step> = Vec::new();
        let mut b = body;
        let mut bodies = Vec::new();
        while let Some(i) = b {
            bodies.push(i);
            b = m.bodies[i].parent;
        }
        for i in bodies.iter().rev() {
            chain.extend(&m.bodies[*i].steps);
        }
        chain.extend(extra);
        let mut r = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut o = [0.0; 3];
        for s in chain {
            match s {
                Step::Trans(ax, e) => {
                    let v = e.eval(p, x);
                    for (k, ok) in o.iter_mut().enumerate() {
                        *ok += r[k][ax.index()] * v;
                    }
                }
                Step::Rot(ax, e) => {
                    let (c, s) = (e.eval(p, x).cos(), e.eval(p, x).sin());
                    let (i, j) = match ax {
                        Axis::X => (1, 2),
                        Axis::Y => (2, 0),
                        Axis::Z => (0, 1),
                    };
                    for row in r.iter_mut() {
                        let (a, b) = (row[i], row[j]);
                        row[i] = a * c + b * s;
                        row[j] = -a * s + b * c;
                    }
                }
            }
        }
        o
    }

    fn max_residual(m: &Model) -> f64 {
        let p = values(m);
        let x: Vec<f64> = m.coordinates.iter().map(|c| c.home).collect();
        let mut worst = 0.0f64;
        for l in &m.loops {
            let a = origin(m, l.a.body, &l.a.steps, &p, &x);
            let b = origin(m, l.b.body, &l.b.steps, &p, &x);
            for c in &l.components {
                worst = worst.max((a[c.index()] - b[c.index()]).abs());
            }
        }
        worst
    }

    #[test]
    fn homes_are_assembled() {
        let s = parse_ok("models/stewart_6ups.toml", STEWART);
        assert!(
            max_residual(&s) < 1e-9,
            "stewart residual {}",
            max_residual(&s)
        );
        let f = parse_ok("models/five_bar.toml", FIVE_BAR);
        assert!(
            max_residual(&f) < 1e-9,
            "five-bar residual {}",
            max_residual(&f)
        );
    }

    #[test]
    fn five_bar_model() {
        let m = parse_ok("models/five_bar.toml", FIVE_BAR);
        assert_eq!(m.name, "five_bar");
        let names: Vec<&str> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["th1", "a1", "th2", "a2", "x", "y"]);
        assert_eq!(m.actuated, [0, 2]);
        assert_eq!(m.outputs, [4, 5]);
        let equations: usize = m.loops.iter().map(|l| l.components.len()).sum();
        assert_eq!(m.coordinates.len() - equations, m.actuated.len());
        let p = values(&m);
        let prox1 = &m.bodies[0];
        let mp = prox1.inertia.as_ref().unwrap();
        assert!(close(
            mp.mass.eval(&p, &[]),
            2700.0 * 0.2 * 0.02 * 0.01,
            1e-12
        ));
        assert!(close(mp.com[0].eval(&p, &[]), 0.1, 1e-15));
        // Box along x: the smallest moment is about x.
        let i: Vec<f64> = mp.inertia.iter().map(|e| e.eval(&p, &[])).collect();
        assert!(i[0] < i[1] && i[1] < i[2], "{i:?}");
        assert_eq!(m.bodies[1].parent, Some(0));
        assert_eq!(m.gravity[1].eval(&p, &[]), -9.81);
        // Elbow-out: the left elbow is left of the left base joint, the right one right of the right.
        let x: Vec<f64> = m.coordinates.iter().map(|c| c.home).collect();
        let e1 = origin(&m, Some(1), &[], &p, &x);
        let e2 = origin(&m, Some(3), &[], &p, &x);
        assert!(e1[0] < -0.15 && e2[0] > 0.15, "{e1:?} {e2:?}");
    }

    #[test]
    fn pose_vector_expansion_order() {
        let src = STEWART.replace("1, 2, 3, 4, 5, 6]]", "4, 5, 6, 1, 2, 3]]");
        let m = parse_ok("t.toml", &src);
        let platform = m.bodies.iter().find(|b| b.name == "platform").unwrap();
        let kinds: Vec<String> = platform
            .steps
            .iter()
            .map(|s| match s {
                Step::Rot(a, Expr::Coord(c)) => {
                    format!("R{}({})", a.name(), m.coordinates[*c].name)
                }
                Step::Trans(a, Expr::Coord(c)) => {
                    format!("T{}({})", a.name(), m.coordinates[*c].name)
                }
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(
            kinds,
            [
                "Rx(rotx)", "Ry(roty)", "Rz(rotz)", "Tx(x)", "Ty(y)", "Tz(z)"
            ]
        );

        let m = parse_ok("t.toml", STEWART);
        let platform = m.bodies.iter().find(|b| b.name == "platform").unwrap();
        let axes: Vec<(bool, Axis)> = platform
            .steps
            .iter()
            .map(|s| match s {
                Step::Rot(a, _) => (true, *a),
                Step::Trans(a, _) => (false, *a),
            })
            .collect();
        assert_eq!(
            axes,
            [
                (false, Axis::X),
                (false, Axis::Y),
                (false, Axis::Z),
                (true, Axis::X),
                (true, Axis::Y),
                (true, Axis::Z)
            ]
        );

        // o_k is the position of transform k: [.., 2, 1, 3, 6, 4, 5] -> Ty Tx Tz Ry Rz Rx.
        let src = STEWART.replace("1, 2, 3, 4, 5, 6]]", "2, 1, 3, 6, 4, 5]]");
        let m = parse_ok("t.toml", &src);
        let platform = m.bodies.iter().find(|b| b.name == "platform").unwrap();
        let names: Vec<String> = platform
            .steps
            .iter()
            .map(|s| match s {
                Step::Rot(a, _) => format!("R{}", a.name()),
                Step::Trans(a, _) => format!("T{}", a.name()),
            })
            .collect();
        assert_eq!(names, ["Ty", "Tx", "Tz", "Ry", "Rz", "Rx"]);
    }

    #[test]
    fn exact_rationals() {
        assert_eq!(parse_decimal("0.489"), Ok((489, 1000)));
        assert_eq!(parse_decimal("12"), Ok((12, 1)));
        assert_eq!(parse_decimal("1e-3"), Ok((1, 1000)));
        assert_eq!(parse_decimal("2.5E+2"), Ok((250, 1)));
        assert_eq!(parse_decimal("0.50"), Ok((1, 2)));
        assert_eq!(parse_decimal("-9.81"), Ok((-981, 100)));
        assert_eq!(parse_decimal("+0.0"), Ok((0, 1)));
        assert_eq!(parse_decimal(".5"), Ok((1, 2)));
        assert_eq!(parse_decimal("5."), Ok((5, 1)));
        assert_eq!(parse_decimal("1000.5e-3"), Ok((2001, 2000)));
        assert_eq!(
            parse_decimal("0.000000000000000000000000000000000000001e38"),
            Ok((1, 10))
        );
        assert_eq!(parse_decimal("1e38"), Ok((10i128.pow(38), 1)));
        assert_eq!(parse_decimal("1e39"), Err(NumError::TooLarge));
        assert_eq!(parse_decimal("1e-39"), Err(NumError::TooLarge));
        assert_eq!(
            parse_decimal("1e999999999999999999999"),
            Err(NumError::TooLarge)
        );
        assert_eq!(
            parse_decimal("123456789012345678901234567890123456789"),
            Err(NumError::TooLarge)
        );
        assert_eq!(
            parse_decimal("1.0000000000000000000000000000000000000000000"),
            Ok((1, 1))
        );
        assert_eq!(parse_decimal("e5"), Err(NumError::Syntax));
        assert_eq!(parse_decimal("1e"), Err(NumError::Syntax));
        assert_eq!(parse_decimal("inf"), Err(NumError::Syntax));
        assert_eq!(parse_decimal("nan"), Err(NumError::Syntax));
        assert_eq!(parse_decimal(""), Err(NumError::Syntax));
        assert_eq!(expr("0.489"), Ok(num(489, 1000)));
        assert_eq!(expr("2.5E+2"), Ok(num(250, 1)));
    }

    #[test]
    fn precedence_and_associativity() {
        let (a, b) = (param(0), param(1));
        let pow = |x: Expr, y: Expr| Expr::Pow(bx(x), bx(y));
        let sub = |x: Expr, y: Expr| Expr::Sub(bx(x), bx(y));
        let neg = |x: Expr| Expr::Neg(bx(x));
        assert_eq!(expr("-a^2"), Ok(neg(pow(a.clone(), Expr::int(2)))));
        assert_eq!(
            expr("2^3^2"),
            Ok(pow(Expr::int(2), pow(Expr::int(3), Expr::int(2))))
        );
        assert_eq!(
            expr("a - b - 1"),
            Ok(sub(sub(a.clone(), b.clone()), Expr::int(1)))
        );
        assert_eq!(
            expr("a + b * 2"),
            Ok(add(a.clone(), mul(b.clone(), Expr::int(2))))
        );
        assert_eq!(
            expr("(a + b) * 2"),
            Ok(mul(add(a.clone(), b.clone()), Expr::int(2)))
        );
        assert_eq!(
            expr("a / b / 2"),
            Ok(div(div(a.clone(), b.clone()), Expr::int(2)))
        );
        assert_eq!(expr("a * -b"), Ok(mul(a.clone(), neg(b.clone()))));
        assert_eq!(expr("-2"), Ok(Expr::int(-2)));
        assert_eq!(expr("2^-1"), Ok(pow(Expr::int(2), Expr::int(-1))));
        assert_eq!(expr("-a*b"), Ok(mul(neg(a.clone()), b.clone())));
        assert_eq!(
            expr("sin(pi / 2)"),
            Ok(Expr::Call(Func::Sin, bx(div(Expr::Pi, Expr::int(2)))))
        );
        assert_eq!(
            expr("sqrt(q)"),
            Ok(Expr::Call(Func::Sqrt, bx(Expr::Coord(0))))
        );
        assert_eq!(expr("1e-3*a"), Ok(mul(num(1, 1000), a.clone())));
        // Errors point at the token, inside the string.
        let e = expr("a + foo * 2").unwrap_err();
        // (The string's content starts at column 1 here.)
        assert_eq!((e[0].pos, e[0].len), (Pos { line: 1, col: 5 }, 3));
        let e = expr("cos(a").unwrap_err();
        assert_eq!(e[0].message, "unclosed `(`");
        let e = expr("a b").unwrap_err();
        assert_eq!(e[0].pos.col, 3);
        assert!(expr(&"(".repeat(200)).is_err());
        assert!(expr(&format!("{}1{}", "(".repeat(60), ")".repeat(60))).is_ok());
    }

    #[test]
    fn error_positions_inside_strings() {
        let src = STEWART.replacen("\"Tx(r0)\"", "\"Tx(r00)\"", 1);
        let d = parse_model("m.toml", &src).unwrap_err();
        assert_eq!(d.items.len(), 1, "{d}");
        let line = src.lines().position(|l| l.contains("r00")).unwrap() + 1;
        let col = src.lines().nth(line - 1).unwrap().find("r00").unwrap() + 1;
        assert_eq!(d.items[0].pos, Pos { line, col });
        let r0_line = src.lines().position(|l| l.starts_with("r0 =")).unwrap() + 1;
        assert_eq!(
            d.items[0].help,
            Some(format!("did you mean `r0` (line {r0_line})?"))
        );
    }

    fn check_rendering(path: &str, src: &str, d: &Diagnostics) {
        let rendered = d.render();
        let lines = src.split('\n').count();
        let mut heads = 0;
        for line in rendered.lines() {
            let Some(rest) = line.strip_prefix(path) else {
                continue;
            };
            heads += 1;
            let mut parts = rest.splitn(4, ':');
            assert_eq!(parts.next(), Some(""), "{line}");
            let l: usize = parts
                .next()
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("bad line in {line:?}"));
            let c: usize = parts
                .next()
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("bad col in {line:?}"));
            assert!(
                parts.next().is_some_and(|s| s.starts_with(" error: ")),
                "{line:?}"
            );
            assert!(
                l >= 1 && l <= lines && c >= 1,
                "position {l}:{c} outside the source in {line:?}"
            );
        }
        assert_eq!(heads, d.items.len(), "{rendered}");
        assert!(!d.items.is_empty());
        assert!(rendered.ends_with(&format!(
            "error: could not compile `{path}`: {} error{}\n",
            d.items.len(),
            if d.items.len() == 1 { "" } else { "s" }
        )));
    }

    /// xorshift64*: a small deterministic generator, no crates needed.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        fn below(&mut self, n: usize) -> usize {
            (self.next() % n.max(1) as u64) as usize
        }
    }

    #[test]
    fn never_panics_on_mutated_models() {
        const WORDS: &[&str] = &[
            "x",
            "d1",
            "phi2",
            "r0",
            "rho",
            "h",
            "-",
            "+",
            "*",
            "/",
            "^",
            "(",
            ")",
            " ",
            "1e9",
            "0.5",
            "1e-40",
            "0",
            "sin",
            "pi",
            "leg1_lower",
            "platform",
            "world",
            "Rz(",
            "Tx(",
            "deg",
            "m",
            "cylinder",
            "box",
            "rod",
            "y",
            ",",
            "z",
            "a",
            "w",
            "\\u00e9",
            "é",
            "\\\\",
        ];
        const CHARS: &[u8] = b"[]{}\"'=,.-+e9 0x_#\n\t()^*/\\apsinqdz";
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let original = STEWART.as_bytes();
        let mut failures = 0;
        for round in 0..3000 {
            let mut bytes = original.to_vec();
            for _ in 0..1 + rng.below(4) {
                let len = bytes.len();
                let a = rng.below(len + 1);
                let span = if rng.below(4) == 0 { 400 } else { 12 };
                let b = (a + 1 + rng.below(span)).min(len);
                match rng.below(8) {
                    0 => {
                        bytes.drain(a..b);
                    }
                    1 => {
                        let copy = bytes[a..b].to_vec();
                        let at = rng.below(bytes.len() + 1);
                        bytes.splice(at..at, copy);
                    }
                    2 => {
                        let fill: Vec<u8> = (a..b).map(|_| CHARS[rng.below(CHARS.len())]).collect();
                        bytes.splice(a..b, fill);
                    }
                    3 => {
                        let n = 1 + rng.below(6);
                        let fill: Vec<u8> = (0..n).map(|_| CHARS[rng.below(CHARS.len())]).collect();
                        bytes.splice(a..a, fill);
                    }
                    4 | 5 => {
                        // Rewrite the inside of a string: keeps the TOML valid, so that the
                        // model-level checks run.
                        let quotes: Vec<usize> =
                            (0..bytes.len()).filter(|&i| bytes[i] == b'"').collect();
                        if quotes.len() >= 2 {
                            let k = rng.below(quotes.len() - 1);
                            let (a, b) = (quotes[k] + 1, quotes[k + 1]);
                            if !bytes[a..b].contains(&b'\n') {
                                let n = rng.below(5);
                                let fill: Vec<u8> = (0..n)
                                    .flat_map(|_| WORDS[rng.below(WORDS.len())].bytes())
                                    .collect();
                                bytes.splice(a..b, fill);
                            }
                        }
                    }
                    6 => {
                        // Delete, duplicate or swap whole lines.
                        let starts: Vec<usize> = std::iter::once(0)
                            .chain(
                                (0..bytes.len())
                                    .filter(|&i| bytes[i] == b'\n')
                                    .map(|i| i + 1),
                            )
                            .collect();
                        let k = rng.below(starts.len().saturating_sub(1));
                        let (a, b) = (starts[k], starts.get(k + 1).copied().unwrap_or(bytes.len()));
                        let line = bytes[a..b].to_vec();
                        match rng.below(3) {
                            0 => {
                                bytes.drain(a..b);
                            }
                            1 => {
                                bytes.splice(a..a, line);
                            }
                            _ => {
                                let at = starts[rng.below(starts.len())].min(bytes.len());
                                bytes.drain(a..b);
                                let at = at.min(bytes.len());
                                bytes.splice(at..at, line);
                            }
                        }
                    }
                    _ => {
                        // Arbitrary bytes, including invalid UTF-8.
                        let n = 1 + rng.below(3);
                        let fill: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                        bytes.splice(a..a, fill);
                    }
                }
            }
            let src = String::from_utf8_lossy(&bytes).into_owned();
            let path = "tests/fuzz.toml";
            let result = std::panic::catch_unwind(|| parse_model(path, &src));
            match result {
                Err(_) => {
                    failures += 1;
                    eprintln!("round {round}: panic on input:\n{src}");
                }
                Ok(Ok(_)) => {}
                Ok(Err(d)) => check_rendering(path, &src, &d),
            }
        }
        assert_eq!(failures, 0);
    }

    #[test]
    fn adversarial_inputs() {
        let deep_expr = format!(
            "[robot]\nname = \"x\"\ngravity = [\"{}1{}\", 0, 0]\n",
            "(".repeat(100_000),
            ")".repeat(100_000)
        );
        let long_sum = format!("[parameters]\na = \"{}1\"\n", "1+".repeat(100_000));
        let minus = format!("[parameters]\na = \"{}1\"\n", "-".repeat(100_000));
        let pow = format!("[parameters]\na = \"{}2\"\n", "2^".repeat(100_000));
        let arrays = format!(
            "coordinates = {}{}\n",
            "[".repeat(100_000),
            "]".repeat(100_000)
        );
        let tables = format!("x = {}1{}\n", "{a=".repeat(10_000), "}".repeat(10_000));
        let inputs = [
            String::new(),
            " \n\t\r\n".to_string(),
            "\u{FEFF}".to_string(),
            "\0".to_string(),
            "[robot]\nname = \"a\"\ngravity = [1e308, 1e308, \"1e38 * 1e38 * 1e38 * 1e38 * 1e38 * 1e38 * 1e38 * 1e38 * 1e38\"]".to_string(),
            "[parameters]\na = 170141183460469231731687303715884105728\nb = -170141183460469231731687303715884105728\nc = 0x7fffffffffffffffffffffffffffffffffff\nd = \"99999999999999999999999999999999999999 * 99999999999999999999999999999999999999\"".to_string(),
            "[parameters]\na = \"0^-1\"\nb = \"(-1)^0.5\"\nc = \"sqrt(-1)\"\nd = \"tan(pi/2)\"\ne = \"1/0\"\n".to_string(),
            "coordinates = [{ name = \"é\", unit = \"m\" }]\n[robot]\nname = \"ünïcode\"".to_string(),
            "[[body]]\nname = \"a\"\ntransforms = [[1,2,3,4,5,6,1,2,3,4,5,-9223372036854775808]]\n".to_string(),
            "[[body]]\nname = \"a\"\ntransforms = [[1,2,3,4,5,6,1,2,3,4,5,99999999999999999999999]]\n".to_string(),
            "[[body]]\nname = \"a\"\ninertia = [\"1e-30\", 1e30, 1, 0, 0, 0]\nmass = 1e-300\n".to_string(),
            "[[body]]\nname = \"a\"\ninertia = [\"nan\", 1, 1, 0, 0, 0]\nmass = \"0/0\"\n".to_string(),
            deep_expr,
            long_sum,
            minus,
            pow,
            arrays,
            tables,
        ];
        for src in &inputs {
            let path = "tests/adversarial.toml";
            let r = std::panic::catch_unwind(|| parse_model(path, src));
            match r {
                Err(_) => panic!("panic on {:?}", &src[..src.len().min(200)]),
                Ok(Ok(_)) => panic!("should not parse: {src}"),
                Ok(Err(d)) => check_rendering(path, src, &d),
            }
        }
    }

    /// Found by `codegen/tests/fuzz_parser.rs`: a TOML error at the end of a CRLF line was
    /// reported two columns past the line's text (at the `\n`, counting the `\r`).
    #[test]
    fn crlf_line_ends_stay_on_the_line() {
        for (src, line, col) in [
            ("[robot]\r\nname\r\n", 2, 5),
            ("[robot]\r\nname = \"c\r\n", 2, 10),
            ("[robot]\r\nname = \"c\"\r", 2, 11),
        ] {
            let d = parse_model("crlf.toml", src).unwrap_err();
            assert_eq!(d.items[0].pos, Pos { line, col }, "{src:?}: {d}");
            check_rendering("crlf.toml", src, &d);
        }
    }

    #[test]
    fn unreadable_file_is_one_error() {
        let d = parse_model_file(std::path::Path::new("/nonexistent/model.toml")).unwrap_err();
        assert_eq!(d.items.len(), 1);
        assert_eq!(d.items[0].pos, Pos { line: 1, col: 1 });
        assert!(
            d.render()
                .starts_with("/nonexistent/model.toml:1:1: error: cannot read")
        );
    }
}
