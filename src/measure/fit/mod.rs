//! Fitting a model's parameters to a campaign's data: the bounded Levenberg-Marquardt fit
//! (`calibrate.rs`) on the small dense algebra it needs (`linalg.rs`).
//!
//! In: a campaign, a model and the names of the parameters to fit. Out: a [`Fit`](calibrate::Fit):
//! the fitted values, their uncertainties, chi^2 and the fitted model.

pub mod calibrate;
pub mod linalg;
