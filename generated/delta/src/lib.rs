//! Generated kernels of the robot `delta`, from `models/delta.toml`: see [`delta`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/delta.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod delta;
pub use self::delta::*;
