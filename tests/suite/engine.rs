//! Campaigns on an existing scheduler (issue 26 item 6) and the provenance of saved results
//! (issue 27 finding 5), on the rheometer campaign (milliseconds per experiment, so what is
//! timed is the scheduler's round trips). The engine here is GNU parallel from Debian's packages
//! (`apt-get install -y parallel`; `.ci/run` installs it).

use std::path::{Path, PathBuf};
use crate::common::{strand_in};
use std::process::Command;

/// A copy of the rheometer campaign (edited by some tests) and data synthesised from its
/// thixotropic truth.
fn campaign() -> (tempfile::TempDir, PathBuf) {
    let fx = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/campaign");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_path_buf();
    for f in ["base.toml", "experiments.toml", "flow_curve.toml", "truth_thixotropy.toml"] {
        std::fs::copy(fx.join(f), d.join(f)).unwrap();
    }
    let (code, _, err) = strand_in(&["synth", "--model", "truth_thixotropy.toml", "--experiments", "experiments.toml", "--noise", "0.01", "--seed", "7", "--out", "data.csv"], &d);
    assert_eq!(code, 0, "{err}");
    (dir, d)
}

fn require_parallel() {
    let found = Command::new("parallel").arg("--version").output().is_ok_and(|o| o.status.success());
    assert!(found, "GNU parallel is not installed, and this test runs calibrate and diagnose through it: apt-get install -y parallel (.ci/run installs it)");
}

const INPUTS: [&str; 6] = ["--model", "base.toml", "--data", "data.csv", "--experiments", "experiments.toml"];
const FIT: [&str; 2] = ["--fit", "material.yield_stress,material.viscosity"];

#[test]
fn calibrate_and_diagnose_through_gnu_parallel_are_bit_identical_to_local_and_a_failed_job_loses_nothing() {
    require_parallel();
    let (_keep, d) = campaign();
    let calibrate = |out: &str, extra: &[&str]| strand_in(&[&["calibrate"], &INPUTS[..], &FIT[..], &["--json", "--out", out], extra].concat(), &d);

    let (code, local, err) = calibrate("local.toml", &[]);
    assert_eq!(code, 0, "{err}");
    let (code, engine, err) = calibrate("engine.toml", &["--engine", "parallel", "--engine-dir", "jobs"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("engine: batch 0001, 6 jobs submitted"), "{err}");
    // the fit's values, uncertainties, history and model values, to the bit (JSON numbers in
    // shortest round-trip form), and the model file written
    assert_eq!(engine, local);
    assert_eq!(std::fs::read_to_string(d.join("engine.toml")).unwrap(), std::fs::read_to_string(d.join("local.toml")).unwrap());
    // run again: every result is collected, nothing submitted
    let (code, again, err) = calibrate("again.toml", &["--engine", "parallel", "--engine-dir", "jobs"]);
    assert_eq!((code, again.as_str()), (0, local.as_str()), "{err}");
    assert!(!err.contains("jobs submitted"), "{err}");

    // jobs 4-6 of each batch fail: the error names each experiment with its job's log, and the
    // three results computed are kept
    let broken = "sed '4,$s/ evaluate / evaluate --bogus /' {jobs} | parallel --will-cite";
    let (code, _, err) = calibrate("broken.toml", &["--engine", broken, "--engine-dir", "retry"]);
    assert_ne!(code, 0);
    for id in ["D", "E", "F"] {
        assert!(err.contains(&format!("experiment '{id}': no result; job ")), "{err}");
    }
    assert!(!err.contains("experiment 'A'") && err.contains("3 of 6 jobs left no result") && err.contains("'--bogus'") && err.contains("retry/logs/D-"), "{err}");
    assert!(err.contains("run the same command again to compute only what is missing"), "{err}");
    assert!(!d.join("broken.toml").exists());
    assert_eq!(std::fs::read_dir(d.join("retry/results")).unwrap().count(), 3);
    // the rerun submits only the three missing, and ends where the local run does
    let (code, retried, err) = calibrate("retried.toml", &["--engine", "parallel", "--engine-dir", "retry"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("3 jobs submitted (3 collected from earlier runs)"), "{err}");
    assert_eq!(retried, local);

    // files edited between planning and running: every job refuses, naming what changed
    let proto = d.join("flow_curve.toml");
    let edit = format!("sed -i 's/hold = 0.5/hold = 0.6/' '{}' && parallel --will-cite < {{jobs}}", proto.display());
    let (code, _, err) = calibrate("edited.toml", &["--engine", &edit, "--engine-dir", "edited"]);
    assert_ne!(code, 0);
    assert!(err.contains("6 of 6 jobs left no result") && err.contains("another scenario") && err.contains("planned with other files"), "{err}");
    // and the results of the old protocol are not collected for the new one
    let (code, _, err) = calibrate("new.toml", &["--engine", "parallel", "--engine-dir", "jobs"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains(", 6 jobs submitted (0 collected from earlier runs)"), "{err}");
    std::fs::write(&proto, std::fs::read_to_string(&proto).unwrap().replace("hold = 0.6", "hold = 0.5")).unwrap();

    // diagnose: the score tests, the likelihood-ratio fits, leave-one-out and the verdict, to the bit
    let diagnose = |extra: &[&str]| strand_in(&[&["diagnose"], &INPUTS[..], &FIT[..], &["--json", "--max-fitted", "1"], extra].concat(), &d);
    let (code, local, err) = diagnose(&[]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&local).unwrap();
    assert_eq!(v["verdict"], "add thixotropy", "{v:#}");
    let (code, engine, err) = diagnose(&["--engine", "parallel", "--engine-dir", "diagnose"]);
    assert_eq!(code, 0, "{err}");
    // the likelihood-ratio fits run side by side, their evaluations submitted together (a batch
    // of more than one evaluation's six jobs), and so do the base model's and the candidate's
    // leave-one-out checks (one after another they would be twelve batches of one job)
    let jobs: Vec<usize> = err
        .lines()
        .filter_map(|l| l.strip_prefix("engine: batch ")?.split(", ").nth(1)?.split(' ').next()?.parse().ok())
        .collect();
    assert!(jobs.iter().any(|&n| n > 6 && n % 6 == 0) && jobs.iter().filter(|&&n| n == 1).count() < 6, "{jobs:?}\n{err}");
    // everything but the stages' wall-clock times
    let untimed = |json: &str| {
        let mut v: serde_json::Value = serde_json::from_str(json).unwrap();
        v.as_object_mut().unwrap().remove("timing");
        v.to_string()
    };
    assert_eq!(untimed(&engine), untimed(&local));
}

#[test]
fn collect_refuses_results_saved_under_another_model_or_scenario() {
    // issue 27's finding: compare --collect took values saved under another model (the truth's
    // chi^2, 12.1, where the base model's is 1.36e4)
    let (_keep, d) = campaign();
    let compare = |model: &str, extra: &[&str]| strand_in(&[&["compare", "--model", model, "--data", "data.csv", "--experiments", "experiments.toml", "--json"], extra].concat(), &d);
    let (code, _, err) = compare("truth_thixotropy.toml", &["--plan", "plan"]);
    assert_eq!(code, 0, "{err}");
    for line in std::fs::read_to_string(d.join("plan/jobs.txt")).unwrap().lines() {
        let o = Command::new("bash").arg("-c").arg(line).output().unwrap();
        assert!(o.status.success(), "{line}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let (code, collected, err) = compare("truth_thixotropy.toml", &["--collect", "plan"]);
    assert_eq!(code, 0, "{err}");
    let (_, local, _) = compare("truth_thixotropy.toml", &[]);
    assert_eq!(collected, local);

    // under the base model the saved values are another model's
    let (code, out, err) = compare("base.toml", &["--collect", "plan"]);
    assert_ne!(code, 0, "{out}");
    assert!(err.contains("experiment 'A'") && err.contains("plan/A.json comes from another model") && !err.contains("another scenario"), "{err}");
    // an edited protocol is another scenario
    let proto = d.join("flow_curve.toml");
    std::fs::write(&proto, std::fs::read_to_string(&proto).unwrap().replace("hold = 0.5", "hold = 0.6")).unwrap();
    let (code, _, err) = compare("truth_thixotropy.toml", &["--collect", "plan"]);
    assert_ne!(code, 0);
    assert!(err.contains("experiment 'A'") && err.contains("another scenario") && !err.contains("another model"), "{err}");
    // a result saved without provenance (by an older strand) is refused too
    std::fs::write(d.join("plan/A.json"), "{\"experiment\": \"A\", \"observables\": [\"stress@20\"], \"values\": [1.0]}").unwrap();
    let (code, _, err) = compare("truth_thixotropy.toml", &["--collect", "plan"]);
    assert_ne!(code, 0);
    assert!(err.contains("experiment 'A'") && err.contains("not a result of this strand") && err.contains("provenance"), "{err}");
}
