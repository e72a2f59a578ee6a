//! Printing to failure: the run finds the layer and time at which a multi-layer print fails.
//!
//! The signal is the top of the printed object sinking. At each output the cross-section at
//! every observed station gives the object's height there ([`CrossSection::height`]). A print
//! that stands settles after each layer and then rests; one that fails by plastic collapse
//! (its bottom yields under the weight above) or buckles keeps sinking. The print has failed
//! when the top at a station sinks faster than `sink_rate` for `window` seconds on end.
//!
//! Why `sink_rate` defaults to the build rate (mean layer height over mean layer period): an
//! object whose top sinks faster than printing raises it cannot grow any more, whatever happens
//! next, and the rate scales with the print (a slow print's settling is slow too). The settling
//! of a fresh layer right behind the nozzle is fast but short (under a second on the fixtures);
//! `window` (0.5 s) is longer than the part of it that the nozzle's exclusion below leaves, and
//! short against the seconds a collapse of a Bingham material takes. Outputs while the nozzle
//! is within `1.5` nozzle widths of a station's plane are not used: the nozzle's own material
//! and the squeeze under it move the top there without any failure, and heights on either side
//! of a pass are not compared (the pass adds a layer).
//!
//! A wall of a yield-stress material on a rough base often does not collapse at once: each new
//! layer makes the bottom yield, it spreads until the weight over its wider base is carried
//! again, and the next layer does the same. The top then rises less than a layer per layer, and
//! the print has also failed when the top at a station has lost `lost` (default one layer
//! height) against the nominal height of the layers printed over it: the nozzle then lays the
//! next layer in the air a layer or more above the top, a print no one would go on with.
//!
//! A wall that spreads can stand on its widening base for many layers, its top still rising
//! nearly a layer per layer, while its bottom has long yielded (BENCHMARKS.md "Printing to
//! failure"). With `spread` set, the print has also failed when the section's width at a
//! station, read just before the nozzle next passes it, has grown by more than `spread` over a
//! layer, once it had grown by less over an earlier one: the first layers spread under the
//! squeeze of the next, then the width stands until the weight above yields the bottom (the
//! plastic-collapse criterion's onset, docs/failure.md). The threshold depends on the cell size
//! (a width is resolved to a fraction of a cell), so it has no default.
//!
//! A slender wall buckles: its top swings sideways, out of the plane of the path, long before it
//! has sunk by much (a tilt of the top by an angle theta lowers it only by about theta^2 / 2 of
//! its height). The print has also failed when the top at a station stands more than `sway`
//! (default half the nozzle's width) to the side of where the nozzle laid it: the next layer
//! would then be laid half beside the one below. The top's lateral position is the mean y of
//! the section's outline within one layer height of its highest point, against the y at which
//! the last print move over the station crossed it (the toolpath's own offsets, such as a
//! scenario's imperfection, are not a failure).
//!
//! Every failure is named by its mode: buckling when the sideways rule found it, or when the
//! top stood at least `sway / 2` to the side when another rule fired; plastic collapse
//! otherwise (a yielding bottom squashes the section about its middle, leaving the top where
//! it was laid).
//!
//! The failure layer is the layer being printed (or the last one started) when the sinking
//! began (when the nozzle passed the station, for spreading): 1 is the first layer. The
//! detector is a pure function of the observation history, so a resumed run finds the same
//! failure.

use crate::print::toolpath::{MoveKind, Toolpath};
use crate::observe::CrossSection;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use crate::invalid::Invalid;

/// The `[observe] failure` table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FailureConfig {
    /// Sinking speed of the top [m/s] past which the print has failed; default the build rate.
    #[serde(default)]
    pub sink_rate: Option<f64>,
    /// Time the top must keep sinking faster than `sink_rate` [s].
    #[serde(default = "default_window")]
    pub window: f64,
    /// Height [m] the top may lose against the nominal height of the layers printed over the
    /// station before the print has failed; default one layer height.
    #[serde(default)]
    pub lost: Option<f64>,
    /// Growth [m] of the section's width at a station over one layer, read just before the
    /// nozzle next passes it, past which the print has failed (once the width grew by less over
    /// an earlier layer); default: no spreading rule.
    #[serde(default)]
    pub spread: Option<f64>,
    /// Sideways offset [m] of the top at a station from where the nozzle laid it, past which
    /// the print has failed by buckling; default half the nozzle's width.
    #[serde(default)]
    pub sway: Option<f64>,
    /// End the run this long after the failure time [s]; default: run to `end_time`.
    #[serde(default)]
    pub stop_after: Option<f64>,
}

impl Default for FailureConfig {
    fn default() -> Self {
        FailureConfig { sink_rate: None, window: default_window(), lost: None, spread: None, sway: None, stop_after: None }
    }
}

fn default_window() -> f64 {
    0.5
}

impl FailureConfig {
    pub fn validate(&self) -> Result<(), Invalid> {
        if let Some(r) = self.sink_rate {
            if !(r > 0.0 && r.is_finite()) {
                return Err(Invalid(format!("observe.failure.sink_rate must be > 0 m/s, got {r}")));
            }
        }
        for (name, v) in [("lost", self.lost), ("spread", self.spread), ("sway", self.sway)] {
            if let Some(l) = v {
                if !(l > 0.0 && l.is_finite()) {
                    return Err(Invalid(format!("observe.failure.{name} must be > 0 m, got {l}")));
                }
            }
        }
        if !(self.window > 0.0 && self.window.is_finite()) {
            return Err(Invalid(format!("observe.failure.window must be > 0 s, got {}", self.window)));
        }
        if let Some(s) = self.stop_after {
            if !(s >= 0.0 && s.is_finite()) {
                return Err(Invalid(format!("observe.failure.stop_after must be >= 0 s, got {s}")));
            }
        }
        Ok(())
    }
}

/// How a print failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureMode {
    /// The bottom yielded under the weight above: the top sank or the section spread.
    PlasticCollapse,
    /// The wall swung out of its plane: the top moved sideways.
    Buckling,
}

impl FailureMode {
    pub fn name(self) -> &'static str {
        match self {
            FailureMode::PlasticCollapse => "plastic collapse",
            FailureMode::Buckling => "buckling",
        }
    }
}

/// Which of the detector's rules found the failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureRule {
    /// The top sank faster than `sink_rate` for `window`.
    Sinking,
    /// The top lost `lost` against the nominal height.
    Lost,
    /// The section's width grew by more than `spread` over a layer.
    Spread,
    /// The top stood more than `sway` to the side of where it was laid.
    Sway,
}

/// Where and when a print failed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// The layer being printed when the top began to sink (1 = the first).
    pub layer: usize,
    /// When the top began to sink faster than the threshold [s].
    pub time: f64,
    /// The station whose top sank first [m].
    pub station: f64,
    /// The print's nominal height then: the failure layer's top above the first layer's base [m].
    pub height: f64,
    /// The sinking speed threshold used [m/s].
    pub sink_rate: f64,
    /// Buckling or plastic collapse.
    pub mode: FailureMode,
    /// The rule that found it.
    pub rule: FailureRule,
    /// The top's sideways offset from where it was laid, at the output that found it [m].
    pub sway: f64,
}

/// Finds the failure of a multi-layer print in its observation history.
pub struct Detector {
    toolpath: Arc<Toolpath>,
    /// (z, t_start, t_end) of each layer.
    layers: Vec<(f64, f64, f64)>,
    /// Nominal height of the first layer's base (its top minus the layer height).
    base: f64,
    sink_rate: f64,
    window: f64,
    /// Outputs with the nozzle's centre nearer than this to a station's plane are not used [m].
    clearance: f64,
    /// Height the top may lose against the nominal [m].
    lost: f64,
    /// Width growth over a layer past which the print has failed [m], if that rule is on.
    spread: Option<f64>,
    /// Sideways offset of the top past which the print has failed by buckling [m].
    sway: f64,
    /// Mean layer height [m]: the band below the top whose outline gives its lateral position.
    layer_height: f64,
    /// `[observe] y_range`: the sections see only this band of y, so only the moves that cross a
    /// station inside it lay their material, and only a nozzle inside it (within `clearance`)
    /// is near.
    y_range: Option<[f64; 2]>,
}

impl Detector {
    /// None for a print of fewer than two layers (a layer's own slump is no failure).
    pub fn new(cfg: &FailureConfig, toolpath: Arc<Toolpath>, nozzle_half_x: f64, y_range: Option<[f64; 2]>) -> Option<Detector> {
        let layers = toolpath.layers();
        let n = layers.len();
        if n < 2 {
            return None;
        }
        let h = (layers[n - 1].0 - layers[0].0) / (n - 1) as f64;
        let period = (layers[n - 1].1 - layers[0].1) / (n - 1) as f64;
        if !(h > 0.0 && period > 0.0) {
            return None;
        }
        Some(Detector {
            base: layers[0].0 - h,
            layers,
            toolpath,
            sink_rate: cfg.sink_rate.unwrap_or(h / period),
            window: cfg.window,
            clearance: 3.0 * nozzle_half_x,
            lost: cfg.lost.unwrap_or(h),
            spread: cfg.spread,
            sway: cfg.sway.unwrap_or(nozzle_half_x),
            layer_height: h,
            y_range,
        })
    }

    /// The 1-based layer being printed at `t` (the last one started).
    pub fn layer_at(&self, t: f64) -> usize {
        self.layers.iter().filter(|l| l.1 <= t).count().max(1)
    }

    /// The highest print move the nozzle has laid over the plane x = `station` by `t` (the latest
    /// of equal heights): its height and the y at which it crossed the plane; None before the
    /// first. The nominal top there, and where the nozzle laid it.
    fn laid_at(&self, station: f64, t: f64) -> Option<(f64, f64)> {
        let mut laid: Option<(f64, f64)> = None;
        for m in self.toolpath.moves().iter().filter(|m| m.kind == MoveKind::Print && m.t0 <= t) {
            let (x0, x1) = (m.from[0], m.to[0]);
            if (x0.min(x1)..=x0.max(x1)).contains(&station) {
                let f = if x1 != x0 { (station - x0) / (x1 - x0) } else { 0.0 };
                let y = m.from[1] + f * (m.to[1] - m.from[1]);
                if m.t0 + f * m.duration() <= t && self.in_range(y, 0.0) && laid.is_none_or(|(z, _)| m.to[2] >= z) {
                    laid = Some((m.to[2], y));
                }
            }
        }
        laid
    }

    /// Whether `y` lies in the observed band of y widened by `margin` (always without a band).
    fn in_range(&self, y: f64, margin: f64) -> bool {
        self.y_range.is_none_or(|[lo, hi]| (lo - margin..=hi + margin).contains(&y))
    }

    /// Nominal height above the base of the layers laid over a station ([`Detector::laid_at`];
    /// 0 before the first).
    fn nominal(&self, laid: Option<(f64, f64)>) -> f64 {
        laid.map_or(0.0, |(z, _)| z.max(self.base) - self.base)
    }

    /// The top's sideways offset at a section: the mean y of its outline's points within one
    /// layer height of the highest, less where the nozzle laid it (0 before it laid any).
    fn sway_of(&self, s: &CrossSection, laid: Option<(f64, f64)>) -> f64 {
        let Some((_, laid)) = laid else { return 0.0 };
        let top = s.profile.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
        let (mut sum, mut n) = (0.0, 0usize);
        for p in s.profile.iter().filter(|p| p[1] >= top - self.layer_height) {
            sum += p[0];
            n += 1;
        }
        if n == 0 {
            0.0
        } else {
            sum / n as f64 - laid
        }
    }

    /// The first failure in an observation history: `at(o)` gives an output's time and its
    /// cross-sections (one per station, in the same order at every output).
    pub fn detect<O>(&self, history: &[O], at: impl Fn(&O) -> (f64, &[CrossSection])) -> Option<Failure> {
        let stations = at(history.first()?).1.len();
        let mut first: Option<Failure> = None;
        for k in 0..stations {
            // the current run of outputs (nozzle away) whose top sank faster than the threshold
            let mut prev: Option<(f64, f64)> = None;
            let mut start: Option<f64> = None;
            let mut spreading = Spreading::default();
            // the top's sideways offset at the latest output with the nozzle away
            let mut sway = 0.0;
            let mut found = |f: Failure| {
                if first.is_none_or(|g| f.time < g.time) {
                    first = Some(f);
                }
            };
            for o in history {
                let (time, sections) = at(o);
                let Some(s) = sections.get(k) else { break };
                // a nozzle parked after the toolpath's end lays nothing: the top is judged under it
                let nozzle = self.toolpath.state_at(time).position;
                let printing = time < self.toolpath.end_time();
                if printing && (nozzle[0] - s.station).abs() < self.clearance && self.in_range(nozzle[1], self.clearance) {
                    if let Some(t) = self.spread.and_then(|limit| spreading.pass(time, limit)) {
                        found(self.failure(t, s.station, FailureRule::Spread, sway));
                        break;
                    }
                    (prev, start) = (None, None);
                    continue;
                }
                if s.particles == 0 {
                    (prev, start) = (None, None);
                    continue;
                }
                spreading.away = Some(s.width);
                let laid = self.laid_at(s.station, time);
                sway = self.sway_of(s, laid);
                if sway.abs() >= self.sway {
                    found(self.failure(time, s.station, FailureRule::Sway, sway));
                    break;
                }
                if self.nominal(laid) - s.height >= self.lost {
                    found(self.failure(time, s.station, FailureRule::Lost, sway));
                    break;
                }
                if let Some((t0, h0)) = prev {
                    if (h0 - s.height) > self.sink_rate * (time - t0) {
                        let t_start = *start.get_or_insert(t0);
                        if time - t_start >= self.window * (1.0 - 1e-9) {
                            found(self.failure(t_start, s.station, FailureRule::Sinking, sway));
                            break;
                        }
                    } else {
                        start = None;
                    }
                }
                prev = Some((time, s.height));
            }
        }
        first
    }

    fn failure(&self, time: f64, station: f64, rule: FailureRule, sway: f64) -> Failure {
        let layer = self.layer_at(time);
        let mode = if rule == FailureRule::Sway || sway.abs() >= 0.5 * self.sway {
            FailureMode::Buckling
        } else {
            FailureMode::PlasticCollapse
        };
        Failure { layer, time, station, height: self.layers[layer - 1].0 - self.base, sink_rate: self.sink_rate, mode, rule, sway }
    }
}

/// The spreading rule's state at one station: the section's width read just before each pass
/// of the nozzle, compared with the one before the previous pass.
#[derive(Default)]
struct Spreading {
    /// Width at the latest output with the nozzle away (None once the nozzle has come near).
    away: Option<f64>,
    /// Width read just before the last pass, and when that pass began.
    before: Option<(f64, f64)>,
    /// Whether the width has grown by less than the limit over a layer.
    stood: bool,
}

impl Spreading {
    /// The nozzle is near the station at `time`: on its first output near, the width read just
    /// before is compared with the one before the previous pass. Returns when that previous
    /// pass began if the width grew by more than `limit` over it, having stood before.
    fn pass(&mut self, time: f64, limit: f64) -> Option<f64> {
        let now = self.away.take()?;
        let mut failed = None;
        if let Some((then, passed)) = self.before {
            let grew = now - then > limit;
            if grew && self.stood {
                failed = Some(passed);
            }
            self.stood |= !grew;
        }
        self.before = Some((now, time));
        failed
    }
}

/// The measurement loop's observables of a print's failure (`experiment,observable,at,value`
/// rows `P1,failure_layer,,7` and `P1,failure_time,,25.3`), taken from a forward run of the
/// experiment's scenario as `strand run` observes it (`report::failure_of`). They are piecewise
/// constant in the parameters (the layer a whole number, the time mostly a layer's deposit plus
/// a delay resolved to the output interval), so no adjoint gives their gradients: the
/// measurement loop differences forward runs (`measure/sensitivity.rs`).
pub const OBSERVABLES: &[&str] = &["failure_layer", "failure_time"];

/// Whether `name@at` is a failure observable written as one: none takes a coordinate.
pub fn check_observable(name: &str, at: Option<f64>) -> Result<(), Invalid> {
    match at {
        Some(_) => Err(Invalid(format!("'{name}' takes no '@' (the print's failure is the first at any station)"))),
        None => Ok(()),
    }
}

/// The value of failure observable `name` for a run that failed with `failure`, or stood: a
/// print of `layers` layers that stands to its end `end` counts as failing after its last layer
/// (`failure_layer` = layers + 1, `failure_time` = end), so a model under which it stands is
/// still compared, with the smallest miss it can have.
pub fn observable(name: &str, failure: Option<&Failure>, layers: usize, end: f64) -> Result<f64, Invalid> {
    match (name, failure) {
        ("failure_layer", Some(f)) => Ok(f.layer as f64),
        ("failure_layer", None) => Ok(layers as f64 + 1.0),
        ("failure_time", Some(f)) => Ok(f.time),
        ("failure_time", None) => Ok(end),
        (other, _) => Err(Invalid(format!("'{other}' is not a failure observable ({})", OBSERVABLES.join(", ")))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::print::toolpath::Segment;

    fn wall(layers: usize) -> Arc<Toolpath> {
        let mut segs = Vec::new();
        for k in 0..layers {
            let x = if k % 2 == 0 { 0.1 } else { 0.0 };
            segs.push(Segment::Print { to: [x, 0.0, 0.01 * (k + 1) as f64], speed: 0.05, extrusion: 0.05 });
            if k + 1 < layers {
                segs.push(Segment::Layer { dz: 0.01, speed: Some(0.05) });
            }
        }
        Arc::new(Toolpath::from_segments([0.0, 0.0, 0.01], &segs).unwrap())
    }

    fn obs(time: f64, station: f64, height: f64, width: f64) -> (f64, Vec<CrossSection>) {
        let section = CrossSection {
            station,
            slab: 0.001,
            // no particles at the station before the first layer is laid there (width 0)
            particles: if width > 0.0 { 10 } else { 0 },
            profile: Vec::new(),
            width,
            height,
            area: 0.0,
            profile_area: 0.0,
            y_center: 0.0,
        };
        (time, vec![section])
    }

    /// Layer k of `wall(n)` spans [2.2 k, 2.2 k + 2] s (2 s of print, 0.2 s of rise); the
    /// station at x = 0.05 sees the nozzle at t = 1 s into each layer.
    fn history(height: impl Fn(f64) -> f64) -> Vec<(f64, Vec<CrossSection>)> {
        spreading_history(height, |_| 0.02)
    }

    fn spreading_history(height: impl Fn(f64) -> f64, width: impl Fn(f64) -> f64) -> Vec<(f64, Vec<CrossSection>)> {
        (0..=300).map(|i| 0.05 * i as f64).map(|t| obs(t, 0.05, height(t), width(t))).collect()
    }

    /// Layers printed over the station by `t`: the nozzle passes it 1 s into each layer.
    fn passed(t: f64) -> f64 {
        ((t - 1.0) / 2.2).floor() + 1.0
    }

    fn detect(d: &Detector, height: impl Fn(f64) -> f64) -> Option<Failure> {
        d.detect(&history(height), |o| (o.0, &o.1[..]))
    }

    #[test]
    fn a_standing_print_does_not_fail() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        // each layer adds 10 mm as the nozzle passes, then settles 0.5 mm over half a second
        let h = |t: f64| {
            let k = passed(t);
            let since = t - 1.0 - 2.2 * (k - 1.0);
            0.01 * k - 0.0005 * (since.clamp(0.0, 0.5) / 0.5)
        };
        assert_eq!(detect(&d, h), None);
    }

    #[test]
    fn a_sinking_top_fails_at_the_layer_it_began_in() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        // build rate 10 mm per 2.2 s = 4.5 mm/s; from t = 5.8 s (layer 3, after the nozzle
        // passed the station) the top sinks at 10 mm/s
        let h = |t: f64| 0.01 * passed(t) - 0.01 * (t - 5.8).max(0.0);
        let f = detect(&d, h).expect("fails");
        assert_eq!(f.layer, 3);
        assert!((f.time - 5.8).abs() <= 0.05 + 1e-9, "{f:?}");
        assert!((f.height - 0.03).abs() < 1e-12 && (f.sink_rate - 0.01 / 2.2).abs() < 1e-12, "{f:?}");
        // a sinking rate just under the threshold is no collapse (only the height it loses
        // over time, with the layer-height test off here)
        let slow = |t: f64| 0.01 * passed(t) - 0.004 * (t - 5.8).max(0.0);
        let rate_only = Detector::new(&FailureConfig { lost: Some(1.0), ..FailureConfig::default() }, wall(4), 0.005, None).unwrap();
        assert_eq!(detect(&rate_only, slow), None);
        assert!(detect(&d, slow).is_some_and(|f| f.time > 7.0), "10 mm lost at 4 mm/s");
    }

    /// A wall that gives way after its last layer, under the nozzle parked at the toolpath's end
    /// (x = 0 after four layers, at 8.6 s), has failed: the parked nozzle lays nothing.
    #[test]
    fn a_top_sinking_under_the_parked_nozzle_after_the_print_has_failed() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        let history: Vec<_> = (0..=300).map(|i| 0.05 * i as f64).map(|t| obs(t, 0.0, 0.04 - 0.01 * (t - 9.0).max(0.0), 0.02)).collect();
        let f = d.detect(&history, |o| (o.0, &o.1[..])).expect("fails after the print");
        assert_eq!(f.layer, 4, "{f:?}");
        assert!(f.time >= 9.0 - 1e-9 && f.time < 10.0, "{f:?}");
    }

    #[test]
    fn a_top_that_lost_a_layer_against_the_nominal_has_failed() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        // each layer adds only 6 mm of its 10 at the station (the stack spreads under it): the
        // top is 12 mm short after the third layer, once its settling has passed 10 mm
        let h = |t: f64| {
            let k = passed(t);
            let since = t - 1.0 - 2.2 * (k - 1.0);
            0.006 * k - 0.001 * since.clamp(0.0, 1.0)
        };
        let f = detect(&d, h).expect("fails");
        assert_eq!(f.layer, 3, "{f:?}");
        // the layer deposited at t = 5.4 s; 3 x 10 - (18 - 1 since) >= 10 from 2 s after
        assert!(f.time > 5.4 && f.time < 7.2, "{f:?}");
    }

    #[test]
    fn a_wall_whose_width_grows_after_standing_has_failed_by_spreading() {
        let spreading = FailureConfig { spread: Some(0.0015), ..FailureConfig::default() };
        let d = Detector::new(&spreading, wall(6), 0.005, None).unwrap();
        // the top rises a full layer per layer (no sinking, nothing lost); the width grows 3 mm
        // under the second layer's squeeze, stands (0.5 mm a layer) under the third and fourth,
        // and grows 3 mm a layer from the fifth on: the bottom yielded under the fifth
        let grown = [0.0, 3.0, 3.5, 4.0, 7.0, 10.0];
        let width = |t: f64| if passed(t) < 1.0 { 0.0 } else { 0.02 + 1e-3 * grown[passed(t).min(6.0) as usize - 1] };
        let f = d.detect(&spreading_history(|t| 0.01 * passed(t), width), |o| (o.0, &o.1[..])).expect("fails");
        // the nozzle comes within 1.5 nozzle widths of the station 0.3 s before it passes it,
        // 1 s into layer 5 (t = 9.8 s)
        assert_eq!(f.layer, 5, "{f:?}");
        assert!((f.time - 9.5).abs() <= 0.05 + 1e-9, "{f:?}");
        // without the rule, or with a limit over the growth, the wall stands
        let off = Detector::new(&FailureConfig::default(), wall(6), 0.005, None).unwrap();
        assert_eq!(off.detect(&spreading_history(|t| 0.01 * passed(t), width), |o| (o.0, &o.1[..])), None);
        let wide = Detector::new(&FailureConfig { spread: Some(0.004), ..FailureConfig::default() }, wall(6), 0.005, None).unwrap();
        assert_eq!(wide.detect(&spreading_history(|t| 0.01 * passed(t), width), |o| (o.0, &o.1[..])), None);
        // a wall that spreads from its first layers on, never standing, has not failed by this
        // rule: the first layers spread under the squeeze of the next
        let always = |t: f64| if passed(t) < 1.0 { 0.0 } else { 0.02 + 3e-3 * passed(t) };
        assert_eq!(d.detect(&spreading_history(|t| 0.01 * passed(t), always), |o| (o.0, &o.1[..])), None);
    }

    /// A section 20 mm wide standing `height` tall, its top centred on `top_y` (a tilted
    /// wall: the outline's top band over to one side).
    fn leaning(time: f64, height: f64, top_y: f64) -> (f64, Vec<CrossSection>) {
        let (t, mut sec) = obs(time, 0.05, height, 0.02);
        let sec0 = &mut sec[0];
        if height > 0.0 {
            // a body 20 mm wide on y = 0, and its top layer shifted to top_y
            sec0.profile = vec![[-0.01, 0.0], [-0.01, height - 0.012], [0.01, height - 0.012], [0.01, 0.0]];
            sec0.profile.splice(2..2, [[top_y - 0.01, height], [top_y, height], [top_y + 0.01, height]]);
            sec0.profile.sort_by(|a, b| a[0].total_cmp(&b[0]));
        }
        (t, sec)
    }

    #[test]
    fn a_top_that_swings_sideways_has_failed_by_buckling() {
        let d = Detector::new(&FailureConfig::default(), wall(6), 0.005, None).unwrap();
        // the top rises a layer per layer, and from t = 7 s (layer 4) swings sideways at 4 mm/s:
        // it passes the default 5 mm (half the 10 mm nozzle) 1.25 s later, long before the
        // height it loses (second order in the tilt) counts
        let history: Vec<_> = (0..=300)
            .map(|i| 0.05 * i as f64)
            .map(|t| leaning(t, 0.01 * passed(t), 0.004 * (t - 7.0).max(0.0)))
            .collect();
        let f = d.detect(&history, |o| (o.0, &o.1[..])).expect("fails");
        assert_eq!((f.mode, f.rule, f.layer), (FailureMode::Buckling, FailureRule::Sway, 4), "{f:?}");
        assert!((f.time - 8.25).abs() <= 0.05 + 1e-9 && f.sway >= 0.005, "{f:?}");
        // a wider limit leaves it standing; a top that stays where it was laid does not fail
        let wide = Detector::new(&FailureConfig { sway: Some(0.05), ..FailureConfig::default() }, wall(6), 0.005, None).unwrap();
        assert_eq!(wide.detect(&history, |o| (o.0, &o.1[..])), None);
        let upright: Vec<_> = (0..=300).map(|i| 0.05 * i as f64).map(|t| leaning(t, 0.01 * passed(t), 0.0)).collect();
        assert_eq!(d.detect(&upright, |o| (o.0, &o.1[..])), None);
    }

    #[test]
    fn a_top_laid_off_line_by_the_toolpath_is_not_a_sway() {
        // the toolpath itself leans 2 mm a layer (an imperfection): the top follows it
        let mut segs = Vec::new();
        for k in 0..6 {
            let x = if k % 2 == 0 { 0.1 } else { 0.0 };
            let y = 0.002 * (k + 1) as f64;
            segs.push(Segment::Print { to: [x, y, 0.01 * (k + 1) as f64], speed: 0.05, extrusion: 0.05 });
            if k + 1 < 6 {
                segs.push(Segment::Travel { to: [x, y + 0.002, 0.01 * (k + 2) as f64], speed: 0.05 });
            }
        }
        let path = Arc::new(Toolpath::from_segments([0.0, 0.002, 0.01], &segs).unwrap());
        let d = Detector::new(&FailureConfig::default(), path.clone(), 0.005, None).unwrap();
        let layers = path.layers();
        let laid = |t: f64| {
            // each layer is laid at y = 2 mm per layer; the station x = 0.05 is crossed halfway
            let k = layers.iter().filter(|l| l.1 + 0.5 * (l.2 - l.1) <= t).count();
            (k as f64, 0.002 * k as f64)
        };
        let history: Vec<_> = (0..=300).map(|i| 0.05 * i as f64).map(|t| leaning(t, 0.01 * laid(t).0, laid(t).1)).collect();
        assert_eq!(d.detect(&history, |o| (o.0, &o.1[..])), None, "{:?}", d.layers);
    }

    #[test]
    fn on_a_ring_the_y_range_picks_the_crossing_the_section_sees() {
        use crate::print::arc::Sense;
        let mut segs = Vec::new();
        for k in 0..3 {
            let z = 0.01 * (k + 1) as f64;
            segs.push(Segment::Arc { to: [0.1, 0.0, z], center: Some([0.0, 0.0]), radius: None, sense: Sense::Ccw, turns: Some(1), speed: 0.05, extrusion: 0.05 });
            if k + 1 < 3 {
                segs.push(Segment::Layer { dz: 0.01, speed: Some(0.05) });
            }
        }
        let path = Arc::new(Toolpath::from_segments([0.1, 0.0, 0.01], &segs).unwrap());
        let end = path.moves().last().unwrap().t1;
        let laid = |range| Detector::new(&FailureConfig::default(), path.clone(), 0.005, range).unwrap().laid_at(0.0, end);
        // the plane x = 0 cuts the ring at y = 0.1 (a quarter turn in) and y = -0.1
        let (z, y) = laid(Some([0.05, 0.15])).unwrap();
        assert!((z - 0.03).abs() < 1e-12 && (y - 0.1).abs() < 1e-3, "{z} {y}");
        let (z, y) = laid(Some([-0.15, -0.05])).unwrap();
        assert!((z - 0.03).abs() < 1e-12 && (y + 0.1).abs() < 1e-3, "{z} {y}");
        assert_eq!(laid(Some([0.2, 0.3])), None);
        // a quarter turn into the first ring only the upper crossing is laid
        let quarter = path.moves()[0].t0 + 0.25 * 2.0 * std::f64::consts::PI * 0.1 / 0.05 + 1e-3;
        let d = Detector::new(&FailureConfig::default(), path.clone(), 0.005, Some([-0.15, -0.05])).unwrap();
        assert_eq!(d.laid_at(0.0, quarter), None);
    }

    #[test]
    fn a_collapse_is_named_so() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        let h = |t: f64| 0.01 * passed(t) - 0.01 * (t - 5.8).max(0.0);
        let f = detect(&d, h).expect("fails");
        assert_eq!((f.mode, f.rule), (FailureMode::PlasticCollapse, FailureRule::Sinking));
    }

    #[test]
    fn the_nozzle_passing_the_station_is_not_a_failure() {
        let d = Detector::new(&FailureConfig::default(), wall(4), 0.005, None).unwrap();
        // the tube's material stands 20 mm above the top while the nozzle is over the station,
        // and leaves with it
        let h = |t: f64| {
            let near = (t - 1.0 - 2.2 * (passed(t + 0.3) - 1.0)).abs() < 0.3;
            0.01 * passed(t) + if near { 0.02 } else { 0.0 }
        };
        assert_eq!(detect(&d, h), None);
    }

    #[test]
    fn one_layer_has_no_detector_and_bad_config_is_refused() {
        assert!(Detector::new(&FailureConfig::default(), wall(1), 0.005, None).is_none());
        let bad = FailureConfig { window: 0.0, ..FailureConfig::default() };
        assert!(bad.validate().unwrap_err().0.contains("window"));
        let bad = FailureConfig { sink_rate: Some(-1.0), ..FailureConfig::default() };
        assert!(bad.validate().unwrap_err().0.contains("sink_rate"));
        let bad = FailureConfig { spread: Some(0.0), ..FailureConfig::default() };
        assert!(bad.validate().unwrap_err().0.contains("spread"));
    }
}
