//! Physical effects a model switches on by name, each with parameters and a null value at which
//! it vanishes; the base model is every effect at its null.
//!
//! An effect acts on the scenario keys an experiment runs with (`material.yield_stress`,
//! `boundary.z_min.friction.mu`, ...): [`Effect::apply`] sets them from the effect's parameters
//! and the experiment's covariates (rest time, age), and [`Effect::apply_adjoint`] carries the
//! keys' adjoints back to those parameters, so the solver's adjoint gives the gradient of any
//! observation with respect to an effect's parameters. Adding an effect is one file here and one
//! line in [`REGISTRY`]; `every_effect_adjoint_agrees_with_central_differences` and
//! `every_effect_at_its_start_runs_as_the_model_without_it` test it.

use super::error::MeasureError;

pub mod ageing;
pub mod declared;
mod effect;
pub mod maxwell;
pub mod modulus;
pub mod process;
pub mod shear_thinning;
pub mod thixotropy;
pub mod viscosity_ageing;
pub mod wall_friction;

pub use effect::{
    add_bar, bar, read, shear_modulus, Covariates, Effect, Keys, ParamSpec, BULK_MODULUS, POISSON_RATIO, SHEAR_MODULUS,
};

/// Every effect of the library, in the order they apply; effects declared in a model file
/// ([`declared`]) apply after them.
pub const REGISTRY: &[&dyn Effect] = &[
    &ageing::Ageing::LINEAR,
    &ageing::Ageing::EXPONENTIAL,
    &thixotropy::Thixotropy,
    &viscosity_ageing::ViscosityAgeing,
    &wall_friction::WallFriction,
    &maxwell::Maxwell,
    &shear_thinning::ShearThinning,
    &modulus::Modulus::ELASTICITY,
    &modulus::Modulus::COMPRESSIBILITY,
    &process::Process::EXTRUSION_FACTOR,
    &process::Process::STANDOFF_OFFSET,
];

pub fn find(name: &str) -> Result<&'static dyn Effect, MeasureError> {
    REGISTRY.iter().copied().find(|e| e.name() == name).ok_or_else(|| {
        MeasureError::Effect(format!(
            "unknown effect '{name}'; known: {}",
            REGISTRY.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// Where `key` lands in a scenario (its TOML document): the floor's friction
/// ([`wall_friction::KEY`]) on the platform the material is printed on when the scenario has
/// one, on the `z_min` face otherwise; every other key where it says.
pub fn placed(key: &str, scenario: &toml::Table) -> String {
    if key != wall_friction::KEY {
        return key.to_string();
    }
    match wall_friction::on_platform(scenario) {
        true => wall_friction::PLATFORM_KEY.to_string(),
        false => wall_friction::Z_MIN_KEY.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The keys a base model sets, with the Maxwell branch's at the material's defaults (no
    /// branch is G_M = 0; t_M defaults to 1 s), so the nulls are checked on them too, and K with
    /// G, or with the Poisson ratio that ties G to it: the stand-ins for the nulls of elasticity
    /// and compressibility.
    fn base_keys() -> [Keys; 2] {
        let common = [
            ("material.yield_stress", 120.0),
            ("material.viscosity", 20.0),
            ("material.a_thix", 0.0),
            ("material.alpha", 0.0),
            ("material.lambda0", 0.0),
            ("material.maxwell_modulus", 0.0),
            ("material.maxwell_time", 1.0),
            ("material.bulk_modulus", 1e6),
        ];
        [("material.shear_modulus", 4e5), ("material.poisson_ratio", 0.3)]
            .map(|g| common.iter().chain([&g]).map(|(k, v)| (k.to_string(), *v)).collect())
    }

    /// The library's effects and the declared examples.
    fn every_effect() -> Vec<&'static dyn Effect> {
        let material: toml::Table = "yield_stress = 120.0\nviscosity = 20.0\n".parse().unwrap();
        let declared = declared::EXAMPLES.iter().map(|text| {
            let t: toml::Table = text.parse().unwrap();
            let (name, table) = t["effects"].as_table().unwrap().iter().next().unwrap();
            declared::declare(name, table.as_table().unwrap(), &material, &|_| None).unwrap().effect as &dyn Effect
        });
        REGISTRY.iter().copied().chain(declared).collect()
    }

    /// The covariates the tests run at, with the one a declared example reads.
    fn covariates() -> Covariates {
        Covariates {
            rest_time: 240.0,
            age: 1800.0,
            declared: [("temperature".to_string(), 31.0)].into_iter().collect(),
        }
    }

    /// J = sum_k w_k keys_k after the effect, against central differences in every parameter
    /// and every key it reads, at a point away from the null. J is summed as differences from
    /// the unperturbed keys, so a large key (G ~ 1e5 Pa) does not drown the others' differences
    /// in round-off.
    #[test]
    fn every_effect_adjoint_agrees_with_central_differences() {
        let x = covariates();
        for (e, keys) in every_effect().into_iter().flat_map(|e| base_keys().map(|k| (e, k))) {
            // a null at infinity is left for a value the solver runs, as a fit would
            let p: Vec<f64> =
                e.params().iter().map(|s| if s.null.is_finite() { s.null } else { 0.0 } + 0.7 * s.scale).collect();
            let mut out = keys.clone();
            e.apply(&p, &x, &mut out).unwrap();
            let w: Keys = out.keys().enumerate().map(|(i, k)| (k.clone(), 1.0 + 0.37 * i as f64)).collect();
            let j = |p: &[f64], keys: &Keys| {
                let mut o = keys.clone();
                e.apply(p, &x, &mut o).unwrap();
                o.iter().map(|(k, v)| w[k] * (v - out[k])).sum::<f64>()
            };
            let mut kb = w.clone();
            let mut pb = vec![0.0; p.len()];
            e.apply_adjoint(&p, &x, &keys, &mut kb, &mut pb);
            for i in 0..p.len() {
                let h = 1e-6 * e.params()[i].scale;
                let (mut a, mut b) = (p.clone(), p.clone());
                a[i] += h;
                b[i] -= h;
                let fd = (j(&a, &keys) - j(&b, &keys)) / (2.0 * h);
                assert!(
                    (pb[i] - fd).abs() <= 1e-6 * fd.abs().max(1.0),
                    "{}.{}: adjoint {} vs {fd}",
                    e.name(),
                    e.params()[i].name,
                    pb[i]
                );
            }
            for k in keys.keys() {
                let h = 1e-6 * keys[k].abs().max(1.0);
                let (mut a, mut b) = (keys.clone(), keys.clone());
                *a.get_mut(k).unwrap() += h;
                *b.get_mut(k).unwrap() -= h;
                let fd = (j(&p, &a) - j(&p, &b)) / (2.0 * h);
                assert!(
                    (bar(&kb, k) - fd).abs() <= 1e-6 * fd.abs().max(1.0),
                    "{}: d/d{k}: adjoint {} vs {fd}",
                    e.name(),
                    bar(&kb, k)
                );
            }
        }
    }

    /// Every effect that says its start runs as the model without it
    /// ([`Effect::start_runs_as_model`]) does, on the print campaign's line (shortened; material,
    /// boundary and print keys all in play), from a model with a Poisson ratio and one with G,
    /// alone and all at once: every particle's position, velocity, J and stress, all an
    /// observable reads, are the same bits (the material's state may hold more: a Maxwell branch
    /// at G_M = 0 carries its stress, 0). A finite floor friction, which does not say so, is seen
    /// to change the run.
    #[test]
    fn every_effect_at_its_start_runs_as_the_model_without_it() {
        use crate::measure::model::Model;
        use crate::measure::campaign::runner::Applied;
        let line = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/print/line.toml");
        let dir = tempfile::tempdir().unwrap();
        let short = dir.path().join("line.toml");
        let text = std::fs::read_to_string(&line).unwrap();
        assert!(text.contains("end_time = 0.9"));
        std::fs::write(&short, text.replace("end_time = 0.9", "end_time = 0.3")).unwrap();
        let x = covariates();
        let state = |m: &Model| -> Vec<u64> {
            let mut sc = Applied::with_keys(m, m.keys(&x).unwrap()).scenario(&short).unwrap();
            sc.simulation.threads = 1;
            let mut sim = crate::solver::Simulation::new(&sc).unwrap();
            let end = sc.simulation.end_time;
            while sim.time < end * (1.0 - 1e-12) {
                sim.step_until(end).unwrap();
            }
            let p = &sim.particles;
            let n = p.n;
            let vectors = p.xg.as_slice()[..n].iter().chain(&p.v.as_slice()[..n]).flat_map(|v| v.to_array());
            let stress = p.stress.as_slice()[..n].iter().flat_map(|s| s.to_cols_array());
            vectors.chain(stress).chain(p.j.as_slice()[..n].iter().copied()).map(|x| (x as f64).to_bits()).collect()
        };
        let at_start = |m: &Model, e: &'static dyn Effect| -> Model {
            let start = e.lr_start(&m.keys(&x).unwrap()).unwrap();
            let mut with = m.with_effect(e);
            for (s, v) in e.params().iter().zip(start) {
                with.set(&format!("{}.{}", e.name(), s.name), v).unwrap();
            }
            with
        };
        let material = "[material]\nkind = \"evp_bingham\"\ndensity = 2100.0\nbulk_modulus = 5.0e4\nviscosity = 20.0\n\
            yield_stress = 100.0\n";
        for g in ["poisson_ratio = 0.3", "shear_modulus = 2.3e4"] {
            let base = Model::from_table(&format!("{material}{g}\n").parse().unwrap()).unwrap();
            let own = state(&base);
            let mut all = base.clone();
            for &e in REGISTRY {
                let with = at_start(&base, e);
                if e.start_runs_as_model() {
                    assert_eq!(state(&with), own, "{} at its start, from {g}", e.name());
                    all = at_start(&all, e);
                } else {
                    assert_ne!(state(&with), own, "{} at its start, from {g}", e.name());
                }
            }
            assert_eq!(state(&all), own, "every effect at its start at once, from {g}");
        }
    }

    #[test]
    fn every_effect_vanishes_at_its_null() {
        let x = covariates();
        for (e, keys) in every_effect().into_iter().flat_map(|e| base_keys().map(|k| (e, k))) {
            let null: Vec<f64> = e.params().iter().map(|s| s.null).collect();
            let mut out = keys.clone();
            e.apply(&null, &x, &mut out).unwrap();
            for (k, v) in &keys {
                assert_eq!(out[k], *v, "{} changes {k} at its null", e.name());
            }
        }
    }
}
