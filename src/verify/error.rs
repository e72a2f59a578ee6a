//! Why a verification case, or the suite, cannot run: its scenario, the simulation, the
//! observables, or a fixture that is not what the case expects.

use crate::report::ReportError;
use crate::scenario::ScenarioError;
use crate::solver::SimError;

#[derive(Debug, thiserror::Error)]
pub enum VerifyError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Report(#[from] ReportError),
    /// A case's fixture lacks what the case edits or reads.
    #[error("{0}")]
    Fixture(String),
    #[error("case {name}: {source}")]
    Case { name: &'static str, source: Box<VerifyError> },
    #[error("no verification case matches '{0}'")]
    NoMatch(String),
}
