//! Coulomb friction on the floor (the `z_min` face the material spreads or is printed on): the
//! wall takes the tangential velocity down by mu times the normal velocity into it (paper 002
//! eq. 35). Null: mu = 0, a free-slip floor, so the scenario's `z_min` must be free slip for the
//! base model to be this effect's null; a no-slip floor is the limit mu -> infinity, where the
//! wall sticks and the loss no longer depends on mu (no score test can see it from there). A
//! rheometer test has no walls: the effect does not reach it.

use super::{bar, Covariates, Effect, Keys, ParamSpec};

pub struct WallFriction;

pub const KEY: &str = "boundary.z_min.friction.mu";

const PARAMS: &[ParamSpec] = &[ParamSpec { name: "mu", null: 0.0, lower: 0.0, upper: f64::INFINITY, scale: 0.2, unit: "-" }];

impl Effect for WallFriction {
    fn name(&self) -> &'static str {
        "wall_friction"
    }
    fn about(&self) -> &'static str {
        "Coulomb friction mu on the floor (z_min), against a free-slip floor"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        // at mu = 0 the friction wall is the free-slip wall to the bit (apply_wall keeps all of
        // vt), and its key is there for the score test to differentiate
        keys.insert(KEY.into(), p[0]);
        Ok(())
    }
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), String> {
        let floor = scenario.get("boundary").and_then(|b| b.get("z_min"));
        match floor {
            Some(toml::Value::String(k)) if k == "free_slip" => Ok(()),
            // a floor with its own friction or no slip is not this effect's null
            other => Err(format!(
                "needs a free-slip floor (its null), and boundary.z_min is {}",
                other.map_or("not set".to_string(), |v| v.to_string())
            )),
        }
    }
    fn apply_adjoint(&self, _: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        p_bar[0] += bar(keys_bar, KEY);
        keys_bar.remove(KEY);
    }
}
