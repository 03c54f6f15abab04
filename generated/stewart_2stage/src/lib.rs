//! Generated kernels of the robot `stewart_2stage`, from `models/stewart_2stage.toml`: see [`stewart_2stage`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/stewart_2stage.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod stewart_2stage;
pub use self::stewart_2stage::*;
