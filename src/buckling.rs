//! Self-weight buckling of a free-standing printed wall or column: the height at which it
//! buckles under its own weight, for a stiffness that grows with the material's age.
//!
//! A column clamped at its base z = 0 and free at its top z = H, of bending stiffness B(z) = E(z)
//! I and weight q per unit height, is neutrally stable when its slope theta = w' solves
//!
//! ```text
//! (B(z) theta')' + q (H - z) theta = 0,   theta(0) = 0,   B(H) theta'(H) = 0
//! ```
//!
//! (differentiate the bending moment of the weight above z, M(z) = int_z^H q (w(s) - w(z)) ds).
//! With B constant the first eigenvalue is Greenhill's, q H^3 / B = 7.837, so
//! H* = 1.986 (B / q)^(1/3); for a wall of thickness t (I / A = t^2 / 12) and density rho,
//! H* = 1.986 (E t^2 / (12 rho g))^(1/3). A long free wall bends as a plate, E / (1 - nu^2) in
//! place of E (Suiker 2018's free wall without edge supports); a column of a short section as a
//! beam. Printed at a build rate v (layer height over layer period), the material at height z
//! of a wall H tall is (H - z) / v old (plus the mix's age at the start), so its stiffness is
//! largest at the base: [`critical_height`] finds the first H at which the wall of that age
//! profile is neutrally stable, by shooting on the equation above (RK4) and bisecting on H.

/// The stiffness and load of a printed column.
pub struct Column<'a> {
    /// Young's modulus [Pa] at a material age [s] (the age law).
    pub modulus: &'a dyn Fn(f64) -> f64,
    /// Bending factor: I / A [m^2] (t^2 / 12 for a wall of thickness t), times
    /// 1 / (1 - nu^2) for a plate.
    pub inertia_per_area: f64,
    /// Density times gravity [N/m3].
    pub weight: f64,
    /// Build rate [m/s]: the column rises this fast; infinite for a column whose material is
    /// all of one age.
    pub build_rate: f64,
    /// The mix's age when the print starts [s].
    pub age_at_start: f64,
}

/// Greenhill's constant: the first eigenvalue of q H^3 / B for a uniform cantilever.
pub const GREENHILL: f64 = 7.837347;

/// Greenhill's critical height 1.986 (B / q)^(1/3) of a uniform column [m], with B / q =
/// E (I / A) / (rho g).
pub fn greenhill_height(modulus: f64, inertia_per_area: f64, weight: f64) -> f64 {
    (GREENHILL * modulus * inertia_per_area / weight).cbrt()
}

impl Column<'_> {
    /// theta'(H) B(H) after shooting from theta(0) = 0, theta'(0) = 1 over a column H tall: its
    /// sign changes as H passes an eigenvalue.
    fn free_end_moment(&self, h: f64, steps: usize) -> f64 {
        // state (theta, m = B theta'): theta' = m / B, m' = -q (H - z) theta
        let b = |z: f64| {
            let age = self.age_at_start + if self.build_rate.is_finite() { (h - z) / self.build_rate } else { 0.0 };
            (self.modulus)(age) * self.inertia_per_area
        };
        let f = |z: f64, y: [f64; 2]| [y[1] / b(z), -self.weight * (h - z) * y[0]];
        let dz = h / steps as f64;
        let mut y = [0.0, b(0.0)];
        for k in 0..steps {
            let z = k as f64 * dz;
            let k1 = f(z, y);
            let k2 = f(z + dz / 2.0, [y[0] + dz / 2.0 * k1[0], y[1] + dz / 2.0 * k1[1]]);
            let k3 = f(z + dz / 2.0, [y[0] + dz / 2.0 * k2[0], y[1] + dz / 2.0 * k2[1]]);
            let k4 = f(z + dz, [y[0] + dz * k3[0], y[1] + dz * k3[1]]);
            for i in 0..2 {
                y[i] += dz / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        y[1]
    }
}

/// The first height at which the printed column is neutrally stable [m]: below it, the free
/// end's moment keeps the sign it has for a short column. None when no height up to `max`
/// buckles.
pub fn critical_height(c: &Column, max: f64) -> Option<f64> {
    const STEPS: usize = 400;
    let scan = 200;
    let sign0 = c.free_end_moment(max / scan as f64, STEPS).signum();
    let mut lo = max / scan as f64;
    for k in 2..=scan {
        let hi = max * k as f64 / scan as f64;
        if c.free_end_moment(hi, STEPS).signum() != sign0 {
            let (mut a, mut b) = (lo, hi);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if c.free_end_moment(m, STEPS).signum() == sign0 {
                    a = m;
                } else {
                    b = m;
                }
            }
            return Some(0.5 * (a + b));
        }
        lo = hi;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uniform_column_buckles_at_greenhills_height() {
        let e = |_: f64| 2.4e5;
        let c = Column { modulus: &e, inertia_per_area: 0.016f64.powi(2) / 12.0, weight: 2000.0 * 9.81, build_rate: f64::INFINITY, age_at_start: 0.0 };
        let h = critical_height(&c, 1.0).unwrap();
        let g = greenhill_height(2.4e5, 0.016f64.powi(2) / 12.0, 2000.0 * 9.81);
        assert!((h / g - 1.0).abs() < 1e-6, "{h} against Greenhill's {g}");
        // 1.986 (B / q)^(1/3), the textbook form
        assert!((g / (1.986 * (2.4e5 * 0.016f64.powi(2) / 12.0 / (2000.0 * 9.81)).cbrt()) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn a_column_stiffer_at_its_base_stands_taller() {
        // E grows 1 kPa/s; printed at 2 mm/s the base of a 100 mm column is 50 s older than
        // its top: taller than Greenhill's height at the top's stiffness, shorter than at the
        // base's
        let e = |a: f64| 1.0e5 + 1.0e3 * a;
        let ipa = 0.01f64.powi(2) / 12.0;
        let c = Column { modulus: &e, inertia_per_area: ipa, weight: 2000.0 * 9.81, build_rate: 0.002, age_at_start: 0.0 };
        let h = critical_height(&c, 1.0).unwrap();
        let top = greenhill_height(1.0e5, ipa, 2000.0 * 9.81);
        let base = greenhill_height(1.0e5 + 1.0e3 * h / 0.002, ipa, 2000.0 * 9.81);
        assert!(top < h && h < base, "{top} < {h} < {base}");
        // a slower print ages the base more: taller still
        let slow = Column { build_rate: 0.001, ..c };
        assert!(critical_height(&slow, 1.0).unwrap() > h);
    }

    #[test]
    fn nothing_buckles_below_the_search_bound() {
        let e = |_: f64| 1.0e9;
        let c = Column { modulus: &e, inertia_per_area: 1e-4, weight: 2e4, build_rate: f64::INFINITY, age_at_start: 0.0 };
        assert_eq!(critical_height(&c, 0.5), None);
    }
}
