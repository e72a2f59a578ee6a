//! Thixotropic build-up and breakdown (Roussel; paper 001 eqs. 11-12, 22): the yield stress is
//! (1 + lambda) tau0, lambda builds at rest at A_thix / tau0 and breaks down at alpha lambda
//! gamma_dot_p. Sets the material's `a_thix` and `alpha`, and the structure a test starts with
//! after its rest time, lambda0 = A_thix t_rest / tau0 (so the yield stress at the start is
//! tau0 + A_thix t_rest, Roussel's linear build-up). Null: A_thix = alpha = 0. Needs a material
//! that carries lambda (evp_bingham, papanastasiou_roussel).
//!
//! At A_thix = 0 no structure builds (lambda0 = 0 too) and alpha has none to break: alpha is left
//! out of the keys, so its column there is 0 without a run. Written out, it would move a run in
//! its last bits only (the return map's quadratic carries alpha even where lambda = 0).

use super::super::error::MeasureError;
use super::effect::{add_bar, bar, read, Covariates, Effect, Keys, ParamSpec};

pub struct Thixotropy;

const PARAMS: &[ParamSpec] = &[
    ParamSpec { name: "a_thix", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 0.5, unit: "Pa/s" },
    ParamSpec { name: "alpha", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 0.01, unit: "-" },
];

impl Effect for Thixotropy {
    fn name(&self) -> &'static str {
        "thixotropy"
    }
    fn about(&self) -> &'static str {
        "structural build-up at rest and breakdown by flow (Roussel: A_thix, alpha; lambda0 from the rest time)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], x: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        let tau0 = read(keys, self.name(), "material.yield_stress")?;
        let lambda0 = if p[0] > 0.0 { p[0] * x.rest_time / tau0 } else { 0.0 };
        keys.insert("material.a_thix".into(), p[0]);
        if p[0] > 0.0 {
            keys.insert("material.alpha".into(), p[1]);
        }
        keys.insert("material.lambda0".into(), lambda0);
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], x: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        let tau0 = keys_in["material.yield_stress"];
        let l_bar = bar(keys_bar, "material.lambda0");
        p_bar[0] += bar(keys_bar, "material.a_thix") + l_bar * x.rest_time / tau0;
        add_bar(keys_bar, "material.yield_stress", -l_bar * p[0] * x.rest_time / (tau0 * tau0));
        // the material's own values are overwritten (alpha only where it was written)
        for k in ["material.a_thix", "material.lambda0"] {
            keys_bar.insert(k.into(), 0.0);
        }
        if p[0] > 0.0 {
            p_bar[1] += bar(keys_bar, "material.alpha");
            keys_bar.insert("material.alpha".into(), 0.0);
        }
    }
}
