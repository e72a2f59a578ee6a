//! A profile in (distance from an axis, position along it) turned about the axis. A rectangle
//! touching the axis makes a cylinder, one away from it a tube (the nozzle body); a trapezoid
//! makes a frustum (a slump cone).

use super::shape::{box_field, sign, Sdf};
use glam::DVec3;

/// A region of the (r, z) half-plane: its signed distance with gradient and Hessian in (r, z).
pub trait Profile: Send + Sync + std::fmt::Debug {
    /// (phi, d phi / d(r, z), its Hessian) at (r, z), r >= 0.
    fn field(&self, rz: [f64; 2]) -> (f64, [f64; 2], [[f64; 2]; 2]);
    /// The largest r, and the least and greatest z.
    fn extent(&self) -> (f64, f64, f64);
}

/// An axis-aligned rectangle of (r, z): its centre and half-sizes.
#[derive(Clone, Debug)]
pub struct Rectangle {
    pub centre: [f64; 2],
    pub half: [f64; 2],
}

impl Profile for Rectangle {
    fn field(&self, [r, z]: [f64; 2]) -> (f64, [f64; 2], [[f64; 2]; 2]) {
        let s = [sign(r - self.centre[0]), sign(z - self.centre[1])];
        let q = [s[0] * (r - self.centre[0]) - self.half[0], s[1] * (z - self.centre[1]) - self.half[1]];
        let (d, g, h) = box_field(q);
        let cross = s[0] * s[1] * h[0][1];
        (d, [s[0] * g[0], s[1] * g[1]], [[h[0][0], cross], [cross, h[1][1]]])
    }

    fn extent(&self) -> (f64, f64, f64) {
        (self.centre[0] + self.half[0], self.centre[1] - self.half[1], self.centre[1] + self.half[1])
    }
}

#[derive(Clone, Debug)]
pub struct Revolved<P> {
    /// A point on the axis, from which `z` is measured.
    pub origin: DVec3,
    /// Unit axis.
    pub axis: DVec3,
    pub profile: P,
}

/// A point in the axis' frame: unit radial direction, distance r from the axis, and the
/// profile's field there.
struct Local {
    radial: DVec3,
    r: f64,
    phi: f64,
    g: [f64; 2],
    h: [[f64; 2]; 2],
}

impl<P: Profile> Revolved<P> {
    fn local(&self, p: DVec3) -> Local {
        let d = p - self.origin;
        let z = d.dot(self.axis);
        let rho = d - self.axis * z;
        let r = rho.length();
        let radial = if r > 0.0 { rho / r } else { self.axis.any_orthonormal_vector() };
        let (phi, g, h) = self.profile.field([r, z]);
        Local { radial, r, phi, g, h }
    }
}

impl<P: Profile> Sdf for Revolved<P> {
    fn distance(&self, p: DVec3) -> f64 {
        self.local(p).phi
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let l = self.local(p);
        l.radial * l.g[0] + self.axis * l.g[1]
    }

    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3 {
        let l = self.local(p);
        let (ur, uz) = (l.radial.dot(u), self.axis.dot(u));
        let mut out = l.radial * (l.h[0][0] * ur + l.h[0][1] * uz) + self.axis * (l.h[1][0] * ur + l.h[1][1] * uz);
        // the radial direction turns with the point: d(radial)/dp = (I - a a^T - r r^T) / r
        if l.r > 0.0 {
            out += (u - self.axis * uz - l.radial * ur) * (l.g[0] / l.r);
        }
        out
    }

    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let (rmax, z0, z1) = self.profile.extent();
        let (a, b) = (self.origin + self.axis * z0, self.origin + self.axis * z1);
        // a circle of radius rmax about the axis reaches rmax sqrt(1 - axis_i^2) along axis i
        let reach = (DVec3::ONE - self.axis * self.axis).max(DVec3::ZERO).powf(0.5) * rmax;
        Some((a.min(b) - reach, a.max(b) + reach))
    }
}
