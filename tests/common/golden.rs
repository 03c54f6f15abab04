//! The golden-file tests' machinery (tests/ui, tests/ui_derive, tests/ui_scene): each
//! `DIR/NAME.toml` is a case whose rendered report must equal `DIR/NAME.stderr` byte for byte;
//! `RBSS_BLESS=1` rewrites the `.stderr` files instead.

use std::fs;
use std::path::{Path, PathBuf};

/// Whether `RBSS_BLESS=1`: write the outputs as the new golden files.
pub fn bless() -> bool {
    std::env::var_os("RBSS_BLESS").is_some_and(|v| v == "1")
}

/// The cases: `dir/*.toml`, sorted.
pub fn cases(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// Compares `actual` with the golden file of `file` (`.stderr` beside it), or writes it when
/// blessing; a mismatch or a missing golden file goes to `failures`, named `{suite}/NAME`.
pub fn check(suite: &str, file: &Path, actual: &str, bless: bool, failures: &mut Vec<String>) {
    let name = file.file_stem().and_then(|s| s.to_str()).unwrap_or("?");
    let golden = file.with_extension("stderr");
    if bless {
        fs::write(&golden, actual)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", golden.display()));
        return;
    }
    match fs::read_to_string(&golden) {
        Ok(expected) if expected == actual => {}
        Ok(expected) => failures.push(format!(
            "{suite}/{name}.stderr does not match the output (- expected, + actual):\n{}",
            diff(&expected, actual)
        )),
        Err(_) => failures.push(format!(
            "{suite}/{name}.stderr is missing; the output is:\n{actual}"
        )),
    }
}

/// A golden file without its case is stale: each goes to `failures`.
pub fn orphans(dir: &Path, failures: &mut Vec<String>) {
    for entry in fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.extension().is_some_and(|e| e == "stderr") && !p.with_extension("toml").exists() {
            failures.push(format!("{} has no .toml beside it", p.display()));
        }
    }
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
