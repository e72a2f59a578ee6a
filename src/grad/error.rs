//! Why a gradient (or a forward run that checks one) cannot be taken: an objective or parameter
//! the scenario cannot give, a scenario the adjoint does not cover, the budget, the checkpoint
//! store, or the simulation beneath.

use super::schedule::ScheduleError;
use crate::observables::ObservableError;
use crate::memory::{fmt_bytes, MemoryError, MemoryPlan};
use crate::print::PrintError;
use crate::scenario::ScenarioError;
use crate::solver::{AdjointError, SimError};
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum GradError {
    /// An objective name that does not parse, or one the state cannot give (no particle where
    /// it looks, a step outside the run).
    #[error("{0}")]
    Objective(String),
    /// A parameter key the scenario does not offer or hold, or a toolpath parameter that cannot
    /// be set.
    #[error("{0}")]
    Param(String),
    /// A scenario or run the adjoint does not cover (sleeping, no fixed time step, ...).
    #[error("{0}")]
    Unsupported(String),
    /// The scenario text, read as TOML to read or set a parameter.
    #[error(transparent)]
    TomlRead(#[from] toml::de::Error),
    #[error(transparent)]
    TomlWrite(#[from] toml::ser::Error),
    /// A perturbed scenario (boxed, as the other large sources: every step's `Result` in the
    /// reverse sweep carries this type).
    #[error(transparent)]
    Scenario(Box<ScenarioError>),
    /// A perturbed toolpath.
    #[error(transparent)]
    Print(Box<PrintError>),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Adjoint(#[from] AdjointError),
    #[error(transparent)]
    Memory(#[from] MemoryError),
    #[error(transparent)]
    Schedule(#[from] ScheduleError),
    #[error(
        "the gradient's RAM budget of {} does not hold its adjoint arrays ({}; one stored state is {}):\n{plan}",
        fmt_bytes(*ram_bytes), fmt_bytes(*adjoint_bytes), fmt_bytes(*state_bytes)
    )]
    Budget { ram_bytes: u64, adjoint_bytes: u64, state_bytes: u64, plan: Box<MemoryPlan> },
    #[error("no checkpoint store")]
    NoStore,
    #[error("no RAM checkpoint of step {0}")]
    NoRamCheckpoint(u64),
    #[error("the RAM checkpoint slots are all taken")]
    RamSlotsFull,
    #[error("no disk checkpoint of step {0}")]
    NoDiskCheckpoint(u64),
    #[error("the disk checkpoint slots are all taken")]
    DiskSlotsFull,
    #[error("the schedule uses disk checkpoints but no disk tier is set up")]
    NoDiskTier,
    /// Creating the checkpoint folder or file, or writing or reading a stored state:
    /// `what` names the act.
    #[error("{what} {}: {source}", path.display())]
    Io { what: &'static str, path: PathBuf, source: std::io::Error },
    #[error("the schedule never reached the objective's step")]
    StepNotReached,
    /// A stored state's sleep tables did not restore.
    #[error("a stored state of the gradient schedule: {0}")]
    SleepState(#[from] crate::sleep::BadUnitState),
}

impl From<ObservableError> for GradError {
    fn from(e: ObservableError) -> GradError {
        GradError::Objective(e.0)
    }
}

impl From<ScenarioError> for GradError {
    fn from(e: ScenarioError) -> GradError {
        GradError::Scenario(Box::new(e))
    }
}

impl From<PrintError> for GradError {
    fn from(e: PrintError) -> GradError {
        GradError::Print(Box::new(e))
    }
}

/// The I/O error `source` of `what` (creating, writing, ...) at `path`.
pub(super) fn io_err<'a>(what: &'static str, path: &'a std::path::Path) -> impl FnOnce(std::io::Error) -> GradError + 'a {
    move |source| GradError::Io { what, path: path.to_path_buf(), source }
}
