//! Writers for simulation output.
pub mod contour;
pub mod contour_plot;
pub mod html;
pub mod plot;
pub mod vtu;
