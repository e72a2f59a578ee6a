//! Writers for simulation output.
pub mod plot;
pub mod vtu;
