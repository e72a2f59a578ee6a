//! The search for settings: bounded gradient projection with restoration, on the settings
//! scaled to their bounds (0 at the lower, 1 at the upper).
//!
//! At each point one gradient run gives the layer's width and height and their Jacobian J in
//! the settings (`line.rs`), and the closed form the build time and its gradient g
//! (`build.rs`). J is corrected along each step by the step's secant (Broyden's update; also at
//! the point kept when a trial is refused): the adjoint gives the local slope, and at coarse
//! cells the section's outline moves by whole particles, so the slope over a step can differ
//! from it severalfold. The step is the Gauss-Newton step -J^+ r that brings the targets' residuals r
//! (in tolerances) to zero, plus, once every target is met, a step against g projected onto the
//! null space of J (which, to first order, leaves the width and the height where they are): the
//! build gets faster along the set of settings that meet the targets. A setting at a bound that
//! the step would push past it is held there (its column dropped), the step is clamped to the
//! bounds and to a trust region, and a trial is kept when it meets the targets where the point
//! did not, builds faster while meeting them, or (neither meeting them) lowers the sum of squared
//! residuals; otherwise the trust region shrinks. It stops when the trust region or the step
//! falls below 1e-3 of the bounds, once the targets are met with half their tolerances to spare and
//! the step promises less than 0.1 % off the build time, or after `max_evaluations` runs.

use super::build::{build, Build, WallGoal};
use super::error::PlanError;
use super::line::{Layer, Line, Point};
use super::targets::Setting;
use crate::grad::GradOptions;
use crate::measure::linalg::{gauss_newton_step, normal_equations, pinv_sym, secant_update};

/// What the search is given.
pub struct Problem<'a> {
    pub line: &'a Line,
    /// One layer's path [m] (the wall's, or the print's extruding length).
    pub length: f64,
    /// Width and height [m] and their tolerances.
    pub target: [f64; 2],
    pub tolerance: [f64; 2],
    /// The settings moved, with their bounds.
    pub free: Vec<(Setting, [f64; 2])>,
    pub wall: Option<WallGoal>,
    pub grad: GradOptions,
    pub max_evaluations: usize,
}

/// A point the search ran.
#[derive(Clone, Debug)]
pub struct Evaluated {
    pub x: Point,
    pub layer: Layer,
    pub build: Build,
    /// (value - target) / tolerance, width and height.
    pub residual: [f64; 2],
    pub accepted: bool,
    /// The targets' Jacobian the next step uses, in the scaled settings and tolerances: the
    /// adjoint's, corrected along the last step by its secant.
    jacobian: Vec<Vec<f64>>,
}

impl Evaluated {
    /// Both layer targets within their tolerances.
    pub fn meets_layer(&self) -> bool {
        self.residual.iter().all(|r| r.abs() <= 1.0)
    }
    /// Every target met: the layer, and the wall within the layer time's bounds.
    pub fn feasible(&self) -> bool {
        self.meets_layer() && self.build.short.is_none()
    }
    fn sum_sq(&self) -> f64 {
        self.residual.iter().map(|r| r * r).sum()
    }
}

impl Problem<'_> {
    fn scale(&self, k: usize) -> f64 {
        let [lo, hi] = self.free[k].1;
        hi - lo
    }

    fn index(&self, k: usize) -> usize {
        self.free[k].0.index()
    }

    /// The start: the scenario's settings, within the bounds.
    pub fn start(&self) -> Point {
        let mut x = self.line.nominal;
        for k in 0..self.free.len() {
            let [lo, hi] = self.free[k].1;
            x[self.index(k)] = x[self.index(k)].clamp(lo, hi);
        }
        x
    }

    /// One run at `x` and its build.
    pub fn evaluate(&self, x: &Point) -> Result<Evaluated, PlanError> {
        let settings: Vec<Setting> = self.free.iter().map(|f| f.0).collect();
        let layer = self.line.layer(x, &settings, &self.grad)?;
        let [w, h] = layer.values;
        if !(w > 0.0 && h > 0.0) {
            return Err(PlanError::Infeasible(format!("at speed {:.4} m/s, extrusion {:.4} m/s, standoff {:.4} m the station x = {} m has no layer (width {w:.3e} m, height {h:.3e} m): is the station on the printed line?", x[0], x[1], x[2], self.line.station)));
        }
        let build = build(self.wall.as_ref(), self.length, [w, h, x[0]])?;
        let residual = [(w - self.target[0]) / self.tolerance[0], (h - self.target[1]) / self.tolerance[1]];
        let mut e = Evaluated { x: *x, layer, build, residual, accepted: false, jacobian: Vec::new() };
        e.jacobian = self.jacobian(&e);
        Ok(e)
    }

    /// The build time's gradient in the scaled free settings.
    fn build_gradient(&self, e: &Evaluated) -> Vec<f64> {
        let g = e.build.gradient;
        (0..self.free.len())
            .map(|k| {
                let i = self.index(k);
                let via_layer = g[0] * e.layer.gradient[0][i] + g[1] * e.layer.gradient[1][i];
                (via_layer + if i == 0 { g[2] } else { 0.0 }) * self.scale(k)
            })
            .collect()
    }

    /// The targets' Jacobian in the scaled free settings (rows: width, height; in tolerances).
    fn jacobian(&self, e: &Evaluated) -> Vec<Vec<f64>> {
        (0..2).map(|r| (0..self.free.len()).map(|k| e.layer.gradient[r][self.index(k)] * self.scale(k) / self.tolerance[r]).collect()).collect()
    }

    /// The step from `e` within the trust region `delta`, in scaled settings.
    fn step(&self, e: &Evaluated, delta: f64) -> Vec<f64> {
        let n = self.free.len();
        let jac = &e.jacobian;
        let g = self.build_gradient(e);
        let u = self.scaled(&e.x);
        let mut cols: Vec<usize> = (0..n).collect();
        let mut d = vec![0.0; n];
        for _ in 0..=n {
            d = vec![0.0; n];
            let (a, jr) = normal_equations(jac, &e.residual, &cols);
            let restore = gauss_newton_step(&a, &jr, 1e-12);
            for (c, &k) in cols.iter().enumerate() {
                d[k] = restore[c];
            }
            let norm = d.iter().map(|x| x.abs()).fold(0.0, f64::max);
            if norm > delta {
                d.iter_mut().for_each(|x| *x *= delta / norm);
            }
            if e.meets_layer() {
                // against g, within the null space of J on the moving columns
                let (pinv, _) = pinv_sym(&a, 1e-12);
                let gc: Vec<f64> = cols.iter().map(|&k| g[k]).collect();
                let proj: Vec<f64> = (0..cols.len())
                    .map(|p| {
                        let jtj_g: Vec<f64> = (0..cols.len()).map(|q| (0..cols.len()).map(|s| a[q][s] * gc[s]).sum()).collect();
                        gc[p] - (0..cols.len()).map(|q| pinv[p][q] * jtj_g[q]).sum::<f64>()
                    })
                    .collect();
                let pn = proj.iter().map(|x| x.abs()).fold(0.0, f64::max);
                if pn > 1e-12 * gc.iter().map(|x| x.abs()).fold(1e-300, f64::max) {
                    let room = (delta - d.iter().map(|x| x.abs()).fold(0.0, f64::max)).max(0.0);
                    for (c, &k) in cols.iter().enumerate() {
                        d[k] -= proj[c] / pn * room;
                    }
                }
            }
            // hold the settings the step pushes past a bound
            let out: Vec<usize> = cols.iter().copied().filter(|&k| (u[k] <= 0.0 && d[k] < 0.0) || (u[k] >= 1.0 && d[k] > 0.0)).collect();
            if out.is_empty() {
                break;
            }
            cols.retain(|k| !out.contains(k));
        }
        d
    }

    fn scaled(&self, x: &Point) -> Vec<f64> {
        (0..self.free.len()).map(|k| (x[self.index(k)] - self.free[k].1[0]) / self.scale(k).max(f64::MIN_POSITIVE)).collect()
    }

    fn unscaled(&self, base: &Point, u: &[f64]) -> Point {
        let mut x = *base;
        for (k, uk) in u.iter().enumerate() {
            x[self.index(k)] = self.free[k].1[0] + uk.clamp(0.0, 1.0) * self.scale(k);
        }
        x
    }

    /// Whether `trial` is better than `at`.
    fn better(trial: &Evaluated, at: &Evaluated) -> bool {
        let faster = trial.build.build_time < at.build.build_time * (1.0 - 1e-9);
        let as_fast = trial.build.build_time <= at.build.build_time * (1.0 + 1e-9);
        match (trial.meets_layer(), at.meets_layer()) {
            (true, false) => true,
            (true, true) => faster || (as_fast && trial.sum_sq() < at.sum_sq()),
            (false, false) => trial.sum_sq() < at.sum_sq(),
            (false, true) => false,
        }
    }

    /// Every point run, in order; the last accepted one is the search's answer.
    pub fn search(&self, progress: bool) -> Result<Vec<Evaluated>, PlanError> {
        let mut at = self.evaluate(&self.start())?;
        at.accepted = true;
        let mut history = vec![at.clone()];
        let mut delta = 0.25;
        let say = |e: &Evaluated, what: &str| {
            if progress {
                eprintln!(
                    "  {what}: speed {:.4} m/s, extrusion {:.4} m/s, standoff {:.4} m -> width {:.3} mm, height {:.3} mm, layer time {:.2} s, build {:.1} s",
                    e.x[0], e.x[1], e.x[2], e.layer.values[0] * 1e3, e.layer.values[1] * 1e3, e.build.layer_time, e.build.build_time
                );
            }
        };
        say(&at, "start");
        while history.len() < self.max_evaluations && delta >= 1e-3 {
            let d = self.step(&at, delta);
            let moved = d.iter().map(|x| x.abs()).fold(0.0, f64::max);
            // done: the targets met with half their tolerance to spare, and the step promises
            // less than 0.1 % off the build time
            let promised = -self.build_gradient(&at).iter().zip(&d).map(|(g, d)| g * d).sum::<f64>() / at.build.build_time;
            let centred = at.feasible() && at.residual.iter().all(|r| r.abs() <= 0.5);
            if moved < 1e-3 || (centred && promised < 1e-3) {
                break;
            }
            let u: Vec<f64> = self.scaled(&at.x).iter().zip(&d).map(|(a, b)| a + b).collect();
            let mut trial = self.evaluate(&self.unscaled(&at.x, &u))?;
            // the step's secant: what the width and the height did along it
            let (from, to) = (self.scaled(&at.x), self.scaled(&trial.x));
            let secant = |jac: &mut Vec<Vec<f64>>| secant(jac, (&from, &to), (&at.residual, &trial.residual));
            if Problem::better(&trial, &at) {
                secant(&mut trial.jacobian);
                trial.accepted = true;
                at = trial.clone();
                delta = (2.0 * delta).min(0.5);
                say(&trial, "kept");
            } else {
                secant(&mut at.jacobian);
                delta /= 4.0;
                say(&trial, "refused");
            }
            history.push(trial);
        }
        Ok(history)
    }
}

/// Broyden's least-change update of `jac` (`measure::linalg::secant_update`, in the scaled
/// settings) for the step `from` -> `to`, along which the residuals went `r0` -> `r1`: the
/// adjoint gives the local slope, which at the cells a plan runs at can differ from the slope
/// over a step (the section's outline moves by whole particles). A step the bounds cut to
/// nothing leaves it as it is.
fn secant(jac: &mut Vec<Vec<f64>>, (from, to): (&[f64], &[f64]), (r0, r1): (&[f64; 2], &[f64; 2])) {
    if from.iter().zip(to).map(|(a, b)| (b - a) * (b - a)).sum::<f64>() <= 0.0 {
        return;
    }
    *jac = secant_update(jac, (from, to), &vec![1.0; from.len()], (r0, r1));
}

/// The answer of a search: its last accepted point.
pub fn answer(history: &[Evaluated]) -> &Evaluated {
    history.iter().rev().find(|e| e.accepted).expect("the start is accepted")
}
