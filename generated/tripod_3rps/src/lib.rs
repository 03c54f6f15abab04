//! Generated kernels of the robot `tripod_3rps`, from `models/tripod_3rps.toml`: see [`tripod_3rps`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/tripod_3rps.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod tripod_3rps;
pub use self::tripod_3rps::*;
