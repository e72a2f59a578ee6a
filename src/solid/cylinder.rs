//! A cylinder of any axis: the centres of its end faces and its radius (a rebar, a pipe).

use super::revolved::{Rectangle, Revolved};
use glam::DVec3;

pub struct Cylinder;

impl Cylinder {
    #[allow(clippy::new_ret_no_self)]
    pub fn new(from: DVec3, to: DVec3, radius: f64) -> Revolved<Rectangle> {
        let length = from.distance(to);
        Revolved { origin: from, axis: (to - from) / length, profile: Rectangle { centre: [0.0, 0.5 * length], half: [radius, 0.5 * length] } }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::shape::{tests::check_derivatives, Sdf};

    #[test]
    fn distances_and_derivatives_on_an_inclined_axis() {
        // a rebar of radius 6 mm along x
        let c = Cylinder::new(DVec3::new(0.0, 0.1, 0.05), DVec3::new(0.2, 0.1, 0.05), 0.006);
        assert!((c.distance(DVec3::new(0.1, 0.1, 0.06)) - 0.004).abs() < 1e-12);
        assert!((c.distance(DVec3::new(0.1, 0.1, 0.05)) + 0.006).abs() < 1e-12);
        assert!((c.distance(DVec3::new(0.203, 0.1, 0.05)) - 0.003).abs() < 1e-12);
        let tilted = Cylinder::new(DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.1, 0.05, 0.2), 0.02);
        check_derivatives(
            &tilted,
            &[DVec3::new(0.05, 0.05, 0.1), DVec3::new(0.04, 0.02, 0.09), DVec3::new(0.13, 0.08, 0.25), DVec3::new(-0.03, -0.01, -0.02), DVec3::new(0.06, -0.02, 0.1)],
        );
    }
}
