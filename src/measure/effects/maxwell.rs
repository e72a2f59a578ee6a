//! A viscoelastic Maxwell branch (paper 004): a spring G_M and a dashpot eta_M = G_M t_M in
//! series, in parallel with the EVP material, adding a deviatoric stress that builds under flow
//! (towards eta_M gamma_dot in steady shear at t_M gamma_dot << 1) and relaxes at rest as
//! exp(-t / t_M). Sets `material.maxwell_modulus` = G_M and `material.maxwell_time` = t_M (see
//! `kernels/src/material/maxwell.rs`). Needs `evp_bingham`.
//!
//! Null: G_M = 0, whatever t_M: the branch's stress stays exactly 0. The modulus's key is set
//! even then, so the material carries the branch's state and the solver's adjoint gives the
//! derivative in G_M at the null (the score test's). t_M's null is the material's default, 1 s,
//! which is also where a fit begun at the null starts it; at G_M = 0 every derivative in t_M is
//! exactly 0, so only `modulus` can flag the effect, and t_M moves once G_M has. Its key is left
//! out at G_M = 0, where it changes nothing: an experiment's keys then do not move with t_M, and
//! its Jacobian column is 0 without the runs central differences would take.

use super::super::error::MeasureError;
use super::effect::{bar, Covariates, Effect, Keys, ParamSpec};

pub struct Maxwell;

const MODULUS: &str = "material.maxwell_modulus";
const TIME: &str = "material.maxwell_time";

const PARAMS: &[ParamSpec] = &[
    ParamSpec { name: "modulus", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 100.0, unit: "Pa" },
    ParamSpec { name: "time", null: 1.0, lower: 1e-3, upper: f64::INFINITY, scale: 1.0, unit: "s" },
];

impl Effect for Maxwell {
    fn name(&self) -> &'static str {
        "maxwell"
    }
    fn about(&self) -> &'static str {
        "viscoelastic Maxwell branch in parallel (paper 004): modulus G_M, relaxation time t_M = eta_M / G_M"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        keys.insert(MODULUS.into(), p[0]);
        if p[0] != 0.0 {
            keys.insert(TIME.into(), p[1]);
        }
        Ok(())
    }
    fn apply_adjoint(&self, _: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        p_bar[0] += bar(keys_bar, MODULUS);
        p_bar[1] += bar(keys_bar, TIME);
        // the material's own values are overwritten
        keys_bar.insert(MODULUS.into(), 0.0);
        keys_bar.insert(TIME.into(), 0.0);
    }
    /// `scenario` is the experiment's scenario with the model's `[material]` in place.
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), MeasureError> {
        match scenario.get("material").and_then(|m| m.get("kind")).and_then(|k| k.as_str()) {
            Some("evp_bingham") => Ok(()),
            other => Err(MeasureError::Effect(format!(
                "needs material.kind = \"evp_bingham\" (the material with a Maxwell branch), and it is {}",
                other.map_or("not set".to_string(), |k| format!("\"{k}\""))
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::model::Model;

    #[test]
    fn it_needs_the_evp_material_and_its_keys_give_the_material_the_branch() {
        let doc = |kind: &str| -> toml::Table { format!("[material]\nkind = \"{kind}\"\n").parse().unwrap() };
        assert!(Maxwell.check_scenario(&doc("evp_bingham")).is_ok());
        let e = Maxwell.check_scenario(&doc("bingham")).unwrap_err().to_string();
        assert!(e.contains("evp_bingham") && e.contains("\"bingham\""), "{e}");
        assert!(Maxwell.check_scenario(&toml::Table::new()).unwrap_err().to_string().contains("not set"));
        // the model's keys make the material: the branch on, or at its null with its state
        let base = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\nshear_modulus = 1e5\n\
            viscosity = 20.0\nyield_stress = 100.0\n";
        for (effect, g_m) in [("[effects.maxwell]\nmodulus = 50.0\ntime = 0.3\n", 50.0), ("[effects.maxwell]\n", 0.0)] {
            let model = Model::from_table(&format!("{base}{effect}").parse().unwrap()).unwrap();
            let keys = model.keys(&Covariates::default()).unwrap();
            let mut mat = model.material.clone();
            for (k, v) in &keys {
                mat.insert(k.strip_prefix("material.").unwrap().to_string(), toml::Value::Float(*v));
            }
            let m = crate::materials::build_material(&mat).unwrap();
            assert_eq!((m.state_names().len(), m.param_names().len()), (14, 10));
            assert_eq!(m.stability().shear_modulus, 1e5 + g_m as crate::kernels::Real);
        }
    }
}
