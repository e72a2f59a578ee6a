//! Coulomb friction on the floor the material stands on: the print platform
//! (`boundary.platform`) when the scenario has one, the `z_min` face otherwise. The wall takes the tangential velocity
//! down by mu times the normal velocity into it (paper 002
//! eq. 35), so the floor lets the material slide once the shear it carries passes mu times the
//! normal load. Null: a no-slip floor, the base model's, which no finite mu is (a friction wall
//! still lets go of material moving away from it, and slides wherever the shear passes mu times
//! the load): mu = infinity, where the loss does not depend on mu, so there is no score to take
//! and diagnose tests the effect by the likelihood ratio, fitting mu from a typical value
//! (`lr_start`). A rheometer test has no walls: the effect does not reach it.

use super::super::error::MeasureError;
use super::effect::{Covariates, Effect, Keys, ParamSpec};

pub struct WallFriction;

/// The model's key: the floor's friction, wherever the floor is; [`super::placed`] puts it on
/// the scenario's platform or its `z_min` face.
pub const KEY: &str = "boundary.floor.friction.mu";
pub const Z_MIN_KEY: &str = "boundary.z_min.friction.mu";
pub const PLATFORM_KEY: &str = "boundary.platform.kind.friction.mu";

/// Whether the material of a scenario (its TOML document) stands on a print platform.
pub fn on_platform(scenario: &toml::Table) -> bool {
    scenario.get("boundary").and_then(|b| b.get("platform")).is_some()
}

const PARAMS: &[ParamSpec] =
    &[ParamSpec { name: "mu", null: f64::INFINITY, lower: 0.0, upper: f64::INFINITY, scale: 0.2, unit: "-" }];

impl Effect for WallFriction {
    fn name(&self) -> &'static str {
        "wall_friction"
    }
    fn about(&self) -> &'static str {
        "Coulomb friction mu on the floor (the platform, or z_min), against a no-slip floor (mu = infinity)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        // the key turns the scenario's no-slip floor into a friction wall (`set_path`)
        if p[0].is_finite() {
            keys.insert(KEY.into(), p[0]);
        }
        Ok(())
    }
    fn check_scenario(&self, scenario: &toml::Table) -> Result<(), MeasureError> {
        let boundary = scenario.get("boundary");
        let (name, floor) = match on_platform(scenario) {
            true => ("boundary.platform.kind", boundary.and_then(|b| b.get("platform")).and_then(|p| p.get("kind"))),
            false => ("boundary.z_min", boundary.and_then(|b| b.get("z_min"))),
        };
        match floor {
            // no-slip is the floor's default, the platform's as the face's
            None => Ok(()),
            Some(toml::Value::String(k)) if k == "no_slip" => Ok(()),
            // a floor that slips or has its own friction is not this effect's null
            Some(other) => {
                Err(MeasureError::Effect(format!("needs a no-slip floor (its null), and {name} is {other}")))
            }
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
    fn lr_start(&self, _: &Keys) -> Result<Vec<f64>, MeasureError> {
        Ok(vec![PARAMS[0].scale])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn it_needs_a_no_slip_floor_on_the_platform_or_the_z_min_face() {
        let doc = |b: &str| -> toml::Table { format!("[boundary]\n{b}").parse().unwrap() };
        let check = |b: &str| WallFriction.check_scenario(&doc(b));
        const PLATFORM: &str = "platform = { z = 0.01, xy_min = [0.0, 0.0], xy_max = [1.0, 1.0] }\n";
        let slipping = PLATFORM.replace(" }\n", ", kind = \"free_slip\" }\n");
        assert!(check("").is_ok() && check("z_min = \"no_slip\"\n").is_ok() && check(PLATFORM).is_ok());
        // the material stands on the platform: the face below it is not the floor
        assert!(check(&format!("z_min = \"free_slip\"\n{PLATFORM}")).is_ok());
        for (floor, says) in [
            ("z_min = \"free_slip\"\n", "boundary.z_min is \"free_slip\""),
            ("z_min = { friction = { mu = 0.3 } }\n", "mu = 0.3"),
            (slipping.as_str(), "boundary.platform.kind is \"free_slip\""),
        ] {
            let e = check(floor).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
        // the key lands on the floor, and a floor with friction is what the solver differentiates
        assert_eq!(super::super::placed(KEY, &doc(PLATFORM)), PLATFORM_KEY);
        assert_eq!(super::super::placed(KEY, &doc("")), Z_MIN_KEY);
        assert_eq!(super::super::placed("material.viscosity", &doc(PLATFORM)), "material.viscosity");
        for (b, key) in [(PLATFORM, PLATFORM_KEY), ("", Z_MIN_KEY)] {
            let mut d = doc(b);
            crate::measure::model::set_path(&mut d, key, 0.4).unwrap();
            let text = format!("{}\n[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n[simulation]\ndx = 0.1\n\
                end_time = 0.1\n[material]\nkind = \"newtonian\"\ndensity = 1000.0\nbulk_modulus = 1e5\nviscosity = \
                1.0\n[memory]\nbudget = \"16 MiB\"\n", toml::to_string(&d).unwrap());
            let sc = crate::scenario::Scenario::parse(&text).unwrap();
            let sim = crate::solver::Simulation::new(&sc).unwrap();
            assert!(
                crate::grad::params::known(&sim).iter().any(|k| k == key),
                "{key}: {:?}",
                crate::grad::params::known(&sim)
            );
        }
    }
}
