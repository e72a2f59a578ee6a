//! The floating-point type of the whole simulator: f64 by default, f32 with the `f32` feature.

#[cfg(not(feature = "f32"))]
mod imp {
    pub type Real = f64;
    pub type V3 = glam::DVec3;
    pub type M3 = glam::DMat3;
    pub const NAME: &str = "f64";
}
#[cfg(feature = "f32")]
mod imp {
    pub type Real = f32;
    pub type V3 = glam::Vec3;
    pub type M3 = glam::Mat3;
    pub const NAME: &str = "f32";
}
pub use imp::*;

/// Convert an f64 literal or parameter into the working precision.
#[inline(always)]
pub fn r(x: f64) -> Real {
    x as Real
}

/// Symmetric part of a matrix.
#[inline]
pub fn sym(a: &M3) -> M3 {
    (*a + a.transpose()) * r(0.5)
}

/// Skew-symmetric part of a matrix.
#[inline]
pub fn skew(a: &M3) -> M3 {
    (*a - a.transpose()) * r(0.5)
}

/// Deviatoric part of a matrix.
#[inline]
pub fn dev(a: &M3) -> M3 {
    let tr = a.x_axis.x + a.y_axis.y + a.z_axis.z;
    *a - M3::from_diagonal(V3::splat(tr / r(3.0)))
}

#[inline]
pub fn trace(a: &M3) -> Real {
    a.x_axis.x + a.y_axis.y + a.z_axis.z
}

/// Double contraction A : B.
#[inline]
pub fn ddot(a: &M3, b: &M3) -> Real {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}
