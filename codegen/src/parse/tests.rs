//! Unit tests of the parser: the shipped models, expressions, positions, robustness.

use super::inertia::check_inertia;
use super::*;

const STEWART: &str = include_str!("../../../models/stewart_6ups.toml");
const FIVE_BAR: &str = include_str!("../../../models/five_bar.toml");

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
        cols: None,
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
            Step::Quat(q) => {
                let e = crate::model::quat_rotation(std::array::from_fn(|i| q[i].eval(p, x)));
                r = std::array::from_fn(|i| {
                    std::array::from_fn(|j| (0..3).map(|k| r[i][k] * e[k][j]).sum())
                });
            }
            Step::Rotation(m) => {
                let e: [[f64; 3]; 3] =
                    std::array::from_fn(|i| std::array::from_fn(|j| m[i][j].eval(p, x)));
                r = std::array::from_fn(|i| {
                    std::array::from_fn(|j| (0..3).map(|k| r[i][k] * e[k][j]).sum())
                });
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
            Step::Rotation(_) | Step::Quat(_) => panic!("a rotation matrix"),
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
            Step::Rotation(_) | Step::Quat(_) => "R".to_string(),
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
        Ok(Expr::Call(Func::Sin, vec![div(Expr::Pi, Expr::int(2))]))
    );
    assert_eq!(
        expr("sqrt(q)"),
        Ok(Expr::Call(Func::Sqrt, vec![Expr::Coord(0)]))
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

/// Steps as text, to compare two models' frames.
fn steps_text(steps: &[Step]) -> Vec<String> {
    steps
        .iter()
        .map(|s| match s {
            Step::Rot(a, e) => format!("R{}({e:?})", a.name()),
            Step::Trans(a, e) => format!("T{}({e:?})", a.name()),
            Step::Rotation(m) => format!("R({m:?})"),
            Step::Quat(q) => format!("Q({q:?})"),
        })
        .collect()
}

#[test]
fn joints_by_name_are_the_elementary_steps() {
    let sugar = FIVE_BAR
        .replace(
            r#"transforms = ["Tx(-b)", "Rz(th1)"]"#,
            r#"transforms = ["Tx(-b)", { revolute = "th1" }]"#,
        )
        .replace(
            r#"transforms = ["Tx(l1)", "Rz(a1)"]"#,
            r#"transforms = ["Tx(l1)", { revolute = "a1", axis = "z" }]"#,
        )
        .replace(
            r#"transforms = ["Tx(x)", "Ty(y)"]"#,
            r#"transforms = [{ prismatic = "x", axis = "x" }, { prismatic = "y", axis = "y" }]"#,
        );
    assert_eq!(sugar.matches("revolute").count(), 2);
    let a = parse_ok("models/five_bar.toml", FIVE_BAR);
    let b = parse_ok("five_bar_joints.toml", &sugar);
    for (x, y) in a.bodies.iter().zip(&b.bodies) {
        assert_eq!(
            steps_text(&x.steps),
            steps_text(&y.steps),
            "body {}",
            x.name
        );
    }
    // Universal and spherical joints, with their default and given axes.
    let spatial = STEWART.replace(
        r#"transforms = ["Rz(alpha1)", "Tx(r0)", "Rx(phi1)", "Ry(psi1)"]"#,
        r#"transforms = ["Rz(alpha1)", "Tx(r0)", { universal = ["phi1", "psi1"] }]"#,
    );
    let spatial = spatial.replace(
        r#"transforms = ["Rz(alpha2)", "Tx(r0)", "Rx(phi2)", "Ry(psi2)"]"#,
        r#"transforms = ["Rz(alpha2)", "Tx(r0)", { spherical = ["phi2", "psi2", "d3"], axes = "xyx" }]"#,
    );
    let m = parse_ok("spatial.toml", &spatial);
    let s = &m.bodies;
    assert_eq!(
        steps_text(&s[0].steps)[2..],
        ["Rx(Coord(6))", "Ry(Coord(12))"]
    );
    assert_eq!(
        steps_text(&s[2].steps)[2..],
        ["Rx(Coord(7))", "Ry(Coord(13))", "Rx(Coord(2))"]
    );
}

#[test]
fn a_loop_with_count_is_the_loops_written_out() {
    // The six loops of the 6-UPS as one entry with `count = 6`.
    let start = STEWART.find("[[loop]]\nname = \"leg1\"").unwrap();
    let one = "[[loop]]\nname = \"leg{i}\"\ncount = 6\na = { body = \"leg{i}_upper\" }\n\
               b = { body = \"platform\", transforms = [\"Rz(beta{i})\", \"Tz(h)\", \"Tx(rp)\"] }\n";
    let repeated = format!("{}{one}", &STEWART[..start]);
    let a = parse_ok("models/stewart_6ups.toml", STEWART);
    let b = parse_ok("repeated.toml", &repeated);
    assert_eq!(a.loops.len(), b.loops.len());
    for (x, y) in a.loops.iter().zip(&b.loops) {
        assert_eq!(x.name, y.name);
        assert_eq!((x.a.body, x.b.body), (y.a.body, y.b.body));
        assert_eq!(steps_text(&x.b.steps), steps_text(&y.b.steps));
    }
}

#[test]
fn index_columns_map_back_to_the_template() {
    // "Rz(alpha{i})" as copy 12: "Rz(alpha12)".
    let cols = index_cols("Rz(alpha{i})", "Rz(alpha12)").unwrap();
    assert_eq!(cols.len(), "Rz(alpha12)".len() + 1);
    assert_eq!(cols[3], 3); // `a`
    assert_eq!(cols[8], 8); // `1` -> `{`
    assert_eq!(cols[9], 8); // `2` -> `{`
    assert_eq!(cols[10], 11); // `)` after `{i}`
    assert_eq!(*cols.last().unwrap(), "Rz(alpha{i})".len());
    assert!(index_cols("Rz(a)", "Rz(a)").is_none());
    assert!(index_cols("x{i}", "y1").is_none());
}

#[test]
fn solids_along_any_axis() {
    let src = FIVE_BAR.replace(
        r#"solid = { shape = "box", size = ["l1", "w", "t"], density = "rho" }"#,
        r#"solid = { shape = "rod", length = "l1", mass = 2, axis = "x" }"#,
    );
    let m = parse_ok("rods.toml", &src);
    let p = values(&m);
    let i: Vec<f64> = m.bodies[0]
        .inertia
        .as_ref()
        .unwrap()
        .inertia
        .iter()
        .map(|e| e.eval(&p, &[]))
        .collect();
    let across = 2.0 * 0.2 * 0.2 / 12.0;
    assert_eq!(i[0], 0.0);
    assert!(
        close(i[1], across, 1e-15) && close(i[2], across, 1e-15),
        "{i:?}"
    );
    let src = FIVE_BAR.replace(
        r#"solid = { shape = "box", size = ["l1", "w", "t"], density = "rho" }"#,
        r#"solid = { shape = "cylinder", radius = 0.01, length = "l1", mass = 2, axis = "y" }"#,
    );
    let m = parse_ok("cylinders.toml", &src);
    let p = values(&m);
    let i: Vec<f64> = m.bodies[0]
        .inertia
        .as_ref()
        .unwrap()
        .inertia
        .iter()
        .map(|e| e.eval(&p, &[]))
        .collect();
    assert!(close(i[1], 2.0 * 0.01 * 0.01 / 2.0, 1e-15), "{i:?}");
    let across = 2.0 * (3.0 * 0.01 * 0.01 + 0.2 * 0.2) / 12.0;
    assert!(
        close(i[0], across, 1e-15) && close(i[2], across, 1e-15),
        "{i:?}"
    );
    // A point mass and a thin rod's own inertia are allowed (positive semidefinite).
    assert!(check_inertia([0.0; 6]).is_none());
    assert!(check_inertia([0.01, 0.01, 0.0, 0.0, 0.0, 0.0]).is_none());
    assert!(check_inertia([0.01, 0.01, -1e-3, 0.0, 0.0, 0.0]).is_some());
}

#[test]
fn a_loop_on_the_wrong_leg_is_blamed_at_its_attachment() {
    // Loop leg3 attached to leg 2's upper link: d3, phi3, psi3 are in no loop.
    let wrong = STEWART.replace(
        "name = \"leg3\"\na = { body = \"leg3_upper\" }",
        "name = \"leg3\"\na = { body = \"leg2_upper\" }",
    );
    assert_ne!(wrong, STEWART);
    let d = parse_model("models/stewart_6ups.toml", &wrong).unwrap_err();
    assert_eq!(d.items.len(), 1, "{d}");
    let e = &d.items[0];
    let line = wrong
        .lines()
        .position(|l| l == "a = { body = \"leg2_upper\" }")
        .unwrap();
    // The second of the two `leg2_upper` attachments is leg3's.
    let lines: Vec<usize> = wrong
        .lines()
        .enumerate()
        .filter(|(_, l)| *l == "a = { body = \"leg2_upper\" }")
        .map(|(i, _)| i + 1)
        .collect();
    assert_eq!(lines.len(), 2);
    assert!(line + 1 == lines[0]);
    assert_eq!((e.pos.line, e.pos.col), (lines[1], 14), "{d}");
    assert!(
        e.message.contains("no loop reaches body `leg3_upper`"),
        "{}",
        e.message
    );
    assert!(e.message.contains("`d3`, `phi3`, `psi3`"), "{}", e.message);
    assert_eq!(
        e.help.as_deref(),
        Some(
            "did you mean `body = \"leg3_upper\"`? every coordinate that is not an output must be moved by a loop"
        )
    );
}

/// The loop kinds as parsed: a coupling's coordinates, ratio and offset; a loop in a moving
/// frame; a distance's length; `ball` as `point`; the equations each adds.
#[test]
fn loop_kinds_parse() {
    let leg = parse_ok(
        "models/leg_four_bar.toml",
        include_str!("../../../models/leg_four_bar.toml"),
    );
    let knee = &leg.loops[0];
    assert_eq!(knee.frame, Some(Side::A));
    assert!(matches!(knee.kind, LoopKind::Point));
    assert_eq!(knee.components, [Axis::X, Axis::Z]);
    let LoopKind::Coupling { a, b, poly } = &leg.loops[1].kind else {
        panic!("a coupling");
    };
    assert_eq!(
        (a, b),
        (&Expr::Coord(1), &Some(Expr::Coord(0))),
        "a = h, b = mo"
    );
    // `ratio` and `offset` are the polynomial `[offset, ratio]`.
    assert_eq!(poly.len(), 2);
    assert!(close(poly[1].eval(&values(&leg), &[]), 0.1, 1e-15));
    assert_eq!(poly[0], Expr::int(0));
    assert_eq!(leg.loops.iter().map(Loop::equations).sum::<usize>(), 3);
    let rod = parse_ok(
        "models/four_bar_rod.toml",
        include_str!("../../../models/four_bar_rod.toml"),
    );
    let LoopKind::Distance(length) = &rod.loops[0].kind else {
        panic!("a distance");
    };
    assert!(close(length.eval(&values(&rod), &[]), 0.3, 1e-15));
    assert!(rod.loops[0].components.is_empty());
    assert_eq!(rod.loops[0].equations(), 1);
    // `ball` is `point`; with the components x, y: a hinge 2 + 2 equations, a weld 2 + 3, a
    // point in a plane or on a line its components only.
    let ball = FIVE_BAR.replacen("name = \"left\"\n", "name = \"left\"\nkind = \"ball\"\n", 1);
    let m = parse_ok("five_bar_ball.toml", &ball);
    assert!(matches!(m.loops[0].kind, LoopKind::Point));
    assert_eq!(m.loops[0].components, [Axis::X, Axis::Y]);
    for (kind, n) in [
        (LoopKind::Hinge(Axis::Z), 4),
        (LoopKind::Weld, 5),
        (LoopKind::Sliding, 2),
    ] {
        let l = Loop {
            kind,
            ..m.loops[0].clone()
        };
        assert_eq!(l.equations(), n);
    }
}

/// A planar two-link arm (about z, links along x) whose tool frame is an output, and a
/// spinner of four joints beside it (so that the model has the six degrees of freedom of a
/// pose output).
fn two_link(outputs: &str) -> String {
    format!(
        r#"coordinates = [
  {{ name = "q1", unit = "rad", home = 0.3 }},
  {{ name = "q2", unit = "rad", home = -0.5 }},
  {{ name = "q3", unit = "rad", home = 0 }},
  {{ name = "q4", unit = "rad", home = 0 }},
  {{ name = "q5", unit = "rad", home = 0 }},
  {{ name = "q6", unit = "rad", home = 0 }},
]

[robot]
name = "two_link"
gravity = [0, -9.81, 0]
actuated = ["q1", "q2"]
outputs = {outputs}

[[body]]
name = "upper"
transforms = ["Rz(q1)"]
mass = 1
com = [0.25, 0, 0]
inertia = [0.01, 0.01, 0.01, 0, 0, 0]

[[body]]
name = "fore"
parent = "upper"
transforms = ["Tx(0.5)", "Rz(q2)"]
mass = 1
com = [0.2, 0, 0]
inertia = [0.01, 0.01, 0.01, 0, 0, 0]

[[body]]
name = "tool"
parent = "fore"
transforms = ["Tx(0.4)", "Rx(0.2)"]

[[body]]
name = "spinner"
transforms = ["Tz(1)", "Rz(q3)", "Rx(q4)", "Ry(q5)", "Rz(q6)"]
mass = 1
com = [0.1, 0, 0]
inertia = [0.01, 0.01, 0.01, 0, 0, 0]
"#
    )
}

#[test]
fn a_task_frame_adds_its_pose_coordinates_and_a_weld() {
    let m = parse_ok(
        "two_link.toml",
        &two_link(r#"[{ frame = "tool", pose = "xyz-rpy" }]"#),
    );
    let names: Vec<&str> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "q1",
            "q2",
            "q3",
            "q4",
            "q5",
            "q6",
            "tool_x",
            "tool_y",
            "tool_z",
            "tool_roll",
            "tool_pitch",
            "tool_yaw"
        ]
    );
    assert_eq!(m.outputs, [6, 7, 8, 9, 10, 11]);
    assert_eq!(m.loops.len(), 1);
    assert_eq!(m.loops[0].name, "tool_pose");
    assert!(m.loops[0].is_weld());
    assert_eq!(m.loops[0].a.body, Some(2));
    assert_eq!(m.loops[0].b.body, None);
    // Home: the frame's pose at q = (0.3, -0.5), by hand (planar, then Rx(0.2) about the tool's x).
    let (q1, q2) = (0.3f64, -0.5f64);
    let want = [
        0.5 * q1.cos() + 0.4 * (q1 + q2).cos(),
        0.5 * q1.sin() + 0.4 * (q1 + q2).sin(),
        0.0,
        0.2,
        0.0,
        q1 + q2,
    ];
    for (c, w) in m.coordinates[6..].iter().zip(want) {
        assert!(close(c.home, w, 1e-15), "{}: {} vs {w}", c.name, c.home);
    }
    // The home closes the weld: f(home) = 0.
    assert!(max_residual(&m) < 1e-15, "{}", max_residual(&m));

    let m = parse_ok(
        "two_link.toml",
        &two_link(r#"[{ frame = "fore", position = true, name = "elbow" }, "q3", "q4", "q5"]"#),
    );
    let names: Vec<&str> = m.coordinates[6..].iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["elbow_x", "elbow_y", "elbow_z"]);
    assert_eq!(m.outputs, [6, 7, 8, 2, 3, 4]);
    assert_eq!(m.loops[0].name, "elbow_position");
    assert_eq!(m.loops[0].equations(), 3);
}

#[test]
fn task_frame_errors_name_the_mistake() {
    let err = |outputs: &str| -> String {
        match parse_model("two_link.toml", &two_link(outputs)) {
            Ok(_) => panic!("{outputs} should be refused"),
            Err(d) => d.to_string(),
        }
    };
    let e = err(r#"[{ frame = "tol", pose = "xyz-rpy" }]"#);
    assert!(e.contains("task frame names unknown body `tol`"), "{e}");
    assert!(e.contains("`tool`"), "{e}");
    let e = err(r#"[{ frame = "tool", pose = "xyz-quat" }]"#);
    assert!(e.contains("unknown pose parametrisation"), "{e}");
    let e = err(r#"[{ frame = "tool" }]"#);
    assert!(e.contains("says neither `pose` nor `position`"), "{e}");
    let e = err(r#"[{ frame = "tool", pose = "xyz-rpy", position = true }]"#);
    assert!(e.contains("both `pose` and `position`"), "{e}");
    let e = err(r#"[{ frame = "tool", position = true }, { frame = "tool", position = true }]"#);
    assert!(e.contains("listed twice"), "{e}");
}
