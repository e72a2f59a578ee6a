//! Quadratic B-spline weights (paper 000 eq. 11-12) and their adjoint.
//!
//! For a particle at grid coordinate `xg = x / dx`, the stencil starts at node
//! `base = floor(xg - 0.5)` and covers `base + 0..3` along each axis; `fx = xg - base` lies in
//! [0.5, 1.5). The weights of the three nodes along one axis are
//! `0.5 (1.5 - fx)^2`, `0.75 - (fx - 1)^2`, `0.5 (fx - 0.5)^2`.

use crate::real::{r, Real, V3};

/// Stencil base node and the fractional offset of the particle from it.
#[inline(always)]
pub fn base_and_fx(xg: V3) -> ([i32; 3], V3) {
    let s = xg - V3::splat(r(0.5));
    let b = [floor_i32(s.x), floor_i32(s.y), floor_i32(s.z)];
    (b, xg - V3::new(b[0] as Real, b[1] as Real, b[2] as Real))
}

/// `floor(x)` as an integer. Without SSE4.1 (the baseline x86-64 target) `f64::floor` is a libm
/// call, which profiling showed taking 13 % of a step; truncation plus a correction for negative
/// non-integers is exact for |x| < 2^31, far beyond any grid coordinate.
#[inline(always)]
pub fn floor_i32(x: Real) -> i32 {
    let t = x as i32;
    t - ((t as Real) > x) as i32
}

/// 1D weights for the three stencil nodes along each axis: `w[k][d]` for node offset `k`, axis `d`.
#[inline(always)]
pub fn weights(fx: V3) -> [V3; 3] {
    let a = V3::splat(r(1.5)) - fx;
    let b = fx - V3::splat(r(1.0));
    let c = fx - V3::splat(r(0.5));
    [a * a * r(0.5), V3::splat(r(0.75)) - b * b, c * c * r(0.5)]
}

/// Adjoint of [`weights`]: given dJ/dw for each (node offset, axis), returns dJ/dfx.
#[inline]
pub fn weights_adjoint(fx: V3, w_bar: &[V3; 3]) -> V3 {
    let dw0 = fx - V3::splat(r(1.5)); // d/dfx of 0.5 (1.5 - fx)^2
    let dw1 = (fx - V3::splat(r(1.0))) * r(-2.0);
    let dw2 = fx - V3::splat(r(0.5));
    w_bar[0] * dw0 + w_bar[1] * dw1 + w_bar[2] * dw2
}

/// Partition of unity check helper: the three weights along an axis sum to one.
#[inline]
pub fn weight_sum(w: &[V3; 3]) -> V3 {
    w[0] + w[1] + w[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn floor_i32_is_floor(x in -1.0e6f64..1.0e6) {
            let x = x as Real;
            prop_assert_eq!(floor_i32(x), x.floor() as i32);
            prop_assert_eq!(floor_i32(x.floor()), x.floor() as i32);
        }
    }

    proptest! {
        #[test]
        fn weights_partition_unity_and_first_moment(x in 0.5f64..1.499, y in 0.5f64..1.499, z in 0.5f64..1.499) {
            let fx = V3::new(x as Real, y as Real, z as Real);
            let w = weights(fx);
            let s = weight_sum(&w);
            prop_assert!((s - V3::ONE).abs().max_element() < 1e-6);
            // linear completeness: sum_k w_k (k - fx) = 0
            let m = w[0] * (-fx) + w[1] * (V3::ONE - fx) + w[2] * (V3::splat(2.0) - fx);
            prop_assert!(m.abs().max_element() < 1e-6);
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn weights_adjoint_matches_central_differences() {
        let fx = V3::new(0.61, 1.02, 1.37);
        let wbar = [V3::new(0.3, -1.1, 0.7), V3::new(2.0, 0.4, -0.2), V3::new(-0.5, 0.9, 1.3)];
        let j = |f: V3| {
            let w = weights(f);
            (0..3).map(|k| w[k].dot(wbar[k])).sum::<f64>()
        };
        let g = weights_adjoint(fx, &wbar);
        let h = 1e-6;
        for d in 0..3 {
            let mut e = V3::ZERO;
            e[d] = h;
            let fd = (j(fx + e) - j(fx - e)) / (2.0 * h);
            assert!((fd - g[d]).abs() <= 1e-6 * fd.abs().max(1.0), "axis {d}: fd {fd} adjoint {}", g[d]);
        }
    }
}
