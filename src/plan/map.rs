//! The printability map (`strand plan --map`): the print run over a grid of two settings, the
//! others held at the plan's point (or, when no plan meets the targets, the search's start).
//!
//! Each grid point is an experiment of the measurement loop (`line.rs`), so the points run on
//! the engine of `measure::engine`: here, `--jobs` at a time, or as the jobs of GNU parallel,
//! Slurm or HyperQueue (`--engine`); every run's memory is planned before the first. A point
//! gives the layer's width and height at the station by a forward run, and the closed form the
//! wall's buildable height at the plan's layer time (or the nozzle's, when that is longer). A
//! point is feasible when the width and the height are within their tolerances and the wall
//! stands to its design height times the safety factor there. Written as CSV (a row a point)
//! and a PNG of heat maps (width, height, buildable height) with the feasible cells outlined
//! and the plan's point marked.

use super::build::WallGoal;
use super::constraint::Buildable;
use super::error::PlanError;
use super::line::{Line, Point};
use super::targets::{Setting, Targets};
use crate::measure::engine::Engine;
use crate::measure::observation::{Observable, Observation};
use crate::measure::runner::{evaluate, find, group, job_threads, par_map_experiments, Jobs};
use crate::output::plot::{plot_heat_maps, HeatMap};
use std::path::Path;

/// A map's axis: a setting over `n` values from its lower to its upper bound.
#[derive(Clone, Copy, Debug)]
pub struct Axis {
    pub setting: Setting,
    pub bounds: [f64; 2],
    pub n: usize,
}

impl Axis {
    pub fn values(&self) -> Vec<f64> {
        let [lo, hi] = self.bounds;
        (0..self.n).map(|k| if self.n == 1 { lo } else { lo + (hi - lo) * k as f64 / (self.n - 1) as f64 }).collect()
    }
    fn index(&self) -> usize {
        self.setting.index()
    }
}

/// The axes `x` and `y` named by `spec` ("speed,extrusion"), over the targets' bounds, `n` x `m`
/// points (`size` "3x3").
pub fn axes(spec: &str, size: &str, targets: &Targets) -> Result<[Axis; 2], PlanError> {
    let names: Vec<&str> = spec.split(',').map(str::trim).collect();
    let counts: Vec<usize> = size.split('x').map(|s| s.trim().parse::<usize>()).collect::<Result<_, _>>().map_err(|_| PlanError::Targets(format!("--map-size {size}: give the points along each axis as NxM, for example 3x3")))?;
    if names.len() != 2 || counts.len() != 2 || names[0] == names[1] {
        return Err(PlanError::Targets(format!("--map {spec} --map-size {size}: a map has two different settings and two counts (speed,extrusion and 3x3)")));
    }
    let mut out = Vec::new();
    for (name, n) in names.iter().zip(counts) {
        let setting = Setting::parse(name).ok_or_else(|| PlanError::Targets(format!("--map: unknown setting '{name}'; a map's axes are speed, extrusion, standoff")))?;
        let bounds = targets.settings.of(setting).ok_or_else(|| PlanError::Targets(format!("--map: settings.{name} has no bounds in the targets: they span the map's axis")))?;
        if n < 2 {
            return Err(PlanError::Targets(format!("--map-size {size}: at least 2 points along each axis")));
        }
        out.push(Axis { setting, bounds, n });
    }
    Ok([out[0], out[1]])
}

/// One grid point.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MapPoint {
    pub x: Point,
    pub width: f64,
    pub height: f64,
    pub buildable: Option<Buildable>,
    pub feasible: bool,
    /// Why the point's run gave no layer.
    pub error: Option<String>,
}

/// The map: its axes, its points (the first axis fastest) and the point marked.
pub struct Map {
    pub axes: [Axis; 2],
    pub points: Vec<MapPoint>,
    pub marked: Point,
    pub layer_time: Option<f64>,
    pub seconds: f64,
}

/// The map of `line` over `axes` around `centre` (the plan's point), the wall's buildable height
/// at `layer_time`, on `engine` `jobs` at a time.
#[allow(clippy::too_many_arguments)]
pub fn map(line: &Line, targets: &Targets, wall: Option<&WallGoal>, axes: [Axis; 2], centre: &Point, layer_time: Option<f64>, engine: &Engine, jobs: usize) -> Result<Map, PlanError> {
    let clock = std::time::Instant::now();
    let mut xs = Vec::new();
    for b in axes[1].values() {
        for a in axes[0].values() {
            let mut x = *centre;
            x[axes[0].index()] = a;
            x[axes[1].index()] = b;
            xs.push(x);
        }
    }
    line.preflight(&xs)?;
    let exps = line.campaign(&xs);
    let names = line.observables();
    let data: Vec<Observation> = exps
        .experiment
        .iter()
        .flat_map(|e| names.iter().map(move |n| (e.id.clone(), n)))
        .map(|(experiment, n)| Ok(Observation { experiment, observable: Observable::parse(n)?, value: 0.0, uncertainty: 1.0 }))
        .collect::<Result<_, PlanError>>()?;
    let values: Vec<Result<[f64; 2], String>> = match engine {
        // a point whose run fails (a line broken up at the station) is a hole in the map
        Engine::Local => {
            let wanted = group(&data);
            let threads = job_threads(jobs, wanted.len());
            par_map_experiments(&wanted, jobs, |k, _| {
                let (id, obs) = &wanted[k];
                Ok(evaluate(&line.model, &exps, find(&exps, id)?, obs, threads).map(|v| [v[0], v[1]]).map_err(|e| e.to_string()))
            })?
        }
        // a scheduler's jobs: one failing fails the map
        _ => engine.evaluate(Jobs::new(jobs), &line.model, (&data, &exps), (None, None))??.values.chunks(2).map(|v| Ok([v[0], v[1]])).collect(),
    };
    let l = &targets.layer;
    let length = targets.layer_length(line.length);
    let mut points = Vec::new();
    for (k, x) in xs.iter().enumerate() {
        let ([width, height], error) = match &values[k] {
            Ok(v) => (*v, None),
            Err(e) => ([f64::NAN; 2], Some(e.clone())),
        };
        let meets = (width - l.width).abs() <= l.width_tolerance && (height - l.height).abs() <= l.height_tolerance;
        let buildable = match (wall, layer_time) {
            (Some(g), Some(t)) if error.is_none() => Some(g.wall.buildable(width, height, t.max(length / x[0]), 2.0 * g.need())?),
            _ => None,
        };
        let stands = match (wall, &buildable) {
            (Some(g), Some(b)) => b.height >= g.need(),
            _ => true,
        };
        points.push(MapPoint { x: *x, width, height, buildable, feasible: meets && stands, error });
    }
    Ok(Map { axes, points, marked: *centre, layer_time, seconds: clock.elapsed().as_secs_f64() })
}

/// The map as CSV: the settings, the layer, the buildable height and failure mode, feasibility.
pub fn write_csv(m: &Map, path: &Path) -> Result<(), PlanError> {
    let mut s = String::from("speed,extrusion,standoff,width,height,buildable_height,failure_mode,feasible\n");
    for p in &m.points {
        let (bh, mode) = match &p.buildable {
            Some(b) => (b.height.to_string(), b.mode.map_or("none", |x| x.name()).to_string()),
            None => (String::new(), String::new()),
        };
        s += &format!("{},{},{},{},{},{bh},{mode},{}\n", p.x[0], p.x[1], p.x[2], p.width, p.height, p.feasible);
    }
    std::fs::write(path, s).map_err(|e| PlanError::Io(format!("{}: {e}", path.display())))
}

/// The map as heat maps of width, height [mm] and buildable height [m] (with a wall) in a PNG.
pub fn write_png(m: &Map, path: &Path) -> Result<(), PlanError> {
    let [a, b] = m.axes;
    let (xs, ys): (Vec<f64>, Vec<f64>) = (a.values().iter().map(|v| v * 1e3).collect(), b.values().iter().map(|v| v * 1e3).collect());
    let marked: Vec<bool> = m.points.iter().map(|p| p.feasible).collect();
    let point = Some([m.marked[a.index()] * 1e3, m.marked[b.index()] * 1e3]);
    let panel = |title: &str, values: Vec<f64>| HeatMap { title: title.into(), xs: xs.clone(), ys: ys.clone(), values, marked: marked.clone(), point };
    let mut panels = vec![panel("width [mm]", m.points.iter().map(|p| p.width * 1e3).collect()), panel("height [mm]", m.points.iter().map(|p| p.height * 1e3).collect())];
    if m.points.iter().any(|p| p.buildable.is_some()) {
        let t = m.layer_time.map_or(String::new(), |t| format!(" at T = {t:.1} s"));
        panels.push(panel(&format!("buildable height [m]{t}"), m.points.iter().map(|p| p.buildable.map_or(f64::NAN, |b| b.height)).collect()));
    }
    let xd = format!("{} [{}]", a.setting.name(), a.setting.unit().0);
    let yd = format!("{} [{}]", b.setting.name(), b.setting.unit().0);
    Ok(plot_heat_maps(path, &xd, &yd, &panels)?)
}

/// The map as text: a row a point.
pub fn text(m: &Map) -> String {
    let mut s = format!("map: {} x {} points in {:.1} s (feasible: *)\n", m.axes[0].n, m.axes[1].n, m.seconds);
    s += "   speed mm/s  extrusion mm/s  standoff mm   width mm  height mm  buildable m\n";
    for p in &m.points {
        let bh = p.buildable.map_or("-".to_string(), |b| format!("{:.3}", b.height));
        let why = p.error.as_ref().map_or(String::new(), |e| format!("  ({e})"));
        s += &format!("{} {:>11.2} {:>15.2} {:>12.2} {:>10.3} {:>10.3} {:>12}{why}\n", if p.feasible { "*" } else { " " }, p.x[0] * 1e3, p.x[1] * 1e3, p.x[2] * 1e3, p.width * 1e3, p.height * 1e3, bh);
    }
    s
}

/// `s` with HTML's special characters escaped.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// The map as an HTML page at `path`: the targets, the heat maps (the PNG `png`, linked by its
/// file name, so the page and its image travel together in one folder) with the region that
/// meets the targets outlined and the plan's point crossed, and a table of the points, the
/// feasible ones shaded. Nothing is fetched from elsewhere.
pub fn write_html(m: &Map, targets: &Targets, png: &Path, path: &Path) -> Result<(), PlanError> {
    use std::fmt::Write;
    let [a, b] = m.axes;
    let l = &targets.layer;
    let name = png.file_name().map_or_else(|| png.display().to_string(), |n| n.to_string_lossy().into_owned());
    let mut s = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>strand plan: printability map</title>\n<style>\nbody { font-family: sans-serif; margin: 2em auto; max-width: 1280px; padding: 0 1em; }\ntable { border-collapse: collapse; }\nth, td { border: 1px solid #bbb; padding: 0.2em 0.6em; text-align: right; }\nth { background: #eee; }\ntr.feasible { background: #dfd; }\ntr.plan { font-weight: bold; }\nimg { max-width: 100%; }\n</style>\n</head>\n<body>\n<h1>Printability map</h1>\n",
    );
    let feasible = m.points.iter().filter(|p| p.feasible).count();
    let _ = writeln!(
        s,
        "<p>{} against {}, {} x {} points. Targets: width {:.2} &plusmn; {:.2} mm, height {:.2} &plusmn; {:.2} mm at the station{}. {feasible} of {} points meet them (outlined in the maps, shaded below); the plan's point is crossed.</p>",
        a.setting.name(),
        b.setting.name(),
        a.n,
        b.n,
        l.width * 1e3,
        l.width_tolerance * 1e3,
        l.height * 1e3,
        l.height_tolerance * 1e3,
        targets.wall.as_ref().map_or(String::new(), |w| format!("; a wall standing to {} m x {}", w.design_height, w.safety_factor)),
        m.points.len()
    );
    let _ = writeln!(s, "<figure><img src=\"{}\" alt=\"heat maps of the layer's width and height and the wall's buildable height\"></figure>", escape(&name));
    s += "<table>\n<tr><th>speed [mm/s]</th><th>extrusion [mm/s]</th><th>standoff [mm]</th><th>width [mm]</th><th>height [mm]</th><th>buildable [m]</th><th>meets the targets</th></tr>\n";
    for p in &m.points {
        let class = match (p.feasible, p.x == m.marked) {
            (_, true) => " class=\"plan\"",
            (true, false) => " class=\"feasible\"",
            _ => "",
        };
        let bh = p.buildable.map_or("-".to_string(), |b| format!("{:.3}", b.height));
        let why = p.error.as_ref().map_or(String::new(), |e| format!(" ({})", escape(e)));
        let _ = writeln!(
            s,
            "<tr{class}><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.3}</td><td>{:.3}</td><td>{bh}</td><td>{}{why}</td></tr>",
            p.x[0] * 1e3,
            p.x[1] * 1e3,
            p.x[2] * 1e3,
            p.width * 1e3,
            p.height * 1e3,
            if p.feasible { "yes" } else { "no" }
        );
    }
    let _ = writeln!(s, "</table>\n<p>The plan's point: speed {:.2} mm/s, extrusion {:.2} mm/s, standoff {:.2} mm.</p>\n</body>\n</html>", m.marked[0] * 1e3, m.marked[1] * 1e3, m.marked[2] * 1e3);
    std::fs::write(path, s).map_err(|e| PlanError::Io(format!("{}: {e}", path.display())))
}
