//! Why a plan cannot be made: targets that are not well posed, targets no setting within the
//! bounds meets (saying which and how close the best came), or the layers below failing.

use crate::grad::GradError;
use crate::observables::ObservableError;
use crate::measure::error::MeasureError;
use crate::output::plot::PlotError;

#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The targets file is not well posed (a tolerance of zero, bounds that exclude each other).
    #[error("targets: {0}")]
    Targets(String),
    /// No setting within the bounds meets a target.
    #[error("no feasible setting: {0}")]
    Infeasible(String),
    /// The print or the model does not offer what a plan needs.
    #[error("{0}")]
    Unsupported(String),
    #[error(transparent)]
    Measure(#[from] MeasureError),
    #[error(transparent)]
    Grad(#[from] GradError),
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error("{0}")]
    Io(String),
}
impl From<ObservableError> for PlanError {
    fn from(e: ObservableError) -> PlanError {
        PlanError::Grad(e.into())
    }
}
