//! A geometric imperfection of the toolpath (`[print] imperfection`): a small horizontal offset
//! of the nozzle that grows with its height, so a print that buckles buckles one chosen way
//! rather than the way rounding happens to push it.
//!
//! ```toml
//! [print]
//! imperfection = { amplitude = 0.002, height = 0.3, shape = "lean", direction = [0.0, 1.0] }
//! # a cylinder about (0, 0), ovalised: radial offset times cos(2 theta)
//! # imperfection = { amplitude = 0.001, height = 0.3, shape = "bow", direction = "radial", center = [0.0, 0.0], waves = 2 }
//! ```
//!
//! The offset at a nozzle position (x, y, z) is `amplitude f(s) d(x, y)`, with
//! s = (z - base) / height clamped to [0, 1] (`base`, default 0, the height where the print
//! stands: the bed) and
//! - `shape = "lean"`: f = s, out of plumb by `amplitude` at `height` (and above it), the first
//!   buckling mode of a column free at its top in a simple form;
//! - `shape = "bow"`: f = sin(pi s), a half sine bulging by `amplitude` at mid-height and back on
//!   the axis at `height` (a column held at its top, or a bulge in a wall's middle);
//! - `direction = [dx, dy]`: d is that horizontal vector, normalised;
//! - `direction = "radial"`: d is the unit vector from `center` [x, y] to the nozzle times
//!   cos(waves theta), theta the angle about `center` from +x (waves = 0, the default: a uniform
//!   swelling; 2 an oval; n, n lobes). At the centre itself d = 0.
//!
//! The offset moves both ends of every move by the offset at that end; a function of position
//! alone, so consecutive moves still chain exactly and pauses stay still. Durations and
//! extrusion speeds are kept (the extruded length is unchanged); a straight move stays straight,
//! so along a long move the offset is the one interpolated between its ends (arcs are short
//! chords). It applies to `path` and G-code alike, from the commanded heights (before
//! `z_offset`). Amplitude 0 returns the toolpath unchanged, bit for bit.

use super::toolpath::{Move, Toolpath, ToolpathError};
use crate::invalid::Invalid;
use serde::Deserialize;

/// The `[print] imperfection` table (see the module doc).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Imperfection {
    /// Largest offset [m].
    pub amplitude: f64,
    /// Height over which the shape runs, from `base` [m].
    pub height: f64,
    /// Height where the offset is 0 (the bed) [m]; default 0.
    #[serde(default)]
    pub base: f64,
    pub shape: Shape,
    pub direction: Direction,
    /// Axis of a radial imperfection [x, y] (m).
    #[serde(default, alias = "centre")]
    pub center: Option<[f64; 2]>,
    /// Lobes round the axis of a radial imperfection; default 0.
    #[serde(default)]
    pub waves: u32,
}

/// How the offset grows with height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    Lean,
    Bow,
}

/// A fixed horizontal direction, or "radial".
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Direction {
    Fixed([f64; 2]),
    Named(String),
}

impl Imperfection {
    /// Check every key, naming it.
    pub fn validate(&self) -> Result<(), Invalid> {
        let bad = |key: &str, message: String| Err(Invalid(format!("print.imperfection.{key}: {message}")));
        if !self.amplitude.is_finite() {
            return bad("amplitude", format!("{} must be finite", self.amplitude));
        }
        if !(self.height.is_finite() && self.height > 0.0) {
            return bad("height", format!("{} must be finite and > 0", self.height));
        }
        if !self.base.is_finite() {
            return bad("base", format!("{} must be finite", self.base));
        }
        match &self.direction {
            Direction::Fixed(d) => {
                let n = d[0].hypot(d[1]);
                if !(n.is_finite() && n > 0.0) {
                    return bad("direction", format!("{d:?} must be a finite, non-zero horizontal vector"));
                }
                if self.center.is_some() {
                    return bad("center", "is for direction = \"radial\" only".into());
                }
                if self.waves != 0 {
                    return bad("waves", "is for direction = \"radial\" only".into());
                }
            }
            Direction::Named(name) if name == "radial" => match self.center {
                None => return bad("center", "direction = \"radial\" needs center = [x, y]".into()),
                Some(c) if !c.iter().all(|v| v.is_finite()) => return bad("center", format!("{c:?} must be finite")),
                Some(_) => {}
            },
            Direction::Named(name) => return bad("direction", format!("{name:?} is neither [dx, dy] nor \"radial\"")),
        }
        Ok(())
    }

    /// The horizontal offset [m] of a nozzle at `p` (validated input).
    pub fn offset(&self, p: [f64; 3]) -> [f64; 2] {
        let s = ((p[2] - self.base) / self.height).clamp(0.0, 1.0);
        let f = match self.shape {
            Shape::Lean => s,
            Shape::Bow => (std::f64::consts::PI * s).sin(),
        };
        let d = match (&self.direction, self.center) {
            (Direction::Fixed(d), _) => {
                let n = d[0].hypot(d[1]);
                [d[0] / n, d[1] / n]
            }
            (Direction::Named(_), Some(c)) => {
                let (vx, vy) = (p[0] - c[0], p[1] - c[1]);
                let r = vx.hypot(vy);
                if r == 0.0 {
                    [0.0, 0.0]
                } else {
                    let lobes = if self.waves == 0 { 1.0 } else { (self.waves as f64 * vy.atan2(vx)).cos() };
                    [vx / r * lobes, vy / r * lobes]
                }
            }
            (Direction::Named(_), None) => [0.0, 0.0], // refused by validate
        };
        [self.amplitude * f * d[0], self.amplitude * f * d[1]]
    }

    /// The toolpath with every move's ends offset (see the module doc); itself if the amplitude
    /// is 0.
    pub fn apply(&self, path: Toolpath) -> Result<Toolpath, ToolpathError> {
        if self.amplitude == 0.0 {
            return Ok(path);
        }
        let shift = |p: [f64; 3]| {
            let o = self.offset(p);
            [p[0] + o[0], p[1] + o[1], p[2]]
        };
        let moves = path.moves().iter().map(|m| Move { from: shift(m.from), to: shift(m.to), ..m.clone() }).collect();
        Toolpath::from_moves(moves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::print::toolpath::Segment;
    use std::f64::consts::PI;

    fn imperfection(text: &str) -> Imperfection {
        #[derive(Deserialize)]
        struct T {
            imperfection: Imperfection,
        }
        toml::from_str::<T>(&format!("imperfection = {text}")).unwrap_or_else(|e| panic!("{e}")).imperfection
    }

    fn path() -> Toolpath {
        let segs = [
            Segment::Print { to: [0.1, 0.0, 0.01], speed: 0.05, extrusion: 0.05 },
            Segment::Pause { duration: 1.0 },
            Segment::Layer { dz: 0.1, speed: None },
            Segment::Print { to: [0.0, 0.0, 0.11], speed: 0.05, extrusion: 0.05 },
            Segment::Layer { dz: 0.3, speed: None },
        ];
        Toolpath::from_segments([0.0, 0.0, 0.01], &segs).unwrap()
    }

    #[test]
    fn offsets_follow_the_formula() {
        let lean = imperfection("{ amplitude = 0.002, height = 0.2, shape = \"lean\", direction = [0.0, 2.0] }");
        lean.validate().unwrap();
        assert_eq!(lean.offset([5.0, 5.0, 0.1]), [0.0, 0.001]);
        assert_eq!(lean.offset([5.0, 5.0, -0.1]), [0.0, 0.0]);
        assert_eq!(lean.offset([5.0, 5.0, 0.5]), [0.0, 0.002]);
        let bow = imperfection("{ amplitude = 0.002, height = 0.2, base = 0.1, shape = \"bow\", direction = [1.0, 0.0] }");
        for z in [0.1, 0.13, 0.2, 0.25, 0.3] {
            let want = 0.002 * (PI * (z - 0.1) / 0.2).sin();
            assert!((bow.offset([0.0, 0.0, z])[0] - want).abs() < 1e-18, "z = {z}");
        }
        assert!(bow.offset([0.0, 0.0, 0.5])[0].abs() < 1e-18); // clamped at the top: sin(pi)
        let radial = imperfection(
            "{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = \"radial\", centre = [1.0, 1.0], waves = 2 }",
        );
        radial.validate().unwrap();
        for theta in [0.0, 0.3, PI / 4.0, 2.0] {
            let p = [1.0 + 0.2 * theta.cos(), 1.0 + 0.2 * theta.sin(), 0.05];
            let o = radial.offset(p);
            let want = 0.0005 * (2.0 * theta).cos();
            assert!((o[0] - want * theta.cos()).abs() < 1e-15 && (o[1] - want * theta.sin()).abs() < 1e-15, "{theta}: {o:?}");
        }
        assert_eq!(radial.offset([1.0, 1.0, 0.05]), [0.0, 0.0]);
        // the toolpath: each end moved by the offset at that end, still a chain, same timing
        let p = path();
        let q = lean.apply(p.clone()).unwrap();
        for (m, n) in p.moves().iter().zip(q.moves()) {
            assert_eq!((m.t0, m.t1, m.extrusion_speed, m.kind), (n.t0, n.t1, n.extrusion_speed, n.kind));
            for (a, b) in [(m.from, n.from), (m.to, n.to)] {
                let o = lean.offset(a);
                assert_eq!(b, [a[0] + o[0], a[1] + o[1], a[2]]);
            }
        }
        assert_eq!(q.total_extruded_length(), p.total_extruded_length());
    }

    #[test]
    fn zero_amplitude_is_bit_identical() {
        let zero = imperfection("{ amplitude = 0.0, height = 0.2, shape = \"bow\", direction = \"radial\", center = [0.05, 0.0], waves = 3 }");
        zero.validate().unwrap();
        assert_eq!(zero.apply(path()).unwrap(), path());
    }

    #[test]
    fn bad_input_is_named() {
        for (text, key) in [
            ("{ amplitude = 0.001, height = 0.0, shape = \"lean\", direction = [1.0, 0.0] }", "height"),
            ("{ amplitude = nan, height = 0.1, shape = \"lean\", direction = [1.0, 0.0] }", "amplitude"),
            ("{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = [0.0, 0.0] }", "direction"),
            ("{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = \"sideways\" }", "direction"),
            ("{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = \"radial\" }", "center"),
            ("{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = [1.0, 0.0], waves = 2 }", "waves"),
            ("{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = [1.0, 0.0], center = [0.0, 0.0] }", "center"),
        ] {
            let msg = imperfection(text).validate().unwrap_err().0;
            assert!(msg.starts_with(&format!("print.imperfection.{key}: ")), "{text}: {msg}");
        }
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct T {
            imperfection: Imperfection,
        }
        for text in [
            "{ amplitude = 0.001, height = 0.1, shape = \"tilt\", direction = [1.0, 0.0] }",
            "{ amplitude = 0.001, height = 0.1, shape = \"lean\", direction = [1.0, 0.0], wave = 2 }",
        ] {
            assert!(toml::from_str::<T>(&format!("imperfection = {text}")).is_err(), "{text}");
        }
    }
}
