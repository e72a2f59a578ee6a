//! Compressibility: the material changes volume under pressure with bulk modulus K (entrained
//! air, a loose granular skeleton), against an incompressible one. Sets `material.bulk_modulus`
//! = K, the K of the equation of state.
//!
//! Null: K = infinity, which the explicit solver cannot run (the wave speed, and so the stable
//! step, goes with sqrt(K)); the base model runs its own finite `material.bulk_modulus` (weakly
//! compressible) as the stand-in, left alone at K = infinity, and diagnose tests the effect by
//! the likelihood ratio of its fit from there, as elasticity's (see `elasticity.rs`). Simple
//! shear in the rheometer keeps the volume, so only simulations see it.

use super::{bar, read_modulus, Covariates, Effect, Keys, ParamSpec};

pub struct Compressibility;

const KEY: &str = "material.bulk_modulus";

const PARAMS: &[ParamSpec] = &[
    // the weakly compressible stand-ins run at 1e5 to 1e7 Pa; K stays > 0, as the material requires
    ParamSpec { name: "bulk_modulus", null: f64::INFINITY, lower: 1.0, upper: f64::INFINITY, scale: 1e6, unit: "Pa" },
];

impl Effect for Compressibility {
    fn name(&self) -> &'static str {
        "compressibility"
    }
    fn about(&self) -> &'static str {
        "compressibility: bulk modulus K of the material, against an incompressible one (K = infinity)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), String> {
        read_modulus(keys, self.name(), KEY)?;
        if p[0].is_finite() {
            keys.insert(KEY.into(), p[0]);
        }
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], _: &Covariates, _: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        if p[0].is_finite() {
            p_bar[0] += bar(keys_bar, KEY);
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
