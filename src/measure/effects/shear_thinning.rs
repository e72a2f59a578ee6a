//! Shear thinning (or thickening): the Herschel-Bulkley flow index n of the Bingham-family
//! materials, tau = tau0 + k gamma_dot^n with the model's `viscosity` playing k. Sets
//! `material.flow_index` = n (see `kernels/src/material/bingham.rs`, `papanastasiou_roussel.rs`
//! and `evp_bingham.rs`, which differentiate their update with respect to it). A flow curve that
//! bends below the Bingham line at mid rates (n < 1) is its signature.
//!
//! Null: n = 1, the Bingham law. The key is set even then, so the adjoint gives the derivative
//! in n at the null (the score test's).

use super::super::error::MeasureError;
use super::effect::{bar, Covariates, Effect, Keys, ParamSpec};

pub struct ShearThinning;

const KEY: &str = "material.flow_index";

const PARAMS: &[ParamSpec] = &[ParamSpec { name: "n", null: 1.0, lower: 0.2, upper: 1.5, scale: 0.1, unit: "-" }];

impl Effect for ShearThinning {
    fn name(&self) -> &'static str {
        "shear_thinning"
    }
    fn about(&self) -> &'static str {
        "Herschel-Bulkley flow index n, tau = tau0 + k gamma_dot^n (k the viscosity key; n < 1 thins, n > 1 thickens)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        keys.insert(KEY.into(), p[0]);
        Ok(())
    }
    fn apply_adjoint(&self, _: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        p_bar[0] += bar(keys_bar, KEY);
        // the material's own value is overwritten
        keys_bar.insert(KEY.into(), 0.0);
    }
    /// `scenario` is the experiment's scenario with the model's `[material]` in place.
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), MeasureError> {
        match scenario.get("material").and_then(|m| m.get("kind")).and_then(|k| k.as_str()) {
            Some("bingham" | "papanastasiou_roussel" | "evp_bingham") => Ok(()),
            other => Err(MeasureError::Effect(format!(
                "needs a Bingham-family material (material.kind = \"bingham\", \"papanastasiou_roussel\" or \
                    \"evp_bingham\"), and it is {}",
                other.map_or("not set".to_string(), |k| format!("\"{k}\""))
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::model::Model;
    use crate::measure::campaign::rheometer::{Protocol, Rheometer};

    #[test]
    fn it_needs_a_bingham_family_material() {
        let doc = |kind: &str| -> toml::Table { format!("[material]\nkind = \"{kind}\"\n").parse().unwrap() };
        for kind in ["bingham", "papanastasiou_roussel", "evp_bingham"] {
            assert!(ShearThinning.check_scenario(&doc(kind)).is_ok(), "{kind}");
        }
        let e = ShearThinning.check_scenario(&doc("newtonian")).unwrap_err().to_string();
        assert!(e.contains("Bingham-family") && e.contains("\"newtonian\""), "{e}");
    }

    /// The effect's key reaches each material, whose rheometer flow curve then follows
    /// tau0 + k gamma_dot^n; and d(reading)/dn through the rheometer's adjoint and the effect's
    /// agrees with central differences in the effect's parameter, at the null and away from it.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn its_gradient_through_the_rheometer_matches_central_differences() {
        let materials = [
            "kind = \"bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\nviscosity = 25.0\nyield_stress = 80.0\n",
            "kind = \"papanastasiou_roussel\"\ndensity = 2300.0\nbulk_modulus = 1e6\nviscosity = 25.0\nyield_stress = \
                80.0\npapanastasiou_m = 100.0\n",
            "kind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\nshear_modulus = 2e4\nviscosity = 25.0\n\
                yield_stress = 80.0\na_thix = 0.3\nalpha = 0.1\n",
        ];
        let proto: Protocol =
            toml::from_str("dt = 1e-3\n[[phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0, 1.0, 0.3]\nhold = 0.5\n")
                .unwrap();
        let weights = [1.0, -0.5, 2.0, 0.7];
        let loss = |mat: &str, n: f64| -> (f64, f64) {
            let model =
                Model::from_table(&format!("[material]\n{mat}[effects.shear_thinning]\nn = {n}\n").parse().unwrap())
                    .unwrap();
            let x = Covariates::default();
            let keys = model.keys(&x).unwrap();
            assert_eq!(keys[KEY], n);
            let m = crate::measure::campaign::runner::Applied::with_keys(&model, keys).material().unwrap();
            let rh = Rheometer::new(&*m, &proto).unwrap();
            let (readings, grad) = rh.gradient(&weights).unwrap();
            let kb: Keys = m.param_names().iter().map(|p| format!("material.{p}")).zip(grad).collect();
            let n = model.parameters(&["shear_thinning.n".to_string()]).unwrap();
            let g = model.keys_adjoint(&x, kb, &n).unwrap()[0];
            (readings.iter().zip(weights).map(|(r, w)| w * r.stress).sum(), g)
        };
        for mat in materials {
            for n in [1.0, 0.6, 1.3] {
                let (_, g) = loss(mat, n);
                let h = 1e-5;
                let cd = (loss(mat, n + h).0 - loss(mat, n - h).0) / (2.0 * h);
                assert!((g - cd).abs() <= 1e-5 * cd.abs(), "{mat} n = {n}: adjoint {g}, central difference {cd}");
                // the readings move with n: the score at the null is not 0
                assert!(cd.abs() > 1.0, "{mat} n = {n}: {cd}");
            }
        }
    }
}
