//! The `[checkpoint]` table.

use serde::Deserialize;
use crate::invalid::Invalid;

/// `[checkpoint]`: when checkpoints are written and how many are kept.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointConfig {
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Wall-clock seconds between checkpoints: the work a crash can cost.
    #[serde(default = "default_wall")]
    pub wall_interval: f64,
    /// Also every this many steps (none by default).
    #[serde(default)]
    pub step_interval: Option<u64>,
    /// Newest checkpoints kept; older ones are deleted once a new one is safely on disk.
    #[serde(default = "default_keep")]
    pub keep: usize,
    /// Write one when the run reaches its end time (to extend it later, or inspect it).
    #[serde(default = "yes")]
    pub at_end: bool,
}

fn yes() -> bool {
    true
}
fn default_wall() -> f64 {
    600.0
}
fn default_keep() -> usize {
    2
}

impl Default for CheckpointConfig {
    fn default() -> Self {
        CheckpointConfig { enabled: true, wall_interval: default_wall(), step_interval: None, keep: default_keep(), at_end: true }
    }
}

impl CheckpointConfig {
    pub fn validate(&self) -> Result<(), Invalid> {
        if !(self.wall_interval > 0.0) {
            return Err(Invalid(format!("checkpoint.wall_interval must be > 0 seconds, got {}", self.wall_interval)));
        }
        if self.step_interval == Some(0) {
            return Err(Invalid("checkpoint.step_interval must be >= 1".into()));
        }
        if self.keep == 0 {
            return Err(Invalid("checkpoint.keep must be >= 1".into()));
        }
        Ok(())
    }
}
