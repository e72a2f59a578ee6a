//! Weakly compressible bi-viscous Bingham fluid (paper 000 eqs. 3-7).
//!
//! ```text
//! sigma     = -p(J) I + tau                              (000 eq. 3; p from `eos`, eq. 4)
//! tau       = 2 mu_a D'                                  (000 eq. 7)
//! mu_a      = mu + tau_y / max(gamma_dot, gamma_c)
//! gamma_dot = sqrt(2 D':D')
//! ```
//!
//! Above the critical shear rate gamma_c this is exactly Bingham, |tau| = tau_y + mu gamma_dot
//! with |tau| = sqrt(tau:tau / 2); below it the fluid is Newtonian with the capped viscosity
//! mu + tau_y / gamma_c, which is therefore the largest viscosity an explicit step must resolve.
//! The two branches agree at gamma_c, so the stress is continuous in L. (Paper 001 eq. 9 writes
//! the lower branch with a free eta_0, which is discontinuous unless eta_0 = eta + tau_0/gamma_c.)
//!
//! Per-particle state: none.

use serde::Deserialize;

use crate::material::{non_negative, positive, Eos, Material, StabilityInfo, UpdateAdjoint};
use crate::real::{ddot, dev, r, sym, trace, Real, M3, V3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bingham {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Plastic viscosity mu after yielding [Pa s].
    pub viscosity: f64,
    /// Yield stress tau_y [Pa].
    pub yield_stress: f64,
    /// Critical shear rate gamma_c [1/s]; 000 fixes it at 0.01.
    #[serde(default = "default_critical_shear_rate")]
    pub critical_shear_rate: f64,
    #[serde(default)]
    pub eos: Eos,
}

fn default_critical_shear_rate() -> f64 {
    0.01
}

impl Bingham {
    pub fn validate(&self) -> Result<(), String> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        non_negative("material.viscosity", self.viscosity)?;
        non_negative("material.yield_stress", self.yield_stress)?;
        positive("material.critical_shear_rate", self.critical_shear_rate)?;
        self.eos.validate("material.eos")
    }
}

impl Material for Bingham {
    fn name(&self) -> &'static str {
        "bingham"
    }

    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }

    fn init_state(&self, _state: &mut [Real]) {}

    #[inline]
    fn update(&self, grad_v: &M3, j: Real, _dt: Real, _state: &mut [Real]) -> M3 {
        let d_dev = dev(&sym(grad_v));
        let gamma_dot = (r(2.0) * ddot(&d_dev, &d_dev)).sqrt();
        // max() also keeps gamma_dot = 0 away from the division.
        let mu_a =
            r(self.viscosity) + r(self.yield_stress) / gamma_dot.max(r(self.critical_shear_rate));
        let p = self.eos.pressure(r(self.bulk_modulus), j);
        d_dev * (r(2.0) * mu_a) - M3::from_diagonal(V3::splat(p))
    }

    fn param_names(&self) -> &'static [&'static str] {
        &["bulk_modulus", "viscosity", "yield_stress", "critical_shear_rate"]
    }

    /// Which of gamma_dot and gamma_c the `max` took is the branch held fixed.
    fn update_adjoint(&self, grad_v: &M3, j: Real, _: Real, _: &[Real], stress_bar: &M3, _: &[Real], out: &mut UpdateAdjoint) {
        let d_dev = dev(&sym(grad_v));
        let gamma_dot = (r(2.0) * ddot(&d_dev, &d_dev)).sqrt();
        let gc = r(self.critical_shear_rate);
        let m = gamma_dot.max(gc);
        let ty = r(self.yield_stress);
        let mu_a = r(self.viscosity) + ty / m;
        let mu_a_bar = r(2.0) * ddot(stress_bar, &d_dev);
        let m_bar = -mu_a_bar * ty / (m * m);
        let mut d_bar = *stress_bar * (r(2.0) * mu_a);
        let mut gc_bar = r(0.0);
        if gamma_dot > gc {
            d_bar += d_dev * (r(2.0) * m_bar / gamma_dot);
        } else {
            gc_bar = m_bar;
        }
        *out.grad_v_bar += sym(&dev(&d_bar));
        let (k_bar, jb) = self.eos.pressure_adjoint(r(self.bulk_modulus), j, -trace(stress_bar));
        *out.j_bar += jb;
        let p = &mut out.params_bar;
        p[0] += k_bar;
        p[1] += mu_a_bar;
        p[2] += mu_a_bar / m;
        p[3] += gc_bar;
    }

    fn stress_at_rest(&self, _state: &[Real], j: Real) -> M3 {
        // update's viscous part vanishes at grad_v = 0, leaving +0 - p off and on the diagonal
        M3::ZERO - M3::from_diagonal(V3::splat(self.eos.pressure(r(self.bulk_modulus), j)))
    }

    fn stability(&self) -> StabilityInfo {
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(0.0),
            max_viscosity: r(self.viscosity + self.yield_stress / self.critical_shear_rate),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::{simple_shear};

    fn concrete() -> Bingham {
        Bingham {
            density: 2300.0,
            bulk_modulus: 1.0e6,
            viscosity: 20.0,
            yield_stress: 300.0,
            critical_shear_rate: 0.01,
            eos: Eos::Linear,
        }
    }

    fn close(a: Real, b: Real, rel: Real) -> bool {
        (a - b).abs() <= rel * b.abs().max(1e-30)
    }

    #[test]
    fn above_critical_rate_shear_stress_is_yield_plus_viscous_with_the_sign_of_the_rate() {
        let m = concrete();
        for g in [0.5 as Real, 3.0, 40.0] {
            let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut []);
            let expect = 300.0 + 20.0 * g;
            assert!(close(s.y_axis.x, expect, 1e-6), "g={g}: {}", s.y_axis.x);
            // Reversing the shear reverses the stress, yield part included.
            let s = m.update(&simple_shear(-g), 1.0, 1e-4, &mut []);
            assert!(close(s.y_axis.x, -expect, 1e-6), "g=-{g}: {}", s.y_axis.x);
            assert_eq!(s.x_axis.x, 0.0);
        }
    }

    #[test]
    fn below_critical_rate_fluid_is_newtonian_with_capped_viscosity() {
        let m = concrete();
        for g in [0.0 as Real, 1e-4, 0.005, 0.01] {
            let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut []);
            let expect = (300.0 / 0.01 + 20.0) * g;
            assert!(
                close(s.y_axis.x, expect, 1e-6) || (g == 0.0 && s.y_axis.x == 0.0),
                "g={g}"
            );
            assert!(s.y_axis.x.is_finite());
        }
    }

    #[test]
    fn gamma_dot_is_the_norm_sqrt_2_d_dev_d_dev() {
        // Planar extension D = diag(e, -e, 0): gamma_dot = sqrt(2 * 2 e^2) = 2 e, and
        // tau_xx = 2 (mu + tau_y / (2e)) e = 2 mu e + tau_y.
        let m = concrete();
        let e = 1.5 as Real;
        let s = m.update(&M3::from_diagonal(V3::new(e, -e, 0.0)), 1.0, 1e-4, &mut []);
        assert!(close(s.x_axis.x, 2.0 * 20.0 * e + 300.0, 1e-6), "{s:?}");
        assert!(close(s.y_axis.y, -(2.0 * 20.0 * e + 300.0), 1e-6));
    }

    #[test]
    fn pressure_comes_from_the_eos() {
        let m = concrete();
        let s = m.update(&M3::ZERO, 0.99, 1e-4, &mut []);
        // K (1/J - 1) by hand for K = 1e6.
        assert!(close(-s.x_axis.x, 10101.010101010166, 1e-5));
    }

    #[test]
    fn stability_uses_the_capped_viscosity() {
        let st = concrete().stability();
        assert!(close(st.max_viscosity, 20.0 + 300.0 * 100.0, 1e-12));
        assert_eq!(st.shear_modulus, 0.0);
    }

    #[test]
    fn validation() {
        assert!(concrete().validate().is_ok());
        let mut m = concrete();
        m.critical_shear_rate = 0.0;
        assert_eq!(
            m.validate().unwrap_err(),
            "material.critical_shear_rate must be > 0, got 0"
        );
        let mut m = concrete();
        m.yield_stress = -1.0;
        assert!(m
            .validate()
            .unwrap_err()
            .starts_with("material.yield_stress"));
    }

    #[test]
    fn critical_shear_rate_defaults_to_paper_value() {
        use serde::de::value::{Error, MapDeserializer};
        let m = Bingham::deserialize(MapDeserializer::<_, Error>::new(
            [
                ("density", 2300.0),
                ("bulk_modulus", 1e6),
                ("viscosity", 20.0),
                ("yield_stress", 300.0),
            ]
            .into_iter(),
        ))
        .unwrap();
        assert_eq!(m.critical_shear_rate, 0.01);
    }

    /// Both branches of the `max`, both equations of state, at random L, J and parameters. L is
    /// scaled to a shear rate 2-20 times gamma_c (flowing) or 0.1-0.5 times it (below), so the
    /// steps of the central differences and of the Taylor test (relative 1e-3 at most) never
    /// cross the kink at gamma_dot = gamma_c.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_on_both_branches() {
        use crate::adjoint_check::Rng;
        use crate::material::test_util::check_update_adjoint;
        for (k, eos) in [Eos::Linear, Eos::Tait { gamma: 7.0 }].into_iter().enumerate() {
            let make = move |p: &[f64]| Bingham { density: 2300.0, bulk_modulus: p[0], viscosity: p[1], yield_stress: p[2], critical_shear_rate: p[3], eos };
            for point in 0..3 {
                for (b, (regime, lo, hi)) in [("flowing", 2.0, 20.0), ("below gamma_c", 0.1, 0.5)].into_iter().enumerate() {
                    let seed = 3 + 10 * k as u64 + 2 * point + b as u64;
                    let mut rng = Rng(seed);
                    let params = [rng.uniform(2e5, 2e6), rng.uniform(10.0, 100.0), rng.uniform(50.0, 500.0), rng.uniform(0.1, 1.0)];
                    let gamma_dot = rng.uniform(lo, hi) * params[3];
                    let l = M3::from_cols_array(&std::array::from_fn(|_| rng.uniform(-1.0, 1.0)));
                    let d = dev(&sym(&l));
                    let l = l * (gamma_dot / (2.0 * ddot(&d, &d)).sqrt());
                    let j = rng.uniform(0.995, 1.005);
                    let label = format!("bingham, {regime}, {eos:?}, point {point}");
                    check_update_adjoint(&label, make, &params, l, j, 1e-3, &[], gamma_dot, &[], &params, 1e-6, seed);
                }
            }
        }
    }
}
