//! Generated kernels of the robot `spring_pendulum`, from `models/spring_pendulum.toml`: see [`spring_pendulum`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/spring_pendulum.toml`.
#![no_std]

// Parameter defaults are exact values such as 45 degrees in rad, not approximations.
#[allow(clippy::approx_constant)]
#[rustfmt::skip]
mod spring_pendulum;
pub use self::spring_pendulum::*;
