//! Generated kernels of the robot `planar_3rrr`, from `models/planar_3rrr.toml`: see [`planar_3rrr`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/planar_3rrr.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod planar_3rrr;
pub use self::planar_3rrr::*;
