//! The lexer and the parser: text -> [`Ast`] (names unresolved, numbers as written).

/// A character range inside an expression string: (offset, length) in characters.
pub type At = (usize, usize);

/// An index into [`Ast::nodes`].
pub type NodeId = usize;

/// An error at a character range of the expression, rustc style: the message, a label under
/// the range and an optional help line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExprError {
    pub at: At,
    pub message: String,
    pub label: String,
    pub help: Option<String>,
}

pub fn expr_err(at: At, message: impl Into<String>, label: impl Into<String>) -> ExprError {
    ExprError {
        at,
        message: message.into(),
        label: label.into(),
        help: None,
    }
}

/// How much input the parser accepts: deeper or longer input is an error, never a stack
/// overflow.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Nesting of operands: parentheses, calls, unary signs and exponents.
    pub max_depth: usize,
    /// Tokens of one expression.
    pub max_tokens: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

/// A node of the tree.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// A number as written (a unary minus directly in front of it is folded in: `-2`).
    Num(String),
    /// A name: `t`, `pi`, a parameter or a coordinate.
    Name(String),
    /// `name(args)`: the function is looked up by the user ([`crate::Func::from_name`]).
    Call(String, Vec<NodeId>),
    Neg(NodeId),
    Bin(BinOp, NodeId, NodeId),
}

/// A parsed expression: nodes in post-order (every node after its operands, so evaluating
/// `nodes` in order is evaluating the expression), the root last.
#[derive(Debug, Clone, PartialEq)]
pub struct Ast {
    /// Each node and the range it is reported at (a call and a name: the name; a number: its
    /// text; an operation: its operator).
    pub nodes: Vec<(Node, At)>,
}

impl Ast {
    pub fn root(&self) -> NodeId {
        self.nodes.len() - 1
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(String),
    Ident(String),
    Op(char),
    End,
}

fn lex(s: &str, limits: &Limits) -> Result<Vec<(Tok, At)>, ExprError> {
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
        if out.len() >= limits.max_tokens {
            return Err(expr_err(
                (start, 1),
                format!(
                    "expression is too long (more than {} tokens)",
                    limits.max_tokens
                ),
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
            if c == '*' {
                e.help = Some("`**` is not an operator: write `a^b` for powers".to_string());
            }
            return Err(e);
        }
    }
    out.push((Tok::End, (chars.len(), 1)));
    Ok(out)
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
pub fn parse(s: &str, limits: &Limits) -> Result<Ast, ExprError> {
    let toks = lex(s, limits)?;
    if toks.len() == 1 {
        return Err(expr_err(
            (0, s.chars().count().max(1)),
            "empty expression",
            "expected a number or an expression",
        ));
    }
    let mut p = Parser {
        toks,
        i: 0,
        depth: 0,
        max_depth: limits.max_depth,
        nodes: Vec::new(),
    };
    p.sum()?;
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
        if t == Tok::Op(',') {
            err.label = "not inside a function's arguments".to_string();
        }
        return Err(err);
    }
    Ok(Ast { nodes: p.nodes })
}

struct Parser {
    toks: Vec<(Tok, At)>,
    i: usize,
    depth: usize,
    max_depth: usize,
    nodes: Vec<(Node, At)>,
}

impl Parser {
    fn peek(&self) -> (&Tok, At) {
        let (t, at) = &self.toks[self.i.min(self.toks.len() - 1)];
        (t, *at)
    }
    fn bump(&mut self) {
        if self.i < self.toks.len() - 1 {
            self.i += 1;
        }
    }
    fn push(&mut self, node: Node, at: At) -> NodeId {
        self.nodes.push((node, at));
        self.nodes.len() - 1
    }
    fn enter(&mut self) -> Result<(), ExprError> {
        self.depth += 1;
        if self.depth > self.max_depth {
            return Err(expr_err(
                self.peek().1,
                "expression is nested too deeply",
                format!("more than {} levels", self.max_depth),
            ));
        }
        Ok(())
    }
    fn sum(&mut self) -> Result<NodeId, ExprError> {
        let mut lhs = self.product()?;
        loop {
            let (op, at) = match self.peek() {
                (Tok::Op('+'), at) => (BinOp::Add, at),
                (Tok::Op('-'), at) => (BinOp::Sub, at),
                _ => return Ok(lhs),
            };
            self.bump();
            let rhs = self.product()?;
            lhs = self.push(Node::Bin(op, lhs, rhs), at);
        }
    }
    fn product(&mut self) -> Result<NodeId, ExprError> {
        let mut lhs = self.unary()?;
        loop {
            let (op, at) = match self.peek() {
                (Tok::Op('*'), at) => (BinOp::Mul, at),
                (Tok::Op('/'), at) => (BinOp::Div, at),
                _ => return Ok(lhs),
            };
            self.bump();
            let rhs = self.unary()?;
            lhs = self.push(Node::Bin(op, lhs, rhs), at);
        }
    }
    fn unary(&mut self) -> Result<NodeId, ExprError> {
        self.enter()?;
        let r = match self.peek() {
            (Tok::Op('-'), at) => {
                self.bump();
                let a = self.unary()?;
                match &mut self.nodes[a] {
                    // `-2` is the number -2 (and `--2` the number 2).
                    (Node::Num(text), span) => {
                        match text.strip_prefix('-') {
                            Some(rest) => *text = rest.to_string(),
                            None => text.insert(0, '-'),
                        }
                        *span = (at.0, span.0 + span.1 - at.0);
                        a
                    }
                    _ => self.push(Node::Neg(a), at),
                }
            }
            (Tok::Op('+'), _) => {
                self.bump();
                self.unary()?
            }
            _ => self.power()?,
        };
        self.depth -= 1;
        Ok(r)
    }
    fn power(&mut self) -> Result<NodeId, ExprError> {
        let base = self.atom()?;
        if let (Tok::Op('^'), at) = self.peek() {
            self.bump();
            let exp = self.unary()?;
            return Ok(self.push(Node::Bin(BinOp::Pow, base, exp), at));
        }
        Ok(base)
    }
    fn atom(&mut self) -> Result<NodeId, ExprError> {
        let (t, at) = self.peek();
        let t = t.clone();
        match t {
            Tok::Num(s) => {
                self.bump();
                Ok(self.push(Node::Num(s), at))
            }
            Tok::Ident(name) => {
                self.bump();
                if *self.peek().0 != Tok::Op('(') {
                    if let Some(f) = crate::Func::from_name(&name) {
                        let mut e = expr_err(
                            self.peek().1,
                            format!("expected `(` after `{name}`"),
                            "a function's arguments are in parentheses",
                        );
                        e.help = Some(format!("write `{}`", f.signature()));
                        return Err(e);
                    }
                    return Ok(self.push(Node::Name(name), at));
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
                Ok(self.push(Node::Call(name, args), at))
            }
            Tok::Op('(') => {
                // Nesting is counted where every operand passes: `unary`.
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

#[cfg(test)]
mod tests {
    use super::*;

    const L: Limits = Limits {
        max_depth: 64,
        max_tokens: 1000,
    };

    /// The tree back as fully parenthesised text.
    fn show(ast: &Ast, id: NodeId) -> String {
        match &ast.nodes[id].0 {
            Node::Num(s) | Node::Name(s) => s.clone(),
            Node::Call(f, args) => {
                let a: Vec<String> = args.iter().map(|&a| show(ast, a)).collect();
                format!("{f}({})", a.join(", "))
            }
            Node::Neg(a) => format!("(-{})", show(ast, *a)),
            Node::Bin(op, a, b) => {
                let o = ["+", "-", "*", "/", "^"][*op as usize];
                format!("({} {o} {})", show(ast, *a), show(ast, *b))
            }
        }
    }

    fn p(s: &str) -> String {
        let ast = parse(s, &L).unwrap_or_else(|e| panic!("{s}: {e:?}"));
        // Post-order: every operand before its node.
        for (i, (n, _)) in ast.nodes.iter().enumerate() {
            let kids = match n {
                Node::Call(_, a) => a.clone(),
                Node::Neg(a) => vec![*a],
                Node::Bin(_, a, b) => vec![*a, *b],
                _ => vec![],
            };
            assert!(kids.iter().all(|&k| k < i), "{s}: not in post-order");
        }
        show(&ast, ast.root())
    }

    #[test]
    fn precedence_calls_and_signs() {
        assert_eq!(p("1 + 2 * 3"), "(1 + (2 * 3))");
        assert_eq!(p("-t^2"), "(-(t ^ 2))");
        assert_eq!(p("2^3^2"), "(2 ^ (3 ^ 2))");
        assert_eq!(p("-2 * x"), "(-2 * x)");
        assert_eq!(p("- -2"), "2");
        assert_eq!(
            p("atan2(y, -x) + hypot(3, 4)"),
            "(atan2(y, (-x)) + hypot(3, 4))"
        );
        assert_eq!(p("10 - 4 - 3"), "((10 - 4) - 3)");
    }

    #[test]
    fn errors_are_located() {
        let e = |s: &str| parse(s, &L).unwrap_err();
        assert_eq!(e("").message, "empty expression");
        assert_eq!(e("(1 + t").at, (0, 1));
        assert_eq!(e("(1 + t").message, "unclosed `(`");
        assert_eq!(e("2 t").at, (2, 1));
        assert_eq!(e("1 $ 2").at, (2, 1));
        assert_eq!(e("sin t").at, (4, 1));
        assert_eq!(e("sin t").message, "expected `(` after `sin`");
        assert_eq!(
            e("1 ** 2").help.as_deref(),
            Some("`**` is not an operator: write `a^b` for powers")
        );
        assert!(
            e(&("(".repeat(100) + "1" + &")".repeat(100)))
                .message
                .contains("nested too deeply")
        );
        assert!(e(&vec!["t"; 600].join("+")).message.contains("too long"));
        let wide = Limits {
            max_depth: 256,
            max_tokens: usize::MAX,
        };
        // A long flat sum needs no recursion.
        assert!(parse(&vec!["t"; 100_000].join("+"), &wide).is_ok());
    }
}
