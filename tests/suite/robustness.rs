//! Nothing lost, nothing silently wrong (issue 27): an output folder never loses a run's files
//! to another run or to a resume, bad input and nonsense options are errors naming the key, a
//! scenario that does something unexpected says so, real slicer G-code imports, and the four
//! parsers (scenario TOML, G-code, measurement CSV, checkpoint reader) neither panic nor hang on
//! any input (property tests; `make fuzz` runs many more cases).

use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_strand");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn strand(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small box of Newtonian fluid slumping for `end` seconds (512 particles, about 120 steps a
/// 0.05 s), an output every 0.01 s.
fn slump(end: f64, viscosity: f64) -> String {
    format!(
        r#"name = "robustness"
[simulation]
dx = 0.02
end_time = {end}
threads = 1
[domain]
min = [0.0, 0.0, 0.0]
max = [0.2, 0.2, 0.2]
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 2.0e5
viscosity = {viscosity}
[[body]]
shape = "box"
min = [0.0, 0.0, 0.0]
max = [0.08, 0.08, 0.08]
[output]
interval = 0.01
[memory]
budget = "64 MiB"
"#
    )
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn run(sc: &Path, out: &Path, extra: &[&str]) -> Output {
    let o = Command::new(BIN).args(["run", s(sc), "--out", s(out), "--quiet", "--json"]).args(extra).output().unwrap();
    o
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut all = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else {
                all.push((e.path(), std::fs::read(e.path()).unwrap()));
            }
        }
    }
    all.sort();
    all
}

fn snapshots_on_disk(out: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("particles_") && n.ends_with(".vtu"))
        .collect();
    v.sort();
    v
}

/// Finding 1: resuming a finished run says so and changes nothing; an end_time before what the
/// run computed is an error, and changes nothing either.
#[test]
fn resuming_a_finished_run_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "s.toml", &slump(0.05, 1.0));
    let out = dir.path().join("out");
    let first = run(&sc, &out, &[]);
    assert!(first.status.success(), "{}", stderr(&first));
    let before = snapshot(&out);
    let o = Command::new(BIN).args(["run", s(&sc), "--out", s(&out), "--json", "--resume"]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("has finished"), "{}", stderr(&o));
    let (a, b): (serde_json::Value, serde_json::Value) = (serde_json::from_slice(&first.stdout).unwrap(), serde_json::from_slice(&o.stdout).unwrap());
    assert_eq!(a["state_hash"], b["state_hash"], "the summary's state is the finished run's");
    assert!(before == snapshot(&out), "a resume of a finished run changed the folder");
    // an end_time before what the run computed
    let shorter = write(dir.path(), "shorter.toml", &slump(0.03, 1.0));
    let o = run(&shorter, &out, &["--resume"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("end_time = 0.03 s lies before what the run has computed"), "{}", stderr(&o));
    assert!(before == snapshot(&out), "a refused resume changed the folder");
}

/// Finding 2: a folder holding a finished run of another scenario is refused; --overwrite
/// removes that run's files (no stale snapshot stays), and nothing else.
#[test]
fn another_scenarios_finished_run_is_refused_unless_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let long = write(dir.path(), "long.toml", &slump(0.05, 1.0));
    let other = write(dir.path(), "other.toml", &slump(0.03, 2.0));
    let out = dir.path().join("out");
    assert!(run(&long, &out, &[]).status.success());
    std::fs::write(out.join("my_notes.txt"), "mine").unwrap();
    let before = snapshot(&out);
    let o = run(&other, &out, &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("finished run of another scenario") && err.contains("material.viscosity") && err.contains("--overwrite"), "{err}");
    assert!(before == snapshot(&out), "the refused run changed the folder");
    let o = run(&other, &out, &["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // 0.03 s at 0.01 s an output: snapshots 0..=3 only, none left from the 0.05 s run
    assert_eq!(snapshots_on_disk(&out), (0..4).map(|k| format!("particles_{k:05}.vtu")).collect::<Vec<_>>());
    let pvd = std::fs::read_to_string(out.join("particles.pvd")).unwrap();
    assert_eq!(pvd.matches("particles_").count(), 4, "{pvd}");
    assert_eq!(std::fs::read_to_string(out.join("my_notes.txt")).unwrap(), "mine", "a file not the run's was touched");
    // the same scenario again, finished: replaced as before
    assert!(run(&other, &out, &[]).status.success());
}

/// Finding 11: a run killed before its first checkpoint: both --resume and a plain run say what
/// happened and give the one command that starts over, which works.
#[test]
fn a_run_killed_before_its_first_checkpoint_names_the_way_out() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "s.toml", &slump(20.0, 1.0));
    let out = dir.path().join("out");
    let mut child = Command::new(BIN).args(["run", s(&sc), "--out", s(&out), "--quiet"]).stderr(std::process::Stdio::null()).spawn().unwrap();
    let t0 = Instant::now();
    while !out.join("particles_00002.vtu").exists() && t0.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL: no checkpoint written
    child.wait().unwrap();
    assert!(out.join("particles_00002.vtu").exists(), "the run made no progress");
    for extra in [&["--resume"][..], &[][..]] {
        let o = run(&sc, &out, extra);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{err}");
        let again = format!("strand run {} --out {} --overwrite", s(&sc), s(&out));
        assert!(err.contains("stopped before"), "{extra:?}: {err}");
        assert!(err.contains(&again), "{extra:?}: {err}");
    }
    let quick = write(dir.path(), "s.toml", &slump(0.02, 1.0));
    let o = run(&quick, &out, &["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(snapshots_on_disk(&out).len(), 3);
}

/// Findings 6, 7, 8, 9: check warns of what a scenario does silently, answers at once for a
/// runaway size, and names the key of a non-finite value.
#[test]
fn check_says_what_a_scenario_does_and_refuses_runaways() {
    let dir = tempfile::tempdir().unwrap();
    let base = slump(0.05, 1.0);
    let check = |name: &str, text: String| {
        let p = write(dir.path(), name, &text);
        let t = Instant::now();
        let o = strand(&["check", s(&p)]);
        (o.status.code(), stderr(&o), t.elapsed())
    };
    let replace = |from: &str, to: &str| {
        assert!(base.contains(from), "{from}");
        base.replace(from, to)
    };
    let (code, err, _) = check("wall.toml", replace("max = [0.2, 0.2, 0.2]", "max = [0.21, 0.2, 0.2]"));
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning: domain.max[0] = 0.21 is not a whole number of cells") && err.contains("the wall is at 0.22"), "{err}");
    let (code, err, _) = check("coarse.toml", replace("dx = 0.02", "dx = 1.0"));
    assert_eq!(code, Some(2));
    assert!(err.contains("less than one cell of simulation.dx"), "{err}");
    let (_, err, _) = check("empty.toml", base[..base.find("[[body]]").unwrap()].to_string() + "[memory]\nbudget = \"64 MiB\"\n");
    assert!(err.contains("nothing to simulate: the scenario has no [[body]] and no [print]"), "{err}");
    let (_, err, _) = check("cut.toml", replace("max = [0.08, 0.08, 0.08]", "max = [0.24, 0.08, 0.08]"));
    assert!(err.contains("body[0] reaches outside the domain") && err.contains("1280 particles remain"), "{err}");
    let (_, err, _) = check("twice.toml", replace("[output]", "[[body]]\nshape = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.04, 0.04, 0.04]\n[output]"));
    assert!(err.contains("body[1] overlaps body[0]: 64 of its particles"), "{err}");
    // runaways: answered at once
    let (code, err, took) = check("fine.toml", replace("dx = 0.02", "dx = 1e-5"));
    assert_eq!(code, Some(2));
    assert!(err.contains("memory plan") && err.contains("over the budget"), "{err}");
    assert!(took < Duration::from_secs(20), "{took:?}");
    let (code, err, _) = check("tiny_dt.toml", replace("threads = 1", "threads = 1\ndt = 1e-300"));
    assert_eq!(code, Some(2));
    assert!(err.contains("simulation.dt = 1e-300 s takes 5.000e298 steps"), "{err}");
    // non-finite values name the key and say so
    let (_, err, _) = check("inf_domain.toml", replace("max = [0.2, 0.2, 0.2]", "max = [inf, 0.2, 0.2]"));
    assert!(err.contains("domain.min[0] and domain.max[0] must be finite"), "{err}");
    let (_, err, _) = check("inf_end.toml", replace("end_time = 0.05", "end_time = inf"));
    assert!(err.contains("simulation.end_time must be a finite time, got inf"), "{err}");
    // mass scaling: a factor >= 1, finite
    for bad in ["0.5", "nan", "inf"] {
        let (code, err, _) = check("mass_scaling.toml", replace("threads = 1", &format!("threads = 1\nmass_scaling = {bad}")));
        assert_eq!(code, Some(2), "{bad}: {err}");
        assert!(err.contains("simulation.mass_scaling must be a finite factor >= 1"), "{bad}: {err}");
    }
}

/// Finding 10: nonsense grad options are refused before anything runs.
#[test]
fn nonsense_grad_options_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "s.toml", &slump(0.02, 1.0));
    for (extra, says) in [
        (&["--check", "--check-steps", "0"][..], "--check-steps: each relative step must be finite and > 0, got 0"),
        (&["--until-rest=-1"][..], "--until-rest: the speed must be finite and > 0"),
    ] {
        let o = strand(&[&["grad", s(&sc), "--objective", "mean_z", "--wrt", "material.viscosity"][..], extra].concat());
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{extra:?}: {}", stderr(&o));
    }
}

/// Finding 3: calibrate and diagnose check their output paths before the fit, and print what
/// they computed before writing files.
#[test]
fn unwritable_outputs_are_refused_before_the_work() {
    let d = root().join("fixtures/measure/campaign");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let (model, exps) = (d.join("base.toml"), d.join("experiments.toml"));
    let o = strand(&["synth", "--model", s(&d.join("truth_null.toml")), "--experiments", s(&exps), "--out", s(&data)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let inputs = ["--model", s(&model), "--data", s(&data), "--experiments", s(&exps), "--fit", "material.yield_stress"];
    let nowhere = tmp.path().join("no/such/dir/x.toml");
    let (ok, bad_plot) = (tmp.path().join("ok.toml"), tmp.path().join("no/plot.png"));
    let cases: [(&str, Vec<&str>, &str); 3] = [
        ("calibrate", vec!["--out", s(&nowhere)], "--out"),
        ("calibrate", vec!["--out", s(&ok), "--plot", s(&bad_plot)], "--plot"),
        ("diagnose", vec!["--out", s(&nowhere)], "--out"),
    ];
    for (cmd, extra, what) in cases {
        let o = strand(&[&[cmd][..], &inputs, &extra].concat());
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{cmd} {extra:?}: {err}");
        assert!(err.contains(&format!("error: {what} ")) && err.contains("cannot be written"), "{cmd} {extra:?}: {err}");
        assert!(!err.contains("step 1") && o.stdout.is_empty(), "{cmd} {extra:?} worked before failing: {err}");
    }
    assert!(!ok.exists(), "a refused calibrate left a file");
}

/// Finding 4, through the command line: a rheometer row observing `banana` is refused.
#[test]
fn a_rheometer_row_of_an_unknown_observable_is_refused() {
    let d = root().join("fixtures/measure/campaign");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let exps = d.join("experiments.toml");
    assert!(strand(&["synth", "--model", s(&d.join("truth_null.toml")), "--experiments", s(&exps), "--out", s(&data)]).status.success());
    let text = std::fs::read_to_string(&data).unwrap();
    let row = text.lines().nth(1).unwrap();
    std::fs::write(&data, text.replacen(row, &row.replacen(",stress,", ",banana,", 1), 1)).unwrap();
    let o = strand(&["compare", "--model", s(&d.join("base.toml")), "--data", s(&data), "--experiments", s(&exps)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("a rheometer test cannot observe 'banana'; it can observe stress"), "{}", stderr(&o));
}

/// Finding 11: the Makefile runs the binary cargo built, wherever CARGO_TARGET_DIR puts it.
#[test]
fn make_run_honours_cargo_target_dir() {
    let o = Command::new("make").args(["-n", "run"]).current_dir(root()).env("CARGO_TARGET_DIR", "/elsewhere/t").output();
    let Ok(o) = o else { return }; // no make on this machine: nothing to check
    let plan = String::from_utf8_lossy(&o.stdout);
    assert!(plan.contains("/elsewhere/t/release/strand run"), "{plan}");
}

/// Finding 12: G-code in the styles of PrusaSlicer, Cura, Klipper, Simplify3D and a robot
/// post-processor imports to the printing moves of the plain file, and the note names what was
/// skipped.
#[test]
fn slicer_gcode_imports_to_the_plain_files_moves() {
    use strand::print::gcode::{parse_gcode_with_notes, GcodeOptions};
    use strand::print::toolpath::MoveKind;
    let opts = GcodeOptions { start: [0.0, 0.0, 12.5], ..GcodeOptions::default() };
    let read = |p: PathBuf| std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let (plain, _) = parse_gcode_with_notes(&read(root().join("fixtures/scenarios/print/two_layers.gcode")), &opts).unwrap();
    let prints = |p: &strand::print::toolpath::Toolpath| -> Vec<_> {
        p.moves().iter().filter(|m| m.kind == MoveKind::Print).map(|m| (m.from, m.to, m.extrusion_speed, m.duration())).collect()
    };
    let want = prints(&plain);
    assert_eq!(want.len(), 2);
    for (file, skipped) in [
        ("prusaslicer.gcode", &["M862.3", "M862.1", "M73", "M201", "M107", "M104", "M109", "G28", "G80", "M900", "M84"][..]),
        ("cura.gcode", &["M140", "M105", "M190", "M109", "G28", "M107", "M84"][..]),
        ("klipper.gcode", &["PRINT_START", "PRINT_END", "EXCLUDE_OBJECT_DEFINE", "SET_VELOCITY_LIMIT", "M117", "M107", "M104", "M84"][..]),
        ("simplify3d.gcode", &["M106", "M104", "M109", "G28", "T0", "M84"][..]),
        ("robot.gcode", &["M400", "M84"][..]),
    ] {
        let (p, notes) = parse_gcode_with_notes(&read(root().join("fixtures/gcode").join(file)), &opts).unwrap_or_else(|e| panic!("{file}: {e}"));
        let got = prints(&p);
        assert_eq!(got.len(), want.len(), "{file}: {:?}", p.moves());
        for (g, w) in got.iter().zip(&want) {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
            assert!((0..3).all(|i| close(g.0[i], w.0[i]) && close(g.1[i], w.1[i])) && close(g.2, w.2) && close(g.3, w.3), "{file}: {g:?} against {w:?}");
        }
        assert!((p.total_extruded_length() - plain.total_extruded_length()).abs() < 1e-12, "{file}");
        for k in skipped {
            assert!(notes.skipped.contains_key(*k), "{file}: {k} not in {notes}");
        }
        assert!(notes.primed == 0.0, "{file}: {notes}"); // every un-retraction restores its retraction
    }
}

/// The start-up note of a run on slicer G-code, one line.
#[test]
fn check_notes_what_the_gcode_import_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/print/two_layers_gcode.toml")).unwrap();
    let gcode = root().join("fixtures/gcode/klipper.gcode");
    let sc = write(dir.path(), "k.toml", &text.replace("gcode = \"two_layers.gcode\"", &format!("gcode = {:?}", s(&gcode))));
    let o = strand(&["check", s(&sc)]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let line = err.lines().find(|l| l.starts_with("note: ")).unwrap_or_else(|| panic!("no note: {err}"));
    assert!(line.contains("klipper.gcode: skipped 17 machine-state command(s)") && line.contains("PRINT_START x1") && line.contains("M104 x2"), "{line}");
}

// The four parsers on arbitrary input: an error or a value, never a panic or a hang.

fn gcode_line() -> impl Strategy<Value = String> {
    let word = prop_oneof![
        "[GMTNXYZEFPS][-+]?[0-9]{0,4}(\\.[0-9]{0,3})?",
        "[A-Z_]{2,12}( [A-Z]+=[0-9]+)?",
        "M11[78] [ -~]{0,20}",
        "\\([ -~]{0,10}\\)?",
        ";[ -~]{0,10}",
        "[ -~]{0,6}",
    ];
    prop::collection::vec(word, 0..6).prop_map(|w| w.join(" "))
}

// 256 cases each (proptest's default; PROPTEST_CASES sets another number, as `make fuzz` does)
proptest! {
    #[test]
    fn parsers_gcode_never_panics(lines in prop::collection::vec(gcode_line(), 0..40)) {
        let _ = strand::print::gcode::parse_gcode_with_notes(&lines.join("\n"), &strand::print::gcode::GcodeOptions::default());
    }

    #[test]
    fn parsers_scenario_never_panics(edits in prop::collection::vec(("[a-z_]{1,12}", "[-+]?[0-9]{0,4}(\\.[0-9]{0,3})?(e[-+]?[0-9]{1,3})?|inf|nan|\"[ -~]{0,8}\"|\\[[0-9., ]{0,12}\\]"), 0..6), cut in 0usize..2000) {
        // the test slump with values replaced (kept in range of the table's keys) and cut anywhere
        let mut text = slump(0.05, 1.0);
        for (key, value) in &edits {
            text = text.replacen("viscosity = 1", &format!("{key} = {value}\nviscosity = 1"), 1);
            text = text.replacen("dx = 0.02", &format!("dx = {value}"), usize::from(key.len() % 3 == 0));
        }
        let text: String = text.chars().take(cut.max(text.len() / 2)).collect();
        if let Ok(sc) = strand::scenario::Scenario::parse(&text) {
            let _ = strand::run::preflight(&sc);
        }
    }

    #[test]
    fn parsers_measurement_csv_never_panics(rows in prop::collection::vec(("[A-Za-z0-9]{0,4}", "[a-z_]{0,8}(@[-0-9.e]{0,6}(:[-0-9.]{0,4})?)?", "[-0-9.e:]{0,8}", "[-0-9.einf]{0,8}", "[-0-9.e]{0,6}"), 0..12)) {
        let mut text = "experiment,observable,at,value,uncertainty\n".to_string();
        for (a, b, c, d, e) in &rows {
            text += &format!("{a},{b},{c},{d},{e}\n");
        }
        let _ = strand::measure::observation::parse_observations(&text);
    }

    #[test]
    fn parsers_checkpoint_reader_never_panics(flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8), cut in any::<prop::sample::Index>(), hlen in prop::option::of(any::<u64>())) {
        let good = checkpoint_bytes();
        let mut b = good.to_vec();
        for (at, v) in &flips {
            let i = at.index(b.len());
            b[i] = *v;
        }
        if let Some(h) = hlen {
            b[16..24].copy_from_slice(&h.to_le_bytes());
        }
        b.truncate(cut.index(b.len() + 1).max(1));
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.ckpt");
        std::fs::write(&p, &b).unwrap();
        let _ = strand::checkpoint::Checkpoint::open(&p);
    }
}

/// A real checkpoint of the test slump's end (written once per test process).
fn checkpoint_bytes() -> &'static [u8] {
    static BYTES: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    BYTES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let sc = write(dir.path(), "s.toml", &slump(0.01, 1.0));
        let out = dir.path().join("out");
        assert!(run(&sc, &out, &[]).status.success());
        let ck = std::fs::read_dir(out.join("checkpoints")).unwrap().flatten().map(|e| e.path()).find(|p| p.extension().is_some_and(|x| x == "ckpt")).unwrap();
        std::fs::read(ck).unwrap()
    })
}
