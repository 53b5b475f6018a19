//! The per-element kernels of texsense, one implementation for the desktop (`f64`, in
//! `texsense-core`, which runs them over blocks of elements on all cores) and for a mat's own
//! microcontroller (`f32`, in `texsense-mcu`, behind a C ABI).
//!
//! `no_std`, no allocation: every state lives in memory the caller owns, with a fixed size
//! per element (docs/embedded.md), and every kernel is generic over the float type
//! ([`Real`]: `f32` or `f64`). It builds with Rust 1.63 (Debian's rustc, the Cortex-M
//! build) as well as the workspace's toolchain.
//!
//! - [`convert`]: capacitance -> compression per element (thesis eq. 2.1) through the
//!   material curve;
//! - [`everett`] and [`preisach`]: the numerical Preisach model (eq. 4.12, 4.15-4.22) with a
//!   bounded memory of turning points;
//! - [`drift`]: eq. 5.8 in its recursive form (rest clock, second clock, level power);
//! - [`detect`]: failure detection on raw capacitance (§6.5.2.5);
//! - [`repair`]: the local repairs of failed readings (eq. 6.14 and others);
//! - [`stage`]: the element-wise stages with the validity rules of a chain;
//! - [`blob`]: the versioned, checksummed model blob a microcontroller runs.

#![no_std]
#![deny(missing_docs, unsafe_op_in_unsafe_fn)]

#[cfg(test)]
extern crate std;

pub mod blob;
pub mod convert;
pub mod detect;
pub mod drift;
pub mod error;
pub mod everett;
pub mod graph;
pub mod preisach;
pub mod real;
pub mod repair;
pub mod stage;

pub use error::KernelError;
pub use real::Real;
