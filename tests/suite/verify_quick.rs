//! `strand verify --quick` passes every case, each run in its own process so that its peak
//! resident memory (VmHWM, reported by the case) can be held against the budget its scenario
//! declares. The full-resolution suite is `make verify`.

use std::process::Command;

fn case_names(exe: &str) -> Vec<String> {
    let out = Command::new(exe).args(["verify", "--list"]).output().unwrap();
    // slow cases are listed with a note and only run when named; they have no quick form
    String::from_utf8_lossy(&out.stdout).lines().filter(|l| !l.contains("(slow")).map(str::to_string).collect()
}

#[test]
fn every_quick_case_passes_within_its_memory_budget() {
    let exe = env!("CARGO_BIN_EXE_strand");
    let names = case_names(exe);
    assert!(names.len() >= 6, "cases: {names:?}");
    let mut rows = 0;
    for name in &names {
        let out = Command::new(exe).args(["verify", "--quick", "--json", "--case", name]).output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| {
            panic!("{name}: bad JSON ({e}): {text}\nstderr: {}", String::from_utf8_lossy(&out.stderr))
        });
        for c in v["cases"].as_array().unwrap() {
            rows += 1;
            assert_eq!(c["quick"], true);
            assert!(
                c["pass"].as_bool().unwrap(),
                "{} failed: error {} > tolerance {} ({})",
                c["case"], c["error"], c["tolerance"], c["notes"]
            );
            let rss = c["peak_rss_bytes"].as_u64().expect("VmHWM readable");
            let budget = c["budget_bytes"].as_u64().unwrap();
            assert!(rss > 1 << 20, "{name}: implausible VmHWM {rss}");
            assert!(rss <= budget, "{name}: peak RSS {rss} B exceeds its declared budget {budget} B");
        }
        assert!(out.status.success(), "{name}: exit status {:?}", out.status);
    }
    assert!(rows >= 12, "expected every row, got {rows}");
}
