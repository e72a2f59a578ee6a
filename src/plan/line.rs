//! The print a plan sets: the scenario under the model, the scenario keys each setting moves,
//! and the layer's width and height at the station with their gradients in the settings.
//!
//! A setting acts on every straight extruding move of the inline `[print] path`: `speed` sets
//! each one's `speed`, `extrusion` each one's `extrusion`; `standoff` is the nozzle's height over
//! the base (the platform, or the domain's floor) at the first extruding move, moved by
//! `print.z_offset`. Every run of a plan has the same end time, that of the slowest print the
//! bounds allow (the scenario's own time after its toolpath kept): the gradient holds the steps
//! fixed, and the section then has at least the scenario's rest before it is read.
//!
//! A point of the plan is an experiment of the measurement loop (`measure::experiments`): the
//! print's scenario with the settings' keys as its `set` and the mix's age as its covariate, so
//! the model's keys, the memory planning (`measure::preflight`) and the map's engine
//! (`measure::engine`) are theirs.

use super::error::PlanError;
use super::targets::{Setting, Targets};
use crate::grad::driver::{gradients, Seeded};
use crate::grad::GradOptions;
use crate::observables::Objective;
use crate::measure::experiments::{Experiment, Experiments};
use crate::measure::model::Model;
use crate::measure::runner::Applied;
use crate::print::toolpath::{MoveKind, Segment, Toolpath};
use crate::scenario::Scenario;
use std::path::{Path, PathBuf};

/// Settings in [`Setting::ALL`]'s order: speed [m/s], extrusion [m/s], standoff [m].
pub type Point = [f64; 3];

/// The print and the model a plan sets.
pub struct Line {
    pub model: Model,
    /// The scenario file.
    pub path: PathBuf,
    /// The scenario's own settings.
    pub nominal: Point,
    /// Indices of the path's straight extruding moves.
    prints: Vec<usize>,
    /// The standoff at z_offset = 0 [m].
    standoff0: f64,
    /// The end time every run of the plan takes [s].
    pub end_time: f64,
    /// One layer's extruding length [m].
    pub length: f64,
    /// The section's station [m] and layer (None: the whole section).
    pub station: f64,
    pub layer: Option<u32>,
    /// The mix's age at the start [s] (the experiments' covariate).
    pub age: f64,
    /// |g| [m/s2].
    pub gravity: f64,
    /// The nozzle's outlet, its narrowest width [m] (a circle's diameter): D of H/D.
    pub nozzle: f64,
}

/// The layer's width and height [m] at a point, and their gradients in the settings.
#[derive(Clone, Debug)]
pub struct Layer {
    pub values: [f64; 2],
    pub gradient: [Point; 2],
}

impl Line {
    /// The print of scenario `path` under `model`, for `targets`.
    pub fn new(model: &Model, path: &Path, targets: &Targets) -> Result<Line, PlanError> {
        let age = targets.wall.as_ref().map_or(0.0, |w| w.age_at_start);
        let x = Experiment { id: "plan".into(), scenario: Some(path.to_path_buf()), protocol: None, set: toml::Table::new(), observe: Vec::new(), rest_time: 0.0, age, covariates: Default::default() };
        let sc = Applied::new(model, &x)?.scenario(path)?;
        let p = sc.print.as_ref().ok_or_else(|| PlanError::Unsupported(format!("{}: no [print] table: a plan sets a print's settings", path.display())))?;
        if p.path.is_empty() {
            return Err(PlanError::Unsupported(format!("{}: a plan sets an inline [print] path (`strand plan` writes a G-code or point-list toolpath inline first: plan::toolpath_file)", path.display())));
        }
        if p.path.iter().any(|s| matches!(s, Segment::Arc { extrusion, .. } if *extrusion > 0.0)) {
            return Err(PlanError::Unsupported(format!("{}: a plan sets straight extruding moves; this path extrudes along arcs (not yet)", path.display())));
        }
        let prints: Vec<usize> = (0..p.path.len()).filter(|&i| matches!(p.path[i], Segment::Print { .. })).collect();
        let Some(Segment::Print { speed, extrusion, .. }) = prints.first().map(|&i| &p.path[i]) else {
            return Err(PlanError::Unsupported(format!("{}: the [print] path has no extruding move", path.display())));
        };
        let start = p.start.ok_or_else(|| PlanError::Unsupported(format!("{}: [print] start is needed with a path", path.display())))?;
        let tp = Toolpath::from_segments(start, &p.path).map_err(|e| PlanError::Unsupported(e.to_string()))?;
        let printed: Vec<_> = tp.moves().iter().filter(|m| m.kind == MoveKind::Print).collect();
        let base = sc.boundary.platform.as_ref().map_or(sc.domain.min[2], |pl| pl.z);
        let standoff0 = printed[0].from[2] - base;
        let length: f64 = printed.iter().map(|m| m.length()).sum();
        let nominal = [*speed, *extrusion, standoff0 + p.z_offset];
        // the slowest print the bounds allow, and the scenario's own time after its toolpath
        let tail = (sc.simulation.end_time - tp.end_time()).max(0.0);
        let slowest = targets.settings.speed.map_or(nominal[0], |b| b[0].min(nominal[0]));
        let printing_now: f64 = printed.iter().map(|m| m.duration()).sum();
        let end_time = tp.end_time() - printing_now + length / slowest + tail;
        let station = match targets.layer.station {
            Some(x) => x,
            None => sc.observe.as_ref().and_then(|o| o.stations.first().copied()).ok_or_else(|| PlanError::Targets("layer.station: give the station (x of the section), the scenario has no [observe] stations".into()))?,
        };
        let gravity = sc.simulation.gravity.iter().map(|g| g * g).sum::<f64>().sqrt();
        Ok(Line { model: model.clone(), path: path.to_path_buf(), nominal, prints, standoff0, end_time, length, station, layer: targets.layer.layer, age, gravity, nozzle: p.nozzle.narrowest() })
    }

    /// The scenario keys a point sets.
    pub fn keys(&self, x: &Point) -> Vec<(String, f64)> {
        let mut k: Vec<(String, f64)> = Vec::new();
        for &i in &self.prints {
            k.push((format!("print.path.{i}.speed"), x[0]));
            k.push((format!("print.path.{i}.extrusion"), x[1]));
        }
        k.push(("print.z_offset".into(), x[2] - self.standoff0));
        k.push(("simulation.end_time".into(), self.end_time));
        k
    }

    /// The keys setting `s` acts through.
    fn keys_of(&self, s: Setting) -> Vec<String> {
        match s {
            Setting::Speed => self.prints.iter().map(|i| format!("print.path.{i}.speed")).collect(),
            Setting::Extrusion => self.prints.iter().map(|i| format!("print.path.{i}.extrusion")).collect(),
            Setting::Standoff => vec!["print.z_offset".into()],
        }
    }

    /// The objectives of the layer's width and height at the station.
    pub fn observables(&self) -> [String; 2] {
        match self.layer {
            Some(k) => [format!("layer_width@{}:{k}", self.station), format!("layer_height@{}:{k}", self.station)],
            None => [format!("width@{}", self.station), format!("height@{}", self.station)],
        }
    }

    /// The width and the height as the objectives of one run, at its end.
    fn seeds(&self) -> Result<Vec<Seeded>, PlanError> {
        self.observables().iter().map(|o| Ok(Seeded { objective: o.parse::<Objective>()?, step: None })).collect()
    }

    /// The point as an experiment `id` of the measurement loop, in a campaign of its own folder.
    pub fn experiment(&self, id: &str, x: &Point) -> Experiment {
        let file = self.path.file_name().map(PathBuf::from).unwrap_or_else(|| self.path.clone());
        let set = self.keys(x).into_iter().map(|(k, v)| (k, toml::Value::Float(v))).collect();
        Experiment { id: id.into(), scenario: Some(file), protocol: None, set, observe: self.observables().to_vec(), rest_time: 0.0, age: self.age, covariates: Default::default() }
    }

    /// A campaign of the points `xs` (ids `p0`, `p1`, ...), relative to the scenario's folder.
    pub fn campaign(&self, xs: &[Point]) -> Experiments {
        let base_dir = self.path.parent().map(Path::to_path_buf).unwrap_or_default();
        Experiments { experiment: xs.iter().enumerate().map(|(k, x)| self.experiment(&format!("p{k}"), x)).collect(), resolution: None, base_dir }
    }

    /// The scenario text with the settings of `x` applied (under the model's material).
    pub fn scenario_text(&self, x: &Point) -> Result<String, PlanError> {
        let e = self.campaign(&[*x]);
        let path = e.base_dir.join(e.experiment[0].scenario.as_ref().expect("a simulation"));
        Ok(Applied::new(&self.model, &e.experiment[0])?.scenario_text(&path)?)
    }

    pub fn scenario(&self, x: &Point) -> Result<Scenario, PlanError> {
        let e = self.campaign(&[*x]);
        Ok(Applied::new(&self.model, &e.experiment[0])?.scenario(&self.path)?)
    }

    /// Plan the memory of every point of `xs` before any runs (`measure::preflight`).
    pub fn preflight(&self, xs: &[Point]) -> Result<(), PlanError> {
        let e = self.campaign(xs);
        crate::measure::preflight::plan_experiments(&self.model, &e, e.experiment.iter().map(|x| x.id.as_str()))?;
        Ok(())
    }

    /// The layer at `x` with its gradients in the `free` settings (one forward and one reverse
    /// sweep for both), the others' entries 0.
    pub fn layer(&self, x: &Point, free: &[Setting], opts: &GradOptions) -> Result<Layer, PlanError> {
        let sc = self.scenario(x)?;
        let seeds = self.seeds()?;
        let by: Vec<(Setting, Vec<String>)> = free.iter().map(|&s| (s, self.keys_of(s))).collect();
        let wrt: Vec<String> = by.iter().flat_map(|(_, k)| k.iter().cloned()).collect();
        let rs = gradients(&sc, &seeds, &wrt, opts)?;
        let mut layer = Layer { values: [rs[0].value, rs[1].value], gradient: [[0.0; 3]; 2] };
        for (r, g) in rs.iter().zip(layer.gradient.iter_mut()) {
            let mut k = 0;
            for (s, keys) in &by {
                g[s.index()] = r.gradient[k..k + keys.len()].iter().sum();
                k += keys.len();
            }
        }
        Ok(layer)
    }

    /// The layer at `x`, by a forward run alone.
    pub fn layer_values(&self, x: &Point, threads: Option<usize>) -> Result<[f64; 2], PlanError> {
        let sc = self.scenario(x)?;
        let seeds = self.seeds()?;
        let v = crate::grad::driver::forward_values(&sc, &seeds, threads)?;
        Ok([v[0], v[1]])
    }
}
