//! What a saved result was computed from, so that no result is ever used under another model,
//! scenario or binary. Every per-experiment result a job saves (`compare --only ID --save FILE`,
//! `strand evaluate JOB --out RESULT`) carries a [`Provenance`]; whoever collects it recomputes
//! the provenance of the experiment as it stands and refuses any difference, naming the
//! experiment and what differs.
//!
//! Also the codec of saved numbers, [`Exact`]: a finite value as a JSON number in its shortest
//! round-trip form (serde_json's `float_roundtrip` reads it back to the same bits), NaN and the
//! infinities as strings, which JSON numbers cannot hold.

use crate::measure::error::{io_error, MeasureError};
use super::experiments::{Experiment, Experiments};
use crate::measure::model::Model;
use super::runner::Applied;
use std::path::Path;

/// The layout of saved results and job files; raise it whenever they change meaning.
pub const RESULT_FORMAT: u32 = 3;

/// The binary and result format a result was written by.
pub fn format() -> String {
    format!("strand {}, result format {RESULT_FORMAT}", env!("CARGO_PKG_VERSION"))
}

/// Hashes (xxh3-128, hex) of what one experiment's result depends on.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// [`format`] of the binary that computed it.
    pub format: String,
    /// The model as strand writes it ([`Model::to_toml`]): material and effects, every number.
    pub model: String,
    /// The experiment's resolved scenario: its file with the model's `[material]` and every key
    /// set, plus the G-code it reads; for a rheometer test, its protocol.
    pub scenario: String,
    /// The experiment's entry in the experiments file (overrides, covariates, observables).
    pub experiment: String,
}

pub fn hash(text: &str) -> String {
    format!("{:032x}", xxhash_rust::xxh3::xxh3_128(text.as_bytes()))
}

impl Provenance {
    /// The provenance of experiment `x` under `model` as the files stand now.
    pub fn of(model: &Model, exps: &Experiments, x: &Experiment) -> Provenance {
        Provenance::of_applied(&model.to_toml(), Applied::new(model, x).as_ref(), exps, x)
    }

    /// [`Provenance::of`] from what a job already holds: the model's text ([`Model::to_toml`])
    /// and the model applied to `x`, or why it could not be.
    pub fn of_applied(
        model_text: &str,
        applied: Result<&Applied, &MeasureError>,
        exps: &Experiments,
        x: &Experiment,
    ) -> Provenance {
        let entry = toml::to_string(x).unwrap_or_else(|e| format!("error: {e}"));
        Provenance {
            format: format(),
            model: hash(model_text),
            scenario: hash(&resolved(applied, exps, x)),
            experiment: hash(&entry),
        }
    }

    /// `saved` (read from `file`) must be this provenance: the error names experiment `id` and
    /// every part that differs.
    pub fn check(&self, saved: &Provenance, id: &str, file: &Path) -> Result<(), MeasureError> {
        let mut differ = Vec::new();
        if saved.format != self.format {
            differ.push(format!("another binary ({}; this is {})", saved.format, self.format));
        }
        for (what, a, b) in [
            ("model", &saved.model, &self.model),
            ("scenario", &saved.scenario, &self.scenario),
            ("experiments entry", &saved.experiment, &self.experiment),
        ] {
            if a != b {
                differ.push(format!("another {what} (hash {}, now {})", &a[..a.len().min(12)], &b[..b.len().min(12)]));
            }
        }
        if differ.is_empty() {
            return Ok(());
        }
        Err(MeasureError::Provenance(format!(
            "experiment '{id}': {} comes from {}; refusing it",
            file.display(),
            differ.join(" and ")
        )))
    }
}

/// The text a result of `x` depends on besides the model and its own entry: the resolved
/// scenario and its G-code, or the rheometer protocol; an error in resolving it is part of the
/// text (the evaluation fails the same way).
fn resolved(applied: Result<&Applied, &MeasureError>, exps: &Experiments, x: &Experiment) -> String {
    let r = match (&x.scenario, &x.protocol) {
        (Some(s), _) => {
            let path = exps.base_dir.join(s);
            match applied {
                Ok(applied) => applied.scenario_text(&path).map(|text| {
                    let gcode = gcode_of(&text, &path);
                    text + &gcode
                }),
                Err(e) => return format!("error: {e}"),
            }
        }
        (None, Some(toml::Value::String(file))) => {
            let p = exps.base_dir.join(file);
            std::fs::read_to_string(&p).map_err(io_error(&p))
        }
        (None, Some(inline)) => toml::to_string(inline).map_err(MeasureError::from),
        (None, None) => Err(MeasureError::Run("neither scenario nor protocol".into())),
    };
    r.unwrap_or_else(|e| format!("error: {e}"))
}

/// The G-code file a resolved scenario prints from (`print.gcode`, relative to the scenario),
/// as text to hash; empty without one.
fn gcode_of(text: &str, scenario: &Path) -> String {
    let doc: toml::Table = match text.parse() {
        Ok(d) => d,
        Err(_) => return String::new(),
    };
    // the toolpath file, G-code or a point list
    let key = ["gcode", "points"].into_iter().find(|k| doc.get("print").and_then(|p| p.get(k)).is_some());
    match key.and_then(|k| doc.get("print").and_then(|p| p.get(k)).and_then(|g| g.as_str()).map(|f| (k, f))) {
        Some((key, file)) => {
            let p = scenario.parent().unwrap_or(Path::new("")).join(file);
            let body = std::fs::read_to_string(&p).unwrap_or_else(|e| format!("error: {e}"));
            format!("\n# print.{key} {file}\n{body}")
        }
        None => String::new(),
    }
}

/// A saved number, read back to the same bits.
#[derive(Clone, Copy, Debug)]
pub struct Exact(pub f64);

impl serde::Serialize for Exact {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            v if v.is_finite() => s.serialize_f64(v),
            v if v.is_nan() => s.serialize_str("NaN"),
            v if v > 0.0 => s.serialize_str("inf"),
            _ => s.serialize_str("-inf"),
        }
    }
}

impl<'de> serde::Deserialize<'de> for Exact {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Exact, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Exact;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number, \"NaN\", \"inf\" or \"-inf\"")
            }
            fn visit_f64<E>(self, v: f64) -> Result<Exact, E> {
                Ok(Exact(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<Exact, E> {
                Ok(Exact(v as f64))
            }
            fn visit_u64<E>(self, v: u64) -> Result<Exact, E> {
                Ok(Exact(v as f64))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Exact, E> {
                match v {
                    "NaN" => Ok(Exact(f64::NAN)),
                    "inf" => Ok(Exact(f64::INFINITY)),
                    "-inf" => Ok(Exact(f64::NEG_INFINITY)),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
                }
            }
        }
        d.deserialize_any(V)
    }
}

pub fn exact(v: &[f64]) -> Vec<Exact> {
    v.iter().copied().map(Exact).collect()
}

pub fn plain(v: &[Exact]) -> Vec<f64> {
    v.iter().map(|e| e.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saved_numbers_read_back_to_the_same_bits() {
        let v =
            [0.1 + 0.2, -0.0, 5e-324, f64::MAX, 1.0 / 3.0, 2.5e-17, -7.0, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];
        let text = serde_json::to_string(&exact(&v)).unwrap();
        let back: Vec<Exact> = serde_json::from_str(&text).unwrap();
        for (a, b) in v.iter().zip(plain(&back)) {
            assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{a:e} came back as {b:e} from {text}");
        }
        assert!(serde_json::from_str::<Vec<Exact>>("[\"many\"]").is_err());
    }

    const MODEL: &str =
        "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";

    #[test]
    fn a_changed_model_scenario_gcode_or_entry_changes_the_provenance_and_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let scenario = "name = \"p\"\n[simulation]\ndx = 0.01\nend_time = 0.1\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = \
            [0.1, 0.1, 0.1]\n[material]\nkind = \"newtonian\"\ndensity = 1000.0\nbulk_modulus = 1e5\nviscosity = 1.0\n\
            [print]\ngcode = \"path.gcode\"\n";
        std::fs::write(d.join("s.toml"), scenario).unwrap();
        std::fs::write(d.join("path.gcode"), "G1 X10 Y0 E1\n").unwrap();
        let exps_text = "[[experiment]]\nid = \"P\"\nscenario = \"s.toml\"\nobserve = [\"width@0.05\"]\n\
            [[experiment]]\nid = \"R\"\nprotocol = { phase = [{ kind = \"shear\", rate = 5.0, duration = 0.5 }] }\n\
            observe = [\"stress@5\"]\n";
        std::fs::write(d.join("e.toml"), exps_text).unwrap();
        let exps = Experiments::load(&d.join("e.toml")).unwrap();
        let model = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let p = |m: &Model, e: &Experiments, id: &str| Provenance::of(m, e, e.get(id).unwrap());
        let base = p(&model, &exps, "P");
        assert_eq!(base, p(&model, &exps, "P"), "the same inputs give the same provenance");
        assert!(!base.scenario.starts_with("error"));
        let file = Path::new("r.json");
        assert!(base.check(&base, "P", file).is_ok());

        let mut other = model.clone();
        other.set("material.viscosity", 7.500000000000001).unwrap();
        let e = base.check(&p(&other, &exps, "P"), "P", file).unwrap_err().to_string();
        // the model reaches a simulation's scenario too (its [material] is the model's)
        assert!(
            e.contains("experiment 'P'")
                && e.contains("another model")
                && e.contains("another scenario")
                && !e.contains("entry"),
            "{e}"
        );

        std::fs::write(d.join("path.gcode"), "G1 X12 Y0 E1\n").unwrap();
        let e = p(&model, &exps, "P").check(&base, "P", file).unwrap_err().to_string();
        assert!(e.contains("another scenario") && !e.contains("another model"), "{e}");

        // a point list is hashed as a G-code file is
        std::fs::write(d.join("s.toml"), scenario.replace("gcode = \"path.gcode\"", "points = \"path.csv\"")).unwrap();
        std::fs::write(d.join("path.csv"), "x, y, z, speed, flow\n0, 0, 0, 1, 0\n0.1, 0, 0, 1, 1e-5\n").unwrap();
        let points = p(&model, &exps, "P");
        std::fs::write(d.join("path.csv"), "x, y, z, speed, flow\n0, 0, 0, 1, 0\n0.12, 0, 0, 1, 1e-5\n").unwrap();
        let e = p(&model, &exps, "P").check(&points, "P", file).unwrap_err().to_string();
        assert!(e.contains("another scenario"), "{e}");
        std::fs::write(d.join("s.toml"), scenario).unwrap();

        let rheo = p(&model, &exps, "R");
        std::fs::write(d.join("e.toml"), exps_text.replace("rate = 5.0", "rate = 5.5")).unwrap();
        let edited = Experiments::load(&d.join("e.toml")).unwrap();
        let e = p(&model, &edited, "R").check(&rheo, "R", file).unwrap_err().to_string();
        assert!(
            e.contains("experiment 'R'") && e.contains("another scenario") && e.contains("another experiments entry"),
            "{e}"
        );

        let mut old = base.clone();
        old.format = "strand 0.0.9, result format 0".into();
        let e = base.check(&old, "P", file).unwrap_err().to_string();
        assert!(e.contains("another binary (strand 0.0.9"), "{e}");
    }
}
