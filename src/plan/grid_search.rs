//! The brute-force check of a plan: the print run over a grid of two free settings spanning
//! their bounds (the others at the plan's point), each point's build by the same closed forms
//! as the plan's (`build.rs`), and the fastest point that meets every target. The plan passes
//! when no grid point is faster by more than the build time changes over one grid spacing at
//! the plan (its gradient along each axis times the spacing): the grid cannot resolve less.

use super::build::{build, Build};
use super::error::PlanError;
use super::map;
use super::map_axes::Axis;
use super::planner::Plan;
use crate::measure::engine::Engine;

/// A grid point with its build.
pub struct Graded {
    pub point: map::MapPoint,
    /// None where the run failed.
    pub build: Option<Build>,
    /// The layer within its tolerances and the wall standing within the layer time's bounds.
    pub feasible: bool,
}

/// The grid search and what it cost.
pub struct GridSearch {
    pub axes: [Axis; 2],
    pub points: Vec<Graded>,
    /// Wall and CPU seconds of the grid: its runs and its points' builds [s].
    pub seconds: f64,
    pub cpu_seconds: f64,
    /// The build time the grid cannot resolve at the plan [s].
    pub slack: f64,
}

impl GridSearch {
    /// The fastest feasible grid point.
    pub fn fastest(&self) -> Option<&Graded> {
        self.points.iter().filter(|g| g.feasible).min_by(|a, b| a.build.as_ref().unwrap().build_time.total_cmp(&b.build.as_ref().unwrap().build_time))
    }

    /// How much faster than `plan` the fastest feasible grid point builds [s] (> slack: the plan
    /// is beaten).
    pub fn gain(&self, plan: &Plan) -> Option<f64> {
        self.fastest().map(|g| plan.best().build.build_time - g.build.as_ref().unwrap().build_time)
    }
}

/// The build time's total derivative in setting `index` at the plan: through the layer's width
/// and height, and directly through the speed.
fn build_derivative(plan: &Plan, index: usize) -> f64 {
    let b = plan.best();
    let g = &b.build.gradient;
    g[0] * b.layer.gradient[0][index] + g[1] * b.layer.gradient[1][index] + if index == 0 { g[2] } else { 0.0 }
}

/// The grid search of `plan` over its first two free settings, `n` points along each, on
/// `engine` `jobs` at a time.
pub fn grid_search(plan: &Plan, n: [usize; 2], engine: &Engine, jobs: usize) -> Result<GridSearch, PlanError> {
    if plan.free.len() < 2 || n.iter().any(|&k| k < 2) {
        return Err(PlanError::Targets("the grid check needs two free settings and two points or more along each".into()));
    }
    let axes: [Axis; 2] = std::array::from_fn(|k| Axis::setting(plan.free[k].0, plan.free[k].1, n[k]));
    let (cpu, clock) = (crate::run::process_cpu_seconds(), std::time::Instant::now());
    let m = map::map(&plan.line, &plan.targets, None, axes, &plan.settings(), None, engine, jobs)?;
    let builds = builds(plan, &m.points, jobs)?;
    let points = m
        .points
        .into_iter()
        .zip(builds)
        .map(|(point, build)| {
            let feasible = point.feasible && build.as_ref().is_some_and(|b| b.short.is_none());
            Graded { point, build, feasible }
        })
        .collect();
    // the cost counts the closed forms too (each point's bisections for its layer time)
    let (seconds, cpu_seconds) = (clock.elapsed().as_secs_f64(), crate::run::process_cpu_seconds() - cpu);
    let slack = axes.iter().map(|a| build_derivative(plan, a.quantity.varied().index()).abs() * (a.bounds[1] - a.bounds[0]) / (a.n - 1) as f64).sum();
    Ok(GridSearch { axes, points, seconds, cpu_seconds, slack })
}

/// Each point's build by the closed forms (None where its run gave no layer), `jobs` points at
/// a time (at most the cores): the layer time's bisections cost about as much as a point's run,
/// and each point's build is its own, so the answers come in the points' order whatever the
/// threads.
fn builds(plan: &Plan, points: &[map::MapPoint], jobs: usize) -> Result<Vec<Option<Build>>, PlanError> {
    let length = plan.targets.layer_length(plan.line.length);
    let one = |p: &map::MapPoint| p.error.is_none().then(|| build(plan.wall.as_ref(), length, [p.width, p.height, p.x[0]])).transpose();
    // --jobs counts a scheduler's jobs too; the builds run here, on this machine's cores
    let threads = jobs.clamp(1, std::thread::available_parallelism().map_or(1, |n| n.get()));
    let chunk = points.len().div_ceil(threads).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = points.chunks(chunk).map(|c| s.spawn(move || c.iter().map(one).collect::<Result<Vec<_>, _>>())).collect();
        let mut all = Vec::with_capacity(points.len());
        for h in handles {
            all.extend(h.join().expect("a build thread panicked")?);
        }
        Ok(all)
    })
}

/// The comparison as text: each side's runs and cost, the fastest feasible builds.
pub fn text(plan: &Plan, g: &GridSearch) -> String {
    let b = &plan.best().build;
    let mut s = format!(
        "grid check: {}x{} over {} and {}: {} forward runs and builds in {:.1} s ({:.1} CPU s); the plan: {} gradient runs in {:.1} s\n",
        g.axes[0].n,
        g.axes[1].n,
        g.axes[0].quantity.name(),
        g.axes[1].quantity.name(),
        g.points.len(),
        g.seconds,
        g.cpu_seconds,
        plan.history.len(),
        plan.seconds
    );
    s += &match (g.fastest(), g.gain(plan)) {
        (Some(f), Some(gain)) => format!(
            "  fastest feasible on the grid: {} at speed {:.4} m/s, extrusion {:.4} m/s, standoff {:.4} m: {:.1} s; the plan's {:.1} s; the grid is {:.2} s faster (resolves {:.2} s): {}\n",
            g.points.iter().filter(|p| p.feasible).count(),
            f.point.x[0],
            f.point.x[1],
            f.point.x[2],
            f.build.as_ref().unwrap().build_time,
            b.build_time,
            gain,
            g.slack,
            if gain <= g.slack { "the plan holds" } else { "THE PLAN IS BEATEN" }
        ),
        _ => format!("  no grid point meets the targets; the plan's build {:.1} s\n", b.build_time),
    };
    s
}

/// `NxM` as the points along the grid's two axes.
pub fn size(s: &str) -> Result<[usize; 2], PlanError> {
    let n: Vec<usize> = s.split('x').map(|k| k.trim().parse::<usize>()).collect::<Result<_, _>>().unwrap_or_default();
    match n[..] {
        [a, b] if a >= 2 && b >= 2 => Ok([a, b]),
        _ => Err(PlanError::Targets(format!("--grid-check {s}: give the points along each axis as NxM, two or more each (5x5)"))),
    }
}
