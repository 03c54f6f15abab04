//! Generated kernels of the robot `stewart_6ups`, from `models/stewart_6ups.toml`: see [`stewart_6ups`](self) below.
//! Regenerate with `cargo run --release -p rbss-codegen -- models/stewart_6ups.toml`.
#![no_std]

#[rustfmt::skip]
mod stewart_6ups;
pub use stewart_6ups::*;
