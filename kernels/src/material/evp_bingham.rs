//! Elasto-viscoplastic Bingham solid with Roussel thixotropy (paper 001 eqs. 14-22, stress update
//! eqs. 36-47).
//!
//! Below yield the deviatoric stress is hypoelastic with the Jaumann rate; above yield it flows
//! with the Bingham law tau = eta gamma_dot_p + (1 + lambda) tau0, where tau = sqrt(J2) =
//! sqrt(s:s / 2) and the yield stress carries the flocculation state lambda (eq. 11):
//!
//! ```text
//! sigma = s - p(J) I                          p from `eos` with the solver's J (001 eq. 31)
//! f     = tau - (1 + lambda) tau0             (eq. 14)
//! D^p   = gamma_dot_p s / (2 tau)             (eq. 19; gamma_dot_p = sqrt(2 D^p:D^p))
//! lambda' = A_thix / tau0 - alpha lambda gamma_dot_p   (eq. 22)
//! ```
//!
//! One step, with D' = dev(sym L), W = skew(L):
//!
//! 1. trial deviator s_tr = R s R^T + 2 G dt D' (eq. 37, deviatoric part), where R is the
//!    Hughes-Winget rotation of the Jaumann rate ([`jaumann_rotation`]). R s R^T equals
//!    s + dt (W s - s W) to first order, and is the "rotationally neutralised" update the paper
//!    asks for: a rigid spin leaves tau unchanged exactly. The volumetric part of eq. 37
//!    (K tr(D) dt) is not integrated: the pressure comes from the EOS at the solver's J. Plastic
//!    flow is isochoric, so it cannot change that pressure; this is why the paper has
//!    p^{n+1} = p^tr.
//! 2. lambda_tr = lambda + A_thix / tau0 dt (eq. 38); f_tr = tau_tr - (1 + lambda_tr) tau0 (eq. 39).
//! 3. If f_tr > 0, the return map. With s' = s_tr - 2 G dt D^p and D^p along s', s' is parallel
//!    to s_tr and tau' = tau_tr - G dt gamma_p (eq. 45); lambda' = lambda_tr / (1 + alpha dt gamma_p)
//!    (eqs. 41, 45); requiring tau' = eta gamma_p + (1 + lambda') tau0 gives eq. 42, a quadratic
//!    (zeta/2) gamma_p^2 + xi gamma_p - f_tr = 0 with xi and zeta of eq. 44. Its positive root is
//!    eq. 43, evaluated without cancellation as 2 f_tr / (xi + sqrt(xi^2 + 2 zeta f_tr)) when
//!    xi > 0 (always so for alpha = 0, where it is exactly eq. 47, f_tr / (eta + G dt)), and as
//!    eq. 43 itself when xi <= 0 (only possible for alpha > 0, so zeta > 0). Then s' = (tau' /
//!    tau_tr) s_tr (eq. 46).
//!
//! Herschel-Bulkley with `flow_index` n (default 1, the paper's Bingham law): the viscous part
//! of the flow rule becomes k gamma_dot_p^n, `viscosity` playing k, so steady flow has
//! tau = (1 + lambda) tau0 + k gamma_dot_p^n. The return map then solves
//! R(gamma_p) = tau_tr - tau0 - G dt gamma_p - k gamma_p^n - tau0 lambda_tr / (1 + alpha dt gamma_p) = 0
//! (eq. 42 divided by 1 + alpha dt gamma_p, with k gamma_p^n for eta gamma_p) by Newton's method
//! safeguarded by bisection on [0, hi], where R(0) = f_tr > 0 and R(hi) <= 0 at
//! hi = min((tau_tr - tau0) / (G dt), ((tau_tr - tau0) / k)^(1/n)). R decreases on that bracket,
//! so its root is unique, whenever tau0 lambda_tr alpha <= G (always without thixotropy); else the
//! root found is one where R crosses zero downwards. At n = 1 the closed form above is used, bit
//! for bit as before. No regularisation is needed for n < 1: the rate the power law sees is the
//! return map's gamma_p > 0, found implicitly, and below yield the material is elastic, so the
//! apparent viscosity k gamma_p^(n-1) never enters a division; d gamma_p / d(theta) =
//! -(dR/d theta) / (dR/d gamma_p) only goes to 0 where dR/d gamma_p = -n k gamma_p^(n-1) blows up.
//! Its viscous tangent is at most G dt (the spring of the trial in series with the dashpot), so
//! the step bound stays the elastic wave speed's; [`Material::stability`] reports `viscosity`
//! (k) as its viscosity at every n, as at n = 1.
//!
//! G is constant (but see "Ageing"). With `poisson_ratio`, eq. 18 is evaluated with the
//! reference K rather than the EOS tangent at the current J (a few percent apart in the weakly
//! compressible range), so the elastic shear response does not follow the density noise of the
//! pressure field.
//!
//! Ageing (optional; `docs/materials.md`): with `bulk_modulus_rate` given, K follows an
//! [`AgeLaw`] of the particle's age a (linear, or bilinear with `bulk_modulus_late_rate` beyond
//! `bulk_modulus_transition_age`), `bulk_modulus` being K at age 0, and G follows K at a fixed
//! ratio: eq. 18 with `poisson_ratio`, G0 K(a) / K0 with `shear_modulus` G0 (the Poisson ratio
//! the pair implies is held). The age is `early_age_solid`'s: the time since the particle's
//! creation plus `age_at_start`, capped at `max_age`, read at the step's start and advanced by
//! dt. The stress is held through stiffening (the rate form): the trial deviator already adds
//! 2 G(a) dt D' to the rotated old one, and the pressure p = p_held + P(K(a), J) keeps a held
//! part p_held in the state, re-expressed at each step's end so that p moves by
//! P(K, J) - P(K, J_old) with the step's K and not by K's growth: p_held' = p_held +
//! P(K(a), J) - P(K(a + dt), J) (both EOS are linear in K). A layer compressed by its own weight
//! keeps its pressure and its J as it hardens; a total form P(K(a), J) would push it to expand.
//! `rest_for_at` ages a sleeping particle and holds its pressure at its J the same way.
//! Without `bulk_modulus_rate` (the default) nothing of this runs and the state has no age:
//! every number is the one before the law existed. `bulk_modulus_rate = 0` is the same
//! material with the age and p_held (then 0) in the state, which gradients in the law's
//! parameters need.
//!
//! Optional viscoelastic Maxwell branch in parallel (paper 004; [`crate::material::maxwell`]):
//! with `maxwell_modulus` G_M given, the Cauchy stress is sigma = s + s_M - p I, where s_M obeys
//! ds_M/dt = 2 G_M D' - s_M / t_M (Jaumann rate, the rotation R of step 1, relaxation time
//! t_M = `maxwell_time` = eta_M / G_M) and is integrated exactly for the step's constant D'. The
//! branch does not enter the yield test: the EVP element and the Maxwell element see the same
//! velocity gradient and their stresses add, so in steady flow the shear stress is
//! tau0 (1 + lambda) + eta gamma_dot + s_M,xy with s_M,xy -> eta_M gamma_dot at Weissenberg
//! number t_M gamma_dot << 1. Without `maxwell_modulus` (the default) there is no branch and no
//! state for it, and the update is the EVP one to the bit. `maxwell_modulus = 0` is the same
//! material (s_M stays exactly 0) but carries the branch's state, which a gradient with respect
//! to `maxwell_modulus` or `maxwell_time` needs (at G_M = 0 the derivative in G_M is carried by
//! s_M through time).
//!
//! Per-particle state (8 reals, 14 with the Maxwell branch, 2 more with the age law):
//! `[s_xx, s_yy, s_zz, s_xy, s_yz, s_xz, lambda, gamma_p]` — the deviatoric Cauchy stress of the
//! EVP element [Pa], the flocculation state [-] (initially `lambda0`), and the accumulated plastic
//! shear strain gamma_p = integral of gamma_dot_p dt [-] (engineering shear measure; the von
//! Mises equivalent plastic strain is gamma_p / sqrt(3)); then, with the branch,
//! `[sM_xx, sM_yy, sM_zz, sM_xy, sM_yz, sM_xz]`, the Maxwell branch's deviatoric stress [Pa];
//! then, with the age law, `[age, p_held]`, the age [s] and the held pressure [Pa].

use serde::Deserialize;

use std::sync::OnceLock;

use crate::material::age_law::{bare, check_ages, law_age, AgeLaw, LawKeys};
use crate::material::eos::{resolve_shear_modulus, shear_modulus_of, shear_modulus_of_partials};
use crate::material::{default_flow_index, maxwell, non_negative, positive, Eos, Material, MaterialError, StabilityInfo, UpdateAdjoint};
use crate::real::{
    ddot, dev, jaumann_rotation, jaumann_rotation_adjoint, r, skew, sym, sym_from_slice, sym_from_slice_adjoint,
    sym_to_array, sym_to_array_adjoint, Real, M3, V3,
};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvpBingham {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Bulk modulus K of the equation of state [Pa].
    pub bulk_modulus: f64,
    /// Elastic shear modulus G [Pa]; give this or `poisson_ratio`.
    #[serde(default)]
    pub shear_modulus: Option<f64>,
    /// Poisson's ratio nu [-], G = 3 K (1 - 2 nu) / (2 (1 + nu)) (001 eq. 18); give this or
    /// `shear_modulus`.
    #[serde(default)]
    pub poisson_ratio: Option<f64>,
    /// Plastic viscosity eta [Pa s]; with `flow_index` n != 1, the consistency k [Pa s^n].
    pub viscosity: f64,
    /// Reference yield stress tau0 [Pa], as sqrt(J2).
    pub yield_stress: f64,
    /// Flocculation rate A_thix [Pa/s].
    #[serde(default)]
    pub a_thix: f64,
    /// Deflocculation coefficient alpha [-].
    #[serde(default)]
    pub alpha: f64,
    /// Initial flocculation state lambda0 [-].
    #[serde(default)]
    pub lambda0: f64,
    /// Shear modulus G_M of the Maxwell branch [Pa]; absent (the default): no branch, which is
    /// G_M = 0 without the branch's six state reals.
    #[serde(default)]
    pub maxwell_modulus: Option<f64>,
    /// Relaxation time t_M = eta_M / G_M of the Maxwell branch [s], > 0; default 1 s (the
    /// time scale of a rheometer's hold; only read with `maxwell_modulus`).
    #[serde(default = "default_maxwell_time")]
    pub maxwell_time: f64,
    /// Flow index n [-] of the Herschel-Bulkley flow rule; 1 (Bingham) when absent.
    #[serde(default = "default_flow_index")]
    pub flow_index: f64,
    #[serde(default)]
    pub eos: Eos,
    /// dK/da [Pa/s], the rate of the bulk modulus's age law (up to the transition age when
    /// bilinear); `bulk_modulus` is then K at age 0 and G follows K (module docs, "Ageing").
    /// Absent (the default): K and G constant, and no age in the state.
    #[serde(default)]
    pub bulk_modulus_rate: Option<f64>,
    /// dK/da beyond `bulk_modulus_transition_age` [Pa/s].
    #[serde(default)]
    pub bulk_modulus_late_rate: Option<f64>,
    /// Age where K's rate changes [s].
    #[serde(default)]
    pub bulk_modulus_transition_age: Option<f64>,
    /// The mix's age when the print starts [s] (every particle's age at its creation); 0 when
    /// absent; only with `bulk_modulus_rate`.
    #[serde(default)]
    pub age_at_start: Option<f64>,
    /// The age the law stops at [s]; absent: none; only with `bulk_modulus_rate`.
    #[serde(default)]
    pub max_age: Option<f64>,
}

const K_KEYS: LawKeys = LawKeys {
    value: "material.bulk_modulus",
    rate: "material.bulk_modulus_rate",
    late_rate: "material.bulk_modulus_late_rate",
    transition_age: "material.bulk_modulus_transition_age",
};

/// The moduli a step reads with the age law on: K and G at the (law) age at the step's start,
/// K at the age the step leaves in the state (in which the held pressure is re-expressed).
struct Aged {
    law: AgeLaw,
    /// The law age at the step's start and whether it moves with the particle's (not past
    /// `max_age`); the same at the step's end.
    start: (f64, bool),
    end: (f64, bool),
    k: f64,
    g: f64,
    k_end: f64,
    /// The age the step leaves in the state.
    age_end: Real,
}

fn default_maxwell_time() -> f64 {
    1.0
}

const STATE: [&str; 8] = ["s_xx", "s_yy", "s_zz", "s_xy", "s_yz", "s_xz", "lambda", "gamma_p"];
const STATE_MAXWELL: [&str; 14] = [
    "s_xx", "s_yy", "s_zz", "s_xy", "s_yz", "s_xz", "lambda", "gamma_p", "sM_xx", "sM_yy", "sM_zz", "sM_xy", "sM_yz", "sM_xz",
];
const STATE_AGED: [&str; 10] = ["s_xx", "s_yy", "s_zz", "s_xy", "s_yz", "s_xz", "lambda", "gamma_p", "age", "p_held"];
const STATE_MAXWELL_AGED: [&str; 16] = [
    "s_xx", "s_yy", "s_zz", "s_xy", "s_yz", "s_xz", "lambda", "gamma_p", "sM_xx", "sM_yy", "sM_zz", "sM_xy", "sM_yz", "sM_xz", "age", "p_held",
];

impl EvpBingham {
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        resolve_shear_modulus(
            "material",
            self.bulk_modulus,
            self.shear_modulus,
            self.poisson_ratio,
        )?;
        // eta = 0 is rate-independent von Mises plasticity, still well posed.
        non_negative("material.viscosity", self.viscosity)?;
        non_negative("material.yield_stress", self.yield_stress)?;
        non_negative("material.a_thix", self.a_thix)?;
        non_negative("material.alpha", self.alpha)?;
        non_negative("material.lambda0", self.lambda0)?;
        if let Some(g_m) = self.maxwell_modulus {
            non_negative("material.maxwell_modulus", g_m)?;
        }
        positive("material.maxwell_time", self.maxwell_time)?;
        positive("material.flow_index", self.flow_index)?;
        if self.a_thix > 0.0 && self.yield_stress == 0.0 {
            return Err(MaterialError::OutOfRangeWhen {
                key: "material.yield_stress",
                range: "> 0",
                when: "material.a_thix > 0",
                reason: "eq. 22 divides by it",
            });
        }
        self.validate_age_law()?;
        self.eos.validate("material.eos")
    }

    /// The age law's keys: only with `bulk_modulus_rate`; finite; K > 0 at every age.
    fn validate_age_law(&self) -> Result<(), MaterialError> {
        let Some(rate) = self.bulk_modulus_rate else {
            let given = [
                ("material.bulk_modulus_late_rate", self.bulk_modulus_late_rate),
                ("material.bulk_modulus_transition_age", self.bulk_modulus_transition_age),
                ("material.age_at_start", self.age_at_start),
                ("material.max_age", self.max_age),
            ];
            return match given.into_iter().find(|(_, v)| v.is_some()) {
                Some((key, _)) => Err(MaterialError::RequiredWhen {
                    key: K_KEYS.rate,
                    when: key,
                    reason: "the bulk modulus's age law is on only with its rate (0 for a law at rest)",
                }),
                None => Ok(()),
            };
        };
        K_KEYS.check(self.bulk_modulus, rate, self.bulk_modulus_late_rate, self.bulk_modulus_transition_age)?;
        let a0 = self.age_at_start.unwrap_or(0.0);
        let span = check_ages(a0, self.max_age)?;
        let k_min = self.k_law().map_or(f64::NAN, |law| law.min_over(a0, self.max_age.unwrap_or(f64::INFINITY)));
        if k_min.is_nan() || k_min <= 0.0 {
            return Err(MaterialError::out_of_range("material.bulk_modulus (with its rates)", format!("> 0 {span}"), k_min));
        }
        Ok(())
    }

    /// The bulk modulus's age law, when `bulk_modulus_rate` is given.
    fn k_law(&self) -> Option<AgeLaw> {
        self.bulk_modulus_rate.map(|rate| AgeLaw { p0: self.bulk_modulus, rate, late: self.bulk_modulus_late_rate.zip(self.bulk_modulus_transition_age) })
    }

    /// G at bulk modulus `k`: with `poisson_ratio`, eq. 18; with `shear_modulus` G0, G0 k / K0
    /// (G / K held, as nu is).
    #[inline]
    fn shear_at(&self, k: f64) -> f64 {
        match self.shear_modulus {
            Some(g0) => g0 * (k / self.bulk_modulus),
            None => shear_modulus_of(k, None, self.poisson_ratio),
        }
    }

    /// Index of the age in the state (the held pressure follows): after the Maxwell branch's.
    fn age_slot(&self) -> usize {
        if self.maxwell_modulus.is_some() {
            14
        } else {
            8
        }
    }

    /// The moduli of a step from a particle of age `age` (law on).
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn aged(&self, law: AgeLaw, age: Real, dt: Real) -> Aged {
        let age_end = age + dt;
        let start = law_age(age as f64, self.max_age);
        let end = law_age(age_end as f64, self.max_age);
        let k = law.value(start.0);
        Aged { law, start, end, k, g: self.shear_at(k), k_end: law.value(end.0), age_end }
    }

    /// The pressure of the held part and the EOS at K of the particle's age (law on).
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn aged_pressure(&self, law: &AgeLaw, state: &[Real], j: Real) -> Real {
        let slot = self.age_slot();
        let k = law.value(law_age(state[slot] as f64, self.max_age).0);
        state[slot + 1] + self.eos.pressure(r(k), j)
    }

    /// Elastic shear modulus G [Pa].
    #[inline]
    pub fn shear_modulus(&self) -> f64 {
        shear_modulus_of(self.bulk_modulus, self.shear_modulus, self.poisson_ratio)
    }

    /// A_thix / tau0 [1/s] (Roussel build-up, 001 eq. 12).
    #[inline]
    fn build_up_rate(&self) -> Real {
        crate::material::build_up_rate(self.a_thix, self.yield_stress)
    }

    /// The Herschel-Bulkley return map's residual at this step's trial state.
    #[inline]
    fn hb_return(&self, g: Real, dt: Real, tau_tr: Real, lambda_tr: Real) -> HbReturn {
        let tau0 = r(self.yield_stress);
        HbReturn {
            excess: tau_tr - tau0,
            g_dt: g * dt,
            k: r(self.viscosity),
            n: r(self.flow_index),
            structure: tau0 * lambda_tr,
            alpha_dt: r(self.alpha) * dt,
        }
    }

    /// Index of `flow_index` in `param_names`: after the Maxwell branch's, when it is there.
    fn flow_index_slot(&self) -> usize {
        if self.maxwell_modulus.is_some() {
            9
        } else {
            7
        }
    }

    /// The parameters without the age law.
    fn base_param_names(&self) -> &'static [&'static str] {
        match (self.shear_modulus.is_some(), self.maxwell_modulus.is_some()) {
            (true, false) => &["bulk_modulus", "shear_modulus", "viscosity", "yield_stress", "a_thix", "alpha", "lambda0", "flow_index"],
            (false, false) => &["bulk_modulus", "poisson_ratio", "viscosity", "yield_stress", "a_thix", "alpha", "lambda0", "flow_index"],
            (true, true) => &[
                "bulk_modulus", "shear_modulus", "viscosity", "yield_stress", "a_thix", "alpha", "lambda0", "maxwell_modulus", "maxwell_time", "flow_index",
            ],
            (false, true) => &[
                "bulk_modulus", "poisson_ratio", "viscosity", "yield_stress", "a_thix", "alpha", "lambda0", "maxwell_modulus", "maxwell_time", "flow_index",
            ],
        }
    }

    /// Chain the adjoints of a step's moduli (K and G at the start age, K at the end age) to the
    /// law's parameters (in `params_bar`, after the kind's own) and to the age before the step
    /// (in `state_bar`); return the adjoints of parameters 1 (G0 or nu) and 0 (K0).
    // real conversions in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn aged_adjoint(&self, a: &Aged, k_bar: Real, k_end_bar: Real, g_bar: Real, state_out_bar: &[Real], out: &mut UpdateAdjoint) -> (Real, Real) {
        let (k_bar, k_end_bar, g_bar) = (k_bar as f64, k_end_bar as f64, g_bar as f64);
        // G(K): G0 K / K0 with G0 given (so K0 enters twice), eq. 18 with nu
        let (k_total, second, mut k0_bar) = match (self.shear_modulus, self.poisson_ratio) {
            (Some(g0), _) => {
                let k0 = self.bulk_modulus;
                (k_bar + g_bar * g0 / k0, g_bar * a.k / k0, -g_bar * g0 * a.k / (k0 * k0))
            }
            (None, Some(nu)) => {
                let (dg_dk, dg_dnu) = shear_modulus_of_partials(a.k, nu);
                (k_bar + g_bar * dg_dk, g_bar * dg_dnu, 0.0)
            }
            (None, None) => (k_bar, 0.0, 0.0),
        };
        let first = self.base_param_names().len();
        let n = if a.law.late.is_some() { 3 } else { 1 };
        let mut age_bar = 0.0;
        for ((age, moving), bar) in [(a.start, k_total), (a.end, k_end_bar)] {
            let d = a.law.partials(age);
            k0_bar += bar * d[0];
            for i in 0..n {
                out.params_bar[first + i] += r(bar * d[1 + i]);
            }
            if moving {
                age_bar += bar * a.law.rate_at(age);
            }
        }
        // age_out = age_in + dt
        let slot = self.age_slot();
        out.state_bar[slot] += state_out_bar[slot] + r(age_bar);
        (r(second), r(k0_bar))
    }

    /// (G_M, t_M) of the Maxwell branch, when there is one.
    #[inline]
    fn maxwell(&self) -> Option<(Real, Real)> {
        self.maxwell_modulus.map(|g_m| (r(g_m), r(self.maxwell_time)))
    }
}

/// The trial deviator of step 1 (001 eq. 37), and the rotation it used.
#[inline]
fn trial_deviator(grad_v: &M3, g: Real, dt: Real, s_old: &M3) -> (M3, M3) {
    let rot = jaumann_rotation(&skew(grad_v), dt);
    // dev(sym()) drops the round-off trace and asymmetry the rotation leaves, so neither can
    // accumulate in the state or reach the returned stress.
    let s_tr = dev(&sym(&(rot * *s_old * rot.transpose()))) + dev(&sym(grad_v)) * (r(2.0) * g * dt);
    (s_tr, rot)
}

/// Positive root gamma_p of (zeta/2) gamma_p^2 + xi gamma_p - f = 0 for f > 0, zeta >= 0
/// (001 eqs. 42-44, 47), in whichever form avoids subtracting nearly equal numbers.
#[inline]
fn plastic_shear_rate(f: Real, xi: Real, zeta: Real) -> Real {
    let root = (xi * xi + r(2.0) * zeta * f).sqrt();
    if xi > r(0.0) {
        r(2.0) * f / (xi + root)
    } else {
        (root - xi) / zeta
    }
}

/// R(gamma_p) = excess - g_dt gamma_p - k gamma_p^n - structure / (1 + alpha_dt gamma_p), the
/// Herschel-Bulkley return map's residual (module docs), with excess = tau_tr - tau0 and
/// structure = tau0 lambda_tr.
struct HbReturn {
    excess: Real,
    g_dt: Real,
    k: Real,
    n: Real,
    structure: Real,
    alpha_dt: Real,
}

impl HbReturn {
    /// (R, dR/d gamma_p, gamma_p^n) at gamma_p > 0.
    #[inline]
    fn residual(&self, gp: Real) -> (Real, Real, Real) {
        let pow = gp.powf(self.n);
        let den = r(1.0) + self.alpha_dt * gp;
        let value = self.excess - self.g_dt * gp - self.k * pow - self.structure / den;
        let slope = -self.g_dt - self.n * self.k * pow / gp + self.structure * self.alpha_dt / (den * den);
        (value, slope, pow)
    }

    /// The root in (0, hi) for f_tr = R(0) > 0: Newton's method, bisecting whenever a step would
    /// leave the bracket the residual's signs keep, to a relative step of a few round-offs.
    fn root(&self) -> Real {
        let mut hi = self.excess / self.g_dt;
        if self.k > r(0.0) {
            hi = hi.min((self.excess / self.k).powf(r(1.0) / self.n));
        }
        let mut lo = r(0.0);
        let mut x = r(0.5) * hi;
        for _ in 0..200 {
            let (value, slope, _) = self.residual(x);
            if value == r(0.0) {
                break;
            }
            if value > r(0.0) {
                lo = x;
            } else {
                hi = x;
            }
            let newton = x - value / slope;
            let next = if slope < r(0.0) && newton > lo && newton < hi { newton } else { r(0.5) * (lo + hi) };
            let done = (next - x).abs() <= r(4.0) * Real::EPSILON * next || hi - lo <= r(4.0) * Real::EPSILON * hi;
            x = next;
            if done {
                break;
            }
        }
        x
    }
}

impl Material for EvpBingham {
    fn name(&self) -> &'static str {
        "evp_bingham"
    }

    fn state_names(&self) -> &'static [&'static str] {
        match (self.maxwell_modulus.is_some(), self.bulk_modulus_rate.is_some()) {
            (false, false) => &STATE,
            (true, false) => &STATE_MAXWELL,
            (false, true) => &STATE_AGED,
            (true, true) => &STATE_MAXWELL_AGED,
        }
    }

    fn init_state(&self, state: &mut [Real]) {
        state[..6].fill(r(0.0));
        state[6] = r(self.lambda0);
        state[7] = r(0.0);
        if self.maxwell_modulus.is_some() {
            state[8..14].fill(r(0.0));
        }
        if self.bulk_modulus_rate.is_some() {
            let slot = self.age_slot();
            state[slot] = r(self.age_at_start.unwrap_or(0.0));
            state[slot + 1] = r(0.0);
        }
    }

    #[inline]
    fn update(&self, grad_v: &M3, j: Real, dt: Real, state: &mut [Real]) -> M3 {
        let aged = self.k_law().map(|law| self.aged(law, state[self.age_slot()], dt));
        let g = match &aged {
            None => r(self.shear_modulus()),
            Some(a) => r(a.g),
        };
        let eta = r(self.viscosity);
        let tau0 = r(self.yield_stress);
        let alpha = r(self.alpha);

        let (s_tr, rot) = trial_deviator(grad_v, g, dt, &sym_from_slice(&state[..6]));
        let lambda_tr = state[6] + self.build_up_rate() * dt;
        let tau_tr = (r(0.5) * ddot(&s_tr, &s_tr)).sqrt();
        let f_tr = tau_tr - (r(1.0) + lambda_tr) * tau0;

        let (s, lambda) = if f_tr > r(0.0) {
            let gamma_p = if self.flow_index == 1.0 {
                let xi = eta + dt * (g + alpha * (tau0 - tau_tr));
                let zeta = r(2.0) * alpha * dt * (dt * g + eta);
                plastic_shear_rate(f_tr, xi, zeta)
            } else {
                self.hb_return(g, dt, tau_tr, lambda_tr).root()
            };
            let tau = tau_tr - dt * g * gamma_p;
            state[7] += gamma_p * dt;
            (
                s_tr * (tau / tau_tr),
                lambda_tr / (r(1.0) + dt * alpha * gamma_p),
            )
        } else {
            (s_tr, lambda_tr)
        };

        state[..6].copy_from_slice(&sym_to_array(&s));
        state[6] = lambda;
        let p = match aged {
            None => M3::from_diagonal(V3::splat(self.eos.pressure(r(self.bulk_modulus), j))),
            Some(a) => {
                // the rate form: p = p_held + P(K(a), J) moves by P(K, J) - P(K, J_old) with the
                // step's K; re-expressed at the end age's K, p_held absorbs the stiffening
                let slot = self.age_slot();
                let p_end = self.eos.pressure(r(a.k_end), j);
                state[slot + 1] = state[slot + 1] + self.eos.pressure(r(a.k), j) - p_end;
                state[slot] = a.age_end;
                M3::from_diagonal(V3::splat(state[slot + 1] + p_end))
            }
        };
        match self.maxwell() {
            None => s - p,
            Some((g_m, t_m)) => {
                let s_m = maxwell::update(&rot, &dev(&sym(grad_v)), g_m, t_m, dt, &sym_from_slice(&state[8..14]));
                state[8..14].copy_from_slice(&sym_to_array(&s_m));
                (s + s_m) - p
            }
        }
    }

    /// [`Material::update`] particle by particle; where the CPU has AVX2 and the material has its
    /// plain form (Bingham's flow rule, no Maxwell branch, no age law), W particles at a time in
    /// lanes (`evp_bingham_lanes.rs`, the same bits).
    fn update_batch(&self, grad_v: &[M3], j: &[Real], dt: Real, state: &mut [Real], stress: &mut [M3]) {
        let n = self.state_names().len();
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::has_avx2() && self.flow_index == 1.0 && self.maxwell_modulus.is_none() && self.k_law().is_none() {
            use crate::material::evp_bingham_lanes::{updates, Consts};
            use crate::wide::W;
            let c = Consts {
                g: r(self.shear_modulus()),
                eta: r(self.viscosity),
                tau0: r(self.yield_stress),
                alpha: r(self.alpha),
                build_up_rate: self.build_up_rate(),
                k: r(self.bulk_modulus),
                eos: self.eos,
            };
            done = grad_v.len() / W * W;
            for p in (0..done).step_by(W) {
                // SAFETY: the CPU has AVX2
                unsafe { updates(&c, &grad_v[p..p + W], &j[p..p + W], dt, &mut state[p * n..(p + W) * n], n, &mut stress[p..p + W]) };
            }
        }
        for p in done..grad_v.len() {
            stress[p] = self.update(&grad_v[p], j[p], dt, &mut state[p * n..(p + 1) * n]);
        }
    }

    /// With the Maxwell branch, `maxwell_modulus` and `maxwell_time` follow (indices 7, 8);
    /// `flow_index` is last of the kind's own; the age law's keys come after it.
    fn param_names(&self) -> &'static [&'static str] {
        let Some(law) = self.k_law() else { return self.base_param_names() };
        // the age law's after the rest: `bulk_modulus_rate`, (`bulk_modulus_late_rate`,
        // `bulk_modulus_transition_age`), `age_at_start`; one list per combination, built once
        static NAMES: [OnceLock<Vec<&'static str>>; 8] = [const { OnceLock::new() }; 8];
        let bilinear = law.late.is_some();
        let mask = self.shear_modulus.is_some() as usize | (self.maxwell_modulus.is_some() as usize) << 1 | (bilinear as usize) << 2;
        NAMES[mask].get_or_init(|| {
            let mut v = self.base_param_names().to_vec();
            v.push(bare(K_KEYS.rate));
            if bilinear {
                v.extend([bare(K_KEYS.late_rate), bare(K_KEYS.transition_age)]);
            }
            v.push("age_at_start");
            v
        })
    }

    /// The return map's root gamma_p is differentiated implicitly: at n = 1 through its quadratic
    /// (eq. 42), whichever form evaluated it, else through the residual R of the module docs;
    /// d/dn at n = 1 (the shear-thinning effect's score) through R too, which has the same root.
    /// The yield test f_tr > 0 is the branch held fixed.
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
        // forward, as in `update`
        let aged = self.k_law().map(|law| self.aged(law, state_in[self.age_slot()], dt));
        let g = match &aged {
            None => r(self.shear_modulus()),
            Some(a) => r(a.g),
        };
        let eta = r(self.viscosity);
        let tau0 = r(self.yield_stress);
        let alpha = r(self.alpha);
        let w = skew(grad_v);
        let s_old = sym_from_slice(&state_in[..6]);
        let d_dev = dev(&sym(grad_v));
        let (s_tr, rot) = trial_deviator(grad_v, g, dt, &s_old);
        let lambda_tr = state_in[6] + self.build_up_rate() * dt;
        let tau_tr = (r(0.5) * ddot(&s_tr, &s_tr)).sqrt();
        let f_tr = tau_tr - (r(1.0) + lambda_tr) * tau0;

        // adjoints of the outputs
        let p_bar = -crate::real::trace(stress_bar);
        let (k_bar, k_end_bar) = match &aged {
            None => {
                let (k_bar, j_bar) = self.eos.pressure_adjoint(r(self.bulk_modulus), j, p_bar);
                *out.j_bar += j_bar;
                (k_bar, r(0.0))
            }
            Some(a) => {
                // p_held' = p_held + P(K, J) - P(K_end, J), p = p_held' + P(K_end, J)
                let slot = self.age_slot();
                let held_bar = state_out_bar[slot + 1] + p_bar;
                out.state_bar[slot + 1] += held_bar;
                let (k_bar, j_bar) = self.eos.pressure_adjoint(r(a.k), j, held_bar);
                let (k_end_bar, j_end_bar) = self.eos.pressure_adjoint(r(a.k_end), j, -state_out_bar[slot + 1]);
                *out.j_bar += j_bar + j_end_bar;
                (k_bar, k_end_bar)
            }
        };
        let s_bar = *stress_bar + sym_to_array_adjoint(&state_out_bar[..6]);
        let lambda_bar = state_out_bar[6];
        out.state_bar[7] += state_out_bar[7];
        let (mut g_bar, mut eta_bar, mut tau0_bar, mut alpha_bar, mut n_bar) = (r(0.0), r(0.0), r(0.0), r(0.0), r(0.0));

        let (s_tr_bar, lambda_tr_bar) = if f_tr > r(0.0) {
            let bingham = self.flow_index == 1.0;
            let xi = eta + dt * (g + alpha * (tau0 - tau_tr));
            let zeta = r(2.0) * alpha * dt * (dt * g + eta);
            let hb = self.hb_return(g, dt, tau_tr, lambda_tr);
            let gamma_p = if bingham { plastic_shear_rate(f_tr, xi, zeta) } else { hb.root() };
            let tau = tau_tr - dt * g * gamma_p;
            let den = r(1.0) + dt * alpha * gamma_p;
            let mut gamma_bar = state_out_bar[7] * dt;
            // lambda = lambda_tr / den
            let mut lambda_tr_bar = lambda_bar / den;
            let den_bar = -lambda_bar * lambda_tr / (den * den);
            alpha_bar += den_bar * dt * gamma_p;
            gamma_bar += den_bar * dt * alpha;
            // s = s_tr tau / tau_tr
            let ratio_bar = ddot(&s_bar, &s_tr);
            let mut s_tr_bar = s_bar * (tau / tau_tr);
            let tau_bar = ratio_bar / tau_tr;
            let mut tau_tr_bar = -ratio_bar * tau / (tau_tr * tau_tr);
            // tau = tau_tr - dt G gamma_p
            tau_tr_bar += tau_bar;
            g_bar -= tau_bar * dt * gamma_p;
            gamma_bar -= tau_bar * dt * g;
            if bingham {
                // (zeta/2) gamma_p^2 + xi gamma_p - f_tr = 0, implicitly; zeta gamma_p + xi = root > 0
                let slope = zeta * gamma_p + xi;
                let f_bar = gamma_bar / slope;
                let xi_bar = -gamma_bar * gamma_p / slope;
                let zeta_bar = -gamma_bar * r(0.5) * gamma_p * gamma_p / slope;
                alpha_bar += zeta_bar * r(2.0) * dt * (dt * g + eta);
                g_bar += zeta_bar * r(2.0) * alpha * dt * dt;
                eta_bar += zeta_bar * r(2.0) * alpha * dt;
                eta_bar += xi_bar;
                g_bar += xi_bar * dt;
                alpha_bar += xi_bar * dt * (tau0 - tau_tr);
                tau0_bar += xi_bar * dt * alpha;
                tau_tr_bar -= xi_bar * dt * alpha;
                // f_tr = tau_tr - (1 + lambda_tr) tau0
                tau_tr_bar += f_bar;
                lambda_tr_bar -= f_bar * tau0;
                tau0_bar -= f_bar * (r(1.0) + lambda_tr);
                // dR/dn = -k gamma_p ln gamma_p; at the root R = -(quadratic) / den, so
                // dR/d gamma_p = -slope / den
                if gamma_p > r(0.0) {
                    n_bar += gamma_bar * den / slope * (-eta * gamma_p * gamma_p.ln());
                }
            } else if gamma_p > r(0.0) {
                // R(gamma_p; theta) = 0: theta_bar += w dR/d theta with w = -gamma_bar / (dR/d gamma_p)
                let (_, slope, pow) = hb.residual(gamma_p);
                let w = -gamma_bar / slope;
                tau_tr_bar += w;
                tau0_bar -= w * (r(1.0) + lambda_tr / den);
                g_bar -= w * dt * gamma_p;
                eta_bar -= w * pow;
                n_bar -= w * eta * pow * gamma_p.ln();
                lambda_tr_bar -= w * tau0 / den;
                alpha_bar += w * tau0 * lambda_tr * dt * gamma_p / (den * den);
            }
            // tau_tr = sqrt(s_tr : s_tr / 2)
            s_tr_bar += s_tr * (r(0.5) * tau_tr_bar / tau_tr);
            (s_tr_bar, lambda_tr_bar)
        } else {
            (s_bar, lambda_bar)
        };

        // lambda_tr = lambda + (A_thix / tau0) dt; at A_thix = 0 (no build-up, the effect's null
        // value) the derivative is the one of A_thix > 0, the side the parameter can take
        out.state_bar[6] += lambda_tr_bar;
        let rate_bar = lambda_tr_bar * dt;
        let a_thix_bar = if tau0 > r(0.0) { rate_bar / tau0 } else { r(0.0) };
        if self.a_thix > 0.0 {
            tau0_bar -= rate_bar * r(self.a_thix) / (tau0 * tau0);
        }
        // s_tr = dev(sym(R s R^T)) + 2 G dt dev(sym L); dev and sym are self-adjoint projections
        let proj_bar = dev(&sym(&s_tr_bar));
        *out.grad_v_bar += proj_bar * (r(2.0) * g * dt);
        g_bar += r(2.0) * dt * ddot(&s_tr_bar, &d_dev);
        let s_old_bar = rot.transpose() * proj_bar * rot;
        let mut rot_bar = (proj_bar + proj_bar.transpose()) * rot * s_old;
        if let Some((g_m, t_m)) = self.maxwell() {
            // sigma = (s + s_M) - p I: s_M's adjoint is the stress's plus its state's
            let s_m_bar = *stress_bar + sym_to_array_adjoint(&state_out_bar[8..14]);
            let a = maxwell::update_adjoint(&rot, &d_dev, g_m, t_m, dt, &sym_from_slice(&state_in[8..14]), &s_m_bar);
            rot_bar += a.rot_bar;
            *out.grad_v_bar += dev(&sym(&a.d_dev_bar));
            sym_from_slice_adjoint(&a.s_old_bar, &mut out.state_bar[8..14]);
            out.params_bar[7] += a.modulus_bar;
            out.params_bar[8] += a.time_bar;
        }
        let w_bar = jaumann_rotation_adjoint(&w, dt, &rot_bar);
        *out.grad_v_bar += skew(&w_bar);
        sym_from_slice_adjoint(&s_old_bar, &mut out.state_bar[..6]);

        let (nu_or_g, k_extra) = match &aged {
            None => match (self.shear_modulus, self.poisson_ratio) {
                (Some(_), _) => (g_bar, r(0.0)),
                (None, Some(nu)) => {
                    let (dg_dk, dg_dnu) = shear_modulus_of_partials(self.bulk_modulus, nu);
                    (g_bar * r(dg_dnu), g_bar * r(dg_dk))
                }
                (None, None) => (r(0.0), r(0.0)),
            },
            Some(a) => self.aged_adjoint(a, k_bar, k_end_bar, g_bar, state_out_bar, out),
        };
        let p = &mut out.params_bar;
        p[0] += if aged.is_none() { k_bar + k_extra } else { k_extra };
        p[1] += nu_or_g;
        p[2] += eta_bar;
        p[3] += tau0_bar;
        p[4] += a_thix_bar;
        p[5] += alpha_bar;
        p[self.flow_index_slot()] += n_bar;
    }

    fn init_state_adjoint(&self, state_bar: &[Real], params_bar: &mut [Real]) {
        params_bar[6] += state_bar[6];
        if self.k_law().is_some() {
            // every particle starts at `age_at_start`, the last parameter
            params_bar[self.param_names().len() - 1] += state_bar[self.age_slot()];
        }
    }

    /// The deviators are the state itself (the EVP's, and the Maxwell branch's), so this is the
    /// stress `update` returned for any grad v, bit for bit, in the same order of operations.
    /// A sleeping particle keeps it: the Maxwell stress relaxes at rest, but not while asleep; on
    /// waking, `rest_for` relaxes it over the whole interval at once.
    fn stress_at_rest(&self, state: &[Real], j: Real) -> M3 {
        let p = match self.k_law() {
            None => M3::from_diagonal(V3::splat(self.eos.pressure(r(self.bulk_modulus), j))),
            Some(law) => M3::from_diagonal(V3::splat(self.aged_pressure(&law, state, j))),
        };
        match self.maxwell() {
            None => sym_from_slice(&state[..6]) - p,
            Some(_) => (sym_from_slice(&state[..6]) + sym_from_slice(&state[8..14])) - p,
        }
    }

    /// Without J: [`Material::rest_for_at`] at J = 1, where the pressure is the held part alone.
    fn rest_for(&self, state: &mut [Real], duration: Real) {
        self.rest_for_at(state, duration, r(1.0));
    }

    fn rest_for_at(&self, state: &mut [Real], duration: Real, j: Real) {
        // at rest below yield only eq. 22's build-up acts, and it is linear in time; the Maxwell
        // stress relaxes as exp(-duration / t_M)
        state[6] += self.build_up_rate() * duration;
        if let Some((_, t_m)) = self.maxwell() {
            maxwell::relax(&mut state[8..14], t_m, duration);
        }
        // the particle ages at its J, and its pressure is held as in `update`
        if let Some(law) = self.k_law() {
            let slot = self.age_slot();
            let before = self.aged_pressure(&law, state, j);
            state[slot] += duration;
            let after = self.aged_pressure(&law, state, j);
            state[slot + 1] += before - after;
        }
    }

    /// Without an age law or a Maxwell branch (false otherwise): the rest adds its build-up to
    /// lambda (state 6), the stress at rest is the deviator held in the state less p(K, J).
    fn wake_adjoint(&self, _state: &[Real], duration: Real, j: Real, stress_bar: &M3, state_bar: &mut [Real], j_bar: &mut Real, params_bar: &mut [Real]) -> bool {
        if self.k_law().is_some() || self.maxwell().is_some() {
            return false;
        }
        crate::real::sym_from_slice_adjoint(stress_bar, &mut state_bar[..6]);
        let p_bar = -(stress_bar.x_axis.x + stress_bar.y_axis.y + stress_bar.z_axis.z);
        let (k_bar, jb) = self.eos.pressure_adjoint(r(self.bulk_modulus), j, p_bar);
        *j_bar += jb;
        // `base_param_names`: bulk_modulus 0, yield_stress 3, a_thix 4
        params_bar[0] += k_bar;
        if self.yield_stress > 0.0 {
            // the build-up A_thix / tau0 times the rest, into lambda (its derivative on the whole
            // admissible side A_thix >= 0, as `update_adjoint` takes it)
            let (tau0, rate_bar) = (r(self.yield_stress), state_bar[6] * duration);
            params_bar[4] += rate_bar / tau0;
            params_bar[3] -= rate_bar * r(self.a_thix) / (tau0 * tau0);
        }
        true
    }

    /// f = tau - (1 + lambda) tau0 (eq. 14) of the EVP element's deviator; the Maxwell branch
    /// does not enter the yield test.
    fn yield_margin(&self, state: &[Real]) -> Real {
        let s = sym_from_slice(&state[..6]);
        (r(1.0) + state[6]) * r(self.yield_stress) - (r(0.5) * ddot(&s, &s)).sqrt()
    }

    /// Eq. 22 at rest: lambda grows by A_thix / tau0 per second, so (1 + lambda) tau0 by A_thix.
    fn strength_gain(&self, duration: Real) -> Real {
        self.build_up_rate() * duration * r(self.yield_stress)
    }

    /// The Maxwell branch adds at most 2 G_M dt D' per step (a spring G_M; see `maxwell`), so
    /// G_M counts with G in the elastic wave speed.
    fn stability(&self) -> StabilityInfo {
        self.stability_at(0.0)
    }

    /// With the age law, the stiffest K (and its G) over the ages [age_at_start, age_at_start +
    /// time] (capped at `max_age`): no particle is older during the step starting at `time`,
    /// and `update` reads the age at the step's start.
    fn stability_at(&self, time: f64) -> StabilityInfo {
        let (k, g) = match self.k_law() {
            None => (self.bulk_modulus, self.shear_modulus()),
            Some(law) => {
                let a0 = self.age_at_start.unwrap_or(0.0);
                let k = law.max_over(a0, law_age(a0 + time.max(0.0), self.max_age).0);
                (k, self.shear_at(k))
            }
        };
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(k),
            shear_modulus: r(g + self.maxwell_modulus.unwrap_or(0.0)),
            max_viscosity: r(self.viscosity),
            thickening: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::{simple_shear, tau_of};
    use crate::real::trace;

    /// Round-off tolerance of the working precision.
    const EPS: Real = if cfg!(feature = "f32") { 1e-5 } else { 1e-12 };

    /// `update_batch` (in lanes where the CPU has AVX2) leaves the bits of `update` particle by
    /// particle: 11 particles (whole groups of lanes and a tail) over 60 steps, lanes that stay
    /// elastic beside lanes that yield, with and without thixotropy (the return map's root in
    /// both of its forms), the Tait EOS, a -0 and a NaN; and the forms that stay one particle at
    /// a time (Maxwell branch, Herschel-Bulkley) too.
    #[test]
    fn the_batch_is_update_bit_for_bit() {
        let k = |i: usize| (i as Real * 0.37).sin();
        let ls: Vec<M3> = (0..11)
            .map(|i| match i % 5 {
                0 => M3::from_diagonal(V3::new(1.0, 0.0, -1.0)) * (50.0 * k(i)),
                1 => M3::from_cols_array(&std::array::from_fn(|j| 1e-3 * k(i + 3 * j))),
                2 => M3::from_cols(V3::new(-0.0, 40.0, 0.0), V3::new(-4.0, 1e-2 * k(i), 0.0), V3::ZERO),
                3 => M3::from_cols_array(&std::array::from_fn(|j| 80.0 * k(i + 5 * j))),
                _ => simple_shear(200.0 * k(i)),
            })
            .collect();
        let j: Vec<Real> = (0..11).map(|i| 1.0 + 1e-3 * k(i + 7)).collect();
        let thixotropic = EvpBingham { a_thix: 2.0e3, alpha: 50.0, lambda0: 0.5, ..solid() };
        let variants = [
            solid(),
            thixotropic.clone(),
            EvpBingham { alpha: 1.0e3, ..thixotropic.clone() },
            EvpBingham { eos: Eos::Tait { gamma: 7.0 }, shear_modulus: None, poisson_ratio: Some(0.3), ..thixotropic.clone() },
            EvpBingham { maxwell_modulus: Some(1e4), ..solid() },
            EvpBingham { flow_index: 0.5, ..solid() },
        ];
        let dt = 1e-4;
        let mut xi_signs = [false; 2];
        for (v, m) in variants.iter().enumerate() {
            let n_state = m.state_names().len();
            let mut a = vec![0.0; n_state * 11];
            for st in a.chunks_mut(n_state) {
                m.init_state(st);
            }
            let mut b = a.clone();
            let mut out = vec![M3::ZERO; 11];
            for step in 0..60 {
                let mut ls = ls.clone();
                if step == 30 {
                    ls[9] = M3::from_diagonal(V3::new(Real::NAN, 0.0, 0.0));
                }
                for (p, l) in ls.iter().enumerate() {
                    // which form of the root each yielding particle takes (alpha > 0 only)
                    let st = &b[p * n_state..(p + 1) * n_state];
                    let (s_tr, _) = trial_deviator(l, r(m.shear_modulus()), dt, &sym_from_slice(&st[..6]));
                    let tau_tr = (r(0.5) * ddot(&s_tr, &s_tr)).sqrt();
                    if m.alpha > 0.0 && tau_tr > (r(1.0) + st[6]) * r(m.yield_stress) {
                        let xi = r(m.viscosity) + dt * (r(m.shear_modulus()) + r(m.alpha) * (r(m.yield_stress) - tau_tr));
                        xi_signs[(xi > 0.0) as usize] = true;
                    }
                }
                m.update_batch(&ls, &j, dt, &mut a, &mut out);
                for p in 0..11 {
                    let s = m.update(&ls[p], j[p], dt, &mut b[p * n_state..(p + 1) * n_state]);
                    assert_eq!(s.to_cols_array().map(|x| x.to_bits()), out[p].to_cols_array().map(|x| x.to_bits()), "variant {v}, step {step}, particle {p}");
                }
                assert_eq!(a.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), b.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), "variant {v}, step {step}");
            }
            assert!(a.chunks(n_state).any(|st| st[7] > 0.0) && a.chunks(n_state).any(|st| st[7] == 0.0), "variant {v}: some particles yield, some stay elastic");
        }
        assert_eq!(xi_signs, [true, true], "the return map's root in both forms");
    }

    fn solid() -> EvpBingham {
        EvpBingham {
            density: 2000.0,
            bulk_modulus: 2.0e6,
            shear_modulus: Some(1.0e6),
            poisson_ratio: None,
            viscosity: 30.0,
            yield_stress: 100.0,
            a_thix: 0.0,
            alpha: 0.0,
            lambda0: 0.0,
            maxwell_modulus: None,
            maxwell_time: 1.0,
            flow_index: 1.0,
            eos: Eos::Linear,
            bulk_modulus_rate: None,
            bulk_modulus_late_rate: None,
            bulk_modulus_transition_age: None,
            age_at_start: None,
            max_age: None,
        }
    }

    fn rel(a: Real, b: Real) -> Real {
        (a - b).abs() / b.abs()
    }

    fn fresh(m: &EvpBingham) -> [Real; 8] {
        let mut st = [0.0; 8];
        m.init_state(&mut st);
        st
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn simple_shear_is_elastic_until_yield_then_reaches_bingham_flow() {
        let m = solid();
        let (g, dt) = (2.0 as Real, 1e-6 as Real);
        let mut st = fresh(&m);
        let mut yielded_at = None;
        for n in 1..=20_000 {
            let s = m.update(&simple_shear(g), 1.0, dt, &mut st);
            let gamma = n as Real * dt * g;
            if st[7] == 0.0 {
                // Elastic: tau = G gamma (the Jaumann correction is O(gamma^2) ~ 1e-8 here).
                assert!(rel(tau_of(&s), 1e6 * gamma) < 1e-6, "n={n}");
            } else if yielded_at.is_none() {
                yielded_at = Some(gamma);
            }
        }
        // Yield at G gamma = tau0, within one step.
        let gy = yielded_at.unwrap();
        assert!(
            gy >= 1e-4 && gy <= 1e-4 + 2.0 * g * dt,
            "yield at gamma = {gy}"
        );
        // Steady flow: all the shear rate is plastic and tau = tau0 + eta g.
        let s = m.update(&simple_shear(g), 1.0, dt, &mut st);
        let bingham = 100.0 + 30.0 * g;
        assert!(
            rel(tau_of(&s), bingham) < 1e-6,
            "tau {} vs {bingham}",
            tau_of(&s)
        );
        assert!(rel(s.y_axis.x, bingham) < 1e-6);
        let gp_before = st[7];
        m.update(&simple_shear(g), 1.0, dt, &mut st);
        assert!(rel((st[7] - gp_before) / dt, g) < 1e-6);
    }

    #[test]
    fn elastic_simple_shear_follows_the_jaumann_closed_form() {
        // Hypoelastic Jaumann simple shear: s_xy = G sin(gamma), s_xx = -s_yy = G (1 - cos gamma),
        // so tau = 2 G sin(gamma / 2); the positive s_xx also fixes the sign of the spin terms.
        let mut m = solid();
        m.yield_stress = 1e12;
        let (g, dt, n) = (1.0 as Real, 1e-3 as Real, 1500);
        let mut st = fresh(&m);
        let mut s = M3::ZERO;
        for _ in 0..n {
            s = m.update(&simple_shear(g), 1.0, dt, &mut st);
        }
        let gamma = n as Real * dt * g;
        let gm = 1e6 as Real;
        assert!((s.y_axis.x - gm * gamma.sin()).abs() < 2e-3 * gm, "{s:?}");
        assert!(
            (s.x_axis.x - gm * (1.0 - gamma.cos())).abs() < 2e-3 * gm,
            "{s:?}"
        );
        assert!((s.y_axis.y + gm * (1.0 - gamma.cos())).abs() < 2e-3 * gm);
        assert!(rel(tau_of(&s), 2.0 * gm * (gamma / 2.0).sin()) < 2e-3);
        assert!(s.z_axis.z.abs() < EPS * gm);
    }

    /// The skew matrix K with K x = a x x.
    fn cross_matrix(a: V3) -> M3 {
        M3::from_cols(
            V3::new(0.0, a.z, -a.y),
            V3::new(-a.z, 0.0, a.x),
            V3::new(a.y, -a.x, 0.0),
        )
    }

    /// Rotation by `angle` about unit `axis` (Rodrigues), independent of the code under test.
    fn rotation(axis: V3, angle: Real) -> M3 {
        let k = cross_matrix(axis);
        M3::IDENTITY + k * angle.sin() + k * k * (1.0 - angle.cos())
    }

    fn max_abs(m: &M3) -> Real {
        m.to_cols_array()
            .iter()
            .fold(0.0, |a: Real, &x| a.max(x.abs()))
    }

    #[test]
    fn rigid_rotation_rotates_the_stress_and_keeps_its_invariants() {
        let m = solid();
        let s0 = M3::from_cols(
            V3::new(30.0, 10.0, -5.0),
            V3::new(10.0, -20.0, 7.0),
            V3::new(-5.0, 7.0, -10.0),
        );
        let mut st = fresh(&m);
        st[..6].copy_from_slice(&sym_to_array(&s0));
        let axis = V3::new(1.0, 2.0, 2.0) / 3.0;
        let omega = 3.0 as Real;
        let w = cross_matrix(axis) * omega;
        let (dt, n) = (1e-3 as Real, 2000);
        let mut s = M3::ZERO;
        for _ in 0..n {
            s = m.update(&w, 1.0, dt, &mut st);
        }
        assert!(
            rel(tau_of(&s), tau_of(&s0)) < 10.0 * EPS,
            "{} vs {}",
            tau_of(&s),
            tau_of(&s0)
        );
        assert!(rel(s.determinant(), s0.determinant()) < 100.0 * EPS);
        assert!(trace(&s).abs() < 1e-9 * tau_of(&s0) || cfg!(feature = "f32"));
        // Co-rotation with the material: s(t) = Q s0 Q^T, Q = exp(W t). The Cayley step turns by
        // 2 atan(omega dt / 2) instead of omega dt, a phase error of n (omega dt)^3 / 12 ~ 5e-6.
        let q = rotation(axis, omega * n as Real * dt);
        let expect = q * s0 * q.transpose();
        let err = max_abs(&(s - expect));
        assert!(err < 1e-4 * tau_of(&s0), "max error {err}");
        assert_eq!(st[7], 0.0);
    }

    #[test]
    fn hughes_winget_rotation_is_orthogonal_and_first_order_jaumann() {
        let w = M3::from_cols(
            V3::new(0.0, 0.3, -0.2),
            V3::new(-0.3, 0.0, 0.1),
            V3::new(0.2, -0.1, 0.0),
        );
        let s = M3::from_cols(
            V3::new(1.0, 2.0, 3.0),
            V3::new(2.0, -4.0, 0.5),
            V3::new(3.0, 0.5, 3.0),
        );
        let mut gaps = [0.0; 2];
        for (i, dt) in [0.02 as Real, 0.01].into_iter().enumerate() {
            let q = jaumann_rotation(&w, dt);
            assert!(max_abs(&(q * q.transpose() - M3::IDENTITY)) < 10.0 * EPS);
            assert!(rel(q.determinant(), 1.0) < 10.0 * EPS);
            // The explicit Jaumann update, against which R s R^T must differ by O(dt^2) only.
            gaps[i] = max_abs(&(q * s * q.transpose() - (s + (w * s - s * w) * dt)));
        }
        let ratio = gaps[0] / gaps[1];
        assert!((ratio - 4.0).abs() < 0.1, "gap ratio {ratio}: {gaps:?}");
    }

    /// Takes one plastic step from a prescribed state with a spin-free L, so the trial state can be
    /// recomputed by hand; returns (tau_new, gamma_p, lambda_new, tau_tr, f_tr, lambda_tr).
    fn one_plastic_step(m: &EvpBingham, dt: Real) -> (Real, Real, Real, Real, Real, Real) {
        let s0 = M3::from_cols(
            V3::new(40.0, 60.0, 0.0),
            V3::new(60.0, -10.0, 20.0),
            V3::new(0.0, 20.0, -30.0),
        );
        let l = M3::from_cols(
            V3::new(0.2, 0.5, -0.1),
            V3::new(0.5, -0.4, 0.3),
            V3::new(-0.1, 0.3, 0.1),
        );
        let mut st = fresh(m);
        st[..6].copy_from_slice(&sym_to_array(&s0));
        st[6] = 0.7;
        let s = m.update(&l, 1.0, dt, &mut st);
        let g = m.shear_modulus() as Real;
        let s_tr = s0 + dev(&l) * (2.0 * g * dt);
        let tau_tr = tau_of(&s_tr);
        let lambda_tr = 0.7 + m.a_thix as Real / m.yield_stress as Real * dt;
        let f_tr = tau_tr - (1.0 + lambda_tr) * m.yield_stress as Real;
        assert!(f_tr > 0.0, "test setup must yield");
        // Radial return: the new deviator is parallel to the trial one.
        let tau_new = tau_of(&s);
        let dir = s * (1.0 / tau_new) - s_tr * (1.0 / tau_tr);
        assert!(max_abs(&dir) < 100.0 * EPS, "{dir:?}");
        (tau_new, st[7] / dt, st[6], tau_tr, f_tr, lambda_tr)
    }

    /// The margin is what tau may still grow before the yield test of `update` fails: a
    /// deviator scaled to the margin's edge sits on the yield surface, and rest grows the margin
    /// by exactly what `rest_for` adds to the yield stress.
    #[test]
    fn yield_margin_is_the_distance_to_the_yield_surface() {
        let m = EvpBingham { a_thix: 40.0, lambda0: 0.3, ..solid() };
        let mut st = fresh(&m);
        let s0 = M3::from_cols(V3::new(20.0, 15.0, 0.0), V3::new(15.0, -5.0, 10.0), V3::new(0.0, 10.0, -15.0));
        st[..6].copy_from_slice(&sym_to_array(&s0));
        let tau0 = tau_of(&s0);
        let margin = m.yield_margin(&st);
        assert!(rel(margin, 1.3 * 100.0 - tau0) < 1e-6, "{margin} against {}", 130.0 - tau0);
        // a deviator of tau = tau0 + margin: f = 0, just below: elastic, just above: plastic
        for (k, elastic) in [(0.999, true), (1.001, false)] {
            let mut s2 = st;
            let scaled = s0 * (k * (tau0 + margin) / tau0);
            s2[..6].copy_from_slice(&sym_to_array(&scaled));
            let before = s2[7];
            m.update(&M3::ZERO, 1.0, 1e-9, &mut s2);
            assert_eq!(s2[7] == before, elastic, "k = {k}");
        }
        let mut rested = st;
        m.rest_for(&mut rested, 2.5);
        assert!(rel(m.yield_margin(&rested), margin + m.strength_gain(2.5)) < 1e-6);
        assert!(rel(m.strength_gain(2.5), 100.0) < 1e-6, "A_thix x 2.5 s = 100 Pa");
    }

    #[test]
    fn converged_plastic_step_satisfies_the_bingham_law() {
        let base = EvpBingham {
            a_thix: 0.8,
            alpha: 0.3,
            ..solid()
        };
        // xi > 0 (ordinary) and xi < 0 (strong deflocculation, large step) forms of eq. 43.
        for (m, dt) in [
            (base.clone(), 1e-4 as Real),
            (
                EvpBingham {
                    alpha: 100.0,
                    viscosity: 0.0,
                    shear_modulus: Some(1.0e3),
                    yield_stress: 20.0,
                    ..base.clone()
                },
                1e-2,
            ),
        ] {
            let (tau, gp, lambda, tau_tr, _, lambda_tr) = one_plastic_step(&m, dt);
            let (eta, tau0, g) = (
                m.viscosity as Real,
                m.yield_stress as Real,
                m.shear_modulus() as Real,
            );
            let xi = eta + dt * (g + m.alpha as Real * (tau0 - tau_tr));
            assert!(gp > 0.0);
            assert_eq!(xi > 0.0, m.alpha < 1.0, "branch coverage: xi = {xi}");
            // Eq. 20 at the new state, eq. 45, and eq. 41.
            let scale = tau_tr;
            assert!(
                (tau - (eta * gp + (1.0 + lambda) * tau0)).abs() < 10.0 * EPS * scale,
                "eq. 20"
            );
            assert!(
                (tau - (tau_tr - g * dt * gp)).abs() < 10.0 * EPS * scale,
                "eq. 45"
            );
            assert!(
                (lambda * (1.0 + dt * m.alpha as Real * gp) - lambda_tr).abs() < 10.0 * EPS,
                "eq. 41"
            );
        }
    }

    #[test]
    fn alpha_zero_uses_eq_47_and_is_the_limit_of_small_alpha() {
        let m = solid();
        let dt = 1e-4 as Real;
        let (_, gp0, lambda0, _, f_tr, _) = one_plastic_step(&m, dt);
        let eq47 = f_tr / (30.0 + 1.0e6 * dt);
        assert!(rel(gp0, eq47) < 10.0 * EPS, "{gp0} vs {eq47}");
        assert_eq!(lambda0, 0.7);
        let (_, gp1, lambda1, _, _, _) = one_plastic_step(
            &EvpBingham {
                alpha: 1e-9,
                ..solid()
            },
            dt,
        );
        assert!(rel(gp1, gp0) < 1e-8, "{gp1} vs {gp0}");
        assert!(rel(lambda1, lambda0) < 1e-8);
        // Deflocculation lowers the yield stress during the step, so more of it is plastic.
        let (_, gp2, lambda2, _, _, _) = one_plastic_step(
            &EvpBingham {
                alpha: 0.1,
                ..solid()
            },
            dt,
        );
        assert!(gp2 > gp0 && lambda2 < lambda0, "{gp2} {lambda2}");
    }

    #[test]
    fn thixotropic_build_up_at_rest_is_linear_and_stress_free() {
        let m = EvpBingham {
            a_thix: 0.5,
            lambda0: 0.1,
            ..solid()
        };
        let mut st = fresh(&m);
        let (dt, n) = (0.1 as Real, 1000);
        let mut s = M3::IDENTITY;
        for _ in 0..n {
            s = m.update(&M3::ZERO, 1.0, dt, &mut st);
        }
        assert!(rel(st[6], 0.1 + 0.5 * (n as Real * dt) / 100.0) < 1e-4);
        assert_eq!(s, M3::ZERO);
        assert_eq!(st[7], 0.0);
        // what a sleeping particle gets on waking: the same state in one call
        let mut slept = fresh(&m);
        m.rest_for(&mut slept, n as Real * dt);
        assert!(rel(slept[6], st[6]) < 1e-5, "{} vs {}", slept[6], st[6]);
        assert_eq!(slept[..6], st[..6]);
        assert_eq!(slept[7], st[7]);
    }

    #[test]
    fn pressure_is_the_eos_of_j_and_independent_of_plasticity() {
        let m = EvpBingham {
            eos: Eos::Tait { gamma: 7.0 },
            ..solid()
        };
        let mut st = fresh(&m);
        let s = m.update(&simple_shear(1e3), 0.99, 1e-3, &mut st);
        assert!(st[7] > 0.0);
        // Tait by hand for K = 2e6: 2 * 10358.311607745221.
        assert!(rel(-trace(&s) / 3.0, 20716.623215490442) < 1e-5);
    }

    #[test]
    fn shear_modulus_from_poisson_ratio_and_validation() {
        let m = EvpBingham {
            shear_modulus: None,
            poisson_ratio: Some(0.45),
            ..solid()
        };
        assert!(m.validate().is_ok());
        // G = E / (2 (1 + nu)) with E = 3 K (1 - 2 nu): 3 * 2e6 * 0.1 / 2.9.
        assert!((m.shear_modulus() - 6.0e5 / 2.9).abs() < 1e-9);
        let both = EvpBingham {
            poisson_ratio: Some(0.45),
            ..solid()
        };
        assert!(both.validate().unwrap_err().to_string().contains("not both"));
        let none = EvpBingham {
            shear_modulus: None,
            ..solid()
        };
        assert!(none.validate().unwrap_err().to_string().contains("required"));
        let bad = EvpBingham {
            shear_modulus: None,
            poisson_ratio: Some(0.5),
            ..solid()
        };
        assert_eq!(
            bad.validate().unwrap_err().to_string(),
            "material.poisson_ratio must be in (-1, 0.5), got 0.5"
        );
        let bad = EvpBingham {
            a_thix: 1.0,
            yield_stress: 0.0,
            ..solid()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("material.yield_stress"));
        assert!(solid().validate().is_ok());
        let st = solid().stability();
        assert_eq!((st.shear_modulus, st.max_viscosity), (1.0e6, 30.0));
    }

    /// The EVP material from parameter values in `param_names` order.
    #[cfg(not(feature = "f32"))]
    fn make(poisson: bool, eos: Eos) -> impl Fn(&[f64]) -> EvpBingham {
        move |p: &[f64]| EvpBingham {
            density: 2100.0,
            bulk_modulus: p[0],
            shear_modulus: (!poisson).then_some(p[1]),
            poisson_ratio: poisson.then_some(p[1]),
            viscosity: p[2],
            yield_stress: p[3],
            a_thix: p[4],
            alpha: p[5],
            lambda0: p[6],
            maxwell_modulus: (p.len() == 10).then(|| p[7]),
            maxwell_time: if p.len() == 10 { p[8] } else { 1.0 },
            flow_index: p[p.len() - 1],
            eos,
            bulk_modulus_rate: None,
            bulk_modulus_late_rate: None,
            bulk_modulus_transition_age: None,
            age_at_start: None,
            max_age: None,
        }
    }

    #[cfg(not(feature = "f32"))]
    fn l_of(v: [f64; 9]) -> M3 {
        M3::from_cols_array(&v)
    }

    /// Every branch: elastic, plastic with alpha = 0 (eq. 47), plastic with thixotropy in the
    /// xi > 0 form and in the xi <= 0 form of the root, with G or nu, both equations of state,
    /// with spin. Points sit well away from the yield surface (|f_tr| >> the perturbation).
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_on_every_branch() {
        use crate::material::test_util::check_update_adjoint;
        let spin = [0.3, -2.0, 0.5, 3.0, -0.4, 1.2, -0.7, 0.9, 0.2];
        let tait = Eos::Tait { gamma: 7.0 };
        // (label, poisson, eos, params, L, J, dt, state)
        type Case = (&'static str, bool, Eos, [f64; 8], [f64; 9], f64, f64, [f64; 8]);
        let cases: Vec<Case> = vec![
            ("elastic", false, Eos::Linear, [1e6, 2e5, 7.5, 630.0, 3.0, 0.0, 0.0, 1.0], spin, 0.98,
             1e-3, [100.0, -40.0, -60.0, 80.0, -30.0, 20.0, 0.0, 0.01]),
            ("plastic, alpha = 0", false, Eos::Linear, [1e6, 2e5, 7.5, 630.0, 3.0, 0.0, 0.0, 1.0], spin.map(|x| 40.0 * x), 1.02,
             1e-3, [500.0, -200.0, -300.0, 400.0, -150.0, 250.0, 0.0, 0.3]),
            ("plastic, thixotropic, nu, Tait", true, tait, [1e6, 0.3, 7.5, 630.0, 50.0, 0.5, 0.2, 1.0], spin.map(|x| 40.0 * x), 0.99,
             1e-3, [500.0, -200.0, -300.0, 400.0, -150.0, 250.0, 0.4, 0.3]),
            ("plastic, xi <= 0", false, Eos::Linear, [1e6, 1e4, 10.0, 500.0, 20.0, 50.0, 0.1, 1.0], spin.map(|x| 20.0 * x), 1.0,
             1e-3, [2000.0, -900.0, -1100.0, 1500.0, -500.0, 700.0, 0.05, 0.1]),
            ("elastic, thixotropic, nu", true, tait, [1e6, 0.25, 7.5, 630.0, 50.0, 0.5, 0.2, 1.0], spin.map(|x| 0.05 * x), 1.01,
             1e-3, [100.0, -40.0, -60.0, 80.0, -30.0, 20.0, 0.4, 0.0]),
        ];
        // flow index 1 (the closed-form root; d/dn is the shear-thinning effect's score), below
        // and above 1 (the Newton root)
        let cases: Vec<(String, Case)> = [1.0, 0.5, 1.4]
            .into_iter()
            .flat_map(|n| cases.iter().map(move |c| (format!("{}, n = {n}", c.0), { let mut c = *c; c.3[7] = n; c })))
            .collect();
        for (k, (label, (_, poisson, eos, params, l, j, dt, state))) in cases.into_iter().enumerate() {
            let label = label.as_str();
            let mat = make(poisson, eos)(&params);
            // confirm the branch the case is meant to take
            let s_tr_tau = {
                let mut st: Vec<Real> = state.to_vec();
                let _ = mat.update(&l_of(l), j, dt, &mut st);
                st[7] > state[7]
            };
            assert_eq!(s_tr_tau, label.starts_with("plastic"), "{label}: branch");
            if label.contains("xi <= 0") && params[7] == 1.0 {
                let tau_tr = 1.0e3; // order of magnitude of the trial tau of this state
                assert!(params[2] + dt * (params[1] + params[5] * (params[3] - 2.0 * tau_tr)) < 0.0, "{label}: xi");
            }
            let state_scale: Vec<f64> = state.iter().map(|v| v.abs().max(1e-2)).collect();
            // thixotropy moves the stress little: perturb it by amounts the stress resolves (an
            // A_thix perturbation below its value, so the rate A_thix / tau0 keeps its branch)
            let param_scale = [1e6, if poisson { 0.1 } else { params[1] }, 10.0, 500.0, (2e3 * params[4]).max(1e4), 1000.0, 1.0, 0.1];
            check_update_adjoint(label, make(poisson, eos), &params, l_of(l), j, dt, &state, 1.0, &state_scale, &param_scale, 1e-6, 17 + k as u64);
        }
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn with_a_flow_index_steady_shear_flow_is_herschel_bulkley() {
        // simple shear above yield: all the rate is plastic at steady state, tau = tau0 + k g^n
        for n in [0.3, 0.6, 1.5] {
            let m = EvpBingham { flow_index: n, ..solid() };
            assert!(m.validate().is_ok());
            for g in [0.05 as Real, 2.0, 30.0] {
                let dt = 1e-6 / g.max(1.0);
                let mut st = fresh(&m);
                let mut s = M3::ZERO;
                // the elastic loading to yield, tau0 / (G g), then twenty relaxation times
                // k g^(n-1) / G of the spring and the power-law dashpot in series
                let t_end = 20.0 * (100.0 / (1e6 * g) + 30.0 * g.powf(n - 1.0) / 1e6);
                for _ in 0..(t_end / dt).ceil() as usize {
                    s = m.update(&simple_shear(g), 1.0, dt, &mut st);
                }
                let hb = 100.0 + 30.0 * g.powf(n);
                let gp = st[7];
                m.update(&simple_shear(g), 1.0, dt, &mut st);
                // the Jaumann spin keeps a share of order (tau / G)^2 of the rate elastic (2.5e-5
                // at 5 kPa), on top of the integration's 1e-6
                let tol = 1e-6 + 2.0 * (hb / 1e6) * (hb / 1e6);
                assert!(rel(tau_of(&s), hb) < tol, "n={n} g={g}: {} vs {hb}", tau_of(&s));
                assert!(rel((st[7] - gp) / dt, g) < tol, "n={n} g={g}: plastic rate {}", (st[7] - gp) / dt);
            }
        }
        let bad = EvpBingham { flow_index: 0.0, ..solid() };
        assert_eq!(bad.validate().unwrap_err().to_string(), "material.flow_index must be > 0, got 0");
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn the_herschel_bulkley_root_solves_its_residual_just_above_yield_and_far_above() {
        // from f_tr = 1e-9 Pa (gamma_p ~ (f_tr / k)^(1/n), 1e-24 /s at n = 0.3) to f_tr = 1e5 Pa
        for n in [0.3, 0.7, 1.3, 2.0] {
            for f_tr in [1e-9, 1e-3, 1.0, 1e3, 1e5] {
                for (lambda_tr, alpha_dt) in [(0.0, 0.0), (0.5, 1e-3), (2.0, 0.5)] {
                    let tau0 = 100.0;
                    let h = HbReturn { excess: f_tr + tau0 * lambda_tr, g_dt: 1e6 * 1e-4, k: 30.0, n, structure: tau0 * lambda_tr, alpha_dt };
                    let gp = h.root();
                    let (value, slope, _) = h.residual(gp);
                    assert!(gp > 0.0 && value.abs() <= 1e-9 * f_tr.max(1e-6) + 1e-12 * h.excess, "n={n} f={f_tr} lambda={lambda_tr}: gp {gp}, R {value}");
                    assert!(slope < 0.0);
                }
            }
        }
    }

    /// A hash of the bits of every stress and state a fixed sequence of updates gives, over every
    /// branch (elastic, plastic with and without thixotropy, spin, rest, Tait): the fingerprint
    /// of the EVP update as it was before the Maxwell branch was added (commit 6aef083), which
    /// the update without the branch must keep to the bit.
    #[allow(clippy::unnecessary_cast)] // to_bits is u32 in f32 builds
    fn fingerprint(m: &EvpBingham) -> u64 {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        };
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |x: Real| {
            h ^= x.to_bits() as u64;
            h = h.wrapping_mul(0x0100_0000_01b3).rotate_left(7);
        };
        let mut st = vec![0.0 as Real; m.state_names().len()];
        m.init_state(&mut st);
        for step in 0..400 {
            let rest = step % 5 == 4;
            let scale = if step < 100 { 0.5 } else { 40.0 };
            let l = if rest { M3::ZERO } else { M3::from_cols(V3::new(u(), u(), u()), V3::new(u(), u(), u()), V3::new(u(), u(), u())) * scale };
            let j = 1.0 + 0.01 * u();
            let s = m.update(&l, j, 1e-3, &mut st);
            s.to_cols_array().into_iter().for_each(&mut eat);
            st.iter().copied().for_each(&mut eat);
        }
        assert!(st[7] > 0.0 && st.iter().all(|x| x.is_finite()), "the sequence must reach the plastic branch: {st:?}");
        h
    }

    #[test]
    fn without_the_maxwell_branch_the_update_is_the_one_before_it_to_the_bit() {
        let cases = [
            solid(),
            EvpBingham { a_thix: 0.8, alpha: 0.3, lambda0: 0.2, eos: Eos::Tait { gamma: 7.0 }, ..solid() },
            EvpBingham { shear_modulus: None, poisson_ratio: Some(0.3), alpha: 100.0, viscosity: 0.0, ..solid() },
        ];
        let got: Vec<u64> = cases.iter().map(fingerprint).collect();
        println!("fingerprints {got:#x?}");
        let want: [u64; 3] = if cfg!(feature = "f32") {
            [0xcfa53d7191755a36, 0x8eeb6c43221c9738, 0x706f929aaa08474a]
        } else {
            [0xce2deec75ee1aa93, 0xe44adc1c480de49e, 0x1cedc622f99803ce]
        };
        assert_eq!(got, want);
    }

    /// The Maxwell branch's adjoint within the whole update: elastic and plastic EVP steps, with
    /// thixotropy, nu and Tait, spin, dt / t_M small and large, and at G_M = 0 (the effect's
    /// null, where the derivative in G_M is what the score test reads). State: the EVP's 8, then
    /// s_M.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_the_maxwell_branch_matches_central_differences() {
        use crate::material::test_util::check_update_adjoint;
        let spin = [0.3, -2.0, 0.5, 3.0, -0.4, 1.2, -0.7, 0.9, 0.2];
        let tait = Eos::Tait { gamma: 7.0 };
        let s_m = [30.0, -10.0, -20.0, 25.0, -8.0, 12.0];
        let evp_el = [100.0, -40.0, -60.0, 80.0, -30.0, 20.0, 0.0, 0.01];
        let evp_pl = [500.0, -200.0, -300.0, 400.0, -150.0, 250.0, 0.4, 0.3];
        let join = |a: [f64; 8], b: [f64; 6]| -> Vec<f64> { a.iter().chain(&b).copied().collect() };
        // (label, poisson, eos, params, L, J, dt, state)
        type Case = (&'static str, bool, Eos, [f64; 10], [f64; 9], f64, f64, Vec<f64>);
        let cases: Vec<Case> = vec![
            // J = 1: the pressure's round-off in the differences would swamp the derivative in t_M,
            // which is O(dt / t_M) small here (the plastic cases take J != 1)
            ("elastic, maxwell", false, Eos::Linear, [1e6, 2e5, 7.5, 630.0, 3.0, 0.0, 0.0, 400.0, 0.5, 1.0], spin, 1.0, 1e-3, join(evp_el, s_m)),
            ("plastic, maxwell, dt / t_M = 2", false, Eos::Linear, [1e6, 2e5, 7.5, 630.0, 3.0, 0.0, 0.0, 400.0, 5e-4, 1.0], spin.map(|x| 40.0 * x), 1.02, 1e-3, join(evp_pl, s_m)),
            ("plastic, thixotropic, nu, Tait, maxwell", true, tait, [1e6, 0.3, 7.5, 630.0, 50.0, 0.5, 0.2, 2e3, 0.1, 1.0], spin.map(|x| 40.0 * x), 0.99, 1e-3, join(evp_pl, s_m)),
            ("elastic, maxwell at its null G_M = 0", false, Eos::Linear, [1e6, 2e5, 7.5, 630.0, 3.0, 0.0, 0.0, 0.0, 1.0, 1.0], spin, 1.0, 1e-3, join(evp_el, [0.0; 6])),
            ("plastic, maxwell at its null G_M = 0", true, tait, [1e6, 0.3, 7.5, 630.0, 50.0, 0.5, 0.2, 0.0, 1.0, 1.0], spin.map(|x| 40.0 * x), 1.01, 1e-3, join(evp_pl, [0.0; 6])),
        ];
        let cases: Vec<(String, Case)> = [1.0, 0.6]
            .into_iter()
            .flat_map(|n| cases.iter().map(move |c| (format!("{}, n = {n}", c.0), { let mut c = c.clone(); c.3[9] = n; c })))
            .collect();
        for (k, (label, (_, poisson, eos, params, l, j, dt, state))) in cases.into_iter().enumerate() {
            let label = label.as_str();
            let mat = make(poisson, eos)(&params);
            assert_eq!((mat.state_names().len(), mat.param_names().len()), (14, 10));
            let mut st: Vec<Real> = state.clone();
            let _ = mat.update(&l_of(l), j, dt, &mut st);
            assert_eq!(st[7] > state[7], label.starts_with("plastic"), "{label}: branch");
            let state_scale: Vec<f64> = state.iter().map(|v| v.abs().max(1.0)).collect();
            let param_scale = [1e6, if poisson { 0.1 } else { params[1] }, 10.0, 500.0, 1e4, 1000.0, 1.0, 1e3, params[8], 0.1];
            check_update_adjoint(label, make(poisson, eos), &params, l_of(l), j, dt, &state, 1.0, &state_scale, &param_scale, 1e-6, 41 + k as u64);
        }
    }

    /// A particle's history under the material: random flow (yielding) with every fourth step at
    /// rest; returns every stress and the final state.
    fn history(m: &EvpBingham, steps: usize) -> (Vec<M3>, Vec<Real>) {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut u = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        };
        let mut st = vec![0.0 as Real; m.state_names().len()];
        m.init_state(&mut st);
        let stresses = (0..steps)
            .map(|step| {
                let l = if step % 4 == 3 { M3::ZERO } else { M3::from_cols(V3::new(u(), u(), u()), V3::new(u(), u(), u()), V3::new(u(), u(), u())) * 40.0 };
                m.update(&l, 1.0 + 0.01 * u(), 1e-3, &mut st)
            })
            .collect();
        (stresses, st)
    }

    #[test]
    fn a_zero_maxwell_modulus_is_the_material_without_the_branch() {
        let base = EvpBingham { a_thix: 0.8, alpha: 0.3, lambda0: 0.2, ..solid() };
        let null = EvpBingham { maxwell_modulus: Some(0.0), maxwell_time: 0.01, ..base.clone() };
        assert_eq!((base.state_names().len(), null.state_names().len()), (8, 14));
        assert_eq!(base.stability(), null.stability());
        let (s0, st0) = history(&base, 300);
        let (s1, st1) = history(&null, 300);
        assert!(st0[7] > 0.0, "the history must yield");
        // equal as numbers (a -0.0 of the EVP stress may come out +0.0 once 0 is added)
        assert_eq!(s0, s1);
        assert_eq!(st0[..], st1[..8]);
        assert!(st1[8..].iter().all(|&x| x == 0.0), "{:?}", &st1[8..]);
        // and the branch on does change it
        let (s2, _) = history(&EvpBingham { maxwell_modulus: Some(50.0), ..null }, 300);
        assert_ne!(s0, s2);
    }

    #[test]
    fn steady_flow_adds_eta_m_gamma_dot_to_the_bingham_stress() {
        // simple shear above yield at Weissenberg number t_M gamma_dot = 0.01; the Bingham part
        // tau0 + eta gamma_dot as in the test without the branch, the Maxwell part G_M t_M
        // gamma_dot (1 - exp(-t / t_M)) -> eta_M gamma_dot, to O(Wi^2)
        let (g_m, t_m) = (2000.0, 0.005);
        let m = EvpBingham { maxwell_modulus: Some(g_m), maxwell_time: t_m, ..solid() };
        let (g, dt) = (2.0 as Real, 1e-5 as Real);
        let mut st = vec![0.0 as Real; 14];
        m.init_state(&mut st);
        for n in 1..=10_000 {
            let s = m.update(&simple_shear(g), 1.0, dt, &mut st);
            let t = n as Real * dt;
            let maxwell = (g_m * t_m) as Real * g * (1.0 - (-t / t_m as Real).exp());
            if n == 250 || n == 10_000 {
                assert!(st[7] > 0.0, "flowing");
                assert!(rel(st[11], maxwell) < 2e-4, "t = {t}: s_M,xy {} vs {maxwell}", st[11]);
                let bingham = 100.0 + 30.0 * g;
                assert!(rel(s.y_axis.x, bingham + maxwell) < 2e-4, "t = {t}: {} vs {}", s.y_axis.x, bingham + maxwell);
            }
        }
        // eta_M gamma_dot = 20 Pa at steady state, on top of tau0 + eta gamma_dot = 160 Pa
        assert!(rel(st[11], 20.0) < 2e-4, "{}", st[11]);
    }

    #[test]
    fn with_the_branch_the_stress_at_rest_is_the_state_and_relaxes_at_rest() {
        // a yield stress the loading stays below: at rest the EVP stress then stays put (a
        // viscous overstress would relax plastically)
        let m = EvpBingham { yield_stress: 1e6, a_thix: 5e3, lambda0: 0.1, maxwell_modulus: Some(500.0), maxwell_time: 0.2, ..solid() };
        let mut st = vec![0.0 as Real; 14];
        m.init_state(&mut st);
        // elastic shear, loading both branches
        for _ in 0..100 {
            m.update(&simple_shear(0.5), 1.0, 1e-3, &mut st);
        }
        assert_eq!(st[7], 0.0, "elastic");
        let s_m0: Vec<Real> = st[8..].to_vec();
        let evp0: Vec<Real> = st[..6].to_vec();
        assert!(s_m0[3] > 0.0);
        let mut slept = st.clone();
        let (dt, n) = (1e-3 as Real, 300);
        let mut s = M3::ZERO;
        for _ in 0..n {
            s = m.update(&M3::ZERO, 1.0, dt, &mut st);
        }
        let bits = |a: &M3| a.to_cols_array().map(|x| x.to_bits());
        assert_eq!(bits(&m.stress_at_rest(&st, 1.0)), bits(&s));
        // the Maxwell stress relaxed by exp(-t / t_M), the EVP stress did not change
        let e = (-(n as Real) * dt / 0.2).exp();
        for k in 0..6 {
            assert!((st[8 + k] - s_m0[k] * e).abs() <= 1e-9 * s_m0[3].abs() || cfg!(feature = "f32"), "entry {k}");
            assert!((st[k] - evp0[k]).abs() <= 10.0 * EPS * evp0[3].abs(), "entry {k}");
        }
        // what a sleeping particle gets on waking
        m.rest_for(&mut slept, n as Real * dt);
        for k in 0..14 {
            assert!((slept[k] - st[k]).abs() <= 1e-4 * st[k].abs().max(1e-3), "entry {k}: {} vs {}", slept[k], st[k]);
        }
    }

    #[test]
    fn maxwell_keys_are_validated_and_stiffen_the_time_step() {
        let m = EvpBingham { maxwell_modulus: Some(300.0), ..solid() };
        assert!(m.validate().is_ok());
        assert_eq!(m.stability().shear_modulus, 1.0e6 + 300.0);
        let bad = EvpBingham { maxwell_modulus: Some(-1.0), ..solid() };
        assert_eq!(bad.validate().unwrap_err().to_string(), "material.maxwell_modulus must be >= 0, got -1");
        let bad = EvpBingham { maxwell_time: 0.0, ..m.clone() };
        assert_eq!(bad.validate().unwrap_err().to_string(), "material.maxwell_time must be > 0, got 0");
        assert_eq!(&m.param_names()[7..], ["maxwell_modulus", "maxwell_time", "flow_index"]);
        assert_eq!(&m.state_names()[8..], ["sM_xx", "sM_yy", "sM_zz", "sM_xy", "sM_yz", "sM_xz"]);
        assert_eq!((solid().param_names().len(), solid().state_names().len()), (8, 8));
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn the_initial_structuration_owes_its_adjoint_to_lambda0() {
        let m = make(false, Eos::Linear)(&[1e6, 2e5, 7.5, 630.0, 1.0, 0.5, 0.3, 1.0]);
        let mut p = [0.0; 8];
        m.init_state_adjoint(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.5, 1.0], &mut p);
        assert_eq!(p, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.5, 0.0]);
    }

    /// K = 2e6 + 2e3 a [Pa] (doubling in 1000 s), bilinear with a late rate 5e3 Pa/s beyond
    /// 600 s when asked; G follows K.
    fn ageing(bilinear: bool) -> EvpBingham {
        EvpBingham {
            bulk_modulus_rate: Some(2e3),
            bulk_modulus_late_rate: bilinear.then_some(5e3),
            bulk_modulus_transition_age: bilinear.then_some(600.0),
            ..solid()
        }
    }

    fn at_age(m: &EvpBingham, age: Real) -> Vec<Real> {
        let mut st = vec![0.0 as Real; m.state_names().len()];
        m.init_state(&mut st);
        st[m.age_slot()] = age;
        st
    }

    /// The same small load applied to a fresh particle early (100 s) and late (1000 s, past the
    /// kink): the stress it takes grows by the law's ratio K(1000) / K(100), the deviator (G
    /// follows K, with G or nu given) and the pressure alike, so the strain a given load makes
    /// shrinks by that ratio.
    #[test]
    fn a_growing_bulk_modulus_stiffens_the_elastic_response_by_the_law_ratio() {
        let l = M3::from_cols(V3::new(-2e-3, 1e-3, 0.0), V3::new(1e-3, 5e-4, 0.0), V3::new(0.0, 0.0, 3e-4));
        let (dt, j) = (1e-2 as Real, 0.999 as Real);
        for bilinear in [false, true] {
            for nu in [None, Some(0.3)] {
                let m = EvpBingham { shear_modulus: if nu.is_some() { None } else { Some(1e6) }, poisson_ratio: nu, ..ageing(bilinear) };
                assert!(m.validate().is_ok());
                let law = m.k_law().unwrap();
                let (mut early, mut late) = (at_age(&m, 100.0), at_age(&m, 1000.0));
                let (s_early, s_late) = (m.update(&l, j, dt, &mut early), m.update(&l, j, dt, &mut late));
                assert_eq!((early[7], late[7]), (0.0, 0.0), "elastic");
                let ratio = (law.value(1000.0) / law.value(100.0)) as Real;
                assert!(ratio > if bilinear { 2.3 } else { 1.8 });
                for (a, b) in s_early.to_cols_array().into_iter().zip(s_late.to_cols_array()) {
                    assert!((b - ratio * a).abs() <= 10.0 * EPS * b.abs().max(1.0), "{a} x {ratio} vs {b}");
                }
                // the age advanced by dt; without the law the response is the age-0 one
                assert_eq!(late[8], 1000.0 + dt);
                let mut fixed = fresh(&solid());
                let s0 = solid().update(&l, j, dt, &mut fixed);
                let k0 = (law.value(100.0) / 2e6) as Real;
                assert!((s_early.x_axis.x - k0 * s0.x_axis.x).abs() <= 10.0 * EPS * s0.x_axis.x.abs() || nu.is_some());
            }
        }
    }

    /// The rate form holds the stress through stiffening: a particle loaded elastically, then
    /// held (L = 0, J fixed) while its K grows fivefold, keeps its stress, the pressure too (a
    /// total form P(K(a), J) would raise it fivefold); sleeping over the same time
    /// (`rest_for_at`) holds it the same; `stress_at_rest` is `update`'s stress to the bit.
    #[test]
    fn the_rate_form_holds_the_stress_while_the_moduli_grow() {
        let m = EvpBingham { yield_stress: 1e5, ..ageing(true) };
        let j = 0.995 as Real;
        let mut st = at_age(&m, 10.0);
        let mut loaded = M3::ZERO;
        for _ in 0..10 {
            loaded = m.update(&simple_shear(0.5), j, 1e-3, &mut st);
        }
        assert_eq!(st[7], 0.0, "elastic");
        let mut slept = st.clone();
        let (dt, n) = (1.0 as Real, 3000);
        let mut held = M3::ZERO;
        for _ in 0..n {
            held = m.update(&M3::ZERO, j, dt, &mut st);
        }
        let law = m.k_law().unwrap();
        #[allow(clippy::unnecessary_cast)] // f32 build
        let age = st[8] as f64;
        assert!(law.value(age) > 5.0 * law.value(10.0));
        let tol = if cfg!(feature = "f32") { 1e-4 } else { 1e-10 };
        let p0 = -trace(&loaded) / 3.0;
        assert!(p0 > 0.0);
        for (a, b) in loaded.to_cols_array().into_iter().zip(held.to_cols_array()) {
            assert!((a - b).abs() <= tol * p0, "{a} vs {b}");
        }
        let bits = |a: &M3| a.to_cols_array().map(|x| x.to_bits());
        assert_eq!(bits(&m.stress_at_rest(&st, j)), bits(&held));
        m.rest_for_at(&mut slept, n as Real * dt, j);
        assert!((slept[8] - st[8]).abs() <= 1e-6 * st[8]);
        let rested = m.stress_at_rest(&slept, j);
        for (a, b) in loaded.to_cols_array().into_iter().zip(rested.to_cols_array()) {
            assert!((a - b).abs() <= tol * p0, "{a} vs {b}");
        }
        // without J, `rest_for` is the particle at J = 1: it ages, its held pressure unchanged
        let mut unloaded = at_age(&m, 10.0);
        m.rest_for(&mut unloaded, 5.0);
        assert_eq!((unloaded[8], unloaded[9]), (15.0, 0.0));
    }

    /// A law at rest (rate 0) is the material without the law, as numbers, with the age and the
    /// held pressure (0) in the state; the law on changes it.
    #[test]
    fn a_zero_rate_is_the_material_without_the_law() {
        let base = EvpBingham { a_thix: 0.8, alpha: 0.3, lambda0: 0.2, eos: Eos::Tait { gamma: 7.0 }, ..solid() };
        let null = EvpBingham { bulk_modulus_rate: Some(0.0), age_at_start: Some(60.0), ..base.clone() };
        assert!(null.validate().is_ok());
        assert_eq!((base.state_names().len(), null.state_names().len()), (8, 10));
        assert_eq!(base.stability(), null.stability_at(1e4));
        let (s0, st0) = history(&base, 300);
        let (s1, st1) = history(&null, 300);
        assert_eq!(s0, s1);
        assert_eq!(st0[..], st1[..8]);
        assert_eq!(st1[9], 0.0);
        // (f32: each 1 ms rounds to the age's spacing at 60 s, 3.8e-6 s)
        assert!((st1[8] - (60.0 + 0.3)).abs() < if cfg!(feature = "f32") { 1e-3 } else { 1e-9 });
        let (s2, _) = history(&EvpBingham { bulk_modulus_rate: Some(1e3), ..null }, 300);
        assert_ne!(s0, s2);
        // with the Maxwell branch the age follows its state
        let both = EvpBingham { maxwell_modulus: Some(10.0), ..ageing(false) };
        assert_eq!(&both.state_names()[14..], ["age", "p_held"]);
        assert_eq!(both.age_slot(), 14);
    }

    /// The stiffest moduli over the ages a particle can have by `time`, capped at `max_age`.
    #[test]
    fn the_time_step_sees_the_stiffest_age() {
        let m = EvpBingham { age_at_start: Some(100.0), maxwell_modulus: Some(300.0), ..ageing(true) };
        assert!(m.validate().is_ok());
        let law = m.k_law().unwrap();
        let at = |a: f64| (law.value(a) as Real, (1e6 * law.value(a) / 2e6 + 300.0) as Real);
        let pair = |s: StabilityInfo| (s.bulk_modulus, s.shear_modulus);
        assert_eq!(pair(m.stability()), at(100.0));
        assert_eq!(m.stability(), m.stability_at(0.0));
        assert_eq!(pair(m.stability_at(900.0)), at(1000.0));
        let capped = EvpBingham { max_age: Some(700.0), ..m.clone() };
        assert_eq!(pair(capped.stability_at(900.0)), at(700.0));
        // past max_age the law stops: a step at 5000 s is a step at 700 s
        let l = M3::from_diagonal(V3::new(-1e-3, 0.0, 0.0));
        let (mut a, mut b) = (at_age(&capped, 5000.0), at_age(&capped, 700.0));
        assert_eq!(capped.update(&l, 0.99, 1.0, &mut a), capped.update(&l, 0.99, 1.0, &mut b));
        // a falling-then-rising law: the bound is the largest value, not the last
        let dip = EvpBingham { bulk_modulus_rate: Some(-1e3), bulk_modulus_late_rate: Some(500.0), bulk_modulus_transition_age: Some(1000.0), ..solid() };
        assert!(dip.validate().is_ok());
        assert_eq!(dip.stability_at(2500.0).bulk_modulus, 2e6);
    }

    #[test]
    fn age_law_keys_are_validated_by_name() {
        let msg = |m: EvpBingham| m.validate().unwrap_err().to_string();
        assert!(ageing(true).validate().is_ok());
        assert!(msg(EvpBingham { bulk_modulus_rate: Some(-3e3), ..solid() }).starts_with("material.bulk_modulus (with its rates) must be > 0 at every age"));
        assert!(EvpBingham { bulk_modulus_rate: Some(-3e3), max_age: Some(600.0), ..solid() }.validate().is_ok());
        assert!(msg(EvpBingham { bulk_modulus_rate: Some(f64::NAN), ..solid() }).starts_with("material.bulk_modulus_rate must be finite"));
        assert!(msg(EvpBingham { bulk_modulus_late_rate: None, ..ageing(true) }).starts_with("material.bulk_modulus_late_rate is required"));
        assert!(msg(EvpBingham { bulk_modulus_transition_age: None, ..ageing(true) }).starts_with("material.bulk_modulus_transition_age is required"));
        assert!(msg(EvpBingham { bulk_modulus_transition_age: Some(-1.0), ..ageing(true) }).starts_with("material.bulk_modulus_transition_age must be >= 0"));
        assert!(msg(EvpBingham { age_at_start: Some(-1.0), ..ageing(false) }).starts_with("material.age_at_start must be >= 0"));
        assert!(msg(EvpBingham { max_age: Some(0.0), ..ageing(false) }).starts_with("material.max_age must be finite and > age_at_start"));
        for (m, key) in [
            (EvpBingham { age_at_start: Some(10.0), ..solid() }, "material.age_at_start"),
            (EvpBingham { max_age: Some(10.0), ..solid() }, "material.max_age"),
            (EvpBingham { bulk_modulus_late_rate: Some(1.0), bulk_modulus_transition_age: Some(5.0), ..solid() }, "material.bulk_modulus_late_rate"),
        ] {
            assert_eq!(msg(m), format!("material.bulk_modulus_rate is required when {key}: the bulk modulus's age law is on only with its rate (0 for a law at rest)"));
        }
        assert_eq!(&ageing(false).param_names()[8..], ["bulk_modulus_rate", "age_at_start"]);
        let names = EvpBingham { maxwell_modulus: Some(1.0), shear_modulus: None, poisson_ratio: Some(0.3), ..ageing(true) }.param_names();
        assert_eq!(names[1], "poisson_ratio");
        assert_eq!(&names[10..], ["bulk_modulus_rate", "bulk_modulus_late_rate", "bulk_modulus_transition_age", "age_at_start"]);
    }

    /// The ageing material from parameter values in `param_names` order: the kind's own (8, or
    /// 10 with the Maxwell branch), then the law's (rate; late rate and transition age when
    /// bilinear) and `age_at_start`.
    #[cfg(not(feature = "f32"))]
    fn make_aged(poisson: bool, eos: Eos, maxwell: bool, bilinear: bool, max_age: Option<f64>) -> impl Fn(&[f64]) -> EvpBingham {
        move |p: &[f64]| {
            let nb = if maxwell { 10 } else { 8 };
            let q = &p[nb..];
            EvpBingham {
                bulk_modulus_rate: Some(q[0]),
                bulk_modulus_late_rate: bilinear.then(|| q[1]),
                bulk_modulus_transition_age: bilinear.then(|| q[2]),
                age_at_start: Some(q[q.len() - 1]),
                max_age,
                ..make(poisson, eos)(&p[..nb])
            }
        }
    }

    /// Central differences and the Taylor test of one step with the age law, at ages before,
    /// just before and after the kink at 600 s and past `max_age`: elastic and plastic, G or nu
    /// given (K0 enters G twice with G0), both equations of state, with the Maxwell branch.
    /// State: the kind's, then the age and the held pressure.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_with_the_age_law_matches_central_differences_across_the_kink() {
        use crate::material::test_util::check_update_adjoint;
        let spin = [0.3, -2.0, 0.5, 3.0, -0.4, 1.2, -0.7, 0.9, 0.2];
        let tait = Eos::Tait { gamma: 7.0 };
        let evp_el = vec![100.0, -40.0, -60.0, 80.0, -30.0, 20.0, 0.0, 0.01];
        let evp_pl = vec![500.0, -200.0, -300.0, 400.0, -150.0, 250.0, 0.4, 0.3];
        // (label, poisson, eos, maxwell, bilinear, max_age, L scale, J, EVP state)
        type Case = (&'static str, bool, Eos, bool, bool, Option<f64>, f64, f64, Vec<f64>);
        let cases: Vec<Case> = vec![
            ("elastic, linear", false, Eos::Linear, false, false, None, 0.1, 0.98, evp_el.clone()),
            ("elastic, bilinear, nu", true, Eos::Linear, false, true, None, 0.1, 1.02, evp_el.clone()),
            ("plastic, bilinear", false, tait, false, true, None, 40.0, 0.99, evp_pl.clone()),
            ("plastic, bilinear, nu, Tait", true, tait, false, true, None, 40.0, 1.01, evp_pl.clone()),
            ("elastic, bilinear, maxwell", false, Eos::Linear, true, true, None, 0.1, 0.99, evp_el.clone()),
            ("plastic, bilinear, max_age", true, Eos::Linear, false, true, Some(800.0), 40.0, 0.98, evp_pl.clone()),
        ];
        let mut seed = 200;
        for (label, poisson, eos, maxwell, bilinear, max_age, scale, j, evp) in cases {
            let mut params = vec![2e6, if poisson { 0.45 } else { 1e5 }, 7.5, 630.0, 50.0, 0.5, 0.2];
            if maxwell {
                params.extend([400.0, 0.5]);
            }
            params.push(1.0);
            params.push(2e3);
            if bilinear {
                params.extend([5e3, 600.0]);
            }
            params.push(30.0);
            let make = make_aged(poisson, eos, maxwell, bilinear, max_age);
            assert!(make(&params).validate().is_ok(), "{label}");
            for age in [300.0, 599.0, 900.0] {
                seed += 1;
                let mut state = evp.clone();
                if maxwell {
                    state.extend([30.0, -10.0, -20.0, 25.0, -8.0, 12.0]);
                }
                state.extend([age, -350.0]);
                let m = make(&params);
                let l = l_of(spin.map(|x| scale * x));
                let mut st = state.clone();
                m.update(&l, j, 1e-3, &mut st);
                assert_eq!(st[7] > state[7], label.starts_with("plastic"), "{label} at {age} s: branch");
                let mut state_scale: Vec<f64> = state.iter().map(|v| v.abs().max(1.0)).collect();
                let n = state.len();
                state_scale[n - 2] = 1.0;
                let mut param_scale: Vec<f64> = params.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
                // as in the tests without the law: K and G (or nu) over their whole size, so the
                // differences of their small derivatives in one step stay above rounding
                param_scale[..7].copy_from_slice(&[1e6, if poisson { 0.1 } else { params[1] }, 10.0, 500.0, 1e4, 1000.0, 1.0]);
                if maxwell {
                    param_scale[7..9].copy_from_slice(&[1e3, params[8]]);
                }
                let nb = if maxwell { 10 } else { 8 };
                if bilinear {
                    // the transition age: well inside the 1 s between it and the nearest age
                    param_scale[nb + 2] = 0.5;
                }
                // the rates reach one step only through the age: a larger step keeps their
                // differences above rounding
                for x in &mut param_scale[nb..nb + if bilinear { 2 } else { 1 }] {
                    *x *= 10.0;
                }
                check_update_adjoint(&format!("{label}, age {age} s"), &make, &params, l, j, 1e-3, &state, 1.0, &state_scale, &param_scale, 1e-6, seed);
            }
        }
    }

    /// A run of 60 steps of 2 s from `age_at_start` = 550 s, through the kink at 601 s and from
    /// elastic into plastic loading with J varying, as a map from all the parameters to the
    /// final stress and state; its adjoint is the steps' adjoints run backwards, then
    /// `init_state_adjoint`. Central differences per parameter, and the Taylor remainder over
    /// all of them at once falling as h^2.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn taylor_test_with_the_age_law_over_a_multi_step_sequence() {
        use crate::adjoint_check::{group_errors, slow_loading, taylor_slope, MaterialRun, Rng};
        // a slow loading with J wavering: elastic first, then flowing; the kink at 601 s falls
        // between the steps at 600 and 602 s; a viscosity of the order of G dt, so that it and
        // the flow index reach the result above rounding
        let ls = slow_loading(60, 0.25);
        let js: Vec<Real> = (0..60).map(|k| 1.0 - 1e-3 * (1.0 + (k as f64 * 0.7).sin())).collect();
        for poisson in [false, true] {
            let x = vec![1e5, if poisson { 0.3 } else { 4e4 }, 5e4, 630.0, 2.0, 0.5, 0.2, 1.0, 100.0, 400.0, 601.0, 550.0];
            let make = make_aged(poisson, Eos::Tait { gamma: 7.0 }, false, true, None);
            let run = MaterialRun::new(make, ls.iter().copied().zip(js.iter().copied()).collect(), 2.0, &x);
            let (states, _) = run.states(&x);
            let last = states.last().unwrap();
            assert!(last[7] > 0.0 && states[3][7] == 0.0, "elastic first, then plastic: gamma_p {} -> {}", states[3][7], last[7]);
            assert!((last[8] - 670.0).abs() < 1e-9 && last[9] != 0.0);
            let mut scale: Vec<f64> = x.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
            // ages: inside the 1 s between the kink and the nearest step
            scale[10] = 0.5;
            scale[11] = 0.5;
            let mut rng = Rng(7);
            let errs = group_errors(&run, &x, &scale, &mut rng);
            println!("multi-step, nu {poisson}: {errs:?}");
            for (name, e) in &errs {
                assert!(*e < 1e-5, "{name}: adjoint vs central differences {e:.1e}");
            }
            let slope = taylor_slope(&run, &x, &scale, &mut rng).expect("curved along the direction");
            println!("multi-step Taylor remainder slope {slope:.3}");
            assert!(slope > 1.9, "Taylor remainder slope {slope:.3}");
        }
    }

    /// Waking without an age law or a Maxwell branch: lambda built up by the rest, the stress at
    /// rest the held deviator less p(K, J).
    #[cfg(not(feature = "f32"))]
    #[test]
    fn wake_adjoint_matches_central_differences() {
        use crate::material::test_util::check_wake_adjoint;
        let state = [100.0, -40.0, -60.0, 80.0, -30.0, 20.0, 0.4, 0.01];
        let state_scale: Vec<f64> = state.iter().map(|v: &f64| 0.1 * v.abs().max(1e-2)).collect();
        for (k, (poisson, eos)) in [(false, Eos::Linear), (true, Eos::Tait { gamma: 7.0 })].into_iter().enumerate() {
            let params = [1e6, if poisson { 0.3 } else { 2e5 }, 7.5, 630.0, 50.0, 0.5, 0.2, 1.0];
            let scale = params.map(|v| 0.1 * v);
            check_wake_adjoint("evp_bingham", make(poisson, eos), &params, 0.99, 2.0, &state, &state_scale, &scale, 1e-6, 71 + k as u64);
        }
    }
}
