//! A parameter that follows the age a of the material [s] (the time since the particle left the
//! nozzle, plus the mix's age when the print started), linear or bilinear in a:
//!
//! ```text
//! linear:    p(a) = p0 + r a
//! bilinear:  p(a) = p0 + r1 a                        for a <= a_t
//!            p(a) = p0 + r1 a_t + r2 (a - a_t)       for a >  a_t
//! ```
//!
//! The bilinear form is the measured early-age behaviour of printable mortars (Kruger et al.: a
//! slow early rate, then a faster one after a transition age). The law gives its value, its
//! derivative in age and its derivatives in each of its parameters, so a material's adjoint can
//! chain through it; at the kink a = a_t the derivatives are those of the early branch (the one
//! `value` takes there), the branch-taken convention of every adjoint in this crate.

use crate::material::{non_negative, MaterialError};

/// p(a): `p0 + rate a`, and beyond `late = Some((late_rate, transition_age))` the late slope.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgeLaw {
    /// Value at age 0.
    pub p0: f64,
    /// Rate [unit/s] (up to the transition age when bilinear).
    pub rate: f64,
    /// `(late_rate, transition_age)`: the rate beyond the transition age [s].
    pub late: Option<(f64, f64)>,
}

impl AgeLaw {
    /// The law's value at age `a`.
    #[inline]
    pub fn value(&self, a: f64) -> f64 {
        match self.late {
            Some((r2, at)) if a > at => self.p0 + self.rate * at + r2 * (a - at),
            _ => self.p0 + self.rate * a,
        }
    }

    /// dp/da at age `a` (the early rate at the kink).
    #[inline]
    pub fn rate_at(&self, a: f64) -> f64 {
        match self.late {
            Some((r2, at)) if a > at => r2,
            _ => self.rate,
        }
    }

    /// Derivatives of p(a) in the parameters `[p0, rate, late_rate, transition_age]` (the last two
    /// 0 for a linear law): on the late branch dp/dr1 = a_t, dp/dr2 = a - a_t, dp/da_t = r1 - r2.
    #[inline]
    pub fn partials(&self, a: f64) -> [f64; 4] {
        match self.late {
            Some((r2, at)) if a > at => [1.0, at, a - at, self.rate - r2],
            _ => [1.0, a, 0.0, 0.0],
        }
    }

    /// The ages in (a0, a1) where the slope changes: the transition age, if inside.
    fn kinks_in(&self, a0: f64, a1: f64) -> Option<f64> {
        self.late.map(|(_, at)| at).filter(|&at| at > a0 && at < a1)
    }

    /// The last slope, the one that holds for all ages beyond the kink.
    fn tail_rate(&self) -> f64 {
        self.late.map_or(self.rate, |(r2, _)| r2)
    }

    /// The smallest value at ages in [a0, a1] (`a1` may be infinite: then -inf if the law ends
    /// falling). Piecewise linear, so the extremes are at the ends or the kink.
    pub fn min_over(&self, a0: f64, a1: f64) -> f64 {
        let end = if a1.is_finite() {
            self.value(a1)
        } else if self.tail_rate() < 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
        let kink = self.kinks_in(a0, a1).map_or(f64::INFINITY, |k| self.value(k));
        self.value(a0).min(end).min(kink)
    }

    /// The largest value at ages in [a0, a1] (`a1` may be infinite: then +inf if the law ends
    /// rising).
    pub fn max_over(&self, a0: f64, a1: f64) -> f64 {
        let end = if a1.is_finite() {
            self.value(a1)
        } else if self.tail_rate() > 0.0 {
            f64::INFINITY
        } else {
            f64::NEG_INFINITY
        };
        let kink = self.kinks_in(a0, a1).map_or(f64::NEG_INFINITY, |k| self.value(k));
        self.value(a0).max(end).max(kink)
    }
}

/// The scenario keys of one law, with the `material.` prefix (param names drop it, [`bare`]).
pub(crate) struct LawKeys {
    pub value: &'static str,
    pub rate: &'static str,
    pub late_rate: &'static str,
    pub transition_age: &'static str,
}

impl LawKeys {
    /// The law's given values finite, its late rate and transition age both or neither, the
    /// transition age >= 0; each message names the key.
    pub(crate) fn check(&self, value: f64, rate: f64, late: Option<f64>, at: Option<f64>) -> Result<(), MaterialError> {
        for (key, x) in [(self.value, value), (self.rate, rate)] {
            if !x.is_finite() {
                return Err(MaterialError::out_of_range(key, "finite", x));
            }
        }
        match (late, at) {
            (Some(l), Some(t)) => {
                if !l.is_finite() {
                    return Err(MaterialError::out_of_range(self.late_rate, "finite", l));
                }
                non_negative(self.transition_age, t)
            }
            (Some(_), None) => Err(MaterialError::RequiredWhen { key: self.transition_age, when: "its late rate is given", reason: "the late rate holds beyond it" }),
            (None, Some(_)) => Err(MaterialError::RequiredWhen { key: self.late_rate, when: "its transition age is given", reason: "it is the rate beyond that age" }),
            (None, None) => Ok(()),
        }
    }
}

/// `material.x` -> `x`.
pub(crate) fn bare(key: &'static str) -> &'static str {
    &key["material.".len()..]
}

/// `age_at_start` >= 0 and `max_age`, if given, finite and beyond it; then the words for the
/// ages a law is checked over, for the messages.
pub(crate) fn check_ages(age_at_start: f64, max_age: Option<f64>) -> Result<String, MaterialError> {
    non_negative("material.age_at_start", age_at_start)?;
    let a0 = age_at_start;
    if let Some(m) = max_age {
        if !(m.is_finite() && m > a0) {
            return Err(MaterialError::out_of_range("material.max_age", format!("finite and > age_at_start = {a0}"), m));
        }
    }
    Ok(match max_age {
        Some(m) => format!("at every age from age_at_start = {a0} s to max_age = {m} s"),
        None => format!("at every age from age_at_start = {a0} s on (set max_age to bound the ages)"),
    })
}

/// The age the laws are evaluated at, and whether it is the particle's (false: held at
/// `max_age`, so the laws do not move with the age).
#[inline]
pub(crate) fn law_age(age: f64, max_age: Option<f64>) -> (f64, bool) {
    match max_age {
        Some(m) if age > m => (m, false),
        _ => (age, true),
    }
}

#[cfg(test)]
mod tests {
    use super::AgeLaw;

    const BILINEAR: AgeLaw = AgeLaw { p0: 100.0, rate: 0.5, late: Some((2.0, 60.0)) };

    #[test]
    fn bilinear_law_is_continuous_with_the_two_rates() {
        let l = BILINEAR;
        assert_eq!(l.value(0.0), 100.0);
        assert_eq!(l.value(60.0), 130.0);
        assert_eq!(l.value(70.0), 150.0);
        assert_eq!((l.rate_at(60.0), l.rate_at(60.1)), (0.5, 2.0));
        let lin = AgeLaw { late: None, ..l };
        assert_eq!(lin.value(70.0), 135.0);
    }

    /// Every partial against central differences, on both branches.
    #[test]
    fn partials_match_central_differences() {
        let f = |p: [f64; 4], a: f64| AgeLaw { p0: p[0], rate: p[1], late: Some((p[2], p[3])) }.value(a);
        let p = [100.0, 0.5, 2.0, 60.0];
        for a in [30.0, 90.0] {
            let d = BILINEAR.partials(a);
            for i in 0..4 {
                let h = 1e-3;
                let (mut up, mut dn) = (p, p);
                up[i] += h;
                dn[i] -= h;
                let fd = (f(up, a) - f(dn, a)) / (2.0 * h);
                assert!((fd - d[i]).abs() < 1e-8, "a = {a}, parameter {i}: {fd} vs {}", d[i]);
            }
            let fd = (BILINEAR.value(a + 1e-3) - BILINEAR.value(a - 1e-3)) / 2e-3;
            assert!((fd - BILINEAR.rate_at(a)).abs() < 1e-8);
        }
    }

    #[test]
    fn extremes_over_an_age_range() {
        // falling then rising: the minimum is at the kink
        let l = AgeLaw { p0: 10.0, rate: -0.1, late: Some((0.2, 50.0)) };
        assert_eq!(l.min_over(0.0, 100.0), 5.0);
        assert_eq!(l.max_over(0.0, 100.0), 15.0);
        assert_eq!(l.min_over(0.0, f64::INFINITY), 5.0);
        assert_eq!(l.max_over(0.0, f64::INFINITY), f64::INFINITY);
        let falling = AgeLaw { p0: 10.0, rate: -0.1, late: None };
        assert_eq!(falling.min_over(0.0, f64::INFINITY), f64::NEG_INFINITY);
        assert_eq!(falling.max_over(20.0, f64::INFINITY), 8.0);
    }
}
