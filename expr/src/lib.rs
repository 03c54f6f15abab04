//! rbss's one expression language, shared by model files (rbss-codegen: parameters, transform
//! steps, masses), scenes and trajectory files (the `rbss` command): one lexer, one parser and
//! one function table.
//!
//! ```text
//! sum     := product (('+' | '-') product)*
//! product := unary (('*' | '/') unary)*
//! unary   := ('-' | '+') unary | power
//! power   := atom ('^' unary)?            (right-associative, above unary minus: -t^2 = -(t^2))
//! atom    := NUMBER | NAME | NAME '(' sum (',' sum)* ')' | '(' sum ')'
//! ```
//!
//! The parser only builds the tree ([`Ast`], names unresolved, numbers as written); each user
//! gives names their meaning (parameters and coordinates in a model, `t` in a trajectory) and
//! numbers theirs (exact rationals in a model, [`parse_decimal`]; f64 in a trajectory). The
//! functions, their arity, their f64 values and their domains are [`Func`]'s; their first and
//! second derivatives, for trajectories' automatic differentiation, are [`HyperDual`]'s.

mod dual;
mod func;
mod number;
mod parser;

pub use dual::HyperDual;
pub use func::Func;
pub use number::{NumError, gcd, parse_decimal};
pub use parser::{Ast, At, BinOp, ExprError, Limits, Node, NodeId, expr_err, parse};
