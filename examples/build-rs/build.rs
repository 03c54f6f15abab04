//! Generates the five-bar's kernels from its model file into `OUT_DIR/five_bar.rs` (and tells
//! cargo to rerun when the model file changes).

fn main() {
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("OUT_DIR"));
    // Relative to this package's directory (where cargo runs build scripts).
    rbss_codegen::build::compile("../../models/five_bar.toml", &out).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
}
