//! The measurement loop on printed layers (issue 26): the process effects' toolpath keys against
//! central differences, and print campaigns with a hidden effect, synthesised at finer cells than
//! the model runs at, diagnosed from a base model started away from the truth.

use strand::grad::check::check;
use strand::grad::{gradient, GradOptions, Objective};
use strand::scenario::Scenario;

/// A short Newtonian print at 5 mm (tests/grad.rs's), its flow 5 % short of the commanded and
/// its nozzle 0.5 mm high: the process effects' keys away from their nulls.
fn tiny_print() -> String {
    r#"
name = "process-keys"
[simulation]
dx = 0.005
end_time = 0.45
dt = 2e-4
j_bar = false
[domain]
min = [-0.02, -0.04, 0.0]
max = [0.07, 0.04, 0.04]
[boundary]
z_min = "no_slip"
[material]
kind = "newtonian"
density = 2100.0
bulk_modulus = 2.0e5
viscosity = 20.0
[print]
nozzle = { shape = "circle", diameter = 0.012 }
start = [0.0, 0.0, 0.006]
extrusion_factor = 0.95
z_offset = 0.0005
path = [
  { kind = "print", to = [0.05, 0.0, 0.006], speed = 0.0817, extrusion = 0.0503 },
  { kind = "pause", duration = 0.1 },
]
[memory]
budget = "64 MiB"
"#
    .to_string()
}

#[test]
fn the_extrusion_factor_and_the_z_offset_gradients_match_central_differences() {
    let sc = Scenario::parse(&tiny_print()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = GradOptions { ram_bytes: 1 << 30, disk_bytes: 0, disk_dir: dir.path().to_path_buf(), threads: None, schedule: None, until_rest: None };
    let wrt: Vec<String> = ["print.extrusion_factor", "print.z_offset"].iter().map(|s| s.to_string()).collect();
    for name in ["area@0.01", "height@0.01", "width@0.01"] {
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

use std::path::{Path, PathBuf};
use std::process::Command;

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
/// them with experiments.toml (and `extra` arguments); the diagnosis as JSON.
fn diagnose(truth: &str, truth_exps: &str, only: &[&str], extra: &[&str]) -> serde_json::Value {
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
    let (base, exps) = (d.join("base.toml"), d.join("experiments.toml"));
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

#[test]
fn hidden_platform_friction_under_single_lines_is_found() {
    let v = diagnose("truth_friction.toml", "experiments_fine.toml", &["line_"], &["--max-fitted", "1"]);
    assert_found(&v, "wall_friction");
    assert_eq!(v["candidates"][0]["test"], "likelihood-ratio", "{v:#}");
}

#[test]
fn hidden_build_up_is_found_from_how_the_first_layer_settles() {
    let v = diagnose("truth_thixotropy.toml", "experiments_fine.toml", &["wall_", "line_"], &["--max-fitted", "1"]);
    assert_found(&v, "thixotropy");
}

#[test]
fn a_truth_without_effects_flags_nothing() {
    let v = diagnose("truth_null.toml", "experiments_fine.toml", &["wall_", "line_"], &["--max-fitted", "1"]);
    assert_eq!(v["verdict"], "explained", "{v:#}");
    assert!(v["candidates"].as_array().unwrap().iter().all(|c| c["recommended"] == false), "{v:#}");
}

#[test]
fn a_pump_short_of_its_flow_is_not_pinned_on_a_material_effect() {
    let v = diagnose("truth_null.toml", "experiments_fine_pump.toml", &["wall_", "line_"], &["--max-fitted", "1"]);
    let verdict = v["verdict"].as_str().unwrap();
    assert!(verdict == "unexplained" || verdict == "add extrusion_factor", "{v:#}");
    if verdict == "add extrusion_factor" {
        assert_found(&v, "extrusion_factor");
        let f = v["candidates"][0]["fitted"].as_array().unwrap().iter().find(|p| p[0] == "extrusion_factor.factor").unwrap()[1].as_f64().unwrap();
        assert!((f / 0.93 - 1.0).abs() < 0.03, "factor {f} against the truth's 0.93");
    }
}
