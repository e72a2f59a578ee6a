//! What every effect is: the [`Effect`] trait, its parameters' and covariates' types, and the
//! helpers effects share to read the scenario keys and add to their adjoints. The registry of
//! effects (`mod.rs`) names the effects; each effect's file names only this one.

use super::super::error::MeasureError;
use std::collections::BTreeMap;

/// Scenario keys and their values for one experiment.
pub type Keys = BTreeMap<String, f64>;

/// One parameter of an effect.
#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    pub name: &'static str,
    /// The value at which the effect vanishes.
    pub null: f64,
    pub lower: f64,
    pub upper: f64,
    /// A typical magnitude: the fit's unit step, and the start of a fit begun at the null.
    pub scale: f64,
    pub unit: &'static str,
}

/// What an experiment is, beyond its scenario: the covariates effects read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Covariates {
    /// Rest before the test [s]: the structure built at rest (thixotropy).
    pub rest_time: f64,
    /// Material age at the test, since mixing [s] (ageing).
    pub age: f64,
    /// Any other the experiment declares (`covariates = { temperature = 31.0 }`), by name: what
    /// an effect declared in a model file may read.
    pub declared: BTreeMap<String, f64>,
}

pub trait Effect: Sync {
    /// Name in model files (`[effects.NAME]`) and parameter names (`NAME.PARAM`).
    fn name(&self) -> &'static str;
    /// One line: what it models.
    fn about(&self) -> &'static str;
    fn params(&self) -> &'static [ParamSpec];
    /// Set the keys this effect governs, from its parameters `p` (in `params()` order).
    fn apply(&self, p: &[f64], x: &Covariates, keys: &mut Keys) -> Result<(), MeasureError>;
    /// Given the keys before `apply` and the adjoints of the keys after it (`keys_bar`, a key
    /// absent = 0), leave in `keys_bar` the adjoints of the keys before it, and add to `p_bar`.
    fn apply_adjoint(&self, p: &[f64], x: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]);
    /// Whether the effect can act on a simulation experiment's scenario (its TOML document with
    /// the model's `[material]` in place, before the keys are set): an error says why not.
    fn check_scenario(&self, _scenario: &toml::Table) -> Result<(), MeasureError> {
        Ok(())
    }
    /// Whether the null lies at infinity, where no finite parameter puts it and no gradient can
    /// be taken (G = infinity, a rigid material, where the explicit step goes to 0; mu =
    /// infinity, a floor that sticks, where the loss no longer depends on mu). Diagnose tests
    /// such an effect by the likelihood ratio, fitting it from [`Effect::lr_start`], instead of by
    /// the score at the null.
    fn null_at_infinity(&self) -> bool {
        false
    }
    /// Where the likelihood-ratio fit of an effect with its null at infinity starts, given the
    /// base model's keys. Best is where the effect leaves those keys as they are (a modulus: the
    /// model's own finite G or K, which the solver runs in the rigid null's place), so chi^2
    /// starts at the base model's and the fit only lowers it; where no finite value does that (no
    /// finite mu is a no-slip floor), a value the effect typically takes.
    fn lr_start(&self, _keys: &Keys) -> Result<Vec<f64>, MeasureError> {
        Ok(self.params().iter().map(|s| s.null).collect())
    }
    /// Whether a model with this effect at its start (its null; [`Effect::lr_start`] for a null
    /// at infinity) runs as the model without it, to the bit, wherever the effect can act: the
    /// keys it leaves may differ (a rate of 0 written out, G in place of the Poisson ratio that
    /// gives it), the run does not. Diagnose then takes the model's own values there instead of
    /// running it again. True of an effect whose null is finite and of the moduli's stand-ins
    /// (test `every_effect_at_its_start_runs_as_the_model_without_it`); not of a finite floor
    /// friction, nor of a declared effect, whose keys no test sees.
    fn start_runs_as_model(&self) -> bool {
        !self.null_at_infinity()
    }
}

/// A key an effect reads, or an error naming what the model lacks.
pub fn read(keys: &Keys, effect: &str, key: &str) -> Result<f64, MeasureError> {
    keys.get(key)
        .copied()
        .ok_or_else(|| MeasureError::Effect(format!("effect '{effect}' needs {key}, which the model does not set")))
}

/// The model's shear modulus G: its `shear_modulus`, or G = 3 K (1 - 2 nu) / (2 (1 + nu)) from
/// `poisson_ratio` nu and `bulk_modulus` K (as the material computes it); or an error naming
/// what the model lacks.
pub fn shear_modulus(keys: &Keys, effect: &str) -> Result<f64, MeasureError> {
    match keys.get(POISSON_RATIO) {
        Some(&nu) => {
            Ok(crate::kernels::material::eos::shear_modulus_of(read(keys, effect, BULK_MODULUS)?, None, Some(nu)))
        }
        None => read(keys, effect, SHEAR_MODULUS),
    }
}

pub const SHEAR_MODULUS: &str = "material.shear_modulus";
pub const BULK_MODULUS: &str = "material.bulk_modulus";
/// A key an effect may remove (the moduli, to set G and K apart): a material number whose key
/// is absent is left out of the material the experiment runs with.
pub const POISSON_RATIO: &str = "material.poisson_ratio";

/// The adjoint of a key (0 when absent).
pub fn bar(keys_bar: &Keys, key: &str) -> f64 {
    keys_bar.get(key).copied().unwrap_or(0.0)
}

pub fn add_bar(keys_bar: &mut Keys, key: &str, v: f64) {
    *keys_bar.entry(key.to_string()).or_insert(0.0) += v;
}
