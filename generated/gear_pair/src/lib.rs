//! Generated kernels of the robot `gear_pair`, from `models/gear_pair.toml`: see [`gear_pair`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/gear_pair.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod gear_pair;
pub use self::gear_pair::*;
