//! Measurements and the experiments that produced them.
//!
//! Measurements are a tidy CSV, one row per observation:
//!
//! ```text
//! experiment,observable,at,value,uncertainty
//! SF240,spread,,0.500,0.010
//! case1,width,0.016,0.0301,0.0005
//! rheo240,stress,10.0,287.0,5.0
//! ```
//!
//! `at` is the station x [m] of a printed-geometry observable (`width`, `height`, `level`, `area`), the time [s] of one observed during
//! a run (`spread`, `front`: a slump spread or a flow distance against time; empty for the end), or the shear rate [1/s] of a rheometer reading.
//! Three printed-geometry observables take a second coordinate after a colon, `X:Y` in the `at`
//! column as in `name@X:Y`: `profile` the lateral position y [m] of a point of the section's top
//! outline (`profile@0.075:0.01`), `layer_height` and `layer_width` the layer, 1 = the bottom one
//! (`layer_height@0.075:2`). `failure_layer` and `failure_time` take no `at`: the layer and time
//! at which a print fails (`failure.rs`). `arrival@X` and `stop_time@D` are read from the flow
//! front's history: the time it reaches x = X, and the time it stops (`front.rs`). The experiments file
//! (TOML) maps each id to what produced it: a scenario with per-experiment overrides (rest time,
//! speeds, geometry: any scenario key), or a virtual-rheometer protocol, and lists what it observes
//! (what `strand synth` produces):
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

use serde::Deserialize;
use std::path::{Path, PathBuf};

/// One measured value.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Observation {
    pub experiment: String,
    pub observable: Observable,
    pub value: f64,
    pub uncertainty: f64,
}

/// What is observed, and where or when.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Observable {
    pub name: String,
    pub at: Option<f64>,
    /// The second coordinate, after `:` (only with `at`): `profile`'s lateral position y [m],
    /// `layer_height`'s and `layer_width`'s layer (1 = the bottom one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at2: Option<f64>,
}

/// Observables a simulation experiment can produce, and those of a rheometer experiment.
pub const SIMULATION_OBSERVABLES: &[&str] = &["spread", "front", "width", "height", "level", "area", "profile", "layer_height", "layer_width", "vx_max", "kinetic_energy", "mean_z", "failure_layer", "failure_time", "arrival", "stop_time"];
pub const RHEOMETER_OBSERVABLES: &[&str] = &["stress"];

/// `X` or `X:Y`, finite numbers, as the `at` of an observable; the error says what is wrong.
pub fn parse_at(a: &str) -> Result<(f64, Option<f64>), String> {
    let number = |v: &str| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("'{}' is not a number", v.trim()));
    let mut parts = a.split(':');
    let at = number(parts.next().unwrap_or(""))?;
    let at2 = parts.next().map(number).transpose()?;
    if parts.next().is_some() {
        return Err(format!("'{}' has more than two coordinates (X or X:Y)", a.trim()));
    }
    Ok((at, at2))
}

/// `at` and `at2` as `X` or `X:Y` (empty for neither).
pub fn at_text(at: Option<f64>, at2: Option<f64>) -> String {
    match (at, at2) {
        (Some(a), Some(b)) => format!("{a}:{b}"),
        (Some(a), None) => format!("{a}"),
        (None, _) => String::new(),
    }
}

impl Observable {
    /// `name`, `name@X` or `name@X:Y`.
    pub fn parse(s: &str) -> Result<Observable, String> {
        let (name, at, at2) = match s.split_once('@') {
            Some((n, a)) => {
                let (at, at2) = parse_at(a).map_err(|e| format!("'{s}': {e}"))?;
                (n.trim(), Some(at), at2)
            }
            None => (s.trim(), None, None),
        };
        if name.is_empty() {
            return Err(format!("'{s}': no observable name before '@'"));
        }
        Ok(Observable { name: name.to_string(), at, at2 })
    }
}

impl std::fmt::Display for Observable {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self.at {
            Some(_) => write!(f, "{}@{}", self.name, at_text(self.at, self.at2)),
            None => write!(f, "{}", self.name),
        }
    }
}

/// Read a measurements CSV; errors name the file and line.
pub fn read_observations(path: &Path) -> Result<Vec<Observation>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse_observations(&text).map_err(|e| format!("{}: {e}", path.display()))
}

pub fn parse_observations(text: &str) -> Result<Vec<Observation>, String> {
    let mut rd = csv::ReaderBuilder::new().trim(csv::Trim::All).comment(Some(b'#')).from_reader(text.as_bytes());
    let header: Vec<String> = rd.headers().map_err(|e| e.to_string())?.iter().map(str::to_string).collect();
    let want = ["experiment", "observable", "at", "value", "uncertainty"];
    let col = |name: &str| header.iter().position(|h| h == name).ok_or_else(|| format!("no '{name}' column (the columns are {})", want.join(",")));
    let idx: Vec<usize> = want.iter().map(|w| col(w)).collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| e.to_string())?;
        let line = rec.position().map_or(0, |p| p.line());
        let field = |k: usize| rec.get(idx[k]).unwrap_or("");
        let number = |k: usize| -> Result<f64, String> {
            field(k).parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("line {line}: {} '{}' is not a number", want[k], field(k)))
        };
        let (at, at2) = if field(2).is_empty() {
            (None, None)
        } else {
            let (a, b) = parse_at(field(2)).map_err(|e| format!("line {line}: at {e} (X, or X:Y for profile@X:Y and layer_height@X:K)"))?;
            (Some(a), b)
        };
        let uncertainty = number(4)?;
        if uncertainty <= 0.0 {
            return Err(format!("line {line}: uncertainty must be > 0, got {uncertainty}"));
        }
        if field(0).is_empty() || field(1).is_empty() {
            return Err(format!("line {line}: experiment and observable must not be empty"));
        }
        out.push(Observation {
            experiment: field(0).to_string(),
            observable: Observable { name: field(1).to_string(), at, at2 },
            value: number(3)?,
            uncertainty,
        });
    }
    if out.is_empty() {
        return Err("no observations".into());
    }
    Ok(out)
}

/// Write observations as the tidy CSV `read_observations` reads.
pub fn write_observations(path: &Path, obs: &[Observation]) -> Result<(), String> {
    let mut w = csv::Writer::from_path(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let err = |e: csv::Error| format!("{}: {e}", path.display());
    w.write_record(["experiment", "observable", "at", "value", "uncertainty"]).map_err(err)?;
    for o in obs {
        let at = at_text(o.observable.at, o.observable.at2);
        w.write_record([o.experiment.clone(), o.observable.name.clone(), at, format!("{:e}", o.value), format!("{:e}", o.uncertainty)]).map_err(err)?;
    }
    w.flush().map_err(|e| format!("{}: {e}", path.display()))
}

/// A TOML number as f64 (integers too); None for anything else.
pub fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or(v.as_integer().map(|i| i as f64))
}

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
    pub fn validate(&self) -> Result<(), String> {
        for (k, v) in &self.fine {
            if number(v).is_none() {
                return Err(format!("fine.\"{k}\" must be a number"));
            }
        }
        match self.fine.get("simulation.dx").and_then(number) {
            Some(dx) if dx > 0.0 && dx.is_finite() => {}
            Some(dx) => return Err(format!("fine.\"simulation.dx\" must be a cell size > 0, got {dx}")),
            None => return Err("fine must set \"simulation.dx\", the finer run's cell size: fine = { \"simulation.dx\" = 0.002 }".into()),
        }
        if let Some(p) = self.order {
            if !(p.is_finite() && p > 0.0 && p <= 8.0) {
                return Err(format!("order must be an order of convergence in (0, 8], got {p}"));
            }
        }
        Ok(())
    }
}

impl Experiment {
    pub fn covariates(&self) -> super::effects::Covariates {
        super::effects::Covariates { rest_time: self.rest_time, age: self.age, declared: self.covariates.clone() }
    }
}

impl Experiments {
    pub fn load(path: &Path) -> Result<Experiments, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut e: Experiments = toml::from_str(&text).map_err(|e| format!("{}: {}", path.display(), e.message()))?;
        e.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        e.validate().map_err(|m| format!("{}: {m}", path.display()))?;
        Ok(e)
    }

    pub fn validate(&self) -> Result<(), String> {
        if let Some(r) = &self.resolution {
            r.validate().map_err(|e| format!("[resolution]: {e}"))?;
        }
        let mut seen = std::collections::HashSet::new();
        for (i, x) in self.experiment.iter().enumerate() {
            if !seen.insert(x.id.as_str()) {
                return Err(format!("experiment.{i}: id '{}' is used twice", x.id));
            }
            let names = match (&x.scenario, &x.protocol) {
                (Some(_), None) => SIMULATION_OBSERVABLES,
                (None, Some(_)) => RHEOMETER_OBSERVABLES,
                _ => return Err(format!("experiment '{}': give either scenario (a simulation) or protocol (a rheometer test)", x.id)),
            };
            for o in &x.observe {
                let ob = Observable::parse(o).map_err(|e| format!("experiment '{}': observe {e}", x.id))?;
                if !names.contains(&ob.name.as_str()) {
                    return Err(format!("experiment '{}': cannot observe '{}'; it can observe {}", x.id, ob.name, names.join(", ")));
                }
                // the coordinates each takes (the time of one taken during the run is checked when it runs)
                let checked = if crate::failure::OBSERVABLES.contains(&ob.name.as_str()) {
                    crate::failure::check_observable(&ob.name, ob.at)
                } else if super::front::OBSERVABLES.contains(&ob.name.as_str()) {
                    super::front::check_observable(&ob)
                } else if x.scenario.is_some() {
                    super::compare::observable_plan(&ob, f64::INFINITY).map(|_| ())
                } else {
                    super::compare::reading_rate(&ob).map(|_| ())
                };
                checked.map_err(|e| format!("experiment '{}': observe {e}", x.id))?;
            }
            for (what, v) in [("rest_time", x.rest_time), ("age", x.age)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("experiment '{}': {what} must be >= 0 seconds, got {v}", x.id));
                }
            }
            for (name, v) in &x.covariates {
                if ["rest_time", "age"].contains(&name.as_str()) {
                    return Err(format!("experiment '{}': covariates.{name}: give {name} as its own key ({name} = ...)", x.id));
                }
                if !v.is_finite() {
                    return Err(format!("experiment '{}': covariates.{name} must be a finite number, got {v}", x.id));
                }
            }
            for (k, v) in &x.set {
                if number(v).is_none() {
                    return Err(format!("experiment '{}': set.{k} must be a number", x.id));
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
    fn observations_round_trip_and_bad_rows_name_their_line() {
        let text = "experiment,observable,at,value,uncertainty\nSF240,spread,,0.5,0.01\n# a comment\ncase1, width ,0.016,0.0301,5e-4\n";
        let obs = parse_observations(text).unwrap();
        assert_eq!(obs.len(), 2);
        assert_eq!(obs[1].observable, Observable { name: "width".into(), at: Some(0.016), at2: None });
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.csv");
        write_observations(&p, &obs).unwrap();
        assert_eq!(read_observations(&p).unwrap(), obs);
        let e = parse_observations("experiment,observable,at,value,uncertainty\nA,spread,,0.5,0.01\nB,spread,,zero,0.01\n").unwrap_err();
        assert!(e.contains("line 3") && e.contains("value 'zero'"), "{e}");
        let e = parse_observations("experiment,observable,at,value,uncertainty\nA,spread,,0.5,0\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("uncertainty"), "{e}");
        let e = parse_observations("experiment,observable,value\nA,spread,0.5\n").unwrap_err();
        assert!(e.contains("no 'at' column"), "{e}");
    }

    #[test]
    fn experiments_are_checked() {
        let parse = |t: &str| -> Result<Experiments, String> {
            let e: Experiments = toml::from_str(t).map_err(|e| e.to_string())?;
            e.validate().map(|_| e)
        };
        let ok = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nobserve = [\"spread\", \"width@0.02\"]\nset = { \"material.yield_stress\" = 300.0 }\n").unwrap();
        assert_eq!(ok.experiment[0].observe.len(), 2);
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nobserve = [\"stress@10\"]\n").unwrap_err();
        assert!(e.contains("cannot observe 'stress'"), "{e}");
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nprotocol = \"p.toml\"\n").unwrap_err();
        assert!(e.contains("either scenario"), "{e}");
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\n[[experiment]]\nid = \"a\"\nscenario = \"t.toml\"\n").unwrap_err();
        assert!(e.contains("used twice"), "{e}");
        let e = parse("[[experiment]]\nid = \"a\"\nscenario = \"s.toml\"\nset = { \"material.kind\" = \"x\" }\n").unwrap_err();
        assert!(e.contains("must be a number"), "{e}");
        // the printed geometry's observables and the coordinates each takes
        let observe = |list: &str, what: &str| parse(&format!("[[experiment]]\nid = \"a\"\n{what} = \"s.toml\"\nobserve = [{list}]\n"));
        let ok = observe("\"profile@0.075:0.01\", \"layer_height@0.075:2\", \"layer_width@0.075:1\", \"height@0.075\"", "scenario").unwrap();
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

    #[test]
    fn a_second_coordinate_parses_prints_back_and_bad_ones_are_named() {
        let o = Observable::parse("profile@0.075:0.01").unwrap();
        assert_eq!(o, Observable { name: "profile".into(), at: Some(0.075), at2: Some(0.01) });
        for s in ["profile@0.075:0.01", "profile@0.075:-0.002", "layer_height@0.075:2", "layer_width@0.03:1", "width@0.016", "spread"] {
            assert_eq!(Observable::parse(s).unwrap().to_string(), s);
        }
        assert_eq!(Observable::parse(" profile @ 0.075 : 0.01 ").unwrap(), o);
        for (bad, want) in [
            ("profile@0.075:", "'' is not a number"),
            ("profile@0.075:y", "'y' is not a number"),
            ("profile@:0.01", "'' is not a number"),
            ("profile@0.075:0.01:0.02", "'0.075:0.01:0.02' has more than two coordinates (X or X:Y)"),
            ("width@inf", "'inf' is not a number"),
            ("@0.1", "no observable name"),
        ] {
            let e = Observable::parse(bad).unwrap_err();
            assert!(e.starts_with(&format!("'{bad}': ")) && e.contains(want), "{bad}: {e}");
        }
        // in the measurements CSV the at column holds X:Y
        let text = "experiment,observable,at,value,uncertainty\ncase1,profile,0.075:0.01,0.012,5e-4\ncase1,layer_height,0.075:2,0.006,2e-4\ncase1,height,0.075,0.018,5e-4\n";
        let obs = parse_observations(text).unwrap();
        let names: Vec<String> = obs.iter().map(|o| o.observable.to_string()).collect();
        assert_eq!(names, ["profile@0.075:0.01", "layer_height@0.075:2", "height@0.075"]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.csv");
        write_observations(&p, &obs).unwrap();
        assert!(std::fs::read_to_string(&p).unwrap().contains("case1,profile,0.075:0.01,"));
        assert_eq!(read_observations(&p).unwrap(), obs);
        let e = parse_observations("experiment,observable,at,value,uncertainty\ncase1,profile,0.075:y,0.012,5e-4\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("at 'y' is not a number"), "{e}");
    }
}
