//! What stops a run, and the exit status it gives the command line.

use crate::solver::SimError;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{source}\n  the state after the failing step is in {} (outputs before it are kept)", snapshot.display())]
    Failed { source: SimError, snapshot: PathBuf },
    #[error("output {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error(transparent)]
    Report(#[from] crate::report::ReportError),
    /// Resuming (or refusing to start over) failed.
    #[error("{0}")]
    Resume(String),
    #[error("checkpoint: {0}")]
    Checkpoint(#[from] crate::checkpoint::writer::WriterError),
    /// The writer thread could not write a checkpoint to disk.
    #[error("checkpoint: writing the checkpoint of step {step} failed: {source}")]
    CheckpointWrite { step: u64, source: std::io::Error },
    #[error("stopped by {signal} at step {step} (t = {time:.6} s); {saved}\n  resume with: {resume}")]
    Interrupted { signal: &'static str, step: u64, time: f64, saved: String, resume: String },
    #[error("disk budget: {0}")]
    DiskBudget(String),
    /// A run stopped by an error after it started: what is on disk and how to go on.
    #[error("{source}\n  {note}")]
    Stopped { source: Box<RunError>, note: String },
}

impl RunError {
    /// Process exit status: 128 + the signal's number after SIGINT (130) or SIGTERM (143), the
    /// shell convention, else 2.
    pub fn exit_code(&self) -> u8 {
        match self {
            RunError::Interrupted { signal: "SIGTERM", .. } => 143,
            RunError::Interrupted { .. } => 130,
            _ => 2,
        }
    }
}

pub(super) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io { path: path.to_path_buf(), source }
}
