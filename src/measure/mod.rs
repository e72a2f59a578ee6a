//! The measurement loop: measurements and the experiments that produced them
//! (`data.rs`), a model and its effects (`model.rs`, `effects/`), a virtual rheometer
//! (`rheometer.rs`), running experiments under a model to compare with measurements or to
//! synthesise them (`compare.rs`) and the comparison as a folder of plots and trends
//! (`report.rs`), observables of the flow front's history (`front.rs`), the discretisation error counted beside the measurement uncertainty
//! (`resolution.rs`), their gradients (`sensitivity.rs`), fitting a model (`calibrate.rs`) and
//! finding the effect it lacks (`diagnose.rs`); where the experiments run (`engine.rs`: here, or
//! as a scheduler's jobs) and what a saved result was computed from (`provenance.rs`).

pub mod calibrate;
pub mod compare;
pub mod data;
pub mod diagnose;
pub mod effects;
pub mod engine;
pub mod expression;
pub mod front;
pub mod linalg;
pub mod model;
pub mod plan;
pub mod provenance;
pub mod report;
pub mod residuals;
pub mod resolution;
pub mod rheometer;
pub mod rounds;
pub mod sensitivity;
