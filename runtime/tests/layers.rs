//! The runtime's modules form layers without import cycles (the layout in the crate docs):
//! the imports of runtime/src/**.rs, as the checker in `layering/` reads them, go only to the
//! same or a lower layer of [`LAYERS`], with no cycle among the modules.

mod layering;

use std::fs;
use std::path::Path;

use layering::{graph_of, violations};

/// The layers, lowest first: a module (by its first path segment) may import modules of its
/// own layer or of lower ones.
const LAYERS: layering::Layers<'static> = &[
    ("dense linear algebra and errors", &["linalg", "error"]),
    (
        "the kernel traits and the robot's structure",
        &["kernels", "tasks"],
    ),
    ("the solve plan", &["plan"]),
    ("the factorizations", &["factor"]),
    ("the model", &["model"]),
    ("the data", &["data"]),
    ("the algorithms", &["algorithm"]),
    ("the integrators", &["integrate"]),
];

#[test]
fn runtime_modules_are_layered_without_cycles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let graph = graph_of(&src);
    assert!(graph.len() > 10, "found only {} modules", graph.len());
    let bad = violations(&graph, LAYERS, "runtime/tests/layers.rs");
    assert!(bad.is_empty(), "{}", bad.join("\n\n"));
}

/// The checker itself: on a small tree with a cycle, an import upwards and one through the
/// root, each is named with its line.
#[test]
fn checker_finds_cycles_and_upward_imports() {
    let dir = std::env::temp_dir().join(format!("rbss-layers-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(dir.join("algorithm")).unwrap();
    let files = [
        (
            "lib.rs",
            "pub mod algorithm;\npub mod data;\npub mod linalg;\npub mod integrate;\n",
        ),
        (
            "linalg.rs",
            "// use crate::integrate::X; (a comment)\nuse crate::data::Buf;\n",
        ),
        (
            "data.rs",
            "use crate::{linalg::{self, dot}, algorithm::reduced::F};\n",
        ),
        ("integrate.rs", "use crate::algorithm::run;\n"),
        (
            "algorithm/mod.rs",
            "mod reduced;\npub use reduced::F;\nfn f() { let _ = \"crate::integrate\"; }\n",
        ),
        (
            "algorithm/reduced.rs",
            "use super::helper;\nfn g() { crate::forward_dynamics(); }\n",
        ),
    ];
    for (name, text) in files {
        fs::write(dir.join(name), text).unwrap();
    }
    let graph = graph_of(&dir);
    let bad = violations(&graph, LAYERS, "runtime/tests/layers.rs").join("\n");
    let _ = fs::remove_dir_all(&dir);
    assert!(
        bad.contains("`linalg` (dense linear algebra and errors) imports `data` (the data)"),
        "{bad}"
    );
    assert!(bad.contains("linalg.rs:2: use crate::data::Buf;"), "{bad}");
    assert!(!bad.contains("(a comment)"), "{bad}");
    assert!(
        bad.contains("`data` (the data) imports `algorithm::reduced`"),
        "{bad}"
    );
    assert!(
        bad.contains("import cycle among algorithm, algorithm::reduced"),
        "{bad}"
    );
    assert!(
        bad.contains("algorithm/reduced.rs:1: use super::helper;"),
        "{bad}"
    );
    assert!(
        bad.contains("`algorithm::reduced` imports through the crate root"),
        "{bad}"
    );
    assert!(!bad.contains("`algorithm` imports `integrate`"), "{bad}");
    assert!(
        !bad.contains("`integrate` (the integrators) imports"),
        "{bad}"
    );
}
