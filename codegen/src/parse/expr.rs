//! Expressions: exact decimal numbers, the lexer and the parser into a raw tree (names
//! unresolved), and helpers that build [`Expr`] trees.

use super::*;

// Exact numbers

#[derive(Debug, PartialEq)]
pub(super) enum NumError {
    Syntax,
    TooLarge,
}

pub(super) fn gcd(mut a: i128, mut b: i128) -> i128 {
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
pub(super) fn parse_decimal(s: &str) -> Result<(i128, i128), NumError> {
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
pub(super) const MAX_DEPTH: usize = 64;
pub(super) const MAX_TOKENS: usize = 1000;

#[derive(Debug, Clone, PartialEq)]
pub(super) enum Tok {
    Num(String),
    Ident(String),
    Op(char),
    End,
}

/// A character range inside an expression string: (offset, length) in characters.
pub(super) type At = (usize, usize);

#[derive(Debug)]
pub(super) struct ExprError {
    pub(super) at: At,
    pub(super) message: String,
    pub(super) label: String,
    pub(super) help: Option<String>,
}

pub(super) fn expr_err(at: At, message: impl Into<String>, label: impl Into<String>) -> ExprError {
    ExprError {
        at,
        message: message.into(),
        label: label.into(),
        help: None,
    }
}

pub(super) fn lex(s: &str) -> Result<Vec<(Tok, At)>, ExprError> {
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
pub(super) enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

#[derive(Debug)]
pub(super) enum Raw {
    Num(i128, i128),
    Ident(String, At),
    Call(String, At, Vec<Raw>),
    Neg(Box<Raw>),
    Bin(BinOp, Box<Raw>, Box<Raw>),
}

pub(super) struct ExprParser {
    pub(super) toks: Vec<(Tok, At)>,
    pub(super) i: usize,
    pub(super) depth: usize,
}

pub(super) fn describe(t: &Tok) -> String {
    match t {
        Tok::Num(s) => format!("number `{s}`"),
        Tok::Ident(s) => format!("`{s}`"),
        Tok::Op(c) => format!("`{c}`"),
        Tok::End => "the end of the expression".to_string(),
    }
}

/// Parses an expression: `+ -` < `* /` < unary `-` < `^` (right-associative), calls
/// `name(args)`, parentheses.
pub(super) fn parse_raw(s: &str) -> Result<Raw, ExprError> {
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
    pub(super) fn peek(&self) -> (&Tok, At) {
        let (t, at) = &self.toks[self.i.min(self.toks.len() - 1)];
        (t, *at)
    }
    pub(super) fn bump(&mut self) {
        if self.i < self.toks.len() - 1 {
            self.i += 1;
        }
    }
    pub(super) fn sum(&mut self) -> Result<Raw, ExprError> {
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
    pub(super) fn product(&mut self) -> Result<Raw, ExprError> {
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
    pub(super) fn unary(&mut self) -> Result<Raw, ExprError> {
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
    pub(super) fn power(&mut self) -> Result<Raw, ExprError> {
        let base = self.atom()?;
        if *self.peek().0 == Tok::Op('^') {
            self.bump();
            let exp = self.unary()?;
            return Ok(Raw::Bin(BinOp::Pow, Box::new(base), Box::new(exp)));
        }
        Ok(base)
    }
    pub(super) fn atom(&mut self) -> Result<Raw, ExprError> {
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
    pub(super) fn unclosed(&self, open: At) -> ExprError {
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

pub(super) fn number_too_large(at: At, s: &str) -> ExprError {
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

pub(super) fn bx(e: Expr) -> Box<Expr> {
    Box::new(e)
}
pub(super) fn mul(a: Expr, b: Expr) -> Expr {
    Expr::Mul(bx(a), bx(b))
}
pub(super) fn add(a: Expr, b: Expr) -> Expr {
    Expr::Add(bx(a), bx(b))
}
pub(super) fn div(a: Expr, b: Expr) -> Expr {
    Expr::Div(bx(a), bx(b))
}
pub(super) fn sq(a: Expr) -> Expr {
    Expr::Pow(bx(a), bx(Expr::int(2)))
}
pub(super) fn deg_to_rad(e: Expr) -> Expr {
    mul(e, div(Expr::Pi, Expr::int(180)))
}

pub(super) fn step_eq(a: &Step, b: &Step) -> bool {
    match (a, b) {
        (Step::Rot(x, e), Step::Rot(y, f)) | (Step::Trans(x, e), Step::Trans(y, f)) => {
            x == y && e == f
        }
        _ => false,
    }
}

/// Short display of a number for messages (6 significant digits).
pub(super) fn fmt_num(v: f64) -> String {
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
