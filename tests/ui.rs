//! Golden tests of the model-file error messages: every `tests/ui/NAME.toml` must fail to
//! parse, and its rendered report must equal `tests/ui/NAME.stderr` byte for byte; a
//! `tests/ui/warn_NAME.toml` must parse with warnings, rendered the same way.
//!
//! `RBSS_BLESS=1 cargo test --release --test ui` rewrites the `.stderr` files instead.

mod common;

use std::fs;
use std::path::Path;

use common::golden;

#[test]
fn ui() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui");
    let bless = golden::bless();
    let files = golden::cases(&dir);
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
        golden::check("tests/ui", file, &actual, bless, &mut failures);
    }
    golden::orphans(&dir, &mut failures);
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
