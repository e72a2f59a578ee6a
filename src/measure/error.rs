//! Why a step of the measurement loop cannot be taken: a file it reads or writes, a value it
//! refuses (named by what holds the value: the model, an effect, an experiment, the
//! measurements, ...), or the simulation, gradient, plot or observer beneath. Each message names
//! what is wrong and where, as the command line prints it. The bottom of `measure/`: it imports
//! no file of the folder, so every file can return it.

use crate::grad::GradError;
use crate::invalid::Invalid;
use crate::observables::ObservableError;
use crate::output::plot::PlotError;
use crate::report::ReportError;
use crate::scenario::ScenarioError;
use crate::solver::SimError;
use std::fmt::Display;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    /// A measured or modelled quantity's name, or its coordinates after `@`, that the experiment
    /// cannot observe.
    #[error("{0}")]
    Observable(String),
    /// The measurements CSV: a missing column, a field that is not a number, no rows.
    #[error("{0}")]
    Observations(String),
    /// A declared effect's expression that does not parse.
    #[error("{0}")]
    Expression(String),
    /// A run's recorded history (the flow front's, the mass passed below a plane), which cannot
    /// give an observable (never recorded, a plane not recorded).
    #[error("{0}")]
    History(String),
    /// An effect that cannot be declared or applied, or a scenario without its null.
    #[error("{0}")]
    Effect(String),
    /// The model: a missing or unknown table, a parameter it does not hold, a value out of bounds.
    #[error("{0}")]
    Model(String),
    /// The experiments file: an id used twice, an experiment that is neither a simulation nor a
    /// rheometer test, a covariate or `[resolution]` value out of range.
    #[error("{0}")]
    Experiments(String),
    /// A virtual rheometer's protocol or model file.
    #[error("{0}")]
    Rheometer(String),
    /// Running an experiment under a model: a key it cannot set, an experiment without a scenario
    /// or protocol.
    #[error("{0}")]
    Run(String),
    /// A saved result whose inputs differ from the current ones.
    #[error("{0}")]
    Provenance(String),
    /// An experiment's simulation over its memory budget, refused before any experiment runs
    /// (`preflight.rs`).
    #[error("{0}")]
    Memory(String),
    /// The discretisation error of `[resolution]`'s finer run, which cannot be estimated.
    #[error("{0}")]
    Resolution(String),
    /// The finer run of `[resolution]`, which failed.
    #[error("{0} (the finer run of [resolution])")]
    FinerRun(Box<MeasureError>),
    /// Where the experiments run: an unknown engine, a job that cannot be written, submitted or
    /// read back.
    #[error("{0}")]
    Engine(String),
    /// The engine's command, which could not start.
    #[error("the engine's command could not start ({source}): {command}")]
    EngineStart { command: String, source: std::io::Error },
    /// The model's failure in a scheduler's job, as its result file records it.
    #[error("{0}")]
    InJob(String),
    /// A distributed comparison's planned jobs and their collected results.
    #[error("{0}")]
    Jobs(String),
    /// The folder of a comparison's report (`--report DIR`): a path that is there and is not a
    /// folder, or one that cannot be created.
    #[error("--report {}: exists and is not a directory", dir.display())]
    ReportNotAFolder { dir: PathBuf },
    #[error("--report {}: cannot create the directory: {source}", dir.display())]
    ReportFolder { dir: PathBuf, source: std::io::Error },
    /// Synthetic measurements that cannot be made (negative noise, nothing to observe).
    #[error("{0}")]
    Synth(String),
    /// A fit that cannot start or go on.
    #[error("{0}")]
    Fit(String),
    /// A file or folder that cannot be read, written, created or resolved.
    #[error("{}: {source}", path.display())]
    File { path: PathBuf, source: std::io::Error },
    /// An I/O error the context names ([`MeasureError::within`]), or of no file (a handle that
    /// cannot be duplicated).
    #[error(transparent)]
    Io(std::io::Error),
    /// TOML that does not parse (boxed: the parser's error is large).
    #[error(transparent)]
    Toml(Box<toml::de::Error>),
    /// An error with where it arose in front: an experiment, a file, a job.
    #[error("{context}: {source}")]
    In { context: String, source: Box<MeasureError> },
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error(transparent)]
    TomlWrite(#[from] toml::ser::Error),
    #[error(transparent)]
    Csv(#[from] csv::Error),
    #[error(transparent)]
    Invalid(#[from] Invalid),
    /// A scenario made from an experiment's (boxed, as the other large sources).
    #[error(transparent)]
    Scenario(Box<ScenarioError>),
    #[error(transparent)]
    Sim(Box<SimError>),
    #[error(transparent)]
    Grad(Box<GradError>),
    /// The observer of a run (`[observe]`), or a failure it detects.
    #[error(transparent)]
    Observer(Box<ReportError>),
    #[error(transparent)]
    Plot(#[from] PlotError),
}

impl MeasureError {
    /// This error with `context` (an experiment, a file, a job) in front: "context: error".
    pub fn within(self, context: impl Display) -> MeasureError {
        MeasureError::In { context: context.to_string(), source: Box::new(self) }
    }
}

impl From<toml::de::Error> for MeasureError {
    fn from(e: toml::de::Error) -> MeasureError {
        MeasureError::Toml(Box::new(e))
    }
}

impl From<ScenarioError> for MeasureError {
    fn from(e: ScenarioError) -> MeasureError {
        MeasureError::Scenario(Box::new(e))
    }
}

impl From<SimError> for MeasureError {
    fn from(e: SimError) -> MeasureError {
        MeasureError::Sim(Box::new(e))
    }
}

impl From<ObservableError> for MeasureError {
    fn from(e: ObservableError) -> MeasureError {
        MeasureError::Observable(e.0)
    }
}

impl From<GradError> for MeasureError {
    fn from(e: GradError) -> MeasureError {
        MeasureError::Grad(Box::new(e))
    }
}

impl From<ReportError> for MeasureError {
    fn from(e: ReportError) -> MeasureError {
        MeasureError::Observer(Box::new(e))
    }
}

/// The I/O error of the file or folder at `path`.
pub fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> MeasureError + '_ {
    move |source| MeasureError::File { path: path.to_path_buf(), source }
}

/// The parse error of the TOML file at `path`.
pub fn toml_error(path: &Path) -> impl FnOnce(toml::de::Error) -> MeasureError + '_ {
    move |source| MeasureError::from(source).within(path.display())
}
