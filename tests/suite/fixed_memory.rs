//! Issue 53: every command that builds a simulation plans its memory first and refuses over the
//! budget before it allocates, naming the budget, the need and what asked for it (the
//! experiment, its `set`, `[resolution] fine`). Each case asks for terabytes at dx = 1e-5; before
//! the plan was made on every path, each command printed nothing while it counted particles or
//! grew to gigabytes, so each test also asserts the refusal comes within seconds.

use crate::common::{self, strand_in};
use std::path::Path;
use std::time::{Duration, Instant};

const MODEL: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = 0.3\nviscosity = 50.0\nyield_stress = 100.0\n";
const DATA: &str = "experiment,observable,at,value,uncertainty\nSF,spread,,0.3,0.01\n";

/// One slump experiment, `SF`, at cell size `dx`, and `more` after it.
fn experiments(dx: &str, more: &str) -> String {
    format!("[[experiment]]\nid = \"SF\"\nscenario = \"slump.toml\"\nset = {{ \"simulation.dx\" = {dx}, \"simulation.end_time\" = 0.1 }}\nobserve = [\"spread\"]\n{more}")
}

/// A folder with the small slump scenario (a 256 MiB budget), a model, data of SF and
/// `experiments` as exps.toml.
fn campaign(experiments: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(common::measure_fixtures("slump").join("slump.toml"), d.join("slump.toml")).unwrap();
    std::fs::write(d.join("model.toml"), MODEL).unwrap();
    std::fs::write(d.join("data.csv"), DATA).unwrap();
    std::fs::write(d.join("exps.toml"), experiments).unwrap();
    dir
}

/// `strand ARGS` in `dir`, refused (exit 2) within seconds over the budget: its stderr.
fn refused_fast(args: &[&str], dir: &Path) -> String {
    let clock = Instant::now();
    let (code, _, err) = strand_in(args, dir);
    let took = clock.elapsed();
    assert_eq!(code, 2, "{args:?}: {err}");
    assert!(took < Duration::from_secs(5), "{args:?} took {took:?} to refuse: {err}");
    assert!(err.contains("over the budget of 256.00 MiB") && err.contains("need at least"), "{args:?}: {err}");
    err
}

const MEASURE: [&str; 6] = ["--model", "model.toml", "--data", "data.csv", "--experiments", "exps.toml"];

fn with(cmd: &str, more: &[&'static str]) -> Vec<&'static str> {
    let cmd: &'static str = Box::leak(cmd.to_string().into_boxed_str());
    [cmd].into_iter().chain(MEASURE).chain(more.iter().copied()).collect()
}

#[test]
fn compare_calibrate_and_diagnose_refuse_an_experiment_set_over_the_budget() {
    let dir = campaign(&experiments("1e-5", ""));
    for args in [with("compare", &[]), with("calibrate", &["--fit", "material.yield_stress"]), with("diagnose", &["--fit", "material.yield_stress"])] {
        let err = refused_fast(&args, dir.path());
        assert!(err.contains("experiment 'SF' (slump.toml with set = { \"simulation.dx\" = 0.00001"), "{args:?}: {err}");
    }
}

#[test]
fn synth_refuses_an_experiment_set_over_the_budget() {
    let dir = campaign(&experiments("1e-5", ""));
    let err = refused_fast(&["synth", "--model", "model.toml", "--experiments", "exps.toml", "--noise", "0.01", "--seed", "1", "--out", "out.csv"], dir.path());
    assert!(err.contains("experiment 'SF'") && !dir.path().join("out.csv").exists(), "{err}");
}

#[test]
fn a_resolution_run_over_the_budget_is_refused_before_the_model_runs() {
    let dir = campaign(&experiments("0.04", "[resolution]\nfine = { \"simulation.dx\" = 1e-5 }\n"));
    let err = refused_fast(&with("compare", &[]), dir.path());
    assert!(err.contains("experiment 'SF', its finer run of [resolution] fine = { \"simulation.dx\" = 0.00001 }"), "{err}");
}

#[test]
fn grad_refuses_a_scenario_over_the_budget() {
    let dir = campaign("");
    let text = std::fs::read_to_string(dir.path().join("slump.toml")).unwrap().replace("dx = 0.02", "dx = 1e-5");
    std::fs::write(dir.path().join("fine.toml"), text).unwrap();
    refused_fast(&["grad", "fine.toml", "--objective", "spread", "--wrt", "material.yield_stress"], dir.path());
}

/// Finding 9: a print's bodies hold no particle before it starts; the plan then counts the grid
/// alone, where it said "at least -0.0000e0 particles" (an empty f64 sum is -0.0).
#[test]
fn check_of_a_print_over_the_budget_counts_the_grid_alone() {
    let dir = tempfile::tempdir().unwrap();
    let sc = dir.path().join("print.toml");
    std::fs::write(&sc, common::tiny_print(1, 1, false, "256 MiB").replace("dx = 0.005", "dx = 1e-5")).unwrap();
    let err = refused_fast(&["check", common::s(&sc)], dir.path());
    assert!(err.contains("the grid alone (before any particle)") && !err.contains("-0.0"), "{err}");
    // a body's count is a whole number, not -0.0000e0
    let sc = dir.path().join("slump.toml");
    std::fs::write(&sc, std::fs::read_to_string(common::measure_fixtures("slump").join("slump.toml")).unwrap().replace("dx = 0.02", "dx = 1e-4")).unwrap();
    let err = refused_fast(&["check", common::s(&sc)], dir.path());
    assert!(err.contains("the grid and the at least 2.") && err.contains("e9 particles of the bodies"), "{err}");
}
