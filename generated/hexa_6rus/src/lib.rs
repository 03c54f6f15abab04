//! Generated kernels of the robot `hexa_6rus`, from `models/hexa_6rus.toml`: see [`hexa_6rus`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/hexa_6rus.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod hexa_6rus;
pub use self::hexa_6rus::*;
