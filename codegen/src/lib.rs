//! rbss-codegen: turns a robot model file into a specialised Rust crate of kinematics and
//! dynamics kernels. See the workspace README and `../shared/design.md`.

pub mod diagnostics;
pub mod model;
pub mod parse;
