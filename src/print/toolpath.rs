//! Toolpaths: timed nozzle moves with piecewise-constant parameters.
//!
//! A toolpath starts at t = 0 and is a chain of moves, each a straight line at constant velocity
//! and constant extrusion speed over a half-open interval [t0, t1). Keeping every parameter
//! constant per interval makes the extruded length piecewise linear, so it and its inverse are
//! exact, and lets gradients be taken per interval later. Units are SI throughout.

use super::arc::{Arc, ArcInput, Sense};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Nozzle speed of a `layer` segment when no earlier segment moved the nozzle [m/s].
const DEFAULT_LAYER_SPEED: f64 = 0.05;
/// Print moves whose heights differ by less than this belong to one layer [m].
const LAYER_Z_TOL: f64 = 1e-9;

/// One timed move of the nozzle: straight line from `from` to `to` over [t0, t1) at constant
/// velocity, extruding at `extrusion_speed` (U, m/s: mean speed of material through the nozzle
/// outlet; 0 for travel moves and pauses).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Move {
    pub t0: f64,
    pub t1: f64,
    pub from: [f64; 3],
    pub to: [f64; 3],
    pub extrusion_speed: f64,
    pub kind: MoveKind,
}

/// What a move does: deposit material, reposition the nozzle, or wait.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MoveKind {
    Print,
    Travel,
    Pause,
}

impl Move {
    /// Duration t1 - t0 [s].
    pub fn duration(&self) -> f64 {
        self.t1 - self.t0
    }

    /// Constant nozzle velocity over the move [m/s].
    pub fn velocity(&self) -> [f64; 3] {
        let dt = self.duration();
        std::array::from_fn(|i| (self.to[i] - self.from[i]) / dt)
    }

    /// Straight-line length of the move [m].
    pub fn length(&self) -> f64 {
        distance(self.from, self.to)
    }
}

/// Nozzle state at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NozzleState {
    pub position: [f64; 3],
    pub velocity: [f64; 3],
    pub extrusion_speed: f64,
    /// Index of the move in effect; `moves().len()` once the path has ended.
    pub interval: usize,
    pub kind: MoveKind,
}

/// One `[[print.path]]` entry of a scenario, relative to where the previous entry left the nozzle.
///
/// ```toml
/// [print]
/// start = [0.0, 0.0, 0.01]
/// [[print.path]]
/// kind = "print"
/// to = [0.5, 0.0, 0.01]
/// speed = 0.05       # nozzle speed [m/s]
/// extrusion = 0.1    # material speed through the outlet [m/s]
/// [[print.path]]
/// kind = "pause"
/// duration = 30.0    # [s]
/// [[print.path]]
/// kind = "layer"
/// dz = 0.01          # [m]; speed optional
/// [[print.path]]
/// kind = "travel"
/// to = [0.0, 0.0, 0.02]
/// speed = 0.1
/// [[print.path]]     # one turn round (0.1, 0), rising a layer: a spiral layer change
/// kind = "arc"
/// to = [0.0, 0.0, 0.03]
/// center = [0.1, 0.0]  # or radius = r (R of G-code; < 0: the long way; not for full turns)
/// sense = "ccw"      # seen from above; or "cw"
/// turns = 1          # whole turns besides the part from the start to `to`; default 0
/// speed = 0.05
/// extrusion = 0.1    # 0: an arc of travel
/// ```
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Segment {
    /// Extruding straight move to `to` [m] at nozzle speed `speed` [m/s], material leaving the
    /// outlet at `extrusion` [m/s].
    Print { to: [f64; 3], speed: f64, extrusion: f64 },
    /// Non-extruding straight move to `to` [m] at `speed` [m/s].
    Travel { to: [f64; 3], speed: f64 },
    /// Rest for `duration` [s]: nozzle still, no extrusion.
    Pause { duration: f64 },
    /// Vertical travel up by `dz` [m]. Without `speed`, the last moving segment's speed is
    /// reused (a layer change rarely warrants its own), or 0.05 m/s if there is none.
    Layer {
        dz: f64,
        #[serde(default)]
        speed: Option<f64>,
    },
    /// Arc (helix if `to`'s z differs from the start's) about a vertical axis, turning `sense`
    /// seen from above, to `to` [m], given by its `center` [x, y] or its signed `radius` [m] (as
    /// G-code's R: < 0 takes the arc over half a turn), plus `turns` whole turns (centre form
    /// only; `to` equal to the start in x, y with turns = 1 is a full circle). Covered at `speed`
    /// along the arc, extruding at `extrusion` (0: a travel). Becomes chords, see `print::arc`.
    Arc {
        to: [f64; 3],
        #[serde(default)]
        center: Option<[f64; 2]>,
        #[serde(default)]
        radius: Option<f64>,
        sense: Sense,
        #[serde(default)]
        turns: Option<u32>,
        speed: f64,
        extrusion: f64,
    },
}

impl Segment {
    /// The `kind` tag as written in TOML.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Segment::Print { .. } => "print",
            Segment::Travel { .. } => "travel",
            Segment::Pause { .. } => "pause",
            Segment::Layer { .. } => "layer",
            Segment::Arc { .. } => "arc",
        }
    }
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ToolpathError {
    /// A `[[print.path]]` entry is invalid; `key` is the offending TOML key.
    #[error("{kind} path[{index}]: {message}")]
    Segment { index: usize, kind: &'static str, key: &'static str, message: String },
    #[error("print.start = {0:?} must be finite")]
    Start([f64; 3]),
    /// A move handed to `from_moves` is invalid or does not chain on to its predecessor.
    #[error("toolpath move {index}: {message}")]
    Move { index: usize, message: String },
    #[error("the toolpath has no moves")]
    Empty,
}

/// A validated chain of moves starting at t = 0, with the extruded length precomputed at every
/// move start so that time <-> extruded length queries are binary searches.
#[derive(Clone, Debug, PartialEq)]
pub struct Toolpath {
    moves: Vec<Move>,
    /// `extruded[k]` = ∫_0^{t0_k} U dt; one more entry than moves (the last is the total).
    extruded: Vec<f64>,
}

impl Toolpath {
    /// Build the timed moves of `segs`, starting at `start` [m] at t = 0. Every error names the
    /// segment (`path[i]`) and the key at fault.
    pub fn from_segments(start: [f64; 3], segs: &[Segment]) -> Result<Toolpath, ToolpathError> {
        if !start.iter().all(|v| v.is_finite()) {
            return Err(ToolpathError::Start(start));
        }
        let mut moves = Vec::with_capacity(segs.len());
        let (mut pos, mut t) = (start, 0.0);
        let mut last_speed = None;
        for (index, seg) in segs.iter().enumerate() {
            let kind = seg.kind_name();
            let bad = |key, message: String| ToolpathError::Segment { index, kind, key, message };
            let (to, to_key, speed, extrusion, move_kind) = match *seg {
                Segment::Print { to, speed, extrusion } => (to, "to", speed, extrusion, MoveKind::Print),
                Segment::Travel { to, speed } => (to, "to", speed, 0.0, MoveKind::Travel),
                Segment::Layer { dz, speed } => {
                    if !(dz.is_finite() && dz > 0.0) {
                        return Err(bad("dz", format!("dz = {dz} must be finite and > 0")));
                    }
                    let to = [pos[0], pos[1], pos[2] + dz];
                    let speed = speed.or(last_speed).unwrap_or(DEFAULT_LAYER_SPEED);
                    (to, "dz", speed, 0.0, MoveKind::Travel)
                }
                Segment::Arc { to, center, radius, sense, turns, speed, extrusion } => {
                    let arc = arc_segment(pos, to, center, radius, sense, turns).map_err(|(key, message)| bad(key, message))?;
                    check_rates(speed, extrusion).map_err(|(key, message)| bad(key, message))?;
                    let move_kind = if extrusion > 0.0 { MoveKind::Print } else { MoveKind::Travel };
                    let chords = arc.timed_points(t, arc.length() / speed).map_err(|m| bad("speed", format!("speed = {speed}: {m}")))?;
                    for (t1, p) in chords {
                        moves.push(Move { t0: t, t1, from: pos, to: p, extrusion_speed: extrusion, kind: move_kind });
                        (pos, t) = (p, t1);
                    }
                    last_speed = Some(speed);
                    continue;
                }
                Segment::Pause { duration } => {
                    if !(duration.is_finite() && duration > 0.0) {
                        return Err(bad("duration", format!("duration = {duration} must be finite and > 0")));
                    }
                    let t1 = t + duration;
                    if !(t1 > t) {
                        return Err(bad("duration", format!("duration = {duration} is lost in rounding at t = {t} s")));
                    }
                    moves.push(Move { t0: t, t1, from: pos, to: pos, extrusion_speed: 0.0, kind: MoveKind::Pause });
                    t = t1;
                    continue;
                }
            };
            check_rates(speed, extrusion).map_err(|(key, message)| bad(key, message))?;
            if !to.iter().all(|v| v.is_finite()) {
                return Err(bad("to", format!("to = {to:?} must be finite")));
            }
            let length = distance(pos, to);
            if length == 0.0 {
                return Err(bad(to_key, format!("zero-length move ({to_key} leaves the nozzle at {pos:?})")));
            }
            let t1 = t + length / speed;
            if !(t1.is_finite() && t1 > t) {
                return Err(bad("speed", format!("speed = {speed} gives no representable duration at t = {t} s")));
            }
            moves.push(Move { t0: t, t1, from: pos, to, extrusion_speed: extrusion, kind: move_kind });
            (pos, t) = (to, t1);
            last_speed = Some(speed);
        }
        Self::from_moves(moves)
    }

    /// Wrap explicit moves (as produced by G-code import). They must chain exactly: the first
    /// starts at t = 0, each starts at its predecessor's `t1` and `to`, durations are positive,
    /// everything is finite, and only print moves extrude.
    pub fn from_moves(moves: Vec<Move>) -> Result<Toolpath, ToolpathError> {
        if moves.is_empty() {
            return Err(ToolpathError::Empty);
        }
        let mut extruded = Vec::with_capacity(moves.len() + 1);
        extruded.push(0.0);
        for (index, m) in moves.iter().enumerate() {
            let bad = |message: String| Err(ToolpathError::Move { index, message });
            let finite = m.from.iter().chain(&m.to).chain([&m.t0, &m.t1, &m.extrusion_speed]).all(|v| v.is_finite());
            if !finite {
                return bad(format!("non-finite value in {m:?}"));
            }
            if !(m.t1 > m.t0) {
                return bad(format!("t1 = {} must be after t0 = {}", m.t1, m.t0));
            }
            let (t_prev, at_prev) = match index {
                0 => (0.0, m.from),
                _ => (moves[index - 1].t1, moves[index - 1].to),
            };
            if m.t0 != t_prev {
                return bad(format!("starts at t0 = {} but the previous move ends at {t_prev}", m.t0));
            }
            if m.from != at_prev {
                return bad(format!("starts at {:?} but the previous move ends at {at_prev:?}", m.from));
            }
            if m.extrusion_speed < 0.0 || (m.kind != MoveKind::Print && m.extrusion_speed != 0.0) {
                return bad(format!("{:?} move with extrusion speed {}", m.kind, m.extrusion_speed));
            }
            if m.kind == MoveKind::Pause && m.from != m.to {
                return bad("pause that moves the nozzle".to_string());
            }
            extruded.push(extruded[index] + m.extrusion_speed * m.duration());
        }
        Ok(Toolpath { moves, extruded })
    }

    /// The moves, in time order.
    pub fn moves(&self) -> &[Move] {
        &self.moves
    }

    /// Time the last move ends [s].
    pub fn end_time(&self) -> f64 {
        self.last().t1
    }

    /// Nozzle state at time `t` [s], clamped to [0, end] (NaN counts as 0). Intervals are
    /// half-open, so at a move boundary the later move is in effect; from the end on the nozzle
    /// rests at its final position with `interval == moves().len()` and kind `Pause`.
    pub fn state_at(&self, t: f64) -> NozzleState {
        let t = self.clamp_time(t);
        self.state_on(self.move_at(t), t)
    }

    /// Move `k`'s own formula evaluated at `t`, even outside its interval (`k = moves().len()`:
    /// at rest at the end). A derivative with respect to the toolpath's parameters at fixed `t`
    /// holds the move fixed: across a move boundary the state is not differentiable.
    pub fn state_on(&self, k: usize, t: f64) -> NozzleState {
        if k >= self.moves.len() {
            return NozzleState {
                position: self.last().to,
                velocity: [0.0; 3],
                extrusion_speed: 0.0,
                interval: self.moves.len(),
                kind: MoveKind::Pause,
            };
        }
        let m = &self.moves[k];
        let s = (t - m.t0) / m.duration();
        NozzleState {
            position: std::array::from_fn(|i| m.from[i] + (m.to[i] - m.from[i]) * s),
            velocity: m.velocity(),
            extrusion_speed: m.extrusion_speed,
            interval: k,
            kind: m.kind,
        }
    }

    /// The move in effect at `t` (already clamped): `moves().len()` from the end on.
    fn move_at(&self, t: f64) -> usize {
        if t >= self.end_time() {
            self.moves.len()
        } else {
            self.interval_index(t)
        }
    }

    /// Length of material extruded through the outlet by time `t` [m]: ∫_0^t U dt, with `t`
    /// clamped as in `state_at`.
    pub fn extruded_length(&self, t: f64) -> f64 {
        let t = self.clamp_time(t);
        self.extruded_on(self.move_at(t), t)
    }

    /// Move `k`'s formula of the extruded length at `t` (see [`Toolpath::state_on`]).
    pub fn extruded_on(&self, k: usize, t: f64) -> f64 {
        if k >= self.moves.len() {
            return self.total_extruded_length();
        }
        self.extruded[k] + self.moves[k].extrusion_speed * (t - self.moves[k].t0)
    }

    /// The earliest time at which `extruded_length` reaches `l` [m]; 0 for l <= 0, None if `l`
    /// exceeds the total (or is NaN). Exact up to rounding because U is constant per move.
    pub fn time_at_extruded_length(&self, l: f64) -> Option<f64> {
        self.move_extruding(l).map(|k| match k {
            None => 0.0,
            Some(k) => {
                let m = &self.moves[k];
                if l == self.extruded[k + 1] {
                    // Reached exactly at the move's end: the boundary itself, not a rounded guess.
                    m.t1
                } else {
                    self.time_at_extruded_on(k, l).min(m.t1)
                }
            }
        })
    }

    /// The move during which the extruded length reaches `l`: `Some(None)` for l <= 0 (t = 0),
    /// None if `l` exceeds the total (or is NaN).
    pub fn move_extruding(&self, l: f64) -> Option<Option<usize>> {
        if l.is_nan() || l > self.total_extruded_length() {
            return None;
        }
        if l <= 0.0 {
            return Some(None);
        }
        // First move whose end has extruded at least l; it starts below l, so it extrudes (U > 0).
        Some(Some(self.extruded[1..].partition_point(|&e| e < l)))
    }

    /// Move `k`'s formula of the time its extruded length reaches `l` (k must extrude).
    pub fn time_at_extruded_on(&self, k: usize, l: f64) -> f64 {
        let m = &self.moves[k];
        m.t0 + (l - self.extruded[k]) / m.extrusion_speed
    }

    /// Total length of material extruded over the whole path [m].
    pub fn total_extruded_length(&self) -> f64 {
        self.extruded[self.moves.len()]
    }

    /// Layers as (z, t_start, t_end): consecutive print moves whose end heights agree within
    /// 1e-9 m form one layer, spanning the first one's start to the last one's end. In time
    /// order; returning to an earlier height later starts a new entry.
    ///
    /// A spiral (the continuous layer change: print moves that rise and follow each other
    /// without a break) is cut into one layer per turn: a layer ends where its heading has
    /// turned through a whole turn, so a circle's helix, or a square's, gives one layer per
    /// loop; z is the height at the turn's end.
    pub fn layers(&self) -> Vec<(f64, f64, f64)> {
        let mut layers: Vec<(f64, f64, f64)> = Vec::new();
        // the previous print move, and the heading turned since the current layer began (a
        // spiral's layer), None while the layer is flat
        let mut prev: Option<&Move> = None;
        let mut turned: Option<f64> = None;
        for m in self.moves.iter().filter(|m| m.kind == MoveKind::Print) {
            let z = m.to[2];
            let rises = m.to[2] - m.from[2] >= LAYER_Z_TOL;
            let after = prev.filter(|p| p.to == m.from && p.t1 == m.t0);
            // a spiral's next move: the heading turned since its layer began, this move's turn
            // included
            let spiral = match (turned, after) {
                (Some(angle), Some(p)) if rises => Some(angle + heading_change(p, m)),
                _ => None,
            };
            match (layers.last_mut(), spiral) {
                (Some(layer), Some(angle)) if angle.abs() < 2.0 * PI * (1.0 - 1e-9) => {
                    turned = Some(angle);
                    (layer.0, layer.2) = (z, m.t1);
                }
                (Some(layer), None) if turned.is_none() && !rises && (layer.0 - z).abs() < LAYER_Z_TOL => layer.2 = m.t1,
                _ => {
                    layers.push((z, m.t0, m.t1));
                    // a loop completed: the next layer carries what this move turned past it,
                    // so that layers stay in step with the turns over many loops
                    turned = match spiral {
                        Some(angle) => Some(angle - 2.0 * PI * angle.signum()),
                        None => rises.then_some(0.0),
                    };
                }
            }
            prev = Some(m);
        }
        layers
    }

    /// Axis-aligned bounds (min, max) of every position the nozzle visits [m].
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let first = self.moves[0].from;
        self.moves.iter().fold((first, first), |(lo, hi), m| {
            (std::array::from_fn(|i| lo[i].min(m.to[i])), std::array::from_fn(|i| hi[i].max(m.to[i])))
        })
    }

    /// Start time of every move followed by the end time: the edges of the intervals over which
    /// the parameters are constant.
    pub fn interval_boundaries(&self) -> Vec<f64> {
        self.moves.iter().map(|m| m.t0).chain([self.end_time()]).collect()
    }

    fn last(&self) -> &Move {
        // from_moves rejects empty paths, so there is always a last move.
        &self.moves[self.moves.len() - 1]
    }

    fn clamp_time(&self, t: f64) -> f64 {
        // f64::max returns the non-NaN operand, so NaN becomes 0.
        t.max(0.0).min(self.end_time())
    }

    /// Index of the move in effect at `t` in [0, end): the last one with t0 <= t.
    fn interval_index(&self, t: f64) -> usize {
        self.moves.partition_point(|m| m.t0 <= t).saturating_sub(1)
    }
}

/// A moving segment's nozzle speed (> 0) and extrusion speed (>= 0), or the TOML key at fault
/// and why.
fn check_rates(speed: f64, extrusion: f64) -> Result<(), (&'static str, String)> {
    if !(speed.is_finite() && speed > 0.0) {
        return Err(("speed", format!("speed = {speed} must be finite and > 0")));
    }
    if !(extrusion.is_finite() && extrusion >= 0.0) {
        return Err(("extrusion", format!("extrusion = {extrusion} must be finite and >= 0")));
    }
    Ok(())
}

/// The arc of an `arc` segment starting at `pos`, or the TOML key at fault and why.
fn arc_segment(
    pos: [f64; 3],
    to: [f64; 3],
    center: Option<[f64; 2]>,
    radius: Option<f64>,
    sense: Sense,
    turns: Option<u32>,
) -> Result<Arc, (&'static str, String)> {
    let arc = match (center, radius) {
        (Some(c), None) => Arc::with_center(pos, to, c, sense, turns.unwrap_or(0)),
        (None, Some(r)) if turns.is_none() => Arc::with_radius(pos, to, r, sense),
        (None, Some(_)) => return Err(("turns", "turns: needs the centre form (center = [x, y]), not radius".into())),
        (Some(_), Some(_)) => return Err(("radius", "radius: give center or radius, not both".into())),
        (None, None) => return Err(("center", "center: an arc needs center = [x, y] or radius".into())),
    };
    arc.map_err(|e| {
        let key = match e.input {
            ArcInput::Center => "center",
            ArcInput::Radius => "radius",
            ArcInput::To => "to",
            ArcInput::Turns => "turns",
        };
        (key, format!("{key}: {}", e.message))
    })
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt()
}

/// The signed angle from `a`'s horizontal heading to `b`'s, in (-pi, pi] (0 if either has none).
fn heading_change(a: &Move, b: &Move) -> f64 {
    let (ax, ay) = (a.to[0] - a.from[0], a.to[1] - a.from[1]);
    let (bx, by) = (b.to[0] - b.from[0], b.to[1] - b.from[1]);
    if (ax == 0.0 && ay == 0.0) || (bx == 0.0 && by == 0.0) {
        return 0.0;
    }
    (ax * by - ay * bx).atan2(ax * bx + ay * by)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn print(to: [f64; 3], speed: f64, extrusion: f64) -> Segment {
        Segment::Print { to, speed, extrusion }
    }

    /// Dyadic numbers throughout so that expected times are exact in binary.
    fn sample() -> Toolpath {
        let segs = [
            print([1.0, 0.0, 0.0], 0.5, 2.0),                    // [0, 2), extrudes 4
            Segment::Travel { to: [1.0, 1.0, 0.0], speed: 1.0 }, // [2, 3)
            Segment::Pause { duration: 0.5 },                    // [3, 3.5)
            Segment::Layer { dz: 0.25, speed: None },            // [3.5, 3.75) at the travel's 1 m/s
            print([0.0, 1.0, 0.25], 0.25, 1.0),                  // [3.75, 7.75), extrudes 4
            Segment::Layer { dz: 0.25, speed: Some(0.5) },       // [7.75, 8.25)
            print([0.0, 0.0, 0.5], 0.5, 0.5),                    // [8.25, 10.25), extrudes 1
        ];
        Toolpath::from_segments([0.0; 3], &segs).unwrap()
    }

    #[test]
    fn state_at_follows_moves_with_half_open_intervals() {
        let p = sample();
        assert_eq!(p.end_time(), 10.25);
        assert_eq!(p.interval_boundaries(), vec![0.0, 2.0, 3.0, 3.5, 3.75, 7.75, 8.25, 10.25]);
        let s = p.state_at(1.0);
        assert_eq!(
            s,
            NozzleState {
                position: [0.5, 0.0, 0.0],
                velocity: [0.5, 0.0, 0.0],
                extrusion_speed: 2.0,
                interval: 0,
                kind: MoveKind::Print
            }
        );
        // At t = 2 the print has ended and the travel is in effect.
        let s = p.state_at(2.0);
        assert_eq!(
            (s.position, s.velocity, s.extrusion_speed, s.interval, s.kind),
            ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.0, 1, MoveKind::Travel)
        );
        let s = p.state_at(3.25);
        assert_eq!((s.position, s.velocity, s.interval, s.kind), ([1.0, 1.0, 0.0], [0.0; 3], 2, MoveKind::Pause));
        let s = p.state_at(3.5);
        assert_eq!(
            (s.position, s.velocity, s.interval, s.kind),
            ([1.0, 1.0, 0.0], [0.0, 0.0, 1.0], 3, MoveKind::Travel)
        );
        let s = p.state_at(3.75);
        assert_eq!(
            (s.position, s.velocity, s.extrusion_speed, s.interval),
            ([1.0, 1.0, 0.25], [-0.25, 0.0, 0.0], 1.0, 4)
        );
        let s = p.state_at(5.75);
        assert_eq!(s.position, [0.5, 1.0, 0.25]);
        let s = p.state_at(10.0);
        assert_eq!((s.position, s.interval), ([0.0, 0.125, 0.5], 6));
        // Clamping: before the start is the start, from the end on the nozzle rests.
        assert_eq!(p.state_at(-1.0), p.state_at(0.0));
        assert_eq!(p.state_at(f64::NAN), p.state_at(0.0));
        assert_eq!(p.state_at(0.0).position, [0.0; 3]);
        let rest = NozzleState {
            position: [0.0, 0.0, 0.5],
            velocity: [0.0; 3],
            extrusion_speed: 0.0,
            interval: 7,
            kind: MoveKind::Pause,
        };
        assert_eq!(p.state_at(10.25), rest);
        assert_eq!(p.state_at(1e9), rest);
    }

    #[test]
    fn extruded_length_and_its_inverse_are_exact() {
        let p = sample();
        assert_eq!(p.total_extruded_length(), 9.0);
        for (t, l) in [
            (-1.0, 0.0),
            (0.0, 0.0),
            (1.0, 2.0),
            (2.0, 4.0),
            (3.25, 4.0),
            (3.75, 4.0),
            (5.75, 6.0),
            (7.75, 8.0),
            (9.25, 8.5),
            (10.25, 9.0),
            (99.0, 9.0),
        ] {
            assert_eq!(p.extruded_length(t), l, "t = {t}");
        }
        // The earliest time: l = 4 is reached at the end of the first print, not after the pause.
        for (l, t) in
            [(-1.0, 0.0), (0.0, 0.0), (2.0, 1.0), (4.0, 2.0), (5.0, 4.75), (8.0, 7.75), (8.5, 9.25), (9.0, 10.25)]
        {
            assert_eq!(p.time_at_extruded_length(l), Some(t), "l = {l}");
        }
        assert_eq!(p.time_at_extruded_length(9.0 + 1e-9), None);
        assert_eq!(p.time_at_extruded_length(f64::NAN), None);
    }

    /// xorshift64*: a fixed-seed generator so the property test is reproducible.
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn inverse_round_trips_on_random_paths() {
        let mut rng = Rng(0x5eed_1234_abcd_0001);
        for _ in 0..50 {
            let mut pos = [0.0; 3];
            let mut segs = Vec::new();
            for _ in 0..20 {
                let r = rng.uniform();
                segs.push(match r {
                    r if r < 0.6 => {
                        pos = [pos[0] + rng.uniform() - 0.5, pos[1] + rng.uniform() - 0.5, pos[2]];
                        print(pos, 0.01 + 0.1 * rng.uniform(), 0.3 * rng.uniform())
                    }
                    r if r < 0.75 => {
                        pos = [pos[0] + rng.uniform() - 0.5, pos[1] + rng.uniform() - 0.5, pos[2]];
                        Segment::Travel { to: pos, speed: 0.05 + rng.uniform() }
                    }
                    r if r < 0.9 => Segment::Pause { duration: 10.0 * rng.uniform() + 1e-3 },
                    _ => {
                        pos[2] += 0.01;
                        Segment::Layer { dz: 0.01, speed: None }
                    }
                });
            }
            let p = Toolpath::from_segments([0.0; 3], &segs).unwrap();
            let total = p.total_extruded_length();
            for _ in 0..200 {
                let l = total * rng.uniform();
                let t = p.time_at_extruded_length(l).unwrap();
                let back = p.extruded_length(t);
                assert!((back - l).abs() <= 1e-12 * l, "l = {l}, t = {t}, back = {back}");
                // Earliest: a moment before, less had come out.
                assert!(t == 0.0 || p.extruded_length(t * (1.0 - 1e-9)) < l);
            }
        }
    }

    #[test]
    fn layers_bounds_and_moves() {
        let p = sample();
        assert_eq!(p.layers(), vec![(0.0, 0.0, 2.0), (0.25, 3.75, 7.75), (0.5, 8.25, 10.25)]);
        assert_eq!(p.bounds(), ([0.0; 3], [1.0, 1.0, 0.5]));
        assert_eq!(p.moves().len(), 7);
        assert_eq!(p.moves()[3].kind, MoveKind::Travel);
        // Two prints at one height with a travel between are one layer.
        let segs = [
            print([1.0, 0.0, 0.0], 1.0, 1.0),
            Segment::Travel { to: [1.0, 1.0, 0.0], speed: 1.0 },
            print([0.0, 1.0, 0.0], 1.0, 1.0),
        ];
        assert_eq!(Toolpath::from_segments([0.0; 3], &segs).unwrap().layers(), vec![(0.0, 0.0, 3.0)]);
    }

    #[test]
    fn a_spiral_is_one_layer_per_turn() {
        // a flat ring at z = 0.01, then a helix of three turns rising 10 mm a turn
        let circle = |z, turns| Segment::Arc { to: [0.1, 0.0, z], center: Some([0.0, 0.0]), radius: None, sense: Sense::Ccw, turns: Some(turns), speed: 0.05, extrusion: 0.05 };
        let (ring, helix) = (circle(0.01, 1), circle(0.04, 3));
        let p = Toolpath::from_segments([0.1, 0.0, 0.01], &[ring, helix]).unwrap();
        let layers = p.layers();
        let turn = 2.0 * PI * 0.1 / 0.05;
        assert_eq!(layers.len(), 4, "{layers:?}");
        for (k, l) in layers.iter().enumerate() {
            // each turn's chords (a turn need not end on a chord's end: within one chord, at
            // most 5 degrees): its end height and its time span
            let chord = 5.0 / 360.0;
            assert!((l.0 - 0.01 * (k + 1) as f64).abs() <= 0.01 * chord, "{k}: {l:?}");
            assert!((l.2 - l.1 - turn).abs() <= 2.0 * chord * turn, "{k}: {l:?}");
        }
        // the turns stay in step: the last ends with the helix
        assert_eq!(layers[3].2, p.end_time());
        // a square spiral (vase mode): four rising sides a loop, two loops
        let side = |x: f64, y: f64, z: f64| print([x, y, z], 0.05, 0.05);
        let square: Vec<Segment> = (0..8)
            .map(|i| {
                let z = 0.01 + 0.0025 * (i + 1) as f64;
                match i % 4 {
                    0 => side(0.1, 0.0, z),
                    1 => side(0.1, 0.1, z),
                    2 => side(0.0, 0.1, z),
                    _ => side(0.0, 0.0, z),
                }
            })
            .collect();
        let layers = Toolpath::from_segments([0.0, 0.0, 0.01], &square).unwrap().layers();
        assert_eq!(layers.iter().map(|l| l.0).collect::<Vec<_>>(), vec![0.02, 0.03], "{layers:?}");
    }

    #[test]
    fn layer_speed_defaults() {
        let p = Toolpath::from_segments([0.0; 3], &[Segment::Layer { dz: 0.1, speed: None }]).unwrap();
        assert_eq!(p.end_time(), 2.0); // 0.1 m at 0.05 m/s
        let segs = [
            Segment::Travel { to: [1.0, 0.0, 0.0], speed: 0.5 },
            Segment::Pause { duration: 1.0 },
            Segment::Layer { dz: 0.5, speed: None },
        ];
        let p = Toolpath::from_segments([0.0; 3], &segs).unwrap();
        assert_eq!(p.interval_boundaries(), vec![0.0, 2.0, 3.0, 4.0]); // the pause does not reset the speed
    }

    fn segment_error(segs: &[Segment]) -> (usize, &'static str, String) {
        match Toolpath::from_segments([0.0; 3], segs) {
            Err(e @ ToolpathError::Segment { index, key, .. }) => (index, key, e.to_string()),
            other => panic!("expected a segment error, got {other:?}"),
        }
    }

    #[test]
    fn segment_errors_name_index_and_key() {
        let ok = print([1.0, 0.0, 0.0], 1.0, 1.0);
        let cases: [(Segment, &str); 10] = [
            (print([2.0, 0.0, 0.0], 0.0, 1.0), "speed"),
            (Segment::Travel { to: [2.0, 0.0, 0.0], speed: f64::NAN }, "speed"),
            (Segment::Travel { to: [2.0, 0.0, 0.0], speed: f64::INFINITY }, "speed"),
            (print([2.0, 0.0, 0.0], 1.0, -0.1), "extrusion"),
            (print([2.0, 0.0, 0.0], 1.0, f64::NAN), "extrusion"),
            (print([f64::INFINITY, 0.0, 0.0], 1.0, 1.0), "to"),
            (Segment::Pause { duration: 0.0 }, "duration"),
            (Segment::Layer { dz: -0.01, speed: None }, "dz"),
            (Segment::Layer { dz: 0.01, speed: Some(-1.0) }, "speed"),
            (Segment::Travel { to: [1.0, 0.0, 0.0], speed: 1.0 }, "to"),
        ];
        for (seg, want_key) in cases {
            let kind = seg.kind_name();
            let (index, key, msg) = segment_error(&[ok.clone(), Segment::Pause { duration: 1.0 }, seg]);
            assert_eq!((index, key), (2, want_key), "{msg}");
            assert!(msg.starts_with(&format!("{kind} path[2]: ")) && msg.contains(want_key), "{msg}");
        }
        let (index, key, msg) = segment_error(&[
            ok.clone(),
            Segment::Travel { to: [2.0, 0.0, 0.0], speed: 1.0 },
            Segment::Pause { duration: 1.0 },
            print([2.0, 0.0, 0.0], 1.0, 1.0),
        ]);
        assert_eq!((index, key), (3, "to"));
        assert!(msg.starts_with("print path[3]: zero-length move"), "{msg}");
        assert!(matches!(Toolpath::from_segments([f64::NAN, 0.0, 0.0], &[]), Err(ToolpathError::Start(_))));
        assert_eq!(Toolpath::from_segments([0.0; 3], &[]), Err(ToolpathError::Empty));
    }

    #[test]
    fn from_moves_requires_a_chain() {
        let m = |t0: f64, t1: f64, from: [f64; 3], to: [f64; 3], u: f64, kind| Move {
            t0,
            t1,
            from,
            to,
            extrusion_speed: u,
            kind,
        };
        let a = m(0.0, 1.0, [0.0; 3], [1.0, 0.0, 0.0], 1.0, MoveKind::Print);
        let error_of = |moves: Vec<Move>| match Toolpath::from_moves(moves) {
            Err(ToolpathError::Move { index, message }) => (index, message),
            other => panic!("expected a move error, got {other:?}"),
        };
        assert!(Toolpath::from_moves(vec![
            a.clone(),
            m(1.0, 2.0, [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, MoveKind::Pause)
        ])
        .is_ok());
        assert!(error_of(vec![m(0.5, 1.0, [0.0; 3], [1.0; 3], 0.0, MoveKind::Travel)]).1.contains("t0"));
        assert_eq!(
            error_of(vec![a.clone(), m(1.5, 2.0, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], 0.0, MoveKind::Travel)]).0,
            1
        );
        assert_eq!(
            error_of(vec![a.clone(), m(1.0, 2.0, [1.5, 0.0, 0.0], [2.0, 0.0, 0.0], 0.0, MoveKind::Travel)]).0,
            1
        );
        assert_eq!(
            error_of(vec![a.clone(), m(1.0, 1.0, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], 0.0, MoveKind::Travel)]).0,
            1
        );
        assert_eq!(
            error_of(vec![a.clone(), m(1.0, 2.0, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], 1.0, MoveKind::Travel)]).0,
            1
        );
        assert_eq!(error_of(vec![a, m(1.0, 2.0, [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], 0.0, MoveKind::Pause)]).0, 1);
        assert_eq!(Toolpath::from_moves(vec![]), Err(ToolpathError::Empty));
    }

    #[test]
    fn arc_segments_become_timed_chords_and_errors_name_the_key() {
        // a quarter circle of radius 1 about the origin at speed pi/2 takes 1 s, then a travel arc
        let arc = |to: [f64; 3], center, radius, sense, turns, speed, extrusion| Segment::Arc { to, center, radius, sense, turns, speed, extrusion };
        let segs = [
            arc([0.0, 1.0, 0.0], Some([0.0, 0.0]), None, Sense::Ccw, None, std::f64::consts::FRAC_PI_2, 2.0),
            arc([1.0, 0.0, 0.5], None, Some(1.0), Sense::Cw, None, 1.0, 0.0),
        ];
        let p = Toolpath::from_segments([1.0, 0.0, 0.0], &segs).unwrap();
        let quarter: Vec<&Move> = p.moves().iter().filter(|m| m.kind == MoveKind::Print).collect();
        // radius 1: the sagitta bound holds, 2 acos(1 - 5e-5) a chord
        assert_eq!(quarter.len(), (std::f64::consts::FRAC_PI_2 / (2.0 * (1.0 - 5e-5f64).acos())).ceil() as usize);
        assert_eq!(quarter.last().unwrap().t1, 1.0);
        assert_eq!(p.total_extruded_length(), 2.0);
        assert_eq!(p.moves().last().unwrap().to, [1.0, 0.0, 0.5]);
        assert!(p.moves()[quarter.len()..].iter().all(|m| m.kind == MoveKind::Travel && m.extrusion_speed == 0.0));
        assert!((p.end_time() - 1.0 - std::f64::consts::FRAC_PI_2.hypot(0.5)).abs() < 1e-15);
        let ok = print([1.0, 0.0, 0.0], 1.0, 1.0);
        for (seg, want_key, needle) in [
            (arc([3.0, 0.0, 0.0], None, Some(0.5), Sense::Cw, None, 1.0, 1.0), "radius", "half the chord"),
            (arc([3.0, 0.0, 0.0], None, Some(0.0), Sense::Cw, None, 1.0, 1.0), "radius", "non-zero"),
            (arc([3.0, 0.0, 0.0], Some([1.5, 0.0]), None, Sense::Cw, None, 1.0, 1.0), "center", "equidistant"),
            (arc([3.0, 0.0, 0.0], Some([2.0, 0.0]), Some(1.0), Sense::Cw, None, 1.0, 1.0), "radius", "not both"),
            (arc([3.0, 0.0, 0.0], None, None, Sense::Cw, None, 1.0, 1.0), "center", "needs"),
            (arc([3.0, 0.0, 0.0], None, Some(1.0), Sense::Cw, Some(1), 1.0, 1.0), "turns", "centre form"),
            (arc([1.0, 0.0, 0.0], Some([2.0, 0.0]), None, Sense::Cw, None, 1.0, 1.0), "turns", "full circle"),
            (arc([1.0, 0.0, 0.0], None, Some(1.0), Sense::Cw, None, 1.0, 1.0), "to", "centre form"),
            (arc([f64::NAN, 0.0, 0.0], Some([2.0, 0.0]), None, Sense::Cw, None, 1.0, 1.0), "to", "finite"),
            (arc([3.0, 0.0, 0.0], Some([2.0, 0.0]), None, Sense::Cw, None, -1.0, 1.0), "speed", "speed"),
            (arc([3.0, 0.0, 0.0], Some([2.0, 0.0]), None, Sense::Cw, None, 1.0, f64::NAN), "extrusion", "extrusion"),
        ] {
            let (index, key, msg) = segment_error(&[ok.clone(), seg]);
            assert_eq!((index, key), (1, want_key), "{msg}");
            assert!(msg.starts_with(&format!("arc path[1]: {want_key}")) && msg.contains(needle), "{msg}");
        }
        // from TOML: an unknown sense is refused
        let text = "[print]\nstart = [0.1, 0.0, 0.01]\n[[print.path]]\nkind = \"arc\"\nto = [0.1, 0.0, 0.02]\ncenter = [0.0, 0.0]\nturns = 1\nsense = \"ccw\"\nspeed = 0.05\nextrusion = 0.05\n";
        let s: Scenario = toml::from_str(text).unwrap();
        let p = Toolpath::from_segments(s.print.start, &s.print.path).unwrap();
        assert_eq!(p.moves().last().unwrap().to, [0.1, 0.0, 0.02]);
        assert_eq!(p.layers().len(), 1); // a spiral of one turn: one layer
        let e = toml::from_str::<Scenario>(&text.replace("\"ccw\"", "\"clockwise\"")).err().unwrap().to_string();
        assert!(e.contains("clockwise") && e.contains("cw"), "{e}");
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct PrintTable {
        start: [f64; 3],
        path: Vec<Segment>,
    }

    #[derive(Deserialize)]
    struct Scenario {
        print: PrintTable,
    }

    #[test]
    fn segments_from_toml() {
        let text = r#"
            [print]
            start = [0.0, 0.0, 0.01]
            [[print.path]]
            kind = "print"
            to = [0.5, 0.0, 0.01]
            speed = 0.05
            extrusion = 0.1
            [[print.path]]
            kind = "pause"
            duration = 30.0
            [[print.path]]
            kind = "layer"
            dz = 0.01
            [[print.path]]
            kind = "travel"
            to = [0.0, 0.0, 0.02]
            speed = 0.1
        "#;
        let s: Scenario = toml::from_str(text).unwrap();
        assert_eq!(s.print.path[2], Segment::Layer { dz: 0.01, speed: None });
        let p = Toolpath::from_segments(s.print.start, &s.print.path).unwrap();
        assert_eq!(p.moves().len(), 4);
        // A misspelt key, a key of another kind, and an unknown kind are all rejected.
        for bad in [
            "kind = \"travel\"\nto = [1.0, 0.0, 0.0]\nsped = 0.1",
            "kind = \"travel\"\nto = [1.0, 0.0, 0.0]\nspeed = 0.1\nextrusion = 0.1",
            "kind = \"spiral\"\nto = [1.0, 0.0, 0.0]",
        ] {
            let text = format!("[print]\nstart = [0.0, 0.0, 0.0]\n[[print.path]]\n{bad}\n");
            assert!(toml::from_str::<Scenario>(&text).is_err(), "accepted {bad:?}");
        }
    }
}
