//! `strand verify --quick --json` passes every case (reduced resolution; the full suite is
//! `make verify`).

use std::process::Command;

#[test]
fn quick_verification_suite_passes() {
    let exe = env!("CARGO_BIN_EXE_strand");
    let out = Command::new(exe).args(["verify", "--quick", "--json"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!("bad JSON ({e}): {text}\nstderr: {}", String::from_utf8_lossy(&out.stderr))
    });
    let cases = v["cases"].as_array().unwrap();
    assert!(cases.len() >= 8, "expected every case, got {}", cases.len());
    for c in cases {
        assert_eq!(c["quick"], true);
        assert!(
            c["pass"].as_bool().unwrap(),
            "{} failed: error {} > tolerance {} ({})",
            c["case"], c["error"], c["tolerance"], c["notes"]
        );
    }
    assert_eq!(v["pass"], true);
    assert!(out.status.success());
}
