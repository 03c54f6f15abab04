//! Generated kernels of the robot `stewart_6ups`, from `models/stewart_6ups.toml`: see [`stewart_6ups`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/stewart_6ups.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod stewart_6ups;
pub use self::stewart_6ups::*;
