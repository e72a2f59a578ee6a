//! The nozzle indicator of paper 000 (sec. 2.5, eqs. 23-24): how strongly a grid node at
//! distance `d` from the nozzle axis is driven at the nozzle's velocity.
//!
//! ```text
//! w(d) = f(t),  t = clip((d - bc0) / (bc1 - bc0), 0, 1),  f(t) = 1 - t^2 (3 - 2t)
//! ```
//!
//! The hard indicator `d < radius` makes the nozzle position (and so the printing speed) vanish
//! from the derivative of everything downstream (000 Table 6); the smooth one keeps it. Here the
//! transition band is centred on the nozzle wall: bc0 = R - delta/2, bc1 = R + delta/2.

use crate::real::{r, Real};

/// Indicator shape: the smooth polynomial step of width `delta`, or the hard `if`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Indicator {
    Smooth { delta: Real },
    Hard,
}

/// Weight in [0, 1] of a node at (signed) distance `d` from the nozzle axis, for wall radius `radius`.
#[inline]
pub fn weight(ind: Indicator, d: Real, radius: Real) -> Real {
    weight_and_slope(ind, d, radius).0
}

/// The weight and its derivative dw/dd (zero for the hard indicator, and outside the band).
#[inline]
pub fn weight_and_slope(ind: Indicator, d: Real, radius: Real) -> (Real, Real) {
    match ind {
        Indicator::Hard => (if d < radius { r(1.0) } else { r(0.0) }, r(0.0)),
        Indicator::Smooth { delta } => {
            let bc0 = radius - r(0.5) * delta;
            let t = (d - bc0) / delta;
            if t <= r(0.0) {
                (r(1.0), r(0.0))
            } else if t >= r(1.0) {
                (r(0.0), r(0.0))
            } else {
                (r(1.0) - t * t * (r(3.0) - r(2.0) * t), -r(6.0) * t * (r(1.0) - t) / delta)
            }
        }
    }
}

/// Adjoint of [`weight`]: given dJ/dw, return (dJ/dd, dJ/dradius). The band is centred on the
/// wall, so w depends on d - radius only.
#[inline]
pub fn weight_adjoint(ind: Indicator, d: Real, radius: Real, w_bar: Real) -> (Real, Real) {
    let (_, s) = weight_and_slope(ind, d, radius);
    (w_bar * s, -w_bar * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_weight_is_one_inside_zero_outside_half_at_the_wall() {
        let ind = Indicator::Smooth { delta: r(0.01) };
        assert_eq!(weight(ind, r(0.0), r(0.1)), r(1.0));
        assert_eq!(weight(ind, r(0.2), r(0.1)), r(0.0));
        assert!((weight(ind, r(0.1), r(0.1)) - r(0.5)).abs() < r(1e-6));
        // monotone across the band
        let mut last = r(2.0);
        for k in 0..=100 {
            let w = weight(ind, r(0.094) + r(0.00012) * r(k as f64), r(0.1));
            assert!(w <= last);
            last = w;
        }
    }

    #[test]
    fn hard_weight_is_the_if() {
        assert_eq!(weight(Indicator::Hard, r(0.0999), r(0.1)), r(1.0));
        assert_eq!(weight(Indicator::Hard, r(0.1), r(0.1)), r(0.0));
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn slope_and_adjoint_match_central_differences() {
        let ind = Indicator::Smooth { delta: 0.01 };
        let radius = 0.1;
        let mut seed = 12345u64;
        for _ in 0..200 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let d = 0.09 + 0.02 * ((seed >> 11) as f64 / (1u64 << 53) as f64);
            let h = 1e-7;
            let fd_d = (weight(ind, d + h, radius) - weight(ind, d - h, radius)) / (2.0 * h);
            let fd_r = (weight(ind, d, radius + h) - weight(ind, d, radius - h)) / (2.0 * h);
            let (ad_d, ad_r) = weight_adjoint(ind, d, radius, 1.0);
            assert!((ad_d - fd_d).abs() <= 1e-6 * fd_d.abs().max(1.0), "d = {d}: {ad_d} vs {fd_d}");
            assert!((ad_r - fd_r).abs() <= 1e-6 * fd_r.abs().max(1.0), "d = {d}: {ad_r} vs {fd_r}");
        }
    }
}
