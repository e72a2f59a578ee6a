//! `strand synth` and `strand compare` end to end: a slump simulation (spread during and after the
//! run, with a per-experiment override) and a rheometer flow curve, synthesised from one model and
//! compared against it and against another.

use std::path::Path;
use crate::common::{strand_in};
use std::process::Command;

const SLUMP: &str = r#"
name = "slump-measure"
[simulation]
dx = 0.02
end_time = 0.15
dt = 2e-4
gravity = [0.0, 0.0, -9.81]
[domain]
min = [-0.3, -0.3, 0.0]
max = [0.3, 0.3, 0.32]
[boundary]
z_min = "no_slip"
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 1.0e5
viscosity = 1.0
[[body]]
shape = "frustum"
base_center = [0.0, 0.0, 0.0]
bottom_radius = 0.1
top_radius = 0.05
height = 0.3
[memory]
budget = "128 MiB"
"#;

const EXPERIMENTS: &str = r#"
[[experiment]]
id = "SF"
scenario = "slump.toml"
observe = ["spread@0.05", "spread"]

[[experiment]]
id = "SF-stiff"
scenario = "slump.toml"
set = { "material.yield_stress" = 400.0 }
observe = ["spread"]

[[experiment]]
id = "flow"
observe = ["stress@10", "stress@1"]
[experiment.protocol]
[[experiment.protocol.phase]]
kind = "sweep"
rates = [10.0, 1.0]
hold = 0.5
"#;

const TRUTH: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = 0.3\nviscosity = 50.0\nyield_stress = 100.0\n";

#[test]
fn synthesised_measurements_compare_to_their_model_exactly_and_to_another_not() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("slump.toml"), SLUMP).unwrap();
    std::fs::write(d.join("exps.toml"), EXPERIMENTS).unwrap();
    std::fs::write(d.join("truth.toml"), TRUTH).unwrap();
    std::fs::write(d.join("other.toml"), TRUTH.replace("yield_stress = 100.0", "yield_stress = 200.0")).unwrap();

    let (code, _, err) = strand_in(&["synth", "--model", "truth.toml", "--experiments", "exps.toml", "--out", "data.csv", "--jobs", "2"], d);
    assert_eq!(code, 0, "{err}");
    let csv = std::fs::read_to_string(d.join("data.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 5, "{csv}");

    // the model that made the data: every residual zero (the scenario's own Newtonian material
    // was replaced by the model's, whatever the number of jobs)
    let (code, out, err) = strand_in(&["compare", "--model", "truth.toml", "--data", "data.csv", "--experiments", "exps.toml", "--json", "--jobs", "2"], d);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 5);
    assert!(rows.iter().all(|r| r["residual"].as_f64() == Some(0.0)), "{out}");
    let spread = |id: &str, at: Option<f64>| rows.iter().find(|r| r["experiment"] == id && r["at"].as_f64() == at).unwrap()["model"].as_f64().unwrap();
    // the slump spreads as it runs, and less with the override's higher yield stress
    assert!(spread("SF", None) > spread("SF", Some(0.05)), "{out}");
    assert!(spread("SF-stiff", None) < spread("SF", None), "{out}");

    // a stiffer model under-predicts the spreads and over-predicts the stresses
    let (code, out, err) = strand_in(&["compare", "--model", "other.toml", "--data", "data.csv", "--experiments", "exps.toml"], d);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("where the model fails most") && out.contains("per experiment") && out.contains("over-predicts"), "{out}");
    let (_, out, _) = strand_in(&["compare", "--model", "other.toml", "--data", "data.csv", "--experiments", "exps.toml", "--json"], d);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["chi2"].as_f64().unwrap() > 1e6, "{out}");

    // bad input names the problem
    std::fs::write(d.join("bad.csv"), "experiment,observable,at,value,uncertainty\nSF,spread,,0.3,0.01\nSF,spread,,wide,0.01\n").unwrap();
    let (code, _, err) = strand_in(&["compare", "--model", "truth.toml", "--data", "bad.csv", "--experiments", "exps.toml"], d);
    assert_eq!(code, 2);
    assert!(err.contains("bad.csv") && err.contains("line 3"), "{err}");
    std::fs::write(d.join("ghost.csv"), "experiment,observable,at,value,uncertainty\nSF9,spread,,0.3,0.01\n").unwrap();
    let (code, _, err) = strand_in(&["compare", "--model", "truth.toml", "--data", "ghost.csv", "--experiments", "exps.toml"], d);
    assert_eq!(code, 2);
    assert!(err.contains("'SF9'") && err.contains("SF, SF-stiff, flow"), "{err}");
}

#[test]
fn the_rheometer_prints_a_flow_curve_and_its_sensitivities() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (code, out, err) = strand_in(&["rheometer", "fixtures/rheometer/mix_a.toml", "--sensitivity", "--json"], root);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let r = v["readings"].as_array().unwrap();
    assert_eq!(r.len(), 8);
    // at 50 /s the structure is broken down: tau0 + eta gamma_dot within 1 %
    let fast = r.iter().find(|x| x["rate"] == 50.0).unwrap();
    assert!((fast["stress"].as_f64().unwrap() / (92.0 + 19.5 * 50.0) - 1.0).abs() < 0.01, "{fast}");
    assert!((fast["d_stress"]["viscosity"].as_f64().unwrap() - 50.0).abs() < 0.1, "{fast}");
    let (code, _, err) = strand_in(&["rheometer", "fixtures/scenarios/slump.toml"], root);
    assert_eq!(code, 2);
    assert!(err.contains("no [rheometer] table"), "{err}");
}

#[test]
fn planned_jobs_collected_compare_exactly_as_a_local_run() {
    let fx = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/campaign");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let exps = fx.join("experiments.toml");
    let (e, m) = (exps.to_str().unwrap(), fx.join("base.toml"));
    let truth = fx.join("truth_thixotropy.toml");
    let (code, _, err) = strand_in(&["synth", "--model", truth.to_str().unwrap(), "--experiments", e, "--noise", "0.01", "--seed", "5", "--out", "data.csv"], d);
    assert_eq!(code, 0, "{err}");
    let args = ["compare", "--model", m.to_str().unwrap(), "--data", "data.csv", "--experiments", e, "--json"];
    let (code, local, err) = strand_in(&args, d);
    assert_eq!(code, 0, "{err}");

    let (code, _, err) = strand_in(&[&args[..], &["--plan", "jobs"]].concat(), d);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<String> = std::fs::read_to_string(d.join("jobs/jobs.txt")).unwrap().lines().map(str::to_string).collect();
    assert_eq!(lines.len(), 6, "{lines:?}");
    assert!(std::fs::read_to_string(d.join("jobs/slurm.sh")).unwrap().contains("--array=1-6"));
    // collecting before every job ran names the one missing
    for line in &lines[..5] {
        let o = Command::new("bash").arg("-c").arg(line).current_dir("/").output().unwrap();
        assert!(o.status.success(), "{line}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let (code, _, err) = strand_in(&[&args[..], &["--collect", "jobs"]].concat(), d);
    assert_ne!(code, 0);
    assert!(err.contains("experiment 'F' has no result"), "{err}");
    let o = Command::new("bash").arg("-c").arg(&lines[5]).output().unwrap();
    assert!(o.status.success());
    let (code, collected, err) = strand_in(&[&args[..], &["--collect", "jobs"]].concat(), d);
    assert_eq!(code, 0, "{err}");
    assert_eq!(collected, local);

    let (code, _, err) = strand_in(&["compare", "--model", m.to_str().unwrap(), "--data", "data.csv", "--experiments", e, "--only", "Z", "--save", "z.json"], d);
    assert_ne!(code, 0);
    assert!(err.contains("--only Z") && err.contains("A, B, C, D, E, F"), "{err}");
}

#[test]
fn printed_profile_points_and_layers_measured_by_synth_are_what_the_run_writes() {
    // The measurement loop's profile@X:Y, layer_height@X:K and layer_width@X:K of the two-layer
    // print against the run's own profiles.csv and layers.csv, then compared with another model.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/grad/two_layers.toml");
    std::fs::copy(&fixture, d.join("print.toml")).unwrap();
    let ys = [-0.006, -0.0025, 0.0, 0.004, 0.0055, 0.0068];
    let mut observe: Vec<String> = ys.iter().map(|y| format!("\"profile@0.015:{y}\"")).collect();
    observe.extend(["\"layer_height@0.015:1\"", "\"layer_height@0.015:2\"", "\"layer_width@0.015:1\""].map(String::from));
    std::fs::write(d.join("exps.toml"), format!("[[experiment]]\nid = \"P\"\nscenario = \"print.toml\"\nobserve = [{}]\n", observe.join(", "))).unwrap();
    let truth = "[material]\nkind = \"evp_bingham\"\ndensity = 2100.0\nbulk_modulus = 2.0e5\npoisson_ratio = 0.3\nviscosity = 20.0\nyield_stress = 100.0\n";
    std::fs::write(d.join("truth.toml"), truth).unwrap();
    std::fs::write(d.join("other.toml"), truth.replace("yield_stress = 100.0", "yield_stress = 150.0")).unwrap();

    let (code, _, err) = strand_in(&["run", "print.toml", "--out", "out", "--quiet"], d);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = strand_in(&["synth", "--model", "truth.toml", "--experiments", "exps.toml", "--out", "data.csv"], d);
    assert_eq!(code, 0, "{err}");
    let csv = std::fs::read_to_string(d.join("data.csv")).unwrap();
    assert!(csv.contains("P,profile,0.015:0.004,") && csv.contains("P,layer_height,0.015:2,"), "{csv}");
    let data = strand::measure::observation::read_observations(&d.join("data.csv")).unwrap();
    assert_eq!(data.len(), ys.len() + 3);

    // the run's outline at its last output (the base is the floor, z = 0)
    let profiles = std::fs::read_to_string(d.join("out/profiles.csv")).unwrap();
    let rows: Vec<Vec<f64>> = profiles.lines().skip(1).map(|l| l.split(',').map(|f| f.parse().unwrap()).collect()).collect();
    let last = rows.iter().map(|r| r[0]).fold(f64::MIN, f64::max);
    assert!((last - 1.0).abs() < 1e-9, "{last}");
    let outline: Vec<[f64; 2]> = rows.iter().filter(|r| r[0] == last).map(|r| [r[2], r[3]]).collect();
    for (o, y) in data.iter().zip(ys) {
        assert_eq!((o.observable.name.as_str(), o.observable.at2), ("profile", Some(y)));
        let z = strand::observe::profile_z_at(&outline, y).unwrap();
        assert!(z > 0.004 && (o.value - z).abs() <= 1e-12, "profile@0.015:{y}: synth {} against the run's outline {z}", o.value);
    }
    // layers.csv: time,station,layer,thickness,total_height (9 digits)
    let layers = std::fs::read_to_string(d.join("out/layers.csv")).unwrap();
    let thickness: Vec<f64> = layers.lines().skip(1).map(|l| l.split(',').collect::<Vec<_>>()).filter(|f| f[0].parse::<f64>().unwrap() == last).map(|f| f[3].parse().unwrap()).collect();
    assert_eq!(thickness.len(), 2, "{layers}");
    for k in 0..2 {
        let o = &data[ys.len() + k];
        assert!((o.value - thickness[k]).abs() <= 1e-11, "layer_height@0.015:{}: synth {} against layers.csv {}", k + 1, o.value, thickness[k]);
    }
    assert!(data[ys.len() + 2].value > 0.01, "{:?}", data[ys.len() + 2]);

    // a stiffer model stands taller; the report plots the profile against y
    let (code, out, err) = strand_in(&["compare", "--model", "other.toml", "--data", "data.csv", "--experiments", "exps.toml", "--report", "rep"], d);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("0.015:0.004") && out.contains("over-predicts"), "{out}");
    for f in ["model_vs_data_profile.png", "model_vs_data_layer_height.png", "model_vs_data_layer_width.png", "index.html"] {
        assert!(d.join("rep").join(f).exists(), "{f}");
    }
}
