//! Generated kernels of the robot `four_bar_rod`, from `models/four_bar_rod.toml`: see [`four_bar_rod`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/four_bar_rod.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod four_bar_rod;
pub use self::four_bar_rod::*;
