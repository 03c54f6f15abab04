//! The generated robots this build knows: one module per crate in `generated/` (its kernels'
//! module file, compiled into this crate), the names accepted by `--model` ([`NAMES`]), and
//! `with_robot!`, which runs code with a `rbss_runtime::Model` of a robot named at run time.
//!
//! The registry is written by the build script (`build.rs`) from `generated/*/`: after
//! `cargo run --release -p rbss-codegen -- models/NAME.toml`, a rebuild of `rbss` knows NAME.
//! The scaling and test robots (`stewart_2stage`, `five_bar_turned`, the loop kinds' robots)
//! are registered only with the cargo feature `all-robots`; without the default feature
//! `robots` (a `--model-file` library's build) only `stewart_6ups` is.

include!(concat!(env!("OUT_DIR"), "/robots.rs"));
