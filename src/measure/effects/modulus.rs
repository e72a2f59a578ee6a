//! Elastic moduli as effects, each against a material that does not have that compliance:
//!
//! * `elasticity`: elastic response and flow stoppage. The EVP material is a solid below yield
//!   with shear modulus G (it loads elastically before it flows, and a flow that stops leaves an
//!   elastic stress), against a rigid-viscoplastic one. Sets `material.shear_modulus` = G.
//! * `compressibility`: the material changes volume under pressure with bulk modulus K
//!   (entrained air, a loose granular skeleton), against an incompressible one. Sets
//!   `material.bulk_modulus` = K, the K of the equation of state. Simple shear in the rheometer
//!   keeps the volume, so only simulations see it.
//!
//! Null: the modulus at infinity (compliance 0), which the explicit solver cannot run: the wave
//! speed, and so the stable step, goes with its square root. The base model runs its own finite
//! modulus as the stand-in for it, and at infinity the effect leaves that key alone, so the
//! effect at its null is the base model as run. Diagnose fits the effect from that stand-in
//! (`stand_in`) and tests it by the likelihood ratio, not by the score at the null (see
//! `diagnose.rs`). A model that gives `poisson_ratio` would tie G to K: it is told to give
//! `shear_modulus`.

use super::{bar, read_modulus, Covariates, Effect, Keys, ParamSpec};

pub struct Modulus {
    name: &'static str,
    about: &'static str,
    key: &'static str,
    params: &'static [ParamSpec],
}

impl Modulus {
    pub const ELASTICITY: Modulus = Modulus {
        name: "elasticity",
        about: "elastic response and flow stoppage: shear modulus G of the EVP solid, against a rigid one (G = infinity)",
        key: "material.shear_modulus",
        // a fresh mortar or concrete at rest: 1e4 to 1e6 Pa; G stays > 0, as the material requires
        params: &[ParamSpec { name: "shear_modulus", null: f64::INFINITY, lower: 1.0, upper: f64::INFINITY, scale: 1e5, unit: "Pa" }],
    };
    pub const COMPRESSIBILITY: Modulus = Modulus {
        name: "compressibility",
        about: "compressibility: bulk modulus K of the material, against an incompressible one (K = infinity)",
        key: "material.bulk_modulus",
        // the weakly compressible stand-ins run at 1e5 to 1e7 Pa; K stays > 0, as the material requires
        params: &[ParamSpec { name: "bulk_modulus", null: f64::INFINITY, lower: 1.0, upper: f64::INFINITY, scale: 1e6, unit: "Pa" }],
    };
}

impl Effect for Modulus {
    fn name(&self) -> &'static str {
        self.name
    }
    fn about(&self) -> &'static str {
        self.about
    }
    fn params(&self) -> &'static [ParamSpec] {
        self.params
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        // checked at the null too, so a model that cannot take the effect is told before a fit
        read_modulus(keys, self.name, self.key)?;
        if p[0].is_finite() {
            keys.insert(self.key.into(), p[0]);
        }
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        if p[0].is_finite() {
            p_bar[0] += bar(keys_bar, self.key);
            // the model's own modulus is overwritten
            keys_bar.insert(self.key.into(), 0.0);
        }
    }
    fn null_at_infinity(&self) -> bool {
        true
    }
    fn stand_in(&self, keys: &Keys) -> Result<Vec<f64>, String> {
        Ok(vec![read_modulus(keys, self.name, self.key)?])
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
        for (e, own, set) in [(Modulus::ELASTICITY, 4e5, 2e4), (Modulus::COMPRESSIBILITY, 1e6, 3e5)] {
            let (name, param, key) = (e.name, e.params[0].name, e.key);
            for (effect, want) in [(format!("[effects.{name}]\n"), own), (format!("[effects.{name}]\n{param} = {set:e}\n"), set)] {
                let model = Model::from_table(&format!("{BASE}{effect}").parse().unwrap()).unwrap();
                assert_eq!(model.keys(&x).unwrap()[key], want, "{name}");
                // written and read back, the null (inf) included
                let back = Model::from_table(&model.to_toml().parse().unwrap()).unwrap();
                assert_eq!(back.keys(&x).unwrap()[key], want, "{name}");
            }
            let base = Model::from_table(&BASE.parse().unwrap()).unwrap();
            assert_eq!(e.stand_in(&base.keys(&x).unwrap()).unwrap(), vec![own], "{name}");
            let nu = BASE.replace("shear_modulus = 4e5", "poisson_ratio = 0.3");
            let err = Model::from_table(&format!("{nu}[effects.{name}]\n").parse().unwrap()).unwrap().keys(&x).unwrap_err();
            assert!(err.contains("not poisson_ratio"), "{name}: {err}");
        }
    }
}
