//! Reverse-mode gradients: dJ/dtheta of an objective J of the final state with respect to
//! scenario parameters theta, through every step, by the discrete adjoint of the step
//! (`step_adjoint.rs`) run under a checkpoint schedule (`schedule/`) within byte caps for RAM and
//! disk (`store.rs`), driven by `driver.rs` and checked by `check.rs`.

pub mod check;
pub mod driver;
mod error;
mod fields;
pub mod params;
mod print_adjoint;
pub mod schedule;
mod step_adjoint;
mod store;

pub use driver::{gradient, GradOptions, GradResult};
pub use error::GradError;
