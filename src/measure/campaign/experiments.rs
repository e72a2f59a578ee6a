//! The experiments file (TOML): what produced the measurements. It maps each experiment's id to
//! a scenario with per-experiment overrides (rest time, speeds, geometry: any scenario key),
//! or a virtual-rheometer protocol, and lists what it observes (what `strand synth` produces):
//!
//! ```toml
//! [[experiment]]
//! id = "SF240"
//! scenario = "slump.toml"                 # relative to this file
//! set = { "material.lambda0" = 1.8 }      # overrides, after the model's [material]
//! observe = ["spread"]
//! rest_time = 240.0                       # covariates the model's effects read: rest before
//! age = 1800.0                            # the test and material age since mixing [s]
//!
//! [[experiment]]
//! id = "rheo240"
//! protocol = "rest240.toml"               # a rheometer protocol ([[phase]] tables)
//! observe = ["stress@10", "stress@1"]
//! ```

use crate::measure::error::{io_error, MeasureError};
use crate::measure::effects::Covariates;
use crate::measure::observables::{self, RHEOMETER_OBSERVABLES, SIMULATION_OBSERVABLES};
use crate::measure::observation::{number, Observable};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The experiments file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiments {
    pub experiment: Vec<Experiment>,
    /// A finer run of every simulation experiment, to estimate the discretisation error
    /// (`resolution.rs`).
    #[serde(default)]
    pub resolution: Option<ResolutionTable>,
    /// Folder the file sits in: scenario and protocol paths are relative to it.
    #[serde(skip)]
    pub base_dir: PathBuf,
}

#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    pub id: String,
    /// A simulation: the scenario file.
    #[serde(default)]
    pub scenario: Option<PathBuf>,
    /// A virtual-rheometer test: a protocol file, or the protocol inline.
    #[serde(default)]
    pub protocol: Option<toml::Value>,
    /// Scenario keys (`material.yield_stress`, `print.path.0.speed`, ...) set for this
    /// experiment, after the model's `[material]`.
    #[serde(default)]
    pub set: toml::Table,
    /// What it observes, as `name` or `name@at`.
    #[serde(default)]
    pub observe: Vec<String>,
    /// Rest before the test [s] (what thixotropy builds on).
    #[serde(default)]
    pub rest_time: f64,
    /// Material age at the test, since mixing [s] (what ageing acts on).
    #[serde(default)]
    pub age: f64,
    /// Other covariates, by name (`covariates = { temperature = 31.0 }`): what an effect
    /// declared in a model file may read, and what `compare --report` and diagnose look for
    /// patterns in.
    #[serde(default)]
    pub covariates: std::collections::BTreeMap<String, f64>,
}

/// The experiments file's `[resolution]` table: the overrides of a finer run of every simulation
/// experiment, and the order of convergence assumed in the Richardson estimate
/// (`resolution.rs`).
///
/// ```toml
/// [resolution]
/// fine = { "simulation.dx" = 0.002 }   # any scenario keys; simulation.dx is required
/// order = 1.0                          # optional; default resolution::DEFAULT_ORDER
/// ```
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ResolutionTable {
    /// Scenario keys of the finer run, set after the experiment's own `set`.
    pub fine: toml::Table,
    /// The order of convergence p assumed in the estimate.
    #[serde(default)]
    pub order: Option<f64>,
}

impl ResolutionTable {
    pub fn validate(&self) -> Result<(), MeasureError> {
        for (k, v) in &self.fine {
            if number(v).is_none() {
                return Err(MeasureError::Experiments(format!("fine.\"{k}\" must be a number")));
            }
        }
        match self.fine.get("simulation.dx").and_then(number) {
            Some(dx) if dx > 0.0 && dx.is_finite() => {}
            Some(dx) => {
                return Err(MeasureError::Experiments(format!(
                    "fine.\"simulation.dx\" must be a cell size > 0, got {dx}"
                )))
            }
            None => {
                return Err(MeasureError::Experiments(
                    "fine must set \"simulation.dx\", the finer run's cell size: fine = { \"simulation.dx\" = 0.002 }"
                        .into(),
                ))
            }
        }
        if let Some(p) = self.order {
            if !(p.is_finite() && p > 0.0 && p <= 8.0) {
                return Err(MeasureError::Experiments(format!(
                    "order must be an order of convergence in (0, 8], got {p}"
                )));
            }
        }
        Ok(())
    }
}

impl Experiment {
    pub fn covariates(&self) -> Covariates {
        Covariates { rest_time: self.rest_time, age: self.age, declared: self.covariates.clone() }
    }
}

impl Experiments {
    pub fn load(path: &Path) -> Result<Experiments, MeasureError> {
        let text = std::fs::read_to_string(path).map_err(io_error(path))?;
        let mut e: Experiments = toml::from_str(&text)
            .map_err(|e| MeasureError::Experiments(format!("{}: {}", path.display(), e.message())))?;
        e.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        e.validate().map_err(|m| m.within(path.display()))?;
        Ok(e)
    }

    pub fn validate(&self) -> Result<(), MeasureError> {
        if let Some(r) = &self.resolution {
            r.validate().map_err(|e| e.within("[resolution]"))?;
        }
        let mut seen = std::collections::HashSet::new();
        for (i, x) in self.experiment.iter().enumerate() {
            if !seen.insert(x.id.as_str()) {
                return Err(MeasureError::Experiments(format!("experiment.{i}: id '{}' is used twice", x.id)));
            }
            let names = match (&x.scenario, &x.protocol) {
                (Some(_), None) => &SIMULATION_OBSERVABLES[..],
                (None, Some(_)) => RHEOMETER_OBSERVABLES,
                _ => {
                    return Err(MeasureError::Experiments(format!(
                        "experiment '{}': give either scenario (a simulation) or protocol (a rheometer test)",
                        x.id
                    )))
                }
            };
            for o in &x.observe {
                let ob = Observable::parse(o)
                    .map_err(|e| MeasureError::Experiments(format!("experiment '{}': observe {e}", x.id)))?;
                if !names.contains(&ob.name.as_str()) {
                    return Err(MeasureError::Experiments(format!(
                        "experiment '{}': cannot observe '{}'; it can observe {}",
                        x.id,
                        ob.name,
                        names.join(", ")
                    )));
                }
                observables::check_coordinates(&ob, x.scenario.is_some())
                    .map_err(|e| MeasureError::Experiments(format!("experiment '{}': observe {e}", x.id)))?;
            }
            for (what, v) in [("rest_time", x.rest_time), ("age", x.age)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(MeasureError::Experiments(format!(
                        "experiment '{}': {what} must be >= 0 seconds, got {v}",
                        x.id
                    )));
                }
            }
            for (name, v) in &x.covariates {
                if ["rest_time", "age"].contains(&name.as_str()) {
                    return Err(MeasureError::Experiments(format!(
                        "experiment '{}': covariates.{name}: give {name} as its own key ({name} = ...)",
                        x.id
                    )));
                }
                if !v.is_finite() {
                    return Err(MeasureError::Experiments(format!(
                        "experiment '{}': covariates.{name} must be a finite number, got {v}",
                        x.id
                    )));
                }
            }
            for (k, v) in &x.set {
                if number(v).is_none() {
                    return Err(MeasureError::Experiments(format!("experiment '{}': set.{k} must be a number", x.id)));
                }
            }
        }
        Ok(())
    }

    pub fn get(&self, id: &str) -> Option<&Experiment> {
        self.experiment.iter().find(|e| e.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn experiments_are_checked() {
        let parse = |t: &str| -> Result<Experiments, String> {
            let e: Experiments = toml::from_str(t).map_err(|e| e.to_string())?;
            e.validate().map(|_| e).map_err(|e| e.to_string())
        };
        let ok = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nobserve = [\"spread\", \"width@0.02\"]\nset \
            = { \"material.yield_stress\" = 300.0 }\n").unwrap();
        assert_eq!(ok.experiment[0].observe.len(), 2);
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nobserve = [\"stress@10\"]\n").unwrap_err();
        assert!(e.contains("cannot observe 'stress'"), "{e}");
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nprotocol = \"p.toml\"\n").unwrap_err();
        assert!(e.contains("either scenario"), "{e}");
        let e = parse(
            "[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\n[[experiment]]\nid = \"a\"\nscenario = \"t.toml\"\n",
        )
        .unwrap_err();
        assert!(e.contains("used twice"), "{e}");
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nset = { \"material.kind\" = \"x\" }\n")
            .unwrap_err();
        assert!(e.contains("must be a number"), "{e}");
        // the printed geometry's observables and the coordinates each takes
        let observe = |list: &str, what: &str| {
            parse(&format!("[[experiment]]\nid = \"a\"\n{what} = \"s.toml\"\nobserve = [{list}]\n"))
        };
        let ok = observe(
            "\"profile@0.075:0.01\", \"layer_height@0.075:2\", \"layer_width@0.075:1\", \"height@0.075\"",
            "scenario",
        )
        .unwrap();
        assert_eq!(ok.experiment[0].observe.len(), 4);
        for (list, want) in [
            ("\"profile@0.075\"", "needs a station and a lateral position: profile@X:Y"),
            ("\"layer_height@0.075\"", "needs a station and a layer: layer_height@X:K"),
            ("\"layer_width@0.075:0\"", "the layer must be a whole number from 1"),
            ("\"layer_height@0.075:1.5\"", "the layer must be a whole number from 1"),
            ("\"width@0.02:0.01\"", "width takes one coordinate"),
            ("\"spread@0.5:1\"", "spread takes one coordinate"),
            ("\"profile@0.075:0.01:1\"", "more than two coordinates"),
        ] {
            let e = observe(list, "scenario").unwrap_err();
            assert!(e.contains("experiment 'a'") && e.contains(want), "{list}: {e}");
        }
        let e = observe("\"stress@5:1\"", "protocol").unwrap_err();
        assert!(e.contains("stress takes one coordinate"), "{e}");
    }

}
