//! The measurement loop on printed layers (issue 26): the process effects' toolpath keys against
//! central differences, and print campaigns with a hidden effect, synthesised at finer cells than
//! the model runs at, diagnosed from a base model started away from the truth.

use std::path::Path;
use strand::grad::check::check;
use strand::grad::{gradient, GradOptions};
use strand::observables::Objective;
use strand::scenario::Scenario;
use crate::common::{strand, s, measure_fixtures};

#[test]
fn the_extrusion_factor_and_the_z_offset_gradients_match_central_differences() {
    // a Newtonian strand on a no-slip floor: on the EVP first layer of two_layers.toml behind its
    // symmetry wall the z offset's central differences do not settle (area@0.015: -7.11e-3 at
    // h = 5e-6 m, -4.66e-3 at 5e-7, against the adjoint's -7.38e-3; measured), likely because
    // the outlet's height moves which nodes the tube drives, an event the adjoint holds fixed.
    // Here (measured): best agreement 2.6e-4 (extrusion factor) and 3.5e-8 (z offset) on
    // area@0.01, 1.8e-4 and 1.2e-6 on height@0.01; 45 s on the shared 2-core machine
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/grad/process_keys.toml");
    let sc = Scenario::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = GradOptions { ram_bytes: 1 << 30, disk_bytes: 0, disk_dir: dir.path().to_path_buf(), threads: None, schedule: None, until_rest: None };
    let wrt: Vec<String> = ["print.extrusion_factor", "print.z_offset"].iter().map(|s| s.to_string()).collect();
    // the flow sets the section's area; the standoff its height
    for name in ["area@0.01", "height@0.01"] {
        let obj: Objective = name.parse().unwrap();
        let r = gradient(&sc, &obj, &wrt, &opts).unwrap();
        let c = check(&sc, &obj, &r, None, &[1e-2, 1e-3]).unwrap();
        for p in &c.params {
            println!("d {name} / d {} = {:.6e}, central differences {:?}", p.param, p.adjoint, p.central);
            let best = p.central.iter().map(|x| x.2).fold(f64::INFINITY, f64::min);
            assert!(best <= 1e-3, "{name}: {p:?}");
        }
    }
}

/// `exps` with only the experiments whose id starts with one of `only`, their scenarios named by
/// absolute paths, written into `dir`: the experiments a test keeps, synthesised alone. The noise
/// is drawn in the file's order, and the kept ones come first, so their data are the bits the
/// whole file gives them.
fn only_experiments(exps: &Path, only: &[&str], dir: &Path) -> std::path::PathBuf {
    let mut doc: toml::Table = std::fs::read_to_string(exps).unwrap().parse().unwrap();
    let list = doc["experiment"].as_array_mut().unwrap();
    let keep = |x: &toml::Value| only.iter().any(|o| x["id"].as_str().unwrap().starts_with(o));
    let kept = list.iter().filter(|x| keep(x)).count();
    assert!(list[..kept].iter().all(keep), "the kept experiments must lead {}", exps.display());
    list.truncate(kept);
    for x in list.iter_mut() {
        let scenario = exps.parent().unwrap().join(x["scenario"].as_str().unwrap());
        x.as_table_mut().unwrap().insert("scenario".into(), scenario.display().to_string().into());
    }
    let out = dir.join("experiments.toml");
    std::fs::write(&out, toml::to_string(&doc).unwrap()).unwrap();
    out
}

/// Synthesise data from `truth` with `truth_exps` (2 mm cells: finer than the model's 3 mm) for
/// the experiments whose id starts with one of `only`, then diagnose the base model against them
/// with `exps` (and `extra` arguments); the diagnosis as JSON.
fn diagnose(truth: &str, truth_exps: &str, only: &[&str], exps: &str, extra: &[&str]) -> serde_json::Value {
    let d = measure_fixtures("print");
    let tmp = tempfile::tempdir().unwrap();
    let t = std::time::Instant::now();
    let kept = only_experiments(&d.join(truth_exps), only, tmp.path());
    let data = tmp.path().join("data.csv");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join(truth)), "--experiments", s(&kept), "--noise", "0.01", "--seed", "7", "--out", s(&data), "--jobs", "2"]);
    assert_eq!(code, 0, "{err}");
    let out = tmp.path().join("best.toml");
    let (base, exps) = (d.join("base.toml"), d.join(exps));
    let args = [
        "diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps),
        "--fit", "material.yield_stress,material.viscosity", "--json", "--jobs", "2", "--out", s(&out),
    ];
    let (code, json, err) = strand(&[&args[..], extra].concat());
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    println!("{truth} ({:.0} s): {v:#}", t.elapsed().as_secs_f64());
    v
}

/// The hidden effect ranks first and is recommended, the recalibrated error at most 30 % of the
/// base model's.
fn assert_found(v: &serde_json::Value, effect: &str) {
    let c = &v["candidates"][0];
    assert_eq!(c["effect"], effect, "{v:#}");
    assert_eq!(v["verdict"], format!("add {effect}"), "{v:#}");
    let ratio = c["error_ratio"].as_f64().unwrap();
    assert!(ratio <= 0.3, "recalibrated error {ratio} of the base model's: {v:#}");
}

// The hidden-effect tests diagnose single lines (`line_*` of the campaign): 3 mm cells with J-bar
// (4 per nozzle diameter) against data synthesised at 2 mm, with the discretisation error
// counted (`experiments_resolved.toml`'s [resolution]). Measured with `strand compare --model
// truth_null.toml --data (the null's data) --experiments experiments_resolved.toml`: the truth's
// own material at 3 mm misses its 2 mm data by 12.9 % in width, 2.7 % in height, 1.7 % in area
// and 9.3 % in the profile point, chi^2 = 3.34 over 22 with the error counted.

/// One candidate fitted, no leave-one-out (`one_step_leave_one_out_agrees_with_exact_refits...`
/// in diagnose.rs checks it), every fit stopped after 4 iterations, so that it fits `make test`.
/// Measured at 0bf333a (beside other runs): 322 s wall (base fit 22 s, score tests 27 s,
/// likelihood-ratio fits 253 s); at 7fdb04f wall friction first (LR 305), error x 0.215. Its
/// fitted values (283 Pa, 13.6 Pa s, mu 0.45) are not the truth's (150 Pa, 20 Pa s, 0.3): four
/// lines' sections do not tell a stiffer material on a slipping floor from the truth.
#[test]
fn hidden_platform_friction_under_single_lines_is_found() {
    let v = diagnose("truth_friction.toml", "experiments_fine.toml", &["line_"], "experiments_resolved.toml", &["--max-fitted", "1", "--no-loo", "--max-iterations", "4"]);
    assert_found(&v, "wall_friction");
    assert_eq!(v["candidates"][0]["test"], "likelihood-ratio", "{v:#}");
}

/// Measured: 165 CPU-s (base fit, score tests, and each likelihood-ratio effect screened by one
/// Gauss-Newton step from its start), verdict "explained"; at 7fdb04f yield stress and viscosity
/// fitted to 156.53 Pa and 15.78 Pa s against the truth's 150 and 20.
#[test]
fn a_truth_without_effects_flags_nothing() {
    let v = diagnose("truth_null.toml", "experiments_fine.toml", &["line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    assert_eq!(v["verdict"], "explained", "{v:#}");
    assert!(v["candidates"].as_array().unwrap().iter().all(|c| c["recommended"] == false), "{v:#}");
}

/// Fitted as the friction's is. Measured at 0bf333a (beside other runs): 297 s wall (base fit
/// 58 s, score tests 26 s, likelihood-ratio fits 140 s, the candidate's fit 52 s); at 7fdb04f
/// "add extrusion_factor", factor 0.933, error x 0.278.
#[test]
fn a_pump_short_of_its_flow_is_not_pinned_on_a_material_effect() {
    // the pump's 7 % shows in the area, which no material parameter moves (mass balance)
    let v = diagnose("truth_null.toml", "experiments_fine_pump.toml", &["line_"], "experiments_resolved.toml", &["--max-fitted", "1", "--no-loo", "--max-iterations", "4"]);
    let verdict = v["verdict"].as_str().unwrap();
    assert!(verdict == "unexplained" || verdict == "add extrusion_factor", "{v:#}");
    if verdict == "add extrusion_factor" {
        assert_eq!(v["candidates"][0]["effect"], "extrusion_factor", "{v:#}");
        let f = v["candidates"][0]["fitted"].as_array().unwrap().iter().find(|p| p[0] == "extrusion_factor.factor").unwrap()[1].as_f64().unwrap();
        assert!((f / 0.93 - 1.0).abs() < 0.03, "factor {f} against the truth's 0.93");
    }
}

#[test]
#[ignore = "a diagnosis not finished in 29 CPU-minutes (docs/print_campaign.md); in make test, build-up is diagnosed from the failure heights of walls (diagnose::hidden_structuration_is_found_from_failure_heights)"]
fn hidden_build_up_is_found_from_lines_and_walls() {
    // In two-layer walls of this geometry the first layer does not settle under the second: at 3
    // mm cells, 60 Pa and no build-up, its height is 6.51 mm at layer times 0.1, 0.6 and 1.5 s
    // (a flat layer holds with a small yield stress). So the build-up shows in how stiff the
    // material has grown during the print (the base model against the truth's data: chi^2 92.2
    // over 22, against 9.7 for the null truth), not in settlement between layer times; a
    // settlement campaign needs walls tall enough to load the bottom near its yield stress,
    // which is the failure campaign of issue 31.
    let v = diagnose("truth_thixotropy.toml", "experiments_fine.toml", &["wall_", "line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    assert_found(&v, "thixotropy");
}
