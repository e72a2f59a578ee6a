//! The material registry: scenario name -> constructor. Adding a material is one file in
//! `kernels/src/material/` and one line here.

use crate::kernels::material::{
    bingham::Bingham, drucker_prager::DruckerPrager, early_age::EarlyAgeSolid, evp_bingham::EvpBingham, newtonian::Newtonian,
    papanastasiou_roussel::PapanastasiouRoussel, Material, MaterialError,
};
use serde::de::DeserializeOwned;
use crate::invalid::Invalid;

type Builder = fn(toml::Table) -> Result<Box<dyn Material>, Invalid>;

pub const REGISTRY: &[(&str, Builder)] = &[
    ("newtonian", |t| build::<Newtonian>(t, Newtonian::validate)),
    ("bingham", |t| build::<Bingham>(t, Bingham::validate)),
    ("papanastasiou_roussel", |t| build::<PapanastasiouRoussel>(t, PapanastasiouRoussel::validate)),
    ("evp_bingham", |t| build::<EvpBingham>(t, EvpBingham::validate)),
    ("drucker_prager", |t| build::<DruckerPrager>(t, DruckerPrager::validate)),
    ("early_age_solid", |t| build::<EarlyAgeSolid>(t, EarlyAgeSolid::validate)),
];

fn build<M: Material + DeserializeOwned + 'static>(
    t: toml::Table,
    validate: fn(&M) -> Result<(), MaterialError>,
) -> Result<Box<dyn Material>, Invalid> {
    let m: M = t.try_into().map_err(|e: toml::de::Error| Invalid(format!("material: {}", e.message())))?;
    validate(&m).map_err(|e| Invalid(e.to_string()))?;
    Ok(Box::new(m))
}

/// Build the material a scenario's `[material]` table describes.
pub fn build_material(table: &toml::Table) -> Result<Box<dyn Material>, Invalid> {
    let mut t = table.clone();
    let kind = match t.remove("kind") {
        Some(toml::Value::String(k)) => k,
        _ => return Err(Invalid("material.kind must be a string naming the model".into())),
    };
    match REGISTRY.iter().find(|(name, _)| *name == kind) {
        Some((_, b)) => b(t),
        None => {
            let names: Vec<&str> = REGISTRY.iter().map(|r| r.0).collect();
            Err(Invalid(format!("material.kind '{kind}' is unknown; known: {}", names.join(", "))))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{Real, M3, V3};

    /// A typical parameter set of every registered material.
    fn examples() -> Vec<(&'static str, &'static str)> {
        let all = vec![
            ("newtonian", "density = 1000.0\nbulk_modulus = 1e6\nviscosity = 30.0"),
            ("bingham", "density = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\ncritical_shear_rate = 0.1"),
            (
                "papanastasiou_roussel",
                "density = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\na_thix = 0.5\nalpha = 0.01\nlambda_max = 2.0",
            ),
            ("evp_bingham", "density = 2100.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\nviscosity = 7.5\nyield_stress = 630.0\na_thix = 0.5\nalpha = 0.01"),
            ("drucker_prager", "density = 2000.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\nfriction_angle_deg = 30.0\ncohesion = 100.0"),
            (
                "early_age_solid",
                "density = 2070.0\npoisson_ratio = 0.3\nyoungs_modulus = 78e3\nyoungs_modulus_rate = 20.0\ncohesion = 100.0\ncohesion_rate = 0.5\ncohesion_late_rate = 2.0\ncohesion_transition_age = 0.02\nfriction_angle_deg = 20.0\nage_at_start = 600.0",
            ),
        ];
        assert_eq!(all.len(), REGISTRY.len(), "every registered material needs an example here");
        all
    }

    /// `stress_at_rest(state after, J)` is the stress `update_batch` returned, bit for bit: at
    /// rest for every material (what a sleeping particle keeps), and for any velocity gradient
    /// for the materials whose stress is their state.
    #[test]
    fn stress_at_rest_reproduces_update_batch() {
        let mut seed = 0x2545f4914f6cdd1du64;
        let mut u = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        };
        // and the EVP material with its Maxwell branch, whose stress relaxes at rest
        let maxwell = ("evp_bingham", "density = 2100.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\nviscosity = 7.5\nyield_stress = 630.0\na_thix = 0.5\nmaxwell_modulus = 2e3\nmaxwell_time = 0.01");
        // and with the bulk modulus's age law (bilinear, the kink within the 40 steps), whose
        // held pressure the rest stress reads
        let aged = ("evp_bingham", "density = 2100.0\nbulk_modulus = 1e6\nshear_modulus = 3e5\nviscosity = 7.5\nyield_stress = 630.0\nbulk_modulus_rate = 1e5\nbulk_modulus_late_rate = 4e5\nbulk_modulus_transition_age = 30.02\nage_at_start = 30.0");
        for (kind, params) in examples().into_iter().chain([maxwell, aged]) {
            let table: toml::Table = toml::from_str(&format!("kind = \"{kind}\"\n{params}")).unwrap();
            let m = build_material(&table).unwrap();
            let sl = m.state_names().len();
            assert_eq!(sl == 14, params.contains("maxwell"), "{kind}: the Maxwell branch's state");
            let n = 64;
            let mut state = vec![0.0 as Real; n * sl];
            for p in 0..n {
                m.init_state(&mut state[p * sl..(p + 1) * sl]);
            }
            let mut stress = vec![M3::ZERO; n];
            let dt = 1e-3 as Real;
            let stress_is_state = matches!(kind, "evp_bingham" | "drucker_prager" | "early_age_solid");
            for step in 0..40 {
                // strong random flow (yielding, plastic branches), then every fourth step at rest
                let rest = step % 4 == 3;
                let l: Vec<M3> = (0..n)
                    .map(|_| if rest { M3::ZERO } else { M3::from_cols(V3::new(u(), u(), u()), V3::new(u(), u(), u()), V3::new(u(), u(), u())) * 20.0 })
                    .collect();
                let j: Vec<Real> = (0..n).map(|_| 1.0 + 0.01 * u()).collect();
                m.update_batch(&l, &j, dt, &mut state, &mut stress);
                if rest || stress_is_state {
                    for p in 0..n {
                        let s = if sl == 0 { &[][..] } else { &state[p * sl..(p + 1) * sl] };
                        let again = m.stress_at_rest(s, j[p]);
                        let bits = |a: &M3| a.to_cols_array().map(|x| x.to_bits());
                        assert_eq!(bits(&again), bits(&stress[p]), "{kind}, step {step}, particle {p}: {again:?} != {:?}", stress[p]);
                    }
                }
            }
        }
    }
}
