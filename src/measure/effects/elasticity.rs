//! Elastic response and flow stoppage: the EVP material is a solid below yield with shear
//! modulus G (it loads elastically before it flows, and a flow that stops leaves an elastic
//! stress), against a rigid-viscoplastic one. Sets `material.shear_modulus` = G.
//!
//! Null: G = infinity (compliance 1/G = 0), the rigid material, which the explicit solver cannot
//! run: the elastic wave speed and so the stable step go with sqrt(G). The base model runs its
//! own finite `material.shear_modulus` as the stand-in for it, and at G = infinity the effect
//! leaves that key alone, so the effect at its null is the base model as run. Diagnose fits the
//! effect from that stand-in (`stand_in`) and tests it by the likelihood ratio, not by the score
//! at the null (see `diagnose.rs`). A model that gives `poisson_ratio` instead would have G twice
//! over: it is told to give `shear_modulus`.

use super::{bar, read_modulus, Covariates, Effect, Keys, ParamSpec};

pub struct Elasticity;

const KEY: &str = "material.shear_modulus";

const PARAMS: &[ParamSpec] = &[
    // a fresh mortar or concrete at rest: 1e4 to 1e6 Pa; G stays > 0, as the material requires
    ParamSpec { name: "shear_modulus", null: f64::INFINITY, lower: 1.0, upper: f64::INFINITY, scale: 1e5, unit: "Pa" },
];

impl Effect for Elasticity {
    fn name(&self) -> &'static str {
        "elasticity"
    }
    fn about(&self) -> &'static str {
        "elastic response and flow stoppage: shear modulus G of the EVP solid, against a rigid one (G = infinity)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        // checked at the null too, so a model that cannot take the effect is told before a fit
        read_modulus(keys, self.name(), KEY)?;
        if p[0].is_finite() {
            keys.insert(KEY.into(), p[0]);
        }
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        if p[0].is_finite() {
            p_bar[0] += bar(keys_bar, KEY);
            // the model's own G is overwritten
            keys_bar.insert(KEY.into(), 0.0);
        }
    }
    fn null_at_infinity(&self) -> bool {
        true
    }
    fn stand_in(&self, keys: &Keys) -> Result<Vec<f64>, String> {
        Ok(vec![read_modulus(keys, self.name(), KEY)?])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::model::Model;

    const BASE: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\nshear_modulus = 4e5\nviscosity = 20.0\nyield_stress = 100.0\n";

    #[test]
    fn its_null_is_the_base_models_stand_in_and_a_finite_modulus_replaces_it() {
        let x = Covariates::default();
        for (effect, g) in [("[effects.elasticity]\n", 4e5), ("[effects.elasticity]\nshear_modulus = 2e4\n", 2e4)] {
            let model = Model::from_table(&format!("{BASE}{effect}").parse().unwrap()).unwrap();
            assert_eq!(model.keys(&x).unwrap()[KEY], g);
            // written and read back, the null (inf) included
            let back = Model::from_table(&model.to_toml().parse().unwrap()).unwrap();
            assert_eq!(back.keys(&x).unwrap()[KEY], g);
        }
        let base = Model::from_table(&BASE.parse().unwrap()).unwrap();
        assert_eq!(Elasticity.stand_in(&base.keys(&x).unwrap()).unwrap(), vec![4e5]);
        let nu = BASE.replace("shear_modulus = 4e5", "poisson_ratio = 0.3");
        let e = Model::from_table(&format!("{nu}[effects.elasticity]\n").parse().unwrap()).unwrap().keys(&x).unwrap_err();
        assert!(e.contains("not poisson_ratio"), "{e}");
    }
}
