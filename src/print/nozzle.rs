//! Nozzle geometry: the outlet's cross-section, the lattice new particles are laid on, and the
//! distance that feeds the nozzle indicator.

use serde::Deserialize;

/// Outlet cross-section, centred on the nozzle axis (vertical).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum NozzleShape {
    Circle { diameter: f64 },
    /// Axis-aligned rectangle, `size = [along x, along y]`.
    Rectangle { size: [f64; 2] },
}

impl NozzleShape {
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            NozzleShape::Circle { diameter } if !(diameter > 0.0 && diameter.is_finite()) => {
                Err(format!("print.nozzle.diameter must be > 0, got {diameter}"))
            }
            NozzleShape::Rectangle { size } if !(size[0] > 0.0 && size[1] > 0.0 && size.iter().all(|s| s.is_finite())) => {
                Err(format!("print.nozzle.size must be two positive lengths, got {size:?}"))
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
    fn lattice_is_symmetric() {
        let c = NozzleShape::Circle { diameter: 0.0123 };
        let pts = c.lattice(0.001);
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]));
        assert!(sx.abs() < 1e-12 && sy.abs() < 1e-12);
    }
}
