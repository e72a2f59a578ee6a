//! Unions (min of the parts' distances), intersections (max) and differences (the intersection
//! with a complement, -phi) of shapes: a reservoir's walls and its gate, three rebars, a wedge of
//! two half-spaces, a mould around a cone. The result is exact near the surface, which is what
//! the contact band reads.

use super::shape::Sdf;
use glam::DVec3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Combine {
    Union,
    Intersection,
}

#[derive(Debug)]
pub struct Combination {
    how: Combine,
    parts: Vec<Box<dyn Sdf>>,
}

impl Combination {
    pub fn new(how: Combine, parts: Vec<Box<dyn Sdf>>) -> Combination {
        Combination { how, parts }
    }

    /// The part whose distance is the combination's (the first on a tie).
    fn deciding(&self, p: DVec3) -> &dyn Sdf {
        let mut best = (0, self.parts[0].distance(p));
        for (i, s) in self.parts.iter().enumerate().skip(1) {
            let d = s.distance(p);
            let better = match self.how {
                Combine::Union => d < best.1,
                Combine::Intersection => d > best.1,
            };
            if better {
                best = (i, d);
            }
        }
        &*self.parts[best.0]
    }
}

impl Sdf for Combination {
    fn distance(&self, p: DVec3) -> f64 {
        self.deciding(p).distance(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        self.deciding(p).gradient(p)
    }
    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3 {
        self.deciding(p).hessian_times(p, u)
    }
    fn union_parts(&self) -> &[Box<dyn Sdf>] {
        match self.how {
            Combine::Union => &self.parts,
            Combine::Intersection => &[],
        }
    }
    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let mut boxes = self.parts.iter().map(|s| s.bounds());
        match self.how {
            // unbounded if any part is
            Combine::Union => boxes.try_fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |acc, b| b.map(|(lo, hi)| (acc.0.min(lo), acc.1.max(hi)))),
            // bounded by any bounded part
            Combine::Intersection => {
                boxes.flatten().fold(None, |acc: Option<(DVec3, DVec3)>, (lo, hi)| Some(acc.map_or((lo, hi), |(a, b)| (a.max(lo), b.min(hi)))))
            }
        }
    }
}

/// Everything outside a shape: what a difference keeps of the space its `minus` takes.
#[derive(Debug)]
pub struct Complement(pub Box<dyn Sdf>);

impl Sdf for Complement {
    fn distance(&self, p: DVec3) -> f64 {
        -self.0.distance(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        -self.0.gradient(p)
    }
    fn hessian_times(&self, p: DVec3, u: DVec3) -> DVec3 {
        -self.0.hessian_times(p, u)
    }
    fn bounds(&self) -> Option<(DVec3, DVec3)> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solid::cuboid::Cuboid;
    use crate::solid::cylinder::Cylinder;
    use crate::solid::frustum::Frustum;
    use crate::solid::half_space::HalfSpace;
    use crate::solid::shape::tests::check_derivatives;

    #[test]
    fn a_union_of_boxes_and_a_wedge() {
        let u = Combination::new(
            Combine::Union,
            vec![Box::new(Cuboid::new(DVec3::ZERO, DVec3::splat(0.1))), Box::new(Cuboid::new(DVec3::new(0.2, 0.0, 0.0), DVec3::new(0.3, 0.1, 0.1)))],
        );
        assert!((u.distance(DVec3::new(0.16, 0.05, 0.05)) - 0.04).abs() < 1e-12);
        assert!(u.bounds().unwrap().1.x == 0.3);
        check_derivatives(&u, &[DVec3::new(0.16, 0.05, 0.05), DVec3::new(0.13, 0.04, 0.12), DVec3::new(0.25, 0.05, 0.07)]);
        // a wedge under z = x tan(30 deg), cut at x = 0.5
        let w = Combination::new(
            Combine::Intersection,
            vec![Box::new(HalfSpace::new(DVec3::ZERO, DVec3::new(-0.5, 0.0, 0.75f64.sqrt()))), Box::new(HalfSpace::new(DVec3::new(0.5, 0.0, 0.0), DVec3::X))],
        );
        assert!(w.distance(DVec3::new(0.3, 0.0, 0.1)) < 0.0);
        assert!(w.distance(DVec3::new(0.3, 0.0, 0.2)) > 0.0);
        assert!(w.bounds().is_none());
        check_derivatives(&w, &[DVec3::new(0.3, 0.0, 0.2), DVec3::new(0.6, 0.1, 0.1)]);
    }

    /// A mould: a cylinder with a cone taken out, bounded by the cylinder, its inner face the
    /// cone's.
    #[test]
    fn a_difference_is_the_first_shape_outside_the_second() {
        let mould = Combination::new(
            Combine::Intersection,
            vec![Box::new(Cylinder::new(DVec3::ZERO, DVec3::new(0.0, 0.0, 0.3), 0.2)), Box::new(Complement(Box::new(Frustum::new(DVec3::ZERO, 0.1, 0.05, 0.3))))],
        );
        assert!(mould.distance(DVec3::new(0.0, 0.0, 0.1)) > 0.05, "the cone's inside is not the mould's");
        assert!((mould.distance(DVec3::new(0.15, 0.0, 0.1)) + 0.05).abs() < 1e-12, "in the wall, 5 cm from the outer face");
        assert!((mould.distance(DVec3::new(0.0, 0.25, 0.1)) - 0.05).abs() < 1e-12);
        let inner = Frustum::new(DVec3::ZERO, 0.1, 0.05, 0.3);
        let p = DVec3::new(0.06, 0.03, 0.2);
        assert_eq!(mould.distance(p), -inner.distance(p));
        let (lo, hi) = mould.bounds().unwrap();
        assert!(lo.abs_diff_eq(DVec3::new(-0.2, -0.2, 0.0), 1e-12) && hi.abs_diff_eq(DVec3::new(0.2, 0.2, 0.3), 1e-12));
        check_derivatives(&mould, &[p, DVec3::new(0.0, 0.25, 0.1), DVec3::new(0.13, 0.02, 0.15), DVec3::new(0.05, -0.02, 0.33)]);
    }
}
