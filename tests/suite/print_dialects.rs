//! G-code as slicers and concrete printers write it (issue 53), and a robot's point list: each
//! fixture, read through a scenario's `[print]`, gives the same deposit as the equivalent scenario
//! `path`: the same printing moves (ends, durations, extrusion speeds), the same dwells and the
//! same extruded volume. A toolpath fixes what the emitter lays, so the same toolpath is the same
//! deposit; these comparisons take milliseconds where a simulated deposit takes seconds.

use strand::print::toolpath::{MoveKind, Toolpath};
use strand::scenario::Scenario;

fn root() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The default scenario's `[print]` toolpath lines (start and path).
const DEFAULT_PATH: &str = "start = [0.0, 0.0, 0.0125]
path = [
  { kind = \"print\", to = [0.04, 0.0, 0.0125], speed = 0.030, extrusion = 0.0336 },
  { kind = \"pause\", duration = 0.2 },
  { kind = \"layer\", dz = 0.0125, speed = 0.05 },
  { kind = \"print\", to = [0.0, 0.0, 0.025], speed = 0.030, extrusion = 0.0336 },
  { kind = \"pause\", duration = 0.15 },
]";

/// The default scenario's toolpath with `toolpath` (TOML lines of `[print]`) instead of its path.
fn toolpath(toolpath: &str) -> Toolpath {
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/default.toml")).unwrap();
    assert!(text.contains(DEFAULT_PATH), "fixtures/scenarios/default.toml changed its path");
    let sc = Scenario::parse(&text.replace(DEFAULT_PATH, toolpath)).unwrap_or_else(|e| panic!("{toolpath}: {e}"));
    sc.print.unwrap().toolpath(&sc.base_dir).unwrap_or_else(|e| panic!("{toolpath}: {e}"))
}

/// A fixture's `[print]` lines: `key = "<fixture>"` and its options.
fn from_file(key: &str, file: &str, options: &str) -> String {
    format!("{key} = {:?}\n{options}", root().join("fixtures").join(file).to_str().unwrap())
}

/// A move that deposits: (from, to, duration, U).
type PrintMove = ([f64; 3], [f64; 3], f64, f64);

/// Moves that deposit, and the dwells' durations.
fn prints_and_dwells(p: &Toolpath) -> (Vec<PrintMove>, Vec<f64>) {
    let prints = p.moves().iter().filter(|m| m.kind == MoveKind::Print).map(|m| (m.from, m.to, m.duration(), m.extrusion_speed)).collect();
    let dwells = p.moves().iter().filter(|m| m.kind == MoveKind::Pause).map(|m| m.duration()).collect();
    (prints, dwells)
}

/// `got` deposits as `want` does: the same printing moves within 1e-12 m, 1e-12 s and 1e-12
/// relative in U, the same extruded volume to 1e-12, and (`dwells`) the same dwells and end.
fn assert_same_deposit(name: &str, got: &Toolpath, want: &Toolpath, dwells: bool) {
    let ((gp, gd), (wp, wd)) = (prints_and_dwells(got), prints_and_dwells(want));
    assert_eq!(gp.len(), wp.len(), "{name}: {:?}", got.moves());
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
    for (g, w) in gp.iter().zip(&wp) {
        let same_ends = (0..3).all(|k| (g.0[k] - w.0[k]).abs() < 1e-12 && (g.1[k] - w.1[k]).abs() < 1e-12);
        assert!(same_ends && close(g.2, w.2) && close(g.3, w.3), "{name}: {g:?} against {w:?}");
    }
    let (gv, wv) = (got.total_extruded_length(), want.total_extruded_length());
    assert!(close(gv, wv), "{name}: extruded {gv} m against {wv} m");
    if dwells {
        assert!(gd.len() == wd.len() && gd.iter().zip(&wd).all(|(a, b)| close(*a, *b)), "{name}: dwells {gd:?} against {wd:?}");
        assert!(close(got.end_time(), want.end_time()), "{name}: ends at {} s against {} s", got.end_time(), want.end_time());
    }
}

/// PrusaSlicer 2.7: object labels, bare G4 and arc fitting give the scenario's two half circles.
#[test]
fn prusaslicer_arcs_labels_and_bare_g4_deposit_as_scenario_arcs() {
    let want = toolpath(
        "start = [0.0, 0.0, 0.0125]
path = [
  { kind = \"arc\", to = [0.04, 0.0, 0.0125], center = [0.02, 0.0], sense = \"cw\", speed = 0.03, extrusion = 0.0336 },
  { kind = \"pause\", duration = 0.2 },
  { kind = \"layer\", dz = 0.0125, speed = 0.05 },
  { kind = \"arc\", to = [0.0, 0.0, 0.025], center = [0.02, 0.0], sense = \"ccw\", speed = 0.03, extrusion = 0.0336 },
  { kind = \"pause\", duration = 0.15 },
]",
    );
    assert!(want.moves().iter().all(|m| m.to[1] >= -1e-15), "both halves through y > 0");
    let got = toolpath(&from_file("gcode", "gcode/prusaslicer_2_7.gcode", "gcode_options = { start = [0.0, 0.0, 12.5] }"));
    // the dwells too: a bare G4 waits for nothing
    assert_same_deposit("prusaslicer_2_7.gcode", &got, &want, true);
}

/// Cura for an Anycubic printer: the lift, the presenting move and `G28 X0` after the last
/// extrusion are skipped; the print is the scenario's to its end.
#[test]
fn cura_with_an_end_of_print_g28_deposits_as_the_scenario_path() {
    let want = toolpath(DEFAULT_PATH);
    let got = toolpath(&from_file("gcode", "gcode/cura.gcode", "gcode_options = { start = [0.0, 0.0, 12.5] }"));
    assert_same_deposit("cura.gcode", &got, &want, true);
}

/// Skeinforge: nested parentheses in comments.
#[test]
fn skeinforge_with_nested_comments_deposits_as_the_scenario_path() {
    let want = toolpath(DEFAULT_PATH);
    let got = toolpath(&from_file("gcode", "gcode/skeinforge.gcode", "gcode_options = { start = [0.0, 0.0, 12.5] }"));
    assert_same_deposit("skeinforge.gcode", &got, &want, true);
}

/// A pump-driven concrete printer: M3 S (L/min) / M5 and the spindle word, no E.
#[test]
fn a_pump_controlled_printer_deposits_as_the_scenario_path() {
    let want = toolpath(DEFAULT_PATH);
    let options = "gcode_options = { start = [0.0, 0.0, 12.5], flow_unit = 1.6666666666666667e-5, pump_on = \"M3\", pump_off = \"M5\" }";
    let got = toolpath(&from_file("gcode", "gcode/pump.gcode", options));
    assert_same_deposit("pump.gcode", &got, &want, true);
}

/// A robot's point list (no dwells in the format).
#[test]
fn a_robot_point_list_deposits_as_the_scenario_path() {
    let want = toolpath(DEFAULT_PATH);
    let got = toolpath(&from_file("points", "points/two_layers.csv", ""));
    assert_same_deposit("two_layers.csv", &got, &want, false);
    assert_eq!(got.moves().len(), 3); // print, layer change, print
}

/// One toolpath per `[print]`, and a bad row names the file and its line.
#[test]
fn point_list_errors_name_the_file_and_line() {
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/default.toml")).unwrap();
    let both = text.replace(DEFAULT_PATH, &(DEFAULT_PATH.to_string() + "\npoints = \"p.csv\""));
    let sc = Scenario::parse(&both);
    let msg = match sc {
        Err(e) => e.to_string(),
        Ok(sc) => sc.print.unwrap().validate().unwrap_err().to_string(),
    };
    assert!(msg.contains("print: give one toolpath, not print.path and print.points"), "{msg}");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.csv"), "x, y, z, speed, flow\n0, 0, 0.01, 0.03, 0\n0.04, 0, 0.01, fast, 1e-5\n").unwrap();
    let scenario = dir.path().join("s.toml");
    std::fs::write(&scenario, text.replace(DEFAULT_PATH, "points = \"p.csv\"")).unwrap();
    let sc = Scenario::load(&scenario).unwrap();
    let msg = sc.print.unwrap().toolpath(&sc.base_dir).unwrap_err().to_string();
    assert!(msg.contains("p.csv: points line 3: speed = \"fast\" is not a finite number"), "{msg}");
}

/// `strand check` says what the import skipped after the last extrusion, and warns of E that
/// looks like filament length (1.75 mm filament for a 0.4 mm nozzle: E 0.0374 per mm of path).
#[test]
fn check_notes_the_skipped_end_and_warns_of_filament_e() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.gcode"), "G21\nM83\nG1 X40 E1.496 F1800\nG1 Z30 F600\nG28 X0\n").unwrap();
    let text = std::fs::read_to_string(root().join("fixtures/scenarios/default.toml")).unwrap();
    let scenario = dir.path().join("s.toml");
    std::fs::write(&scenario, text.replace(DEFAULT_PATH, "gcode = \"p.gcode\"\ngcode_options = { start = [0.0, 0.0, 12.5] }")).unwrap();
    let (code, _, err) = crate::common::strand(&["check", scenario.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let note = err.lines().find(|l| l.starts_with("note: ")).unwrap_or_else(|| panic!("no note: {err}"));
    assert!(note.contains("p.gcode") && note.contains("2 motion command(s) after the last extrusion skipped"), "{note}");
    let warning = err.lines().find(|l| l.contains("E lays")).unwrap_or_else(|| panic!("no warning: {err}"));
    assert!(warning.starts_with("warning: ") && warning.contains("E lays 0.037 m of extrudate per metre of path") && warning.contains("filament_diameter"), "{warning}");
}
