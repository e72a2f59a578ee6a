//! The nozzle stands higher or lower over the bed than the toolpath commands, by the same
//! `offset` all along it (`print.z_offset`): a bed levelled or a Z origin set off by a few
//! millimetres. Every layer's standoff changes by it, so the first layer's height and width do,
//! and the layers above follow. Null: offset = 0. It acts on printing experiments only.

use super::{Covariates, Effect, Keys, ParamSpec};

pub struct StandoffOffset;

pub const KEY: &str = "print.z_offset";

// a two-sided null: the nozzle may stand higher or lower
const PARAMS: &[ParamSpec] = &[ParamSpec { name: "offset", null: 0.0, lower: -0.05, upper: 0.05, scale: 1e-3, unit: "m" }];

impl Effect for StandoffOffset {
    fn name(&self) -> &'static str {
        "standoff_offset"
    }
    fn about(&self) -> &'static str {
        "the nozzle's height over the bed off by offset all along the toolpath"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        keys.insert(KEY.into(), p[0]);
        Ok(())
    }
    fn apply_adjoint(&self, _: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        p_bar[0] += keys_bar.remove(KEY).unwrap_or(0.0);
    }
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), String> {
        super::check_print_key(scenario, "z_offset", 0.0)
    }
}
