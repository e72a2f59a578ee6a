//! The plan's layer time driven by the simulated wall (`strand plan --check-wall`): the reduced
//! wall (`wall_check.rs`) calibrates the closed form (`constraint.rs`), round after round, until a
//! wall stands.
//!
//! In: a plan whose point meets the targets, the layer time of the first round (the plan's, or
//! `--check-wall-at`), a cap on the rounds, and the folder for the rounds' walls (`round-K/`).
//! Out: the rounds (each: its layer time, its simulated wall, and when the wall failed, the
//! multiplier of Prandtl's collapse factor at which the closed form at that layer time puts the
//! height the wall stood to) and, when a wall stood, the plan set to its layer time with the
//! closed form's factor calibrated; otherwise the plan untouched and [`Rounds::refusal`] naming how
//! close the last wall came.
//!
//! Each round: simulate the wall at T_k. It stands: done. It fails standing H_k (the layers below
//! the one that failed): the factor s_k with H_cf(T_k, s_k) = H_k, and the next layer time is the
//! shortest T within the layer time's bounds at which H_cf(T, s(T)) reaches the design height x
//! safety factor, with s(T) = s_k after one failure, and after more the secant through the last
//! two (T, s), held within the closed form's 10 % accuracy of the factors found: the factor the
//! simulation bears out is extrapolated along the layer time. The closed form is steep in the
//! factor near the layer time at which the wall would never collapse (1 % on the factor moves the
//! height 17 % on fixtures/plan), but the layer time it asks is not. A wall whose simulated
//! failure does not follow the closed form (a longer layer time leaving it no taller) does not
//! converge; the refusal says so. The height
//! stood is counted in whole layers (the failed one left out), so the factor is calibrated low and
//! the next wall errs towards standing.
//!
//! The simulation refutes the closed form, never relaxes it: the reduced wall stands on a rough
//! base that the closed form's squeeze leaves out (`wall_check.rs`), and taller, so no
//! round after the first is shorter than the plan's layer time, and the plan's layer time only
//! ever grows. A wall that stands at a shorter layer time stands at a longer one (older, stronger
//! layers below), so a first round under the plan's layer time (a probe, `--check-wall-at`) that
//! stands leaves the plan as it is. The layer shape does not depend on the layer time (the line
//! is one pass), so the layer's settings stay the plan's; only the layer time and the build
//! change (`build::simulated`), and the closed form's factor becomes the calibrated one.

use super::build;
use super::constraint::{shortest_time, Buildable, Wall, COLLAPSE_FACTOR_ACCURACY};
use super::error::PlanError;
use super::planner::Plan;
use super::wall_check::{self, WallCheck};
use std::path::Path;

/// Rounds at most by default (`--wall-rounds`): each is a reduced wall, about 600 s on
/// fixtures/plan's own targets.
pub const DEFAULT_ROUNDS: usize = 3;

/// The range searched for the collapse factor's multiplier.
const FACTOR_RANGE: [f64; 2] = [0.05, 20.0];

/// One round: a wall simulated at a layer time.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Round {
    /// [s]
    pub layer_time: f64,
    pub stands: bool,
    /// How tall the simulated wall stood [m]: its layers when it stood, the layers below the
    /// failed one otherwise.
    pub stood_to: f64,
    /// When it failed: the multiplier of Prandtl's collapse factor at which the closed form at
    /// this layer time puts `stood_to`.
    pub factor_scale: Option<f64>,
    pub check: WallCheck,
}

/// The rounds and what they left.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Rounds {
    pub rounds: Vec<Round>,
    pub max_rounds: usize,
    /// The design height x safety factor [m].
    pub need: f64,
    /// A wall stood: the layer time the plan now has [s] (the standing round's, or the plan's
    /// own when that is longer).
    pub layer_time: Option<f64>,
    /// The last failed round's factor multiplier (1 when none failed).
    pub factor_scale: f64,
    /// Whether the plan took the rounds' layer time and factor (a wall stood only longer than
    /// the plan's layer time).
    pub changed: bool,
    /// No wall stood: the next layer time the calibrated closed form asks for, or, when none
    /// within the bounds does, how tall it has the wall stand at the longest.
    pub next: Option<f64>,
    pub unreachable: Option<Buildable>,
    /// The layer time's upper bound [s].
    pub longest: f64,
}

impl Rounds {
    /// Why no wall stood: how close the last came and what the calibrated closed form says.
    pub fn refusal(&self) -> Option<PlanError> {
        if self.layer_time.is_some() {
            return None;
        }
        let last = self.rounds.last()?;
        let what = match (self.next, &self.unreachable) {
            (_, Some(b)) => format!(
                "the closed form calibrated on it (collapse factor x {:.4}) has no layer time within the bounds at which the wall stands: at the longest, {} s, it stands {:.3} m",
                self.factor_scale, self.longest, b.height
            ),
            (Some(t), None) => format!(
                "the closed form calibrated on it (collapse factor x {:.4}) asks next for a layer time of {t:.2} s (--wall-rounds {} to try it)",
                self.factor_scale,
                self.max_rounds + 1
            ),
            (None, None) => String::new(),
        };
        // a longer layer time that left the wall no taller: its failure is not the closed form's
        let stalled = match &self.rounds[..] {
            [.., a, b] if b.layer_time > a.layer_time && b.stood_to <= a.stood_to => format!(
                "; at {:.2} s it stood no taller than at {:.2} s ({:.3} m): the simulated failure does not follow the closed form's collapse there, and a longer layer time alone may not make it stand",
                b.layer_time, a.layer_time, b.stood_to
            ),
            _ => String::new(),
        };
        Some(PlanError::Infeasible(format!(
            "the wall did not stand when simulated in {} round{} (--wall-rounds {}): the last, at a layer time of {:.2} s, stood {:.3} m of the {:.3} m asked (design height x safety factor), {:.0} % of it; {what}{stalled}",
            self.rounds.len(),
            if self.rounds.len() == 1 { "" } else { "s" },
            self.max_rounds,
            last.layer_time,
            last.stood_to,
            self.need,
            100.0 * last.stood_to / self.need
        )))
    }
}

/// The multiplier s of Prandtl's collapse factor at which the closed form has a wall `w` x `h`
/// at layer time `t` stand to `height` (the lower end of its bracket: the closed form at s stands
/// no taller), within [`FACTOR_RANGE`].
pub fn calibrate(wall: &Wall, [w, h]: [f64; 2], t: f64, height: f64, max: f64) -> Result<f64, PlanError> {
    let at = |s: f64| wall.with_collapse_factor(s).buildable(w, h, t, max).map(|b| b.height);
    let [mut a, mut b] = FACTOR_RANGE;
    if at(a)? >= height {
        return Ok(a);
    }
    if at(b)? < height {
        return Ok(b);
    }
    while b / a > 1.0 + 1e-9 {
        let m = (a * b).sqrt();
        if at(m)? < height {
            a = m;
        } else {
            b = m;
        }
    }
    Ok(a)
}

/// The shortest layer time in `[lo, hi]` at which the closed form with the factor multiplier
/// `factor(T)` has the wall stand to `need`, or how tall it stands at `hi`.
fn shortest(wall: &Wall, [w, h]: [f64; 2], need: f64, factor: &dyn Fn(f64) -> f64, bounds: [f64; 2]) -> Result<Result<f64, Buildable>, PlanError> {
    shortest_time(&|t| wall.with_collapse_factor(factor(t)).buildable(w, h, t, 2.0 * need).map(|b| (b.height >= need, b)), bounds, 1e-6)
}

/// The next layer time after the failed rounds `fits` (layer time, calibrated factor; longest
/// last): the shortest in [`floor`, `hi`], and past the longest failed, with the factor s_k, or
/// after two failures the secant through the last two. The secant's factor is held within the
/// closed form's accuracy ([`COLLAPSE_FACTOR_ACCURACY`]) of the factors the rounds found: a line
/// through two nearby rounds would otherwise run to any factor over a long layer time.
fn next(wall: &Wall, layer: [f64; 2], need: f64, fits: &[(f64, f64)], [floor, hi]: [f64; 2]) -> Result<Result<f64, Buildable>, PlanError> {
    let (t1, s1) = *fits.last().expect("a failed round");
    let slope = match fits {
        [.., (t0, s0), _] if t1 > *t0 => (s1 - s0) / (t1 - t0),
        _ => 0.0,
    };
    let (min, max) = fits.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &(_, s)| (a.min(s), b.max(s)));
    let range = [(min * (1.0 - COLLAPSE_FACTOR_ACCURACY)).max(FACTOR_RANGE[0]), (max * (1.0 + COLLAPSE_FACTOR_ACCURACY)).min(FACTOR_RANGE[1])];
    let factor = move |t: f64| (s1 + slope * (t - t1)).clamp(range[0], range[1]);
    // strictly past the failed layer time: no round simulates one twice
    shortest(wall, layer, need, &factor, [floor.max(t1 * (1.0 + 1e-3)), hi])
}

/// The rounds of `plan`'s wall from the layer time `first`, at most `max_rounds`, each wall's
/// scenario and outputs in `out/round-K`; when one stands, `plan` takes its layer time (see the
/// module's doc). Each round is printed to stderr as it ends (one takes minutes).
pub fn drive(plan: &mut Plan, first: f64, max_rounds: usize, threads: Option<usize>, out: &Path) -> Result<Rounds, PlanError> {
    let goal = plan.wall.as_ref().ok_or_else(|| PlanError::Targets("--check-wall: the targets have no [wall]".into()))?;
    if max_rounds == 0 {
        return Err(PlanError::Targets("--wall-rounds 0: give one round at least".into()));
    }
    if first > goal.layer_time[1] {
        return Err(PlanError::Targets(format!("--check-wall-at {first} s is over settings.layer_time's upper bound {} s", goal.layer_time[1])));
    }
    let b = plan.best();
    let (layer, speed, planned) = (b.layer.values, b.x[0], b.build.layer_time);
    let length = plan.targets.layer_length(plan.line.length);
    let [lo, hi] = goal.layer_time;
    // no round after the first shorter than the plan's layer time (itself over its floor)
    let floor = lo.max(length / speed).max(planned);
    let need = goal.need();
    let mut r = Rounds { rounds: Vec::new(), max_rounds, need, layer_time: None, factor_scale: 1.0, changed: false, next: None, unreachable: None, longest: hi };
    let mut fits: Vec<(f64, f64)> = Vec::new();
    let mut t = first;
    for k in 1..=max_rounds {
        let check = wall_check::check(plan, t, threads, &out.join(format!("round-{k}")))?;
        let stood_to = match &check.failure {
            None => check.layers as f64 * check.layer_height,
            Some(f) => f.layer.saturating_sub(1) as f64 * check.layer_height,
        };
        let factor_scale = match check.stands {
            true => None,
            false => Some(calibrate(&goal.wall, layer, t, stood_to, 2.0 * need)?),
        };
        let round = Round { layer_time: t, stands: check.stands, stood_to, factor_scale, check };
        eprint!("{}", round_text(k, &round));
        r.rounds.push(round);
        if let Some(s) = factor_scale {
            fits.push((t, s));
            r.factor_scale = s;
            match next(&goal.wall, layer, need, &fits, [floor, hi])? {
                Ok(n) => {
                    r.next = Some(n);
                    t = n;
                }
                Err(short) => {
                    r.unreachable = Some(short);
                    return Ok(r);
                }
            }
            continue;
        }
        let layer_time = t.max(planned);
        r.layer_time = Some(layer_time);
        r.next = None;
        r.changed = layer_time > planned;
        if r.changed {
            let goal = plan.wall.as_mut().expect("checked above");
            goal.wall = goal.wall.with_collapse_factor(r.factor_scale);
            let at = plan.history.iter().rposition(|e| e.accepted).expect("the start is accepted");
            plan.history[at].build = build::simulated(goal, length, [layer[0], layer[1], speed], layer_time)?;
        }
        return Ok(r);
    }
    Ok(r)
}

/// One round in a few lines.
pub fn round_text(k: usize, r: &Round) -> String {
    let mut s = format!("round {k}: {}", wall_check::text(&r.check));
    if let Some(f) = r.factor_scale {
        s += &format!("  calibrated: the closed form puts the {:.3} m it stood at {:.2} s with Prandtl's collapse factor x {f:.4}\n", r.stood_to, r.layer_time);
    }
    s
}

/// The rounds and their outcome.
pub fn text(r: &Rounds) -> String {
    r.rounds.iter().enumerate().map(|(k, x)| round_text(k + 1, x)).collect::<String>() + &outcome(r)
}

/// The rounds' outcome in a line.
pub fn outcome(r: &Rounds) -> String {
    match (r.layer_time, r.refusal()) {
        (Some(t), _) if r.changed => format!(
            "wall: stands when simulated (round {} of at most {}); the plan's layer time is now {t:.2} s, its closed form's collapse factor x {:.4}\n",
            r.rounds.len(),
            r.max_rounds,
            r.factor_scale
        ),
        (Some(t), _) => format!("wall: stands when simulated (round {} of at most {}); the plan's layer time stays {t:.2} s\n", r.rounds.len(), r.max_rounds),
        (None, Some(e)) => format!("wall: {e}\n"),
        (None, None) => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::model::Model;

    /// fixtures/plan/truth.toml's material: 150 Pa building up by 2 Pa/s.
    fn wall() -> Wall {
        let t = "[material]\nkind = \"evp_bingham\"\ndensity = 2100.0\nbulk_modulus = 5e4\npoisson_ratio = 0.3\nviscosity = 20.0\nyield_stress = 150.0\nbulk_modulus_rate = 500.0\n[effects.thixotropy]\na_thix = 2.0\n";
        Wall::of(&Model::from_table(&t.parse().unwrap()).unwrap(), 0.0, 9.81).unwrap()
    }

    #[test]
    fn the_calibrated_closed_form_puts_the_height_stood_and_asks_a_longer_layer_time() {
        let (w, layer, need) = (wall(), [0.017, 0.0064], 0.15);
        let planned = w.shortest_layer_time(layer[0], layer[1], need, [5.0, 600.0]).unwrap().unwrap();
        // a wall that stood 90 mm at the plan's layer time: a factor under 1 that puts 90 mm there
        let s = calibrate(&w, layer, planned, 0.09, 2.0 * need).unwrap();
        let at = w.with_collapse_factor(s).buildable(layer[0], layer[1], planned, 2.0 * need).unwrap().height;
        assert!(s < 1.0 && (at / 0.09 - 1.0).abs() < 1e-3, "factor {s}: {at} m");
        // the next layer time stands by the calibrated form, and is longer
        let t2 = next(&w, layer, need, &[(planned, s)], [planned, 600.0]).unwrap().unwrap();
        let h2 = w.with_collapse_factor(s).buildable(layer[0], layer[1], t2, 2.0 * need).unwrap().height;
        assert!(t2 > planned && h2 >= need * (1.0 - 1e-9), "{t2} s after {planned} s: {h2} m");
        // a second failure there, no taller: the secant's factor falls (at most to 10 % under the
        // lowest found), so the next layer time is longer again, and stands with s2 itself
        let s2 = calibrate(&w, layer, t2, 0.09, 2.0 * need).unwrap();
        let t3 = next(&w, layer, need, &[(planned, s), (t2, s2)], [planned, 600.0]).unwrap().unwrap();
        let h3 = w.with_collapse_factor(s2).buildable(layer[0], layer[1], t3, 2.0 * need).unwrap().height;
        assert!(s2 < s && t3 > t2 && h3 >= need * (1.0 - 1e-6), "{s2} after {s}; {t3} s after {t2} s: {h3} m");
        // a height out of any factor's reach in the range: its end
        assert_eq!(calibrate(&w, layer, planned, 0.0, 2.0 * need).unwrap(), FACTOR_RANGE[0]);
    }
}
