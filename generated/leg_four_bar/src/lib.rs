//! Generated kernels of the robot `leg_four_bar`, from `models/leg_four_bar.toml`: see [`leg_four_bar`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/leg_four_bar.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod leg_four_bar;
pub use self::leg_four_bar::*;
