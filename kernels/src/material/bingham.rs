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
//! Herschel-Bulkley with `flow_index` n (default 1, Bingham): the plastic viscosity becomes
//! k max(gamma_dot, gamma_c)^(n-1), `viscosity` playing k, so above gamma_c
//! |tau| = tau_y + k gamma_dot^n. The same cap at gamma_c regularises the power law: for n < 1 its
//! apparent viscosity k gamma_dot^(n-1) would blow up as the rate goes to 0, and below gamma_c
//! the fluid is Newtonian with mu_c = k gamma_c^(n-1) + tau_y / gamma_c, still continuous at
//! gamma_c and still the largest viscosity for n <= 1. For n > 1 the viscosity grows with the
//! rate, k gamma_dot^(n-1), without bound: [`StabilityInfo::thickening`] says so.
//!
//! Per-particle state: none.

use serde::Deserialize;

use crate::material::{default_flow_index, non_negative, positive, rate_power, Eos, Material, MaterialError, StabilityInfo, Thickening, UpdateAdjoint};
use crate::real::{ddot, dev, r, sym, trace, Real, M3, V3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bingham {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Plastic viscosity mu after yielding [Pa s]; with `flow_index` n != 1, the consistency k
    /// [Pa s^n].
    pub viscosity: f64,
    /// Yield stress tau_y [Pa].
    pub yield_stress: f64,
    /// Critical shear rate gamma_c [1/s]; 000 fixes it at 0.01.
    #[serde(default = "default_critical_shear_rate")]
    pub critical_shear_rate: f64,
    /// Flow index n [-] of the Herschel-Bulkley law; 1 (Bingham) when absent.
    #[serde(default = "default_flow_index")]
    pub flow_index: f64,
    #[serde(default)]
    pub eos: Eos,
}

fn default_critical_shear_rate() -> f64 {
    0.01
}

impl Bingham {
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        non_negative("material.viscosity", self.viscosity)?;
        non_negative("material.yield_stress", self.yield_stress)?;
        positive("material.critical_shear_rate", self.critical_shear_rate)?;
        positive("material.flow_index", self.flow_index)?;
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
        // max() also keeps gamma_dot = 0 away from the division and the power.
        let m = gamma_dot.max(r(self.critical_shear_rate));
        let mu_a = r(self.viscosity) * rate_power(m, r(self.flow_index)) + r(self.yield_stress) / m;
        let p = self.eos.pressure(r(self.bulk_modulus), j);
        d_dev * (r(2.0) * mu_a) - M3::from_diagonal(V3::splat(p))
    }

    fn param_names(&self) -> &'static [&'static str] {
        &["bulk_modulus", "viscosity", "yield_stress", "critical_shear_rate", "flow_index"]
    }

    /// Which of gamma_dot and gamma_c the `max` took is the branch held fixed. d/dn of
    /// k m^(n-1) is k m^(n-1) ln m, taken at n = 1 too (the shear-thinning effect's score).
    fn update_adjoint(&self, grad_v: &M3, j: Real, _: Real, _: &[Real], stress_bar: &M3, _: &[Real], out: &mut UpdateAdjoint) {
        let d_dev = dev(&sym(grad_v));
        let gamma_dot = (r(2.0) * ddot(&d_dev, &d_dev)).sqrt();
        let gc = r(self.critical_shear_rate);
        let m = gamma_dot.max(gc);
        let ty = r(self.yield_stress);
        let n = r(self.flow_index);
        let power = rate_power(m, n);
        let eta = r(self.viscosity) * power;
        let mu_a = eta + ty / m;
        let mu_a_bar = r(2.0) * ddot(stress_bar, &d_dev);
        let mut m_bar = -mu_a_bar * ty / (m * m);
        if n != r(1.0) {
            m_bar += mu_a_bar * (n - r(1.0)) * eta / m;
        }
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
        p[1] += mu_a_bar * power;
        p[2] += mu_a_bar / m;
        p[3] += gc_bar;
        p[4] += mu_a_bar * eta * m.ln();
    }

    fn stress_at_rest(&self, _state: &[Real], j: Real) -> M3 {
        // update's viscous part vanishes at grad_v = 0, leaving +0 - p off and on the diagonal
        M3::ZERO - M3::from_diagonal(V3::splat(self.eos.pressure(r(self.bulk_modulus), j)))
    }

    /// Nothing changes at rest: the stress at rest `-p(K, J) I` takes the adjoint to K and J.
    fn wake_adjoint(&self, _state: &[Real], _duration: Real, j: Real, stress_bar: &M3, _state_bar: &mut [Real], j_bar: &mut Real, params_bar: &mut [Real]) -> bool {
        self.eos.add_rest_stress_adjoint(r(self.bulk_modulus), j, stress_bar, &mut params_bar[0], j_bar);
        true
    }

    /// mu_a at gamma_c, the largest for n <= 1; for n > 1 the power law grows past it,
    /// mu_a(g) <= mu_a(gamma_c) + k (max(g, gamma_c)^(n-1) - gamma_c^(n-1)).
    fn stability(&self) -> StabilityInfo {
        let (k, n, gc) = (self.viscosity, self.flow_index, self.critical_shear_rate);
        let power = if n == 1.0 { 1.0 } else { gc.powf(n - 1.0) };
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(0.0),
            max_viscosity: r(k * power + self.yield_stress / gc),
            thickening: (n > 1.0).then(|| Thickening { coefficient: r(k), exponent: r(n - 1.0), floor_rate: r(gc) }),
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
            flow_index: 1.0,
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
            m.validate().unwrap_err().to_string(),
            "material.critical_shear_rate must be > 0, got 0"
        );
        let mut m = concrete();
        m.yield_stress = -1.0;
        assert!(m
            .validate()
            .unwrap_err()
            .to_string()
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

    #[test]
    fn with_a_flow_index_the_flow_curve_is_herschel_bulkley_and_the_cap_regularises_it() {
        for n in [0.4 as Real, 0.6, 1.5] {
            // Real is f32 under the `f32` feature, where the cast is needed
            #[allow(clippy::unnecessary_cast)]
            let m = Bingham { flow_index: n as f64, ..concrete() };
            assert!(m.validate().is_ok());
            for g in [0.5 as Real, 3.0, 40.0] {
                let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut []);
                let expect = 300.0 + 20.0 * g.powf(n);
                assert!(close(s.y_axis.x, expect, 1e-6), "n={n} g={g}: {} vs {expect}", s.y_axis.x);
            }
            // below gamma_c: Newtonian with mu_c = k gamma_c^(n-1) + tau_y / gamma_c, finite at rest
            let mu_c = 20.0 * (0.01 as Real).powf(n - 1.0) + 300.0 / 0.01;
            for g in [0.0 as Real, 1e-6, 0.004] {
                let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut []);
                assert!(s.y_axis.x.is_finite() && (s.y_axis.x - mu_c * g).abs() <= 1e-9 * mu_c * g.max(1e-30), "n={n} g={g}");
            }
            // the step's viscosity bound: mu_c, and for n > 1 its growth with the rate
            let st = m.stability();
            assert!(close(st.max_viscosity, mu_c, 1e-12));
            assert_eq!(st.thickening.is_some(), n > 1.0);
            for g in [1e-3, 0.5, 3.0, 40.0, 1e3] {
                let s = m.update(&simple_shear(g as Real), 1.0, 1e-4, &mut []);
                assert!((s.y_axis.x as f64 / g) <= st.viscosity_up_to(g) * (1.0 + if cfg!(feature = "f32") { 1e-5 } else { 1e-9 }), "n={n} g={g}");
            }
        }
        let bad = Bingham { flow_index: 0.0, ..concrete() };
        assert_eq!(bad.validate().unwrap_err().to_string(), "material.flow_index must be > 0, got 0");
    }

    #[test]
    fn a_flow_index_of_one_is_the_bingham_material_to_the_bit() {
        let (a, b) = (concrete(), Bingham { flow_index: 1.0, critical_shear_rate: 0.3, ..concrete() });
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            ((rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        };
        for m in [a, b] {
            for k in 0..200 {
                let l = M3::from_cols(V3::new(u(), u(), u()), V3::new(u(), u(), u()), V3::new(u(), u(), u())) * if k % 2 == 0 { 1e-3 } else { 5.0 };
                // the law before the flow index: mu + tau_y / max(gamma_dot, gamma_c)
                let d = dev(&sym(&l));
                let g = (2.0 * ddot(&d, &d)).sqrt();
                let mu_a = r(m.viscosity) + r(m.yield_stress) / g.max(r(m.critical_shear_rate));
                let before = d * (2.0 * mu_a) - M3::from_diagonal(V3::splat(m.eos.pressure(r(m.bulk_modulus), 0.999)));
                assert_eq!(m.update(&l, 0.999, 1e-4, &mut []).to_cols_array().map(|x| x.to_bits()), before.to_cols_array().map(|x| x.to_bits()));
            }
            assert_eq!(m.stability().max_viscosity, r(m.viscosity + m.yield_stress / m.critical_shear_rate));
        }
    }

    /// Both branches of the `max`, both equations of state, flow indices 1 (where d/dn is the
    /// shear-thinning effect's score), below and above 1, at random L, J and parameters. L is
    /// scaled to a shear rate 2-20 times gamma_c (flowing) or 0.1-0.5 times it (below), so the
    /// steps of the central differences and of the Taylor test (relative 1e-3 at most) never
    /// cross the kink at gamma_dot = gamma_c.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_on_both_branches() {
        use crate::adjoint_check::Rng;
        use crate::material::test_util::check_update_adjoint;
        for (k, eos) in [Eos::Linear, Eos::Tait { gamma: 7.0 }].into_iter().enumerate() {
            let make = move |p: &[f64]| Bingham { density: 2300.0, bulk_modulus: p[0], viscosity: p[1], yield_stress: p[2], critical_shear_rate: p[3], flow_index: p[4], eos };
            for point in 0..3 {
                for (b, (regime, lo, hi)) in [("flowing", 2.0, 20.0), ("below gamma_c", 0.1, 0.5)].into_iter().enumerate() {
                    for (i, n) in [1.0, 0.45, 1.4].into_iter().enumerate() {
                        let seed = 3 + 10 * k as u64 + 2 * point + b as u64 + 100 * i as u64;
                        let mut rng = Rng(seed);
                        let params = [rng.uniform(2e5, 2e6), rng.uniform(10.0, 100.0), rng.uniform(50.0, 500.0), rng.uniform(0.1, 1.0), n];
                        let gamma_dot = rng.uniform(lo, hi) * params[3];
                        let l = M3::from_cols_array(&std::array::from_fn(|_| rng.uniform(-1.0, 1.0)));
                        let d = dev(&sym(&l));
                        let l = l * (gamma_dot / (2.0 * ddot(&d, &d)).sqrt());
                        let j = rng.uniform(0.995, 1.005);
                        let label = format!("bingham, {regime}, n = {n}, {eos:?}, point {point}");
                        check_update_adjoint(&label, make, &params, l, j, 1e-3, &[], gamma_dot, &[], &params, 1e-6, seed);
                    }
                }
            }
        }
    }

    /// Waking changes no state; the stress at rest -p(K, J) I takes the adjoint to K and J.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn wake_adjoint_matches_central_differences() {
        use crate::material::test_util::check_wake_adjoint;
        for (k, eos) in [Eos::Linear, Eos::Tait { gamma: 7.0 }].into_iter().enumerate() {
            let make = |p: &[f64]| Bingham { bulk_modulus: p[0], viscosity: p[1], yield_stress: p[2], critical_shear_rate: p[3], flow_index: p[4], eos, ..concrete() };
            let params = [1.0e6, 20.0, 300.0, 0.01, 1.0];
            let scale = params.map(|v| 0.1 * v);
            check_wake_adjoint("bingham", make, &params, 0.995, 2.0, &[], &[], &scale, 1e-6, 41 + k as u64);
        }
    }
}
