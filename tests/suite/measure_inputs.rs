//! Issue 53: bad measurement inputs named before anything runs: an effect that is not finite,
//! `[resolution]` tables that cannot work, and print experiments whose cell-size error nothing
//! counts.

use crate::common::{measure_fixtures, s, strand_in};
use std::path::Path;
use std::time::Instant;

const MODEL: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = 0.3\nviscosity = 50.0\nyield_stress = 100.0\n";

/// `strand compare` of `model` against one slump observation, the experiment at 4 cm cells for
/// `end_time` s and `more` after it: exit code, stderr and seconds taken.
fn compare_slump(model: &str, end_time: f64, more: &str) -> (i32, String, f64) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(measure_fixtures("slump").join("slump.toml"), d.join("slump.toml")).unwrap();
    std::fs::write(d.join("model.toml"), model).unwrap();
    std::fs::write(d.join("data.csv"), "experiment,observable,at,value,uncertainty\nSF,spread,,0.3,0.01\n").unwrap();
    let exps = format!("[[experiment]]\nid = \"SF\"\nscenario = \"slump.toml\"\nset = {{ \"simulation.dx\" = 0.04, \"simulation.end_time\" = {end_time} }}\nobserve = [\"spread\"]\n{more}");
    std::fs::write(d.join("exps.toml"), exps).unwrap();
    let clock = Instant::now();
    let (code, _, err) = strand_in(&["compare", "--model", "model.toml", "--data", "data.csv", "--experiments", "exps.toml"], d);
    (code, err, clock.elapsed().as_secs_f64())
}

/// Finding 6: an effect that divides by zero gave `material.yield_stress must be >= 0, got inf`;
/// the error names the effect, its expression and that the value is not finite.
#[test]
fn an_effect_that_is_not_finite_is_named_with_its_expression() {
    let model = format!("{MODEL}\n[effects.yield_growth]\nsets = {{ \"material.yield_stress\" = \"yield_stress / (1 - a)\" }}\nparams = {{ a = {{ null = 0, min = 0, max = 2 }} }}\na = 1.0\n");
    let (code, err, _) = compare_slump(&model, 0.1, "");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("effect 'yield_growth'") && err.contains("'yield_stress / (1 - a)'") && err.contains("not a finite number") && !err.contains(">= 0"), "{err}");
}

/// Finding 7: a fine cell that is not finer was refused only after the model's own runs; it is
/// refused before any run (here the model's run would take minutes).
#[test]
fn a_resolution_that_is_not_finer_is_refused_before_any_run() {
    let (code, err, took) = compare_slump(MODEL, 100.0, "[resolution]\nfine = { \"simulation.dx\" = 0.05 }\n");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("experiment 'SF': [resolution] fine.\"simulation.dx\" = 0.05 is not finer") && took < 5.0, "{took} s: {err}");
}

/// Finding 8: a misspelt key inside `fine` blamed a line of the generated scenario text; the
/// error names `[resolution] fine` and the key.
#[test]
fn a_misspelt_fine_key_is_named_in_resolution() {
    let (code, err, took) = compare_slump(MODEL, 100.0, "[resolution]\nfine = { \"simulation.dx\" = 0.02, \"simulation.dxx\" = 0.02 }\n");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("[resolution] fine.\"simulation.dxx\"") && err.contains("unknown field `dxx`") && !err.contains("line") && took < 5.0, "{took} s: {err}");
}

/// Finding 11: calibrate and diagnose on print experiments without `[resolution]` warn once that
/// the cell size's error is not counted and how to count it; with the table, not. (The --out
/// that cannot be written stops each before its runs.)
#[test]
fn print_experiments_without_resolution_are_warned_of_in_calibrate_and_diagnose() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fixtures = measure_fixtures("print");
    for f in ["line.toml", "wall.toml", "base.toml", "experiments.toml"] {
        std::fs::copy(fixtures.join(f), d.join(f)).unwrap();
    }
    std::fs::write(d.join("data.csv"), "experiment,observable,at,value,uncertainty\nline_V60,width,0.04,0.03,0.001\n").unwrap();
    let with_table = std::fs::read_to_string(d.join("experiments.toml")).unwrap() + "\n[resolution]\nfine = { \"simulation.dx\" = 0.002 }\n";
    std::fs::write(d.join("counted.toml"), with_table).unwrap();
    let nowhere = Path::new("/nonexistent/dir/model.toml");
    for cmd in ["calibrate", "diagnose"] {
        for (exps, warned) in [("experiments.toml", true), ("counted.toml", false)] {
            let (code, _, err) = strand_in(&[cmd, "--model", "base.toml", "--data", "data.csv", "--experiments", exps, "--fit", "material.yield_stress", "--out", s(nowhere)], d);
            assert_eq!(code, 2, "{cmd} {exps}: {err}");
            let warnings = err.matches("without a [resolution] table").count();
            assert_eq!(warnings, warned as usize, "{cmd} {exps}: {err}");
            if warned {
                assert!(err.contains("line_V60") && err.contains("[resolution] fine") && err.contains("docs/discretisation.md"), "{err}");
            }
        }
    }
}
