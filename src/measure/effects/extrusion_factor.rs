//! The pump delivers a fixed fraction of the flow the toolpath commands: every print move's
//! extrusion speed is `factor` times the commanded one (`print.extrusion_factor`), so every
//! section's area scales with it, as a worn pump, a slipping feed or a flow multiplier off by a
//! few percent do. Null: factor = 1, the flow as commanded. It acts on printing experiments only:
//! a test that prints nothing (a slump, a rheometer) is not reached.

use super::{Covariates, Effect, Keys, ParamSpec};

pub struct ExtrusionFactor;

pub const KEY: &str = "print.extrusion_factor";

// a two-sided null: the pump may deliver more than commanded as well as less
const PARAMS: &[ParamSpec] = &[ParamSpec { name: "factor", null: 1.0, lower: 0.2, upper: 5.0, scale: 0.05, unit: "-" }];

impl Effect for ExtrusionFactor {
    fn name(&self) -> &'static str {
        "extrusion_factor"
    }
    fn about(&self) -> &'static str {
        "delivered over commanded flow: every print move's extrusion speed x factor"
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
        super::check_print_key(scenario, "extrusion_factor", 1.0)
    }
}
