//! The targets file of `strand plan` (TOML): the layer the print must lay, the wall it must
//! build, and the machine's bounds on every setting the plan may choose.
//!
//! ```toml
//! [layer]                     # the layer's section at a station, each with its tolerance
//! station = 0.025             # x of the section [m]; default the scenario's first station
//! width = 0.016               # [m]
//! width_tolerance = 0.001     # |width - 0.016| <= 0.001
//! height = 0.006
//! height_tolerance = 0.0005
//! # layer = 1                 # layer K of a multi-layer print (layer_width@X:K); default the section
//!
//! [wall]                      # optional: the wall the layers build
//! design_height = 0.4         # [m]
//! safety_factor = 1.5         # it must stand to 1.5 x 0.4 m by the closed-form criteria
//! length = 2.0                # one layer's path [m]; default the print's extruding moves
//! age_at_start = 0.0          # the mix's age when the print starts [s]
//!
//! [settings]                  # [lower, upper]; a setting left out keeps the scenario's value
//! speed = [0.04, 0.12]        # nozzle speed of every extruding move [m/s]
//! extrusion = [0.03, 0.08]    # extrusion speed U of every extruding move [m/s]
//! standoff = [0.004, 0.008]   # nozzle over the base [m] (print.z_offset moves it)
//! layer_time = [5.0, 600.0]   # one layer's period [s] (at least length / speed)
//! ```

use super::error::PlanError;
use serde::Deserialize;
use std::path::Path;

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Targets {
    pub layer: LayerTargets,
    #[serde(default)]
    pub wall: Option<WallTargets>,
    pub settings: Bounds,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerTargets {
    #[serde(default)]
    pub station: Option<f64>,
    pub width: f64,
    pub width_tolerance: f64,
    pub height: f64,
    pub height_tolerance: f64,
    #[serde(default)]
    pub layer: Option<u32>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallTargets {
    pub design_height: f64,
    pub safety_factor: f64,
    #[serde(default)]
    pub length: Option<f64>,
    #[serde(default)]
    pub age_at_start: f64,
}

/// The bounds of each setting, `[lower, upper]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    #[serde(default)]
    pub speed: Option<[f64; 2]>,
    #[serde(default)]
    pub extrusion: Option<[f64; 2]>,
    #[serde(default)]
    pub standoff: Option<[f64; 2]>,
    #[serde(default)]
    pub layer_time: Option<[f64; 2]>,
}

/// A setting the plan chooses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Setting {
    Speed,
    Extrusion,
    Standoff,
}

impl Setting {
    pub const ALL: [Setting; 3] = [Setting::Speed, Setting::Extrusion, Setting::Standoff];

    pub fn name(self) -> &'static str {
        match self {
            Setting::Speed => "speed",
            Setting::Extrusion => "extrusion",
            Setting::Standoff => "standoff",
        }
    }

    pub fn parse(s: &str) -> Option<Setting> {
        Setting::ALL.into_iter().find(|x| x.name() == s)
    }

    /// The setting's place in a point (`line::Point`), in [`Setting::ALL`]'s order.
    pub fn index(self) -> usize {
        Setting::ALL.iter().position(|a| *a == self).expect("every setting is in ALL")
    }

    /// The unit a report shows the setting in, and its factor from SI.
    pub fn unit(self) -> (&'static str, f64) {
        if self == Setting::Standoff {
            ("mm", 1e3)
        } else {
            ("mm/s", 1e3)
        }
    }
}

impl Bounds {
    /// The bounds of a simulated setting, when the targets free it.
    pub fn of(&self, s: Setting) -> Option<[f64; 2]> {
        match s {
            Setting::Speed => self.speed,
            Setting::Extrusion => self.extrusion,
            Setting::Standoff => self.standoff,
        }
    }
}

impl Targets {
    pub fn load(path: &Path) -> Result<Targets, PlanError> {
        let text = std::fs::read_to_string(path).map_err(|e| PlanError::Io(format!("{}: {e}", path.display())))?;
        Targets::parse(&text).map_err(|e| PlanError::Targets(format!("{}: {}", path.display(), e.to_string().trim_start_matches("targets: "))))
    }

    pub fn parse(text: &str) -> Result<Targets, PlanError> {
        let t: Targets = toml::from_str(text).map_err(|e| PlanError::Targets(e.message().to_string()))?;
        t.validate()?;
        Ok(t)
    }

    /// The settings the plan moves, in [`Setting::ALL`]'s order.
    /// One layer's path [m]: the wall's, or `printed` (the print's extruding length).
    pub fn layer_length(&self, printed: f64) -> f64 {
        self.wall.as_ref().and_then(|w| w.length).unwrap_or(printed)
    }

    pub fn free(&self) -> Vec<(Setting, [f64; 2])> {
        Setting::ALL.into_iter().filter_map(|s| self.settings.of(s).map(|b| (s, b))).collect()
    }

    /// Well posed: positive targets and tolerances, bounds in order, and a layer time the
    /// nozzle can keep (its upper bound at least one layer's length over the highest speed).
    pub fn validate(&self) -> Result<(), PlanError> {
        let bad = |m: String| Err(PlanError::Targets(m));
        let l = &self.layer;
        for (what, v) in [("layer.width", l.width), ("layer.height", l.height)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{what} must be a length > 0 m, got {v}"));
            }
        }
        for (what, v, of) in [("layer.width_tolerance", l.width_tolerance, l.width), ("layer.height_tolerance", l.height_tolerance, l.height)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!(
                    "{what} = {v}: a tolerance of zero (or less) cannot be met, a simulated section is never exact; give the band the layer may lie in, > 0 (for example {:.2e} m, 5 % of the target)",
                    0.05 * of
                ));
            }
        }
        if l.layer == Some(0) {
            return bad("layer.layer: layers are counted from 1 (the bottom one)".into());
        }
        if let Some(w) = &self.wall {
            if !(w.design_height.is_finite() && w.design_height > 0.0) {
                return bad(format!("wall.design_height must be a height > 0 m, got {}", w.design_height));
            }
            if !(w.safety_factor.is_finite() && w.safety_factor >= 1.0) {
                return bad(format!("wall.safety_factor must be >= 1 (the wall stands to the design height times it), got {}", w.safety_factor));
            }
            if w.length.is_some_and(|x| !(x.is_finite() && x > 0.0)) {
                return bad(format!("wall.length must be a layer's path length > 0 m, got {:?}", w.length));
            }
            if !(w.age_at_start.is_finite() && w.age_at_start >= 0.0) {
                return bad(format!("wall.age_at_start must be >= 0 s, got {}", w.age_at_start));
            }
        }
        let s = &self.settings;
        for (name, b) in [("speed", s.speed), ("extrusion", s.extrusion), ("standoff", s.standoff), ("layer_time", s.layer_time)] {
            let Some([lo, hi]) = b else { continue };
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0) {
                return bad(format!("settings.{name} = [{lo}, {hi}]: bounds must be finite and > 0"));
            }
            if lo > hi {
                return bad(format!("settings.{name} = [{lo}, {hi}]: the lower bound exceeds the upper, so the bounds exclude every value"));
            }
        }
        if self.free().is_empty() {
            return bad("settings: free at least one of speed, extrusion, standoff (give its [lower, upper])".into());
        }
        if s.layer_time.is_some() && self.wall.is_none() {
            return bad("settings.layer_time needs a [wall] (the layer time matters only to the wall's failure)".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = "[layer]\nwidth = 0.016\nwidth_tolerance = 0.001\nheight = 0.006\nheight_tolerance = 0.0005\n[wall]\ndesign_height = 0.3\nsafety_factor = 1.5\n[settings]\nspeed = [0.04, 0.12]\nlayer_time = [5.0, 600.0]\n";

    fn err(text: &str) -> String {
        Targets::parse(text).unwrap_err().to_string()
    }

    #[test]
    fn bad_targets_name_what_is_wrong() {
        let t = Targets::parse(OK).unwrap();
        assert_eq!(t.free(), vec![(Setting::Speed, [0.04, 0.12])]);
        let e = err(&OK.replace("width_tolerance = 0.001", "width_tolerance = 0.0"));
        assert!(e.contains("layer.width_tolerance = 0: a tolerance of zero"), "{e}");
        let e = err(&OK.replace("height_tolerance = 0.0005", "height_tolerance = -1e-4"));
        assert!(e.contains("layer.height_tolerance = -0.0001") && e.contains("cannot be met"), "{e}");
        let e = err(&OK.replace("speed = [0.04, 0.12]", "speed = [0.12, 0.04]"));
        assert!(e.contains("settings.speed = [0.12, 0.04]: the lower bound exceeds the upper"), "{e}");
        let e = err(&OK.replace("safety_factor = 1.5", "safety_factor = 0.8"));
        assert!(e.contains("wall.safety_factor must be >= 1"), "{e}");
        let e = err(&OK.replace("speed = [0.04, 0.12]\n", ""));
        assert!(e.contains("free at least one of speed, extrusion, standoff"), "{e}");
        let e = err(&OK.replace("[layer]", "[layer]\ncolour = 1"));
        assert!(e.contains("unknown field `colour`"), "{e}");
    }
}
