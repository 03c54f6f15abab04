//! Expressions of a model: the shared language (`rbss_expr`: one lexer, one parser, one
//! function table) read into a raw tree with exact numbers, and helpers that build [`Expr`] trees.

use super::*;

pub(super) use rbss_expr::{ExprError, NumError, expr_err, parse_decimal};

/// Maximal nesting (parentheses, unary minus, exponents) and number of tokens of one
/// expression of a model: deeper input is an error, never a stack overflow.
const LIMITS: rbss_expr::Limits = rbss_expr::Limits {
    max_depth: 64,
    max_tokens: 1000,
};

/// A character range inside an expression string: (offset, length) in characters.
pub(super) type At = rbss_expr::At;

pub(super) use rbss_expr::BinOp;

/// An expression as parsed by the shared language (`rbss_expr`), names unresolved, numbers
/// exact.
#[derive(Debug)]
pub(super) enum Raw {
    Num(i128, i128),
    Ident(String, At),
    Call(String, At, Vec<Raw>),
    Neg(Box<Raw>),
    Bin(BinOp, Box<Raw>, Box<Raw>),
}

/// Parses an expression of a model: the shared parser, its numbers read as exact rationals.
pub(super) fn parse_raw(s: &str) -> Result<Raw, ExprError> {
    let ast = rbss_expr::parse(s, &LIMITS)?;
    let mut built: Vec<Option<Raw>> = Vec::with_capacity(ast.nodes.len());
    for (node, at) in &ast.nodes {
        let mut take = |i: usize| built[i].take().expect("post-order: each operand once");
        let raw = match node {
            rbss_expr::Node::Num(text) => match parse_decimal(text) {
                Ok((n, d)) => Raw::Num(n, d),
                Err(NumError::TooLarge) => return Err(number_too_large(*at, text)),
                Err(NumError::Syntax) => {
                    return Err(expr_err(*at, format!("invalid number `{text}`"), ""));
                }
            },
            rbss_expr::Node::Name(name) => Raw::Ident(name.clone(), *at),
            rbss_expr::Node::Call(name, args) => {
                let args = args.iter().map(|&a| take(a)).collect();
                Raw::Call(name.clone(), *at, args)
            }
            rbss_expr::Node::Neg(a) => Raw::Neg(Box::new(take(*a))),
            rbss_expr::Node::Bin(op, a, b) => {
                let (a, b) = (take(*a), take(*b));
                Raw::Bin(*op, Box::new(a), Box::new(b))
            }
        };
        built.push(Some(raw));
    }
    Ok(built
        .pop()
        .flatten()
        .expect("a parsed expression has a root"))
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
        (Step::Rotation(m), Step::Rotation(n)) => m == n,
        (Step::Quat(m), Step::Quat(n)) => m == n,
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
