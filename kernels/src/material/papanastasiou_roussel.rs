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
//! Herschel-Bulkley with `flow_index` n (default 1): the plastic viscosity eta becomes
//! k q^(1-n) with q = m phi(m gamma_dot) = (1 - exp(-m gamma_dot)) / gamma_dot, `viscosity`
//! playing k. The Papanastasiou factor q that regularises the yield term regularises the power
//! law too: q -> 1 / gamma_dot once m gamma_dot >> 1, so tau -> tau0 (1 + lambda) +
//! k gamma_dot^n there, while at rest q -> m and the apparent viscosity k q^(1-n) tends to
//! k m^(1-n) instead of blowing up as k gamma_dot^(n-1) does for n < 1. As phi <= 1,
//! k m^(1-n) is also its bound for n <= 1; for n > 1 it grows as k gamma_dot^(n-1) without
//! bound ([`StabilityInfo::thickening`]; 1/q <= gamma_dot + 1/m <= 2 max(gamma_dot, 1/m)).
//!
//! Per-particle state: `[lambda]` (flocculation state, dimensionless), initialised to `lambda0`.

use serde::Deserialize;

use crate::material::{default_flow_index, non_negative, positive, rate_power, Eos, Material, MaterialError, StabilityInfo, Thickening, UpdateAdjoint};
use crate::real::{ddot, dev, r, sym, trace, Real, M3, V3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PapanastasiouRoussel {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Plastic viscosity eta [Pa s]; with `flow_index` n != 1, the consistency k [Pa s^n].
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
    /// Flow index n [-] of the Herschel-Bulkley law; 1 (Bingham) when absent.
    #[serde(default = "default_flow_index")]
    pub flow_index: f64,
    #[serde(default)]
    pub eos: Eos,
}

fn default_m() -> f64 {
    10.0
}

impl PapanastasiouRoussel {
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        non_negative("material.viscosity", self.viscosity)?;
        non_negative("material.yield_stress", self.yield_stress)?;
        positive("material.papanastasiou_m", self.papanastasiou_m)?;
        non_negative("material.a_thix", self.a_thix)?;
        non_negative("material.alpha", self.alpha)?;
        non_negative("material.lambda0", self.lambda0)?;
        positive("material.flow_index", self.flow_index)?;
        if self.a_thix > 0.0 && self.yield_stress == 0.0 {
            return Err(MaterialError::OutOfRangeWhen {
                key: "material.yield_stress",
                range: "> 0",
                when: "material.a_thix > 0",
                reason: "eq. 12 divides by it",
            });
        }
        match self.lambda_max {
            None if self.a_thix > 0.0 => Err(MaterialError::RequiredWhen {
                key: "material.lambda_max",
                when: "material.a_thix > 0",
                reason: "it caps the structural build-up at rest, which would otherwise raise the \
                      apparent viscosity (and shrink the stable time step) without bound",
            }),
            Some(lm) if !(lm.is_finite() && lm >= self.lambda0) => Err(MaterialError::out_of_range(
                "material.lambda_max",
                format!("finite and >= material.lambda0 ({})", self.lambda0),
                lm,
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

    /// Adjoints `(a_thix_bar, yield_stress_bar)` of [`Self::build_up_rate`] for `rate_bar`. The
    /// forward returns 0 at A_thix = 0 only to avoid 0/0 when tau0 = 0; with tau0 > 0 the rate is
    /// A_thix / tau0 on the whole admissible side A_thix >= 0, so the quotient's derivative is
    /// taken there too (otherwise a gradient could never move A_thix away from 0).
    #[inline]
    fn build_up_rate_adjoint(&self, rate_bar: Real) -> (Real, Real) {
        if self.yield_stress > 0.0 {
            let tau0 = r(self.yield_stress);
            (rate_bar / tau0, -rate_bar * r(self.a_thix) / (tau0 * tau0))
        } else {
            (r(0.0), r(0.0))
        }
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

/// phi'(x) = (exp(-x) - phi(x)) / x, which tends to -1/2 as x -> 0.
#[inline]
fn one_minus_exp_neg_over_x_derivative(x: Real) -> Real {
    // The closed form loses about 4 u / x to cancellation (u the unit round-off; 9e-15 relative
    // at the switch); the series sum_k (-1)^k k x^(k-1) / (k+1)!, cut after x^7, is off by
    // x^8 / 403200 < 1e-16 there.
    if x < r(0.05) {
        r(-1.0 / 2.0)
            + x * (r(1.0 / 3.0)
                + x * (r(-1.0 / 8.0)
                    + x * (r(1.0 / 30.0)
                        + x * (r(-1.0 / 144.0)
                            + x * (r(1.0 / 840.0)
                                + x * (r(-1.0 / 5760.0) + x * r(1.0 / 45360.0)))))))
    } else {
        ((-x).exp() - one_minus_exp_neg_over_x(x)) / x
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
        let phi = one_minus_exp_neg_over_x(m * gamma_dot);
        // k q^(1-n) = k / q^(n-1), q = m phi
        let eta = r(self.viscosity) / rate_power(m * phi, r(self.flow_index));
        let eta_a = eta + r(self.yield_stress) * (r(1.0) + lambda) * m * phi;
        let p = self.eos.pressure(r(self.bulk_modulus), j);
        d_dev * (r(2.0) * eta_a) - M3::from_diagonal(V3::splat(p))
    }

    fn param_names(&self) -> &'static [&'static str] {
        // The last entry is whichever value caps lambda (see `lambda_cap`); without `lambda_max`,
        // update reads lambda0 only as that cap.
        if self.lambda_max.is_some() {
            &[
                "bulk_modulus",
                "viscosity",
                "yield_stress",
                "papanastasiou_m",
                "a_thix",
                "alpha",
                "lambda_max",
                "flow_index",
            ]
        } else {
            &[
                "bulk_modulus",
                "viscosity",
                "yield_stress",
                "papanastasiou_m",
                "a_thix",
                "alpha",
                "lambda0",
                "flow_index",
            ]
        }
    }

    /// Adjoint of [`PapanastasiouRoussel::update`], holding constant:
    /// * the clamp of lambda the forward applied (at 0, at the cap, or none). A trial value exactly
    ///   on a bound counts as unclamped: the one-sided derivative from inside [0, cap], the only
    ///   side states reach (ties are common without thixotropy, where lambda stays at 0 or at
    ///   lambda0 for good);
    /// * at rest, gamma_dot = sqrt(2 D':D') is a cone, and its subgradient 0 is taken: the stress
    ///   is differentiable there, only the decay term of lambda is not;
    /// * A_thix / tau0 is differentiated as that quotient also at A_thix = 0 (see
    ///   `build_up_rate_adjoint`);
    /// * d/dn of k q^(1-n) is -k q^(1-n) ln q, taken at n = 1 too (the shear-thinning effect's
    ///   score).
    fn update_adjoint(
        &self,
        grad_v: &M3,
        j: Real,
        dt: Real,
        state_in: &[Real],
        stress_bar: &M3,
        state_out_bar: &[Real],
        out: &mut UpdateAdjoint,
    ) {
        let d_dev = dev(&sym(grad_v));
        let gamma_dot = (r(2.0) * ddot(&d_dev, &d_dev)).sqrt();

        let alpha = r(self.alpha);
        let lambda_in = state_in[0];
        let trial = lambda_in + (self.build_up_rate() - alpha * lambda_in * gamma_dot) * dt;
        let cap = r(self.lambda_cap());
        // The forward's `.max(0).min(cap)`, branch by branch.
        let at_cap = trial.max(r(0.0)) > cap;
        let at_zero = !at_cap && trial < r(0.0);
        let lambda = if at_cap {
            cap
        } else if at_zero {
            r(0.0)
        } else {
            trial
        };

        let m = r(self.papanastasiou_m);
        let tau0 = r(self.yield_stress);
        let x = m * gamma_dot;
        let phi = one_minus_exp_neg_over_x(x);
        let structure = r(1.0) + lambda;
        let n = r(self.flow_index);
        let q = m * phi;
        let power = rate_power(q, n);
        let eta = r(self.viscosity) / power;
        let eta_a = eta + tau0 * structure * m * phi;

        // stress = 2 eta_a D' - p I
        let eta_a_bar = r(2.0) * ddot(&d_dev, stress_bar);
        let mut d_dev_bar = *stress_bar * (r(2.0) * eta_a);
        let p_bar = -trace(stress_bar);
        let (bulk_bar, j_bar) = self.eos.pressure_adjoint(r(self.bulk_modulus), j, p_bar);

        let lambda_bar = state_out_bar[0] + eta_a_bar * tau0 * m * phi;
        let mut tau0_bar = eta_a_bar * structure * m * phi;
        // eta_a = k q^(1-n) + tau0 (1 + lambda) q: its derivative in q
        let mut q_bar = eta_a_bar * tau0 * structure;
        if n != r(1.0) {
            q_bar += eta_a_bar * (r(1.0) - n) * eta / q;
        }
        // q = m phi(m g): d/dm [(1 - exp(-m g)) / g] = exp(-m g), free of cancellation.
        let m_bar = q_bar * (-x).exp();
        let mut gamma_dot_bar = q_bar * m * m * one_minus_exp_neg_over_x_derivative(x);

        let (trial_bar, cap_bar) = if at_cap {
            (r(0.0), lambda_bar)
        } else if at_zero {
            (r(0.0), r(0.0))
        } else {
            (lambda_bar, r(0.0))
        };
        out.state_bar[0] += trial_bar * (r(1.0) - alpha * gamma_dot * dt);
        let alpha_bar = -trial_bar * lambda_in * gamma_dot * dt;
        gamma_dot_bar -= trial_bar * alpha * lambda_in * dt;
        let (a_thix_bar, tau0_rate_bar) = self.build_up_rate_adjoint(trial_bar * dt);
        tau0_bar += tau0_rate_bar;

        if gamma_dot > r(0.0) {
            d_dev_bar += d_dev * (r(2.0) * gamma_dot_bar / gamma_dot);
        }
        // dev and sym are self-adjoint projections under A:B.
        *out.grad_v_bar += dev(&sym(&d_dev_bar));
        *out.j_bar += j_bar;

        let p = &mut out.params_bar;
        p[0] += bulk_bar;
        p[1] += eta_a_bar / power;
        p[2] += tau0_bar;
        p[3] += m_bar;
        p[4] += a_thix_bar;
        p[5] += alpha_bar;
        p[6] += cap_bar;
        p[7] -= eta_a_bar * eta * q.ln();
    }

    /// lambda starts at lambda0; when lambda0 is a listed parameter (no `lambda_max`), the
    /// initial state's adjoint is its adjoint too.
    fn init_state_adjoint(&self, state_bar: &[Real], params_bar: &mut [Real]) {
        if self.lambda_max.is_none() {
            params_bar[6] += state_bar[0];
        }
    }

    fn stress_at_rest(&self, _state: &[Real], j: Real) -> M3 {
        // update's viscous part vanishes at grad_v = 0, leaving +0 - p off and on the diagonal
        M3::ZERO - M3::from_diagonal(V3::splat(self.eos.pressure(r(self.bulk_modulus), j)))
    }

    fn rest_for(&self, state: &mut [Real], duration: Real) {
        // gamma_dot = 0: linear build-up up to the cap, as the clamp of `update` does step by step
        state[0] = (state[0] + self.build_up_rate() * duration).max(r(0.0)).min(r(self.lambda_cap()));
    }

    /// `rest_for` then the stress at rest `-p(K, J) I`. The build-up is linear up to the cap, so
    /// lambda woken at the cap after a build-up was clamped (its adjoint goes to the cap's
    /// parameter); otherwise it came through unclamped (its adjoint passes, the rest's goes to
    /// A_thix / tau0), without build-up too, as `update_adjoint` counts a trial on a bound.
    fn wake_adjoint(&self, state: &[Real], duration: Real, j: Real, stress_bar: &M3, state_bar: &mut [Real], j_bar: &mut Real, params_bar: &mut [Real]) -> bool {
        self.eos.add_rest_stress_adjoint(r(self.bulk_modulus), j, stress_bar, &mut params_bar[0], j_bar);
        if self.build_up_rate() * duration > r(0.0) && state[0] >= r(self.lambda_cap()) {
            // `param_names`' entry 6 is whichever value caps lambda
            params_bar[6] += std::mem::replace(&mut state_bar[0], r(0.0));
        } else {
            let (a_thix_bar, tau0_bar) = self.build_up_rate_adjoint(state_bar[0] * duration);
            params_bar[4] += a_thix_bar;
            params_bar[2] += tau0_bar;
        }
        true
    }

    /// phi <= 1, so with n <= 1 this bounds eta_a for every lambda the update lets through; for
    /// n > 1 the power law's part is k q^(1-n) <= 2^(n-1) k max(g, 1/m)^(n-1) (module docs).
    fn stability(&self) -> StabilityInfo {
        let (k, n, m) = (self.viscosity, self.flow_index, self.papanastasiou_m);
        let k_bound = if n > 1.0 { k * 2f64.powf(n - 1.0) } else { k };
        let power = if n == 1.0 { 1.0 } else { m.powf(1.0 - n) };
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(0.0),
            max_viscosity: r(k_bound * power + self.yield_stress * (1.0 + self.lambda_cap()) * m),
            thickening: (n > 1.0).then(|| Thickening { coefficient: r(k_bound), exponent: r(n - 1.0), floor_rate: r(1.0 / m) }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::simple_shear;

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
            flow_index: 1.0,
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
        // a sleeping particle's build-up, in one call
        let mut slept = [0.0];
        m.init_state(&mut slept);
        m.rest_for(&mut slept, t);
        assert!(rel(slept[0], st[0]) < 1e-5, "{} vs {}", slept[0], st[0]);
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
        let mut slept = [0.0];
        m.rest_for(&mut slept, 100.0);
        assert_eq!(slept[0], 0.3);
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
        assert_eq!(
            m.validate().unwrap_err().to_string(),
            "material.lambda_max is required when material.a_thix > 0: it caps the structural build-up at rest, \
             which would otherwise raise the apparent viscosity (and shrink the stable time step) without bound"
        );
        m.lambda_max = Some(5.0);
        assert!(m.validate().is_ok());
        m.lambda0 = 6.0;
        assert!(m
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("material.lambda_max must be"));
        let mut m = mix();
        m.papanastasiou_m = 0.0;
        assert_eq!(
            m.validate().unwrap_err().to_string(),
            "material.papanastasiou_m must be > 0, got 0"
        );
        let mut m = mix();
        m.alpha = -0.1;
        assert!(m.validate().unwrap_err().to_string().starts_with("material.alpha"));
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

    /// One point of the adjoint check. Each test's points keep the trial lambda at least 1% of
    /// lambda away from the bound it is on the other side of, and m gamma_dot away from the
    /// switches of phi and phi' (1e-4, 0.05), further than the largest perturbation (1e-3
    /// relative), so no difference straddles a branch.
    #[cfg(not(feature = "f32"))]
    #[derive(Clone, Copy)]
    struct Point {
        /// In `param_names` order: K, eta, tau0, m, A_thix, alpha, lambda_max | lambda0, n.
        params: [f64; 8],
        /// Whether the last parameter is `lambda_max`; else it is lambda0, then the cap.
        by_lambda_max: bool,
        eos: Eos,
        gamma_dot: f64,
        j: f64,
        dt: f64,
        lambda: f64,
        /// Parameters (indices in `params`) held fixed: their influence at this point is below
        /// what differences of f64 outputs resolve to 1e-6, and other points check them.
        unresolved: &'static [usize],
    }

    #[cfg(not(feature = "f32"))]
    const ALPHA: usize = 5;
    #[cfg(not(feature = "f32"))]
    const M: usize = 3;

    /// (gamma_dot, J, unresolved) from the series branches of phi and phi' (m g = 5e-5, 0.01) to
    /// exp(-m g) ~ 2e-22 (m g = 50), for m = 10 (see `adjoint_across_shear_rates`).
    #[cfg(not(feature = "f32"))]
    const RATE_POINTS: [(f64, f64, &[usize]); 4] = [(5e-6, 1.0 - 1e-8, &[ALPHA]), (1e-3, 1.0 - 1e-6, &[ALPHA]), (0.02, 0.999, &[]), (5.0, 0.98, &[M])];

    #[cfg(not(feature = "f32"))]
    impl Point {
        /// Not validated: a few points take A_thix > 0 without `lambda_max`, which validation
        /// rejects but the update defines.
        fn material(&self, p: &[f64]) -> PapanastasiouRoussel {
            PapanastasiouRoussel {
                density: 2000.0,
                bulk_modulus: p[0],
                viscosity: p[1],
                yield_stress: p[2],
                papanastasiou_m: p[3],
                a_thix: p[4],
                alpha: p[5],
                lambda0: if self.by_lambda_max { 0.0 } else { p[6] },
                lambda_max: self.by_lambda_max.then_some(p[6]),
                flow_index: p[7],
                eos: self.eos,
            }
        }

        /// The adjoint check at a random L of this shear rate, every input perturbed by about a
        /// tenth of its size.
        fn check(&self, label: &str, seed: u64) {
            let mut rng = crate::adjoint_check::Rng(seed);
            let l = M3::from_cols_array(&std::array::from_fn(|_| rng.uniform(-1.0, 1.0)));
            let d = dev(&sym(&l));
            let l = l * (self.gamma_dot / (2.0 * ddot(&d, &d)).sqrt());
            let l_max = l
                .to_cols_array()
                .iter()
                .fold(0.0, |a: f64, v| a.max(v.abs()));
            let param_scale: Vec<f64> = (0..8)
                .map(|i| match self.unresolved.contains(&i) {
                    true => 0.0,
                    false => 0.1 * self.params[i],
                })
                .collect();
            crate::material::test_util::check_update_adjoint(
                label,
                |p: &[f64]| self.material(p),
                &self.params,
                l,
                self.j,
                self.dt,
                &[self.lambda],
                0.1 * l_max,
                &[0.1 * self.lambda],
                &param_scale,
                1e-6,
                seed,
            );
        }
    }

    #[cfg(not(feature = "f32"))]
    const TAIT: Eos = Eos::Tait { gamma: 7.0 };

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_lambda_between_its_bounds() {
        // trial lambda = 1 + (0.05 - 0.5 g) dt stays well inside (0, 3). J near 1 keeps the
        // pressure (~2e3) from swamping, in the differences' round-off, the small effect of A_thix
        // and alpha on the stress.
        let base = Point {
            params: [3.3e5, 30.0, 100.0, 10.0, 5.0, 0.5, 3.0, 1.0],
            by_lambda_max: true,
            eos: TAIT,
            gamma_dot: 0.2,
            j: 0.995,
            dt: 0.1,
            lambda: 1.0,
            unresolved: &[],
        };
        for (k, eos) in [TAIT, Eos::Linear].into_iter().enumerate() {
            let seed = 11 + 10 * k as u64;
            for (i, g) in [0.2, 0.07].into_iter().enumerate() {
                let pt = Point {
                    eos,
                    gamma_dot: g,
                    ..base
                };
                pt.check(&format!("interior {eos:?} g={g}"), seed + i as u64);
            }
            // Without lambda_max the cap is lambda0 = 3 (not reached).
            let pt = Point {
                eos,
                by_lambda_max: false,
                gamma_dot: 0.15,
                j: 1.005,
                ..base
            };
            pt.check(&format!("interior, cap lambda0, {eos:?}"), seed + 2);
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_lambda_clamped_at_zero() {
        // alpha g dt = 10 drives the trial lambda to about -4.5; m g = 1000 is also the large-rate
        // end, where exp(-m g) underflows to 0.
        for (k, eos) in [TAIT, Eos::Linear].into_iter().enumerate() {
            let pt = Point {
                params: [3.3e5, 30.0, 100.0, 10.0, 0.5, 1.0, 3.0, 1.0],
                by_lambda_max: true,
                eos,
                gamma_dot: 100.0,
                j: 0.97,
                dt: 0.1,
                lambda: 0.5,
                unresolved: &[],
            };
            pt.check(&format!("at zero {eos:?}"), 21 + k as u64);
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_lambda_clamped_at_the_cap() {
        // Build-up 0.5/s over dt = 0.1 takes lambda = 2.99 to a trial 3.04 > lambda_max = 3.
        let base = Point {
            params: [3.3e5, 30.0, 100.0, 10.0, 50.0, 0.05, 3.0, 1.0],
            by_lambda_max: true,
            eos: TAIT,
            gamma_dot: 0.03,
            j: 0.99,
            dt: 0.1,
            lambda: 2.99,
            unresolved: &[],
        };
        for (k, eos) in [TAIT, Eos::Linear].into_iter().enumerate() {
            Point { eos, ..base }.check(&format!("at cap {eos:?}"), 31 + k as u64);
        }
        // Capped by lambda0 = 2 with lambda = 2.5 above it (a state only a perturbation reaches).
        let pt = Point {
            params: [3.3e5, 30.0, 100.0, 10.0, 0.5, 0.05, 2.0, 1.0],
            by_lambda_max: false,
            lambda: 2.5,
            ..base
        };
        pt.check("at cap lambda0", 33);
    }

    /// The mix of the shear-rate sweeps at rest, J = 1 and lambda = 1.2, on the lambda_max branch.
    #[cfg(not(feature = "f32"))]
    fn rate_point() -> Point {
        Point {
            params: [3.3e5, 30.0, 100.0, 10.0, 5.0, 1.0, 3.0, 1.0],
            by_lambda_max: true,
            eos: TAIT,
            gamma_dot: 0.0,
            j: 1.0,
            dt: 0.1,
            lambda: 1.2,
            unresolved: &[],
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_across_shear_rates() {
        // m g from the series branches of phi and phi' (5e-5, 0.01) to exp(-m g) ~ 2e-22 (50).
        // At small rates J = 1 - 1e-8 keeps the pressure (K (1/J - 1) ~ 3e-3) from swamping the
        // shear stress (~1e-3 at m g = 5e-5) in the differences' round-off. Unresolved: alpha
        // while alpha g dt <= 1e-4, and m where its derivative exp(-m g) ~ 2e-22.
        let base = rate_point();
        for (k, eos) in [TAIT, Eos::Linear].into_iter().enumerate() {
            for (i, (gamma_dot, j, unresolved)) in RATE_POINTS.into_iter().enumerate() {
                let pt = Point {
                    eos,
                    gamma_dot,
                    j,
                    unresolved,
                    ..base
                };
                let seed = 41 + 10 * k as u64 + i as u64;
                pt.check(&format!("m g={} {eos:?}", 10.0 * gamma_dot), seed);
            }
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_at_rest_and_without_thixotropy() {
        // Not checked by central differences: g = 0 is the cone of sqrt(2 D':D'), and A_thix = 0
        // lies on the edge of its admissible range. The adjoint takes the subgradient 0 and the
        // one-sided derivative d(A_thix / tau0) / dA_thix = 1 / tau0.
        let mut m = mix();
        m.alpha = 0.3;
        let dt = 0.1;
        let (mut gv, mut jb, mut sb, mut pb) = (M3::ZERO, 0.0, [0.0], [0.0; 8]);
        let mut out = UpdateAdjoint {
            grad_v_bar: &mut gv,
            j_bar: &mut jb,
            state_bar: &mut sb,
            params_bar: &mut pb,
        };
        m.update_adjoint(&M3::ZERO, 1.0, dt, &[0.0], &M3::ZERO, &[1.0], &mut out);
        assert_eq!(gv, M3::ZERO);
        assert_eq!(sb[0], 1.0);
        assert_eq!(pb, [0.0, 0.0, 0.0, 0.0, dt / 100.0, 0.0, 0.0, 0.0]);
        // At rest a stress cotangent sees the stress's tangent 2 (eta + tau0 m) dev(sym(.)).
        let s_bar = M3::from_cols_array(&[0.3, -0.2, 0.5, 0.1, 0.7, -0.4, 0.2, 0.6, -0.9]);
        let (mut gv, mut pb) = (M3::ZERO, [0.0; 8]);
        let mut out = UpdateAdjoint {
            grad_v_bar: &mut gv,
            j_bar: &mut jb,
            state_bar: &mut sb,
            params_bar: &mut pb,
        };
        m.update_adjoint(&M3::ZERO, 1.0, dt, &[0.0], &s_bar, &[0.0], &mut out);
        let expect = dev(&sym(&s_bar)) * (2.0 * (30.0 + 100.0 * 10.0));
        assert!(gv.abs_diff_eq(expect, 1e-9), "{gv} vs {expect}");
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_a_flow_index_across_shear_rates_and_lambda_branches() {
        // the points of `adjoint_across_shear_rates` (series branches of phi and phi', the
        // middle, exp(-m g) ~ 2e-22) and of the clamped cases, with n below and above 1, where the
        // power law's q^(1-n) is regularised (m g << 1) or is HB (m g >> 1)
        let base = rate_point();
        for (k, n) in [0.5, 1.3].into_iter().enumerate() {
            for (i, (gamma_dot, j, unresolved)) in RATE_POINTS.into_iter().enumerate() {
                let mut params = base.params;
                params[7] = n;
                let pt = Point { params, gamma_dot, j, unresolved, ..base };
                pt.check(&format!("n={n}, m g={}", 10.0 * gamma_dot), 141 + 10 * k as u64 + i as u64);
            }
            // lambda clamped at zero (large rate, where m's derivative exp(-m g) underflows to 0)
            // and at the cap (small rate)
            let pt = Point { params: [3.3e5, 30.0, 100.0, 10.0, 0.5, 1.0, 3.0, n], gamma_dot: 100.0, j: 0.97, lambda: 0.5, eos: Eos::Linear, unresolved: &[M], ..base };
            pt.check(&format!("n={n}, at zero"), 161 + k as u64);
            let pt = Point { params: [3.3e5, 30.0, 100.0, 10.0, 50.0, 0.05, 3.0, n], gamma_dot: 0.03, j: 0.99, lambda: 2.99, ..base };
            pt.check(&format!("n={n}, at cap"), 171 + k as u64);
        }
    }

    #[test]
    fn with_a_flow_index_the_flow_curve_is_herschel_bulkley_and_finite_at_rest() {
        for n in [0.4 as Real, 0.6, 1.5] {
            // Real is f32 under the `f32` feature, where the cast is needed
            #[allow(clippy::unnecessary_cast)]
            let m = PapanastasiouRoussel { flow_index: n as f64, papanastasiou_m: 100.0, ..mix() };
            assert!(m.validate().is_ok());
            // m g >= 50: (1 - exp(-m g))^(1-n) is 1 to round-off, so tau = tau0 + k g^n
            for g in [0.5 as Real, 1.0, 4.0, 30.0] {
                let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut [0.0]);
                let hb = 100.0 + 30.0 * g.powf(n);
                assert!(rel(s.y_axis.x, hb) < 10.0 * EPS, "n={n} g={g}: {} vs {hb}", s.y_axis.x);
            }
            // at vanishing rate the apparent viscosity tends to k m^(1-n) + tau0 m, not infinity
            let g = 1e-9 as Real;
            let s = m.update(&simple_shear(g), 1.0, 1e-4, &mut [0.0]);
            let eta0 = 30.0 * (100.0 as Real).powf(1.0 - n) + 100.0 * 100.0;
            assert!(rel(s.y_axis.x / g, eta0) < 1e-6, "n={n}: {} vs {eta0}", s.y_axis.x / g);
            assert_eq!(m.update(&M3::ZERO, 1.0, 1e-4, &mut [0.0]).y_axis.x, 0.0);
            // the step's viscosity bound holds at every rate
            let st = m.stability();
            assert!(rel(st.max_viscosity, if n <= 1.0 { eta0 } else { 30.0 * (2.0 as Real).powf(n - 1.0) * (100.0 as Real).powf(1.0 - n) + 1e4 }) < EPS);
            assert_eq!(st.thickening.is_some(), n > 1.0);
            for g in [1e-6, 1e-3, 0.01, 0.1, 1.0, 40.0, 1e3] {
                let s = m.update(&simple_shear(g as Real), 1.0, 1e-4, &mut [0.0]);
                assert!(s.y_axis.x as f64 / g <= st.viscosity_up_to(g) * (1.0 + if cfg!(feature = "f32") { 1e-5 } else { 1e-9 }), "n={n} g={g}");
            }
        }
        let bad = PapanastasiouRoussel { flow_index: -0.5, ..mix() };
        assert_eq!(bad.validate().unwrap_err().to_string(), "material.flow_index must be > 0, got -0.5");
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn phi_derivative_is_accurate_on_both_sides_of_the_series_switch() {
        // Reference: the alternating series sum (-1)^k k x^(k-1) / (k+1)!, converged far below
        // f64 precision for x <= 1; beyond, the closed form (exp(-x) (1 + x) - 1) / x^2 is exact
        // enough.
        let reference = |x: f64| {
            if x > 1.0 {
                return ((-x).exp() * (1.0 + x) - 1.0) / (x * x);
            }
            let (mut sum, mut pow, mut fact) = (0.0, 1.0, 1.0);
            for k in 1..40 {
                fact *= k as f64 + 1.0;
                sum += if k % 2 == 1 { -1.0 } else { 1.0 } * k as f64 * pow / fact;
                pow *= x;
            }
            sum
        };
        for x in [
            0.0, 1e-12, 1e-6, 1e-3, 0.0499, 0.05, 0.0501, 0.1, 0.5, 1.0, 3.0, 30.0,
        ] {
            let v = one_minus_exp_neg_over_x_derivative(x);
            assert!(
                rel(v, reference(x)) < 2e-14,
                "x={x}: {v} vs {}",
                reference(x)
            );
        }
    }

    /// Waking after a rest: lambda built up below the cap (its adjoint to A_thix and tau0),
    /// clamped at lambda_max, and without thixotropy at and below the cap lambda0.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn wake_adjoint_matches_central_differences() {
        use crate::material::test_util::check_wake_adjoint;
        // (label, by lambda_max, A_thix, cap, lambda before); K, eta, tau0, m, alpha, n fixed below
        let cases = [
            ("built up below the cap", true, 5.0, 3.0, 1.0),
            ("clamped at lambda_max", true, 5.0, 3.0, 2.95),
            ("no thixotropy, below lambda_max", true, 0.0, 3.0, 0.5),
        ];
        for (k, (label, by_lambda_max, a_thix, cap, lambda)) in cases.into_iter().enumerate() {
            let pt = Point {
                params: [3.3e5, 30.0, 100.0, 10.0, a_thix, 0.5, cap, 1.0],
                by_lambda_max,
                eos: TAIT,
                gamma_dot: 0.0,
                j: 0.995,
                dt: 0.0,
                lambda,
                unresolved: &[],
            };
            // at A_thix = 0 the forward's rate is one-sided (0 below), and the adjoint takes the
            // admissible side's quotient, as `update_adjoint` does: not a central difference
            let scale = pt.params.map(|v| 0.1 * v);
            let state_scale = [0.1 * lambda];
            let label = format!("papanastasiou_roussel, {label}");
            check_wake_adjoint(&label, |p: &[f64]| pt.material(p), &pt.params, pt.j, 2.0, &[lambda], &state_scale, &scale, 1e-6, 61 + k as u64);
        }
    }
}
