//! Ageing of the plastic viscosity: eta grows with the material's age t since mixing, linearly,
//! eta (1 + r t), evaluated at the experiment's age (as `ageing` does for the yield stress).
//! Null: r = 0. The README's worked example of adding an effect.

use super::super::error::MeasureError;
use super::effect::{add_bar, bar, read, Covariates, Effect, Keys, ParamSpec};

pub struct ViscosityAgeing;

const KEY: &str = "material.viscosity";

const PARAMS: &[ParamSpec] =
    &[ParamSpec { name: "rate", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 2e-4, unit: "1/s" }];

impl Effect for ViscosityAgeing {
    fn name(&self) -> &'static str {
        "viscosity_ageing"
    }
    fn about(&self) -> &'static str {
        "ageing of the plastic viscosity, eta (1 + rate age)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], x: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        let eta = read(keys, self.name(), KEY)?;
        keys.insert(KEY.into(), eta * (1.0 + p[0] * x.age));
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], x: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        // eta_out = eta_in (1 + r t): d/dr = eta_in t, d/d eta_in = 1 + r t
        let eta_bar = bar(keys_bar, KEY);
        p_bar[0] += eta_bar * keys_in[KEY] * x.age;
        keys_bar.insert(KEY.into(), 0.0);
        add_bar(keys_bar, KEY, eta_bar * (1.0 + p[0] * x.age));
    }
}
