//! Golden tests of the model-file errors found while deriving, not by the parser:
//! every `tests/ui_derive/NAME.toml` parses, but `rbss_codegen::generate` must reject it, and
//! its rendered report must equal `tests/ui_derive/NAME.stderr` byte for byte (e.g. a loop
//! component that is identically zero or depends on no coordinate: a loop that cannot close; a
//! home configuration that does not assemble; a mass matrix that is singular at the home).
//!
//! `RBSS_BLESS=1 cargo test --release --test ui_derive` rewrites the `.stderr` files instead.

use std::fs;
use std::path::{Path, PathBuf};

#[test]
fn ui_derive() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui_derive");
    let bless = std::env::var_os("RBSS_BLESS").is_some_and(|v| v == "1");
    let mut files: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no tests/ui_derive/*.toml");
    // With dynamics: `M` is checked at the assembled home.
    let opts = rbss_codegen::Options::default();
    let mut failures = Vec::new();
    for file in &files {
        let name = file.file_stem().unwrap().to_string_lossy().into_owned();
        let shown = format!("tests/ui_derive/{name}.toml");
        let source = fs::read_to_string(file).unwrap();
        if let Err(d) = rbss_codegen::parse::parse_model(&shown, &source) {
            failures.push(format!(
                "{shown}: must parse (parser errors belong in tests/ui), but:\n{d}"
            ));
            continue;
        }
        let actual = match rbss_codegen::generate(&shown, &source, &opts, &mut |_| {}) {
            Ok(_) => {
                failures.push(format!("{shown}: generated without errors"));
                continue;
            }
            Err(e @ rbss_codegen::Error::Model(_)) => e.to_string(),
            Err(e) => panic!("{shown}: not a model error: {e}"),
        };
        let golden = file.with_extension("stderr");
        if bless {
            fs::write(&golden, &actual).unwrap();
            continue;
        }
        match fs::read_to_string(&golden) {
            Ok(expected) if expected == actual => {}
            Ok(expected) => failures.push(format!(
                "tests/ui_derive/{name}.stderr differs:\n--- expected\n{expected}--- actual\n{actual}"
            )),
            Err(_) => failures.push(format!(
                "tests/ui_derive/{name}.stderr is missing; the output is:\n{actual}"
            )),
        }
    }
    for entry in fs::read_dir(&dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.extension().is_some_and(|e| e == "stderr") && !p.with_extension("toml").exists() {
            failures.push(format!("{} has no .toml beside it", p.display()));
        }
    }
    assert!(
        failures.is_empty(),
        "{}\n\nrun `RBSS_BLESS=1 cargo test --release --test ui_derive` to accept the new output",
        failures.join("\n\n")
    );
}
