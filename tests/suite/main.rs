//! The integration tests, one module per area, in one binary: one link instead of one per file
//! (`cargo test --release --test suite -- AREA::`). `tests/alloc.rs` stays apart: it installs its own
//! global allocator.

mod architecture;
mod buckling;
mod cli;
mod common;
mod diagnose;
mod engine;
mod fixed_memory;
mod grad;
mod measure;
mod measure_inputs;
mod measure_report;
mod plan;
mod print;
mod print_arcs;
mod print_dialects;
mod print_laid;
mod print_campaign;
mod resolution;
mod resume;
mod robustness;
mod shear_thinning;
mod solids;
mod solver_core;
mod state_hashes;
mod verify_quick;
