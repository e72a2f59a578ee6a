//! Coulomb friction on the floor (the `z_min` face the material spreads or is printed on): the
//! wall takes the tangential velocity down by mu times the normal velocity into it (paper 002
//! eq. 35), so the floor lets the material slide once the shear it carries passes mu times the
//! normal load. Null: a no-slip floor, the base model's, which no finite mu is (a friction wall
//! still lets go of material moving away from it, and slides wherever the shear passes mu times
//! the load): mu = infinity, where the loss does not depend on mu, so there is no score to take
//! and diagnose tests the effect by the likelihood ratio, fitting mu from a typical value
//! (`lr_start`). A rheometer test has no walls: the effect does not reach it.

use super::{Covariates, Effect, Keys, ParamSpec};

pub struct WallFriction;

pub const KEY: &str = "boundary.z_min.friction.mu";

const PARAMS: &[ParamSpec] = &[ParamSpec { name: "mu", null: f64::INFINITY, lower: 0.0, upper: f64::INFINITY, scale: 0.2, unit: "-" }];

impl Effect for WallFriction {
    fn name(&self) -> &'static str {
        "wall_friction"
    }
    fn about(&self) -> &'static str {
        "Coulomb friction mu on the floor (z_min), against a no-slip floor (mu = infinity)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        // the key turns the scenario's no-slip floor into a friction wall (`set_path`)
        if p[0].is_finite() {
            keys.insert(KEY.into(), p[0]);
        }
        Ok(())
    }
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), String> {
        let boundary = scenario.get("boundary");
        if boundary.and_then(|b| b.get("platform")).is_some() {
            return Err("acts on the z_min floor, and this scenario's material stands on boundary.platform".into());
        }
        match boundary.and_then(|b| b.get("z_min")) {
            // no-slip is the floor's default
            None => Ok(()),
            Some(toml::Value::String(k)) if k == "no_slip" => Ok(()),
            // a floor that slips or has its own friction is not this effect's null
            Some(other) => Err(format!("needs a no-slip floor (its null), and boundary.z_min is {other}")),
        }
    }
    fn apply_adjoint(&self, p: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        if p[0].is_finite() {
            p_bar[0] += keys_bar.remove(KEY).unwrap_or(0.0);
        }
    }
    fn null_at_infinity(&self) -> bool {
        true
    }
    fn lr_start(&self, _: &Keys) -> Result<Vec<f64>, String> {
        Ok(vec![PARAMS[0].scale])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_needs_a_no_slip_floor_and_no_platform() {
        let check = |b: &str| WallFriction.check_scenario(&format!("[boundary]\n{b}").parse().unwrap());
        assert!(check("").is_ok() && check("z_min = \"no_slip\"\n").is_ok());
        for (floor, says) in [("z_min = \"free_slip\"\n", "\"free_slip\""), ("z_min = { friction = { mu = 0.3 } }\n", "mu = 0.3"), ("platform = { z = 0.01, xy_min = [0.0, 0.0], xy_max = [1.0, 1.0] }\n", "platform")] {
            let e = check(floor).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }
}
