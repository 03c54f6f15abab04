//! The `rbss` command's modules form layers without import cycles: the imports of
//! src/**.rs, as the runtime's checker (`runtime/tests/layering/`) reads them, go only to the
//! same or a lower layer of [`LAYERS`], with no cycle among the modules. The imports are
//! those between top-level modules (`layering::top_level`): a module directory (`derive/`,
//! `solve/`, ...) keeps its `mod.rs` helpers that its children name by `super::`. The crate root
//! (lib.rs: the output helpers and the `outln!` macros) is the lowest layer.

#[path = "../runtime/tests/layering/mod.rs"]
mod layering;

use std::path::Path;

use layering::{graph_of, top_level, violations};

/// The layers, lowest first: a module (by its first path segment) may import modules of its
/// own layer or of lower ones.
const LAYERS: layering::Layers<'static> = &[
    ("the crate root's helpers and macros (lib.rs)", &[""]),
    (
        "output files, plots, the robots and the robot option",
        &[
            "output",
            "csv",
            "describe",
            "plot",
            "robots",
            "robot_arg",
            "kinematics",
        ],
    ),
    ("trajectories", &["trajectory"]),
    ("the paper's study", &["paper"]),
    (
        "the subcommands and the robot libraries",
        &[
            "inverse_dynamics",
            "roundtrip",
            "simulate",
            "solver_table",
            "stress",
            "bench",
            "model_file",
        ],
    ),
    ("the argument parser and dispatch", &["cli"]),
    ("the entry points", &["entry", "main"]),
];

#[test]
fn command_modules_are_layered_without_cycles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let graph = graph_of(&src);
    assert!(graph.len() > 15, "found only {} modules", graph.len());
    let bad = violations(&top_level(&graph), LAYERS, "tests/layers.rs");
    assert!(bad.is_empty(), "{}", bad.join("\n\n"));
}
