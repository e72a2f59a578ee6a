//! The `strand` command line: a run writes its outputs, bad input is an error naming the problem,
//! and a blow-up keeps what was computed plus the failing state.

use crate::common;

use std::process::Command;

fn strand(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_strand")).args(args).output().unwrap()
}

fn scenario(dir: &std::path::Path, text: &str) -> String {
    let p = dir.join("s.toml");
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn run_writes_snapshots_and_globals() {
    let dir = tempfile::tempdir().unwrap();
    let text = common::dam_break(2, "256 MiB", "")
        .replace("end_time = 0.2", "end_time = 0.05")
        .replace("[memory]", "[output]\ninterval = 0.025\n\n[memory]");
    let sc = scenario(dir.path(), &text);
    let out = dir.path().join("out");
    let o = strand(&["run", &sc, "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["particles_00000.vtu", "particles_00002.vtu", "particles.pvd", "globals.csv"] {
        assert!(out.join(f).exists(), "missing {f}");
    }
    let csv = std::fs::read_to_string(out.join("globals.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "header + 3 outputs:\n{csv}");
    assert!(csv.lines().last().unwrap().starts_with("5.0"), "{csv}");
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let sc = scenario(dir.path(), &common::dam_break(1, "256 MiB", "").replace("[domain]", "[domain]\nsize = 3"));
    let o = strand(&["check", &sc]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("size"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = strand(&["run", "/nonexistent/scenario.toml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/scenario.toml"));
    let o = strand(&["verify", "--case", "no_such_case"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn blow_up_keeps_outputs_and_the_failing_state() {
    let dir = tempfile::tempdir().unwrap();
    let text = common::dam_break(1, "256 MiB", "").replace("reorder_interval = 5", "reorder_interval = 5\ndt = 0.05");
    let sc = scenario(dir.path(), &text);
    let out = dir.path().join("out");
    let o = strand(&["run", &sc, "--out", out.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("blow-up at step") && err.contains("failed_state.vtu"), "{err}");
    assert!(out.join("failed_state.vtu").exists());
    assert!(out.join("particles_00000.vtu").exists(), "the initial snapshot must survive");
}

/// Issue 53 finding 2: a fresh run into a folder holding a finished run of the same scenario
/// that would not write all of it again (a shorter end time, snapshots or checkpoints switched
/// off) is refused, naming why, and leaves every file; `--overwrite` replaces it. A run to the
/// same end replaces it as before.
#[test]
fn a_rerun_that_would_write_less_does_not_replace_a_finished_run() {
    let dir = tempfile::tempdir().unwrap();
    let text = common::dam_break(2, "256 MiB", "")
        .replace("end_time = 0.2", "end_time = 0.05")
        .replace("[memory]", "[output]\ninterval = 0.025\n\n[memory]");
    let out = dir.path().join("out");
    let run = |text: &str, more: &[&str]| {
        let sc = scenario(dir.path(), text);
        strand(&[&["run", &sc, "--out", out.to_str().unwrap(), "--quiet"], more].concat())
    };
    assert!(run(&text, &[]).status.success());
    let files = |d: &std::path::Path| {
        let mut v: Vec<_> = std::fs::read_dir(d).unwrap().flatten().map(|e| e.file_name()).collect();
        v.sort();
        v
    };
    let (before, checkpoints) = (files(&out), files(&out.join("checkpoints")));
    assert!(before.iter().any(|f| f == "particles_00002.vtu") && !checkpoints.is_empty(), "{before:?} {checkpoints:?}");
    for (changed, why) in [
        (text.replace("end_time = 0.05", "end_time = 0.03"), "before that run's 0.05 s"),
        (text.replace("interval = 0.025", "interval = 0.025\nvtu = false"), "output.vtu = false"),
    ] {
        let o = run(&changed, &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains("finished run of this scenario") && err.contains(why) && err.contains("--overwrite"), "{err}");
        assert_eq!((files(&out), files(&out.join("checkpoints"))), (before.clone(), checkpoints.clone()), "the refused run touched the folder");
    }
    assert!(run(&text, &[]).status.success(), "a run to the same end replaces it");
    let shorter = text.replace("end_time = 0.05", "end_time = 0.03");
    assert!(run(&shorter, &["--overwrite"]).status.success());
    let csv = std::fs::read_to_string(out.join("globals.csv")).unwrap();
    assert!(csv.lines().last().unwrap().starts_with("3.0"), "the shorter run's: {csv}");
}

/// Issue 53 finding 10: every bench target runs the binary cargo built, under CARGO_TARGET_DIR
/// when it is set: the scripts are given $(STRAND), and bench/compare.sh reads the variable.
#[test]
fn the_bench_targets_honour_cargo_target_dir() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let makefile = std::fs::read_to_string(root.join("Makefile")).unwrap();
    let targets: Vec<&str> = makefile.lines().filter_map(|l| l.strip_suffix(':').or_else(|| l.split_once(": ").map(|(t, _)| t))).filter(|t| t.starts_with("bench-")).collect();
    assert!(targets.len() >= 10, "{targets:?}");
    let elsewhere = "/elsewhere/cargo-target";
    for t in targets {
        let o = Command::new("make").args(["-n", "-C", root.to_str().unwrap(), t]).env("CARGO_TARGET_DIR", elsewhere).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "make -n {t}: {}", String::from_utf8_lossy(&o.stderr));
        for line in text.lines() {
            let runs_strand = (line.starts_with("python3 bench/") && !line.contains("layer_cost.py")) || line.starts_with("bash bench/print_diagnose.sh");
            if runs_strand {
                assert!(line.contains(&format!("{elsewhere}/release/strand")), "{t}: {line}");
            }
            if line.contains("bench/compare.sh") {
                assert!(line.contains(&format!("CARGO_TARGET_DIR={elsewhere}")), "{t}: {line}");
            }
        }
    }
    let script = std::fs::read_to_string(root.join("bench/compare.sh")).unwrap();
    assert!(script.contains("${CARGO_TARGET_DIR:-target}") && !script.contains("./target/") && !script.contains("dir target/"), "bench/compare.sh");
}
