//! Writes `$OUT_DIR/robot.rs`: `include!` of the file `$RBSS_ROBOT_LIB` names (written by
//! `rbss --model-file` into its cache entry: the generated robot's module by an absolute path,
//! `rbss_ffi::export!` and `rbss::export_command!`), or nothing without it (a workspace build).

fn main() {
    println!("cargo:rerun-if-env-changed=RBSS_ROBOT_LIB");
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR"));
    let text = match std::env::var("RBSS_ROBOT_LIB") {
        // `{:?}`: a Rust string literal of the path.
        Ok(p) if !p.is_empty() => format!("include!({p:?});\n"),
        _ => String::new(),
    };
    std::fs::write(out.join("robot.rs"), text).expect("cannot write $OUT_DIR/robot.rs");
}
