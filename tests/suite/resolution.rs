//! The discretisation error through `strand compare` (`src/measure/resolution.rs`): the small
//! slump of `fixtures/measure/slump/` at 4 cm cells measured by its own 2 cm run, with and
//! without the experiments' `[resolution]` table, and bad tables named; and a fit that starts
//! from the estimate's runs at the model.

use std::path::Path;
use crate::common::{strand_in};

const EXPERIMENTS: &str = r#"
[[experiment]]
id = "SF"
scenario = "slump.toml"
set = { "simulation.dx" = 0.04, "simulation.end_time" = 0.1 }
observe = ["spread", "mean_z"]

[[experiment]]
id = "flow"
observe = ["stress@10"]
[experiment.protocol]
[[experiment.protocol.phase]]
kind = "sweep"
rates = [10.0]
hold = 0.5
"#;

const MODEL: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = 0.3\nviscosity = 50.0\nyield_stress = 100.0\n";

fn compare_json(d: &Path, exps: &str) -> serde_json::Value {
    let (code, out, err) = strand_in(&["compare", "--model", "model.toml", "--data", "data.csv", "--experiments", exps, "--json"], d);
    assert_eq!(code, 0, "{err}");
    serde_json::from_str(&out).unwrap()
}

#[test]
fn measurements_of_the_finer_run_are_explained_by_the_estimated_discretisation_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/slump/slump.toml"), d.join("slump.toml")).unwrap();
    std::fs::write(d.join("model.toml"), MODEL).unwrap();
    // the "measurements": the same model at 2 cm cells, 1 % uncertainty
    std::fs::write(d.join("fine.toml"), EXPERIMENTS.replace("\"simulation.dx\" = 0.04", "\"simulation.dx\" = 0.02")).unwrap();
    let (code, _, err) = strand_in(&["synth", "--model", "model.toml", "--experiments", "fine.toml", "--noise", "0.01", "--seed", "3", "--out", "data.csv"], d);
    assert_eq!(code, 0, "{err}");
    std::fs::write(d.join("coarse.toml"), EXPERIMENTS).unwrap();
    std::fs::write(d.join("counted.toml"), format!("{EXPERIMENTS}\n[resolution]\nfine = {{ \"simulation.dx\" = 0.02 }}\norder = 1.0\n")).unwrap();

    let fine = compare_json(d, "fine.toml");
    let coarse = compare_json(d, "coarse.toml");
    let counted = compare_json(d, "counted.toml");
    let rows = |v: &serde_json::Value| v["rows"].as_array().unwrap().clone();
    let (fine, coarse, counted) = (rows(&fine), rows(&coarse), rows(&counted));
    let num = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap_or_else(|| panic!("{k} in {r}"));
    // the 4 cm model misses its own 2 cm values by far more than the uncertainty ...
    assert!(coarse[..2].iter().any(|r| num(r, "z").abs() > 3.0), "{coarse:?}");
    for k in 0..2 {
        let (c, f, r) = (num(&coarse[k], "model"), num(&fine[k], "model"), &counted[k]);
        // ... by what Richardson at order 1 and ratio 2 estimates: e = (f_h - f_h/2) 2 / (2 - 1)
        assert_eq!(num(r, "model"), c);
        let e = num(r, "discretisation");
        assert!((e - 2.0 * (c - f)).abs() <= 1e-12 * e.abs().max(1e-300), "{r} against coarse {c} fine {f}");
        let sigma = num(r, "uncertainty").hypot(e);
        assert!((num(r, "z") - num(r, "residual") / sigma).abs() < 1e-12, "{r}");
        // counted, the cell size explains the misfit: |z| within the noise
        assert!(num(r, "z").abs() < 1.5, "{r}");
    }
    // a rheometer reading has no cells: no error, z as before
    assert!(counted[2].get("discretisation").is_none(), "{:?}", counted[2]);
    assert_eq!(num(&counted[2], "z"), num(&coarse[2], "z"));

    // the text report shows the error beside z, and the estimates with their runs
    let (code, out, err) = strand_in(&["compare", "--model", "model.toml", "--data", "data.csv", "--experiments", "counted.toml"], d);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("discretisation error (Richardson, order p = 1") && out.contains("discretis.") && out.contains("extrapolated"), "{out}");
    assert!(out.contains("with the discretisation error counted"), "{out}");

    // bad tables are named
    for (table, want) in [
        ("fine = { \"simulation.end_time\" = 0.1 }", "fine must set \"simulation.dx\""),
        ("fine = { \"simulation.dx\" = \"fine\" }", "fine.\"simulation.dx\" must be a number"),
        ("fine = { \"simulation.dx\" = 0.02 }\norder = -1.0", "order must be an order of convergence"),
        ("fine = { \"simulation.dx\" = 0.02 }\norders = 1.0", "unknown field `orders`"),
        ("order = 1.0", "missing field `fine`"),
        ("fine = { \"simulation.dx\" = 0.08 }", "is not finer than the cell size the model runs it at, 0.04"),
    ] {
        std::fs::write(d.join("bad.toml"), format!("{EXPERIMENTS}\n[resolution]\n{table}\n")).unwrap();
        let (code, _, err) = strand_in(&["compare", "--model", "model.toml", "--data", "data.csv", "--experiments", "bad.toml"], d);
        assert_eq!(code, 2, "{table}: {err}");
        assert!(err.contains(want), "{table}: {err}");
    }
}

/// The estimate's runs at the model are a fit's runs (fixed step, all awake): a fit started from
/// their values (`calibrate_at`, as calibrate and diagnose start) is the fit that runs its start
/// itself, bit for bit, and one started from other values is not.
#[test]
fn a_fit_from_the_estimates_runs_is_the_fit_that_runs_its_start() {
    use strand::measure::calibrate::{calibrate, calibrate_at, Fit};
    use strand::measure::campaign::{Campaign, FitOptions};
    use strand::measure::{experiments::Experiments, model::Model, resolution::counted_data, synth::synth};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/slump/slump.toml"), d.join("slump.toml")).unwrap();
    std::fs::write(d.join("counted.toml"), format!("{EXPERIMENTS}\n[resolution]\nfine = {{ \"simulation.dx\" = 0.02 }}\norder = 1.0\n")).unwrap();
    let exps = Experiments::load(&d.join("counted.toml")).unwrap();
    let truth = Model::from_table(&MODEL.parse().unwrap()).unwrap();
    let start = Model::from_table(&MODEL.replace("viscosity = 50.0", "viscosity = 35.0").replace("yield_stress = 100.0", "yield_stress = 130.0").parse().unwrap()).unwrap();
    let (data, counted) = counted_data(&start, synth(&truth, &exps, 0.01, 3, 2).unwrap(), &exps, 2).unwrap();
    let at_model = counted.expect("a [resolution] table").start_values;
    let names = ["material.yield_stress".to_string(), "material.viscosity".to_string()];
    let opts = FitOptions { jobs: 2, ..FitOptions::default() };
    let c = Campaign::new(&exps, &data, &opts);
    let itself = calibrate(&c, &start, &names).unwrap();
    let from_runs = calibrate_at(&c, &start, Some(&at_model), &names).unwrap();
    let what = |f: &Fit| (f.at_start.values.clone(), f.at_start.jacobian.clone(), f.history.clone(), f.values.clone(), f.model_values.clone(), f.jacobian.clone(), f.uncertainty.clone());
    assert!(itself.history.len() > 1, "the fit took a step: {:?}", itself.history);
    assert_eq!(what(&from_runs), what(&itself));
    // the values given are the ones taken
    let shifted: Vec<f64> = at_model.iter().map(|v| v * 1.001).collect();
    let no_steps = FitOptions { max_iterations: 0, ..opts.clone() };
    assert_ne!(calibrate_at(&c.with_opts(&no_steps), &start, Some(&shifted), &names).unwrap().at_start.values, itself.at_start.values);
}
