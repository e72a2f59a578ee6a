//! The verification suite: closed-form and experimental references, run by `strand verify`.
//!
//! Every case builds a scenario, runs the solver, and reduces the particle state to one error
//! figure compared with a tolerance. `--quick` runs each case at reduced resolution and time so
//! the suite fits in `make test`; its tolerances are looser and the table marks them.

pub mod analytic;
mod cases;
mod error;
mod print;

pub use cases::{CaseResult, CASES, SLOW_CASES};
pub use error::VerifyError;
use std::time::Instant;

/// Peak resident set size of this process (VmHWM), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Run the suite; returns whether every selected case passed.
pub fn run_suite(quick: bool, json: bool, filter: Option<&str>, threads: Option<usize>) -> Result<bool, VerifyError> {
    let mut results = Vec::new();
    let mut matched = 0;
    let slow = SLOW_CASES.iter().filter(|(name, _)| filter == Some(*name));
    for (name, case) in CASES.iter().chain(slow) {
        if filter.is_some_and(|f| !name.contains(f)) {
            continue;
        }
        matched += 1;
        let t0 = Instant::now();
        if !json {
            eprintln!("verify: running {name}{} ...", if quick { " (quick)" } else { "" });
        }
        let mut rs = case(quick, threads.unwrap_or(0)).map_err(|e| VerifyError::Case { name, source: Box::new(e) })?;
        let wall = t0.elapsed().as_secs_f64();
        for r in &mut rs {
            r.wall_s = wall;
            r.peak_rss_bytes = peak_rss_bytes();
        }
        if !json {
            for r in &rs {
                eprintln!("  {}", r.row());
            }
            if rs.is_empty() {
                eprintln!("  (nothing to check in this mode)");
            }
        }
        results.extend(rs);
    }
    if matched == 0 {
        return Err(VerifyError::NoMatch(filter.unwrap_or("").to_string()));
    }
    let all = results.iter().all(|r| r.pass);
    if json {
        let v = serde_json::json!({ "quick": quick, "pass": all, "cases": results });
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
    } else {
        println!("{}", CaseResult::header());
        for r in &results {
            println!("{}", r.row());
        }
        println!("{}", if all { "all cases pass" } else { "SOME CASES FAIL" });
    }
    Ok(all)
}
