//! A deterministic, in-process fuzzer of the model-file parser and validator
//! (`rbss_codegen::parse::{parse_model, parse_model_file}`), and of the URDF, MJCF and SDF
//! importers (`rbss_codegen::import::import_file`, `fuzz_importers`).
//!
//! Why not cargo-fuzz: it needs a nightly toolchain (`-Z sanitizer`), and this project builds
//! on stable only. So this is a seeded mutation fuzzer in the manner of cargo-fuzz's
//! structure-aware mutators: it starts from the real models (`models/*.toml`) and every golden
//! error case (`tests/ui/*.toml`) and applies 1 to 4 mutations per case, byte-level (delete,
//! duplicate, overwrite, insert, random bytes including invalid UTF-8) and structure-aware
//! (delete, duplicate, swap or move lines and whole `[table]` sections; replace a value by a
//! value of a random type; rename keys and names, with typos, Rust keywords, Unicode and
//! 10 000-character names; huge, tiny, NaN and infinite numbers; deep nesting of arrays,
//! inline tables and parentheses; grow or shrink arrays such as the 12-element pose vector;
//! CRLF, tabs, a byte-order mark). Cases with invalid UTF-8 go through `parse_model_file`.
//!
//! For every case it asserts: no panic (`catch_unwind`); a model that parses is consistent
//! (names and indices in range); an error report renders, its first line and every error's
//! first line match `^PATH:\d+:\d+: error: ` with the line inside the file and the column at
//! most one past the end of that line, and it ends with the `could not compile` summary.
//!
//! The parser never touches symbolica, so this runs on any number of threads.
//!
//! ```text
//! cargo test --release -p rbss-codegen --test fuzz_parser                     # CI: 5000 cases
//! RBSS_FUZZ_CASES=100000 cargo test --release -p rbss-codegen --test fuzz_parser -- --nocapture
//! RBSS_FUZZ_SEED=7 ...                                                        # another stream
//! ```
//!
//! A failing case is written to `$TMPDIR/rbss-fuzz-PID/failure-CASE.toml` and named in the
//! panic message; `RBSS_FUZZ_SEED` and the case number reproduce it.

use std::collections::{BTreeMap, HashSet};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::Instant;

mod common;

use common::Rng;
use rbss_codegen::diagnostics::Diagnostics;
use rbss_codegen::model::{Expr, Model, Step};
use rbss_codegen::parse::{parse_model, parse_model_file};

/// Cases in CI (about a second in release); `RBSS_FUZZ_CASES` overrides.
const DEFAULT_CASES: u64 = 5000;

// ---------------------------------------------------------------------------------------------
// Vocabulary

/// Names: valid, near-misses of the models' names, keywords, reserved words, odd characters.
const NAMES: &[&str] = &[
    "x",
    "y",
    "z",
    "d1",
    "d7",
    "phi2",
    "psi6",
    "rotx",
    "r0",
    "rp",
    "rho",
    "h",
    "b",
    "l1",
    "l2",
    "th1",
    "a1",
    "leg1_lower",
    "leg1_lowr",
    "leg2_upper",
    "platform",
    "platfrom",
    "prox1",
    "dist2",
    "effector",
    "world",
    "World",
    "left",
    "leg1",
    "leg9",
    "stewart_6ups",
    "five_bar",
    "FiveBar",
    "fn",
    "self",
    "Self",
    "type",
    "_",
    "pi",
    "sin",
    "sqrt",
    "Rz",
    "Tx",
    "",
    " ",
    "1abc",
    "a-b",
    "a b",
    "é",
    "ünïcode",
    "😀",
    "a\u{0}b",
    "\u{202e}rtl",
    "x__y",
    "trailing_",
];

/// Expression fragments (inside strings).
const WORDS: &[&str] = &[
    "x", "d1", "phi2", "r0", "rho", "h", "-", "+", "*", "/", "^", "**", "(", ")", " ", "1e9",
    "0.5", "1e-40", "1e38", "1e39", "0", "-0", "sin", "cos", "tan", "sqrt", "pi", "Rz(", "Tx(",
    "Ry(", "Tz(", ",", "1/0", "0/0", "0^-1", "sqrt(-1)", "deg", "m", "rad", "cylinder", "box",
    "rod", "atan2(", "hypot(", "asin(", "acos(", "abs(", "exp(", "ln(", "\\u00e9", "é", "\\\\",
    "\\\"", "\t", "nan", "inf", "e", ".", "..", "1.2.3", "#",
];

/// TOML keys of the format, and near-misses.
const KEYS: &[&str] = &[
    "name",
    "nmae",
    "unit",
    "home",
    "value",
    "doc",
    "description",
    "gravity",
    "actuated",
    "outputs",
    "output",
    "parent",
    "transforms",
    "transform",
    "mass",
    "com",
    "inertia",
    "solid",
    "shape",
    "radius",
    "length",
    "size",
    "density",
    "a",
    "b",
    "body",
    "components",
    "coordinates",
    "parameters",
    "robot",
    "loop",
    "frames",
    "frame",
    "rpy",
    "quat",
    "axis_angle",
    "pose",
    "xyz",
    "inverse",
];

/// Scalar TOML values of every type, including extremes.
const SCALARS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "42",
    "9223372036854775807",
    "-9223372036854775808",
    "99999999999999999999999",
    "0x7fffffff",
    "0o777",
    "0b1010",
    "1_000",
    "0.5",
    "-0.0",
    "1e308",
    "-1e308",
    "1e309",
    "1.7976931348623157e308",
    "5e-324",
    "1e-320",
    "1e38",
    "1e39",
    "1e-39",
    "nan",
    "+nan",
    "-nan",
    "inf",
    "+inf",
    "-inf",
    "true",
    "false",
    "1979-05-27T07:32:00Z",
    "1979-05-27",
    "07:32:00",
    "\"\"",
    "\"x\"",
    "\"-m\"",
    "\"1e309\"",
    "\"nan\"",
    "\"inf\"",
    "\"0/0\"",
    "\"1/0\"",
    "\"Rz(\"",
    "\"Rz(alpha1)\"",
    "\"Tx(r0)\"",
    "{ rpy = [0, 0, \"pi\"] }",
    "{ quat = [1, 0, 0, 0] }",
    "{ quat = [0, 0, 0, 0] }",
    "{ axis_angle = [0, 0, 1, 90], unit = \"deg\" }",
    "{ pose = { xyz = [0, 0, 1], rpy = [0, 0, 0] } }",
    "{ inverse = [\"Tx(r0)\"] }",
    "{ frame = \"nowhere\" }",
    "\"world\"",
    "\"platform\"",
    "\"cylinder\"",
    "\"deg\"",
    "'literal'",
    "'''multi\nline'''",
    "\"\"\"multi\nline\"\"\"",
    "[]",
    "{}",
    "[[]]",
    "[{}]",
];

/// Control and odd characters for byte-level mutations.
const CHARS: &[u8] = b"[]{}\"'=,.-+e9 0x_#\n\r\t()^*/\\apsinqdz";

// ---------------------------------------------------------------------------------------------
// Mutations

/// Start of every line (and the end of the text).
fn line_starts(b: &[u8]) -> Vec<usize> {
    let mut v = vec![0];
    v.extend((0..b.len()).filter(|&i| b[i] == b'\n').map(|i| i + 1));
    if *v.last().unwrap() != b.len() {
        v.push(b.len());
    }
    v
}

/// A random line's byte range (with its newline).
fn random_line(b: &[u8], rng: &mut Rng) -> (usize, usize) {
    let s = line_starts(b);
    if s.len() < 2 {
        return (0, b.len());
    }
    let k = rng.below(s.len() - 1);
    (s[k], s[k + 1])
}

/// A random value of a random type (scalars, strings of expression words, arrays, inline
/// tables, deep nesting).
fn random_value(rng: &mut Rng, depth: usize) -> String {
    match rng.below(if depth > 3 { 3 } else { 7 }) {
        0 | 1 => rng.pick(SCALARS).to_string(),
        2 => {
            let n = rng.below(6);
            let s: String = (0..n).map(|_| *rng.pick(WORDS)).collect();
            format!("\"{}\"", s.replace('"', "\\\""))
        }
        3 => {
            let n = rng.below(14);
            let items: Vec<String> = (0..n).map(|_| random_value(rng, depth + 1)).collect();
            format!("[{}]", items.join(", "))
        }
        4 => {
            let n = rng.below(4);
            let items: Vec<String> = (0..n)
                .map(|_| format!("{} = {}", rng.pick(KEYS), random_value(rng, depth + 1)))
                .collect();
            format!("{{ {} }}", items.join(", "))
        }
        5 => {
            // Deep nesting: arrays, inline tables or parentheses in an expression.
            let max = if rng.chance(10) { 5000 } else { 60 };
            let d = 1 + rng.below(max);
            match rng.below(3) {
                0 => format!("{}1{}", "[".repeat(d), "]".repeat(d)),
                1 => format!("{}1{}", "{a = ".repeat(d), "}".repeat(d)),
                _ => format!("\"{}x{}\"", "(".repeat(d), ")".repeat(d)),
            }
        }
        _ => {
            // A name, possibly huge.
            let name = if rng.chance(8) {
                "n".repeat(10_000)
            } else {
                rng.pick(NAMES).to_string()
            };
            format!("\"{}\"", name.replace('\\', "\\\\").replace('"', "\\\""))
        }
    }
}

/// Byte ranges of `"..."` strings on one line (no escapes inside, for simplicity).
fn strings(b: &[u8]) -> Vec<(usize, usize)> {
    let quotes: Vec<usize> = (0..b.len()).filter(|&i| b[i] == b'"').collect();
    quotes
        .chunks_exact(2)
        .map(|q| (q[0] + 1, q[1]))
        .filter(|&(a, e)| !b[a..e].contains(&b'\n'))
        .collect()
}

/// Byte ranges of number-like tokens outside strings (roughly).
fn numbers(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    let mut in_str = false;
    while i < b.len() {
        let c = b[i];
        if c == b'"' {
            in_str = !in_str;
        } else if c == b'\n' {
            in_str = false;
        } else if !in_str
            && (c.is_ascii_digit() || c == b'-')
            && (i == 0 || !b[i - 1].is_ascii_alphanumeric() && b[i - 1] != b'_')
        {
            let start = i;
            i += 1;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b"._+-".contains(&b[i])) {
                i += 1;
            }
            out.push((start, i));
            continue;
        }
        i += 1;
    }
    out
}

/// `[table]` sections: from a header line to the next header line.
fn sections(b: &[u8]) -> Vec<(usize, usize)> {
    let s = line_starts(b);
    let heads: Vec<usize> = s
        .iter()
        .copied()
        .filter(|&i| i < b.len() && b[i] == b'[')
        .collect();
    heads
        .iter()
        .enumerate()
        .map(|(k, &a)| (a, heads.get(k + 1).copied().unwrap_or(b.len())))
        .collect()
}

fn mutate(bytes: &mut Vec<u8>, rng: &mut Rng) {
    let len = bytes.len();
    let a = rng.below(len + 1);
    let span = if rng.chance(4) { 400 } else { 12 };
    let e = (a + 1 + rng.below(span)).min(len);
    match rng.below(20) {
        // --- byte level ---
        0 => {
            bytes.drain(a..e);
        }
        1 => {
            let copy = bytes[a..e].to_vec();
            let at = rng.below(bytes.len() + 1);
            bytes.splice(at..at, copy);
        }
        2 => {
            let fill: Vec<u8> = (a..e).map(|_| *rng.pick(CHARS)).collect();
            bytes.splice(a..e, fill);
        }
        3 => {
            let n = 1 + rng.below(6);
            let fill: Vec<u8> = (0..n).map(|_| *rng.pick(CHARS)).collect();
            bytes.splice(a..a, fill);
        }
        4 => {
            // Arbitrary bytes, often invalid UTF-8 (a lone continuation byte, a truncated
            // sequence, an overlong encoding, a surrogate).
            let fill: Vec<u8> = match rng.below(5) {
                0 => vec![0x80],
                1 => vec![0xE2, 0x82],
                2 => vec![0xC0, 0xAF],
                3 => vec![0xED, 0xA0, 0x80],
                _ => (0..1 + rng.below(3)).map(|_| rng.next() as u8).collect(),
            };
            bytes.splice(a..a, fill);
        }
        // --- lines ---
        5 => {
            let (a, e) = random_line(bytes, rng);
            bytes.drain(a..e);
        }
        6 => {
            let (a, e) = random_line(bytes, rng);
            let line = bytes[a..e].to_vec();
            bytes.splice(a..a, line);
        }
        7 => {
            // Swap two lines / move a line.
            let (a1, e1) = random_line(bytes, rng);
            let line = bytes[a1..e1].to_vec();
            bytes.drain(a1..e1);
            let s = line_starts(bytes);
            let at = *rng.pick(&s);
            bytes.splice(at..at, line);
        }
        // --- sections ---
        8 => {
            let secs = sections(bytes);
            if !secs.is_empty() {
                let (a, e) = *rng.pick(&secs);
                match rng.below(3) {
                    0 => {
                        bytes.drain(a..e);
                    }
                    1 => {
                        let copy = bytes[a..e].to_vec();
                        bytes.splice(a..a, copy);
                    }
                    _ => {
                        // Move the section elsewhere, e.g. `[[loop]]` before its bodies, or
                        // `coordinates = [...]` ending up after a header.
                        let copy = bytes[a..e].to_vec();
                        bytes.drain(a..e);
                        let s = line_starts(bytes);
                        let at = *rng.pick(&s);
                        bytes.splice(at..at, copy);
                    }
                }
            }
        }
        // --- values ---
        9 | 10 => {
            // Replace the value of a `key = value` line by a random value of a random type.
            let (la, le) = random_line(bytes, rng);
            if let Some(eq) = bytes[la..le].iter().position(|&c| c == b'=') {
                let start = la + eq + 1;
                let end = if bytes[le - 1] == b'\n' { le - 1 } else { le };
                let v = format!(" {}", random_value(rng, 0));
                bytes.splice(start..end.max(start), v.into_bytes());
            }
        }
        11 => {
            // Rename a key.
            let (la, le) = random_line(bytes, rng);
            if let Some(eq) = bytes[la..le].iter().position(|&c| c == b'=') {
                let key = rng.pick(KEYS).as_bytes().to_vec();
                let key = if rng.chance(3) {
                    format!("\"{}\"", rng.pick(NAMES)).into_bytes()
                } else {
                    key
                };
                let mut k = key;
                k.push(b' ');
                bytes.splice(la..la + eq, k);
            }
        }
        12 | 13 => {
            // Rewrite the inside of a string: an expression or a name.
            let ss = strings(bytes);
            if !ss.is_empty() {
                let (a, e) = *rng.pick(&ss);
                let fill: String = if rng.chance(2) {
                    (0..rng.below(6)).map(|_| *rng.pick(WORDS)).collect()
                } else {
                    rng.pick(NAMES).to_string()
                };
                bytes.splice(a..e, fill.replace('"', "\\\"").into_bytes());
            }
        }
        14 => {
            // Insert a word into a string (a typo in an expression).
            let ss = strings(bytes);
            if !ss.is_empty() {
                let (a, e) = *rng.pick(&ss);
                let at = a + rng.below(e - a + 1);
                bytes.splice(at..at, rng.pick(WORDS).bytes());
            }
        }
        15 => {
            // Replace a number by an extreme one.
            let ns = numbers(bytes);
            if !ns.is_empty() {
                let (a, e) = *rng.pick(&ns);
                let v = *rng.pick(&[
                    "1e308",
                    "1e309",
                    "-1e309",
                    "5e-324",
                    "nan",
                    "inf",
                    "-inf",
                    "0",
                    "-0",
                    "1e38",
                    "1e39",
                    "1e-39",
                    "-1",
                    "0.0",
                    "99999999999999999999",
                    "1e-300",
                    "7",
                ]);
                bytes.splice(a..e, v.bytes());
            }
        }
        16 => {
            // Grow or shrink an array: drop an element or duplicate one (pose vector arity,
            // gravity, com, inertia, components).
            let (la, le) = random_line(bytes, rng);
            let line = &bytes[la..le];
            let commas: Vec<usize> = (0..line.len()).filter(|&i| line[i] == b',').collect();
            if !commas.is_empty() {
                let c = la + *rng.pick(&commas);
                if rng.chance(2) {
                    // drop ", <elem>" up to the next comma or bracket
                    let mut end = c + 1;
                    while end < le && !b",]}\n".contains(&bytes[end]) {
                        end += 1;
                    }
                    bytes.drain(c..end);
                } else {
                    let mut start = c;
                    while start > la && !b",[{".contains(&bytes[start - 1]) {
                        start -= 1;
                    }
                    let elem = bytes[start..c + 1].to_vec();
                    bytes.splice(start..start, elem);
                }
            }
        }
        17 => {
            // Deep nesting spliced at a random place in a value.
            let max = if rng.chance(5) { 3000 } else { 50 };
            let d = 1 + rng.below(max);
            let (open, close) = *rng.pick(&[("[", "]"), ("(", ")"), ("{a=", "}")]);
            let (la, le) = random_line(bytes, rng);
            if let Some(eq) = bytes[la..le].iter().position(|&c| c == b'=') {
                let end = if bytes[le - 1] == b'\n' { le - 1 } else { le };
                bytes.splice(end..end, close.repeat(d).into_bytes());
                let at = la + eq + 1;
                bytes.splice(at..at, open.repeat(d).into_bytes());
            }
        }
        18 => {
            // Line endings, tabs, a byte-order mark.
            match rng.below(3) {
                0 => {
                    let s = String::from_utf8_lossy(bytes).replace('\n', "\r\n");
                    *bytes = s.into_bytes();
                }
                1 => {
                    let s = String::from_utf8_lossy(bytes).replace("  ", "\t");
                    *bytes = s.into_bytes();
                }
                _ => {
                    bytes.splice(0..0, "\u{FEFF}".bytes());
                }
            }
        }
        _ => {
            // A new key/value line or a table header.
            let s = line_starts(bytes);
            let at = *rng.pick(&s);
            let line = match rng.below(3) {
                0 => format!("{} = {}\n", rng.pick(KEYS), random_value(rng, 0)),
                1 => format!("[{}]\n", rng.pick(KEYS)),
                _ => format!("[[{}]]\nname = \"{}\"\n", rng.pick(KEYS), rng.pick(NAMES)),
            };
            bytes.splice(at..at, line.into_bytes());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Checks

/// Problems with a rendered report (empty when it is well formed).
fn check_report(path: &str, src: &str, d: &Diagnostics) -> Vec<String> {
    let mut bad = Vec::new();
    let rendered = d.render();
    let lines: Vec<&str> = src.split('\n').collect();
    if d.items.is_empty() {
        bad.push("an error report without errors".to_string());
    }
    let first = rendered.lines().next().unwrap_or("");
    if parse_head(path, first).is_none() {
        bad.push(format!("first line is not `PATH:L:C: error: `: {first:?}"));
    }
    let mut heads = 0;
    for line in rendered.lines() {
        if !line.starts_with(path) {
            continue;
        }
        heads += 1;
        match parse_head(path, line) {
            None => bad.push(format!("malformed error line {line:?}")),
            Some((l, c)) => {
                if l == 0 || l > lines.len() {
                    bad.push(format!(
                        "line {l} outside the file ({} lines): {line:?}",
                        lines.len()
                    ));
                } else {
                    let text = lines[l - 1].strip_suffix('\r').unwrap_or(lines[l - 1]);
                    let width = text.chars().count();
                    if c == 0 || c > width + 1 {
                        bad.push(format!(
                            "column {c} outside line {l} ({width} characters): {line:?}"
                        ));
                    }
                }
            }
        }
    }
    if heads != d.items.len() {
        bad.push(format!(
            "{} errors but {heads} error lines in the report",
            d.items.len()
        ));
    }
    let n = d.items.len();
    let tail = format!(
        "error: could not compile `{path}`: {n} error{}\n",
        if n == 1 { "" } else { "s" }
    );
    if !rendered.ends_with(&tail) {
        bad.push("the report does not end with the summary line".to_string());
    }
    for it in &d.items {
        if it.message.trim().is_empty() {
            bad.push("an empty message".to_string());
        }
    }
    bad
}

/// `PATH:L:C: error: ...` -> `(L, C)`.
fn parse_head(path: &str, line: &str) -> Option<(usize, usize)> {
    let rest = line.strip_prefix(path)?.strip_prefix(':')?;
    let (l, rest) = rest.split_once(':')?;
    let (c, rest) = rest.split_once(':')?;
    if !rest.starts_with(" error: ")
        || l.is_empty()
        || c.is_empty()
        || !l.bytes().all(|b| b.is_ascii_digit())
        || !c.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    Some((l.parse().ok()?, c.parse().ok()?))
}

/// Problems with a model that parsed (its indices must be usable without bounds checks).
fn check_model(m: &Model) -> Vec<String> {
    let mut bad = Vec::new();
    let n = m.coordinates.len();
    if m.actuated.iter().chain(&m.outputs).any(|&j| j >= n) {
        bad.push("actuated/outputs index out of range".to_string());
    }
    for b in &m.bodies {
        if b.parent.is_some_and(|p| p >= m.bodies.len()) {
            bad.push(format!("body {} has a parent out of range", b.name));
        }
    }
    for l in &m.loops {
        for att in [&l.a, &l.b] {
            if att.body.is_some_and(|p| p >= m.bodies.len()) {
                bad.push(format!("loop {} names a body out of range", l.name));
            }
        }
    }
    let np = m.parameters.len();
    let mut exprs: Vec<&Expr> = m.gravity.iter().collect();
    exprs.extend(m.parameters.iter().map(|p| &p.expr));
    for b in &m.bodies {
        exprs.extend(b.steps.iter().flat_map(step_exprs));
        if let Some(mp) = &b.inertia {
            exprs.push(&mp.mass);
            exprs.extend(mp.com.iter().chain(&mp.inertia));
        }
    }
    for l in &m.loops {
        exprs.extend(l.a.steps.iter().chain(&l.b.steps).flat_map(step_exprs));
    }
    if exprs.iter().any(|e| !indices_ok(e, np, n)) {
        bad.push("an expression with a parameter or coordinate index out of range".to_string());
    }
    if m.coordinates.iter().any(|c| !c.home.is_finite()) {
        bad.push("a non-finite home".to_string());
    }
    if m.parameters.iter().any(|p| !p.value.is_finite()) {
        bad.push("a non-finite parameter value".to_string());
    }
    bad
}

fn step_exprs(s: &Step) -> Vec<&Expr> {
    match s {
        Step::Rot(_, e) | Step::Trans(_, e) => vec![e],
        Step::Rotation(m) => m.iter().flatten().collect(),
        Step::Quat(q) => q.iter().collect(),
    }
}

fn indices_ok(e: &Expr, np: usize, n: usize) -> bool {
    match e {
        Expr::Param(i) => *i < np,
        Expr::Coord(j) => *j < n,
        Expr::Num { .. } | Expr::Pi => true,
        Expr::Neg(a) => indices_ok(a, np, n),
        Expr::Call(_, args) => args.iter().all(|a| indices_ok(a, np, n)),
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            indices_ok(a, np, n) && indices_ok(b, np, n)
        }
    }
}

/// A message with its specifics (names in backticks, numbers) blanked: the kind of error.
fn template(msg: &str) -> String {
    let mut out = String::new();
    let mut in_tick = false;
    let mut prev_digit = false;
    for ch in msg.chars() {
        if ch == '`' {
            in_tick = !in_tick;
            if in_tick {
                out.push_str("`_`");
            }
            continue;
        }
        if in_tick {
            continue;
        }
        if ch.is_ascii_digit() {
            if !prev_digit {
                out.push('N');
            }
            prev_digit = true;
            continue;
        }
        prev_digit = false;
        out.push(ch);
    }
    out
}

#[derive(Default)]
struct Stats {
    cases: u64,
    parsed: u64,
    errors: u64,
    through_file: u64,
    not_utf8: u64,
    toml_syntax: u64,
    messages: HashSet<String>,
    templates: BTreeMap<String, u64>,
    failures: Vec<String>,
}

fn env_u64(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} is not a number")),
        Err(_) => default,
    }
}

fn corpus(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for dir in ["models", "tests/ui"] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .unwrap_or_else(|e| panic!("cannot read {dir}: {e}"))
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        paths.sort();
        for p in paths {
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            files.push((rel, std::fs::read(&p).unwrap()));
        }
    }
    assert!(files.len() >= 3, "no seed corpus found");
    files
}

#[test]
fn fuzz_model_parser() {
    let cases = env_u64("RBSS_FUZZ_CASES", DEFAULT_CASES);
    let seed = env_u64("RBSS_FUZZ_SEED", 0x5eed_f022);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let seeds = corpus(&root);
    // The real models are mutated more often than the small golden cases.
    let weights: Vec<usize> = seeds
        .iter()
        .map(|(p, _)| if p.starts_with("models") { 8 } else { 1 })
        .collect();
    let total_weight: usize = weights.iter().sum();
    let tmpdir = tempfile::tempdir().unwrap();
    let tmp = tmpdir.path();
    let file_path = tmp.join("case.toml");
    let path = "fuzz/case.toml";

    let mut st = Stats::default();
    let t0 = Instant::now();
    for case in 0..cases {
        let mut rng = Rng::new(seed ^ case.wrapping_mul(0x1000_0000_01B3));
        let mut w = rng.below(total_weight);
        let mut k = 0;
        while w >= weights[k] {
            w -= weights[k];
            k += 1;
        }
        let mut bytes = seeds[k].1.clone();
        for _ in 0..1 + rng.below(4) {
            mutate(&mut bytes, &mut rng);
        }
        st.cases += 1;

        // Valid UTF-8 goes to parse_model; otherwise (and for a sample of the rest) through
        // the file, as `rbss-codegen` reads it.
        let utf8 = std::str::from_utf8(&bytes).is_ok();
        let via_file = !utf8 || rng.chance(50);
        let (shown, result, src) = if via_file {
            st.through_file += 1;
            std::fs::write(&file_path, &bytes).unwrap();
            let shown = file_path.display().to_string();
            let r = catch_unwind(AssertUnwindSafe(|| parse_model_file(&file_path)));
            (shown, r, String::from_utf8_lossy(&bytes).into_owned())
        } else {
            let src = String::from_utf8(bytes.clone()).unwrap();
            let r = catch_unwind(AssertUnwindSafe(|| parse_model(path, &src)));
            (path.to_string(), r, src)
        };
        let problems = match result {
            Err(e) => {
                let msg = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                vec![format!("panic: {msg}")]
            }
            Ok(Ok(model)) => {
                st.parsed += 1;
                check_model(&model)
            }
            Ok(Err(d)) => {
                st.errors += 1;
                for it in &d.items {
                    if it.message.starts_with("TOML syntax") {
                        st.toml_syntax += 1;
                    }
                    if it.message.contains("not valid UTF-8") {
                        st.not_utf8 += 1;
                    }
                    st.messages.insert(it.message.clone());
                    *st.templates.entry(template(&it.message)).or_default() += 1;
                }
                // The rendering must also survive (its own catch_unwind: a panic there is a bug
                // of the renderer, not the parser).
                match catch_unwind(AssertUnwindSafe(|| check_report(&shown, &src, &d))) {
                    Ok(p) => p,
                    Err(_) => vec!["panic while rendering the report".to_string()],
                }
            }
        };
        if !problems.is_empty() {
            let out = tmp.join(format!("failure-{case}.toml"));
            std::fs::write(&out, &bytes).unwrap();
            st.failures.push(format!(
                "case {case} (seed {seed:#x}, from {}; input saved to {}):\n  {}",
                seeds[k].0,
                out.display(),
                problems.join("\n  ")
            ));
            if st.failures.len() >= 20 {
                break;
            }
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&file_path);

    println!(
        "fuzz_model_parser: {} cases in {secs:.2} s ({:.0} cases/s, seed {seed:#x}): {} parsed, {} rejected \
         ({} through parse_model_file, {} not UTF-8, {} TOML syntax errors); {} distinct error messages, \
         {} distinct kinds (names and numbers blanked)",
        st.cases,
        st.cases as f64 / secs,
        st.parsed,
        st.errors,
        st.through_file,
        st.not_utf8,
        st.toml_syntax,
        st.messages.len(),
        st.templates.len()
    );
    if std::env::var_os("RBSS_FUZZ_VERBOSE").is_some() {
        let mut kinds: Vec<(&String, &u64)> = st.templates.iter().collect();
        kinds.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
        for (t, n) in kinds {
            println!("{n:>8}  {t}");
        }
    }
    assert!(
        st.failures.is_empty(),
        "{} failing cases:\n{}",
        st.failures.len(),
        st.failures.join("\n")
    );
    // The mutations must reach the validator, not only the TOML parser.
    assert!(
        st.errors > st.cases / 4 && st.templates.len() > 30,
        "the fuzzer hardly reaches the model checks: {} errors, {} kinds",
        st.errors,
        st.templates.len()
    );
}

/// The importers (URDF, MJCF, SDF) under the same mutations, seeded with the import tests'
/// sources and golden error cases: no panic, and every report well formed and located in the
/// source (`codegen/src/import`).
#[test]
fn fuzz_importers() {
    use rbss_codegen::import::{Format, import_file};
    // A fifth of the parser's cases: an import case costs more (a file written and read).
    let cases = env_u64("RBSS_FUZZ_CASES", DEFAULT_CASES) / 5;
    let seed = env_u64("RBSS_FUZZ_SEED", 0x5eed_f022) ^ 0x1417;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/import");
    let mut seeds: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    for d in [dir.clone(), dir.join("ui")] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(&d)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| Format::from_path(p).is_some())
            .collect();
        paths.sort();
        for p in paths {
            let bytes = std::fs::read(&p).unwrap();
            seeds.push((p, bytes));
        }
    }
    assert!(seeds.len() >= 6, "no importer seed corpus");
    let tmpdir = tempfile::tempdir().unwrap();
    let (mut imported, mut rejected) = (0u64, 0u64);
    let mut failures = Vec::new();
    let t0 = Instant::now();
    for case in 0..cases {
        let mut rng = Rng::new(seed ^ case.wrapping_mul(0x1000_0000_01B3));
        let (from, original) = &seeds[rng.below(seeds.len())];
        let mut bytes = original.clone();
        for _ in 0..1 + rng.below(4) {
            mutate(&mut bytes, &mut rng);
        }
        let ext = from.extension().unwrap().to_string_lossy().into_owned();
        let file = tmpdir.path().join(format!("case.{ext}"));
        std::fs::write(&file, &bytes).unwrap();
        let format = Format::from_path(&file).unwrap();
        let shown = file.display().to_string();
        let result = catch_unwind(AssertUnwindSafe(|| import_file(&file, &shown, format)));
        let problems = match result {
            Err(_) => vec!["panic".to_string()],
            Ok(Ok((m, _))) => {
                imported += 1;
                // What an import writes is a TOML document.
                match toml::from_str::<toml::Table>(&m.render()) {
                    Ok(_) => Vec::new(),
                    Err(e) => vec![format!("the written model is not TOML: {e}")],
                }
            }
            Ok(Err(d)) => {
                rejected += 1;
                let src = String::from_utf8_lossy(&bytes).into_owned();
                match catch_unwind(AssertUnwindSafe(|| check_report(&shown, &src, &d))) {
                    Ok(p) => p,
                    Err(_) => vec!["panic while rendering the report".to_string()],
                }
            }
        };
        if !problems.is_empty() {
            let out = tmpdir.path().join(format!("failure-{case}.{ext}"));
            std::fs::write(&out, &bytes).unwrap();
            failures.push(format!(
                "case {case} (from {}; saved to {}): {}",
                from.display(),
                out.display(),
                problems.join("; ")
            ));
            if failures.len() >= 20 {
                break;
            }
        }
    }
    println!(
        "fuzz_importers: {cases} cases in {:.2} s: {imported} imported, {rejected} rejected",
        t0.elapsed().as_secs_f64()
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(
        rejected > cases / 4,
        "the mutations hardly reach the importers' checks"
    );
}
