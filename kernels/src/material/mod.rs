//! Constitutive models. Each material is one file implementing [`Material`]; the solver calls
//! [`Material::update`] once per particle per step, after G2P, with the particle's new velocity
//! gradient and volume ratio, and stores the returned Cauchy stress for the next P2G.
//!
//! A material's per-particle internal state is a fixed number of reals (`state_names().len()`),
//! stored contiguously per particle in the particle pool; each material documents its layout.
//! Parameters are plain serde structs so a scenario's `[material]` table maps onto them directly
//! (unknown keys are rejected).

use crate::real::{Real, M3};

pub mod eos;
pub mod newtonian;
pub mod bingham;
pub mod papanastasiou_roussel;
pub mod evp_bingham;
pub mod maxwell;
pub mod drucker_prager;
#[cfg(target_arch = "x86_64")]
mod drucker_prager_lanes;
#[cfg(target_arch = "x86_64")]
mod evp_bingham_lanes;
#[cfg(target_arch = "x86_64")]
mod lanes;
pub mod age_law;
pub mod early_age;
pub mod error;

pub use eos::Eos;
pub use error::MaterialError;

/// Kinematics and invariants shared by the materials' tests.
#[cfg(test)]
pub(crate) mod test_util {
    #[cfg(not(feature = "f32"))]
    pub use crate::adjoint_check::{check_update_adjoint, check_wake_adjoint};
    use crate::real::{ddot, dev, Real, M3, V3};

    /// L with the single entry dv_x/dy = g (glam is column-major: column 1 holds d v / d y).
    pub fn simple_shear(g: Real) -> M3 {
        M3::from_cols(V3::ZERO, V3::new(g, 0.0, 0.0), V3::ZERO)
    }

    /// tau = sqrt(J2) of a stress.
    pub fn tau_of(s: &M3) -> Real {
        (0.5 * ddot(&dev(s), &dev(s))).sqrt()
    }
}

/// Roussel's structural build-up rate A_thix / tau0 [1/s] (001 eq. 12); 0 when there is no
/// build-up, so tau0 may then be 0.
#[inline]
pub(crate) fn build_up_rate(a_thix: f64, yield_stress: f64) -> Real {
    if a_thix > 0.0 {
        crate::real::r(a_thix / yield_stress)
    } else {
        0.0
    }
}

/// Validation helper: `v` must be finite and > 0; the message names the key.
pub(crate) fn positive(key: &'static str, v: f64) -> Result<(), MaterialError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(MaterialError::out_of_range(key, "> 0", v))
    }
}

/// Validation helper: `v` must be finite and >= 0; the message names the key.
pub(crate) fn non_negative(key: &'static str, v: f64) -> Result<(), MaterialError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(MaterialError::out_of_range(key, ">= 0", v))
    }
}

/// Wave and viscous properties the time-step control needs (paper-independent CFL bounds).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilityInfo {
    /// Reference density rho0 [kg/m3].
    pub density: Real,
    /// Largest tangent bulk modulus the material can reach in normal use [Pa].
    pub bulk_modulus: Real,
    /// Elastic shear modulus [Pa]; 0 for fluids.
    pub shear_modulus: Real,
    /// Largest dynamic viscosity an explicit step must resolve [Pa s]; 0 when none. With
    /// `thickening`, the largest at shear rates up to its `floor_rate`.
    pub max_viscosity: Real,
    /// A viscosity that grows without bound with the shear rate (a flow index n > 1); `None`
    /// when `max_viscosity` bounds it at every rate.
    pub thickening: Option<Thickening>,
}

/// Growth of the viscosity with the shear rate g beyond what `max_viscosity` covers:
/// mu(g) <= max_viscosity + coefficient (max(g, floor_rate)^exponent - floor_rate^exponent), so
/// the bound is continuous in the flow index at n = 1 (exponent n - 1 -> 0, growth -> 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thickening {
    /// [Pa s^n].
    pub coefficient: Real,
    /// n - 1 > 0.
    pub exponent: Real,
    /// [1/s].
    pub floor_rate: Real,
}

impl StabilityInfo {
    /// The largest viscosity at shear rates up to `max_rate` [Pa s].
    // The casts are f32 -> f64 under the `f32` feature, where Real is f32.
    #[allow(clippy::unnecessary_cast)]
    pub fn viscosity_up_to(&self, max_rate: f64) -> f64 {
        let base = self.max_viscosity as f64;
        match self.thickening {
            None => base,
            Some(t) => {
                let (c, e, f) = (t.coefficient as f64, t.exponent as f64, t.floor_rate as f64);
                base + c * (max_rate.max(f).powf(e) - f.powf(e))
            }
        }
    }
}

/// Flow index n of the Herschel-Bulkley materials (tau = tau0 + k gamma_dot^n, the `viscosity`
/// key playing k): 1, Bingham, when the key is absent.
pub(crate) fn default_flow_index() -> f64 {
    1.0
}

/// x^(n - 1), the power law's factor on k, skipped at n = 1 so that a Bingham material costs no
/// `powf` and gives the bits it gave before the flow index existed.
#[inline]
pub(crate) fn rate_power(x: Real, n: Real) -> Real {
    if n == 1.0 {
        1.0
    } else {
        x.powf(n - 1.0)
    }
}

/// Where [`Material::update_adjoint`] accumulates (`+=`) the adjoints of what `update` read.
pub struct UpdateAdjoint<'a> {
    /// Adjoint of the velocity gradient L.
    pub grad_v_bar: &'a mut M3,
    /// Adjoint of the volume ratio J.
    pub j_bar: &'a mut Real,
    /// Adjoint of the internal state *before* the update (`state_names().len()` reals).
    pub state_bar: &'a mut [Real],
    /// Adjoints of the parameters named by [`Material::param_names`], in that order.
    pub params_bar: &'a mut [Real],
}

/// One constitutive model.
pub trait Material: Send + Sync + std::fmt::Debug {
    /// Registry name, as written in scenario files.
    fn name(&self) -> &'static str;

    /// Names of the per-particle internal state variables, in storage order.
    fn state_names(&self) -> &'static [&'static str];

    /// Initial internal state of a newly created particle (stress-free, at rest).
    fn init_state(&self, state: &mut [Real]);

    /// Advance the internal state over one step and return the new Cauchy stress.
    ///
    /// * `grad_v` — velocity gradient L = dv/dx at the particle (MLS-MPM's C matrix);
    /// * `j` — volume ratio V / V0 after this step's volume update;
    /// * `dt` — step length;
    /// * `state` — this particle's internal state (`state_names().len()` reals).
    fn update(&self, grad_v: &M3, j: Real, dt: Real, state: &mut [Real]) -> M3;

    /// The stress `update` returns with `grad_v = 0` (a particle at rest), from the state it
    /// leaves and the volume ratio, bit for bit. A sleeping particle keeps this stress with zero
    /// velocity and velocity gradient, so a restart checkpoint need not store any of the three:
    /// they are rebuilt from the state and J (for materials whose stress lives in the state, it
    /// is the stress `update` returns for any `grad_v`).
    fn stress_at_rest(&self, state: &[Real], j: Real) -> M3;

    /// Advance the internal state over `duration` at rest (`grad_v = 0`, below yield), in one go:
    /// what `duration / dt` calls of `update` would do, up to round-off. A sleeping particle skips
    /// the per-step update, and gets this when its block wakes, so structural build-up
    /// (thixotropy) goes on while material sleeps. Materials whose state does not evolve at rest
    /// keep the default, which does nothing.
    fn rest_for(&self, _state: &mut [Real], _duration: Real) {}

    /// [`Material::rest_for`] for a particle that sleeps at volume ratio `j`: what a material
    /// whose pressure is held through ageing (`evp_bingham` with an age law) needs. The solver
    /// wakes particles with this; the default ignores `j`.
    fn rest_for_at(&self, state: &mut [Real], duration: Real, _j: Real) {
        self.rest_for(state, duration)
    }

    /// Adjoint of waking a sleeping particle of volume ratio `j` after `duration` asleep: the
    /// state becomes `state = rest_for_at(before, duration, j)` and the stress `stress_at_rest`
    /// of it (`state` is the one it wakes with). `state_bar` holds the adjoint of the state after and becomes that of the state before;
    /// the stress's adjoint `stress_bar` goes to it, to `j_bar` and, with the rest's, to
    /// `params_bar` (in [`Material::param_names`] order). Returns false, touching nothing, for a
    /// material (or a configuration of one) without it: a gradient run refuses to wake it.
    #[allow(clippy::too_many_arguments)]
    fn wake_adjoint(&self, _state: &[Real], _duration: Real, _j: Real, _stress_bar: &M3, _state_bar: &mut [Real], _j_bar: &mut Real, _params_bar: &mut [Real]) -> bool {
        false
    }

    /// How far tau = sqrt(J2) of the stress held in `state` may rise before the material
    /// yields [Pa]: the margin a sleeping unit keeps against loads put on it while it sleeps
    /// (the solver's `sleep.rs` wakes it when the load's share passes the margin). Materials
    /// whose stress does not live in their state, or that have no yield stress, keep the
    /// default 0: any added load wakes them.
    fn yield_margin(&self, _state: &[Real]) -> Real {
        0.0
    }

    /// Whether the sleep update tests each sleeping unit against the load its column added on
    /// it since it fell asleep (the load on the column's top and the weights of the sleeping
    /// units between), not only against the load on the top. A material whose
    /// [`Material::yield_margin`] stays well above the weight of a layer needs it: its deep units
    /// stay asleep under the first layers, and must wake as the stack above nears their
    /// strength. The others keep false, the rule measured with `evp_bingham` (whose margin is
    /// near 0 where flow has just stopped, so the first load on a column wakes it).
    fn column_loads(&self) -> bool {
        false
    }

    /// A particle waking from sleep takes the compressive stress `traction` [Pa, >= 0] along
    /// `axis` (down) that its column added on it while it slept (with
    /// [`Material::column_loads`]). Why: the stress of a sleeping particle is frozen, so a deep
    /// unit that slept under layers laid and fallen asleep above it wakes without their weight
    /// in its stress, and takes it at once: a step load, which overshoots to twice its static
    /// effect and, under mass scaling, threw the printed cylinder of bench/cylinder.py down in layer
    /// 11 where it stands to 24 awake (10 mm cells). Materials
    /// whose stress does not live in their state keep the default, which does nothing.
    fn take_column_load(&self, _state: &mut [Real], _axis: usize, _traction: Real) {}

    /// Yield stress gained by `duration` at rest (structural build-up) [Pa], no more than
    /// [`Material::rest_for`] gives any particle: what a sleeping unit's margin grows by while
    /// it sleeps.
    fn strength_gain(&self, _duration: Real) -> Real {
        0.0
    }

    /// Data for the automatic time step.
    fn stability(&self) -> StabilityInfo;

    /// Data for the automatic time step of the step starting at simulation time `time` [s]: a
    /// material whose stiffness changes with the particles' age (`early_age_solid`) bounds it
    /// over every age a particle can have by then (at most the mix's age at the start plus
    /// `time`). Materials whose moduli do not age keep the default, [`Material::stability`].
    fn stability_at(&self, _time: f64) -> StabilityInfo {
        self.stability()
    }

    /// The parameters gradients are taken with respect to, named by their scenario key under
    /// `[material]` (e.g. `"yield_stress"`), in the order [`Material::update_adjoint`] fills
    /// `params_bar`. The density is not listed: `update` does not read it (it enters through the
    /// particle masses, which the gradient driver differentiates).
    fn param_names(&self) -> &'static [&'static str];

    /// Vector-Jacobian product of [`Material::update`]: given the inputs the forward read
    /// (`state_in` is the internal state *before* the update; it is not modified) and the adjoints
    /// of its outputs (`stress_bar` of the returned stress, `state_out_bar` of the updated state),
    /// accumulate the adjoints of `grad_v`, `j`, the state before the update and the parameters
    /// into `out`. `dt` is held fixed (not differentiated). At a kink of a `max`/`min` or a
    /// yield-surface branch the adjoint is the derivative of the branch the forward took.
    #[allow(clippy::too_many_arguments)]
    fn update_adjoint(
        &self,
        grad_v: &M3,
        j: Real,
        dt: Real,
        state_in: &[Real],
        stress_bar: &M3,
        state_out_bar: &[Real],
        out: &mut UpdateAdjoint,
    );

    /// Adjoint of [`Material::init_state`]: accumulate into `params_bar` (indexed like
    /// `param_names`) what the adjoint `state_bar` of a new particle's state owes the parameters
    /// the initial state is made of (e.g. the initial structuration lambda0). Most initial states
    /// are constant, hence the default.
    fn init_state_adjoint(&self, _state_bar: &[Real], _params_bar: &mut [Real]) {}

    /// Reference density rho0 [kg/m3].
    fn density(&self) -> Real {
        self.stability().density
    }

    /// Batch form over slices, the one the solver uses: one dynamic dispatch per batch, a
    /// monomorphic loop inside.
    fn update_batch(&self, grad_v: &[M3], j: &[Real], dt: Real, state: &mut [Real], stress: &mut [M3]) {
        let n = self.state_names().len();
        for p in 0..grad_v.len() {
            let s = if n == 0 { &mut [][..] } else { &mut state[p * n..(p + 1) * n] };
            stress[p] = self.update(&grad_v[p], j[p], dt, s);
        }
    }
}
