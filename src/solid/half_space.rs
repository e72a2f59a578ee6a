//! A half-space: everything behind a plane (an inclined wall, a sloped floor). Its normal points
//! out of the solid, into the material.

use super::shape::Sdf;
use glam::DVec3;

#[derive(Clone, Debug)]
pub struct HalfSpace {
    point: DVec3,
    normal: DVec3,
}

impl HalfSpace {
    pub fn new(point: DVec3, normal: DVec3) -> HalfSpace {
        HalfSpace { point, normal: normal.normalize() }
    }
}

impl Sdf for HalfSpace {
    fn distance(&self, p: DVec3) -> f64 {
        (p - self.point).dot(self.normal)
    }
    fn gradient(&self, _: DVec3) -> DVec3 {
        self.normal
    }
    fn hessian_times(&self, _: DVec3, _: DVec3) -> DVec3 {
        DVec3::ZERO
    }
    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::shape::tests::check_derivatives;

    #[test]
    fn an_inclined_plane() {
        let h = HalfSpace::new(DVec3::new(0.0, 0.0, 0.1), DVec3::new(-1.0, 0.0, 2.0));
        assert!(h.distance(DVec3::new(0.0, 0.0, 0.0)) < 0.0);
        assert!((h.distance(DVec3::new(0.0, 0.3, 0.1 + 5f64.sqrt())) - 2.0).abs() < 1e-12);
        check_derivatives(&h, &[DVec3::new(0.1, 0.2, 0.3)]);
    }
}
