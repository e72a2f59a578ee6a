//! Arcs: the same circle printed through every form strand reads (a scenario `arc` by its centre
//! and by its radius, G-code G2 and G3 with I/J and with R) is the same toolpath circle with the
//! same extruded volume, and two forms turning opposite ways deposit the same ring.

// `m as f64` is a no-op in the default build but a conversion with the `f32` feature.
#![allow(clippy::unnecessary_cast)]

use crate::common;

use strand::print::gcode::{parse_gcode, GcodeOptions};
use strand::print::toolpath::Toolpath;
use strand::scenario::Scenario;
use strand::solver::Simulation;

/// The circle: radius 15 mm about (25, 0) mm at the tiny print's height, 6 mm, from (10, 0) mm,
/// at 60 mm/s extruding at 60 mm/s (E counts mm of extrudate: E = the arc's length in mm).
const CENTER: [f64; 2] = [0.025, 0.0];
const R: f64 = 0.015;
const Z: f64 = 0.006;
const SPEED: f64 = 0.06;
/// The print ends at 2 pi R / V; the runs stop 0.1 s after it.
const T_END: f64 = std::f64::consts::TAU * R / SPEED + 0.1;

/// The scenario `path` lines of each scenario form.
fn scenario_forms() -> [(&'static str, String); 2] {
    let arc = |to: f64, geometry: &str| {
        format!("  {{ kind = \"arc\", to = [{to}, 0.0, {Z}], {geometry}, sense = \"ccw\", speed = {SPEED}, extrusion = {SPEED} }},\n")
    };
    [
        ("scenario arc, center", arc(0.01, "center = [0.025, 0.0], turns = 1")),
        ("scenario arc, radius (two halves)", arc(0.04, "radius = 0.015") + &arc(0.01, "radius = 0.015")),
    ]
}

/// The moves of each G-code form (millimetres, relative E).
fn gcode_forms() -> [(&'static str, String); 4] {
    let e = std::f64::consts::TAU * 15.0;
    let h = e / 2.0;
    [
        ("G2 I/J", format!("G2 X10 Y0 I15 J0 E{e:.12} F3600\n")),
        ("G3 I/J", format!("G3 X10 Y0 I15 J0 E{e:.12} F3600\n")),
        ("G2 R", format!("G2 X40 Y0 R15 E{h:.12} F3600\nG2 X10 Y0 R15 E{h:.12}\n")),
        ("G3 R and I/J, relative", format!("G91\nG3 X30 Y0 R-15 E{h:.12} F3600\nG3 X-30 Y0 I-15 J0 E{h:.12}\n")),
    ]
}

fn gcode_file(moves: &str) -> String {
    format!("G21\nG90\nM83\n{moves}G4 P100\n")
}

/// The tiny print's scenario with `path` lines instead of its straight line.
fn scenario_text(path: &str) -> String {
    let text = common::tiny_print(2, 1, false, "256 MiB");
    let line = "  { kind = \"print\", to = [0.05, 0.0, 0.006], speed = 0.04, extrusion = 0.04 },\n";
    assert!(text.contains(line) && text.contains("start = [0.0, 0.0, 0.006]"), "{text}");
    text.replace(line, path).replace("start = [0.0, 0.0, 0.006]", "start = [0.01, 0.0, 0.006]")
}

/// The tiny print's scenario reading `p.gcode` (start at (10, 0, 6) mm).
fn gcode_scenario_text() -> String {
    let text = scenario_text("")
        .replace("start = [0.01, 0.0, 0.006]", "gcode = \"p.gcode\"\ngcode_options = { start = [10.0, 0.0, 6.0] }")
        .replace("path = [\n  { kind = \"pause\", duration = 0.1 },\n]", "");
    assert!(!text.contains("path =") && text.contains("gcode ="), "{text}");
    text
}

#[test]
fn every_arc_form_gives_the_same_circle_and_volume() {
    let mut paths: Vec<(&str, Toolpath)> = Vec::new();
    for (name, path) in scenario_forms() {
        let sc = Scenario::parse(&scenario_text(&path)).unwrap_or_else(|e| panic!("{name}: {e}"));
        paths.push((name, sc.print.unwrap().toolpath(&sc.base_dir).unwrap()));
    }
    let opts = GcodeOptions { start: [10.0, 0.0, 6.0], ..GcodeOptions::default() };
    for (name, moves) in gcode_forms() {
        paths.push((name, parse_gcode(&gcode_file(&moves), &opts).unwrap_or_else(|e| panic!("{name}: {e}"))));
    }
    let volume = std::f64::consts::TAU * R; // extruded length: U = V over the circle
    let print_time = std::f64::consts::TAU * R / SPEED;
    for (name, p) in &paths {
        assert!((p.total_extruded_length() / volume - 1.0).abs() < 1e-12, "{name}: extruded {}", p.total_extruded_length());
        let last_print = p.moves().iter().rev().find(|m| m.extrusion_speed > 0.0).unwrap();
        assert!((last_print.t1 / print_time - 1.0).abs() < 1e-12, "{name}: the circle ends at {} s", last_print.t1);
        assert!(p.moves().len() >= 72, "{name}: {} moves", p.moves().len());
        for m in p.moves() {
            let r = (m.to[0] - CENTER[0]).hypot(m.to[1] - CENTER[1]);
            assert!((r - R).abs() < 1e-12 && (m.to[2] - Z).abs() < 1e-15, "{name}: {m:?} off the circle (r = {r})");
        }
        let end = p.moves().last().unwrap().to;
        assert!((end[0] - 0.01).abs() < 1e-15 && end[1].abs() < 1e-15, "{name}: ends at {end:?}");
    }
}

/// Mass of every particle and the mean and standard deviation of the deposited particles'
/// (below the outlet) distance from the circle's axis.
fn deposit(s: &Simulation) -> (f64, f64, f64) {
    let p = &s.particles;
    let mass: f64 = p.mass.as_slice()[..p.n].iter().map(|&m| m as f64).sum();
    let r: Vec<f64> =
        (0..p.n).map(|i| s.position(i)).filter(|x| x[2] < Z).map(|x| (x[0] - CENTER[0]).hypot(x[1] - CENTER[1])).collect();
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let sd = (r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / r.len() as f64).sqrt();
    assert!(r.len() > 200, "{} deposited particles", r.len());
    (mass, mean, sd)
}

fn run(sc: &Scenario) -> Simulation {
    let mut s = Simulation::new(sc).unwrap();
    while s.time < T_END {
        s.step_until(T_END).unwrap();
    }
    s
}

/// The scenario arc turning counter-clockwise and G-code G2 turning clockwise lay the same ring:
/// the same mass, and the deposited particles at the same mean distance from the axis with the
/// same spread, within 0.2 mm (a twenty-fifth of a 5 mm cell; a circle 1 mm larger fails it).
#[test]
fn a_scenario_arc_and_gcode_g2_deposit_the_same_ring() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.gcode"), gcode_file(&gcode_forms()[0].1)).unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(&path, gcode_scenario_text()).unwrap();
    let gcode = Scenario::load(&path).unwrap();
    let other = std::thread::spawn(move || deposit(&run(&gcode)));
    let (ma, ra, sa) = deposit(&run(&Scenario::parse(&scenario_text(&scenario_forms()[0].1)).unwrap()));
    let (mb, rb, sb) = other.join().unwrap();
    eprintln!("scenario arc: mass {ma} kg, radius {ra} m, spread {sa} m; G2: {mb} kg, {rb} m, {sb} m");
    assert!((ma / mb - 1.0).abs() < 1e-6, "mass {ma} vs {mb} kg");
    assert!((ra - R).abs() < 2e-3, "the ring's mean radius {ra} m is not about the circle's {R} m");
    assert!((ra - rb).abs() < 2e-4, "mean radius {ra} vs {rb} m");
    assert!((sa - sb).abs() < 2e-4, "radial spread {sa} vs {sb} m");
}
