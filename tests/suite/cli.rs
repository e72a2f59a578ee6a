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
