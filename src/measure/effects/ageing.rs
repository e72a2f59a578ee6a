//! Structural ageing: the yield stress grows with the material's age t since mixing,
//! irreversibly (hydration, not flocculation: flow does not undo it, unlike thixotropy).
//! Linear, tau0 (1 + r t), or exponential, tau0 exp(r t), evaluated at the experiment's age: a
//! test lasts seconds, ageing takes tens of minutes, so the yield stress is taken as constant
//! over one test. Null: r = 0.

use super::super::error::MeasureError;
use super::effect::{add_bar, bar, read, Covariates, Effect, Keys, ParamSpec};

pub struct Ageing {
    name: &'static str,
    exponential: bool,
}

impl Ageing {
    pub const LINEAR: Ageing = Ageing { name: "ageing", exponential: false };
    pub const EXPONENTIAL: Ageing = Ageing { name: "ageing_exp", exponential: true };

    /// tau0(t) / tau0 and its derivative in r.
    fn factor(&self, r: f64, age: f64) -> (f64, f64) {
        if self.exponential {
            let f = (r * age).exp();
            (f, age * f)
        } else {
            (1.0 + r * age, age)
        }
    }
}

const PARAMS: &[ParamSpec] =
    &[ParamSpec { name: "rate", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 2e-4, unit: "1/s" }];

impl Effect for Ageing {
    fn name(&self) -> &'static str {
        self.name
    }
    fn about(&self) -> &'static str {
        if self.exponential {
            "irreversible ageing of the yield stress, tau0 exp(rate age)"
        } else {
            "irreversible ageing of the yield stress, tau0 (1 + rate age)"
        }
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], x: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        let tau0 = read(keys, self.name, "material.yield_stress")?;
        keys.insert("material.yield_stress".into(), tau0 * self.factor(p[0], x.age).0);
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], x: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        let tau0 = keys_in["material.yield_stress"];
        let (f, df) = self.factor(p[0], x.age);
        let t_bar = bar(keys_bar, "material.yield_stress");
        p_bar[0] += t_bar * tau0 * df;
        keys_bar.insert("material.yield_stress".into(), 0.0);
        add_bar(keys_bar, "material.yield_stress", t_bar * f);
    }
}
