//! Weakly compressible Newtonian fluid (paper 000 eqs. 3-6).
//!
//! ```text
//! sigma = -p(J) I + tau                        (000 eq. 3)
//! p     = Eos::pressure(K, J)                  (000 eq. 4 for `Linear`; 001 eq. 31 for `Tait`)
//! tau   = 2 mu D',  D' = sym(L) - tr(L)/3 I    (000 eqs. 5-6)
//! ```
//!
//! Per-particle state: none. The stress depends only on this step's velocity gradient and on the
//! volume ratio J the solver tracks.

use serde::Deserialize;

use crate::material::{non_negative, positive, Eos, Material, MaterialError, StabilityInfo, UpdateAdjoint};
use crate::real::{ddot, dev, r, sym, trace, Real, M3, V3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Newtonian {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Dynamic viscosity mu [Pa s].
    pub viscosity: f64,
    #[serde(default)]
    pub eos: Eos,
}

impl Newtonian {
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        // mu = 0 is a legitimate inviscid (Euler) fluid.
        non_negative("material.viscosity", self.viscosity)?;
        self.eos.validate("material.eos")
    }
}

impl Material for Newtonian {
    fn name(&self) -> &'static str {
        "newtonian"
    }

    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }

    fn init_state(&self, _state: &mut [Real]) {}

    #[inline]
    fn update(&self, grad_v: &M3, j: Real, _dt: Real, _state: &mut [Real]) -> M3 {
        let d_dev = dev(&sym(grad_v));
        let p = self.eos.pressure(r(self.bulk_modulus), j);
        d_dev * (r(2.0) * r(self.viscosity)) - M3::from_diagonal(V3::splat(p))
    }

    fn param_names(&self) -> &'static [&'static str] {
        &["bulk_modulus", "viscosity"]
    }

    fn update_adjoint(&self, grad_v: &M3, j: Real, _: Real, _: &[Real], stress_bar: &M3, _: &[Real], out: &mut UpdateAdjoint) {
        // dev and sym are self-adjoint projections
        *out.grad_v_bar += sym(&dev(stress_bar)) * (r(2.0) * r(self.viscosity));
        let (k_bar, j_bar) = self.eos.pressure_adjoint(r(self.bulk_modulus), j, -trace(stress_bar));
        *out.j_bar += j_bar;
        out.params_bar[0] += k_bar;
        out.params_bar[1] += r(2.0) * ddot(stress_bar, &dev(&sym(grad_v)));
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

    fn stability(&self) -> StabilityInfo {
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(0.0),
            max_viscosity: r(self.viscosity),
            thickening: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::{simple_shear};

    fn water() -> Newtonian {
        Newtonian {
            density: 1000.0,
            bulk_modulus: 1.0e6,
            viscosity: 1.0e-3,
            eos: Eos::Linear,
        }
    }

    #[test]
    fn simple_shear_gives_mu_gamma_dot_and_no_pressure() {
        let m = water();
        for g in [2.0 as Real, -3.0] {
            let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut []);
            let expect = r(m.viscosity) * g;
            assert!((s.y_axis.x - expect).abs() <= 1e-6 * expect.abs(), "{s:?}");
            assert!((s.x_axis.y - expect).abs() <= 1e-6 * expect.abs());
            for (i, c) in [s.x_axis.x, s.y_axis.y, s.z_axis.z, s.z_axis.x, s.z_axis.y]
                .iter()
                .enumerate()
            {
                assert_eq!(*c, 0.0, "component {i}");
            }
        }
    }

    #[test]
    fn pure_compression_stress_is_minus_eos_pressure() {
        // Viscous enough that a volumetric viscous stress (2 mu tr(L)/3 = 10 Pa) would show.
        let m = Newtonian {
            viscosity: 10.0,
            ..water()
        };
        let l = M3::from_diagonal(V3::splat(-0.5));
        let s = m.update(&l, 0.99, 1e-4, &mut []);
        // K (1/J - 1) evaluated by hand: 1e6 * (1/0.99 - 1).
        let p = 10101.010101010166 as Real;
        for c in [s.x_axis.x, s.y_axis.y, s.z_axis.z] {
            assert!((c + p).abs() <= 1e-5 * p, "{s:?}");
        }
        assert!(s.x_axis.y.abs() + s.y_axis.z.abs() + s.x_axis.z.abs() == 0.0);
        assert!((trace(&s) / 3.0 + p).abs() <= 1e-5 * p);
    }

    #[test]
    fn tait_pressure_matches_hand_value() {
        let mut m = water();
        m.eos = Eos::Tait { gamma: 7.0 };
        // K/gamma (exp(-gamma (J - 1)) - 1), evaluated by hand for K = 1e6, gamma = 7.
        for (j, p) in [
            (0.99 as Real, 10358.311607745221 as Real),
            (1.02, -18663.10922874204),
        ] {
            let s = m.update(&M3::ZERO, j, 1e-4, &mut []);
            assert!((s.x_axis.x + p).abs() <= 1e-5 * p.abs(), "j={j}: {s:?}");
        }
        let s = m.update(&M3::ZERO, 1.0, 1e-4, &mut []);
        assert_eq!(s, M3::ZERO);
    }

    #[test]
    fn linear_and_tait_agree_to_first_order() {
        let k = 1.0e6 as Real;
        let tait = Eos::Tait { gamma: 7.0 };
        // p_lin = K(-e + e^2 + ..), p_tait = K(-e + gamma e^2/2 + ..): the gap is K e^2 |1 - gamma/2|.
        let mut prev = None;
        for e in [1e-2 as Real, 5e-3, 2.5e-3] {
            let j = 1.0 + e;
            let gap = (Eos::Linear.pressure(k, j) - tait.pressure(k, j)).abs();
            assert!(gap <= 3.0 * k * e * e, "e={e}: gap {gap}");
            assert!(gap >= 2.0 * k * e * e, "e={e}: gap {gap}");
            if let Some(g) = prev {
                let ratio: Real = g / gap;
                assert!(
                    (ratio - 4.0).abs() < 0.2,
                    "gap must be second order, ratio {ratio}"
                );
            }
            prev = Some(gap);
        }
    }

    #[test]
    fn validation_names_the_key() {
        let mut m = water();
        m.viscosity = -1.0;
        assert_eq!(
            m.validate().unwrap_err().to_string(),
            "material.viscosity must be >= 0, got -1"
        );
        let mut m = water();
        m.bulk_modulus = 0.0;
        assert!(m.validate().unwrap_err().to_string().contains("material.bulk_modulus"));
        let mut m = water();
        m.eos = Eos::Tait { gamma: -7.0 };
        assert!(m.validate().unwrap_err().to_string().contains("material.eos.gamma"));
        assert!(water().validate().is_ok());
    }

    #[test]
    fn deserializes_with_linear_default_and_rejects_unknown_keys() {
        use serde::de::value::{Error, MapDeserializer};
        let ok: Newtonian = Newtonian::deserialize(MapDeserializer::<_, Error>::new(
            [
                ("density", 1000.0),
                ("bulk_modulus", 1e6),
                ("viscosity", 1e-3),
            ]
            .into_iter(),
        ))
        .unwrap();
        assert_eq!(ok.eos, Eos::Linear);
        let bad = Newtonian::deserialize(MapDeserializer::<_, Error>::new(
            [
                ("density", 1000.0),
                ("bulk_modulus", 1e6),
                ("viscosity", 1e-3),
                ("viscosty", 1.0),
            ]
            .into_iter(),
        ));
        assert!(bad.unwrap_err().to_string().contains("viscosty"));
    }

    /// Random L, J and parameters: the stress is linear in L and mu, and the EOS smooth in J, so
    /// any point will do; both EOS.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences() {
        use crate::adjoint_check::Rng;
        use crate::material::test_util::check_update_adjoint;
        for (k, eos) in [Eos::Linear, Eos::Tait { gamma: 7.0 }].into_iter().enumerate() {
            let make = move |p: &[f64]| Newtonian { density: 1000.0, bulk_modulus: p[0], viscosity: p[1], eos };
            for point in 0..3 {
                let seed = 11 + 10 * k as u64 + point;
                let mut rng = Rng(seed);
                let l = M3::from_cols_array(&std::array::from_fn(|_| rng.uniform(-3.0, 3.0)));
                let params = [rng.uniform(1e5, 1e6), rng.uniform(0.1, 10.0)];
                let j = rng.uniform(0.95, 1.05);
                let label = format!("newtonian, {eos:?}, point {point}");
                check_update_adjoint(&label, make, &params, l, j, 1e-3, &[], 1.0, &[], &params, 1e-6, seed);
            }
        }
    }

    /// Waking changes no state; the stress at rest -p(K, J) I takes the adjoint to K and J.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn wake_adjoint_matches_central_differences() {
        use crate::material::test_util::check_wake_adjoint;
        for (k, eos) in [Eos::Linear, Eos::Tait { gamma: 7.0 }].into_iter().enumerate() {
            let make = |p: &[f64]| Newtonian { bulk_modulus: p[0], viscosity: p[1], eos, ..water() };
            let params = [1.0e6, 1.0e-3];
            check_wake_adjoint("newtonian", make, &params, 1.004, 2.0, &[], &[], &params.map(|v| 0.1 * v), 1e-6, 51 + k as u64);
        }
    }
}
