//! Golden results: a refactoring must keep every result bit-identical. Four cases at reduced size
//! — the default print (`strand run`'s embedded scenario, shortened), a print whose sleeping
//! particles merge, a gradient run (under a schedule that uses the disk) and a hidden-effect
//! campaign's synthesised measurements and model values — are compared, bit for bit, with the
//! values recorded in `tests/state_hashes/CASE.txt`.
//!
//! Re-recording: `STRAND_RECORD_HASHES=1 cargo test --release --test suite -- state_hashes::` rewrites the
//! files from this build instead of comparing. Do it only for a deliberate change of numerics, in
//! a commit of its own that says why the numbers changed; a refactoring never re-records.
//!
//! The hashes hold for this build configuration: the release profile without `target-cpu=native`
//! (no `.cargo/config` sets RUSTFLAGS), so no fused multiply-adds are chosen by the compiler, and
//! the platform's libm for `exp`, `powf`, `ln`, ... (a different libm or target may round them
//! differently, and then the file must be re-recorded on that machine).

use crate::common;

use std::path::PathBuf;
use strand::run::{run_scenario, RunOptions};
use strand::scenario::Scenario;


fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `text` with `key = old` replaced by `key = new`, asserting it was there.
fn set(text: &str, old: &str, new: &str) -> String {
    assert!(text.contains(old), "{old} not in the scenario");
    text.replacen(old, new, 1)
}

/// The final state hash and step count of a whole `strand run` (outputs and all), on one thread
/// (tests/suite/print.rs asserts any thread count gives the same bits).
fn run_hash(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions { out: dir.path().join("out"), quiet: true, threads: Some(1), ..Default::default() };
    let r = run_scenario(&Scenario::parse(text).unwrap(), &opts).unwrap();
    format!("{:016x} steps {} particles {}", r.state_hash, r.steps, r.particles)
}

fn bits(v: &[f64]) -> String {
    v.iter().map(|x| format!("{:016x}", x.to_bits())).collect::<Vec<_>>().join(" ")
}

/// The default print of `strand run` at 5 mm cells (the domain one cell taller for the nozzle
/// tube), to t = 1.6 s: the first layer laid, asleep, and woken as the second begins.
fn default_print() -> String {
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/default.toml")).unwrap();
    let text = set(&text, "end_time = 3.3", "end_time = 1.6");
    let text = set(&text, "dx = 0.0025", "dx = 0.005");
    run_hash(&set(&text, "max = [0.065, 0.045, 0.035]", "max = [0.065, 0.045, 0.04]"))
}

/// The wide tiny print whose sleeping interior merges (`[sleep] coarsen`), to t = 1.5 s: the
/// first layer's particles merge at about 1.4 s and the second layer wakes some of them.
fn sleeping_and_merging_print() -> String {
    let text = common::wide_tiny_print(1, 2, true, "64 MiB");
    run_hash(&set(&text, "end_time = 2.99", "end_time = 1.5"))
}

/// `strand grad` on the two-layer print: the value and gradient bits, under a revolve schedule
/// with disk slots (so the gradient store's disk writer takes part).
fn gradient_run() -> String {
    use strand::grad::driver::{gradients, Seeded};
    use strand::grad::{schedule::Kind, GradOptions};
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/grad/two_layers.toml")).unwrap();
    let sc = Scenario::parse(&set(&text, "end_time = 1.0", "end_time = 0.6")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = GradOptions {
        ram_bytes: 1 << 30,
        disk_bytes: 1 << 30,
        disk_dir: dir.path().to_path_buf(),
        threads: None,
        schedule: Some(Kind::parse("revolve:3,3").unwrap()),
        until_rest: None,
    };
    let seeds: Vec<Seeded> = ["layer_height@0.015:1", "spread"].iter().map(|o| Seeded { objective: o.parse().unwrap(), step: None }).collect();
    let wrt = vec!["material.yield_stress".to_string(), "material.viscosity".to_string()];
    let rs = gradients(&sc, &seeds, &wrt, &opts).unwrap();
    rs.iter().map(|r| format!("{} steps {} value {} gradient {}", r.objective, r.steps, bits(&[r.value]), bits(&r.gradient))).collect::<Vec<_>>().join("; ")
}

/// The slump campaign (`fixtures/measure/slump`): synthesised measurements of the truth with a
/// hidden effect (compressibility), noisy, and the base model's values at them.
fn campaign() -> String {
    use strand::measure::{experiments::Experiments, model::Model, runner::model_values, synth::synth};
    let dir = root().join("fixtures/measure/slump");
    let e = Experiments::load(&dir.join("experiments.toml")).unwrap();
    let truth = Model::load(&dir.join("truth_compressibility.toml")).unwrap();
    let obs = synth(&truth, &e, 0.01, 7, 2).unwrap();
    let base = Model::load(&dir.join("base.toml")).unwrap();
    let values = model_values(&base, &obs, &e, 2).unwrap();
    let measured: Vec<f64> = obs.iter().flat_map(|o| [o.value, o.uncertainty]).collect();
    format!("synth {} model {}", bits(&measured), bits(&values))
}

/// Compare `got` with `tests/state_hashes/NAME.txt`, or record it there with
/// STRAND_RECORD_HASHES=1.
fn check(name: &str, got: String) {
    let path = root().join("tests/suite/state_hashes").join(format!("{name}.txt"));
    if std::env::var_os("STRAND_RECORD_HASHES").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, format!("{got}\n")).unwrap();
        eprintln!("recorded {}", path.display());
        return;
    }
    let want = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e} (record with STRAND_RECORD_HASHES=1)", path.display()));
    assert!(want.trim_end() == got, "{name} changed (a refactoring must keep results bit-identical):\n  recorded {}\n  now      {got}", want.trim_end());
}

#[test]
fn the_default_print_is_bit_identical_to_the_recorded_one() {
    check("default_print", default_print());
}

#[test]
fn the_sleeping_and_merging_print_is_bit_identical_to_the_recorded_one() {
    check("sleeping_and_merging_print", sleeping_and_merging_print());
}

#[test]
fn the_gradients_are_bit_identical_to_the_recorded_ones() {
    check("gradient_run", gradient_run());
}

#[test]
fn the_campaign_values_are_bit_identical_to_the_recorded_ones() {
    check("hidden_effect_campaign", campaign());
}
