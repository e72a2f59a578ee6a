//! The measurement loop (issue 6): measurements and the experiments that produced them
//! (`data.rs`), a model and its effects (`model.rs`, `effects/`), a virtual rheometer
//! (`rheometer.rs`), running experiments under a model to compare with measurements or to
//! synthesise them (`compare.rs`) and the comparison as a folder of plots and trends
//! (`report.rs`), the discretisation error counted beside the measurement uncertainty
//! (`resolution.rs`), their gradients (`sensitivity.rs`), fitting a model
//! (`calibrate.rs`) and finding the effect it lacks (`diagnose.rs`).

pub mod calibrate;
pub mod compare;
pub mod data;
pub mod diagnose;
pub mod effects;
pub mod linalg;
pub mod model;
pub mod plan;
pub mod report;
pub mod resolution;
pub mod rheometer;
pub mod sensitivity;
