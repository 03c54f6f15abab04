//! The generator's modules form layers without import cycles (the layout drawn in the crate
//! docs, codegen/src/lib.rs): the imports of codegen/src/**.rs, as the runtime's checker
//! (`runtime/tests/layering/`) reads them, go only to the same or a lower layer of [`LAYERS`],
//! with no cycle among the modules. The imports are
//! those between top-level modules (`layering::top_level`): a module directory (`derive/`,
//! `solve/`, ...) keeps its `mod.rs` helpers that its children name by `super::`.

#[path = "../../runtime/tests/layering/mod.rs"]
mod layering;

use std::path::Path;

use layering::{graph_of, top_level, violations};

/// The layers, lowest first: a module (by its first path segment) may import modules of its
/// own layer or of lower ones.
const LAYERS: layering::Layers<'static> = &[
    (
        "shared types: positions and errors, the model, source files, the catalogue",
        &["diagnostics", "model", "source", "catalog", "lock"],
    ),
    ("the expression graph", &["graph", "simplify"]),
    ("the front ends", &["parse", "import", "scene"]),
    ("the derivation", &["derive", "expanded"]),
    ("the checks at the home", &["assemble", "rank"]),
    ("the back end", &["emit", "solve", "backend"]),
    ("the drivers", &["generate", "write", "build", "main"]),
];

#[test]
fn codegen_modules_are_layered_without_cycles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let graph = graph_of(&src);
    assert!(graph.len() > 30, "found only {} modules", graph.len());
    let bad = violations(&top_level(&graph), LAYERS, "codegen/tests/layers.rs");
    assert!(bad.is_empty(), "{}", bad.join("\n\n"));
}
