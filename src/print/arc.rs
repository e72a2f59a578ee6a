//! Circular and helical arcs in the horizontal (XY) plane, subdivided into the straight chords a
//! toolpath is made of. One place for both the scenario's `arc` segments and G-code G2/G3.
//!
//! An arc turns about a vertical axis through `center`, clockwise or counter-clockwise seen from
//! above (+z), from the nozzle's position to `end`. Its height rises linearly with the angle (a
//! helix when the end's z differs from the start's: the continuous spiral layer change). If the
//! start and end lie at slightly different distances from the centre (rounded G-code), the radius
//! too varies linearly with the angle, so that the last chord ends exactly at `end`.
//!
//! The toolpath stays a chain of straight constant-velocity moves (its extruded length and its
//! inverse are exact per move), so an arc becomes `n` chords of equal angle. `n` is the smallest
//! count for which
//! - every chord's sagitta (its largest distance from the arc) is at most [`MAX_SAGITTA`] =
//!   0.05 mm: a tenth or less of the particle spacing of any resolution strand runs (cells of
//!   1 mm and coarser, two or more particles per cell), so the deposit cannot tell the chords from
//!   the arc; and
//! - every chord turns the nozzle by at most [`MAX_CHORD_ANGLE`] = 5 degrees, so the nozzle's
//!   velocity, which drives the grid, turns in small steps even on a tight arc whose sagitta
//!   bound alone would allow a few chords (a 10 mm radius would otherwise get 8 chords a turn).
//!
//! A circle of radius 0.25 m becomes 158 chords, one of 50 mm 72 (the angle bound).
//!
//! Timing: the chords are timed so the nozzle covers the *arc length* at the commanded speed,
//! as a printer's controller does (it interpolates the arc itself): a 500 mm circle at
//! 5000 mm/min takes pi 0.5 / 0.0833 s. Each chord, spanning the same angle, lasts the same
//! time, so the nozzle moves along a chord slightly slower than `speed` (by the chord to arc ratio,
//! 1 - 1e-4 at 5 degrees). The extrusion speed is constant over the arc, so the material extruded
//! is what the real machine lays over the arc's duration.

use std::f64::consts::{PI, TAU};

/// Largest distance between a chord and its arc [m] (see the module doc).
pub const MAX_SAGITTA: f64 = 5e-5;
/// Largest angle one chord spans [rad] (5 degrees; see the module doc).
pub const MAX_CHORD_ANGLE: f64 = 5.0 * PI / 180.0;
/// The start's and the end's distances from a given centre may differ by this much [m] ...
pub const CENTER_ABS_TOL: f64 = 5e-5;
/// ... or by this fraction of the radius: the larger of the two is accepted (as LinuxCNC does,
/// so that I/J rounded to a few decimals by a slicer are accepted, a wrong centre is not).
pub const CENTER_REL_TOL: f64 = 1e-3;
/// Most chords one arc may become: a bound on memory against a mistyped radius or turn count
/// (a full circle of 100 km radius is about 3e6 chords).
pub const MAX_CHORDS: usize = 1_000_000;

/// Which way the nozzle turns, seen from above (+z).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Sense {
    /// Clockwise (G2).
    Cw,
    /// Counter-clockwise (G3).
    Ccw,
}

/// The input an [`ArcError`] is about, so the caller can name its own key or G-code word.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArcInput {
    /// The centre (scenario `center`, G-code I/J).
    Center,
    /// The signed radius (scenario `radius`, G-code R).
    Radius,
    /// The end point (scenario `to`, G-code X/Y/Z).
    To,
    /// The number of whole turns (scenario `turns`).
    Turns,
}

/// Why an arc cannot be built: the input at fault and what is wrong with it.
#[derive(Clone, Debug, PartialEq)]
pub struct ArcError {
    pub input: ArcInput,
    pub message: String,
}

fn err<T>(input: ArcInput, message: String) -> Result<T, ArcError> {
    Err(ArcError { input, message })
}

/// An arc, validated: centre, radii at both ends, start angle, signed sweep (> 0 counter-clockwise)
/// and heights at both ends [m, rad].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arc {
    pub center: [f64; 2],
    pub r0: f64,
    pub r1: f64,
    pub theta0: f64,
    pub sweep: f64,
    pub start: [f64; 3],
    pub end: [f64; 3],
}

impl Arc {
    /// The arc from `start` to `end` about `center`, turning `sense`. Its sweep is the angle from
    /// start to end in that sense, in [0, 2 pi), plus `turns` whole turns; it must be > 0, so an
    /// end equal to the start in x, y needs turns >= 1 (a full circle; a helix if z differs).
    pub fn with_center(start: [f64; 3], end: [f64; 3], center: [f64; 2], sense: Sense, turns: u32) -> Result<Arc, ArcError> {
        finite(start, end)?;
        if !center.iter().all(|v| v.is_finite()) {
            return err(ArcInput::Center, format!("{center:?} must be finite"));
        }
        let r0 = (start[0] - center[0]).hypot(start[1] - center[1]);
        let r1 = (end[0] - center[0]).hypot(end[1] - center[1]);
        if r0 == 0.0 {
            return err(ArcInput::Center, format!("{center:?} is the start itself: zero radius"));
        }
        if (r1 - r0).abs() > CENTER_ABS_TOL.max(CENTER_REL_TOL * r0) {
            return err(
                ArcInput::Center,
                format!(
                    "{center:?} is not equidistant from the start ({r0} m) and the end ({r1} m); tolerance {CENTER_ABS_TOL} m or {CENTER_REL_TOL} of the radius"
                ),
            );
        }
        let theta0 = (start[1] - center[1]).atan2(start[0] - center[0]);
        let base = if start[0] == end[0] && start[1] == end[1] {
            0.0
        } else {
            let theta1 = (end[1] - center[1]).atan2(end[0] - center[0]);
            let d = match sense {
                Sense::Ccw => theta1 - theta0,
                Sense::Cw => theta0 - theta1,
            };
            d.rem_euclid(TAU)
        };
        let sweep = base + TAU * turns as f64;
        if !(sweep > 0.0) {
            return err(ArcInput::Turns, "0 with the end equal to the start in x, y: a full circle needs turns >= 1".into());
        }
        let sweep = match sense {
            Sense::Ccw => sweep,
            Sense::Cw => -sweep,
        };
        let arc = Arc { center, r0, r1, theta0, sweep, start, end };
        let n = arc.chord_count();
        if n > MAX_CHORDS {
            let input = if turns > 0 { ArcInput::Turns } else { ArcInput::Center };
            return err(input, format!("a radius of {r0} m turning {} rad needs {n} chords, more than {MAX_CHORDS}", sweep.abs()));
        }
        Ok(arc)
    }

    /// The arc of signed radius `radius` from `start` to `end` turning `sense`, as G-code's R:
    /// R > 0 takes the arc of at most half a turn, R < 0 the one of at least half a turn. The ends
    /// must differ in x, y (a full circle needs the centre form) and |R| be at least half the chord
    /// between them (up to 1e-9 of it, taken as exactly half: a half circle).
    pub fn with_radius(start: [f64; 3], end: [f64; 3], radius: f64, sense: Sense) -> Result<Arc, ArcError> {
        finite(start, end)?;
        if !radius.is_finite() || radius == 0.0 {
            return err(ArcInput::Radius, format!("{radius} must be finite and non-zero"));
        }
        let (dx, dy) = (end[0] - start[0], end[1] - start[1]);
        let chord = dx.hypot(dy);
        if chord == 0.0 {
            return err(ArcInput::To, "ends where the arc starts in x, y: a full circle needs the centre form".into());
        }
        let half = 0.5 * chord;
        let r = radius.abs();
        if r < half * (1.0 - 1e-9) {
            return err(ArcInput::Radius, format!("|{radius}| is less than half the chord from the start to the end ({half} m)"));
        }
        let h = ((r - half) * (r + half)).max(0.0).sqrt();
        // the centre lies left of the chord (seen from above, going start -> end) for a short
        // counter-clockwise arc and for a long clockwise one, right of it otherwise
        let left = (sense == Sense::Ccw) == (radius > 0.0);
        let side = if left { 1.0 } else { -1.0 };
        let center = [0.5 * (start[0] + end[0]) - side * h * dy / chord, 0.5 * (start[1] + end[1]) + side * h * dx / chord];
        Arc::with_center(start, end, center, sense, 0)
    }

    /// Length of the arc [m]: of the helix sqrt((r sweep)^2 + dz^2), with r the mean of the end
    /// radii (exact when they agree).
    pub fn length(&self) -> f64 {
        (0.5 * (self.r0 + self.r1) * self.sweep).hypot(self.end[2] - self.start[2])
    }

    /// Number of chords: the fewest meeting both the sagitta and the angle bound.
    pub fn chord_count(&self) -> usize {
        let r = self.r0.max(self.r1);
        // a chord spanning angle a has sagitta r (1 - cos(a / 2))
        let by_sagitta = 2.0 * (1.0 - MAX_SAGITTA / r).clamp(-1.0, 1.0).acos();
        let a = by_sagitta.min(MAX_CHORD_ANGLE);
        ((self.sweep.abs() / a).ceil() as usize).max(1)
    }

    /// The chords' end points, in order: the last is `end` exactly, the start is not included.
    pub fn points(&self) -> Vec<[f64; 3]> {
        let n = self.chord_count();
        let mut pts: Vec<[f64; 3]> = (1..n)
            .map(|k| {
                let s = k as f64 / n as f64;
                let (theta, r) = (self.theta0 + self.sweep * s, self.r0 + (self.r1 - self.r0) * s);
                [self.center[0] + r * theta.cos(), self.center[1] + r * theta.sin(), self.start[2] + (self.end[2] - self.start[2]) * s]
            })
            .collect();
        pts.push(self.end);
        pts
    }

    /// The chords' end points with the times the nozzle reaches them, starting at time `t0` and
    /// covering the arc's length in `duration`: equal angles in equal times. Times increase
    /// strictly, or the error says the duration is too short to split at `t0`.
    pub fn timed_points(&self, t0: f64, duration: f64) -> Result<Vec<(f64, [f64; 3])>, String> {
        let pts = self.points();
        let n = pts.len();
        let mut prev = t0;
        let mut out = Vec::with_capacity(n);
        for (k, p) in pts.into_iter().enumerate() {
            let t = if k + 1 == n { t0 + duration } else { t0 + duration * (k + 1) as f64 / n as f64 };
            if !(t.is_finite() && t > prev) {
                return Err(format!("a duration of {duration} s in {n} chords is not representable at t = {t0} s"));
            }
            out.push((t, p));
            prev = t;
        }
        Ok(out)
    }
}

fn finite(start: [f64; 3], end: [f64; 3]) -> Result<(), ArcError> {
    if !start.iter().all(|v| v.is_finite()) {
        return err(ArcInput::To, format!("the start {start:?} must be finite"));
    }
    if !end.iter().all(|v| v.is_finite()) {
        return err(ArcInput::To, format!("{end:?} must be finite"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on_circle(arc: &Arc, p: [f64; 3], r: f64) -> bool {
        ((p[0] - arc.center[0]).hypot(p[1] - arc.center[1]) - r).abs() < 1e-12
    }

    #[test]
    fn full_circle_chords_length_ends_and_sagitta() {
        let r = 0.25;
        let start = [1.0 + r, 2.0, 0.01];
        let arc = Arc::with_center(start, start, [1.0, 2.0], Sense::Ccw, 1).unwrap();
        assert!((arc.length() - TAU * r).abs() < 1e-15, "{}", arc.length());
        let pts = arc.points();
        assert_eq!(pts.len(), 158); // ceil(2 pi / (2 acos(1 - 5e-5 / 0.25)))
        assert_eq!(*pts.last().unwrap(), start);
        let mut prev = start;
        let mut chord_sum = 0.0;
        for p in &pts {
            assert!(on_circle(&arc, *p, r), "{p:?}");
            let c = (p[0] - prev[0]).hypot(p[1] - prev[1]);
            // sagitta of a chord of length c on radius r
            let sag = r - (r * r - 0.25 * c * c).sqrt();
            assert!(sag <= MAX_SAGITTA * (1.0 + 1e-9), "sagitta {sag}");
            assert!(sag > 0.5 * MAX_SAGITTA, "chords finer than needed: sagitta {sag}");
            chord_sum += c;
            prev = *p;
        }
        // chords are shorter than the arc by about sweep^2 / 24 of it
        assert!(chord_sum < arc.length() && chord_sum > arc.length() * (1.0 - 1e-4), "{chord_sum}");
        // counter-clockwise: the first chord goes towards +y
        assert!(pts[0][1] > 2.0);
        let cw = Arc::with_center(start, start, [1.0, 2.0], Sense::Cw, 1).unwrap();
        assert!(cw.points()[0][1] < 2.0);
        // a small circle is held by the angle bound
        let small = Arc::with_center([0.01, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.0], Sense::Cw, 1).unwrap();
        assert_eq!(small.points().len(), 72);
    }

    #[test]
    fn helix_rises_linearly_with_the_angle() {
        // 30 mm radius: the angle bound holds, 72 chords a turn
        let arc = Arc::with_center([0.03, 0.0, 0.01], [0.03, 0.0, 0.04], [0.0, 0.0], Sense::Ccw, 3).unwrap();
        let n = arc.chord_count();
        assert_eq!(n, 216);
        let pts = arc.points();
        for (k, p) in pts.iter().enumerate() {
            let s = (k + 1) as f64 / n as f64;
            assert!((p[2] - (0.01 + 0.03 * s)).abs() < 1e-15, "{k}: {p:?}");
            assert!(on_circle(&arc, *p, 0.03));
        }
        // after each whole turn the nozzle is back above the start, one pitch higher
        let turn = &pts[n / 3 - 1];
        assert!((turn[0] - 0.03).abs() < 1e-15 && turn[1].abs() < 1e-15 && (turn[2] - 0.02).abs() < 1e-15, "{turn:?}");
        assert!((arc.length() - (0.03 * 3.0 * TAU).hypot(0.03)).abs() < 1e-15);
        let timed = arc.timed_points(2.0, 6.0).unwrap();
        assert_eq!(timed.last().unwrap(), &(8.0, arc.end));
        assert!((timed[0].0 - (2.0 + 6.0 / n as f64)).abs() < 1e-15);
    }

    #[test]
    fn radius_form_takes_the_short_or_the_long_arc() {
        // from (1, 0) to (0, 1): a quarter circle about the origin counter-clockwise with R = 1,
        // three quarters about (1, 1) with R = -1
        let (a, b) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let short = Arc::with_radius(a, b, 1.0, Sense::Ccw).unwrap();
        assert!(short.center[0].abs() < 1e-15 && short.center[1].abs() < 1e-15, "{short:?}");
        assert!((short.sweep - 0.5 * PI).abs() < 1e-14);
        let long = Arc::with_radius(a, b, -1.0, Sense::Ccw).unwrap();
        assert!((long.center[0] - 1.0).abs() < 1e-15 && (long.center[1] - 1.0).abs() < 1e-15, "{long:?}");
        assert!((long.sweep - 1.5 * PI).abs() < 1e-14);
        // clockwise: the short arc goes round (1, 1), the long one round the origin
        let short = Arc::with_radius(a, b, 1.0, Sense::Cw).unwrap();
        assert!((short.center[0] - 1.0).abs() < 1e-15 && (short.sweep + 0.5 * PI).abs() < 1e-14, "{short:?}");
        let long = Arc::with_radius(a, b, -1.0, Sense::Cw).unwrap();
        assert!(long.center[0].abs() < 1e-15 && (long.sweep + 1.5 * PI).abs() < 1e-14, "{long:?}");
        // half a circle: |R| is half the chord
        let half = Arc::with_radius([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0, Sense::Cw).unwrap();
        assert!(half.center[1].abs() < 1e-15 && (half.sweep + PI).abs() < 1e-14, "{half:?}");
        assert!(half.points().iter().all(|p| p[1] >= -1e-15), "clockwise from -x to +x passes over +y");
    }

    #[test]
    fn errors_name_their_input() {
        let o = [0.0; 3];
        let e = |r: Result<Arc, ArcError>| r.unwrap_err();
        let bad = e(Arc::with_radius(o, [1.0, 0.0, 0.0], 0.4, Sense::Cw));
        assert_eq!(bad.input, ArcInput::Radius);
        assert!(bad.message.contains("half the chord"), "{}", bad.message);
        assert_eq!(e(Arc::with_radius(o, [1.0, 0.0, 0.0], 0.0, Sense::Cw)).input, ArcInput::Radius);
        assert_eq!(e(Arc::with_radius(o, [1.0, 0.0, 0.0], f64::NAN, Sense::Cw)).input, ArcInput::Radius);
        assert_eq!(e(Arc::with_radius(o, [0.0, 0.0, 1.0], 1.0, Sense::Cw)).input, ArcInput::To);
        let off = e(Arc::with_center(o, [2.0, 0.0, 0.0], [0.9, 0.0], Sense::Cw, 0));
        assert!(off.input == ArcInput::Center && off.message.contains("equidistant"), "{off:?}");
        assert_eq!(e(Arc::with_center(o, [1.0, 0.0, 0.0], [0.0, 0.0], Sense::Cw, 0)).input, ArcInput::Center);
        assert_eq!(e(Arc::with_center(o, o, [f64::INFINITY, 0.0], Sense::Cw, 1)).input, ArcInput::Center);
        assert_eq!(e(Arc::with_center([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0], Sense::Cw, 0)).input, ArcInput::Turns);
        assert_eq!(e(Arc::with_center([1.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0], [0.0, 0.0], Sense::Cw, 0)).input, ArcInput::To);
        let many = e(Arc::with_center([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0], Sense::Cw, 100_000));
        assert!(many.input == ArcInput::Turns && many.message.contains("chords"), "{many:?}");
        assert_eq!(e(Arc::with_radius(o, [1.0, 0.0, 0.0], -1e9, Sense::Cw)).input, ArcInput::Center);
        // within the tolerance the radius varies from start to end, and the chain ends exactly
        let arc = Arc::with_center([1.0, 0.0, 0.0], [-1.0004, 0.0, 0.0], [0.0, 0.0], Sense::Ccw, 0).unwrap();
        assert_eq!(*arc.points().last().unwrap(), [-1.0004, 0.0, 0.0]);
    }
}
