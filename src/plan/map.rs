//! The printability map (`strand plan --map`): the print run over a grid of two settings or of
//! their dimensionless groups V/U and H/D (`map_axes.rs`), the others held at the plan's point
//! (or, when no plan meets the targets, the search's start).
//!
//! Each grid point is an experiment of the measurement loop (`line.rs`), so the points run on
//! the engine of `measure::engine`: here, `--jobs` at a time, or as the jobs of GNU parallel,
//! Slurm or HyperQueue (`--engine`); every run's memory is planned before the first. A point
//! gives the layer's width and height at the station by a forward run, and the closed form the
//! wall's buildable height at the plan's layer time (or the nozzle's, when that is longer). A
//! point is feasible when the width and the height are within their tolerances and the wall
//! stands to its design height times the safety factor there. Written as CSV (a row a point),
//! as text, and as a PNG of contour plots (width, height, buildable height; `output::contour_plot`)
//! with the region meeting the targets shaded and the plan's point crossed, which the plan's HTML
//! report (`report_html.rs`) embeds.

use super::build::WallGoal;
use super::constraint::Buildable;
use super::error::PlanError;
use super::line::{Line, Point};
use super::map_axes::{self, Axis};
use super::targets::Targets;
use crate::measure::engine::Engine;
use crate::measure::observation::{Observable, Observation};
use crate::measure::runner::{evaluate, find, group, job_threads, par_map_experiments, Jobs};
use crate::output::contour_plot::{plot_contour_maps, ContourMap, ContourPanel};
use std::path::Path;

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
    /// The height the wall must stand to [m], with a wall.
    pub need: Option<f64>,
    pub seconds: f64,
}

/// The map of `line` over `axes` around `centre` (the plan's point), the wall's buildable height
/// at `layer_time`, on `engine` `jobs` at a time; refused before any run when a grid point's
/// setting leaves its bounds (`map_axes::points`).
#[allow(clippy::too_many_arguments)]
pub fn map(line: &Line, targets: &Targets, wall: Option<&WallGoal>, axes: [Axis; 2], centre: &Point, layer_time: Option<f64>, engine: &Engine, jobs: usize) -> Result<Map, PlanError> {
    let clock = std::time::Instant::now();
    let xs = map_axes::points(&axes, targets, centre)?;
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
    Ok(Map { axes, points, marked: *centre, layer_time, need: wall.map(WallGoal::need), seconds: clock.elapsed().as_secs_f64() })
}

/// The map as CSV: the settings and their groups V/U and H/D (D the nozzle's narrowest width
/// `diameter`), the layer, the buildable height and failure mode, feasibility.
pub fn write_csv(m: &Map, diameter: f64, path: &Path) -> Result<(), PlanError> {
    let mut s = String::from("speed,extrusion,standoff,v_over_u,h_over_d,width,height,buildable_height,failure_mode,feasible\n");
    for p in &m.points {
        let (bh, mode) = match &p.buildable {
            Some(b) => (b.height.to_string(), b.mode.map_or("none", |x| x.name()).to_string()),
            None => (String::new(), String::new()),
        };
        s += &format!("{},{},{},{},{},{},{},{bh},{mode},{}\n", p.x[0], p.x[1], p.x[2], p.x[0] / p.x[1], p.x[2] / diameter, p.width, p.height, p.feasible);
    }
    std::fs::write(path, s).map_err(|e| PlanError::Io(format!("{}: {e}", path.display())))
}

/// The map as contour plots in a PNG: the width and the height [mm] and, with a wall, the
/// buildable height [m], each with its target band's edges bold; the region meeting every target
/// shaded, the plan's point crossed.
pub fn write_png(m: &Map, targets: &Targets, path: &Path) -> Result<(), PlanError> {
    let [a, b] = m.axes;
    let l = &targets.layer;
    let along = |x: &Axis| x.values().iter().map(|v| v * x.quantity.shown()).collect::<Vec<f64>>();
    let band = |t: f64, tol: f64| Some([(t - tol) * 1e3, (t + tol) * 1e3]);
    let mut panels = vec![
        ContourPanel { title: format!("width [mm], target {:.2} +- {:.2}", l.width * 1e3, l.width_tolerance * 1e3), values: m.points.iter().map(|p| p.width * 1e3).collect(), band: band(l.width, l.width_tolerance) },
        ContourPanel { title: format!("height [mm], target {:.2} +- {:.2}", l.height * 1e3, l.height_tolerance * 1e3), values: m.points.iter().map(|p| p.height * 1e3).collect(), band: band(l.height, l.height_tolerance) },
    ];
    if let (Some(need), true) = (m.need, m.points.iter().any(|p| p.buildable.is_some())) {
        let t = m.layer_time.map_or(String::new(), |t| format!(" at T = {t:.1} s"));
        panels.push(ContourPanel { title: format!("buildable height [m]{t}, need {need:.3}"), values: m.points.iter().map(|p| p.buildable.map_or(f64::NAN, |b| b.height)).collect(), band: Some([need, f64::INFINITY]) });
    }
    let point = Some([a.quantity.of(&m.marked) * a.quantity.shown(), b.quantity.of(&m.marked) * b.quantity.shown()]);
    let map = ContourMap { xs: along(&a), ys: along(&b), x_desc: a.quantity.label(&m.marked), y_desc: b.quantity.label(&m.marked), panels, point };
    Ok(plot_contour_maps(path, &map)?)
}

/// The map as text: a row a point, with its groups V/U and H/D (D = `diameter`).
pub fn text(m: &Map, diameter: f64) -> String {
    let mut s = format!("map: {} x {} points of {} and {} in {:.1} s (feasible: *)\n", m.axes[0].n, m.axes[1].n, m.axes[0].quantity.label(&m.marked), m.axes[1].quantity.label(&m.marked), m.seconds);
    s += "   speed mm/s  extrusion mm/s  standoff mm    V/U    H/D   width mm  height mm  buildable m\n";
    for p in &m.points {
        let bh = p.buildable.map_or("-".to_string(), |b| format!("{:.3}", b.height));
        let why = p.error.as_ref().map_or(String::new(), |e| format!("  ({e})"));
        s += &format!("{} {:>11.2} {:>15.2} {:>12.2} {:>6.3} {:>6.3} {:>10.3} {:>10.3} {:>12}{why}\n", if p.feasible { "*" } else { " " }, p.x[0] * 1e3, p.x[1] * 1e3, p.x[2] * 1e3, p.x[0] / p.x[1], p.x[2] / diameter, p.width * 1e3, p.height * 1e3, bh);
    }
    s
}
