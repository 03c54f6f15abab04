//! The C ABI's places against its table (rbss-abi, `ffi/abi/src/lib.rs`): `include/rbss.h`'s
//! prototypes (names, order, return and argument types, argument names, the arrays' length
//! comments) and `#define`s, and the ctypes layer's table `python/rbss/_abi.py` (written from
//! the table; `RBSS_BLESS=1` rewrites it). `export!` and the PyO3 core are made from the table
//! (the compiler checks them).

use std::path::Path;

use rbss_abi::{ABI_VERSION, CONSTANTS, FUNCTIONS, c_return_type, c_type};

/// A prototype of the header: return type, name, arguments (type, name, length comment).
#[derive(Debug)]
struct Prototype {
    ret: String,
    name: String,
    args: Vec<(String, String, Option<String>)>,
}

/// `const double *x` -> ("const double *", "x"): types with ` *` and single spaces.
fn split_declaration(decl: &str) -> (String, String) {
    let decl = decl.trim();
    let start = decl
        .rfind(|c: char| !(c.is_alphanumeric() || c == '_'))
        .map_or(0, |i| i + 1);
    let ty = decl[..start].replace('*', " *");
    let ty = ty.split_whitespace().collect::<Vec<_>>().join(" ");
    (ty, decl[start..].to_string())
}

/// The header without comments outside parentheses and without preprocessor lines, and the
/// `#define NAME VALUE`s.
fn prototypes(header: &str) -> (Vec<Prototype>, Vec<(String, String)>) {
    let mut defines = Vec::new();
    let mut code = String::new();
    for line in header.lines() {
        let t = line.trim_start();
        if let Some(rest) = t.strip_prefix("#define ") {
            let mut words = rest.split_whitespace();
            if let (Some(name), Some(value)) = (words.next(), words.next()) {
                defines.push((name.to_string(), value.to_string()));
            }
        } else if !t.starts_with('#') {
            code += line;
            code.push('\n');
        }
    }
    // Comments at depth 0 out; those inside a prototype's parentheses (the lengths) kept.
    let mut text = String::new();
    let (mut depth, mut rest) = (0usize, code.as_str());
    while let Some(c) = rest.chars().next() {
        if depth == 0 && rest.starts_with("/*") {
            let end = rest.find("*/").expect("an unterminated comment") + 2;
            rest = &rest[end..];
            text.push(' ');
            continue;
        }
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            _ => {}
        }
        text.push(c);
        rest = &rest[c.len_utf8()..];
    }
    let mut out = Vec::new();
    for statement in text.split(';') {
        let s = statement.trim();
        let Some(open) = s.find('(') else { continue };
        if s.starts_with("typedef") || !s[..open].contains("rbss_") {
            continue;
        }
        let (ret, name) = split_declaration(&s[..open]);
        let params = &s[open + 1..s.rfind(')').unwrap()];
        // Split at the commas outside comments.
        let mut parts = vec![String::new()];
        let mut in_comment = false;
        let b = params.as_bytes();
        for (i, &ch) in b.iter().enumerate() {
            if !in_comment && params[i..].starts_with("/*") {
                in_comment = true;
            } else if in_comment && i > 0 && b[i - 1] == b'*' && ch == b'/' {
                in_comment = false;
            }
            if ch == b',' && !in_comment {
                parts.push(String::new());
            } else {
                parts.last_mut().unwrap().push(ch as char);
            }
        }
        let mut args = Vec::new();
        for p in parts {
            let (decl, comment) = match (p.find("/*"), p.find("*/")) {
                (Some(a), Some(e)) => (
                    format!("{}{}", &p[..a], &p[e + 2..]),
                    Some(p[a + 2..e].split_whitespace().collect::<Vec<_>>().join(" ")),
                ),
                _ => (p.clone(), None),
            };
            if decl.trim() == "void" || decl.trim().is_empty() {
                continue;
            }
            let (ty, arg) = split_declaration(&decl);
            args.push((ty, arg, comment));
        }
        out.push(Prototype { ret, name, args });
    }
    (out, defines)
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap()
}

#[test]
fn the_header_is_the_table() {
    let header = std::fs::read_to_string(root().join("ffi/include/rbss.h")).unwrap();
    let (protos, defines) = prototypes(&header);
    let names: Vec<&str> = protos.iter().map(|p| p.name.as_str()).collect();
    let table: Vec<&str> = FUNCTIONS.iter().map(|f| f.name).collect();
    assert_eq!(
        names, table,
        "rbss.h's functions and their order against the table"
    );
    for (p, f) in protos.iter().zip(FUNCTIONS) {
        assert_eq!(
            Some(p.ret.as_str()),
            c_return_type(f.ret),
            "{}: return type",
            f.name
        );
        // The lengths without their spaces: `stringify!` writes `(2 * n) x (2 * n)` as
        // `(2 * n) x(2 * n)`.
        let squash = |l: &str| l.split_whitespace().collect::<String>();
        let want: Vec<(String, String, Option<String>)> = f
            .args
            .iter()
            .map(|a| {
                let len = a.len.map(|l| match a.kind {
                    "input_or_null" => format!("{l}, or NULL"),
                    _ => l.to_string(),
                });
                let len = len.as_deref().map(squash);
                (c_type(a.kind).unwrap().to_string(), a.name.to_string(), len)
            })
            .collect();
        let got: Vec<(String, String, Option<String>)> = p
            .args
            .iter()
            .map(|(t, n, l)| (t.clone(), n.clone(), l.as_deref().map(squash)))
            .collect();
        assert_eq!(
            got, want,
            "{}: arguments (type, name, length comment)",
            f.name
        );
    }
    let mut want: Vec<(String, String)> = CONSTANTS
        .iter()
        .map(|(n, v)| (n.to_string(), v.to_string()))
        .collect();
    want.push(("RBSS_ABI_VERSION".into(), format!("{ABI_VERSION}u")));
    // (The include guard, `#define RBSS_H`, has no value.)
    let mut got = defines;
    want.sort();
    got.sort();
    assert_eq!(got, want, "rbss.h's #defines against the table's constants");
}

#[test]
fn the_parser_sees_what_it_must() {
    // The checker itself: a changed length, type or name is seen.
    let (p, _) = prototypes(
        "/* a, b (c) */\nint rbss_x(rbss_robot *h, const double *u /* actuated, or NULL */,\n \
         double t, double *m /* m x n */); /* i < n */\nconst char *rbss_y(const rbss_robot *h);",
    );
    assert_eq!(p.len(), 2);
    assert_eq!((p[0].ret.as_str(), p[0].name.as_str()), ("int", "rbss_x"));
    assert_eq!(
        p[0].args,
        vec![
            ("rbss_robot *".into(), "h".into(), None),
            (
                "const double *".into(),
                "u".into(),
                Some("actuated, or NULL".into())
            ),
            ("double".into(), "t".into(), None),
            ("double *".into(), "m".into(), Some("m x n".into())),
        ]
    );
    assert_eq!(p[1].ret, "const char *");
    assert_eq!(
        p[1].args,
        vec![("const rbss_robot *".into(), "h".into(), None)]
    );
}

#[test]
fn the_ctypes_table_is_written_from_the_table() {
    let path = root().join("python/rbss/_abi.py");
    let want = rbss_abi::python_module();
    if std::env::var_os("RBSS_BLESS").is_some() {
        std::fs::write(&path, &want).unwrap();
    }
    let got = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        got == want,
        "{} is stale: `RBSS_BLESS=1 cargo test --release -p rbss-ffi --test abi` rewrites it",
        path.display()
    );
}
