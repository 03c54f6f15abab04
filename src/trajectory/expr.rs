//! Expressions in `t` with exact first and second derivatives: rbss's expression language
//! (the crate `rbss_expr`, shared with model files) compiled to postfix code and evaluated on
//! second-order hyper-dual numbers (forward-mode automatic differentiation). No symbolic
//! algebra.
//!
//! Names: `t` and `pi`; numbers; `+ - * / ^` (usual precedence; `^` binds tighter than unary
//! minus and is right-associative, so `-t^2 = -(t^2)` and `2^3^2 = 2^9`); parentheses; and
//! every function of [`Func`]: `sin cos tan exp ln sqrt atan2 asin acos hypot abs`.

pub use rbss_expr::HyperDual;
use rbss_expr::{Ast, BinOp, Func, Limits, Node};

/// One instruction of the postfix code.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Op {
    Const(f64),
    T,
    Neg,
    Bin(BinOp),
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
/// recursive; this keeps its stack use bounded). A flat sum may be as long as it likes.
const LIMITS: Limits = Limits {
    max_depth: 256,
    max_tokens: usize::MAX,
};

impl Expr {
    /// Parses `src`; on error, the byte offset in `src` and a message.
    pub fn parse(src: &str) -> Result<Expr, ExprError> {
        // Character offsets of the shared parser to byte offsets of `src`.
        let byte = |chars: usize| src.char_indices().nth(chars).map_or(src.len(), |(b, _)| b);
        let fail = |at: (usize, usize), message: String| ExprError {
            offset: byte(at.0),
            message,
        };
        let ast: Ast = rbss_expr::parse(src, &LIMITS).map_err(|e| {
            let message = match e.help {
                Some(h) => format!("{} ({h})", e.message),
                None => e.message,
            };
            fail(e.at, message)
        })?;
        let mut code = Vec::with_capacity(ast.nodes.len());
        for (node, at) in &ast.nodes {
            let op = match node {
                Node::Num(text) => match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Op::Const(v),
                    _ => return Err(fail(*at, format!("`{text}` is not a finite number"))),
                },
                Node::Name(name) => match name.as_str() {
                    "t" => Op::T,
                    "pi" => Op::Const(std::f64::consts::PI),
                    _ => {
                        return Err(fail(
                            *at,
                            format!(
                                "unknown name `{name}`: expressions use t, pi, numbers and {}",
                                Func::NAMES.join(" ")
                            ),
                        ));
                    }
                },
                Node::Call(name, args) => {
                    let Some(f) = Func::from_name(name) else {
                        return Err(fail(
                            *at,
                            format!(
                                "unknown function `{name}`: the functions are {}",
                                Func::NAMES.join(" ")
                            ),
                        ));
                    };
                    if args.len() != f.arity() {
                        let n = f.arity();
                        return Err(fail(
                            *at,
                            format!(
                                "`{name}` takes {n} argument{}, found {}: write `{}`",
                                if n == 1 { "" } else { "s" },
                                args.len(),
                                f.signature()
                            ),
                        ));
                    }
                    Op::Call(f)
                }
                Node::Neg(_) => Op::Neg,
                Node::Bin(op, ..) => Op::Bin(*op),
            };
            code.push(op);
        }
        let mut depth = 0usize;
        let mut max = 0usize;
        for op in &code {
            match op {
                Op::Const(_) | Op::T => depth += 1,
                Op::Bin(_) => depth -= 1,
                Op::Call(f) => depth -= f.arity() - 1,
                Op::Neg => {}
            }
            max = max.max(depth);
        }
        Ok(Expr { code, depth: max })
    }

    /// The value and its first and second derivatives with respect to `t`. Allocates nothing
    /// for expressions whose evaluation stack is at most [`INLINE_STACK`] deep (every one a
    /// person writes; deeper ones use a heap buffer).
    pub fn eval(&self, t: f64) -> HyperDual {
        if self.depth <= INLINE_STACK {
            let mut stack = [HyperDual::constant(0.0); INLINE_STACK];
            self.run(t, &mut stack)
        } else {
            let mut stack = vec![HyperDual::constant(0.0); self.depth];
            self.run(t, &mut stack)
        }
    }

    /// The postfix code on `stack` (at least `self.depth` long, which `parse` computed from the
    /// code: every push has its slot, every pop its operand).
    fn run(&self, t: f64, stack: &mut [HyperDual]) -> HyperDual {
        let tt = HyperDual::variable(t);
        let mut sp = 0_usize;
        for op in &self.code {
            match *op {
                Op::Const(c) => {
                    stack[sp] = HyperDual::constant(c);
                    sp += 1;
                }
                Op::T => {
                    stack[sp] = tt;
                    sp += 1;
                }
                Op::Neg => stack[sp - 1] = -stack[sp - 1],
                Op::Call(f) => {
                    let at = sp - f.arity();
                    stack[at] = f.dual(&stack[at..sp]);
                    sp = at + 1;
                }
                Op::Bin(op) => {
                    let (a, b) = (stack[sp - 2], stack[sp - 1]);
                    sp -= 1;
                    stack[sp - 1] = match op {
                        BinOp::Add => a + b,
                        BinOp::Sub => a - b,
                        BinOp::Mul => a * b,
                        BinOp::Div => a / b,
                        BinOp::Pow => a.pow(b),
                    };
                }
            }
        }
        stack[0]
    }
}

/// The deepest evaluation stack [`Expr::eval`] keeps on the machine stack.
const INLINE_STACK: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;

    /// Past the inline stack's depth the buffer is on the heap; the result is the same.
    #[test]
    fn deep_expressions_evaluate_too() {
        let deep = format!("{}t{}", "1+(".repeat(40), ")".repeat(40));
        let e = Expr::parse(&deep).unwrap();
        assert!(e.depth > INLINE_STACK, "{}", e.depth);
        let r = e.eval(0.5);
        assert_eq!((r.v, r.d1, r.d2), (40.5, 1.0, 0.0));
        let shallow = ev("1+t", 0.5);
        assert_eq!((shallow.v, shallow.d1, shallow.d2), (1.5, 1.0, 0.0));
    }

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
        assert_eq!(p.offset, 0);
        assert!(p.message.contains("unclosed `(`"), "{}", p.message);
        assert!(e("(1 + t t").message.contains("expected `)`"));
        assert_eq!(e("2 t").offset, 2);
        assert_eq!(e("1 $ 2").offset, 2);
        assert_eq!(e("1..2").offset, 2);
        assert_eq!(e("1e999").offset, 0);
        let u = e("t + atan(1)");
        assert_eq!(u.offset, 4);
        assert!(
            u.message.contains("unknown function `atan`"),
            "{}",
            u.message
        );
        let c = e("sin(1, t)");
        assert_eq!(c.offset, 0);
        assert!(
            c.message.contains("takes 1 argument, found 2"),
            "{}",
            c.message
        );
        assert!(e("atan2(t)").message.contains("write `atan2(y, x)`"));
        assert_eq!(e("t * é").offset, 4);
        let deep = "(".repeat(100_000) + "t" + ")".repeat(100_000).as_str();
        assert!(e(&deep).message.contains("nested too deeply"));
        let deep = "-".repeat(100_000) + "t";
        assert!(e(&deep).message.contains("nested too deeply"));
        // A long flat sum is fine (no recursion in the parser's loops or the evaluator).
        let long = vec!["t"; 100_000].join(" + ");
        assert_eq!(ev(&long, 1.0).d1, 100_000.0);
    }

    /// The functions added with the shared language (atan2 asin acos hypot abs): values equal
    /// std's, derivatives by the chain rule against closed forms written here.
    #[test]
    fn inverse_trigonometry_and_friends() {
        let t = 0.3;
        let r = ev("atan2(sin(t), cos(t))", t);
        assert!((r.v - t).abs() < 1e-15 && (r.d1 - 1.0).abs() < 1e-15 && r.d2.abs() < 1e-15);
        let r = ev("asin(t)", t);
        assert_eq!(r.v, t.asin());
        assert!((r.d1 - 1.0 / (1.0 - t * t).sqrt()).abs() < 1e-15);
        assert!((r.d2 - t / (1.0 - t * t).powf(1.5)).abs() < 1e-14);
        let r = ev("acos(t)", t);
        assert_eq!(r.v, t.acos());
        assert!((r.d1 + 1.0 / (1.0 - t * t).sqrt()).abs() < 1e-15);
        let r = ev("hypot(3 * t, 4 * t)", t);
        assert!((r.v - 5.0 * t).abs() < 1e-15 && (r.d1 - 5.0).abs() < 1e-14 && r.d2.abs() < 1e-13);
        let r = ev("abs(t - 1)", t);
        assert_eq!((r.v, r.d1, r.d2), ((t - 1.0).abs(), -1.0, 0.0));
        assert_eq!(ev("atan2(1, -1)", 0.0).v, 1f64.atan2(-1.0));
    }
}
