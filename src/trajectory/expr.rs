//! Expressions in `t` with exact first and second derivatives: a small parser that compiles to
//! postfix code, evaluated on second-order hyper-dual numbers (forward-mode automatic
//! differentiation). No symbolic algebra.
//!
//! Grammar (usual precedence; `^` binds tighter than unary minus and is right-associative, so
//! `-t^2 = -(t^2)` and `2^3^2 = 2^9`):
//!
//! ```text
//! expr    := term (('+' | '-') term)*
//! term    := unary (('*' | '/') unary)*
//! unary   := ('-' | '+') unary | power
//! power   := primary ('^' unary)?
//! primary := NUMBER | 't' | 'pi' | FUNC '(' expr ')' | '(' expr ')'
//! FUNC    := sin | cos | tan | exp | ln | sqrt
//! ```

/// A second-order hyper-dual number `v + d1 ε₁ + d1 ε₂ + d2 ε₁ε₂` (with `ε₁² = ε₂² = 0`) for
/// one variable: seeded with `t + ε₁ + ε₂`, a function `f` maps it to
/// `f(t) + f'(t) (ε₁ + ε₂) + f''(t) ε₁ε₂`. Both `ε` parts are equal for a function of one
/// variable, so one field `d1` holds them; the arithmetic is the hyper-dual one, exact up to
/// rounding (no truncation error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HyperDual {
    /// `f(t)`.
    pub v: f64,
    /// `f'(t)`.
    pub d1: f64,
    /// `f''(t)`.
    pub d2: f64,
}

impl HyperDual {
    /// A constant: both derivatives zero.
    pub fn constant(v: f64) -> Self {
        HyperDual {
            v,
            d1: 0.0,
            d2: 0.0,
        }
    }

    /// The variable itself at `t`: `t + ε₁ + ε₂`.
    pub fn variable(t: f64) -> Self {
        HyperDual {
            v: t,
            d1: 1.0,
            d2: 0.0,
        }
    }

    /// `g(self)` from `g(v)`, `g'(v)` and `g''(v)` (the chain rule to second order).
    fn chain(self, g: f64, g1: f64, g2: f64) -> Self {
        HyperDual {
            v: g,
            d1: g1 * self.d1,
            d2: g2 * self.d1 * self.d1 + g1 * self.d2,
        }
    }

    fn is_constant(self) -> bool {
        self.d1 == 0.0 && self.d2 == 0.0
    }

    pub fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r, 2.0 * r * r * r)
    }

    /// `self^e`: with a constant exponent `p` the power rule (integer `p` accepts a negative
    /// base), otherwise `exp(e ln self)`.
    pub fn pow(self, e: Self) -> Self {
        if !e.is_constant() {
            return (self.ln() * e).exp();
        }
        let p = e.v;
        if p == 0.0 {
            return HyperDual::constant(1.0);
        }
        if p == 1.0 {
            return self;
        }
        if p.fract() == 0.0 && p.abs() <= i32::MAX as f64 {
            let n = p as i32;
            // n >= 2 or n <= -1: u^(n-2) is finite wherever u^n is (u != 0 for n < 0).
            let u = self.v;
            let um2 = u.powi(n - 2);
            return self.chain(u.powi(n), p * u * um2, p * (p - 1.0) * um2);
        }
        let u = self.v;
        self.chain(
            u.powf(p),
            p * u.powf(p - 1.0),
            p * (p - 1.0) * u.powf(p - 2.0),
        )
    }

    pub fn sin(self) -> Self {
        let (s, c) = self.v.sin_cos();
        self.chain(s, c, -s)
    }

    pub fn cos(self) -> Self {
        let (s, c) = self.v.sin_cos();
        self.chain(c, -s, -c)
    }

    pub fn tan(self) -> Self {
        let t = self.v.tan();
        let sec2 = 1.0 + t * t;
        self.chain(t, sec2, 2.0 * t * sec2)
    }

    pub fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e, e)
    }

    pub fn ln(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(self.v.ln(), r, -r * r)
    }

    pub fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s, -0.25 / (s * self.v))
    }
}

impl std::ops::Add for HyperDual {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        HyperDual {
            v: self.v + o.v,
            d1: self.d1 + o.d1,
            d2: self.d2 + o.d2,
        }
    }
}

impl std::ops::Sub for HyperDual {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        HyperDual {
            v: self.v - o.v,
            d1: self.d1 - o.d1,
            d2: self.d2 - o.d2,
        }
    }
}

impl std::ops::Neg for HyperDual {
    type Output = Self;
    fn neg(self) -> Self {
        HyperDual {
            v: -self.v,
            d1: -self.d1,
            d2: -self.d2,
        }
    }
}

impl std::ops::Mul for HyperDual {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        HyperDual {
            v: self.v * o.v,
            d1: self.d1 * o.v + self.v * o.d1,
            d2: self.d2 * o.v + 2.0 * self.d1 * o.d1 + self.v * o.d2,
        }
    }
}

impl std::ops::Div for HyperDual {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        if o.is_constant() {
            let r = 1.0 / o.v;
            HyperDual {
                v: self.v * r,
                d1: self.d1 * r,
                d2: self.d2 * r,
            }
        } else {
            self * o.recip()
        }
    }
}

/// The functions an expression may call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Exp,
    Ln,
    Sqrt,
}

impl Func {
    fn from_name(name: &str) -> Option<Func> {
        Some(match name {
            "sin" => Func::Sin,
            "cos" => Func::Cos,
            "tan" => Func::Tan,
            "exp" => Func::Exp,
            "ln" => Func::Ln,
            "sqrt" => Func::Sqrt,
            _ => return None,
        })
    }

    fn apply(self, x: HyperDual) -> HyperDual {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
            Func::Sqrt => x.sqrt(),
        }
    }
}

/// One instruction of the postfix code.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Op {
    Const(f64),
    T,
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Call(Func),
}

/// A parse error at byte `offset` of the expression.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExprError {
    pub offset: usize,
    pub message: String,
}

/// A compiled expression in `t`.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    code: Vec<Op>,
    /// Deepest evaluation stack the code needs.
    depth: usize,
}

/// Parentheses, unary signs and powers nested deeper than this are refused (the parser is
/// recursive; this keeps its stack use bounded).
const MAX_NESTING: usize = 256;

impl Expr {
    /// Parses `src`; on error, the byte offset in `src` and a message.
    pub fn parse(src: &str) -> Result<Expr, ExprError> {
        let tokens = lex(src);
        let mut p = Parser {
            tokens: &tokens,
            pos: 0,
            code: Vec::new(),
            nesting: 0,
            end: src.len(),
        };
        if tokens.is_empty() {
            return Err(ExprError {
                offset: 0,
                message: "empty expression".into(),
            });
        }
        p.expr()?;
        if let Some(tok) = p.peek() {
            let message = match &tok.kind {
                Kind::Bad(m) => m.clone(),
                k => format!(
                    "expected an operator (+ - * / ^) or the end, found {}",
                    k.describe()
                ),
            };
            return Err(ExprError {
                offset: tok.offset,
                message,
            });
        }
        let mut depth = 0usize;
        let mut max = 0usize;
        for op in &p.code {
            match op {
                Op::Const(_) | Op::T => depth += 1,
                Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Pow => depth -= 1,
                Op::Neg | Op::Call(_) => {}
            }
            max = max.max(depth);
        }
        Ok(Expr {
            code: p.code,
            depth: max,
        })
    }

    /// The value and its first and second derivatives with respect to `t`.
    pub fn eval(&self, t: f64) -> HyperDual {
        let mut stack: Vec<HyperDual> = Vec::with_capacity(self.depth);
        let tt = HyperDual::variable(t);
        for op in &self.code {
            let v = match *op {
                Op::Const(c) => HyperDual::constant(c),
                Op::T => tt,
                Op::Neg | Op::Call(_) => {
                    let a = stack.pop().unwrap_or(HyperDual::constant(f64::NAN));
                    match *op {
                        Op::Call(f) => f.apply(a),
                        _ => -a,
                    }
                }
                _ => {
                    let b = stack.pop().unwrap_or(HyperDual::constant(f64::NAN));
                    let a = stack.pop().unwrap_or(HyperDual::constant(f64::NAN));
                    match *op {
                        Op::Add => a + b,
                        Op::Sub => a - b,
                        Op::Mul => a * b,
                        Op::Div => a / b,
                        _ => a.pow(b),
                    }
                }
            };
            stack.push(v);
        }
        stack.pop().unwrap_or(HyperDual::constant(f64::NAN))
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    Num(f64),
    Ident(String),
    Sym(char),
    /// Text that is no token, with the message to report when the parser reaches it (so that
    /// the first error in reading order is the one reported).
    Bad(String),
}

impl Kind {
    fn describe(&self) -> String {
        match self {
            Kind::Num(_) => "a number".into(),
            Kind::Ident(s) => format!("`{s}`"),
            Kind::Sym(c) => format!("`{c}`"),
            Kind::Bad(m) => m.clone(),
        }
    }
}

#[derive(Debug, Clone)]
struct Token {
    kind: Kind,
    offset: usize,
}

fn lex(src: &str) -> Vec<Token> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || c == b'.' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
                let mut j = i + 1;
                if j < b.len() && (b[j] == b'+' || b[j] == b'-') {
                    j += 1;
                }
                if j < b.len() && b[j].is_ascii_digit() {
                    while j < b.len() && b[j].is_ascii_digit() {
                        j += 1;
                    }
                    i = j;
                }
            }
            let text = &src[start..i];
            let kind = match text.parse() {
                Ok(v) => Kind::Num(v),
                Err(_) => Kind::Bad(format!("`{text}` is not a number")),
            };
            out.push(Token {
                kind,
                offset: start,
            });
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Token {
                kind: Kind::Ident(src[start..i].to_string()),
                offset: start,
            });
        } else if b"+-*/^()".contains(&c) {
            out.push(Token {
                kind: Kind::Sym(c as char),
                offset: i,
            });
            i += 1;
        } else {
            let ch = src[i..].chars().next().unwrap_or('?');
            let hint = if ch == ',' {
                " (functions take one argument)"
            } else {
                ""
            };
            out.push(Token {
                kind: Kind::Bad(format!("unexpected character `{ch}`{hint}")),
                offset: i,
            });
            i += ch.len_utf8();
        }
    }
    out
}

struct Parser<'a> {
    tokens: &'a [Token],
    pos: usize,
    code: Vec<Op>,
    nesting: usize,
    end: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.pos)
    }

    fn peek_sym(&self, c: char) -> bool {
        matches!(self.peek(), Some(Token { kind: Kind::Sym(s), .. }) if *s == c)
    }

    fn offset(&self) -> usize {
        self.peek().map_or(self.end, |t| t.offset)
    }

    fn nest(&mut self) -> Result<(), ExprError> {
        self.nesting += 1;
        if self.nesting > MAX_NESTING {
            return Err(ExprError {
                offset: self.offset(),
                message: format!("nested more than {MAX_NESTING} levels deep"),
            });
        }
        Ok(())
    }

    fn expr(&mut self) -> Result<(), ExprError> {
        self.term()?;
        loop {
            let op = if self.peek_sym('+') {
                Op::Add
            } else if self.peek_sym('-') {
                Op::Sub
            } else {
                return Ok(());
            };
            self.pos += 1;
            self.term()?;
            self.code.push(op);
        }
    }

    fn term(&mut self) -> Result<(), ExprError> {
        self.unary()?;
        loop {
            let op = if self.peek_sym('*') {
                Op::Mul
            } else if self.peek_sym('/') {
                Op::Div
            } else {
                return Ok(());
            };
            self.pos += 1;
            self.unary()?;
            self.code.push(op);
        }
    }

    fn unary(&mut self) -> Result<(), ExprError> {
        self.nest()?;
        if self.peek_sym('-') {
            self.pos += 1;
            self.unary()?;
            self.code.push(Op::Neg);
        } else if self.peek_sym('+') {
            self.pos += 1;
            self.unary()?;
        } else {
            self.power()?;
        }
        self.nesting -= 1;
        Ok(())
    }

    fn power(&mut self) -> Result<(), ExprError> {
        self.primary()?;
        if self.peek_sym('^') {
            self.pos += 1;
            self.unary()?;
            self.code.push(Op::Pow);
        }
        Ok(())
    }

    fn expect_close(&mut self, open: usize) -> Result<(), ExprError> {
        if self.peek_sym(')') {
            self.pos += 1;
            Ok(())
        } else if let Some(Token {
            kind: Kind::Bad(m),
            offset,
        }) = self.peek()
        {
            Err(ExprError {
                offset: *offset,
                message: m.clone(),
            })
        } else {
            let found = self
                .peek()
                .map_or("the end".to_string(), |t| t.kind.describe());
            Err(ExprError {
                offset: self.offset(),
                message: format!(
                    "expected `)` to close the `(` at column {} of the expression, found {found}",
                    open + 1
                ),
            })
        }
    }

    fn primary(&mut self) -> Result<(), ExprError> {
        let Some(tok) = self.peek().cloned() else {
            return Err(ExprError {
                offset: self.end,
                message: "expected a number, `t`, `pi`, a function or `(`, found the end".into(),
            });
        };
        self.pos += 1;
        match tok.kind {
            Kind::Num(v) => self.code.push(Op::Const(v)),
            Kind::Ident(name) => match name.as_str() {
                "t" => self.code.push(Op::T),
                "pi" => self.code.push(Op::Const(std::f64::consts::PI)),
                _ => {
                    let Some(f) = Func::from_name(&name) else {
                        return Err(ExprError {
                            offset: tok.offset,
                            message: format!(
                                "unknown name `{name}`: expressions use t, pi, numbers and \
                                 sin cos tan exp ln sqrt"
                            ),
                        });
                    };
                    if !self.peek_sym('(') {
                        return Err(ExprError {
                            offset: self.offset(),
                            message: format!("expected `(` after `{name}`"),
                        });
                    }
                    let open = self.offset();
                    self.pos += 1;
                    self.nest()?;
                    self.expr()?;
                    self.nesting -= 1;
                    self.expect_close(open)?;
                    self.code.push(Op::Call(f));
                }
            },
            Kind::Bad(message) => {
                return Err(ExprError {
                    offset: tok.offset,
                    message,
                });
            }
            Kind::Sym('(') => {
                self.nest()?;
                self.expr()?;
                self.nesting -= 1;
                self.expect_close(tok.offset)?;
            }
            other => {
                return Err(ExprError {
                    offset: tok.offset,
                    message: format!(
                        "expected a number, `t`, `pi`, a function or `(`, found {}",
                        other.describe()
                    ),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(s: &str, t: f64) -> HyperDual {
        Expr::parse(s)
            .unwrap_or_else(|e| panic!("{s}: {e:?}"))
            .eval(t)
    }

    #[test]
    fn precedence_and_associativity() {
        assert_eq!(ev("1 + 2 * 3", 0.0).v, 7.0);
        assert_eq!(ev("-2^2", 0.0).v, -4.0);
        assert_eq!(ev("2^3^2", 0.0).v, 512.0);
        assert_eq!(ev("2^-1", 0.0).v, 0.5);
        assert_eq!(ev("8 / 4 / 2", 0.0).v, 1.0);
        assert_eq!(ev("10 - 4 - 3", 0.0).v, 3.0);
        assert_eq!(ev("(1 + 2) * 3", 0.0).v, 9.0);
        assert_eq!(ev("- - 3", 0.0).v, 3.0);
        assert_eq!(ev("1.5e2 + .5 + 2E-1", 0.0).v, 150.7);
        assert_eq!(ev("pi", 0.0).v, std::f64::consts::PI);
    }

    #[test]
    fn power_rules() {
        // t^3 at t = -2: value -8, 3 t^2 = 12, 6 t = -12 (integer power of a negative base).
        assert_eq!(
            ev("t^3", -2.0),
            HyperDual {
                v: -8.0,
                d1: 12.0,
                d2: -12.0
            }
        );
        // t^2 at 0 and t^1: no 0 * inf.
        assert_eq!(
            ev("t^2", 0.0),
            HyperDual {
                v: 0.0,
                d1: 0.0,
                d2: 2.0
            }
        );
        assert_eq!(
            ev("t^1", 0.0),
            HyperDual {
                v: 0.0,
                d1: 1.0,
                d2: 0.0
            }
        );
        // 2^t: exp(t ln 2).
        let r = ev("2^t", 1.0);
        let l = 2f64.ln();
        assert!((r.v - 2.0).abs() < 1e-15 && (r.d1 - 2.0 * l).abs() < 1e-15);
        assert!((r.d2 - 2.0 * l * l).abs() < 1e-15);
    }

    #[test]
    fn errors_point_at_the_offending_token() {
        let e = |s: &str| Expr::parse(s).unwrap_err();
        assert_eq!(e("").offset, 0);
        let x = e("0.1*cos(pi*x)");
        assert_eq!(x.offset, 11);
        assert!(x.message.contains("unknown name `x`"), "{}", x.message);
        assert_eq!(e("1 +").offset, 3);
        assert_eq!(e("sin t").offset, 4);
        let p = e("(1 + t");
        assert_eq!(p.offset, 6);
        assert!(p.message.contains("expected `)`"), "{}", p.message);
        assert_eq!(e("2 t").offset, 2);
        assert_eq!(e("1 $ 2").offset, 2);
        assert_eq!(e("1..2").offset, 0);
        assert_eq!(e("atan2(1, t)").offset, 0);
        let c = e("sin(1, t)");
        assert_eq!(c.offset, 5);
        assert!(c.message.contains("one argument"), "{}", c.message);
        assert_eq!(e("t * é").offset, 4);
        let deep = "(".repeat(100_000) + "t" + &")".repeat(100_000);
        assert!(e(&deep).message.contains("nested more than"));
        let deep = "-".repeat(100_000) + "t";
        assert!(e(&deep).message.contains("nested more than"));
        // A long flat sum is fine (no recursion in the parser's loops or the evaluator).
        let long = vec!["t"; 100_000].join(" + ");
        assert_eq!(ev(&long, 1.0).d1, 100_000.0);
    }
}
