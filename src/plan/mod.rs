//! From a calibrated mix to print settings (`strand plan`).
//!
//! In: a model (as `strand calibrate` writes it), a print (a scenario with an inline `[print]`
//! path) and targets (`targets.rs`): the layer's width and height at a station with their
//! tolerances, a design height the wall must stand to with a safety factor, and bounds on the
//! speed, the extrusion speed, the standoff and the layer time.
//! Out: the settings of the fastest build that meets every target ([`Plan`]), found by bounded
//! gradient projection on the adjoint gradients of `strand grad` (`optimise.rs`), with the
//! predicted layer, the wall's buildable height and failure mode by the closed forms
//! (`constraint.rs`, `build.rs`), the margins and the sensitivity of each target to each
//! setting (`report.rs`, and as an HTML page with the map: `report_html.rs`); or an error naming
//! the target that cannot be met and how close the best setting came. `map.rs` runs the print
//! over a grid of two settings or their groups V/U and H/D (`map_axes.rs`): the printability map. `toolpath_file.rs` writes a G-code or point-list print inline for the plan, and the
//! file again with the planned settings. `grid_search.rs` checks a plan against a brute-force
//! grid of its settings; `wall_check.rs` simulates a reduced wall of the planned layer with the
//! failure detector, and `wall_rounds.rs` drives the plan's layer time by it, calibrating the
//! closed form's collapse factor round after round until a simulated wall stands.
//!
//! Imports point one way: `error.rs` and `targets.rs` at the bottom; the print (`line.rs`) and
//! the wall (`constraint.rs`); the build (`build.rs`); the search (`optimise.rs`); the plan
//! (`planner.rs`); then the report and the map. plan sits above grad/, measure/, print/ and run/; none of them
//! imports it.

pub mod build;
pub mod constraint;
pub mod error;
pub mod grid_search;
pub mod line;
pub mod map;
pub mod map_axes;
pub mod optimise;
pub mod planner;
pub mod report;
pub mod report_html;
pub mod targets;
pub mod toolpath_file;
pub mod wall_check;
pub mod wall_rounds;

pub use planner::{plan, Plan, PlanOptions};
