//! Golden tests of the scene-file errors: every `tests/ui_scene/NAME.toml` is a scene that
//! `rbss-codegen --scene` must reject (in the scene itself, or checked against its model), and
//! its rendered report must equal `tests/ui_scene/NAME.stderr` byte for byte.
//!
//! `RBSS_BLESS=1 cargo test --release --test ui_scene` rewrites the `.stderr` files instead.

use std::fs;
use std::path::{Path, PathBuf};

use rbss_codegen::scene;

#[test]
fn ui_scene() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/ui_scene");
    let bless = std::env::var_os("RBSS_BLESS").is_some_and(|v| v == "1");
    let mut files: Vec<PathBuf> = fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
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
        let golden = file.with_extension("stderr");
        if bless {
            fs::write(&golden, &actual).unwrap();
            continue;
        }
        match fs::read_to_string(&golden) {
            Ok(expected) if expected == actual => {}
            Ok(expected) => failures.push(format!(
                "tests/ui_scene/{name}.stderr does not match; expected:\n{expected}\nactual:\n{actual}"
            )),
            Err(_) => failures.push(format!(
                "tests/ui_scene/{name}.stderr is missing; the output is:\n{actual}"
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
        "{} of {} scene ui tests failed:\n\n{}\n\nrun `RBSS_BLESS=1 cargo test --release --test ui_scene` to accept the new output",
        failures.len(),
        files.len(),
        failures.join("\n\n")
    );
}
