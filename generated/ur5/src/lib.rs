//! Generated kernels of the robot `ur5`, from `models/ur5.toml`: see [`ur5`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/ur5.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod ur5;
pub use self::ur5::*;
