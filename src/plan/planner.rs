//! A plan: the problem a targets file poses for a print under a model, checked before any run
//! (bounds against each other, every run's memory), searched (`optimise.rs`), and checked
//! against the targets afterwards (each target missed, and how close the best setting came).

use super::build::WallGoal;
use super::constraint;
use super::error::PlanError;
use super::line::{Line, Point};
use super::optimise::{answer, Evaluated, Problem};
use super::targets::{Setting, Targets};
use std::path::Path;

/// A plan: the settings found and everything the report says about them.
pub struct Plan {
    pub line: Line,
    pub targets: Targets,
    /// The settings' bounds as searched (the speed's lower bound raised to what the layer
    /// time's upper bound allows).
    pub free: Vec<(Setting, [f64; 2])>,
    /// Every point run, the plan's the last accepted.
    pub history: Vec<Evaluated>,
    /// The wall, with its material's closed forms.
    pub wall: Option<WallGoal>,
    /// Whether the wall's buckling was checked (the material's stiffness is known).
    pub buckling_checked: bool,
    /// The layer time's bounds [s], with a wall.
    pub layer_time: Option<[f64; 2]>,
    /// The search's wall time [s].
    pub seconds: f64,
}

impl Plan {
    pub fn best(&self) -> &Evaluated {
        answer(&self.history)
    }
    pub fn settings(&self) -> Point {
        self.best().x
    }

    /// Why the plan's point does not meet the targets: each target missed and how close the best
    /// setting came.
    pub fn infeasible(&self) -> Option<PlanError> {
        let b = self.best();
        let l = &self.targets.layer;
        let at = format!("speed {:.4} m/s, extrusion {:.4} m/s, standoff {:.4} m", b.x[0], b.x[1], b.x[2]);
        let mut missed = Vec::new();
        for (k, (name, target, tol)) in [("width", l.width, l.width_tolerance), ("height", l.height, l.height_tolerance)].into_iter().enumerate() {
            if b.residual[k].abs() > 1.0 {
                let v = b.layer.values[k];
                missed.push(format!(
                    "the layer {name} {:.2} +- {:.2} mm cannot be met within the bounds: the closest setting found ({at}) gives {:.2} mm, {:.2} mm off ({:.1} tolerances)",
                    target * 1e3,
                    tol * 1e3,
                    v * 1e3,
                    (v - target).abs() * 1e3,
                    b.residual[k].abs()
                ));
            }
        }
        if let (Some(short), Some(w), Some([_, hi])) = (&b.build.short, &self.targets.wall, self.layer_time) {
            missed.push(format!(
                "the wall cannot stand to its design height {} m times {} = {:.3} m within the layer time's bounds: at the longest, {hi} s, it stands {:.3} m ({}), {:.0} % of it, with layers {:.2} x {:.2} mm ({at})",
                w.design_height,
                w.safety_factor,
                w.design_height * w.safety_factor,
                short.height,
                short.mode.map_or("no failure found", |m| m.name()),
                100.0 * short.height / (w.design_height * w.safety_factor),
                b.layer.values[0] * 1e3,
                b.layer.values[1] * 1e3
            ));
        }
        (!missed.is_empty()).then(|| PlanError::Infeasible(missed.join("; ")))
    }
}

/// Options of a plan's search.
pub struct PlanOptions {
    pub grad: crate::grad::GradOptions,
    pub max_evaluations: usize,
    pub progress: bool,
}

/// The problem of `targets` for the print at `scenario` under `model`, checked before any run:
/// the bounds against each other and every run's memory at the bounds' corners.
pub fn problem<'a>(line: &'a Line, targets: &Targets, opts: &PlanOptions) -> Result<Problem<'a>, PlanError> {
    let mut free = targets.free();
    let length = targets.layer_length(line.length);
    let wall = match &targets.wall {
        None => None,
        Some(w) => {
            let fastest = targets.settings.speed.map_or(line.nominal[0], |b| b[1]);
            let [lo, hi] = targets.settings.layer_time.unwrap_or([f64::MIN_POSITIVE, f64::INFINITY]);
            if length / fastest > hi {
                return Err(PlanError::Targets(format!(
                    "settings.layer_time's upper bound {hi} s is shorter than one layer takes the nozzle at the highest speed, {length} m / {fastest} m/s = {:.3} s: the bounds exclude each other",
                    length / fastest
                )));
            }
            // the speed's lower bound: no slower than a layer within the layer time's upper bound
            if let Some((_, b)) = free.iter_mut().find(|(s, _)| *s == Setting::Speed) {
                b[0] = b[0].max(length / hi);
            }
            let wall = constraint::Wall::of(&line.model, w.age_at_start, line.gravity)?;
            Some(WallGoal { wall, design_height: w.design_height, safety_factor: w.safety_factor, layer_time: [lo, hi] })
        }
    };
    // a zero-width bound holds its setting
    free.retain(|(_, [lo, hi])| hi > lo);
    if free.is_empty() {
        return Err(PlanError::Targets("settings: every bound holds its setting (lower = upper): nothing is left to choose".into()));
    }
    let p = Problem {
        line,
        length,
        target: [targets.layer.width, targets.layer.height],
        tolerance: [targets.layer.width_tolerance, targets.layer.height_tolerance],
        free,
        wall,
        grad: opts.grad.clone(),
        max_evaluations: opts.max_evaluations,
    };
    // every run's memory, planned at the bounds' corners (the extrusion speed and the standoff
    // change the emitted particles and the nozzle's reach)
    let corners: Vec<Point> = (0..1usize << p.free.len())
        .map(|c| {
            let mut x = p.start();
            for (k, (s, [lo, hi])) in p.free.iter().enumerate() {
                x[s.index()] = if c >> k & 1 == 1 { *hi } else { *lo };
            }
            x
        })
        .collect();
    line.preflight(&corners)?;
    Ok(p)
}

/// The plan of `targets` for the print at `scenario` under `model`: the search's answer, which
/// [`Plan::infeasible`] checks against the targets.
pub fn plan(model: &crate::measure::model::Model, scenario: &Path, targets: &Targets, opts: &PlanOptions) -> Result<Plan, PlanError> {
    let clock = std::time::Instant::now();
    let line = Line::new(model, scenario, targets)?;
    let (history, free, wall) = {
        let p = problem(&line, targets, opts)?;
        let history = p.search(opts.progress)?;
        let Problem { free, wall, .. } = p;
        (history, free, wall)
    };
    let (buckling_checked, layer_time) = (wall.as_ref().is_some_and(|w| w.wall.checks_buckling()), wall.as_ref().map(|w| w.layer_time));
    Ok(Plan { line, targets: targets.clone(), free, history, wall, buckling_checked, layer_time, seconds: clock.elapsed().as_secs_f64() })
}
