//! The measurement loop: measurements (`observation.rs`), what can be observed
//! (`observables.rs`; the flow front's history in `front.rs`, the mass passed below a plane in
//! `passing.rs`) and the experiments that produced them (`experiments.rs`), a model and its
//! effects (`model.rs`, `effects/`), a virtual rheometer (`rheometer.rs`), running experiments
//! under a model (`runner.rs`), comparing with measurements (`compare.rs`) or synthesising them
//! (`synth.rs`), the comparison as a folder of plots and trends (`report.rs`) and the shapes of
//! its residuals (`residuals.rs`), the discretisation error counted beside the measurement
//! uncertainty (`resolution.rs`), gradients (`sensitivity.rs`; idle workers lent to the
//! experiments still running, `spare.rs`), fitting a model (`calibrate.rs`) and finding the
//! effect it lacks (`diagnose.rs`); where the experiments run (`engine.rs`: here, or as a
//! scheduler's jobs) and what a saved result was computed from (`provenance.rs`); a long command's
//! progress (`progress.rs`); why a step cannot be taken (`error.rs`).
//!
//! Imports point one way (no circle among these files, `tests/suite/architecture.rs`): `error.rs` and
//! `observation.rs` at the bottom; then the observables, the effects and the model; the experiments; the runner;
//! comparison and synthesis; reports and residual shapes; and sensitivity, calibration, the
//! engine, diagnosis and rounds on top.

pub mod calibrate;
pub mod campaign;
pub mod chain;
pub mod compare;
pub mod diagnose;
pub mod effects;
pub mod engine;
pub mod error;
pub mod experiments;
pub mod expression;
pub mod front;
pub mod linalg;
pub mod model;
pub mod observables;
pub mod observation;
pub mod passing;
pub mod plan;
pub mod preflight;
pub mod progress;
pub mod provenance;
pub mod report;
pub mod residuals;
pub mod resolution;
pub mod rheometer;
pub mod rounds;
pub mod runner;
pub mod sensitivity;
pub mod spare;
pub mod synth;
