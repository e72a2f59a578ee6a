//! strand: a fixed-memory, streaming MLS-MPM simulator for 3D concrete printing.

// `x as f64` is a no-op in the default f64 build but a real conversion with the `f32` feature.
#![allow(clippy::unnecessary_cast)]
// `!(x > 0.0)` is deliberate: it is true for NaN, which must be rejected too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Loops over the three axes (and over particle index ranges feeding several arrays) read more
// plainly with an index than with zipped iterators.
#![allow(clippy::needless_range_loop)]

pub use strand_kernels as kernels;
pub use strand_kernels::{Real, M3, V3};

pub mod bench;
pub mod buckling;
pub mod checkpoint;
pub mod config;
pub mod disk;
pub mod failure;
pub mod grad;
pub mod grid;
pub mod invalid;
pub mod key;
pub mod materials;
pub mod measure;
pub mod memory;
pub mod observe;
pub mod observables;
pub mod output;
pub mod particles;
pub mod plan;
pub mod pools;
pub mod print;
pub mod run;
pub mod scenario;
pub mod solver;
// solid bodies (issue 30)
pub mod solid;
pub mod threads;
pub mod writer;
pub mod verify;
pub mod sleep;
pub mod report;
