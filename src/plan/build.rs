//! The build a layer makes: the layer time a wall of it needs and the time to print the wall to
//! its design height, with their derivatives in the layer's width and height and the speed.
//!
//! The layer time T is the longest of: the layer time's lower bound, the nozzle's time over one
//! layer (its length over the speed), and the shortest time at which the wall stands to its
//! design height times the safety factor (`constraint.rs`). The build time is the number of
//! layers, design height over layer height, times T: the objective a plan lowers. Without a
//! `[wall]`, the build time is one layer's time, length over speed.

use super::constraint::{Buildable, Wall};
use super::error::PlanError;

/// The wall a plan must build.
pub struct WallGoal {
    pub wall: Wall,
    pub design_height: f64,
    pub safety_factor: f64,
    /// The layer time's bounds [s].
    pub layer_time: [f64; 2],
}

impl WallGoal {
    /// The height the wall must stand to [m].
    pub fn need(&self) -> f64 {
        self.design_height * self.safety_factor
    }

    /// The shortest layer time in `[floor, hi]` (hi raised to the floor) at which a wall of
    /// layers `w` x `h` stands to [`WallGoal::need`], or what it reaches at the longest.
    fn shortest_layer_time(&self, w: f64, h: f64, [floor, hi]: [f64; 2]) -> Result<Result<f64, Buildable>, PlanError> {
        self.wall.shortest_layer_time(w, h, self.need(), [floor, hi.max(floor)])
    }
}

/// What bounds the layer time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// The layer time's lower bound.
    LowerBound,
    /// The nozzle's time over the layer.
    Nozzle,
    /// The wall's failure.
    Failure,
    /// The shortest layer time at which the simulated wall stood (`wall_rounds.rs`).
    Simulated,
}

/// A point's build.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Build {
    /// [s]
    pub layer_time: f64,
    pub bound: Bound,
    /// [s]
    pub build_time: f64,
    /// d build_time / d (width, height, speed).
    pub gradient: [f64; 3],
    /// d layer_time / d (width, height, speed).
    pub layer_time_gradient: [f64; 3],
    /// How tall the wall stands at the layer time (None without a wall).
    pub buildable: Option<Buildable>,
    /// The wall cannot stand to its height within the layer time's bounds: what it reaches at
    /// the longest.
    pub short: Option<Buildable>,
}

/// The build of a layer `w` x `h` printed at `speed` over `length` metres a layer.
pub fn build(goal: Option<&WallGoal>, length: f64, [w, h, speed]: [f64; 3]) -> Result<Build, PlanError> {
    let nozzle = length / speed;
    let Some(g) = goal else {
        let gradient = [0.0, 0.0, -nozzle / speed];
        return Ok(Build { layer_time: nozzle, bound: Bound::Nozzle, build_time: nozzle, gradient, layer_time_gradient: gradient, buildable: None, short: None });
    };
    let [lo, hi] = g.layer_time;
    let floor = lo.max(nozzle);
    let (t, bound, short) = match g.shortest_layer_time(w, h, [floor, hi])? {
        Ok(t) if t > floor => (t, Bound::Failure, None),
        Ok(_) => (floor, if nozzle >= lo { Bound::Nozzle } else { Bound::LowerBound }, None),
        Err(best) => (hi.max(floor), Bound::Failure, Some(best)),
    };
    at(g, [floor, hi], [w, h, speed], t, bound, short)
}

/// The build of a layer `w` x `h` printed at `speed` over `length` metres a layer, at the layer
/// time `t` at which a simulated wall of it stood (`wall_rounds.rs`); the layer time's
/// derivatives are the closed form's, with `goal`'s collapse factor.
pub fn simulated(g: &WallGoal, length: f64, [w, h, speed]: [f64; 3], t: f64) -> Result<Build, PlanError> {
    let [lo, hi] = g.layer_time;
    at(g, [lo.max(length / speed), hi], [w, h, speed], t, Bound::Simulated, None)
}

/// The build at the layer time `t`, bound by `bound`, with the floor of the layer time (its
/// lower bound or the nozzle's time) and its upper bound.
fn at(g: &WallGoal, [floor, hi]: [f64; 2], [w, h, speed]: [f64; 3], t: f64, bound: Bound, short: Option<Buildable>) -> Result<Build, PlanError> {
    let layers = g.design_height / h;
    // dT/dw, dT/dh by central differences of the closed form (its bisection resolves 1e-9 of T)
    let (dt_dw, dt_dh) = if matches!(bound, Bound::Failure | Bound::Simulated) && short.is_none() {
        let eps = 1e-4;
        let at = |w: f64, h: f64| -> Result<f64, PlanError> { Ok(g.shortest_layer_time(w, h, [floor, hi])?.unwrap_or(hi)) };
        ((at(w * (1.0 + eps), h)? - at(w * (1.0 - eps), h)?) / (2.0 * eps * w), (at(w, h * (1.0 + eps))? - at(w, h * (1.0 - eps))?) / (2.0 * eps * h))
    } else {
        (0.0, 0.0)
    };
    // at the nozzle's bound t = length / speed
    let dt_dv = if bound == Bound::Nozzle { -t / speed } else { 0.0 };
    let gradient = [layers * dt_dw, layers * dt_dh - layers * t / h, layers * dt_dv];
    let buildable = Some(g.wall.buildable(w, h, t, 2.0 * g.need())?);
    Ok(Build { layer_time: t, bound, build_time: layers * t, gradient, layer_time_gradient: [dt_dw, dt_dh, dt_dv], buildable, short })
}
