//! Generated kernels of the robot `spatial_crank`, from `models/spatial_crank.toml`: see [`spatial_crank`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/spatial_crank.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod spatial_crank;
pub use self::spatial_crank::*;
