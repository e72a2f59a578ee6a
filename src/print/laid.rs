//! Laid deposits: each layer appears at rest in its nominal cross-section (`width` across the
//! path, `height` below the outlet) as the nozzle passes, instead of being extruded through the
//! tube.
//!
//! This is the activation ("element birth") model of buildability studies (Wolfs, Bos & Salet
//! 2018 activate each layer of their printed cylinder so): it asks whether the layer stack
//! stands, not what shape the extrudate takes. It adds no momentum (an extruded deposit brings
//! the nozzle's velocity with it, and under mass scaling s its momentum flux s rho V^2), so mass
//! scaling leaves the deposit as it is and only the wall's quasi-static response is accelerated.
//!
//! The deposit is cut into columns, one per particle spacing h of extruded material: column q
//! holds the volume w h h of the pushed lengths (q h .. (q + 1) h) w h / A, is added when the
//! last of it has been extruded, and is laid at the outlet's position when its middle was
//! extruded, on an `across` x `down` lattice in the plane normal to the path's horizontal
//! heading. Every particle stands for an equal share of the column's volume, so the mass is the
//! toolpath's extruded volume exactly.

use serde::Deserialize;
use crate::invalid::Invalid;
use super::toolpath::{MoveKind, Toolpath};

/// The section a laid deposit takes.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LaidSection {
    /// Across the path [m].
    pub width: f64,
    /// Below the outlet [m].
    pub height: f64,
}

/// How far a print move's extruded volume per metre of path may differ from the laid section's
/// area: past it the section does not hold what the toolpath extrudes.
pub const SECTION_TOLERANCE: f64 = 0.05;

impl LaidSection {
    pub fn validate(&self) -> Result<(), Invalid> {
        for (key, v) in [("width", self.width), ("height", self.height)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(Invalid(format!("print.deposit.{key} must be > 0, got {v}")));
            }
        }
        Ok(())
    }

    /// Every print move extrudes, per metre of its horizontal path, the section's area within
    /// [`SECTION_TOLERANCE`] (through an outlet of area `outlet_area`), and moves horizontally.
    pub fn check(&self, tp: &Toolpath, outlet_area: f64) -> Result<(), Invalid> {
        let area = self.width * self.height;
        for (k, m) in tp.moves().iter().enumerate().filter(|(_, m)| m.kind == MoveKind::Print && m.extrusion_speed > 0.0) {
            let run = ((m.to[0] - m.from[0]).powi(2) + (m.to[1] - m.from[1]).powi(2)).sqrt();
            let per_metre = m.extrusion_speed * outlet_area * m.duration() / run;
            if run <= 0.0 || (per_metre / area - 1.0).abs() > SECTION_TOLERANCE {
                let what = if run <= 0.0 { "moves only vertically".to_string() } else { format!("extrudes {:.4e} m3 per metre of path", per_metre) };
                return Err(Invalid(format!(
                    "print.deposit: print move {} ({:?} -> {:?}) {what}, but the laid section {} x {} m holds {:.4e} m3 per metre \
                     (more than {:.0} % apart); set the section to what the toolpath extrudes, or its extrusion to the section",
                    k + 1, m.from, m.to, self.width, self.height, area, 100.0 * SECTION_TOLERANCE
                )));
            }
        }
        Ok(())
    }

    /// The lattice of one column at particle spacing `h`: offsets across the path (from the
    /// heartline) and below the outlet, each in the middle of its equal share.
    pub fn lattice(&self, h: f64) -> LaidLattice {
        let share = |len: f64| {
            let n = (len / h).round().max(1.0) as usize;
            (0..n).map(|i| (i as f64 + 0.5) * len / n as f64).collect::<Vec<_>>()
        };
        let across = share(self.width).into_iter().map(|o| o - 0.5 * self.width).collect();
        LaidLattice { across, down: share(self.height), volume: self.width * self.height * h }
    }
}

/// One column of a laid deposit.
#[derive(Clone, Debug, PartialEq)]
pub struct LaidLattice {
    /// Offsets across the path, from the heartline [m].
    pub across: Vec<f64>,
    /// Depths below the outlet [m].
    pub down: Vec<f64>,
    /// The column's volume [m3].
    pub volume: f64,
}

impl LaidLattice {
    pub fn particles(&self) -> usize {
        self.across.len() * self.down.len()
    }

    /// The farthest a particle lies from the heartline, horizontally [m].
    pub fn reach(&self) -> f64 {
        self.across.iter().fold(0.0f64, |m, a| m.max(a.abs()))
    }

    /// Each particle's volume.
    pub fn particle_volume(&self) -> f64 {
        self.volume / self.particles() as f64
    }

    /// Column `q`'s due time and positions (handed to `put`): pushed lengths per column
    /// `per_column` (the column's volume over the outlet's area).
    pub fn layout(&self, tp: &Toolpath, q: u64, per_column: f64, mut put: impl FnMut([f64; 3])) -> f64 {
        let due = tp.time_at_extruded_length((q + 1) as f64 * per_column).unwrap_or(f64::INFINITY);
        let l = (q as f64 + 0.5) * per_column;
        let middle = tp.time_at_extruded_length(l).unwrap_or(due);
        // on the move extruding there, even where the middle falls on its end (the state at that
        // instant would be the next move's, a layer change with no heading)
        let st = match tp.move_extruding(l).flatten() {
            Some(k) => tp.state_on(k, middle),
            None => tp.state_at(middle),
        };
        let (vx, vy) = (st.velocity[0], st.velocity[1]);
        let speed = (vx * vx + vy * vy).sqrt();
        // horizontal normal to the heading (left of it); `check` refuses print moves without one
        let n = if speed > 0.0 { [-vy / speed, vx / speed] } else { [0.0, 1.0] };
        for d in &self.down {
            for a in &self.across {
                put([st.position[0] + a * n[0], st.position[1] + a * n[1], st.position[2] - d]);
            }
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::print::toolpath::Segment;

    fn line(extrusion: f64) -> Toolpath {
        let seg: Segment = toml::from_str(&format!("kind = \"print\"\nto = [0.1, 0.0, 0.01]\nspeed = 0.05\nextrusion = {extrusion}")).unwrap();
        Toolpath::from_segments([0.0, 0.0, 0.01], &[seg]).unwrap()
    }

    #[test]
    fn a_column_is_the_section_at_rest_behind_the_outlet() {
        let s = LaidSection { width: 0.04, height: 0.01 };
        let l = s.lattice(0.0025);
        assert_eq!((l.across.len(), l.down.len()), (16, 4));
        assert!((l.particle_volume() * 64.0 - 0.04 * 0.01 * 0.0025).abs() < 1e-18);
        // a 0.02 x 0.02 outlet extruding the section's area per metre: U A = V w h
        let area = 4e-4;
        let tp = line(0.05 * 0.04 * 0.01 / area);
        s.check(&tp, area).unwrap();
        let per_column = l.volume / area;
        let mut pts = Vec::new();
        let due = l.layout(&tp, 3, per_column, |x| pts.push(x));
        // column 3 is complete once 4 columns' volume is out: 4 h along the path at V
        assert!((due - 4.0 * 0.0025 / 0.05).abs() < 1e-12, "{due}");
        let xs: Vec<f64> = pts.iter().map(|p| p[0]).collect();
        assert!(xs.iter().all(|x| (x - 3.5 * 0.0025).abs() < 1e-12), "laid where its middle was extruded: {xs:?}");
        let (ymin, ymax) = pts.iter().fold((1.0f64, -1.0f64), |a, p| (a.0.min(p[1]), a.1.max(p[1])));
        let (zmin, zmax) = pts.iter().fold((1.0f64, -1.0f64), |a, p| (a.0.min(p[2]), a.1.max(p[2])));
        assert!((ymin + 0.02 - 0.00125).abs() < 1e-12 && (ymax - 0.02 + 0.00125).abs() < 1e-12, "{ymin} {ymax}");
        assert!((zmin - 0.00125).abs() < 1e-12 && (zmax - 0.00875).abs() < 1e-12, "{zmin} {zmax}");
    }

    /// A column whose middle falls on the end of its move takes that move's heading, not the
    /// next move's (a layer change, vertical).
    #[test]
    fn a_column_ending_a_move_keeps_its_heading() {
        let segs: Vec<Segment> = toml::from_str::<toml::Table>(
            "s = [{ kind = \"print\", to = [0.0, 0.005, 0.01], speed = 0.05, extrusion = 0.05 }, { kind = \"layer\", dz = 0.01, speed = 0.05 }]",
        )
        .unwrap()["s"]
            .clone()
            .try_into()
            .unwrap();
        let tp = Toolpath::from_segments([0.0, 0.0, 0.01], &segs).unwrap();
        // 2 mm columns of a 4 x 2 mm section: the third one's middle (5 mm) is the move's end
        let l = LaidSection { width: 0.004, height: 0.002 }.lattice(0.002);
        let per_column = l.volume / 8e-6;
        let mut pts = Vec::new();
        l.layout(&tp, 2, per_column, |x| pts.push(x));
        // the move runs along +y: the section lies across it, along x
        assert!(pts.iter().all(|p| (p[1] - 0.005).abs() < 1e-12) && pts.iter().any(|p| p[0] > 0.0005), "{pts:?}");
    }

    #[test]
    fn a_section_that_does_not_hold_the_extruded_volume_is_refused() {
        let s = LaidSection { width: 0.04, height: 0.01 };
        let area = 4e-4;
        let err = s.check(&line(1.2 * 0.05 * 0.04 * 0.01 / area), area).unwrap_err().0;
        assert!(err.contains("print move 1") && err.contains("holds 4.0000e-4 m3 per metre"), "{err}");
        assert!(LaidSection { width: 0.0, height: 0.01 }.validate().unwrap_err().0.contains("print.deposit.width"));
    }
}
