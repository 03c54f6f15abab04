//! Golden tests of the model-file errors found while deriving, not by the parser:
//! every `tests/ui_derive/NAME.toml` parses, but `rbss_codegen::generate` must reject it, and
//! its rendered report must equal `tests/ui_derive/NAME.stderr` byte for byte (e.g. a loop
//! component that is identically zero or depends on no coordinate: a loop that cannot close; a
//! home configuration that does not assemble; a mass matrix that is singular at the home).
//!
//! `RBSS_BLESS=1 cargo test --release --test ui_derive` rewrites the `.stderr` files instead.

mod common;

use std::fs;
use std::path::Path;

use common::golden;

#[test]
fn ui_derive() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui_derive");
    let bless = golden::bless();
    let files = golden::cases(&dir);
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
        golden::check("tests/ui_derive", file, &actual, bless, &mut failures);
    }
    golden::orphans(&dir, &mut failures);
    assert!(
        failures.is_empty(),
        "{}\n\nrun `RBSS_BLESS=1 cargo test --release --test ui_derive` to accept the new output",
        failures.join("\n\n")
    );
}
