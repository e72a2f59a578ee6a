//! Papanastasiou-regularised Bingham fluid with Roussel thixotropy ("PR-Bingham", paper 001
//! eqs. 10-13, update 31-35).
//!
//! ```text
//! sigma     = -p(J) I + tau                                          (001 eq. 35; p from `eos`)
//! gamma_dot = sqrt(2 D':D')                                          (001 eq. 32)
//! lambda'   = clamp(lambda + (A_thix / tau0 - alpha lambda gamma_dot) dt, 0, lambda_max)
//!                                                                    (001 eq. 33, forward Euler of eq. 12)
//! tau       = 2 [eta + tau0 (1 + lambda') (1 - exp(-m gamma_dot)) / gamma_dot] D'   (001 eq. 34)
//! ```
//!
//! The factor (1 - exp(-m g)) / g tends to m as g -> 0; it is evaluated as m * phi(m g) with
//! phi(x) = -expm1(-x) / x and a Taylor series near 0, so it is accurate to round-off and finite
//! at rest.
//!
//! Bounds on lambda (not in the paper):
//! * lambda >= 0. The exact solution of eq. 12 never leaves [0, inf) from lambda0 >= 0; forward
//!   Euler only does so when alpha gamma_dot dt > 1, i.e. when the step no longer resolves the
//!   deflocculation time 1 / (alpha gamma_dot), and a negative lambda would drop the yield stress
//!   below tau0.
//! * lambda <= lambda_max. At rest eq. 12 grows lambda linearly without bound, and with it the
//!   largest apparent viscosity eta + tau0 (1 + lambda) m that an explicit step must resolve. The
//!   time step is chosen from parameters alone, so the build-up saturates at `lambda_max`, which
//!   is required when `a_thix > 0`; with `a_thix = 0`, lambda can only decay and lambda0 bounds it.
//!
//! Per-particle state: `[lambda]` (flocculation state, dimensionless), initialised to `lambda0`.

use serde::Deserialize;

use crate::material::{non_negative, positive, Eos, Material, StabilityInfo};
use crate::real::{ddot, dev, r, sym, Real, M3, V3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PapanastasiouRoussel {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Plastic viscosity eta [Pa s].
    pub viscosity: f64,
    /// Reference yield stress tau0 [Pa] (right after mixing, lambda = 0).
    pub yield_stress: f64,
    /// Papanastasiou stress-growth parameter m [s]; 001 uses m = 10 s (Poiseuille benchmark).
    #[serde(default = "default_m")]
    pub papanastasiou_m: f64,
    /// Flocculation rate A_thix [Pa/s].
    #[serde(default)]
    pub a_thix: f64,
    /// Deflocculation coefficient alpha [-].
    #[serde(default)]
    pub alpha: f64,
    /// Initial flocculation state lambda0 [-].
    #[serde(default)]
    pub lambda0: f64,
    /// Saturation of the structural build-up [-]; required when `a_thix > 0` (see module docs).
    #[serde(default)]
    pub lambda_max: Option<f64>,
    #[serde(default)]
    pub eos: Eos,
}

fn default_m() -> f64 {
    10.0
}

impl PapanastasiouRoussel {
    pub fn validate(&self) -> Result<(), String> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        non_negative("material.viscosity", self.viscosity)?;
        non_negative("material.yield_stress", self.yield_stress)?;
        positive("material.papanastasiou_m", self.papanastasiou_m)?;
        non_negative("material.a_thix", self.a_thix)?;
        non_negative("material.alpha", self.alpha)?;
        non_negative("material.lambda0", self.lambda0)?;
        if self.a_thix > 0.0 && self.yield_stress == 0.0 {
            return Err(
                "material.yield_stress must be > 0 when material.a_thix > 0 (eq. 12 divides by it)"
                    .into(),
            );
        }
        match self.lambda_max {
            None if self.a_thix > 0.0 => Err(
                "material.lambda_max is required when material.a_thix > 0: it caps the structural \
                 build-up at rest, which would otherwise raise the apparent viscosity (and shrink \
                 the stable time step) without bound"
                    .into(),
            ),
            Some(lm) if !(lm.is_finite() && lm >= self.lambda0) => Err(format!(
                "material.lambda_max must be finite and >= material.lambda0 ({}), got {lm}",
                self.lambda0
            )),
            _ => self.eos.validate("material.eos"),
        }
    }

    /// Upper bound of lambda: the configured cap, or lambda0 when nothing can raise lambda.
    fn lambda_cap(&self) -> f64 {
        self.lambda_max.unwrap_or(self.lambda0)
    }

    /// A_thix / tau0 [1/s] (Roussel build-up, 001 eq. 12).
    #[inline]
    fn build_up_rate(&self) -> Real {
        crate::material::build_up_rate(self.a_thix, self.yield_stress)
    }
}

/// phi(x) = (1 - exp(-x)) / x for x >= 0, with phi(0) = 1.
#[inline]
pub(crate) fn one_minus_exp_neg_over_x(x: Real) -> Real {
    // Below 1e-4 the truncation error of the cubic Taylor polynomial, x^4/120, is under 1e-18.
    if x < r(1e-4) {
        r(1.0) - x * (r(0.5) - x * (r(1.0 / 6.0) - x * r(1.0 / 24.0)))
    } else {
        -(-x).exp_m1() / x
    }
}

impl Material for PapanastasiouRoussel {
    fn name(&self) -> &'static str {
        "papanastasiou_roussel"
    }

    fn state_names(&self) -> &'static [&'static str] {
        &["lambda"]
    }

    fn init_state(&self, state: &mut [Real]) {
        state[0] = r(self.lambda0);
    }

    #[inline]
    fn update(&self, grad_v: &M3, j: Real, dt: Real, state: &mut [Real]) -> M3 {
        let d_dev = dev(&sym(grad_v));
        let gamma_dot = (r(2.0) * ddot(&d_dev, &d_dev)).sqrt();

        let lambda = state[0];
        let lambda = (lambda + (self.build_up_rate() - r(self.alpha) * lambda * gamma_dot) * dt)
            .max(r(0.0))
            .min(r(self.lambda_cap()));
        state[0] = lambda;

        let m = r(self.papanastasiou_m);
        let eta_a = r(self.viscosity)
            + r(self.yield_stress)
                * (r(1.0) + lambda)
                * m
                * one_minus_exp_neg_over_x(m * gamma_dot);
        let p = self.eos.pressure(r(self.bulk_modulus), j);
        d_dev * (r(2.0) * eta_a) - M3::from_diagonal(V3::splat(p))
    }

    fn param_names(&self) -> &'static [&'static str] {
        &[]
    }

    fn update_adjoint(&self, _: &M3, _: Real, _: Real, _: &[Real], _: &M3, _: &[Real], _: &mut crate::material::UpdateAdjoint) {
        todo!("adjoint of {}", self.name())
    }

    fn stability(&self) -> StabilityInfo {
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(0.0),
            // phi <= 1, so this bounds eta_a for every lambda the update lets through.
            max_viscosity: r(self.viscosity
                + self.yield_stress * (1.0 + self.lambda_cap()) * self.papanastasiou_m),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::{simple_shear};

    fn mix() -> PapanastasiouRoussel {
        PapanastasiouRoussel {
            density: 2000.0,
            bulk_modulus: 3.3e5,
            viscosity: 30.0,
            yield_stress: 100.0,
            papanastasiou_m: 10.0,
            a_thix: 0.0,
            alpha: 0.0,
            lambda0: 0.0,
            lambda_max: None,
            eos: Eos::Tait { gamma: 7.0 },
        }
    }

    /// Round-off tolerance of the working precision.
    const EPS: Real = if cfg!(feature = "f32") { 1e-5 } else { 1e-12 };

    fn rel(a: Real, b: Real) -> Real {
        (a - b).abs() / b.abs()
    }

    #[test]
    fn without_thixotropy_shear_stress_is_regularised_bingham() {
        let mut m = mix();
        m.papanastasiou_m = 100.0;
        for g in [0.5 as Real, 1.0, 4.0] {
            let mut st = [0.0];
            let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut st);
            // Eq. 10 in simple shear: tau_xy = eta g + tau0 (1 - exp(-m g)); with m g >= 50 the
            // exponential is below 2e-22, so this is tau0 + eta g.
            let bingham = 100.0 + 30.0 * g;
            assert!(rel(s.y_axis.x, bingham) < EPS, "g={g}: {}", s.y_axis.x);
            let s = m.update(&simple_shear(-g), 1.0, 1e-4, &mut st);
            assert!(rel(s.y_axis.x, -bingham) < EPS);
        }
        // Moderate m g: the exponential matters.
        let mut m = mix();
        m.papanastasiou_m = 10.0;
        let g = 0.05 as Real;
        let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut [0.0]);
        let expect = 30.0 * g + 100.0 * (1.0 - (-10.0 * g).exp());
        assert!(rel(s.y_axis.x, expect) < 1e-6, "{} vs {expect}", s.y_axis.x);
    }

    #[test]
    fn at_vanishing_rate_apparent_viscosity_tends_to_eta_plus_tau0_m() {
        let m = mix();
        let g = 1e-9 as Real;
        let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut [0.0]);
        // (1 - e^-mg)/g = m (1 - m g / 2 + ...).
        let expect = (30.0 + 100.0 * 10.0 * (1.0 - 10.0 * g / 2.0)) * g;
        assert!(rel(s.y_axis.x, expect) < 1e-6);
        let s = m.update(&M3::ZERO, 1.0, 1e-4, &mut [0.0]);
        assert_eq!(s, M3::ZERO);
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn phi_is_accurate_on_both_sides_of_the_series_switch() {
        // Reference: the alternating series sum (-x)^k / (k+1)!, converged far below f64 precision.
        let reference = |x: f64| {
            let (mut sum, mut term) = (0.0, 1.0);
            for k in 1..30 {
                sum += term;
                term *= -x / (k as f64 + 1.0);
            }
            sum
        };
        for x in [0.0, 1e-12, 1e-6, 9.999e-5, 1e-4, 1.0001e-4, 1e-3, 0.1, 1.0] {
            let v = one_minus_exp_neg_over_x(x);
            assert!(
                (v - reference(x)).abs() <= 4.0 * f64::EPSILON,
                "x={x}: {v} vs {}",
                reference(x)
            );
        }
        assert!(rel(one_minus_exp_neg_over_x(50.0), 1.0 / 50.0) < 1e-15);
    }

    #[test]
    fn thixotropic_build_up_at_rest_is_linear() {
        let mut m = mix();
        m.a_thix = 0.5;
        m.lambda0 = 0.2;
        m.lambda_max = Some(100.0);
        let mut st = [0.0];
        m.init_state(&mut st);
        let dt = 0.1 as Real;
        let n = 1000;
        for _ in 0..n {
            m.update(&M3::ZERO, 1.0, dt, &mut st);
        }
        let t = n as Real * dt;
        let expect = 0.2 + 0.5 * t / 100.0;
        assert!(rel(st[0], expect) < 1e-4, "{} vs {expect}", st[0]);
    }

    #[test]
    fn build_up_saturates_at_lambda_max() {
        let mut m = mix();
        m.a_thix = 1.0;
        m.lambda_max = Some(0.3);
        let mut st = [0.0];
        for _ in 0..100 {
            m.update(&M3::ZERO, 1.0, 1.0, &mut st);
        }
        assert_eq!(st[0], 0.3);
        // The stability bound covers the saturated state: eta + tau0 (1 + 0.3) m.
        assert!(rel(m.stability().max_viscosity, 30.0 + 100.0 * 1.3 * 10.0) < EPS);
    }

    /// Error of the discrete lambda at time `t_end` against the closed-form solution of eq. 12
    /// under constant shear rate g: lambda = l_ss + (lambda0 - l_ss) exp(-alpha g t),
    /// l_ss = A / (tau0 alpha g).
    fn breakdown_error(dt: Real) -> Real {
        let mut m = mix();
        m.a_thix = 0.4;
        m.alpha = 0.05;
        m.lambda0 = 3.0;
        m.lambda_max = Some(3.0);
        let g = 4.0 as Real;
        let t_end = 10.0 as Real;
        let steps = (t_end / dt).round() as usize;
        let mut st = [0.0];
        m.init_state(&mut st);
        let mut stress = M3::ZERO;
        for _ in 0..steps {
            stress = m.update(&simple_shear(g), 1.0, dt, &mut st);
        }
        // Eq. 34 uses the updated lambda.
        let tau = 30.0 * g + 100.0 * (1.0 + st[0]) * (1.0 - (-10.0 * g).exp());
        assert!(rel(stress.y_axis.x, tau) < 1e-5);
        let l_ss = 0.4 / (100.0 * 0.05 * g);
        let exact = l_ss + (3.0 - l_ss) * (-0.05 * g * t_end).exp();
        st[0] - exact
    }

    #[test]
    fn breakdown_under_constant_shear_converges_to_ode_solution_at_first_order() {
        let e1 = breakdown_error(0.02);
        let e2 = breakdown_error(0.01);
        // Forward Euler: error ~ C dt, so halving dt halves it.
        assert!(e1.abs() < 5e-3, "{e1}");
        let ratio = e1 / e2;
        assert!((ratio - 2.0).abs() < 0.05, "ratio {ratio} ({e1}, {e2})");
    }

    #[test]
    fn lambda_stays_non_negative_when_the_step_overshoots_deflocculation() {
        let mut m = mix();
        m.alpha = 1.0;
        m.lambda0 = 1.0;
        let mut st = [0.0];
        m.init_state(&mut st);
        // alpha g dt = 10: forward Euler alone would give lambda = -9.
        m.update(&simple_shear(100.0), 1.0, 0.1, &mut st);
        assert_eq!(st[0], 0.0);
    }

    #[test]
    fn validation() {
        assert!(mix().validate().is_ok());
        let mut m = mix();
        m.a_thix = 0.5;
        assert!(m
            .validate()
            .unwrap_err()
            .starts_with("material.lambda_max is required"));
        m.lambda_max = Some(5.0);
        assert!(m.validate().is_ok());
        m.lambda0 = 6.0;
        assert!(m
            .validate()
            .unwrap_err()
            .starts_with("material.lambda_max must be"));
        let mut m = mix();
        m.papanastasiou_m = 0.0;
        assert_eq!(
            m.validate().unwrap_err(),
            "material.papanastasiou_m must be > 0, got 0"
        );
        let mut m = mix();
        m.alpha = -0.1;
        assert!(m.validate().unwrap_err().starts_with("material.alpha"));
    }

    #[test]
    fn defaults() {
        use serde::de::value::{Error, MapDeserializer};
        let m = PapanastasiouRoussel::deserialize(MapDeserializer::<_, Error>::new(
            [
                ("density", 2000.0),
                ("bulk_modulus", 3.3e5),
                ("viscosity", 30.0),
                ("yield_stress", 100.0),
            ]
            .into_iter(),
        ))
        .unwrap();
        assert_eq!(
            (m.papanastasiou_m, m.a_thix, m.alpha, m.lambda0),
            (10.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(m.lambda_max, None);
        assert_eq!(m.eos, Eos::Linear);
        assert!(m.validate().is_ok());
        assert_eq!(m.stability().max_viscosity, r(30.0 + 100.0 * 10.0));
    }
}
