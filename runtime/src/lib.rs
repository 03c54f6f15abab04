//! rbss-runtime: the kernel trait generated robots implement, and the solvers built on it.

pub mod kernels;
pub mod linalg;
pub use kernels::{IkBlock, Kernels, Structure};
