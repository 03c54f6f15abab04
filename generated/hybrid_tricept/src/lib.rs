//! Generated kernels of the robot `hybrid_tricept`, from `models/hybrid_tricept.toml`: see [`hybrid_tricept`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/hybrid_tricept.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod hybrid_tricept;
pub use self::hybrid_tricept::*;
