//! Repetition expands to exactly what is written by hand: the paper's 6-UPS written with one
//! leg and `count = 6` (codegen/tests/models/stewart_6ups_repeated.toml) generates the same
//! crate as models/stewart_6ups.toml, byte for byte, except the header's hash of the model text
//! (and the manifest's hashes of the model and the module) and the line numbers that doc
//! comments quote (`models/stewart_6ups.toml:62`).

use std::path::Path;

/// The generated crate's files, each with the model's hash and `PATH:LINE` references blanked;
/// also the number of references blanked.
fn generate(source: &str) -> (Vec<(String, String)>, usize) {
    let path = "models/stewart_6ups.toml";
    let generated =
        rbss_codegen::generate(path, source, &rbss_codegen::Options::default(), &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"));
    let mut refs = 0;
    let files = generated
        .files
        .into_iter()
        .map(|(p, text)| {
            let mut out = String::new();
            for line in text.lines() {
                if line.starts_with("// model: ") {
                    out.push_str("// model: (hash)\n");
                    continue;
                }
                // The manifest's hashes of the two model texts and of the modules (which quote
                // different lines).
                if let Some(key) = ["model_sha256 = ", "module_sha256 = "]
                    .iter()
                    .find(|k| line.starts_with(**k))
                {
                    out.push_str(&format!("{key}(hash)\n"));
                    continue;
                }
                let mut rest = line;
                while let Some(at) = rest.find(&format!("{path}:")) {
                    let after = &rest[at + path.len() + 1..];
                    let digits = after.chars().take_while(char::is_ascii_digit).count();
                    assert!(digits > 0, "`{path}:` without a line number in {line:?}");
                    out.push_str(&rest[..at]);
                    out.push_str(path);
                    out.push_str(":LINE");
                    rest = &after[digits..];
                    refs += 1;
                }
                out.push_str(rest);
                out.push('\n');
            }
            (p.display().to_string(), out)
        })
        .collect();
    (files, refs)
}

#[test]
fn the_6ups_written_with_one_leg_generates_the_same_kernels() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let by_hand = std::fs::read_to_string(root.join("../models/stewart_6ups.toml")).unwrap();
    let repeated =
        std::fs::read_to_string(root.join("tests/models/stewart_6ups_repeated.toml")).unwrap();
    assert!(repeated.contains("[[leg]]") && repeated.contains("count = 6"));
    let (a, refs_a) = generate(&by_hand);
    let (b, refs_b) = generate(&repeated);
    assert_eq!(refs_a, refs_b);
    assert!(
        refs_a >= 21,
        "every parameter's doc quotes its line: {refs_a}"
    );
    assert_eq!(a.len(), b.len());
    for ((pa, ta), (pb, tb)) in a.iter().zip(&b) {
        assert_eq!(pa, pb);
        if ta != tb {
            let line = ta.lines().zip(tb.lines()).position(|(x, y)| x != y);
            let show = |t: &str| {
                line.and_then(|l| t.lines().nth(l))
                    .unwrap_or("(length)")
                    .to_string()
            };
            panic!(
                "{pa} differs at line {:?}:\n  by hand:  {}\n  repeated: {}",
                line.map(|l| l + 1),
                show(ta),
                show(tb)
            );
        }
    }
    // The kernels are most of the module: the comparison is not of an empty file.
    let module = &a
        .iter()
        .find(|(p, _)| p.ends_with("stewart_6ups.rs"))
        .unwrap()
        .1;
    assert!(
        module.contains("pub fn mass_matrix"),
        "no mass matrix kernel"
    );
    assert!(module.lines().count() > 1000);
}
