//! A vertical frustum of a cone (z up) standing on its base centre: a slump cone, or, taken away
//! from a larger shape (`difference`), the mould around one. Its profile is the trapezoid of
//! (r, z) mirrored about the axis, so the distance is exact everywhere and the axis is no face.

use super::revolved::{Profile, Revolved};
use glam::{DMat2, DVec2, DVec3};

pub struct Frustum;

impl Frustum {
    #[allow(clippy::new_ret_no_self)]
    pub fn new(base_center: DVec3, bottom_radius: f64, top_radius: f64, height: f64) -> Revolved<ConvexPolygon> {
        let corners = [[-bottom_radius, 0.0], [bottom_radius, 0.0], [top_radius, height], [-top_radius, height]];
        Revolved { origin: base_center, axis: DVec3::Z, profile: ConvexPolygon::new(&corners) }
    }
}

/// A convex polygon of (r, z), its corners counter-clockwise; edges of zero length (a cone's
/// apex) are dropped.
#[derive(Clone, Debug)]
pub struct ConvexPolygon {
    /// Each edge: its start, its direction (start to end) and its outward unit normal.
    edges: Vec<(DVec2, DVec2, DVec2)>,
}

impl ConvexPolygon {
    pub fn new(corners: &[[f64; 2]]) -> ConvexPolygon {
        let n = corners.len();
        let edges = (0..n)
            .filter_map(|i| {
                let (a, b) = (DVec2::from(corners[i]), DVec2::from(corners[(i + 1) % n]));
                let e = b - a;
                (e.length() > 0.0).then(|| (a, e, DVec2::new(e.y, -e.x).normalize()))
            })
            .collect();
        ConvexPolygon { edges }
    }
}

impl Profile for ConvexPolygon {
    /// Inside, the least distance to an edge's line (the field is linear there); outside, the
    /// distance to the nearest point of the boundary, an edge's (linear) or a corner's (curved).
    fn field(&self, rz: [f64; 2]) -> (f64, [f64; 2], [[f64; 2]; 2]) {
        let p = DVec2::from(rz);
        let (k, s) = self.edges.iter().enumerate().map(|(i, (a, _, n))| (i, n.dot(p - *a))).fold((0, f64::NEG_INFINITY), |best, e| if e.1 > best.1 { e } else { best });
        if s <= 0.0 {
            return (s, self.edges[k].2.to_array(), [[0.0; 2]; 2]);
        }
        let mut nearest = (f64::INFINITY, DVec2::ZERO, false);
        for &(a, e, n) in &self.edges {
            let t = ((p - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
            let d = p.distance(a + e * t);
            if d < nearest.0 {
                let corner = t <= 0.0 || t >= 1.0;
                nearest = (d, if corner { (p - (a + e * t)) / d } else { n }, corner);
            }
        }
        let (d, g, corner) = nearest;
        let h = if corner { (DMat2::IDENTITY - DMat2::from_cols(g * g.x, g * g.y)) * (1.0 / d) } else { DMat2::ZERO };
        (d, g.to_array(), [h.col(0).to_array(), h.col(1).to_array()])
    }

    fn extent(&self) -> (f64, f64, f64) {
        self.edges.iter().fold((0.0, f64::INFINITY, f64::NEG_INFINITY), |(r, lo, hi), (a, _, _)| (r.max(a.x.abs()), lo.min(a.y), hi.max(a.y)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::shape::{tests::check_derivatives, Sdf};

    #[test]
    fn the_abrams_cone_inside_outside_and_at_its_rims() {
        // 20 cm base, 10 cm top, 30 cm high
        let c = Frustum::new(DVec3::new(0.1, -0.2, 0.0), 0.1, 0.05, 0.3);
        let slant = DVec2::new(0.3, 0.05).normalize(); // the outward normal of the side in (r, z)
        // on the axis, nearest the side (its radius there, times the cosine of its slope) or the base
        assert!((c.distance(DVec3::new(0.1, -0.2, 0.1)) + (0.1 - 0.05 / 3.0) * slant.x).abs() < 1e-12);
        assert!((c.distance(DVec3::new(0.1, -0.2, 0.01)) + 0.01).abs() < 1e-12);
        // outside the side at mid-height, 2 cm off along the normal
        let q = DVec2::new(0.075, 0.15) + slant * 0.02;
        assert!((c.distance(DVec3::new(0.1 + q.x, -0.2, q.y)) - 0.02).abs() < 1e-12);
        // above the top rim's corner
        assert!((c.distance(DVec3::new(0.1, -0.2 + 0.08, 0.34)) - 0.05).abs() < 1e-12);
        let (lo, hi) = c.bounds().unwrap();
        assert!(lo.abs_diff_eq(DVec3::new(0.0, -0.3, 0.0), 1e-12) && hi.abs_diff_eq(DVec3::new(0.2, -0.1, 0.3), 1e-12), "{lo} {hi}");
        check_derivatives(
            &c,
            &[
                DVec3::new(0.13, -0.18, 0.12),
                DVec3::new(0.1 + q.x, -0.2, q.y),
                DVec3::new(0.17, -0.17, 0.33),
                DVec3::new(0.22, -0.2, -0.03),
                DVec3::new(0.12, -0.21, 0.02),
                DVec3::new(0.05, -0.25, 0.2),
            ],
        );
        // a cone to its apex: the zero-length top edge is dropped
        let apex = Frustum::new(DVec3::ZERO, 0.1, 0.0, 0.2);
        assert!((apex.distance(DVec3::new(0.0, 0.0, 0.25)) - 0.05).abs() < 1e-12);
        check_derivatives(&apex, &[DVec3::new(0.01, 0.02, 0.24), DVec3::new(0.03, 0.0, 0.05)]);
    }
}
