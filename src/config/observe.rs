//! The `[observe]` table: the observables a run records at each output.

use crate::failure::FailureConfig;
use serde::Deserialize;
use std::path::PathBuf;
use crate::invalid::Invalid;

/// The `[observe]` table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObserveConfig {
    /// x positions of the cross-sections to record [m].
    #[serde(default)]
    pub stations: Vec<f64>,
    /// Thickness of the slab of particles each cross-section takes [m]; default one cell.
    #[serde(default)]
    pub slab: Option<f64>,
    /// Height the heights are measured from [m]; default the platform top, else domain.min z.
    #[serde(default)]
    pub base_z: Option<f64>,
    /// Measured cross-section points (CSV with header `y,z`, metres) drawn over the plots.
    #[serde(default)]
    pub measured: Option<PathBuf>,
    /// Record the slump-flow spread (mean diameter of the material near the base).
    #[serde(default)]
    pub spread: bool,
    /// The domain is half of a symmetric problem, cut at the plane y = this value (a free-slip
    /// wall): observables see the material together with its mirror image.
    #[serde(default)]
    pub mirror_y: Option<f64>,
    /// The observables see only the particles with `y_range[0] <= y <= y_range[1]` [m]: on a
    /// closed toolpath (a cylinder) the plane of a station cuts the wall twice, and the range
    /// keeps one crossing. Applied after `mirror_y`.
    #[serde(default)]
    pub y_range: Option<[f64; 2]>,
    /// Failure detection of a multi-layer print (`failure.rs`): on whenever a print of two or
    /// more layers has stations; this table sets its threshold and can end the run after it.
    #[serde(default)]
    pub failure: FailureConfig,
}

impl ObserveConfig {
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.stations.iter().any(|x| !x.is_finite()) {
            return Err(Invalid("observe.stations must be finite x positions".into()));
        }
        if let Some(s) = self.slab {
            if !(s > 0.0 && s.is_finite()) {
                return Err(Invalid(format!("observe.slab must be > 0, got {s}")));
            }
        }
        if let Some([lo, hi]) = self.y_range {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(Invalid(format!("observe.y_range must be [low, high] with finite low < high [m], got [{lo}, {hi}]")));
            }
        }
        self.failure.validate()
    }
}
