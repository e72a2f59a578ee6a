// What the integration tests share: running the strand binary, and scenario text.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// `strand ARGS` in the test's own directory: its exit code, stdout and stderr.
pub fn strand(args: &[&str]) -> (i32, String, String) {
    output(Command::new(env!("CARGO_BIN_EXE_strand")).args(args))
}

/// `strand ARGS` in `dir`: its exit code, stdout and stderr.
pub fn strand_in(args: &[&str], dir: &Path) -> (i32, String, String) {
    output(Command::new(env!("CARGO_BIN_EXE_strand")).args(args).current_dir(dir))
}

fn output(c: &mut Command) -> (i32, String, String) {
    let o = c.output().unwrap();
    (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `fixtures/measure/DIR` of the repository.
pub fn measure_fixtures(dir: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure").join(dir)
}

/// A small quasi-2D dam break: `threads` workers, `budget` memory.
pub fn dam_break(threads: usize, budget: &str, extra_memory: &str) -> String {
    format!(
        r#"
name = "test-dam-break"
[simulation]
dx = 0.02
end_time = 0.2
threads = {threads}
reorder_interval = 5
[domain]
min = [0.0, 0.0, 0.0]
max = [0.6, 0.16, 0.4]
periodic = [false, true, false]
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 2.0e5
viscosity = 1.0
[[body]]
shape = "box"
min = [0.0, 0.0, 0.0]
max = [0.2, 0.16, 0.3]
[memory]
budget = "{budget}"
{extra_memory}
"#
    )
}

/// A tiny print at 5 mm resolution: a 12 mm nozzle laying `layers` short layers (6 mm high),
/// with sleeping on or off (`[sleep] enabled = false`: all awake, as the default would not have
/// it), on `threads` workers.
pub fn tiny_print(threads: usize, layers: usize, sleep: bool, budget: &str) -> String {
    let mut path = String::new();
    for l in 0..layers {
        let z = 0.006 * (l + 1) as f64;
        let (x0, x1) = if l % 2 == 0 { (0.0, 0.05) } else { (0.05, 0.0) };
        if l > 0 {
            path += "  { kind = \"layer\", dz = 0.006, speed = 0.05 },\n";
        }
        let _ = x0;
        path += &format!("  {{ kind = \"print\", to = [{x1}, 0.0, {z}], speed = 0.04, extrusion = 0.04 }},\n");
        path += "  { kind = \"pause\", duration = 0.1 },\n";
    }
    let t_end = layers as f64 * (0.05 / 0.04 + 0.1 + 0.12) + 0.05;
    let zmax = 0.006 * layers as f64 + 0.03;
    format!(
        r#"
name = "test-tiny-print"
[simulation]
dx = 0.005
end_time = {t_end}
threads = {threads}
[domain]
min = [-0.02, -0.04, 0.0]
max = [0.07, 0.04, {zmax}]
[material]
kind = "evp_bingham"
density = 2100.0
bulk_modulus = 1.0e6
poisson_ratio = 0.3
viscosity = 7.5
yield_stress = 630.0
[print]
nozzle = {{ shape = "circle", diameter = 0.012 }}
start = [0.0, 0.0, 0.006]
path = [
{path}]
{sleep}
[observe]
stations = [0.025]
[output]
interval = 0.1
vtu = false
[memory]
budget = "{budget}"
"#,
        sleep = if sleep { "[sleep]\nrest_time = 0.02\ncheck_interval = 16" } else { "[sleep]\nenabled = false" }
    )
}

/// [`tiny_print`] (sleeping) with a wider strand, a 20 mm nozzle, thick enough at 5 mm for
/// cells inside it after two layers; with `coarsen`, their sleeping particles merge
/// (`[sleep] coarsen`).
pub fn wide_tiny_print(threads: usize, layers: usize, coarsen: bool, budget: &str) -> String {
    let text = tiny_print(threads, layers, true, budget);
    for key in ["diameter = 0.012", "extrusion = 0.04", "[sleep]\n"] {
        assert!(text.contains(key), "{key} not in {text}");
    }
    let text = text.replace("diameter = 0.012", "diameter = 0.02").replace("extrusion = 0.04", "extrusion = 0.06");
    if coarsen {
        text.replace("[sleep]\n", "[sleep]\ncoarsen = true\n")
    } else {
        text
    }
}

/// Resident memory a strand process may hold beyond its declared budget: the binary and its
/// libraries, thread stacks, the allocator's arenas and the output stage's buffers (measured:
/// a tiny print peaks at about 10 MiB in all, pools included).
pub const RSS_SLACK: u64 = 8 << 20;

/// Run `strand run SCENARIO --out OUT --quiet --json ARGS` in a child process, so that its
/// VmHWM is the run's own, and assert it succeeded with a peak RSS within the scenario's
/// `[memory] budget` plus [`RSS_SLACK`]. Returns the JSON summary. The fixture every long test
/// uses to prove bounded memory.
pub fn run_within_budget(scenario: &std::path::Path, out: &std::path::Path, args: &[&str]) -> serde_json::Value {
    let sc = strand::scenario::Scenario::load(scenario).unwrap();
    let budget = strand::memory::parse_size(&sc.memory.budget).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_strand"))
        .args(["run", scenario.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet", "--json"])
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    let peak = summary["peak_rss_bytes"].as_u64().unwrap_or_else(|| panic!("no peak in {stdout}"));
    assert!(peak > 1 << 20, "implausible peak {peak}");
    assert!(
        peak <= budget + RSS_SLACK,
        "peak RSS {:.1} MiB above the budget {:.1} MiB + {} MiB",
        peak as f64 / 1048576.0,
        budget as f64 / 1048576.0,
        RSS_SLACK >> 20
    );
    summary
}
