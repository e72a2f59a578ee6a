//! Pure compute kernels of strand: everything here is a function over slices and small values,
//! with no I/O, no globals and no allocation, so the solver can call it from any thread and the
//! adjoints can be checked in isolation.

// The tests' hand-computed values are written to f64 precision; under `--features f32` they
// round, which is what those tests' tolerances allow for.
#![cfg_attr(all(test, feature = "f32"), allow(clippy::excessive_precision))]

pub mod real;
pub mod bspline;
pub mod cpu;
pub mod material;
pub mod transfer;
#[cfg(target_arch = "x86_64")]
mod wide;
#[cfg(target_arch = "x86_64")]
mod transfer_lanes;
#[cfg(target_arch = "x86_64")]
mod p2g_lanes;
pub mod transfer_adjoint;
#[cfg(target_arch = "x86_64")]
mod transfer_adjoint_lanes;
pub mod boundary;

pub use real::{Real, M3, V3};
pub mod nozzle;
pub mod solid;
#[cfg(all(test, not(feature = "f32")))]
pub(crate) mod adjoint_check;
