//! The model against measurements (`strand compare`): each observation's residual and z-score,
//! their summaries per experiment and per observable, and chi^2, the loss a calibration
//! minimises. The model's values come from the runner (`campaign/runner.rs`).
//!
//! In: data and the model's values of them. Out: the comparison, as text and JSON, or as a
//! folder of plots (`report.rs`); its jobs across machines (`plan.rs`); synthetic data from a
//! model (`synth.rs`).

pub mod plan;
pub mod report;
pub mod synth;

use super::error::MeasureError;
use super::campaign::experiments::Experiments;
use super::model::Model;
use super::observation::{at_text, Observable, Observation};
use super::campaign::runner::model_values;

/// One observation against the model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    pub experiment: String,
    pub observable: String,
    pub at: Option<f64>,
    /// The second coordinate (`profile@X:Y`'s y, `layer_height@X:K`'s layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at2: Option<f64>,
    pub measured: f64,
    pub uncertainty: f64,
    pub model: f64,
    /// model - measured.
    pub residual: f64,
    /// residual / uncertainty, or with the discretisation error added in quadrature:
    /// residual / sqrt(uncertainty^2 + discretisation^2).
    pub z: f64,
    /// The model's estimated discretisation error (`resolution.rs`): its value at its cell size
    /// minus the Richardson extrapolation; absent without `[resolution]` and for rheometer tests.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub discretisation: Option<f64>,
}

impl Row {
    /// Where the observation was taken, as a table cell: `X`, `X:Y`, or `-` for none.
    pub fn at_cell(&self) -> String {
        if self.at.is_some() {
            at_text(self.at, self.at2)
        } else {
            "-".to_string()
        }
    }

    /// The observable as written in the data: `name`, `name@X` or `name@X:Y`.
    pub fn label(&self) -> String {
        Observable { name: self.observable.clone(), at: self.at, at2: self.at2 }.to_string()
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Summary {
    pub name: String,
    pub n: usize,
    /// sqrt(mean z^2).
    pub rms_z: f64,
    /// Mean |residual| / |measured|.
    pub mean_rel_error: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Comparison {
    pub rows: Vec<Row>,
    pub by_experiment: Vec<Summary>,
    pub by_observable: Vec<Summary>,
    /// Sum of z^2: the loss a calibration minimises.
    pub chi2: f64,
}

fn summarise<'a>(rows: impl Iterator<Item = &'a Row>, key: impl Fn(&Row) -> String) -> Vec<Summary> {
    let mut out: Vec<(String, Vec<&Row>)> = Vec::new();
    for r in rows {
        let k = key(r);
        match out.iter_mut().find(|(n, _)| *n == k) {
            Some((_, v)) => v.push(r),
            None => out.push((k, vec![r])),
        }
    }
    out.into_iter()
        .map(|(name, rs)| {
            let n = rs.len();
            let rms_z = (rs.iter().map(|r| r.z * r.z).sum::<f64>() / n as f64).sqrt();
            let mean_rel_error = rs.iter().map(|r| (r.residual / r.measured).abs()).sum::<f64>() / n as f64;
            Summary { name, n, rms_z, mean_rel_error }
        })
        .collect()
}

/// Run every experiment the data name and compare.
pub fn compare(
    model: &Model,
    data: &[Observation],
    exps: &Experiments,
    jobs: usize,
) -> Result<Comparison, MeasureError> {
    Ok(comparison(data, &model_values(model, data, exps, jobs)?))
}

/// The comparison of `data` with the model's values of it.
pub fn comparison(data: &[Observation], values: &[f64]) -> Comparison {
    comparison_with_discretisation(data, values, &vec![None; data.len()])
}

/// The comparison with each observation's discretisation error (if any) added in quadrature to
/// its uncertainty in z.
pub fn comparison_with_discretisation(
    data: &[Observation],
    values: &[f64],
    discretisation: &[Option<f64>],
) -> Comparison {
    let rows: Vec<Row> = data
        .iter()
        .zip(values)
        .zip(discretisation)
        .map(|((o, &model), &d)| {
            let residual = model - o.value;
            let sigma = o.uncertainty.hypot(d.unwrap_or(0.0));
            Row {
                experiment: o.experiment.clone(),
                observable: o.observable.name.clone(),
                at: o.observable.at,
                at2: o.observable.at2,
                measured: o.value,
                uncertainty: o.uncertainty,
                model,
                residual,
                z: residual / sigma,
                discretisation: d,
            }
        })
        .collect();
    let by_experiment = summarise(rows.iter(), |r| r.experiment.clone());
    let by_observable = summarise(rows.iter(), |r| r.observable.clone());
    let chi2 = rows.iter().map(|r| r.z * r.z).sum();
    Comparison { rows, by_experiment, by_observable, chi2 }
}

/// The comparison as text: every observation, the summaries, and where the model fails most.
pub fn report(c: &Comparison) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // the discretisation column only when the experiments declare [resolution]
    let counted = c.rows.iter().any(|r| r.discretisation.is_some());
    let cell = |r: &Row| match (counted, r.discretisation) {
        (false, _) => String::new(),
        (true, Some(d)) => format!(" {d:>13.4e}"),
        (true, None) => format!(" {:>13}", "-"),
    };
    let head = if counted { format!(" {:>13}", "discretis.") } else { String::new() };
    let _ = writeln!(
        s,
        "{:<14} {:<16} {:>10} {:>13} {:>13} {:>13}{head} {:>8}",
        "experiment", "observable", "at", "measured", "model", "residual", "z"
    );
    for r in &c.rows {
        let _ = writeln!(
            s,
            "{:<14} {:<16} {:>10} {:>13.6e} {:>13.6e} {:>13.4e}{} {:>8.2}",
            r.experiment,
            r.observable,
            r.at_cell(),
            r.measured,
            r.model,
            r.residual,
            cell(r),
            r.z
        );
    }
    if counted {
        let _ = writeln!(
            s,
            "(discretis.: the model's estimated discretisation error, added in quadrature to the uncertainty in z)"
        );
    }
    for (title, list) in [("per experiment", &c.by_experiment), ("per observable", &c.by_observable)] {
        let _ = writeln!(s, "\n{title}:");
        for m in list {
            let _ = writeln!(
                s,
                "  {:<16} n = {:<4} rms z = {:<10.3} mean |relative error| = {:.2} %",
                m.name,
                m.n,
                m.rms_z,
                100.0 * m.mean_rel_error
            );
        }
    }
    let mut worst: Vec<&Row> = c.rows.iter().collect();
    worst.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    let _ = writeln!(s, "\nwhere the model fails most (largest |z|):");
    for r in worst.iter().take(5) {
        let dir = if r.residual > 0.0 { "over" } else { "under" };
        let _ = writeln!(
            s,
            "  {} {}: z = {:.2} (model {dir}-predicts by {:.2} %)",
            r.experiment,
            r.label(),
            r.z,
            100.0 * (r.residual / r.measured).abs()
        );
    }
    let _ = writeln!(s, "\nchi^2 = {:.6e} over {} observations", c.chi2, c.rows.len());
    s
}

#[cfg(test)]
mod tests {
    use super::super::campaign::runner::fixture::{setup, MODEL};
    use super::synth::synth;
    use super::*;

    #[test]
    fn synthetic_data_of_the_model_itself_has_no_residual_and_another_model_has() {
        let (m, e) = setup();
        let data = synth(&m, &e, 0.0, 1, 2).unwrap();
        assert_eq!(data.len(), 3);
        // tau0 + eta gamma_dot, the override reaching the second experiment only
        let expect = [630.0 + 7.5 * 20.0, 630.0 + 7.5 * 5.0, 300.0 + 7.5 * 5.0];
        for (o, x) in data.iter().zip(expect) {
            assert!((o.value / x - 1.0).abs() < 1e-3, "{o:?} vs {x}");
        }
        let c = compare(&m, &data, &e, 1).unwrap();
        assert!(c.rows.iter().all(|r| r.residual == 0.0), "{c:?}");
        let other = Model::from_table(&MODEL.replace("viscosity = 7.5", "viscosity = 9.0").parse().unwrap()).unwrap();
        let c = compare(&other, &data, &e, 1).unwrap();
        assert!(c.rows.iter().all(|r| r.residual > 0.0) && c.chi2 > 0.0, "{c:?}");
        let text = report(&c);
        assert!(text.contains("where the model fails most") && text.contains("flow stress@20"), "{text}");
    }

    #[test]
    fn the_report_shows_both_coordinates() {
        let data: Vec<Observation> = ["profile@0.075:0.01", "layer_height@0.075:2"]
            .iter()
            .map(|s| Observation {
                experiment: "print".into(),
                observable: Observable::parse(s).unwrap(),
                value: 0.01,
                uncertainty: 1e-4,
            })
            .collect();
        let c = comparison(&data, &[0.011, 0.012]);
        assert_eq!((c.rows[0].at, c.rows[0].at2), (Some(0.075), Some(0.01)));
        let text = report(&c);
        assert!(text.contains("print profile@0.075:0.01: z = 10.00") && text.contains("0.075:2"), "{text}");
        let json = serde_json::to_value(&c).unwrap();
        assert_eq!(json["rows"][1]["at2"], 2.0);
    }
}
