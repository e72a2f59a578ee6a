//! Effects on the printing process rather than the material, each one `[print]` setting that
//! acts on the whole toolpath, path or G-code, with its null inside its bounds (the process may
//! be off either way, so diagnose tests it two-sided):
//!
//! - `extrusion_factor`: the pump delivers `factor` times the flow the toolpath commands
//!   (`print.extrusion_factor` scales every print move's extrusion speed), so every section's
//!   area scales with it, as a worn pump, a slipping feed or a flow multiplier off by a few
//!   percent do. Null 1.
//! - `standoff_offset`: the nozzle stands `offset` higher over the bed than commanded, all along
//!   the toolpath (`print.z_offset`), as a bed levelled or a Z origin set off by a few
//!   millimetres does. Null 0.
//!
//! A test that prints nothing (a slump, a rheometer) is not reached.

use super::super::error::MeasureError;
use super::effect::{Covariates, Effect, Keys, ParamSpec};

pub struct Process {
    name: &'static str,
    about: &'static str,
    /// The `[print]` field it sets.
    field: &'static str,
    params: &'static [ParamSpec],
}

impl Process {
    pub const EXTRUSION_FACTOR: Process = Process {
        name: "extrusion_factor",
        about: "delivered over commanded flow: every print move's extrusion speed x factor",
        field: "extrusion_factor",
        params: &[ParamSpec { name: "factor", null: 1.0, lower: 0.2, upper: 5.0, scale: 0.05, unit: "-" }],
    };
    pub const STANDOFF_OFFSET: Process = Process {
        name: "standoff_offset",
        about: "the nozzle's height over the bed off by offset all along the toolpath",
        field: "z_offset",
        params: &[ParamSpec { name: "offset", null: 0.0, lower: -0.05, upper: 0.05, scale: 1e-3, unit: "m" }],
    };

    /// The scenario key it sets.
    pub fn key(&self) -> String {
        format!("print.{}", self.field)
    }
}

impl Effect for Process {
    fn name(&self) -> &'static str {
        self.name
    }
    fn about(&self) -> &'static str {
        self.about
    }
    fn params(&self) -> &'static [ParamSpec] {
        self.params
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        keys.insert(self.key(), p[0]);
        Ok(())
    }
    fn apply_adjoint(&self, _: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        p_bar[0] += keys_bar.remove(&self.key()).unwrap_or(0.0);
    }
    /// It prints, and leaves the field at the effect's null, which the effect replaces.
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), MeasureError> {
        let print = scenario.get("print").ok_or_else(|| {
            MeasureError::Effect("acts on the printing process, and this scenario prints nothing (no [print])".into())
        })?;
        let null = self.params[0].null;
        match print.get(self.field).map(super::super::observation::number) {
            None => Ok(()),
            Some(Some(v)) if v == null => Ok(()),
            Some(v) => Err(MeasureError::Effect(format!(
                "needs print.{} at its null {null}, and the scenario sets {}",
                self.field,
                v.map_or("a non-number".to_string(), |v| v.to_string())
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_process_effect_needs_a_print_at_its_null() {
        let check = |e: &Process, doc: &str| e.check_scenario(&doc.parse().unwrap());
        for e in [&Process::EXTRUSION_FACTOR, &Process::STANDOFF_OFFSET] {
            assert!(check(e, "[print]\nqueue = 4\n").is_ok());
            assert!(check(e, "[boundary]\n").unwrap_err().to_string().contains("prints nothing"));
            let bad = format!("[print]\n{} = 0.5\n", e.field);
            assert!(check(e, &bad).unwrap_err().to_string().contains(&format!("print.{} at its null", e.field)));
        }
    }
}
