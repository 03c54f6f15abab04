//! Model paths the generated crate shows (issue 37, finding 9): a path with `"` or `\` makes a
//! valid `Cargo.toml` whose description holds the path as written, and a path with a control
//! character (a newline would end the header comment and make the rest of the path code) is
//! refused with an error that names it, escaped.

use std::path::Path;

fn five_bar() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(root.join("models/five_bar.toml")).unwrap()
}

fn generate(path: &str) -> Result<rbss_codegen::Generated, rbss_codegen::Error> {
    rbss_codegen::generate(
        path,
        &five_bar(),
        &rbss_codegen::Options::default(),
        &mut |_| {},
    )
}

#[test]
fn quotes_and_backslashes_are_escaped_in_cargo_toml() {
    let path = r#"models/my "robot" \ arm/five_bar.toml"#;
    let g = generate(path).unwrap_or_else(|e| panic!("{e}"));
    let cargo = &g
        .files
        .iter()
        .find(|(p, _)| p == Path::new("Cargo.toml"))
        .unwrap()
        .1;
    let doc: toml::Table = toml::from_str(cargo).unwrap_or_else(|e| panic!("{e}\n{cargo}"));
    let description = doc["package"]["description"].as_str().unwrap();
    assert!(description.contains(path), "{description}");
    assert_eq!(doc["package"]["name"].as_str(), Some("five_bar"));
    let manifest = &g
        .files
        .iter()
        .find(|(p, _)| p == Path::new(rbss_codegen::MANIFEST))
        .unwrap()
        .1;
    let m: toml::Table = toml::from_str(manifest).unwrap_or_else(|e| panic!("{e}\n{manifest}"));
    assert_eq!(m["model"].as_str(), Some(path));
}

#[test]
fn control_characters_in_the_path_are_refused() {
    for path in [
        "models/a\nfn evil() {}\n.toml",
        "models/tab\there.toml",
        "m\r.toml",
    ] {
        let e = match generate(path) {
            Ok(_) => panic!("{path:?} was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(
            e.contains("holds the control character") && e.contains(&format!("{path:?}")),
            "{e}"
        );
        // The message itself stays on its lines: the path is shown escaped.
        assert!(!e.contains("fn evil() {}\n"), "{e}");
    }
}
