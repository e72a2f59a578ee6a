//! The measurement loop, in the order data flow through it:
//!
//! - the measurements (`observation.rs`), what can be observed (`observables.rs`; the flow
//!   front's history in `front.rs`, the mass passed below a plane in `passing.rs`);
//! - a model: the `[material]` and the effects switched on (`model.rs`, `effects/`, the
//!   expressions of declared effects in `expression.rs`);
//! - a campaign (`campaign/`): the experiments and their data, run under a model, here or as a
//!   scheduler's jobs, with values, gradients and the discretisation error;
//! - the model against the data (`compare/`): residuals, the report folder, synthetic data;
//! - a fit of the model's parameters (`fit/`), and the effect the model lacks (`diagnose/`);
//! - why a step cannot be taken (`error.rs`).
//!
//! Each folder's module doc says what enters it and what leaves. Imports point one way (no circle
//! among these files, `tests/suite/architecture.rs`): `error.rs` and `observation.rs` at the
//! bottom; the observables, the effects and the model; the campaign; comparison; the fit; and
//! diagnosis on top. The modules most callers name are also found at `measure::NAME` (below),
//! the paths the rest of the crate and the tests use; files of the loop name each other by
//! their place.

pub mod campaign;
pub mod compare;
pub mod diagnose;
pub mod effects;
pub mod error;
pub mod expression;
pub mod fit;
pub mod front;
pub mod model;
pub mod observables;
pub mod observation;
pub mod passing;

pub use campaign::{
    engine, experiments, preflight, progress, provenance, resolution, rheometer, runner, sensitivity, spare,
};
pub use compare::{plan, report, synth};
pub use diagnose::{chain, residuals, rounds};
pub use fit::{calibrate, linalg};
