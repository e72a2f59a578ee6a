//! Elastic moduli as effects, each against a material that does not have that compliance:
//!
//! * `elasticity`: elastic response and flow stoppage. The EVP material is a solid below yield
//!   with shear modulus G (it loads elastically before it flows, and a flow that stops leaves an
//!   elastic stress), against a rigid-viscoplastic one. Sets `material.shear_modulus` = G.
//! * `compressibility`: the material changes volume under pressure with bulk modulus K
//!   (entrained air, a loose granular skeleton), against an incompressible one. Sets
//!   `material.bulk_modulus` = K, the K of the equation of state, and holds G at the model's.
//!   Simple shear in the rheometer keeps the volume, so only simulations see it.
//!
//! Null: the modulus at infinity (compliance 0), which the explicit solver cannot run: the wave
//! speed, and so the stable step, goes with its square root. The base model runs its own finite
//! modulus as the stand-in for it, and at infinity the effect leaves the keys alone, so the
//! effect at its null is the base model as run. Diagnose fits the effect from that stand-in
//! (`lr_start`) and tests it by the likelihood ratio, not by the score at the null (see
//! `diagnose.rs`).
//!
//! A model giving `poisson_ratio` nu ties G to K (G = 3 K (1 - 2 nu) / (2 (1 + nu))), so neither
//! could move alone: a finite modulus here replaces nu by the model's G (`shear_modulus`, what
//! the material computes from nu), and then sets its own. At the stand-in the material is the
//! base model's to the bit.

use super::super::error::MeasureError;
use crate::kernels::material::eos::shear_modulus_of_partials;
use super::effect::{
    bar, read, shear_modulus, Covariates, Effect, Keys, ParamSpec, BULK_MODULUS, POISSON_RATIO, SHEAR_MODULUS,
};

pub struct Modulus {
    name: &'static str,
    about: &'static str,
    key: &'static str,
    params: &'static [ParamSpec],
}

impl Modulus {
    pub const ELASTICITY: Modulus = Modulus {
        name: "elasticity",
        about:
            "elastic response and flow stoppage: shear modulus G of the EVP solid, against a rigid one (G = infinity)",
        key: "material.shear_modulus",
        // a fresh mortar or concrete at rest: 1e4 to 1e6 Pa; G stays > 0, as the material requires
        params: &[ParamSpec {
            name: "shear_modulus",
            null: f64::INFINITY,
            lower: 1.0,
            upper: f64::INFINITY,
            scale: 1e5,
            unit: "Pa",
        }],
    };
    pub const COMPRESSIBILITY: Modulus = Modulus {
        name: "compressibility",
        about: "compressibility: bulk modulus K of the material, against an incompressible one (K = infinity)",
        key: "material.bulk_modulus",
        // the weakly compressible stand-ins run at 1e5 to 1e7 Pa; K stays > 0, as the material requires
        params: &[ParamSpec {
            name: "bulk_modulus",
            null: f64::INFINITY,
            lower: 1.0,
            upper: f64::INFINITY,
            scale: 1e6,
            unit: "Pa",
        }],
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
    fn apply(&self, p: &[f64], _: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        // read at the null too, so a model that cannot take the effect is told before a fit
        let g = shear_modulus(keys, self.name)?;
        if p[0].is_finite() {
            if keys.remove(POISSON_RATIO).is_some() {
                keys.insert(SHEAR_MODULUS.into(), g);
            }
            keys.insert(self.key.into(), p[0]);
        }
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], _: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        if !p[0].is_finite() {
            return;
        }
        p_bar[0] += bar(keys_bar, self.key);
        // the model's own modulus is overwritten
        keys_bar.insert(self.key.into(), 0.0);
        if let Some(&nu) = keys_in.get(POISSON_RATIO) {
            // G = 3 K (1 - 2 nu) / (2 (1 + nu)) went on as the material's G (0 when it is the key
            // overwritten above); K and nu were not keys after it
            let g_bar = bar(keys_bar, SHEAR_MODULUS);
            let (dg_dk, dg_dnu) = shear_modulus_of_partials(keys_in[BULK_MODULUS], nu);
            keys_bar.insert(SHEAR_MODULUS.into(), 0.0);
            keys_bar.insert(POISSON_RATIO.into(), g_bar * dg_dnu);
            let k_bar = if self.key == BULK_MODULUS { 0.0 } else { bar(keys_bar, BULK_MODULUS) };
            keys_bar.insert(BULK_MODULUS.into(), k_bar + g_bar * dg_dk);
        }
    }
    fn null_at_infinity(&self) -> bool {
        true
    }
    fn lr_start(&self, keys: &Keys) -> Result<Vec<f64>, MeasureError> {
        let g = shear_modulus(keys, self.name)?;
        Ok(vec![if self.key == SHEAR_MODULUS { g } else { read(keys, self.name, self.key)? }])
    }
    /// The stand-in is the material's own modulus, G as it computes it from nu where the model
    /// gives nu (module doc).
    fn start_runs_as_model(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::model::Model;

    const BASE: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\nshear_modulus = 4e5\n\
        viscosity = 20.0\nyield_stress = 100.0\n";

    #[test]
    fn its_null_is_the_base_models_stand_in_and_a_finite_modulus_replaces_it() {
        let x = Covariates::default();
        for (e, own, set) in [(Modulus::ELASTICITY, 4e5, 2e4), (Modulus::COMPRESSIBILITY, 1e6, 3e5)] {
            let (name, param, key) = (e.name, e.params[0].name, e.key);
            for (effect, want) in
                [(format!("[effects.{name}]\n"), own), (format!("[effects.{name}]\n{param} = {set:e}\n"), set)]
            {
                let model = Model::from_table(&format!("{BASE}{effect}").parse().unwrap()).unwrap();
                assert_eq!(model.keys(&x).unwrap()[key], want, "{name}");
                // written and read back, the null (inf) included
                let back = Model::from_table(&model.to_toml().parse().unwrap()).unwrap();
                assert_eq!(back.keys(&x).unwrap()[key], want, "{name}");
            }
            let base = Model::from_table(&BASE.parse().unwrap()).unwrap();
            assert_eq!(e.lr_start(&base.keys(&x).unwrap()).unwrap(), vec![own], "{name}");
        }
    }

    /// With `poisson_ratio` nu, G is the material's G(K, nu) at the stand-in, and a finite
    /// modulus moves alone: the material built from the keys has the other one unchanged.
    #[test]
    fn a_model_with_a_poisson_ratio_has_its_moduli_set_apart() {
        let x = Covariates::default();
        let nu = BASE.replace("shear_modulus = 4e5", "poisson_ratio = 0.3");
        let base = Model::from_table(&nu.parse().unwrap()).unwrap();
        let moduli = |m: &Model| {
            let applied = crate::measure::campaign::runner::Applied::with_keys(m, m.keys(&x).unwrap());
            let s = applied.material().unwrap().stability();
            (s.shear_modulus as f64, s.bulk_modulus as f64)
        };
        let (g, k) = moduli(&base);
        assert!((g - 3e6 * 0.4 / 2.6).abs() < 1e-6 * g, "{g}");
        for (e, set) in [(&Modulus::ELASTICITY, 2e4), (&Modulus::COMPRESSIBILITY, 3e5)] {
            let start = e.lr_start(&base.keys(&x).unwrap()).unwrap()[0];
            assert_eq!(start, if e.key == SHEAR_MODULUS { g } else { k }, "{}", e.name);
            let mut m = base.with_effect(e);
            assert_eq!(moduli(&m), (g, k), "{} at its null", e.name);
            let p = format!("{}.{}", e.name, e.params[0].name);
            m.set(&p, start).unwrap();
            assert_eq!(moduli(&m), (g, k), "{} at its stand-in", e.name);
            m.set(&p, set).unwrap();
            let want = if e.key == SHEAR_MODULUS { (set, k) } else { (g, set) };
            assert_eq!(moduli(&m), want, "{}", e.name);
        }
    }
}
