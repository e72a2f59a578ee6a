//! The observables against the reporter's and against central differences.

use super::state::Frame;
use super::{names, At, Objective, Seed};
use crate::kernels::{Real, V3};
use crate::solver::Simulation;
use crate::observe::{self, Cloud};
use crate::scenario::Scenario;

/// The two-layer print of the gradient tests, its y >= 0 half observed with the mirror image
/// (`half`) or whole, at three stations.
fn two_layers(half: bool) -> String {
    let text = include_str!("../../fixtures/scenarios/grad/two_layers.toml").replace("stations = [0.015]", "stations = [0.006, 0.015, 0.024]");
    if half {
        return text;
    }
    text.replace("min = [-0.02, 0.0, 0.0]", "min = [-0.02, -0.04, 0.0]").replace("y_min = \"symmetry\"\n", "").replace("mirror_y = 0.0\n", "")
}

fn run(text: &str) -> (Scenario, Simulation) {
    let sc = Scenario::parse(text).unwrap();
    let mut sim = Simulation::new(&sc).unwrap();
    let end = sc.simulation.end_time;
    while sim.time < end * (1.0 - 1e-12) {
        sim.step_until(end).unwrap();
    }
    (sc, sim)
}

/// The reporter's cloud: positions and volumes, with the mirror images under `mirror_y`.
fn cloud_of(sim: &Simulation, mirror_y: Option<f64>) -> (Vec<[f64; 3]>, Vec<f64>) {
    let p = &sim.particles;
    let mut pos: Vec<[f64; 3]> = (0..p.n).map(|i| sim.position(i)).collect();
    let mut vol: Vec<f64> = (0..p.n).map(|i| (p.vol0.as_slice()[i] * p.j.as_slice()[i]) as f64).collect();
    if let Some(y0) = mirror_y {
        for i in 0..p.n {
            pos.push([pos[i][0], 2.0 * y0 - pos[i][1], pos[i][2]]);
            vol.push(vol[i]);
        }
    }
    (pos, vol)
}

fn value(sim: &Simulation, frame: &Frame, name: &str) -> f64 {
    name.parse::<Objective>().unwrap().evaluate(sim, frame, None).unwrap()
}

/// The smooth width and height: near the extreme-based ones, the same for the half model with
/// its mirror image as for the whole, and their seeds those of central differences in each
/// particle's position, volume ratio and initial volume.
#[test]
fn smooth_width_and_height_are_near_the_extremes_and_their_seeds_are_their_derivatives() {
    let mut whole = Vec::new();
    for half in [false, true] {
        let (_, mut sim) = run(&two_layers(half));
        let frame = Frame::of(&sim);
        let x = 0.015;
        let mut got = Vec::new();
        for (smooth, extreme) in [("smooth_width", "width"), ("smooth_height", "height")] {
            let name = format!("{smooth}@{x}");
            let (v, e) = (value(&sim, &frame, &name), value(&sim, &frame, &format!("{extreme}@{x}")));
            assert!((v - e).abs() <= 2.0 * frame.spacing, "half {half}: {name} {v} against {extreme} {e}");
            got.push(v);
            let n = sim.particles.n;
            let (mut xg, mut vel, mut j, mut mass, mut vol0) = (vec![V3::ZERO; n], vec![V3::ZERO; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            let obj: Objective = name.parse().unwrap();
            let seed = Seed { xg: &mut xg, v: &mut vel, j: &mut j, mass: &mut mass, vol0: &mut vol0 };
            obj.evaluate(&sim, &frame, Some(seed)).unwrap();
            // the particles the edges hang on most, in each coordinate, and in J and V0
            let heaviest = |g: &dyn Fn(usize) -> f64| (0..n).max_by(|&a, &b| g(a).abs().total_cmp(&g(b).abs())).unwrap();
            let mut checked = 0;
            for which in 0..5 {
                let g = |i: usize| match which { 0 => xg[i].x, 1 => xg[i].y, 2 => xg[i].z, 3 => j[i], _ => vol0[i] } as f64;
                let i = heaviest(&g);
                if g(i) == 0.0 {
                    continue;
                }
                let eps = 1e-6;
                let scale = if which == 4 { sim.particles.vol0.as_slice()[i] as f64 } else { 1.0 };
                let mut at = |e: f64| {
                    let p = &mut sim.particles;
                    match which {
                        0 => p.xg.as_mut_slice()[i].x += e as Real,
                        1 => p.xg.as_mut_slice()[i].y += e as Real,
                        2 => p.xg.as_mut_slice()[i].z += e as Real,
                        3 => p.j.as_mut_slice()[i] += e as Real,
                        _ => p.vol0.as_mut_slice()[i] += e as Real,
                    }
                    value(&sim, &frame, &name)
                };
                let (up, down) = (at(eps * scale), at(-2.0 * eps * scale));
                at(eps * scale);
                let fd = (up - down) / (2.0 * eps * scale);
                assert!((fd - g(i)).abs() <= 1e-4 * g(i).abs(), "half {half}, {name}, particle {i}, derivative {which}: seed {:e}, central differences {fd:e}", g(i));
                checked += 1;
            }
            assert!(checked >= 4, "half {half}, {name}: {checked} derivatives seeded");
        }
        whole.push(got);
    }
    for k in 0..2 {
        assert!((whole[0][k] - whole[1][k]).abs() <= 0.05 * whole[0][k], "whole {:?} against half {:?}", whole[0], whole[1]);
    }
}

#[test]
fn profile_points_and_layer_heights_and_widths_are_the_reporters_observables() {
    for half in [true, false] {
        let (sc, sim) = run(&two_layers(half));
        let frame = Frame::of(&sim);
        assert_eq!(frame.mirror_y, half.then_some(0.0));
        let mut reporter = crate::report::Reporter::new(&sc, &sim).unwrap().unwrap();
        let o = reporter.observe(&sim).clone();
        let (pos, vol) = cloud_of(&sim, frame.mirror_y);
        let cloud = Cloud { pos: &pos, vol: &vol, spacing: frame.spacing };
        let tops: Vec<f64> = sim.printer.as_ref().unwrap().toolpath.layers().iter().map(|l| l.0).collect();
        assert_eq!(tops, [0.006, 0.012]);
        let mut interpolated = 0;
        for (k, section) in o.sections.iter().enumerate() {
            let x = section.station;
            let (first, last) = (section.profile[0][0], section.profile.last().unwrap()[0]);
            // across the section and 3 mm beyond, off the bin edges (where the outline is vertical)
            for j in 0..=200 {
                let y = first - 0.003 + (last - first + 0.006) * (j as f64 + 0.37) / 200.0;
                let want = observe::profile_z_at(&section.profile, y).map_or(0.0, |z| z - frame.base_z);
                let got = value(&sim, &frame, &format!("profile@{x}:{y}"));
                assert!((got - want).abs() <= 1e-12, "half {half}, profile@{x}:{y}: {got} against the reporter's outline {want}");
                interpolated += usize::from(got > 0.0 && section.profile.iter().all(|p| p[0] != y));
            }
            let widths = observe::layer_widths(&cloud, x, frame.slab, &tops);
            assert_eq!(o.layers[k].len(), 2);
            for layer in 1..=2 {
                let got = value(&sim, &frame, &format!("layer_height@{x}:{layer}"));
                assert!((got - o.layers[k][layer - 1]).abs() <= 1e-12, "half {half}, layer_height@{x}:{layer}: {got} against {:?}", o.layers[k]);
                let got = value(&sim, &frame, &format!("layer_width@{x}:{layer}"));
                assert!((got - widths[layer - 1]).abs() <= 1e-12, "half {half}, layer_width@{x}:{layer}: {got} against {widths:?}");
                assert!(widths[layer - 1] > 0.0 && o.layers[k][layer - 1] > 0.0);
            }
            // the layers add up to the section's height, and the widest layer is the section's width
            assert!((o.layers[k].iter().sum::<f64>() - section.height).abs() <= 1e-12, "{:?} against {}", o.layers[k], section.height);
            assert!((widths.iter().cloned().fold(0.0, f64::max) - section.width).abs() <= 1e-12, "{widths:?} against {}", section.width);
        }
        assert!(interpolated > 100, "{interpolated} points between outline vertices");
        // no such layer, no material
        let e = "layer_height@0.015:3".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string();
        assert!(e.contains("layer 3") && e.contains("1..=2"), "{e}");
        let e = "profile@0.05:0".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string();
        assert!(e.contains("no particle"), "{e}");
    }
}

#[test]
fn the_profile_drops_to_the_base_between_filaments_and_beside_them() {
    // two boxes of 2 x 5 x 4 and 2 x 2 x 2 particles (10 mm cells, 2 per cell), 15 mm apart
    let text = r#"
name = "two-boxes"
[simulation]
dx = 0.01
end_time = 0.1
[domain]
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 1e5
viscosity = 1.0
[[body]]
shape = "box"
min = [0.02, 0.02, 0.0]
max = [0.03, 0.045, 0.02]
[[body]]
shape = "box"
min = [0.02, 0.06, 0.0]
max = [0.03, 0.07, 0.01]
[memory]
budget = "16 MiB"
"#;
    let sc = Scenario::parse(text).unwrap();
    let sim = Simulation::new(&sc).unwrap();
    let frame = Frame::of(&sim);
    let (pos, vol) = cloud_of(&sim, None);
    let cloud = Cloud { pos: &pos, vol: &vol, spacing: frame.spacing };
    let section = observe::cross_section(&cloud, 0.025, frame.slab, frame.base_z);
    assert_eq!(section.profile.len(), 5 + 2 + 8, "{:?}", section.profile);
    // the level is the height where there is material, 0 where there is none
    let top = section.height;
    assert!((value(&sim, &frame, "level@0.025") - top).abs() <= 1e-12 && (value(&sim, &frame, "height@0.025") - top).abs() <= 1e-12);
    assert_eq!(value(&sim, &frame, "level@0.08"), 0.0);
    assert!("height@0.08".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string().contains("no particle"));
    assert_eq!("level@0.025".parse::<Objective>().unwrap().name(), "level@0.025");
    assert!("level@0.02,0.03".parse::<Objective>().unwrap_err().to_string().contains("one station"));
    for j in 0..100 {
        let y = 0.01 + 0.07 * (j as f64 + 0.5) / 100.0;
        let want = observe::profile_z_at(&section.profile, y).map_or(0.0, |z| z - frame.base_z);
        let got = value(&sim, &frame, &format!("profile@0.025:{y}"));
        assert!((got - want).abs() <= 1e-12, "y = {y}: {got} against {want}");
        let expect = if (0.02..=0.045).contains(&y) {
            0.02
        } else if (0.06..=0.07).contains(&y) {
            0.01
        } else {
            0.0
        };
        assert!((got - expect).abs() <= 1e-9, "y = {y}: {got}, a box top of {expect}");
    }
}

#[test]
fn names_parse_and_print_back_and_bad_ones_say_what_they_take() {
    for name in ["profile@0.075:0.01", "profile@0.075:-0.002", "layer_height@0.075:2", "layer_width@0.03:1", "smooth_width@0.04", "smooth_height@0.04"] {
        let o: Objective = name.parse().unwrap();
        assert_eq!(o.name(), name);
        assert_eq!(o.name().parse::<Objective>().unwrap(), o);
    }
    assert_eq!("profile@0.075:0.01".parse::<Objective>().unwrap().at, At::Point { station: 0.075, y: 0.01 });
    assert_eq!(" layer_height@0.075: 3".trim().parse::<Objective>().unwrap().at, At::Layer { station: 0.075, layer: 3 });
    for (bad, want) in [
        ("profile@0.075", "profile takes X:Y"),
        ("profile@0.075:", "profile takes X:Y"),
        ("profile@a:0.01", "profile takes X:Y"),
        ("profile@0.075:0.01:0.02", "profile takes X:Y"),
        ("profile@0.075:inf", "profile takes X:Y"),
        ("layer_height@0.075", "layer_height takes X:K"),
        ("layer_height@0.075:0", "layer K (1 = the bottom one)"),
        ("layer_height@0.075:1.5", "layer_height takes X:K"),
        ("layer_width@0.075:-1", "layer_width takes X:K"),
        ("smooth_width@0.04,0.05", "smooth_width takes one station"),
        ("smooth_height@x", "stations after '@' must be numbers"),
        ("profile", "unknown objective 'profile'"),
    ] {
        let e = bad.parse::<Objective>().unwrap_err().to_string();
        assert!(e.contains(want) && e.contains(bad), "{bad}: {e}");
    }
    for name in ["profile@X:Y", "layer_height@X:K", "layer_width@X:K"] {
        assert!(names().contains(name), "{}", names());
    }
}
