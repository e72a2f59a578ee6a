//! Nozzle geometry: the outlet's cross-section, the lattice new particles are laid on, and the
//! distance that feeds the nozzle indicator.

use serde::Deserialize;
use crate::invalid::Invalid;

/// Outlet cross-section, centred on the nozzle axis (vertical).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum NozzleShape {
    Circle { diameter: f64 },
    /// Axis-aligned rectangle, `size = [along x, along y]`.
    Rectangle { size: [f64; 2] },
}

/// The fewest cells across the outlet that give a printed section right in kind, with J-bar on
/// and with it off (as gradient runs, calibrate and diagnose need). Measured on a 16 mm nozzle
/// 8 mm above the bed at yield stresses 163 and 312 Pa (BENCHMARKS.md, "Discretisation error";
/// `make bench-nozzle-cells`): with J-bar, 3 to 6 cells all order the two strands rightly (the
/// softer one wider and lower) with the area within 0.9 % of the mass balance; without it,
/// 4 cells make the strand more than twice the standoff high with 26-34 % too much area, and
/// 5 cells order the heights wrongly with 8-10 % too much, 6 cells order them rightly (by
/// 0.03 mm) with 2.5-4.1 % too much.
pub const MIN_CELLS_ACROSS: f64 = 3.0;
pub const MIN_CELLS_ACROSS_WITHOUT_J_BAR: f64 = 6.0;

/// The evidence the warning cites, J-bar on and off.
const EVIDENCE: &str = "with J-bar, 3 to 6 cells give a 16 mm line's section right in kind (area within 0.9 % of the mass balance)";
const EVIDENCE_WITHOUT_J_BAR: &str = "without J-bar, 4 cells make a 16 mm line twice the standoff high with 26-34 % too much area, 5 cells order a soft and a stiff material's heights wrongly";

impl NozzleShape {
    /// The outlet's narrowest width: a circle's diameter, a rectangle's shorter side.
    pub fn narrowest(&self) -> f64 {
        match *self {
            NozzleShape::Circle { diameter } => diameter,
            NozzleShape::Rectangle { size } => size[0].min(size[1]),
        }
    }

    /// What `strand check` and `strand run` warn when cells of size `dx` span the outlet fewer
    /// times than a section needs ([`MIN_CELLS_ACROSS`], or without J-bar
    /// [`MIN_CELLS_ACROSS_WITHOUT_J_BAR`]); None when they span it enough.
    pub fn resolution_warning(&self, dx: f64, j_bar: bool) -> Option<String> {
        let (need, evidence) = if j_bar { (MIN_CELLS_ACROSS, EVIDENCE) } else { (MIN_CELLS_ACROSS_WITHOUT_J_BAR, EVIDENCE_WITHOUT_J_BAR) };
        let cells = self.narrowest() / dx;
        (cells < need).then(|| {
            format!(
                "the nozzle spans {cells:.1} cells ({:.1} mm outlet, {:.2} mm cells); a printed section {} needs {need} or more: {evidence} (BENCHMARKS.md \"Discretisation error\"). Use dx <= {:.4} m",
                1e3 * self.narrowest(),
                1e3 * dx,
                if j_bar { "with J-bar" } else { "without J-bar" },
                self.narrowest() / need
            )
        })
    }

    pub fn validate(&self) -> Result<(), Invalid> {
        match *self {
            NozzleShape::Circle { diameter } if !(diameter > 0.0 && diameter.is_finite()) => {
                Err(Invalid(format!("print.nozzle.diameter must be > 0, got {diameter}")))
            }
            NozzleShape::Rectangle { size } if !(size[0] > 0.0 && size[1] > 0.0 && size.iter().all(|s| s.is_finite())) => {
                Err(Invalid(format!("print.nozzle.size must be two positive lengths, got {size:?}")))
            }
            _ => Ok(()),
        }
    }

    /// Exact outlet area [m2].
    pub fn area(&self) -> f64 {
        match *self {
            NozzleShape::Circle { diameter } => std::f64::consts::PI * diameter * diameter / 4.0,
            NozzleShape::Rectangle { size } => size[0] * size[1],
        }
    }

    /// Half-extent of the outlet along x and y (for bounding boxes).
    pub fn half_extent(&self) -> [f64; 2] {
        match *self {
            NozzleShape::Circle { diameter } => [diameter / 2.0; 2],
            NozzleShape::Rectangle { size } => [size[0] / 2.0, size[1] / 2.0],
        }
    }

    /// The distance fed to the indicator and the wall position it is compared with, for a point
    /// at horizontal offset (ox, oy) from the axis: (|o|, R) for a circle; for a rectangle the
    /// largest excess over the half-sizes, against 0 (its zero level set is the rectangle).
    #[inline]
    pub fn distance(&self, ox: f64, oy: f64) -> (f64, f64) {
        match *self {
            NozzleShape::Circle { diameter } => ((ox * ox + oy * oy).sqrt(), diameter / 2.0),
            NozzleShape::Rectangle { size } => ((ox.abs() - size[0] / 2.0).max(oy.abs() - size[1] / 2.0), 0.0),
        }
    }

    /// Gradient of [`NozzleShape::distance`] with respect to the offset (ox, oy), on the branch the
    /// distance takes (zero at the axis of a circle, where it has none).
    #[inline]
    pub fn distance_gradient(&self, ox: f64, oy: f64) -> [f64; 2] {
        match *self {
            NozzleShape::Circle { .. } => {
                let d = (ox * ox + oy * oy).sqrt();
                if d > 0.0 {
                    [ox / d, oy / d]
                } else {
                    [0.0; 2]
                }
            }
            NozzleShape::Rectangle { size } => {
                if ox.abs() - size[0] / 2.0 >= oy.abs() - size[1] / 2.0 {
                    [ox.signum(), 0.0]
                } else {
                    [0.0, oy.signum()]
                }
            }
        }
    }

    /// Horizontal offsets of the lattice points (spacing `h`, points at cell centres of an
    /// h-lattice aligned with the axis) that lie inside the outlet.
    pub fn lattice(&self, h: f64) -> Vec<[f64; 2]> {
        let [ex, ey] = self.half_extent();
        let (nx, ny) = ((ex / h).ceil() as i64, (ey / h).ceil() as i64);
        let mut pts = Vec::new();
        for i in -nx..nx {
            for j in -ny..ny {
                let (ox, oy) = ((i as f64 + 0.5) * h, (j as f64 + 0.5) * h);
                let (d, r) = self.distance(ox, oy);
                if d < r {
                    pts.push([ox, oy]);
                }
            }
        }
        pts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_area_approaches_the_outlet_area() {
        let c = NozzleShape::Circle { diameter: 0.025 };
        let h = 0.0005;
        let n = c.lattice(h).len() as f64;
        assert!((n * h * h / c.area() - 1.0).abs() < 0.01, "{}", n * h * h / c.area());
        let r = NozzleShape::Rectangle { size: [0.02, 0.01] };
        assert_eq!(r.lattice(0.001).len(), 200);
    }

    #[test]
    fn too_few_cells_across_the_outlet_are_warned_of() {
        let c = NozzleShape::Circle { diameter: 0.016 };
        let w = c.resolution_warning(0.004, false).expect("4 cells across without J-bar");
        assert!(w.contains("spans 4.0 cells") && w.contains("16.0 mm outlet") && w.contains("without J-bar"), "{w}");
        assert!(c.resolution_warning(0.004, true).is_none(), "4 cells with J-bar are enough");
        for (j_bar, need) in [(true, MIN_CELLS_ACROSS), (false, MIN_CELLS_ACROSS_WITHOUT_J_BAR)] {
            assert!(c.resolution_warning(0.016 / need, j_bar).is_none());
            assert!(c.resolution_warning(0.016 / (need - 0.5), j_bar).is_some());
        }
        // a rectangle is as fine as its shorter side
        let r = NozzleShape::Rectangle { size: [0.04, 0.01] };
        assert!(r.resolution_warning(0.01 / MIN_CELLS_ACROSS, true).is_none());
        assert!(r.resolution_warning(0.04 / MIN_CELLS_ACROSS, true).is_some());
    }

    #[test]
    fn lattice_is_symmetric() {
        let c = NozzleShape::Circle { diameter: 0.0123 };
        let pts = c.lattice(0.001);
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]));
        assert!(sx.abs() < 1e-12 && sy.abs() < 1e-12);
    }
}
