//! The material registry: scenario name -> constructor. Adding a material is one file in
//! `kernels/src/material/` and one line here.

use crate::kernels::material::{
    bingham::Bingham, drucker_prager::DruckerPrager, evp_bingham::EvpBingham, newtonian::Newtonian,
    papanastasiou_roussel::PapanastasiouRoussel, Material,
};
use serde::de::DeserializeOwned;

type Builder = fn(toml::Table) -> Result<Box<dyn Material>, String>;

pub const REGISTRY: &[(&str, Builder)] = &[
    ("newtonian", |t| build::<Newtonian>(t, Newtonian::validate)),
    ("bingham", |t| build::<Bingham>(t, Bingham::validate)),
    ("papanastasiou_roussel", |t| build::<PapanastasiouRoussel>(t, PapanastasiouRoussel::validate)),
    ("evp_bingham", |t| build::<EvpBingham>(t, EvpBingham::validate)),
    ("drucker_prager", |t| build::<DruckerPrager>(t, DruckerPrager::validate)),
];

fn build<M: Material + DeserializeOwned + 'static>(
    t: toml::Table,
    validate: fn(&M) -> Result<(), String>,
) -> Result<Box<dyn Material>, String> {
    let m: M = t.try_into().map_err(|e: toml::de::Error| format!("material: {}", e.message()))?;
    validate(&m)?;
    Ok(Box::new(m))
}

/// Build the material a scenario's `[material]` table describes.
pub fn build_material(table: &toml::Table) -> Result<Box<dyn Material>, String> {
    let mut t = table.clone();
    let kind = match t.remove("kind") {
        Some(toml::Value::String(k)) => k,
        _ => return Err("material.kind must be a string naming the model".into()),
    };
    match REGISTRY.iter().find(|(name, _)| *name == kind) {
        Some((_, b)) => b(t),
        None => {
            let names: Vec<&str> = REGISTRY.iter().map(|r| r.0).collect();
            Err(format!("material.kind '{kind}' is unknown; known: {}", names.join(", ")))
        }
    }
}
