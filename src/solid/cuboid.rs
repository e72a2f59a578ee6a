//! An axis-aligned box.

use super::shape::{box_field, sign, Sdf};
use glam::DVec3;

#[derive(Clone, Debug)]
pub struct Cuboid {
    centre: DVec3,
    half: DVec3,
}

impl Cuboid {
    pub fn new(min: DVec3, max: DVec3) -> Cuboid {
        Cuboid { centre: (min + max) * 0.5, half: (max - min) * 0.5 }
    }

    /// Local coordinates q_i = |p_i - c_i| - half_i and the signs of p - c.
    fn local(&self, p: DVec3) -> ([f64; 3], DVec3) {
        let d = p - self.centre;
        let s = DVec3::new(sign(d.x), sign(d.y), sign(d.z));
        ((d * s - self.half).to_array(), s)
    }
}

impl Sdf for Cuboid {
    fn distance(&self, p: DVec3) -> f64 {
        box_field(self.local(p).0).0
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let (q, s) = self.local(p);
        DVec3::from(box_field(q).1) * s
    }

    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3 {
        let (q, s) = self.local(p);
        let (_, _, h) = box_field(q);
        let su = u * s;
        DVec3::new(
            s.x * (h[0][0] * su.x + h[0][1] * su.y + h[0][2] * su.z),
            s.y * (h[1][0] * su.x + h[1][1] * su.y + h[1][2] * su.z),
            s.z * (h[2][0] * su.x + h[2][1] * su.y + h[2][2] * su.z),
        )
    }

    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        Some((self.centre - self.half, self.centre + self.half))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::shape::tests::check_derivatives;

    #[test]
    fn distances_and_derivatives() {
        let b = Cuboid::new(DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.2, 0.1, 0.05));
        assert!((b.distance(DVec3::new(0.1, 0.05, 0.08)) - 0.03).abs() < 1e-12);
        assert!((b.distance(DVec3::new(0.1, 0.05, 0.04)) + 0.01).abs() < 1e-12);
        // beyond an edge: Euclidean
        assert!((b.distance(DVec3::new(0.23, 0.05, 0.09)) - 0.05).abs() < 1e-12);
        check_derivatives(
            &b,
            &[DVec3::new(0.1, 0.05, 0.08), DVec3::new(0.23, 0.05, 0.09), DVec3::new(-0.03, -0.02, -0.01), DVec3::new(0.15, 0.03, 0.02), DVec3::new(0.05, 0.12, 0.03)],
        );
    }
}
