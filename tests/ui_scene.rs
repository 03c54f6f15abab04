//! Golden tests of the scene-file errors: every `tests/ui_scene/NAME.toml` is a scene that
//! `rbss-codegen --scene` must reject (in the scene itself, or checked against its model), and
//! its rendered report must equal `tests/ui_scene/NAME.stderr` byte for byte.
//!
//! `RBSS_BLESS=1 cargo test --release --test ui_scene` rewrites the `.stderr` files instead.

mod common;

use std::fs;
use std::path::Path;

use common::golden;

use rbss_codegen::scene;

#[test]
fn ui_scene() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui_scene");
    let bless = golden::bless();
    let files = golden::cases(&dir);
    assert!(
        files.len() >= 8,
        "tests/ui_scene/*.toml: {} cases",
        files.len()
    );
    let mut failures = Vec::new();
    for file in &files {
        let name = file.file_stem().unwrap().to_string_lossy().into_owned();
        let shown = format!("tests/ui_scene/{name}.toml");
        let source = fs::read_to_string(file).unwrap();
        // Paths in the scene are relative to the scene file; resolve from the package root.
        let parsed = scene::parse_scene_in(&shown, &source, root.join("tests/ui_scene"));
        let actual = match parsed {
            Err(d) => d.render(),
            Ok(s) => match rbss_codegen::generate_scene(&s, "rbss-runtime", &mut |_| {}) {
                Ok(_) => {
                    failures.push(format!(
                        "{shown}: generated without errors, but a ui test must fail"
                    ));
                    continue;
                }
                // The model's absolute path (in "cannot read" errors) is shown from the root.
                Err(e) => e.to_string().replace(&format!("{}/", root.display()), ""),
            },
        };
        golden::check("tests/ui_scene", file, &actual, bless, &mut failures);
    }
    golden::orphans(&dir, &mut failures);
    assert!(
        failures.is_empty(),
        "{} of {} scene ui tests failed:\n\n{}\n\nrun `RBSS_BLESS=1 cargo test --release --test ui_scene` to accept the new output",
        failures.len(),
        files.len(),
        failures.join("\n\n")
    );
}
