//! strand: a fixed-memory, streaming MLS-MPM simulator for 3D concrete printing.

pub use strand_kernels as kernels;
pub use strand_kernels::{Real, M3, V3};

pub mod output;
pub mod verify;
