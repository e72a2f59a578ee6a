//! The signed-distance interface every solid shape implements, the `shape = ...` table that
//! builds one, and the distance field of a box in N local coordinates that the box, the
//! cylinder and the nozzle body share.
//!
//! A shape is a signed distance `phi(p)`: negative inside, zero on the surface, the distance to
//! it outside (at least near the surface: a union or intersection is exact only there, which is
//! all the contact band reads). Its gradient is the outward normal; the Hessian times a vector is
//! what the adjoint needs when the normal moves with the solid.

use super::cuboid::Cuboid;
use super::cylinder::Cylinder;
use super::frustum::Frustum;
use super::half_space::HalfSpace;
use super::nozzle_body::NozzleBody;
use super::union::{Combination, Combine, Complement};
use glam::DVec3;
use serde::Deserialize;
use crate::invalid::Invalid;

/// A signed distance function with its derivatives, in the solid's own frame.
pub trait Sdf: Send + Sync + std::fmt::Debug {
    fn distance(&self, p: DVec3) -> f64;
    /// d phi / d p (unit length wherever phi is differentiable).
    fn gradient(&self, p: DVec3) -> DVec3;
    /// The Hessian of phi at `p` times `u`.
    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3;
    /// Bounding box of the solid (None: unbounded, as a half-space).
    fn bounds(&self) -> Option<(DVec3, DVec3)>;
    /// The parts of a union, each a body of its own on the grid (empty for any other shape).
    fn union_parts(&self) -> &[Box<dyn Sdf>] {
        &[]
    }
}

/// The `shape` of a `[[solid]]` table (or of a part of a union).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeConfig {
    /// Axis-aligned box.
    Box { min: [f64; 3], max: [f64; 3] },
    /// Cylinder of any axis: the centres of its two end faces and its radius.
    Cylinder { from: [f64; 3], to: [f64; 3], radius: f64 },
    /// A vertical frustum of a cone (z up) standing on `base_center`, as a `[[body]]` frustum: a
    /// slump cone.
    Frustum { base_center: [f64; 3], bottom_radius: f64, top_radius: f64, height: f64 },
    /// Everything on the side of the plane through `point` that `normal` points away from
    /// (`normal` points out of the solid, into the material); an inclined wall or floor.
    HalfSpace { point: [f64; 3], normal: [f64; 3] },
    /// A region in any of the parts.
    Union { parts: Vec<ShapeConfig> },
    /// A region in all of the parts (a wedge: two half-spaces).
    Intersection { parts: Vec<ShapeConfig> },
    /// The region of `of` outside `minus` (a mould: a cylinder less the cone it holds).
    Difference { of: Box<ShapeConfig>, minus: Box<ShapeConfig> },
    /// The nozzle's body, moving with the outlet: a tube of the outlet's inner diameter and this
    /// outer diameter whose flat end is the outlet plane, `height` tall (default: the driven
    /// tube's height). Only with `motion = "nozzle"` (the default for this shape).
    Nozzle { outer_diameter: f64, #[serde(default)] height: Option<f64> },
}

/// What building a shape needs from the rest of the scenario.
pub struct ShapeContext {
    /// The nozzle's inner (outlet) diameter and driven tube height, when the scenario prints
    /// through a circular nozzle.
    pub nozzle: Option<(f64, f64)>,
}

impl ShapeConfig {
    /// Check the values, naming the key under `key` (e.g. `solid[2]`).
    pub fn validate(&self, key: &str) -> Result<(), Invalid> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match self {
            ShapeConfig::Box { min, max } => {
                if !finite(min) || !finite(max) {
                    return Err(Invalid(format!("{key}.min and {key}.max must be finite")));
                }
                if (0..3).any(|a| !(max[a] > min[a])) {
                    return Err(Invalid(format!("{key}: box max must exceed min on every axis, got min {min:?}, max {max:?}")));
                }
            }
            ShapeConfig::Cylinder { from, to, radius } => {
                if !finite(from) || !finite(to) {
                    return Err(Invalid(format!("{key}.from and {key}.to must be finite")));
                }
                positive(key, "radius", *radius)?;
                if DVec3::from(*from).distance(DVec3::from(*to)) <= 0.0 {
                    return Err(Invalid(format!("{key}: cylinder from and to must differ (they set the axis)")));
                }
            }
            ShapeConfig::Frustum { base_center, bottom_radius, top_radius, height } => {
                if !finite(base_center) {
                    return Err(Invalid(format!("{key}.base_center must be finite")));
                }
                positive(key, "bottom_radius", *bottom_radius)?;
                if !(*top_radius >= 0.0 && top_radius.is_finite()) {
                    return Err(Invalid(format!("{key}.top_radius must be >= 0, got {top_radius}")));
                }
                positive(key, "height", *height)?;
            }
            ShapeConfig::HalfSpace { point, normal } => {
                if !finite(point) || !finite(normal) {
                    return Err(Invalid(format!("{key}.point and {key}.normal must be finite")));
                }
                if DVec3::from(*normal).length() <= 0.0 {
                    return Err(Invalid(format!("{key}.normal must be a non-zero vector")));
                }
            }
            ShapeConfig::Union { parts } | ShapeConfig::Intersection { parts } => {
                if parts.is_empty() {
                    return Err(Invalid(format!("{key}.parts is empty; give at least one shape")));
                }
                for (i, p) in parts.iter().enumerate() {
                    p.validate_part(&format!("{key}.parts[{i}]"), "a union or intersection")?;
                }
            }
            ShapeConfig::Difference { of, minus } => {
                of.validate_part(&format!("{key}.of"), "a difference")?;
                minus.validate_part(&format!("{key}.minus"), "a difference")?;
            }
            ShapeConfig::Nozzle { outer_diameter, height } => {
                positive(key, "outer_diameter", *outer_diameter)?;
                if let Some(h) = height {
                    positive(key, "height", *h)?;
                }
            }
        }
        Ok(())
    }

    /// Check a part of a combination (`whole`, e.g. "a difference"): any shape but the nozzle
    /// body, which moves with the nozzle.
    fn validate_part(&self, key: &str, whole: &str) -> Result<(), Invalid> {
        if matches!(self, ShapeConfig::Nozzle { .. }) {
            return Err(Invalid(format!("{key}: the nozzle body cannot be part of {whole}")));
        }
        self.validate(key)
    }

    /// The shape's distance function.
    pub fn build(&self, key: &str, cx: &ShapeContext) -> Result<Box<dyn Sdf>, Invalid> {
        Ok(match self {
            ShapeConfig::Box { min, max } => Box::new(Cuboid::new(DVec3::from(*min), DVec3::from(*max))),
            ShapeConfig::Cylinder { from, to, radius } => Box::new(Cylinder::new(DVec3::from(*from), DVec3::from(*to), *radius)),
            ShapeConfig::Frustum { base_center, bottom_radius, top_radius, height } => Box::new(Frustum::new(DVec3::from(*base_center), *bottom_radius, *top_radius, *height)),
            ShapeConfig::HalfSpace { point, normal } => Box::new(HalfSpace::new(DVec3::from(*point), DVec3::from(*normal))),
            ShapeConfig::Difference { of, minus } => {
                let (of, minus) = (of.build(&format!("{key}.of"), cx)?, minus.build(&format!("{key}.minus"), cx)?);
                Box::new(Combination::new(Combine::Intersection, vec![of, Box::new(Complement(minus))]))
            }
            ShapeConfig::Union { parts } | ShapeConfig::Intersection { parts } => {
                let how = if matches!(self, ShapeConfig::Union { .. }) { Combine::Union } else { Combine::Intersection };
                let built = parts.iter().enumerate().map(|(i, p)| p.build(&format!("{key}.parts[{i}]"), cx)).collect::<Result<Vec<_>, _>>()?;
                Box::new(Combination::new(how, built))
            }
            ShapeConfig::Nozzle { outer_diameter, height } => {
                let Some((inner, tube)) = cx.nozzle else {
                    return Err(Invalid(format!("{key}: shape = \"nozzle\" needs a [print] table with a circular nozzle")));
                };
                if *outer_diameter <= inner {
                    return Err(Invalid(format!("{key}.outer_diameter ({outer_diameter} m) must exceed the nozzle's diameter ({inner} m)")));
                }
                Box::new(NozzleBody::new(inner / 2.0, outer_diameter / 2.0, height.unwrap_or(tube)))
            }
        })
    }
}

/// `key.name` must be a finite length > 0.
fn positive(key: &str, name: &str, v: f64) -> Result<(), Invalid> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(Invalid(format!("{key}.{name} must be > 0, got {v}")))
    }
}

/// A box's distance field in local coordinates `q_i = |x_i| - half_i` (the excess over the
/// half-sizes): the distance, its gradient in q and its Hessian in q. Outside (some q_i > 0) it
/// is the Euclidean length of the positive parts; inside, the largest (least negative) q_i.
pub fn box_field<const N: usize>(q: [f64; N]) -> (f64, [f64; N], [[f64; N]; N]) {
    let mut grad = [0.0; N];
    let mut hess = [[0.0; N]; N];
    let outside: f64 = q.iter().map(|&x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
    if outside > 0.0 {
        for i in 0..N {
            grad[i] = q[i].max(0.0) / outside;
        }
        for i in (0..N).filter(|&i| q[i] > 0.0) {
            for j in (0..N).filter(|&j| q[j] > 0.0) {
                hess[i][j] = (if i == j { 1.0 } else { 0.0 } - grad[i] * grad[j]) / outside;
            }
        }
        return (outside, grad, hess);
    }
    let k = (0..N).fold(0, |k, i| if q[i] > q[k] { i } else { k });
    grad[k] = 1.0;
    (q[k], grad, hess)
}

/// The sign used for |x| in the box field's local coordinates (+1 at 0, a choice on the kink).
#[inline]
pub fn sign(x: f64) -> f64 {
    if x < 0.0 {
        -1.0
    } else {
        1.0
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Central differences of the distance against the gradient and of the gradient against the
    /// Hessian product, at points `pts` (chosen away from the kinks by far more than the step).
    pub(crate) fn check_derivatives(s: &dyn Sdf, pts: &[DVec3]) {
        let h = 1e-6;
        let u = DVec3::new(0.3, -0.7, 0.5);
        for &p in pts {
            let g = s.gradient(p);
            let hu = s.hessian_times(p, u);
            for a in 0..3 {
                let mut e = DVec3::ZERO;
                e[a] = h;
                let fd = (s.distance(p + e) - s.distance(p - e)) / (2.0 * h);
                assert!((fd - g[a]).abs() < 1e-6, "{s:?} at {p}: d phi/dx{a} {} against {fd}", g[a]);
            }
            let fd = (s.gradient(p + u * h) - s.gradient(p - u * h)) / (2.0 * h);
            assert!((fd - hu).length() < 1e-5 * (1.0 + fd.length()), "{s:?} at {p}: H u {hu} against {fd}");
            assert!((g.length() - 1.0).abs() < 1e-9, "{s:?} at {p}: |grad| = {}", g.length());
        }
    }

    #[test]
    fn the_box_field_is_the_distance_outside_and_the_largest_excess_inside() {
        assert_eq!(box_field([-0.2, -0.1]).0, -0.1);
        assert!((box_field([0.3, 0.4]).0 - 0.5).abs() < 1e-15);
        assert_eq!(box_field([0.3, -0.4]).0, 0.3);
    }
}
