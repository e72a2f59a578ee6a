//! What was measured: observations and the observables they are of, and the measurements CSV.
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
//! `at` is where or when the observable is taken, `X`, or `X:Y` for one with a second coordinate
//! (`observables.rs` says what each observable's coordinates are). This file is the bottom of the
//! measurement loop: it imports nothing else of it.

use super::error::{io_error, MeasureError};
use std::path::Path;

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

/// `X` or `X:Y`, finite numbers, as the `at` of an observable; the error says what is wrong.
pub fn parse_at(a: &str) -> Result<(f64, Option<f64>), MeasureError> {
    let number = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| MeasureError::Observable(format!("'{}' is not a number", v.trim())))
    };
    let mut parts = a.split(':');
    let at = number(parts.next().unwrap_or(""))?;
    let at2 = parts.next().map(number).transpose()?;
    if parts.next().is_some() {
        return Err(MeasureError::Observable(format!("'{}' has more than two coordinates (X or X:Y)", a.trim())));
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
    pub fn parse(s: &str) -> Result<Observable, MeasureError> {
        let (name, at, at2) = match s.split_once('@') {
            Some((n, a)) => {
                let (at, at2) = parse_at(a).map_err(|e| e.within(format!("'{s}'")))?;
                (n.trim(), Some(at), at2)
            }
            None => (s.trim(), None, None),
        };
        if name.is_empty() {
            return Err(MeasureError::Observable(format!("'{s}': no observable name before '@'")));
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
pub fn read_observations(path: &Path) -> Result<Vec<Observation>, MeasureError> {
    let text = std::fs::read_to_string(path).map_err(io_error(path))?;
    parse_observations(&text).map_err(|e| e.within(path.display()))
}

pub fn parse_observations(text: &str) -> Result<Vec<Observation>, MeasureError> {
    let mut rd = csv::ReaderBuilder::new().trim(csv::Trim::All).comment(Some(b'#')).from_reader(text.as_bytes());
    let header: Vec<String> = rd.headers()?.iter().map(str::to_string).collect();
    let want = ["experiment", "observable", "at", "value", "uncertainty"];
    let col = |name: &str| {
        header.iter().position(|h| h == name).ok_or_else(|| {
            MeasureError::Observations(format!("no '{name}' column (the columns are {})", want.join(",")))
        })
    };
    let idx: Vec<usize> = want.iter().map(|w| col(w)).collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec?;
        let line = rec.position().map_or(0, |p| p.line());
        let field = |k: usize| rec.get(idx[k]).unwrap_or("");
        let number = |k: usize| -> Result<f64, MeasureError> {
            field(k).parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                MeasureError::Observations(format!("line {line}: {} '{}' is not a number", want[k], field(k)))
            })
        };
        let (at, at2) = if field(2).is_empty() {
            (None, None)
        } else {
            let (a, b) = parse_at(field(2)).map_err(|e| {
                MeasureError::Observations(format!(
                    "line {line}: at {e} (X, or X:Y for profile@X:Y and layer_height@X:K)"
                ))
            })?;
            (Some(a), b)
        };
        let uncertainty = number(4)?;
        if uncertainty <= 0.0 {
            return Err(MeasureError::Observations(format!("line {line}: uncertainty must be > 0, got {uncertainty}")));
        }
        if field(0).is_empty() || field(1).is_empty() {
            return Err(MeasureError::Observations(format!("line {line}: experiment and observable must not be empty")));
        }
        out.push(Observation {
            experiment: field(0).to_string(),
            observable: Observable { name: field(1).to_string(), at, at2 },
            value: number(3)?,
            uncertainty,
        });
    }
    if out.is_empty() {
        return Err(MeasureError::Observations("no observations".into()));
    }
    Ok(out)
}

/// Write observations as the tidy CSV `read_observations` reads.
pub fn write_observations(path: &Path, obs: &[Observation]) -> Result<(), MeasureError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| MeasureError::from(e).within(path.display()))?;
    let err = |e: csv::Error| MeasureError::from(e).within(path.display());
    w.write_record(["experiment", "observable", "at", "value", "uncertainty"]).map_err(err)?;
    for o in obs {
        let at = at_text(o.observable.at, o.observable.at2);
        w.write_record([
            o.experiment.clone(),
            o.observable.name.clone(),
            at,
            format!("{:e}", o.value),
            format!("{:e}", o.uncertainty),
        ])
        .map_err(err)?;
    }
    w.flush().map_err(io_error(path))
}

/// A TOML number as f64 (integers too); None for anything else.
pub fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or(v.as_integer().map(|i| i as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observations_round_trip_and_bad_rows_name_their_line() {
        let text = "experiment,observable,at,value,uncertainty\nSF240,spread,,0.5,0.01\n# a comment\ncase1, width \
            ,0.016,0.0301,5e-4\n";
        let obs = parse_observations(text).unwrap();
        assert_eq!(obs.len(), 2);
        assert_eq!(obs[1].observable, Observable { name: "width".into(), at: Some(0.016), at2: None });
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.csv");
        write_observations(&p, &obs).unwrap();
        assert_eq!(read_observations(&p).unwrap(), obs);
        let e =
            parse_observations("experiment,observable,at,value,uncertainty\nA,spread,,0.5,0.01\nB,spread,,zero,0.01\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("line 3") && e.contains("value 'zero'"), "{e}");
        let e = parse_observations("experiment,observable,at,value,uncertainty\nA,spread,,0.5,0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("uncertainty"), "{e}");
        let e = parse_observations("experiment,observable,value\nA,spread,0.5\n").unwrap_err().to_string();
        assert!(e.contains("no 'at' column"), "{e}");
    }

    #[test]
    fn a_second_coordinate_parses_prints_back_and_bad_ones_are_named() {
        let o = Observable::parse("profile@0.075:0.01").unwrap();
        assert_eq!(o, Observable { name: "profile".into(), at: Some(0.075), at2: Some(0.01) });
        for s in [
            "profile@0.075:0.01",
            "profile@0.075:-0.002",
            "layer_height@0.075:2",
            "layer_width@0.03:1",
            "width@0.016",
            "spread",
        ] {
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
            let e = Observable::parse(bad).unwrap_err().to_string();
            assert!(e.starts_with(&format!("'{bad}': ")) && e.contains(want), "{bad}: {e}");
        }
        // in the measurements CSV the at column holds X:Y
        let text = "experiment,observable,at,value,uncertainty\ncase1,profile,0.075:0.01,0.012,5e-4\n\
            case1,layer_height,0.075:2,0.006,2e-4\ncase1,height,0.075,0.018,5e-4\n";
        let obs = parse_observations(text).unwrap();
        let names: Vec<String> = obs.iter().map(|o| o.observable.to_string()).collect();
        assert_eq!(names, ["profile@0.075:0.01", "layer_height@0.075:2", "height@0.075"]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.csv");
        write_observations(&p, &obs).unwrap();
        assert!(std::fs::read_to_string(&p).unwrap().contains("case1,profile,0.075:0.01,"));
        assert_eq!(read_observations(&p).unwrap(), obs);
        let e = parse_observations("experiment,observable,at,value,uncertainty\ncase1,profile,0.075:y,0.012,5e-4\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("at 'y' is not a number"), "{e}");
    }
}
