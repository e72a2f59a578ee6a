//! A rectangle in (distance from an axis, position along it) turned about the axis: a cylinder
//! when the rectangle touches the axis, a tube otherwise. The cylinder and the nozzle body are
//! both one.

use super::shape::{box_field, sign, Sdf};
use glam::DVec3;

#[derive(Clone, Debug)]
pub struct Revolved {
    /// A point on the axis, from which `z` is measured.
    pub origin: DVec3,
    /// Unit axis.
    pub axis: DVec3,
    /// Centre of the rectangle: distance from the axis and position along it.
    pub centre: [f64; 2],
    /// Half-sizes of the rectangle: radial and axial.
    pub half: [f64; 2],
}

/// The local frame of a point: unit radial direction, distance r from the axis, position z.
struct Local {
    radial: DVec3,
    r: f64,
    z: f64,
    /// Signs of r - r_c and z - z_c.
    s: [f64; 2],
    q: [f64; 2],
}

impl Revolved {
    fn local(&self, p: DVec3) -> Local {
        let d = p - self.origin;
        let z = d.dot(self.axis);
        let rho = d - self.axis * z;
        let r = rho.length();
        let radial = if r > 0.0 { rho / r } else { self.axis.any_orthonormal_vector() };
        let s = [sign(r - self.centre[0]), sign(z - self.centre[1])];
        let q = [s[0] * (r - self.centre[0]) - self.half[0], s[1] * (z - self.centre[1]) - self.half[1]];
        Local { radial, r, z, s, q }
    }
}

impl Sdf for Revolved {
    fn distance(&self, p: DVec3) -> f64 {
        box_field(self.local(p).q).0
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let l = self.local(p);
        let (_, g, _) = box_field(l.q);
        l.radial * (l.s[0] * g[0]) + self.axis * (l.s[1] * g[1])
    }

    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3 {
        let l = self.local(p);
        let (_, g, h) = box_field(l.q);
        let (d_r, d_rr, d_rz, d_zz) = (l.s[0] * g[0], h[0][0], l.s[0] * l.s[1] * h[0][1], h[1][1]);
        let (ur, uz) = (l.radial.dot(u), self.axis.dot(u));
        let mut out = l.radial * (d_rr * ur + d_rz * uz) + self.axis * (d_rz * ur + d_zz * uz);
        // the radial direction turns with the point: d(radial)/dp = (I - a a^T - r r^T) / r
        if l.r > 0.0 {
            out += (u - self.axis * uz - l.radial * ur) * (d_r / l.r);
        }
        let _ = l.z;
        out
    }

    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let rmax = self.centre[0] + self.half[0];
        let (a, b) = (self.origin + self.axis * (self.centre[1] - self.half[1]), self.origin + self.axis * (self.centre[1] + self.half[1]));
        Some((a.min(b) - DVec3::splat(rmax), a.max(b) + DVec3::splat(rmax)))
    }
}
