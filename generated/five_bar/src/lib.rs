//! Generated kernels of the robot `five_bar`, from `models/five_bar.toml`: see [`five_bar`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/five_bar.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod five_bar;
pub use self::five_bar::*;
