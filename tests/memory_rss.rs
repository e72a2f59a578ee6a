//! Peak resident memory of each verification case, run in its own process, stays below the
//! memory budget its scenario declares.

use std::process::Command;

#[test]
fn verify_cases_stay_within_their_budgets() {
    let exe = env!("CARGO_BIN_EXE_strand");
    for case in ["poiseuille_newtonian", "hydrostatic_column", "dam_break_martin_moyce"] {
        let out = Command::new(exe).args(["verify", "--quick", "--json", "--case", case]).output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{case}: {e}: {text}"));
        for c in v["cases"].as_array().unwrap() {
            let rss = c["peak_rss_bytes"].as_u64().expect("VmHWM readable");
            let budget = c["budget_bytes"].as_u64().unwrap();
            assert!(rss <= budget, "{case}: peak RSS {rss} B exceeds its budget {budget} B");
            assert!(rss > 1 << 20, "{case}: implausible VmHWM {rss}");
        }
    }
}
