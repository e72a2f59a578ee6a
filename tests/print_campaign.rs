//! The measurement loop on printed layers (issue 26): the process effects' toolpath keys against
//! central differences, and print campaigns with a hidden effect, synthesised at finer cells than
//! the model runs at, diagnosed from a base model started away from the truth.

use std::path::{Path, PathBuf};
use std::process::Command;
use strand::grad::check::check;
use strand::grad::{gradient, GradOptions, Objective};
use strand::scenario::Scenario;

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

fn campaign() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/print")
}

fn strand(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_strand")).args(args).output().unwrap();
    (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Synthesise data from `truth` with `truth_exps` (2 mm cells: finer than the model's 2.5 mm),
/// keep the experiments whose id starts with one of `only`, then diagnose the base model against
/// them with `exps` (and `extra` arguments); the diagnosis as JSON.
fn diagnose(truth: &str, truth_exps: &str, only: &[&str], exps: &str, extra: &[&str]) -> serde_json::Value {
    let d = campaign();
    let tmp = tempfile::tempdir().unwrap();
    let all = tmp.path().join("all.csv");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join(truth)), "--experiments", s(&d.join(truth_exps)), "--noise", "0.01", "--seed", "7", "--out", s(&all), "--jobs", "2"]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&all).unwrap();
    let kept: Vec<&str> = text.lines().enumerate().filter(|(i, l)| *i == 0 || only.iter().any(|o| l.starts_with(o))).map(|(_, l)| l).collect();
    let data = tmp.path().join("data.csv");
    std::fs::write(&data, kept.join("\n") + "\n").unwrap();
    let out = tmp.path().join("best.toml");
    let (base, exps) = (d.join("base.toml"), d.join(exps));
    let args = [
        "diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps),
        "--fit", "material.yield_stress,material.viscosity", "--json", "--jobs", "2", "--out", s(&out),
    ];
    let t = std::time::Instant::now();
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

// The four hidden-effect tests below do not run in `make test`: measured on this campaign (2-core
// machine, CPU seconds), each diagnosis needs hours where CI gives minutes, and at the resolution
// such a campaign affords the discretisation error is as large as the effects:
//
// - cost: one gradient of one observable of a 2.5 mm line is 4.8 s of CPU (`strand grad
//   line.toml --objective height@0.015`), 22 of them per Jacobian, some five Jacobians per
//   calibration, and a diagnosis calibrates some twenty times (base fit, two likelihood-ratio
//   starts for wall_friction, the candidate's fit, and a leave-one-out refit of the base and of
//   the candidate per experiment): ~3 CPU-hours. The friction diagnosis had used 503 CPU-s
//   (24 min on the shared machine) without finishing. Issue 26 item 4 (one reverse pass per
//   experiment, Gauss-Newton leave-one-out) is what brings it within reach.
// - discretisation: the null truth's own model at 2.5 mm against its 2 mm data (`strand compare
//   --model truth_null.toml --data ... --experiments experiments.toml`): chi^2 = 3070 over 22
//   observations, three of the four lines' area 12-15 % low (the fourth 4 % high)
//   and every profile point 18-26 % low, much as a pump short of its flow would make them: without the discretisation error counted, the null truth would be
//   blamed on extrusion_factor. With it (`experiments_resolved.toml`, which needs the
//   `[resolution]` table of issue 26 item 3), the base model compares at chi^2 = 1.27 (null),
//   1.49 (pump 7 % short) and 3.64 (build-up 400 Pa/s) over 22 observations: the null comes out
//   explained, but the build-up and the pump lie within the first-order Richardson error of
//   2.5 mm cells against 2 mm (five times their difference), so neither can be found or flagged;
//   the friction truth (mu = 0.3) compares at chi^2 = 29.3 over 16.

#[test]
#[ignore = "~3 CPU-hours a diagnosis (see above); needs issue 26 item 4"]
fn hidden_platform_friction_under_single_lines_is_found() {
    let v = diagnose("truth_friction.toml", "experiments_fine.toml", &["line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    assert_found(&v, "wall_friction");
    assert_eq!(v["candidates"][0]["test"], "likelihood-ratio", "{v:#}");
}

#[test]
#[ignore = "~3 CPU-hours a diagnosis; and the build-up lies within the discretisation error of 2.5 mm cells (chi^2 3.64 over 22 with it counted, before any fit): expected to fail, not run to its end"]
fn hidden_build_up_is_found_from_how_the_first_layer_settles() {
    let v = diagnose("truth_thixotropy.toml", "experiments_fine.toml", &["wall_", "line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    assert_found(&v, "thixotropy");
}

#[test]
#[ignore = "~3 CPU-hours a diagnosis; needs [resolution] (issue 26 item 3): without it the discretisation error is pinned on an effect"]
fn a_truth_without_effects_flags_nothing() {
    let v = diagnose("truth_null.toml", "experiments_fine.toml", &["wall_", "line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    assert_eq!(v["verdict"], "explained", "{v:#}");
    assert!(v["candidates"].as_array().unwrap().iter().all(|c| c["recommended"] == false), "{v:#}");
}

#[test]
#[ignore = "~3 CPU-hours a diagnosis; and the 7 % pump lies within the discretisation error of 2.5 mm cells (chi^2 1.49 over 22 with it counted, before any fit): expected 'explained', which this test refuses; not run to its end"]
fn a_pump_short_of_its_flow_is_not_pinned_on_a_material_effect() {
    let v = diagnose("truth_null.toml", "experiments_fine_pump.toml", &["wall_", "line_"], "experiments_resolved.toml", &["--max-fitted", "1"]);
    let verdict = v["verdict"].as_str().unwrap();
    assert!(verdict == "unexplained" || verdict == "add extrusion_factor", "{v:#}");
    if verdict == "add extrusion_factor" {
        assert_found(&v, "extrusion_factor");
        let f = v["candidates"][0]["fitted"].as_array().unwrap().iter().find(|p| p[0] == "extrusion_factor.factor").unwrap()[1].as_f64().unwrap();
        assert!((f / 0.93 - 1.0).abs() < 0.03, "factor {f} against the truth's 0.93");
    }
}
