//! strand: a fixed-memory, streaming MLS-MPM simulator for 3D concrete printing.

pub use strand_kernels as kernels;
pub use strand_kernels::{Real, M3, V3};

pub mod bench;
pub mod grid;
pub mod materials;
pub mod memory;
pub mod output;
pub mod particles;
pub mod run;
pub mod scenario;
pub mod solver;
pub mod threads;
pub mod verify;
