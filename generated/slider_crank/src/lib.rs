//! Generated kernels of the robot `slider_crank`, from `models/slider_crank.toml`: see [`slider_crank`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/slider_crank.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod slider_crank;
pub use self::slider_crank::*;
