//! Golden tests of the model-file error messages: every `tests/ui/NAME.toml` must fail to
//! parse, and its rendered report must equal `tests/ui/NAME.stderr` byte for byte; a
//! `tests/ui/warn_NAME.toml` must parse with warnings, rendered the same way.
//!
//! `RBSS_BLESS=1 cargo test --release --test ui` rewrites the `.stderr` files instead.

use std::fs;
use std::path::{Path, PathBuf};

fn cases(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// A line diff (longest common subsequence), `-` expected, `+` actual.
fn diff(expected: &str, actual: &str) -> String {
    let a: Vec<&str> = expected.lines().collect();
    let b: Vec<&str> = actual.lines().collect();
    let mut lcs = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for i in (0..a.len()).rev() {
        for j in (0..b.len()).rev() {
            lcs[i][j] = if a[i] == b[j] {
                lcs[i + 1][j + 1] + 1
            } else {
                lcs[i + 1][j].max(lcs[i][j + 1])
            };
        }
    }
    let (mut i, mut j) = (0, 0);
    let mut out = String::new();
    while i < a.len() || j < b.len() {
        if i < a.len() && j < b.len() && a[i] == b[j] {
            out.push_str(&format!("  {}\n", a[i]));
            i += 1;
            j += 1;
        } else if i < a.len() && (j == b.len() || lcs[i + 1][j] >= lcs[i][j + 1]) {
            out.push_str(&format!("- {}\n", a[i]));
            i += 1;
        } else {
            out.push_str(&format!("+ {}\n", b[j]));
            j += 1;
        }
    }
    if expected.ends_with('\n') != actual.ends_with('\n') {
        out.push_str("(the files differ in their final newline)\n");
    }
    out
}

#[test]
fn ui() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui");
    let bless = std::env::var_os("RBSS_BLESS").is_some_and(|v| v == "1");
    let files = cases(&dir);
    assert!(!files.is_empty(), "no tests/ui/*.toml");
    let mut failures = Vec::new();
    for file in &files {
        let name = file
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("?")
            .to_string();
        let shown = format!("tests/ui/{name}.toml");
        let source =
            fs::read_to_string(file).unwrap_or_else(|e| panic!("cannot read {shown}: {e}"));
        // `warn_*.toml` must parse, with warnings; every other file must fail.
        let warn = name.starts_with("warn_");
        let actual = match rbss_codegen::parse::parse_model_with_warnings(&shown, &source) {
            (Ok(_), w) if warn && !w.items.is_empty() => w.render_warnings(),
            (Ok(_), _) if warn => {
                failures.push(format!("{shown}: parsed without warnings"));
                continue;
            }
            (Ok(_), _) => {
                failures.push(format!(
                    "{shown}: parsed without errors, but a ui test must fail"
                ));
                continue;
            }
            (Err(d), _) => d.render(),
        };
        let golden = file.with_extension("stderr");
        if bless {
            fs::write(&golden, &actual)
                .unwrap_or_else(|e| panic!("cannot write {}: {e}", golden.display()));
            continue;
        }
        match fs::read_to_string(&golden) {
            Ok(expected) if expected == actual => {}
            Ok(expected) => failures.push(format!(
                "tests/ui/{name}.stderr does not match the output (- expected, + actual):\n{}",
                diff(&expected, &actual)
            )),
            Err(_) => failures.push(format!(
                "tests/ui/{name}.stderr is missing; the output is:\n{actual}"
            )),
        }
    }
    // A golden file without its model is stale.
    for entry in fs::read_dir(&dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.extension().is_some_and(|e| e == "stderr") && !p.with_extension("toml").exists() {
            failures.push(format!("{} has no .toml beside it", p.display()));
        }
    }
    if !failures.is_empty() {
        panic!(
            "{} of {} ui tests failed:\n\n{}\n\nrun `RBSS_BLESS=1 cargo test --release --test ui` to accept the new output",
            failures.len(),
            files.len(),
            failures.join("\n\n")
        );
    }
    println!("{} ui tests passed", files.len());
}
