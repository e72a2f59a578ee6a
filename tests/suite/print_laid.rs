//! Laid deposits (`[print] deposit = { kind = "laid", width, height }`, `src/print/laid.rs`):
//! each layer appears at rest in its section as the nozzle passes, so it brings no momentum and
//! mass scaling leaves it as it is (an extruded deposit under mass scaling s arrives with the
//! momentum flux s rho V^2 and spreads).

use crate::common;

/// The tiny print of two layers (12 mm nozzle, U = V: pi 6^2 mm2 of section per metre) laid in a
/// `WIDTH` x 6 mm section, with `mass_scaling = s`: the section at its station and the peak
/// kinetic-to-external-work ratio.
fn laid_wall(s: f64) -> (f64, f64, f64, f64) {
    let dir = tempfile::tempdir().unwrap();
    let text = common::tiny_print(1, 2, false, "256 MiB");
    let nozzle = "nozzle = { shape = \"circle\", diameter = 0.012 }";
    assert!(text.contains(nozzle) && text.contains("dx = 0.005\n"));
    let text = text
        .replace(nozzle, &format!("{nozzle}\ndeposit = {{ kind = \"laid\", width = {WIDTH}, height = 0.006 }}"))
        .replace("dx = 0.005\n", &format!("dx = 0.005\nmass_scaling = {s}\n"));
    let sc = dir.path().join("laid.toml");
    std::fs::write(&sc, text).unwrap();
    let j = common::run_within_budget(&sc, &dir.path().join("out"), &[]);
    let section = &j["last_observation"]["sections"][0];
    let get = |k: &str| section[k].as_f64().unwrap_or_else(|| panic!("no {k} in {section}"));
    (get("width"), get("height"), get("area"), j["inertia"]["peak_kinetic_to_external"].as_f64().unwrap_or(0.0))
}

const WIDTH: f64 = std::f64::consts::PI * 0.006 * 0.006 / 0.006;

#[test]
fn a_laid_wall_takes_its_section_and_mass_scaling_leaves_it_as_it_is() {
    let real = std::thread::spawn(|| laid_wall(1.0));
    let scaled = laid_wall(16.0);
    let real = real.join().unwrap();
    eprintln!("laid: s = 1 {real:?}; s = 16 {scaled:?} (width, height, area, peak KE/W)");
    for (w, h, a, ke) in [real, scaled] {
        // two layers of the section, settled by less than a millimetre; the width and area as
        // the section observable measures them from particle positions
        assert!((w / WIDTH - 1.0).abs() < 0.05, "width {w} against {WIDTH}");
        assert!(h < 0.012 + 1e-9 && h > 0.011, "height {h} against 2 x 6 mm");
        assert!((a / (2.0 * WIDTH * 0.006) - 1.0).abs() < 0.05, "area {a}");
        assert!(ke < 0.01, "a laid deposit is quasi-static: peak KE/W {ke}");
    }
    // mass scaling accelerates the wall's response only
    assert!((scaled.0 / real.0 - 1.0).abs() < 0.01 && (scaled.1 / real.1 - 1.0).abs() < 0.01, "{scaled:?} against {real:?}");
}
