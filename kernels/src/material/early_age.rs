//! Early-age solid: a printed concrete that stiffens and strengthens where it lies. Elastic up to
//! the Mohr-Coulomb-matched Drucker-Prager cone with tension cutoff of `drucker_prager.rs`, whose
//! return map (and its adjoint) it runs on constants built per particle from the particle's age.
//!
//! The age a of a particle [s] is the time since its creation plus the mix's age when the print
//! started, `age_at_start`. A printed particle is created where it enters the nozzle's tube, so
//! the time it spends in the tube (tube height over extrusion speed while printing, and all of a
//! pause) counts: not yet the time since it left the outlet. The Young's modulus E, the cohesion c and the
//! friction angle phi each follow an [`AgeLaw`] of a, linear (p0 + r a) or bilinear (a slow early
//! rate up to a transition age, a faster one beyond; Kruger et al.); the Poisson ratio nu is
//! constant, so K = E / (3 (1 - 2 nu)) and G = 3 K (1 - 2 nu) / (2 (1 + nu)) = E / (2 (1 + nu))
//! follow E. The laws are written in the age, not the print time, so a layer printed late is as
//! young when it leaves the nozzle as the first one was.
//!
//! Rules, and why:
//! * **Age at the start of the step.** `update` builds the constants from the age held in the
//!   state (the age at the step's start), then advances it by dt: an explicit step reads the
//!   material as it was when the step began, like every other state variable; a new particle's
//!   first step sees the fresh mix (p(age_at_start)); and no particle is older than
//!   `age_at_start + t` during the step that starts at time t, the bound
//!   [`Material::stability_at`] gives the time step. The difference to the end-of-step age is
//!   dt r, one step of the law.
//! * **Stress under stiffening: the rate form.** The trial stress is sigma_tr = R sigma R^T +
//!   dt C(a) : D with the stiffness of the particle's age: the stress already built is kept, not
//!   rescaled as E grows (a total form sigma = C(a) : eps would raise the stress of a loaded layer
//!   as it hardens, without any new strain). A solidifying material stores the stress of the
//!   strain increments it took with the stiffness it had when it took them; the new solid
//!   skeleton forms around the deformed state, stress-free (Bazant's solidification theory). So
//!   the elastic stress increment of a step uses E(age), and a constant strain held leaves the
//!   stress constant however stiff the particle becomes.
//! * **Tension cutoff.** `tension_cutoff` (if given) is capped by the cone apex c cot(phi) at the
//!   particle's age: sigma_t = min(tension_cutoff, apex(a)), so the cutoff needs no check against
//!   an apex that moves with age; without it, sigma_t is the apex.
//! * **max_age** (optional): the age the laws stop at; an older particle keeps the parameters of
//!   `max_age`. It bounds the ages the laws are checked over (a friction angle growing without
//!   end would pass 90 deg), and is not differentiated (the age, held fixed, is then
//!   `max_age`, and the laws' derivative in age is 0).
//! * **Sleeping.** `rest_for` ages the particle by the time it slept (the material keeps ageing
//!   while it sleeps). `yield_margin` is the held stress's distance to the cone or the cutoff of
//!   its age, and `column_loads` is on: a sleeping unit wakes when the load its column added on it
//!   since it fell asleep nears that margin (module notes of `src/sleep/`), not under any load
//!   (which woke the whole wall under every new layer); waking, it takes that load in its stress
//!   (`take_column_load`). `strength_gain` stays 0 (a lower bound).
//!
//! Adjoint: the return map's adjoint gives the adjoints of the constants; [`Cone::adjoint`]
//! chains them to (K, G, phi, psi, c, cutoff), and those to the law parameters at the particle's
//! age and, through each law's slope, to the age before the step (which then flows back, step by
//! step, to `age_at_start` through `init_state_adjoint`). At a law's kink and at the cutoff's
//! `min` the derivative is that of the branch taken.
//!
//! Per-particle state (8 reals): `[sigma_xx, sigma_yy, sigma_zz, sigma_xy, sigma_yz, sigma_xz,
//! eps_p, age]` — the Cauchy stress [Pa], the equivalent plastic strain [-] (as
//! `drucker_prager`) and the age [s]. In the f32 build the age is an f32: an increment dt below
//! half its spacing (1.2e-4 s at an age of one hour) is lost, so long f32 runs with small steps
//! under-age the material; the f64 build resolves 1e-12 s at that age.

use std::sync::OnceLock;

use serde::Deserialize;

use crate::material::age_law::{bare, check_ages, law_age, AgeLaw, LawKeys};
use crate::material::drucker_prager::{apex, return_map, return_map_adjoint, return_map_batch, yield_margin, Angles, Cone, ConeMatch, Consts};
use crate::material::eos::{shear_modulus_of, shear_modulus_of_partials};
use crate::material::{non_negative, positive, Material, MaterialError, StabilityInfo, UpdateAdjoint};
use crate::real::{r, sym_from_slice, Real, M3};

/// The per-particle state (module notes).
const STATE_NAMES: [&str; 8] = ["sigma_xx", "sigma_yy", "sigma_zz", "sigma_xy", "sigma_yz", "sigma_xz", "eps_p", "age"];
const STATE_LEN: usize = STATE_NAMES.len();

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EarlyAgeSolid {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Poisson's ratio nu [-], constant.
    pub poisson_ratio: f64,
    /// Young's modulus at age 0, E0 [Pa].
    pub youngs_modulus: f64,
    /// dE/da [Pa/s] (up to the transition age when bilinear).
    #[serde(default)]
    pub youngs_modulus_rate: f64,
    /// dE/da beyond `youngs_modulus_transition_age` [Pa/s].
    #[serde(default)]
    pub youngs_modulus_late_rate: Option<f64>,
    /// Age where E's rate changes [s].
    #[serde(default)]
    pub youngs_modulus_transition_age: Option<f64>,
    /// Cohesion at age 0 [Pa].
    #[serde(default)]
    pub cohesion: f64,
    /// dc/da [Pa/s].
    #[serde(default)]
    pub cohesion_rate: f64,
    /// dc/da beyond `cohesion_transition_age` [Pa/s].
    #[serde(default)]
    pub cohesion_late_rate: Option<f64>,
    /// [s].
    #[serde(default)]
    pub cohesion_transition_age: Option<f64>,
    /// Friction angle at age 0 [deg].
    pub friction_angle_deg: f64,
    /// dphi/da [deg/s].
    #[serde(default)]
    pub friction_angle_rate: f64,
    /// dphi/da beyond `friction_angle_transition_age` [deg/s].
    #[serde(default)]
    pub friction_angle_late_rate: Option<f64>,
    /// [s].
    #[serde(default)]
    pub friction_angle_transition_age: Option<f64>,
    /// Dilatancy angle psi [deg], constant, 0 <= psi <= phi at every age.
    #[serde(default)]
    pub dilatancy_angle_deg: f64,
    /// Tensile strength of the mean stress [Pa], capped by the apex c cot(phi) at each age;
    /// absent: the apex.
    #[serde(default)]
    pub tension_cutoff: Option<f64>,
    /// The mix's age when the print starts [s]: every particle's age at its creation.
    #[serde(default)]
    pub age_at_start: f64,
    /// The age the laws stop at [s] (older particles keep its parameters); absent: none.
    #[serde(default)]
    pub max_age: Option<f64>,
    /// The Mohr-Coulomb vertices the cone passes through at every age: `extension` (the
    /// default) or `compression` (`drucker_prager.rs`).
    #[serde(default)]
    pub cone_match: ConeMatch,
}

const E_KEYS: LawKeys = LawKeys {
    value: "material.youngs_modulus",
    rate: "material.youngs_modulus_rate",
    late_rate: "material.youngs_modulus_late_rate",
    transition_age: "material.youngs_modulus_transition_age",
};
const C_KEYS: LawKeys = LawKeys {
    value: "material.cohesion",
    rate: "material.cohesion_rate",
    late_rate: "material.cohesion_late_rate",
    transition_age: "material.cohesion_transition_age",
};
const PHI_KEYS: LawKeys = LawKeys {
    value: "material.friction_angle_deg",
    rate: "material.friction_angle_rate",
    late_rate: "material.friction_angle_late_rate",
    transition_age: "material.friction_angle_transition_age",
};

/// Where each parameter sits in `param_names`: each law takes 2 slots (value, rate), 4 when
/// bilinear (late rate, transition age); then nu, psi, age_at_start and the cutoff if given.
#[derive(Clone, Copy, Debug)]
struct Layout {
    e: usize,
    c: usize,
    phi: usize,
    nu: usize,
    psi: usize,
    age0: usize,
    cut: Option<usize>,
}

impl EarlyAgeSolid {
    fn e_law(&self) -> AgeLaw {
        AgeLaw { p0: self.youngs_modulus, rate: self.youngs_modulus_rate, late: self.youngs_modulus_late_rate.zip(self.youngs_modulus_transition_age) }
    }

    fn c_law(&self) -> AgeLaw {
        AgeLaw { p0: self.cohesion, rate: self.cohesion_rate, late: self.cohesion_late_rate.zip(self.cohesion_transition_age) }
    }

    fn phi_law(&self) -> AgeLaw {
        AgeLaw { p0: self.friction_angle_deg, rate: self.friction_angle_rate, late: self.friction_angle_late_rate.zip(self.friction_angle_transition_age) }
    }

    fn layout(&self) -> Layout {
        let width = |law: AgeLaw| if law.late.is_some() { 4 } else { 2 };
        let e = 0;
        let c = e + width(self.e_law());
        let phi = c + width(self.c_law());
        let nu = phi + width(self.phi_law());
        Layout { e, c, phi, nu, psi: nu + 1, age0: nu + 2, cut: self.tension_cutoff.map(|_| nu + 3) }
    }

    /// The age the laws are evaluated at, and whether it is the particle's.
    #[inline]
    fn law_age(&self, age: f64) -> (f64, bool) {
        law_age(age, self.max_age)
    }

    /// K from E and nu.
    #[inline]
    fn bulk_of(&self, e: f64) -> f64 {
        e / (3.0 * (1.0 - 2.0 * self.poisson_ratio))
    }

    /// The return map's inputs at a particle's age.
    #[inline]
    fn cone_at(&self, age: f64) -> Cone {
        self.cone_at_with(age, None)
    }

    /// The trigonometry of the cone's angles when the friction angle does not change with age
    /// (its rates are zero), the same at every age.
    fn fixed_angles(&self) -> Option<Angles> {
        let phi = self.phi_law();
        let fixed = phi.rate == 0.0 && phi.late.is_none_or(|(late, _)| late == 0.0);
        // p0 + 0 a is p0 + 0 at every finite age: value(0) is every age's angle to the bit
        fixed.then(|| Angles::of(phi.value(0.0), self.dilatancy_angle_deg, self.cone_match))
    }

    /// [`EarlyAgeSolid::cone_at`], the apex taken from `fixed` when given (the angles'
    /// trigonometry, from [`EarlyAgeSolid::fixed_angles`]).
    #[inline]
    fn cone_at_with(&self, age: f64, fixed: Option<&Angles>) -> Cone {
        let (a, _) = self.law_age(age);
        let k = self.bulk_of(self.e_law().value(a));
        let (phi, c) = (self.phi_law().value(a), self.c_law().value(a));
        Cone {
            k,
            g: shear_modulus_of(k, None, Some(self.poisson_ratio)),
            phi_deg: phi,
            psi_deg: self.dilatancy_angle_deg,
            cohesion: c,
            // sigma_t = min(tension_cutoff, apex): the apex branch is `None`
            cutoff: self.tension_cutoff.filter(|&t| t <= fixed.map_or_else(|| apex(c, phi), |f| f.apex(c))),
            matched: self.cone_match,
        }
    }

    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        let nu = self.poisson_ratio;
        if !(nu.is_finite() && nu > -1.0 && nu < 0.5) {
            return Err(MaterialError::out_of_range("material.poisson_ratio", "in (-1, 0.5)", nu));
        }
        let span = check_ages(self.age_at_start, self.max_age)?;
        let a0 = self.age_at_start;
        let a1 = self.max_age.unwrap_or(f64::INFINITY);
        E_KEYS.check(self.youngs_modulus, self.youngs_modulus_rate, self.youngs_modulus_late_rate, self.youngs_modulus_transition_age)?;
        C_KEYS.check(self.cohesion, self.cohesion_rate, self.cohesion_late_rate, self.cohesion_transition_age)?;
        PHI_KEYS.check(self.friction_angle_deg, self.friction_angle_rate, self.friction_angle_late_rate, self.friction_angle_transition_age)?;
        let (e, c, phi) = (self.e_law(), self.c_law(), self.phi_law());
        let e_min = e.min_over(a0, a1);
        if e_min.is_nan() || e_min <= 0.0 {
            return Err(MaterialError::out_of_range("material.youngs_modulus (with its rates)", format!("> 0 {span}"), e_min));
        }
        let c_min = c.min_over(a0, a1);
        if c_min.is_nan() || c_min < 0.0 {
            return Err(MaterialError::out_of_range("material.cohesion (with its rates)", format!(">= 0 {span}"), c_min));
        }
        let (phi_min, phi_max) = (phi.min_over(a0, a1), phi.max_over(a0, a1));
        if phi_min.is_nan() || phi_min < 0.0 {
            return Err(MaterialError::out_of_range("material.friction_angle_deg (with its rates)", format!(">= 0 {span}"), phi_min));
        }
        if phi_max.is_nan() || phi_max >= 90.0 {
            return Err(MaterialError::out_of_range("material.friction_angle_deg (with its rates)", format!("< 90 {span}"), phi_max));
        }
        let psi = self.dilatancy_angle_deg;
        if !(psi.is_finite() && psi >= 0.0 && psi <= phi_min) {
            return Err(MaterialError::out_of_range(
                "material.dilatancy_angle_deg",
                format!("in [0, the smallest friction angle = {phi_min}] {span}"),
                psi,
            ));
        }
        // c + phi is piecewise linear and >= 0 with non-falling tails (checked above): it is 0
        // somewhere only if it is 0 at an end or a kink
        let mut ages = vec![a0];
        ages.extend([c.late, phi.late].into_iter().flatten().map(|(_, at)| at).filter(|&at| at > a0 && at < a1));
        if a1.is_finite() {
            ages.push(a1);
        }
        if ages.iter().any(|&a| c.value(a) <= 0.0 && phi.value(a) <= 0.0) {
            return Err(MaterialError::NoShearStrength);
        }
        if let Some(t) = self.tension_cutoff {
            non_negative("material.tension_cutoff", t)?;
        }
        Ok(())
    }

    /// Chain the adjoints of the return map's constants, at the particle's age `age`, to the
    /// parameters (`params_bar`, in `param_names` order) and return the adjoint of the age.
    fn consts_adjoint(&self, age: f64, cone: &Cone, bar: [Real; 7], params_bar: &mut [Real]) -> f64 {
        let [k_bar, g_bar, phi_bar, psi_bar, c_bar, cut_bar] = cone.adjoint(bar);
        let nu = self.poisson_ratio;
        // G = 3 K (1 - 2 nu) / (2 (1 + nu)), K = E / (3 (1 - 2 nu))
        let (dg_dk, dg_dnu) = shear_modulus_of_partials(cone.k, nu);
        let k_total = k_bar + g_bar * dg_dk;
        let e_bar = k_total / (3.0 * (1.0 - 2.0 * nu));
        let nu_bar = g_bar * dg_dnu + k_total * 2.0 * cone.k / (1.0 - 2.0 * nu);
        let lay = self.layout();
        let (a, ages) = self.law_age(age);
        let mut age_bar = 0.0;
        for (law, start, p_bar) in [(self.e_law(), lay.e, e_bar), (self.c_law(), lay.c, c_bar), (self.phi_law(), lay.phi, phi_bar)] {
            let n = if law.late.is_some() { 4 } else { 2 };
            for (i, d) in law.partials(a).into_iter().take(n).enumerate() {
                params_bar[start + i] += (p_bar * d) as Real;
            }
            if ages {
                age_bar += p_bar * law.rate_at(a);
            }
        }
        params_bar[lay.nu] += nu_bar as Real;
        params_bar[lay.psi] += psi_bar as Real;
        if let (Some(i), Some(_)) = (lay.cut, cone.cutoff) {
            params_bar[i] += cut_bar as Real;
        }
        age_bar
    }
}

impl Material for EarlyAgeSolid {
    fn name(&self) -> &'static str {
        "early_age_solid"
    }

    fn state_names(&self) -> &'static [&'static str] {
        &STATE_NAMES
    }

    /// Stress-free, no plastic strain, the mix's age.
    fn init_state(&self, state: &mut [Real]) {
        state[..7].fill(r(0.0));
        state[7] = r(self.age_at_start);
    }

    /// The return map on the constants of the age at the step's start; then the age advances.
    #[inline]
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn update(&self, grad_v: &M3, _j: Real, dt: Real, state: &mut [Real]) -> M3 {
        let c = self.cone_at(state[7] as f64).consts();
        let sigma = return_map(&c, grad_v, dt, state);
        state[7] += dt;
        sigma
    }

    /// Same as `update` particle by particle, with the constants of the return map built once
    /// for a run of particles of one age (particles laid in one step share their age to the bit:
    /// 86 % of the particles of the printed cylinder of bench/cylinder.py follow one of their own
    /// age in the pool), the trigonometry of a friction angle that does not change with age once
    /// per batch, and the elastic steps in lanes (`drucker_prager_lanes.rs`).
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn update_batch(&self, grad_v: &[M3], _j: &[Real], dt: Real, state: &mut [Real], stress: &mut [M3]) {
        let fixed = self.fixed_angles();
        // the age whose constants `last` holds: built from the same bits, they are the same
        let mut last: Option<(Real, Consts)> = None;
        return_map_batch(grad_v, dt, state, STATE_LEN, stress, |st| {
            let age = st[7];
            match last {
                Some((a, c)) if a.to_bits() == age.to_bits() => c,
                _ => {
                    let cone = self.cone_at_with(age as f64, fixed.as_ref());
                    let c = match &fixed {
                        Some(angles) => cone.consts_with(angles),
                        None => cone.consts(),
                    };
                    last = Some((age, c));
                    c
                }
            }
        });
        // the age advances after the step that read it
        for st in state.chunks_exact_mut(STATE_LEN).take(grad_v.len()) {
            st[7] += dt;
        }
    }

    fn stress_at_rest(&self, state: &[Real], _j: Real) -> M3 {
        // the full Cauchy stress is the state (the pressure is not an EOS of J)
        sym_from_slice(&state[..6])
    }

    /// Sleeping material keeps ageing.
    fn rest_for(&self, state: &mut [Real], duration: Real) {
        state[7] += duration;
    }

    /// The distance of the held stress to the cone or the cutoff of the particle's age, at its
    /// mean stress (`drucker_prager::yield_margin`). Why not 0 (any load wakes): a layer
    /// at rest under the ones above it then sleeps until their added weight nears its strength,
    /// instead of waking with the whole wall under every new layer (the printed cylinder,
    /// BENCHMARKS.md). `strength_gain` stays 0: the cohesion's growth while asleep is left out
    /// of the margin, which keeps it a lower bound.
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn yield_margin(&self, state: &[Real]) -> Real {
        yield_margin(&self.cone_at(state[7] as f64).consts(), state)
    }

    /// Its margin is many layers' weight: the column's load must reach the deep units.
    fn column_loads(&self) -> bool {
        true
    }

    /// The held stress takes the column's added weight as a uniaxial compression along the
    /// down axis (a free-standing wall under a vertical load), on top of what it held.
    fn take_column_load(&self, state: &mut [Real], axis: usize, traction: Real) {
        state[axis] -= traction;
    }

    fn stability(&self) -> StabilityInfo {
        self.stability_at(0.0)
    }

    /// The stiffest E over the ages [age_at_start, age_at_start + time] (capped at `max_age`):
    /// no particle is older than that during the step starting at `time`, and `update` reads the
    /// age at the step's start.
    fn stability_at(&self, time: f64) -> StabilityInfo {
        let a0 = self.age_at_start;
        let a1 = self.law_age(a0 + time.max(0.0)).0;
        let k = self.bulk_of(self.e_law().max_over(a0, a1));
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(k),
            shear_modulus: r(shear_modulus_of(k, None, Some(self.poisson_ratio))),
            max_viscosity: r(0.0),
            thickening: None,
        }
    }

    /// `[youngs_modulus, youngs_modulus_rate, (youngs_modulus_late_rate,
    /// youngs_modulus_transition_age), cohesion..., friction_angle_deg..., poisson_ratio,
    /// dilatancy_angle_deg, age_at_start, (tension_cutoff)]`, the bracketed ones when given.
    fn param_names(&self) -> &'static [&'static str] {
        // one list per combination of the optional keys, built once
        static NAMES: [OnceLock<Vec<&'static str>>; 16] = [const { OnceLock::new() }; 16];
        let (e, c, phi, cut) = (self.e_law().late.is_some(), self.c_law().late.is_some(), self.phi_law().late.is_some(), self.tension_cutoff.is_some());
        let mask = e as usize | (c as usize) << 1 | (phi as usize) << 2 | (cut as usize) << 3;
        NAMES[mask].get_or_init(|| {
            let mut v = Vec::new();
            for (keys, bilinear) in [(&E_KEYS, e), (&C_KEYS, c), (&PHI_KEYS, phi)] {
                v.extend([bare(keys.value), bare(keys.rate)]);
                if bilinear {
                    v.extend([bare(keys.late_rate), bare(keys.transition_age)]);
                }
            }
            v.extend(["poisson_ratio", "dilatancy_angle_deg", "age_at_start"]);
            if cut {
                v.push("tension_cutoff");
            }
            v
        })
    }

    /// The return map's adjoint (zone held) chained through the constants to the laws at the
    /// age before the step; the age's own adjoint passes through (age_out = age_in + dt) and
    /// gains the laws' slopes.
    // a real conversion in the f32 build
    #[allow(clippy::unnecessary_cast)]
    fn update_adjoint(&self, grad_v: &M3, _j: Real, dt: Real, state_in: &[Real], stress_bar: &M3, state_out_bar: &[Real], out: &mut UpdateAdjoint) {
        let age = state_in[7] as f64;
        let cone = self.cone_at(age);
        let bar = return_map_adjoint(&cone.consts(), grad_v, dt, state_in, stress_bar, state_out_bar, out);
        let age_bar = self.consts_adjoint(age, &cone, bar, out.params_bar);
        out.state_bar[7] += state_out_bar[7] + age_bar as Real;
    }

    /// Every particle starts at `age_at_start`.
    fn init_state_adjoint(&self, state_bar: &[Real], params_bar: &mut [Real]) {
        params_bar[self.layout().age0] += state_bar[7];
    }
}

#[cfg(test)]
// `as f64` / `as Real` are real conversions in the f32 build
#[allow(clippy::unnecessary_cast)]
mod tests {
    use super::*;
    use crate::material::drucker_prager::DruckerPrager;
    use crate::material::test_util::tau_of;
    use crate::real::{sym_to_array, trace, V3};

    /// Wolfs, Bos & Salet 2018's printed cylinder: E = 0.078 MPa + 0.0012 MPa/min t, nu = 0.3,
    /// rho = 2070; a linearly growing cohesion and a constant friction angle (illustrative
    /// values of the order they measured).
    fn wolfs() -> EarlyAgeSolid {
        EarlyAgeSolid {
            density: 2070.0,
            poisson_ratio: 0.3,
            youngs_modulus: 0.078e6,
            youngs_modulus_rate: 0.0012e6 / 60.0,
            youngs_modulus_late_rate: None,
            youngs_modulus_transition_age: None,
            cohesion: 2.0e3,
            cohesion_rate: 1.0,
            cohesion_late_rate: None,
            cohesion_transition_age: None,
            friction_angle_deg: 20.0,
            friction_angle_rate: 0.0,
            friction_angle_late_rate: None,
            friction_angle_transition_age: None,
            dilatancy_angle_deg: 0.0,
            tension_cutoff: None,
            age_at_start: 0.0,
            max_age: None,
            cone_match: ConeMatch::Extension,
        }
    }

    fn start(m: &EarlyAgeSolid, sigma: M3, age: f64) -> [Real; 8] {
        let mut st = [0.0; 8];
        m.init_state(&mut st);
        st[..6].copy_from_slice(&sym_to_array(&sigma));
        st[7] = age as Real;
        st
    }

    /// A deterministic sequence of velocity gradients, strong enough to yield.
    fn gradients(n: usize, size: f64) -> Vec<M3> {
        // xorshift, uniform in [-size, size)
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * size
        };
        (0..n).map(|_| M3::from_cols_array(&std::array::from_fn(|_| u() as Real))).collect()
    }

    /// With every rate 0 the material is `drucker_prager` with K = E / (3 (1 - 2 nu)) and the
    /// same nu and cone match, bit for bit: same stress and state every step, through elastic,
    /// shear, tension and apex returns, with and without a cutoff.
    #[test]
    fn at_constant_age_it_is_drucker_prager_bit_for_bit() {
        for (cutoff, psi, cone_match) in [(None, 0.0, ConeMatch::Extension), (Some(1.5e3), 5.0, ConeMatch::Extension), (Some(1.5e3), 5.0, ConeMatch::Compression)] {
            let m = EarlyAgeSolid { youngs_modulus_rate: 0.0, cohesion_rate: 0.0, tension_cutoff: cutoff, dilatancy_angle_deg: psi, age_at_start: 300.0, cone_match, ..wolfs() };
            assert!(m.validate().is_ok());
            let dp = DruckerPrager {
                density: m.density,
                bulk_modulus: m.bulk_of(m.youngs_modulus),
                shear_modulus: None,
                poisson_ratio: Some(m.poisson_ratio),
                friction_angle_deg: m.friction_angle_deg,
                dilatancy_angle_deg: psi,
                cohesion: m.cohesion,
                tension_cutoff: cutoff,
                cone_match,
            };
            assert!(dp.validate().is_ok());
            let mut a = [0.0 as Real; 8];
            m.init_state(&mut a);
            let mut b = [0.0 as Real; 7];
            dp.init_state(&mut b);
            let mut plastic = false;
            for l in gradients(400, 5.0) {
                let (sa, sb) = (m.update(&l, 1.0, 1e-3, &mut a), dp.update(&l, 1.0, 1e-3, &mut b));
                assert_eq!(sa.to_cols_array().map(|x| x.to_bits()), sb.to_cols_array().map(|x| x.to_bits()));
                assert_eq!(a[..7].iter().map(|x| x.to_bits()).collect::<Vec<_>>(), b.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
                plastic |= a[6] > 0.0;
            }
            assert!(plastic, "the sequence must reach the yield surface");
        }
    }

    /// The batch, which builds the constants once for a run of particles of one age and a fixed
    /// friction angle's trigonometry once, and takes elastic steps in lanes, gives `update`'s bits
    /// particle by particle: runs of one to three particles of many ages, through elastic, shear,
    /// tension and apex returns, with the angle fixed or growing, with and without a cutoff.
    #[test]
    fn the_batch_is_update_bit_for_bit() {
        for (phi_rate, cutoff, psi) in [(0.0, None, 0.0), (0.0, Some(1.5e3), 5.0), (0.01, None, 0.0), (0.01, Some(1.5e3), 5.0)] {
            let m = EarlyAgeSolid { friction_angle_rate: phi_rate, tension_cutoff: cutoff, dilatancy_angle_deg: psi, max_age: Some(3600.0), ..wolfs() };
            assert!(m.validate().is_ok());
            assert_eq!(m.fixed_angles().is_some(), phi_rate == 0.0);
            // whole groups of lanes and a tail, in f64 and f32
            let n = 67;
            let mut one: Vec<Real> = (0..n).flat_map(|p| start(&m, M3::ZERO, 60.0 * (p * p % 7 + p / 3) as f64)).collect();
            let mut batch = one.clone();
            let mut plastic = false;
            for l in gradients(200 * n, 5.0).chunks(n) {
                let mut stress = vec![M3::ZERO; n];
                m.update_batch(l, &vec![1.0; n], 1e-3, &mut batch, &mut stress);
                for (p, st) in one.chunks_mut(8).enumerate() {
                    let sigma = m.update(&l[p], 1.0, 1e-3, st);
                    assert_eq!(sigma.to_cols_array().map(|x| x.to_bits()), stress[p].to_cols_array().map(|x| x.to_bits()));
                }
                assert_eq!(one.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), batch.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
                plastic |= one.chunks(8).any(|st| st[6] > 0.0);
            }
            assert!(plastic, "the sequence must reach the yield surface");
        }
    }

    /// One elastic step from rest under uniaxial strain: d sigma_xx = (K + 4/3 G) eps_dot dt with
    /// the moduli of the age at the step's start; the age then advances by dt. A second step at a
    /// later age adds its own increment at its own E, leaving the first one as it was (the rate
    /// form: stiffening does not rescale stress already built).
    #[test]
    fn elastic_increment_uses_the_modulus_of_the_age() {
        let m = wolfs();
        let (rate, dt) = (1e-3 as Real, 1e-2 as Real);
        let l = M3::from_diagonal(V3::new(-rate, 0.0, 0.0));
        let oedometric = |age: f64| {
            let e = m.youngs_modulus + m.youngs_modulus_rate * age;
            (e * (1.0 - 0.3) / ((1.0 + 0.3) * (1.0 - 0.6))) as Real
        };
        let tol: Real = if cfg!(feature = "f32") { 1e-5 } else { 1e-12 };
        let mut st = start(&m, M3::ZERO, 600.0);
        let s1 = m.update(&l, 1.0, dt, &mut st);
        let want1 = -oedometric(600.0) * rate * dt;
        assert!((s1.x_axis.x - want1).abs() < tol * want1.abs(), "{} vs {want1}", s1.x_axis.x);
        assert!((st[7] - (600.0 + dt)).abs() <= 1e-4 * dt);
        // an hour later
        st[7] = 4200.0;
        let s2 = m.update(&l, 1.0, dt, &mut st);
        let want2 = want1 - oedometric(4200.0) * rate * dt;
        assert!((s2.x_axis.x - want2).abs() < tol * want2.abs(), "{} vs {want2}", s2.x_axis.x);
        assert!(oedometric(4200.0) > 1.7 * oedometric(600.0));
        // strain held (L = 0) while the particle ages: the stress stays
        st[7] = 10000.0;
        let s3 = m.update(&M3::ZERO, 1.0, dt, &mut st);
        assert_eq!(s3, s2);
        assert_eq!(st[6], 0.0);
    }

    /// Isochoric axial compression (trace-free L, psi = 0, so sigma_m stays 0): once yielding,
    /// tau of every step is k_phi = 6 c(a) cos(phi) / (sqrt3 (3 + sin(phi))) with the cohesion of
    /// the step's starting age — the deviatoric yield stress q = sqrt3 tau follows the cohesion
    /// law in time (bilinear here), also with phi = 0 (q = 2 c(a)).
    #[test]
    fn yield_stress_follows_the_cohesion_law_in_time() {
        for phi in [0.0, 20.0] {
            let m = EarlyAgeSolid { cohesion_rate: 0.5, cohesion_late_rate: Some(3.0), cohesion_transition_age: Some(1000.0), friction_angle_deg: phi, age_at_start: 500.0, ..wolfs() };
            assert!(m.validate().is_ok());
            let l = M3::from_diagonal(V3::new(0.5, 0.5, -1.0)) * (0.02 as Real);
            let dt = 0.5 as Real;
            let mut st = start(&m, M3::ZERO, m.age_at_start);
            let (mut yielded, mut checked) = (0, 0);
            for _ in 0..2400 {
                let age = st[7] as f64;
                let before = st[6];
                let sigma = m.update(&l, 1.0, dt, &mut st);
                assert!(trace(&sigma).abs() < 1e-6 * tau_of(&sigma).max(1.0));
                if st[6] > before {
                    yielded += 1;
                    let c = m.c_law().value(age);
                    let p = phi.to_radians();
                    let k_phi = 6.0 * c * p.cos() / (3f64.sqrt() * (3.0 + p.sin()));
                    let tol = if cfg!(feature = "f32") { 1e-5 } else { 1e-12 };
                    assert!(((tau_of(&sigma) as f64) - k_phi).abs() < tol * k_phi, "phi {phi}, age {age}: tau {} vs k_phi {k_phi}", tau_of(&sigma));
                    if age > 1000.0 {
                        checked += 1;
                    }
                }
            }
            assert!(yielded > 100 && checked > 100, "phi {phi}: {yielded} plastic steps, {checked} past the kink");
        }
    }

    /// `rest_for` ages the particle and leaves its stress; `stability_at` gives the stiffest
    /// modulus any particle can have by then, capped at `max_age`, and equals `stability()` at 0.
    #[test]
    fn resting_ages_and_the_time_step_sees_the_stiffest_age() {
        let m = EarlyAgeSolid { age_at_start: 120.0, ..wolfs() };
        let mut st = start(&m, M3::from_diagonal(V3::new(-10.0, -5.0, -5.0)), 120.0);
        let before = st;
        m.rest_for(&mut st, 60.0);
        assert_eq!(st[7], 180.0);
        assert_eq!(st[..7], before[..7]);
        let k_at = |age: f64| m.bulk_of(m.youngs_modulus + m.youngs_modulus_rate * age) as Real;
        assert_eq!(m.stability().bulk_modulus, k_at(120.0));
        assert_eq!(m.stability_at(0.0), m.stability());
        assert_eq!(m.stability_at(3600.0).bulk_modulus, k_at(3720.0));
        let capped = EarlyAgeSolid { max_age: Some(1000.0), ..m.clone() };
        assert!(capped.validate().is_ok());
        assert_eq!(capped.stability_at(3600.0).bulk_modulus, k_at(1000.0));
        // past max_age the laws stop: a step at 5000 s is a step at 1000 s
        let (mut a, mut b) = (start(&capped, M3::ZERO, 5000.0), start(&capped, M3::ZERO, 1000.0));
        let l = M3::from_diagonal(V3::new(-1e-3, 0.0, 0.0));
        assert_eq!(capped.update(&l, 1.0, 1.0, &mut a), capped.update(&l, 1.0, 1.0, &mut b));
        // a falling-then-rising law: the bound is its largest value over the ages, not the last
        let dip = EarlyAgeSolid { youngs_modulus_rate: -10.0, youngs_modulus_late_rate: Some(5.0), youngs_modulus_transition_age: Some(1000.0), age_at_start: 0.0, ..wolfs() };
        assert!(dip.validate().is_ok());
        assert_eq!(dip.stability_at(1500.0).bulk_modulus, dip.bulk_of(dip.youngs_modulus) as Real);
    }

    #[test]
    fn validation_names_the_key() {
        assert!(wolfs().validate().is_ok());
        let msg = |m: EarlyAgeSolid| m.validate().unwrap_err().to_string();
        assert!(msg(EarlyAgeSolid { youngs_modulus_rate: -1.0, ..wolfs() }).starts_with("material.youngs_modulus (with its rates) must be > 0 at every age"));
        assert!(msg(EarlyAgeSolid { youngs_modulus_late_rate: Some(1.0), ..wolfs() }).starts_with("material.youngs_modulus_transition_age is required"));
        assert!(msg(EarlyAgeSolid { cohesion_transition_age: Some(1.0), ..wolfs() }).starts_with("material.cohesion_late_rate is required"));
        assert!(msg(EarlyAgeSolid { cohesion_rate: f64::NAN, ..wolfs() }).starts_with("material.cohesion_rate must be finite"));
        // a growing friction angle passes 90 deg some day: max_age bounds the ages
        let growing = EarlyAgeSolid { friction_angle_rate: 0.01, ..wolfs() };
        assert!(msg(growing.clone()).starts_with("material.friction_angle_deg (with its rates) must be < 90"));
        assert!(EarlyAgeSolid { max_age: Some(3600.0), ..growing }.validate().is_ok());
        assert!(msg(EarlyAgeSolid { dilatancy_angle_deg: 25.0, ..wolfs() }).starts_with("material.dilatancy_angle_deg"));
        assert!(msg(EarlyAgeSolid { poisson_ratio: 0.5, ..wolfs() }).starts_with("material.poisson_ratio"));
        assert!(msg(EarlyAgeSolid { age_at_start: -1.0, ..wolfs() }).starts_with("material.age_at_start"));
        assert!(msg(EarlyAgeSolid { max_age: Some(0.0), ..wolfs() }).starts_with("material.max_age"));
        assert!(msg(EarlyAgeSolid { tension_cutoff: Some(-1.0), ..wolfs() }).starts_with("material.tension_cutoff"));
        assert!(msg(EarlyAgeSolid { friction_angle_deg: 0.0, cohesion: 0.0, ..wolfs() }).contains("no shear strength"));
        // cohesion falling to 0 at the kink with no friction
        let fall = EarlyAgeSolid { friction_angle_deg: 0.0, cohesion: 100.0, cohesion_rate: -1.0, cohesion_late_rate: Some(1.0), cohesion_transition_age: Some(100.0), ..wolfs() };
        assert!(msg(fall).contains("no shear strength"));
        use serde::de::value::{Error, MapDeserializer};
        let unknown = EarlyAgeSolid::deserialize(MapDeserializer::<_, Error>::new(
            [("density", 2070.0), ("poisson_ratio", 0.3), ("youngs_modulus", 1e5), ("friction_angle_deg", 20.0), ("bulk_modulus", 1e6)].into_iter(),
        ));
        assert!(unknown.unwrap_err().to_string().contains("bulk_modulus"));
    }

    #[test]
    fn param_names_follow_the_keys_given() {
        let m = wolfs();
        assert_eq!(
            m.param_names(),
            ["youngs_modulus", "youngs_modulus_rate", "cohesion", "cohesion_rate", "friction_angle_deg", "friction_angle_rate", "poisson_ratio", "dilatancy_angle_deg", "age_at_start"]
        );
        let b = bilinear(true);
        assert_eq!(b.param_names().len(), 16);
        assert_eq!(b.param_names()[2..4], ["youngs_modulus_late_rate", "youngs_modulus_transition_age"]);
        assert_eq!(b.param_names()[15], "tension_cutoff");
        assert_eq!(b.layout().age0, 14);
    }

    /// Every law bilinear (kinks at 600 s), the friction angle growing, optionally a cutoff.
    fn bilinear(cut: bool) -> EarlyAgeSolid {
        from_params(&bilinear_params(cut), cut, ConeMatch::Extension)
    }

    fn bilinear_params(cut: bool) -> Vec<f64> {
        let mut p = vec![78e3, 10.0, 30.0, 600.0, 2e3, 0.5, 2.0, 600.0, 20.0, 0.002, 0.004, 600.0, 0.3, 4.0, 0.0];
        if cut {
            p.push(2e3);
        }
        p
    }

    fn from_params(p: &[f64], cut: bool, cone_match: ConeMatch) -> EarlyAgeSolid {
        EarlyAgeSolid {
            density: 2070.0,
            youngs_modulus: p[0],
            youngs_modulus_rate: p[1],
            youngs_modulus_late_rate: Some(p[2]),
            youngs_modulus_transition_age: Some(p[3]),
            cohesion: p[4],
            cohesion_rate: p[5],
            cohesion_late_rate: Some(p[6]),
            cohesion_transition_age: Some(p[7]),
            friction_angle_deg: p[8],
            friction_angle_rate: p[9],
            friction_angle_late_rate: Some(p[10]),
            friction_angle_transition_age: Some(p[11]),
            poisson_ratio: p[12],
            dilatancy_angle_deg: p[13],
            age_at_start: p[14],
            tension_cutoff: cut.then(|| p[15]),
            max_age: Some(3600.0),
            cone_match,
        }
    }

    /// A stress of mean `sm` and tau = `size` along the deviator of `u`, eps_p 0.01, at `age`.
    #[cfg(not(feature = "f32"))]
    fn stress(sm: f64, size: f64, u: &[f64], age: f64) -> [f64; 8] {
        let t = (u[0] + u[1] + u[2]) / 3.0;
        let d = [u[0] - t, u[1] - t, u[2] - t];
        let norm = (0.5 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + u[3] * u[3] + u[4] * u[4] + u[5] * u[5]).sqrt();
        let k = size / norm;
        [sm + k * d[0], sm + k * d[1], sm + k * d[2], k * u[3], k * u[4], k * u[5], 0.01, age]
    }

    /// `check_update_adjoint` (fourth-order central differences per input group, and the Taylor
    /// remainder) at ages before, just before, and after the laws' kinks at 600 s, in the elastic
    /// zone, on the cone (shear return), at the apex (the default cutoff, whose adjoint reaches
    /// c and phi and through their laws the age), and on a given cutoff (tension return; below
    /// the apex at these ages).
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_across_the_kink() {
        use crate::adjoint_check::Rng;
        use crate::material::test_util::check_update_adjoint;
        let u0 = [0.8, -0.5, -0.3, 0.35, -0.2, 0.25];
        let l0 = [0.3, -0.8, 0.5, 1.0, -0.4, 0.6, -0.7, 0.9, 0.2];
        // (label, cutoff given, mean stress, tau, trace-free L)
        let cases = [
            ("elastic", false, -1e3, 1e3, false),
            ("shear", false, -1e3, 5e3, false),
            ("shear, cutoff given", true, -1e3, 5e3, false),
            ("apex", false, 1.5e4, 300.0, true),
            ("tension on the given cutoff", true, 3e3, 300.0, false),
            ("shear, compression-matched", false, -1e3, 5e3, false),
            ("apex, compression-matched", false, 1.5e4, 300.0, true),
        ];
        let mut seed = 100;
        for (label, cut, sm, tau, trace_free) in cases {
            let params = bilinear_params(cut);
            let cone_match = if label.ends_with("compression-matched") { ConeMatch::Compression } else { ConeMatch::Extension };
            let make = move |p: &[f64]| from_params(p, cut, cone_match);
            assert!(make(&params).validate().is_ok());
            let mut scale: Vec<f64> = params.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
            // a rate moves its parameter by the rate's step times the age: 10 % of the rate keeps
            // that above the rounding of the differences (as the Taylor test below)
            for i in [1, 2, 5, 6, 9, 10] {
                scale[i] *= 10.0;
            }
            for age in [300.0, 599.0, 900.0] {
                seed += 1;
                let mut rng = Rng(seed);
                let l: Vec<f64> = l0.iter().map(|x| x + rng.uniform(-0.2, 0.2)).collect();
                let mut l = M3::from_cols_array(&l.try_into().unwrap());
                if trace_free {
                    // at the apex K reaches the result only through eps_p's tiny volumetric part
                    // (see drucker_prager's adjoint test)
                    l -= M3::from_diagonal(V3::splat(trace(&l) / 3.0));
                }
                let u: Vec<f64> = u0.iter().map(|x| x + rng.uniform(-0.1, 0.1)).collect();
                let state = stress(sm * rng.uniform(0.95, 1.05), tau * rng.uniform(0.95, 1.05), &u, age);
                let m = make(&params);
                let mut st = state;
                m.update(&l, 1.0, 1e-3, &mut st);
                assert_eq!(st[6] == state[6], label == "elastic", "{label} at {age} s: zone");
                let mut state_scale: Vec<f64> = state.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
                state_scale[7] = 1.0;
                // 1e-5: on the cone the stress hardly depends on E or phi's slope, and the
                // differences of those small derivatives keep ~1e-6 of rounding
                check_update_adjoint(&format!("{label}, age {age} s"), make, &params, l, 1.0, 1e-3, &state, 0.1, &state_scale, &scale, 1e-5, seed);
            }
        }
    }

    /// A run of 60 steps of 2 s from `age_at_start` = 550 s, through the kinks at 600 s and from
    /// elastic into plastic loading, as a map from all the parameters (each law's four, nu, psi,
    /// age_at_start, the cutoff) to the final stress and state; its adjoint is the steps'
    /// adjoints run backwards, then `init_state_adjoint`. Central differences per parameter, and
    /// the Taylor remainder over all of them at once falling as h^2.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn taylor_test_over_a_multi_step_sequence() {
        use crate::adjoint_check::{group_errors, slow_loading, taylor_slope, MaterialRun, Rng};
        // slow isochoric compression with a little shear and volume change: elastic first, then
        // on the cone; the kinks at 600 s fall between the steps at 598, 600 and 602 s, so set
        // them at 601 s
        let ls = slow_loading(60, 1.0);
        let mut x = bilinear_params(true);
        x[14] = 550.0;
        for i in [3, 7, 11] {
            x[i] = 601.0;
        }
        let run = MaterialRun::new(|p: &[f64]| from_params(p, true, ConeMatch::Extension), ls.into_iter().map(|l| (l, 1.0)).collect(), 2.0, &x);
        let (states, _) = run.states(&x);
        let last = states.last().unwrap();
        assert!(last[6] > 0.0 && states[20][6] == 0.0, "elastic first, then plastic: eps_p {} -> {}", states[20][6], last[6]);
        assert!((last[7] - 670.0).abs() < 1e-9);
        let mut scale: Vec<f64> = x.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
        for i in [3, 7, 11, 14] {
            // ages: perturbations well inside the 1 s between a kink and the nearest step
            scale[i] = 0.5;
        }
        // the rates reach the result only through the ages they act over (70 s at most, 20 s
        // beyond the kinks): a 10 % step keeps their differences above rounding
        for i in [1, 2, 5, 6, 9, 10] {
            scale[i] *= 10.0;
        }
        let mut rng = Rng(5);
        let errs = group_errors(&run, &x, &scale, &mut rng);
        println!("multi-step: {errs:?}");
        // (rounding, not truncation: the errors fall as the steps grow, 3e-5 -> 4e-7 for the late
        // rate of E from a 1 % to a 100 % step)
        for (name, e) in &errs {
            assert!(*e < 1e-5, "{name}: adjoint vs central differences {e:.1e}");
        }
        let slope = taylor_slope(&run, &x, &scale, &mut rng).expect("curved along the direction");
        println!("multi-step Taylor remainder slope {slope:.3}");
        assert!(slope > 1.9, "Taylor remainder slope {slope:.3}");
    }
}
