//! rbss-codegen: turns a robot model file into a specialised Rust crate of kinematics and
//! dynamics kernels. See the workspace README and `../shared/design.md`.
//!
//! Pipeline: [`parse`] (model file -> [`model::Model`], every error at once) -> [`derive`](mod@derive)
//! (frames, `f`, `G`, `gamma`, `M`, `psi` as named intermediates in one [`graph::Graph`]) ->
//! the checks at the home ([`assemble`], [`rank`]) -> the back end ([`backend`]: one file per
//! emitted item, over [`emit`] (graph -> Rust tokens) and [`solve`]) -> [`generate`](mod@generate)
//! (prettyplease, the crate's files). Beside the kernels, [`solve`] writes the robot's solves
//! (forward and inverse dynamics, the inverse-kinematics blocks, forward kinematics'
//! elimination) over the structure it knows (the inverse-kinematics blocks, the structural
//! non-zeros of `G` and `M`): numeric code on a tape that folds zeros and numbers, one function
//! per kind of block. What a crate offers (its kernels and solves, in emission order, behind
//! which runtime trait methods, for which task of a scene) is one table, [`catalog`].
//!
//! The modules form layers; a module imports only from its own layer or lower ones, without
//! cycles (`tests/layers.rs` holds it):
//!
//! ```text
//! drivers            generate  write  build  main
//!                        |
//! back end           backend/ (params, structure, kernels, solves, impls, crate_files)
//!                    emit  solve
//!                        |
//! checks at the home assemble  rank
//!                        |
//! derivation         derive/  expanded
//!                        |
//! front ends         parse/  import/  scene
//!                        |
//! expression graph   graph  simplify
//!                        |
//! shared types       diagnostics (Pos)  model (SourceFile)  source (read_source, line/column)
//!                    catalog  lock
//! ```
//!
//! `expanded` is the same derivation done the other way, fully expanded with symbolica: the
//! independent reference the tests compare the kernels with. Only it touches symbolica, and
//! only while `lock::SymbolicaLock` is held. Both are behind the cargo feature `symbolica`
//! (off by default, on for this crate's tests): generation, the command and the build-script
//! API ([`build`]) never compile symbolica.
//!
//! From a build script, in the manner of prost-build:
//! ```no_run
//! // build.rs
//! let out = std::path::PathBuf::from(std::env::var("OUT_DIR").unwrap());
//! rbss_codegen::build::compile("models/my_robot.toml", &out).unwrap_or_else(|e| {
//!     eprintln!("{e}");
//!     std::process::exit(1)
//! });
//! ```

pub mod assemble;
pub mod backend;
pub mod build;
pub mod catalog;
pub mod derive;
pub mod diagnostics;
pub mod emit;
#[cfg(feature = "symbolica")]
pub mod expanded;
pub mod generate;
pub mod graph;
pub mod import;
#[cfg(feature = "symbolica")]
pub mod lock;
pub mod model;
pub mod parse;
pub mod rank;
pub mod scene;
pub mod simplify;
pub mod solve;
pub mod source;
pub mod write;

pub use generate::{
    Error, Generated, MANIFEST, Options, Report, generate, generate_scene, generate_with_runtime,
    stale_files,
};
pub use write::write_crate;
