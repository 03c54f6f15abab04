//! Generated kernels of the robot `five_bar_turned`, from `models/five_bar_turned.toml`: see [`five_bar_turned`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/five_bar_turned.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod five_bar_turned;
pub use self::five_bar_turned::*;
