//! Writers for simulation output.
pub mod vtu;
