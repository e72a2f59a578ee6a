//! The nozzle's body: a tube from the outlet's radius to its outer radius, its flat end in the
//! outlet plane, standing `height` above it, in the frame of the outlet (z up). It moves with the
//! nozzle; the tube's inside stays the driven flow of `print/`.

use super::revolved::{Rectangle, Revolved};
use glam::DVec3;

pub struct NozzleBody;

impl NozzleBody {
    #[allow(clippy::new_ret_no_self)]
    pub fn new(inner_radius: f64, outer_radius: f64, height: f64) -> Revolved<Rectangle> {
        Revolved {
            origin: DVec3::ZERO,
            axis: DVec3::Z,
            profile: Rectangle {
                centre: [0.5 * (inner_radius + outer_radius), 0.5 * height],
                half: [0.5 * (outer_radius - inner_radius), 0.5 * height],
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::shape::{tests::check_derivatives, Sdf};

    #[test]
    fn the_flat_end_and_both_walls() {
        let b = NozzleBody::new(0.01, 0.02, 0.03);
        // under the flat end
        assert!((b.distance(DVec3::new(0.015, 0.0, -0.004)) - 0.004).abs() < 1e-12);
        // inside the bore, 3 mm from the inner wall
        assert!((b.distance(DVec3::new(0.0, 0.007, 0.01)) - 0.003).abs() < 1e-12);
        // beside the outer wall
        assert!((b.distance(DVec3::new(0.025, 0.0, 0.01)) - 0.005).abs() < 1e-12);
        assert!(b.distance(DVec3::new(0.0, 0.015, 0.01)) < 0.0);
        check_derivatives(
            &b,
            &[DVec3::new(0.015, 0.001, -0.004), DVec3::new(0.002, 0.007, 0.01), DVec3::new(0.02, 0.011, 0.01), DVec3::new(0.006, 0.0, -0.003), DVec3::new(0.0105, 0.0085, 0.012), DVec3::new(0.025, 0.001, -0.004)],
        );
    }
}
