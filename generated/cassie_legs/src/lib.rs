//! Generated kernels of the robot `cassie_legs`, from `models/cassie_legs.toml`: see [`cassie_legs`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/cassie_legs.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod cassie_legs;
pub use self::cassie_legs::*;
