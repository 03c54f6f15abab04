//! The robot registry of the `rbss` command, made at build time from `generated/*/`.
//!
//! Every generated crate `generated/NAME/` (written by `rbss-codegen models/NAME.toml`) holds
//! its kernels in one module file, `generated/NAME/src/NAME.rs`, which needs only
//! `rbss_runtime` and `libm`, and a manifest, `generated/NAME/rbss-manifest.toml`, that names
//! the module, its type and its model file (this script reads only the manifest). This script writes `$OUT_DIR/robots.rs`, included by
//! `src/robots.rs`: one `pub mod NAME` per robot (the module file, by path), the list
//! `NAMES`, and the dispatch macro `with_robot!`. A new robot therefore reaches every
//! `--model` of the command with a rebuild, without an edit to the command's source or
//! manifest.
//!
//! Robots in [`OPTIONAL`] (test and scaling robots the main job does not use, and that cost
//! compile time) are registered only with the cargo feature `all-robots`. Without the default
//! feature `robots` only [`ALWAYS`] is: that is how a `--model-file` library (src/model_file.rs)
//! builds this crate, so that its first build does not compile the other robots' solvers.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Generated robots left out of the default build; the `all-robots` feature adds them.
/// `stewart_2stage` is the scaling robot (48 coordinates, the largest generated crate);
/// `five_bar_turned` is `five_bar` written in turned frames, a test of constant folding;
/// `four_bar_rod`, `gear_pair`, `leg_four_bar`, `slider_crank` and `spatial_crank` test the
/// loop kinds
/// (tests/loop_kinds.rs); `cassie_legs`, a Cassie-like leg pair with thin rods, tests
/// ill-conditioned forward dynamics (tests/cassie_legs.rs).
const OPTIONAL: &[&str] = &[
    "stewart_2stage",
    "five_bar_turned",
    "four_bar_rod",
    "gear_pair",
    "leg_four_bar",
    "slider_crank",
    "spatial_crank",
    "cassie_legs",
];

/// The robot every build registers: `paper`, `stress` and the default trajectory (TraekP) are
/// its. Without the feature `robots` (a `--model-file` library's build of this crate, which
/// runs its one robot through `cli::main_with_model`) it is the only one.
const ALWAYS: &str = "stewart_6ups";

/// One registered robot.
struct Robot {
    /// The robot's name: the crate's directory, its module file and its `--model` name.
    name: String,
    /// The kernels' type (from the manifest).
    type_name: String,
    /// The module file.
    path: PathBuf,
    /// The model file it was generated from (from the manifest).
    model: String,
}

/// The flat `key = value` lines of a generated crate's manifest (`rbss-manifest.toml`, written
/// by `rbss_codegen::generate`): strings unquoted (with `\\` and `\"` undone), other values as
/// written. Comments and blank lines are skipped.
fn manifest(text: &str) -> Vec<(String, String)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| {
            let v = v.trim();
            let v = match v.strip_prefix('"').and_then(|v| v.strip_suffix('"')) {
                Some(inner) => inner.replace("\\\"", "\"").replace("\\\\", "\\"),
                None => v.to_string(),
            };
            (k.trim().to_string(), v)
        })
        .collect()
}

/// The robot in `dir` (`generated/NAME`), from its manifest, or `None` when `dir` is not a
/// generated crate.
fn robot(dir: &Path) -> Result<Option<Robot>, String> {
    let Some(name) = dir.file_name().and_then(|n| n.to_str()) else {
        return Ok(None);
    };
    let manifest_path = dir.join("rbss-manifest.toml");
    let text = match std::fs::read_to_string(&manifest_path) {
        Ok(t) => t,
        // A crate from before the manifest: its module is there, the manifest is not.
        Err(_) if dir.join("src").join(format!("{name}.rs")).is_file() => {
            return Err(format!(
                "{}: missing (a crate written by an older rbss-codegen); regenerate it with \
                 `cargo run --release -p rbss-codegen -- models/{name}.toml`",
                manifest_path.display()
            ));
        }
        Err(_) => return Ok(None),
    };
    let fields = manifest(&text);
    let get = |key: &str| {
        fields
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| format!("{}: no `{key}`", manifest_path.display()))
    };
    let manifest_name = get("name")?;
    if manifest_name != name {
        return Err(format!(
            "{}: the robot is `{manifest_name}` but its directory is `{name}`",
            manifest_path.display()
        ));
    }
    let path = dir.join(get("module")?);
    if !path.is_file() {
        return Err(format!(
            "{}: the module `{}` is missing",
            manifest_path.display(),
            path.display()
        ));
    }
    Ok(Some(Robot {
        name: name.to_string(),
        type_name: get("type")?,
        path,
        model: get("model")?,
    }))
}

fn registry(robots: &[Robot]) -> String {
    let mut s = String::from(
        "// @generated by the build script of `rbss` (build.rs) from generated/*/.\n\n",
    );
    for r in robots {
        let _ = writeln!(
            s,
            "/// The kernels of `{name}`, generated from `{model}` \
             (the module of the crate `generated/{name}`).\n\
             #[allow(clippy::approx_constant)]\n\
             #[rustfmt::skip]\n\
             #[path = {path:?}]\n\
             pub mod {name};\n",
            name = r.name,
            model = r.model,
            path = r.path.display().to_string(),
        );
    }
    let names: Vec<String> = robots.iter().map(|r| format!("{:?}", r.name)).collect();
    let _ = writeln!(
        s,
        "/// Robot names accepted by `--model`: every crate in `generated/` (sorted) that this \
         build registers.\npub const NAMES: &[&str] = &[{}];\n",
        names.join(", ")
    );
    s.push_str(
        "/// Runs `$body` with `$model` bound to a `rbss_runtime::Model` of the named robot\n\
         /// (default parameters); an unknown name is an `Err(String)`. Inside this crate it is\n\
         /// in textual scope after `mod robots`; elsewhere it is `rbss::with_robot!`.\n\
         #[macro_export]\n\
         macro_rules! with_robot {\n\
         \x20   ($name:expr, |$model:ident| $body:expr) => {\n\
         \x20       match $name {\n",
    );
    for r in robots {
        let _ = writeln!(
            s,
            "            {:?} => {{\n\
             \x20               let $model = rbss_runtime::Model::new($crate::robots::{}::{}::default());\n\
             \x20               $body\n\
             \x20           }}",
            r.name, r.name, r.type_name
        );
    }
    s.push_str(
        "            other => Err(format!(\n\
         \x20               \"unknown robot `{other}`; known: {}\",\n\
         \x20               $crate::robots::NAMES.join(\", \")\n\
         \x20           )),\n\
         \x20       }\n\
         \x20   };\n\
         }\n",
    );
    s
}

fn main() {
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let generated = root.join("generated");
    // A new or removed crate changes the directory's mtime; a regenerated module its own.
    println!("cargo:rerun-if-changed=generated");
    let all = std::env::var_os("CARGO_FEATURE_ALL_ROBOTS").is_some();
    // `all-robots` implies `robots` (Cargo.toml).
    let registered = std::env::var_os("CARGO_FEATURE_ROBOTS").is_some();
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&generated)
        .unwrap_or_else(|e| panic!("{}: cannot list: {e}", generated.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let mut robots = Vec::new();
    for dir in &dirs {
        match robot(dir) {
            Ok(Some(r)) => {
                println!("cargo:rerun-if-changed={}", r.path.display());
                println!(
                    "cargo:rerun-if-changed={}",
                    dir.join("rbss-manifest.toml").display()
                );
                let keep = if registered {
                    all || !OPTIONAL.contains(&r.name.as_str())
                } else {
                    r.name == ALWAYS
                };
                if keep {
                    robots.push(r);
                }
            }
            Ok(None) => {}
            Err(e) => panic!("rbss registry: {e}"),
        }
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR")).join("robots.rs");
    std::fs::write(&out, registry(&robots))
        .unwrap_or_else(|e| panic!("{}: cannot write: {e}", out.display()));
}
