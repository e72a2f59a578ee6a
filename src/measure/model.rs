//! A model: the `[material]` every experiment runs with and the effects switched on, seen as
//! named parameters (`material.yield_stress`, `thixotropy.a_thix`, ...) that calibration moves and
//! diagnosis extends.
//!
//! ```toml
//! [material]
//! kind = "evp_bingham"
//! yield_stress = 90.0
//! ...
//! [effects.thixotropy]      # parameters left out take their null value
//! a_thix = 0.4
//! ```
//!
//! An `[effects.NAME]` table with `sets` declares an effect of the model's own (expressions over
//! the keys, its parameters and the covariates; `effects/declared.rs`); with `candidate = true`
//! it is declared only, for `strand diagnose` to test beside the library's.
//!
//! For one experiment the model gives scenario keys ([`Model::keys`]): the material's numbers as
//! `material.KEY`, then each effect's keys from its parameters and the experiment's covariates,
//! in registry order, the declared ones after, by name; the experiment's own `set` overrides come
//! last. [`Model::keys_adjoint`]
//! carries the keys' adjoints back to the parameters.

use super::error::{io_error, toml_error, MeasureError};
use super::effects::declared::{self, Declared};
use super::effects::{self, Covariates, Effect, Keys};
use crate::key::Key;
use std::path::{Path, PathBuf};
use std::collections::BTreeMap;

#[derive(Clone)]
pub struct Model {
    pub material: toml::Table,
    /// Effects switched on, in registry order, with their parameter values.
    pub effects: Vec<(&'static dyn Effect, Vec<f64>)>,
    /// Effects the model file declares, switched on or candidates, by name.
    pub declared: Vec<&'static Declared>,
    pub path: PathBuf,
    /// Each material number's unit: its value in the model as it was read, before any fit moved
    /// it (see [`Model::unit`]).
    pub units: BTreeMap<String, f64>,
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let e: Vec<(&str, &Vec<f64>)> = self.effects.iter().map(|(e, p)| (e.name(), p)).collect();
        f.debug_struct("Model").field("material", &self.material).field("effects", &e).finish()
    }
}

/// Bounds of a parameter and its unit step.
#[derive(Clone, Copy, Debug)]
pub struct Bounds {
    pub lower: f64,
    pub upper: f64,
    pub scale: f64,
}

impl Model {
    pub fn load(path: &Path) -> Result<Model, MeasureError> {
        let text = std::fs::read_to_string(path).map_err(io_error(path))?;
        let t: toml::Table = text.parse().map_err(toml_error(path))?;
        Model::from_source(&t, Some(&text))
            .map(|mut m| {
                m.path = path.to_path_buf();
                m
            })
            .map_err(|e| e.within(path.display()))
    }

    pub fn from_table(t: &toml::Table) -> Result<Model, MeasureError> {
        Model::from_source(t, None)
    }

    /// The model of `t`, parsed from `text` when there is one (errors in a declared effect's
    /// expression then give its line), its parameters within their bounds and its material one
    /// that builds.
    fn from_source(t: &toml::Table, text: Option<&str>) -> Result<Model, MeasureError> {
        let model = Model::parse(t, text)?;
        for n in model.param_names() {
            let (v, b) = (model.get(&n)?, model.bounds(&n)?);
            // an infinite null (elasticity's rigid G) is where the effect is off, so it may be written
            if !((v.is_finite() || v == model.null(&n)) && v >= b.lower && v <= b.upper) {
                return Err(MeasureError::Model(format!("{n} = {v} is outside [{}, {}]", b.lower, b.upper)));
            }
        }
        crate::materials::build_material(&model.material)?;
        Ok(model)
    }

    /// The model of `t` exactly as written, without the checks of [`Model::from_table`]: a
    /// trial model of a fit, saved as a job for an engine, must fail where its evaluation does,
    /// as it does locally.
    pub fn from_table_as_written(t: &toml::Table) -> Result<Model, MeasureError> {
        Model::parse(t, None)
    }

    fn parse(t: &toml::Table, text: Option<&str>) -> Result<Model, MeasureError> {
        // [rheometer] is `strand rheometer`'s protocol, which a model file may carry
        if let Some(k) = t.keys().find(|k| !["material", "effects", "rheometer"].contains(&k.as_str())) {
            return Err(MeasureError::Model(format!("unknown table '{k}' (a model has [material] and [effects.NAME])")));
        }
        let material = match t.get("material") {
            Some(toml::Value::Table(m)) => m.clone(),
            _ => return Err(MeasureError::Model("no [material] table".into())),
        };
        let units = material
            .iter()
            .filter_map(|(k, v)| {
                super::observation::number(v).filter(|x| x.is_finite() && *x != 0.0).map(|x| (k.clone(), x.abs()))
            })
            .collect();
        let mut model = Model { material, effects: Vec::new(), declared: Vec::new(), path: PathBuf::new(), units };
        if let Some(e) = t.get("effects") {
            let e = e
                .as_table()
                .ok_or_else(|| MeasureError::Model("effects must be a table of [effects.NAME] tables".into()))?;
            for (name, v) in e {
                let v = v.as_table().ok_or_else(|| MeasureError::Model(format!("effects.{name} must be a table")))?;
                if declared::is_declaration(v) {
                    let line_of = |key: &str| text.and_then(|text| expression_line(text, name, key));
                    let d = declared::declare(name, v, &model.material, &line_of)?;
                    model.declared.push(d.effect);
                    if !d.candidate {
                        model = model.with_effect(d.effect);
                        model.effects.iter_mut().find(|(e, _)| e.name() == name).expect("just added").1 = d.values;
                    }
                    continue;
                }
                let effect = effects::find(name)?;
                let mut p: Vec<f64> = effect.params().iter().map(|s| s.null).collect();
                for (k, x) in v {
                    let i = effect.params().iter().position(|s| s.name == k).ok_or_else(|| {
                        MeasureError::Model(format!(
                            "effects.{name}: unknown parameter '{k}'; it has {}",
                            effect.params().iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
                        ))
                    })?;
                    p[i] = super::observation::number(x)
                        .ok_or_else(|| MeasureError::Model(format!("effects.{name}.{k} must be a number")))?;
                }
                model = model.with_effect(effect);
                model.effects.iter_mut().find(|(e, _)| e.name() == name).expect("just added").1 = p;
            }
        }
        Ok(model)
    }

    /// The model with `effect` on at its null (unchanged if it is on already).
    pub fn with_effect(&self, effect: &'static dyn Effect) -> Model {
        let mut m = self.clone();
        if !m.has(effect.name()) {
            m.effects.push((effect, effect.params().iter().map(|s| s.null).collect()));
            // the library's in registry order, then the declared ones by name
            let rank = |e: &dyn Effect| {
                (effects::REGISTRY.iter().position(|r| r.name() == e.name()).unwrap_or(usize::MAX), e.name())
            };
            m.effects.sort_by_key(|(e, _)| rank(*e));
        }
        m
    }

    /// An effect parameter's null; NaN for a material number (which has none).
    fn null(&self, name: &str) -> f64 {
        match self.locate(name) {
            Ok(Slot::Effect(e, p)) => self.effects[e].0.params()[p].null,
            _ => f64::NAN,
        }
    }

    pub fn has(&self, effect: &str) -> bool {
        self.effects.iter().any(|(e, _)| e.name() == effect)
    }

    /// An effect of the library or one the model file declares.
    pub fn effect(&self, name: &str) -> Result<&'static dyn Effect, MeasureError> {
        match self.declared.iter().find(|d| d.name() == name) {
            Some(d) => Ok(*d),
            None => effects::find(name),
        }
    }

    /// Every parameter: the material's numbers, then each effect's.
    pub fn param_names(&self) -> Vec<String> {
        let mut n: Vec<String> = self
            .material
            .iter()
            .filter(|(_, v)| super::observation::number(v).is_some())
            .map(|(k, _)| format!("material.{k}"))
            .collect();
        for (e, _) in &self.effects {
            n.extend(e.params().iter().map(|s| format!("{}.{}", e.name(), s.name)));
        }
        n
    }

    fn locate(&self, name: &str) -> Result<Slot, MeasureError> {
        let unknown = || {
            MeasureError::Model(format!("unknown parameter '{name}'; the model has {}", self.param_names().join(", ")))
        };
        let parsed = Key::parse(name).map_err(|_| unknown())?;
        let (head, key) = (parsed.table(), parsed.field());
        if head == "material" {
            return match self.material.get(key).and_then(super::observation::number) {
                Some(_) => Ok(Slot::Material(key.to_string())),
                None => Err(unknown()),
            };
        }
        let e = self.effects.iter().position(|(e, _)| e.name() == head).ok_or_else(|| match self.effect(head) {
            Ok(_) if self.declared.iter().any(|d| d.name() == head) => MeasureError::Model(format!(
                "'{name}': effect '{head}' is declared as a candidate, not in the model (remove its candidate = true)"
            )),
            Ok(_) => {
                MeasureError::Model(format!("'{name}': effect '{head}' is not in the model (add [effects.{head}])"))
            }
            Err(_) => unknown(),
        })?;
        let p = self.effects[e].0.params().iter().position(|s| s.name == key).ok_or_else(unknown)?;
        Ok(Slot::Effect(e, p))
    }

    /// Parameters `names`, each key parsed and located once, with its value, bounds and unit here.
    pub fn parameters(&self, names: &[String]) -> Result<Vec<Parameter>, MeasureError> {
        names
            .iter()
            .map(|name| {
                let slot = self.locate(name)?;
                let (value, bounds, unit) = (self.value_at(&slot), self.bounds_at(&slot), self.unit_at(&slot));
                let key = Key::parse(name).expect("located");
                Ok(Parameter { key, slot, value, bounds, unit })
            })
            .collect()
    }

    /// The model edited: `effects` switched on, each at its null (one on already stays as it
    /// is), then each parameter of `values` set. Every edit of a model's numbers goes through
    /// here: diagnosis's candidate effects and their starts, a fit's trial steps, a difference's
    /// sides. The parameters of `values` are resolved ([`Model::parameters`]) in a model with the
    /// effects of the edited one.
    pub fn edited(&self, effects: &[&'static dyn Effect], values: &[(&Parameter, f64)]) -> Model {
        let mut m = self.clone();
        for e in effects {
            m = m.with_effect(*e);
        }
        for (p, v) in values {
            m.set_at(&p.slot, *v);
        }
        m
    }

    pub fn get(&self, name: &str) -> Result<f64, MeasureError> {
        Ok(self.value_at(&self.locate(name)?))
    }

    pub fn set(&mut self, name: &str, v: f64) -> Result<(), MeasureError> {
        let slot = self.locate(name)?;
        self.set_at(&slot, v);
        Ok(())
    }

    fn value_at(&self, slot: &Slot) -> f64 {
        match slot {
            Slot::Material(k) => super::observation::number(&self.material[k]).expect("located"),
            Slot::Effect(e, p) => self.effects[*e].1[*p],
        }
    }

    fn set_at(&mut self, slot: &Slot, v: f64) {
        match slot {
            Slot::Material(k) => {
                self.material.insert(k.clone(), toml::Value::Float(v));
            }
            Slot::Effect(e, p) => self.effects[*e].1[*p] = v,
        }
    }

    /// Bounds of a parameter: an effect's own; a material number stays >= 0, and one that is
    /// positive stays positive (the materials reject a zero modulus or density).
    pub fn bounds(&self, name: &str) -> Result<Bounds, MeasureError> {
        Ok(self.bounds_at(&self.locate(name)?))
    }

    fn bounds_at(&self, slot: &Slot) -> Bounds {
        match slot {
            Slot::Material(_) => {
                let v = self.value_at(slot);
                Bounds {
                    lower: if v > 0.0 { 1e-6 * v } else { 0.0 },
                    upper: f64::INFINITY,
                    scale: if v != 0.0 { v.abs() } else { 1.0 },
                }
            }
            Slot::Effect(e, p) => {
                let s = self.effects[*e].0.params()[*p];
                Bounds { lower: s.lower, upper: s.upper, scale: s.scale }
            }
        }
    }

    /// The magnitude a parameter is measured against: a material number's value in the model as
    /// it was read (its scale where that was 0), an effect parameter's scale. A difference of a
    /// simulation takes its step from the larger of this and the parameter's value: a material
    /// number a fit has taken towards 0 (a viscosity the data barely see, walked to its bound)
    /// is still differenced over a step that moves the model by more than particle noise.
    pub fn unit(&self, name: &str) -> Result<f64, MeasureError> {
        Ok(self.unit_at(&self.locate(name)?))
    }

    fn unit_at(&self, slot: &Slot) -> f64 {
        match slot {
            Slot::Material(k) => match self.units.get(k) {
                Some(&u) => u,
                None => self.bounds_at(slot).scale,
            },
            Slot::Effect(e, p) => self.effects[*e].0.params()[*p].scale,
        }
    }

    /// The scenario keys of one experiment (before its `set` overrides).
    pub fn keys(&self, x: &Covariates) -> Result<Keys, MeasureError> {
        self.keys_traced(x).map(|(keys, _)| keys)
    }

    /// The keys after every effect, and the keys before each effect (what its adjoint reads).
    fn keys_traced(&self, x: &Covariates) -> Result<(Keys, Vec<Keys>), MeasureError> {
        let mut keys: Keys = self
            .material
            .iter()
            .filter_map(|(k, v)| super::observation::number(v).map(|n| (format!("material.{k}"), n)))
            .collect();
        let mut before = Vec::with_capacity(self.effects.len());
        for (e, p) in &self.effects {
            before.push(keys.clone());
            e.apply(p, x, &mut keys).map_err(|m| m.within(format!("effect '{}'", e.name())))?;
            // a value an effect made not finite is the effect's fault, named here rather than
            // as a bad material value later
            if let Some((k, v)) = keys.iter().find(|(k, v)| {
                !v.is_finite() && before.last().and_then(|b| b.get(k.as_str())).is_none_or(|w| w.is_finite())
            }) {
                return Err(MeasureError::Effect(format!(
                    "effect '{}' gives {k} = {v}, not a finite number (its parameters {p:?})",
                    e.name()
                )));
            }
        }
        Ok((keys, before))
    }

    /// d(objective)/d(parameter) for `params` (resolved in this model), given the adjoints of the
    /// keys [`Model::keys`] returned for covariates `x`.
    pub fn keys_adjoint(
        &self,
        x: &Covariates,
        mut keys_bar: Keys,
        params: &[Parameter],
    ) -> Result<Vec<f64>, MeasureError> {
        let (_, before) = self.keys_traced(x)?;
        let mut effect_bar: Vec<Vec<f64>> = self.effects.iter().map(|(_, p)| vec![0.0; p.len()]).collect();
        for (i, (e, p)) in self.effects.iter().enumerate().rev() {
            e.apply_adjoint(p, x, &before[i], &mut keys_bar, &mut effect_bar[i]);
        }
        Ok(params
            .iter()
            .map(|p| match &p.slot {
                Slot::Material(k) => effects::bar(&keys_bar, &format!("material.{k}")),
                Slot::Effect(e, i) => effect_bar[*e][*i],
            })
            .collect())
    }

    /// The model file.
    pub fn to_toml(&self) -> String {
        let mut t = toml::Table::new();
        t.insert("material".into(), toml::Value::Table(self.material.clone()));
        if !self.effects.is_empty() || !self.declared.is_empty() {
            let mut e = toml::Table::new();
            for (eff, p) in &self.effects {
                let tab: toml::Table = match self.declared.iter().find(|d| d.name() == eff.name()) {
                    Some(d) => d.to_table(Some(p)),
                    None => {
                        eff.params().iter().zip(p).map(|(s, v)| (s.name.to_string(), toml::Value::Float(*v))).collect()
                    }
                };
                e.insert(eff.name().into(), toml::Value::Table(tab));
            }
            for d in self.declared.iter().filter(|d| !self.has(d.name())) {
                e.insert(d.name().into(), toml::Value::Table(d.to_table(None)));
            }
            t.insert("effects".into(), toml::Value::Table(e));
        }
        toml::to_string(&t).expect("a model serialises")
    }
}

/// A model's parameter, its key parsed once ([`Model::parameters`]): a material number or an
/// effect's parameter, with its value, bounds and unit in the model it was resolved in (a
/// material number's bounds and unit follow its value). It sets that model, and every model with
/// the same effects (a fit's trial models: [`Model::edited`]).
#[derive(Clone, Debug)]
pub struct Parameter {
    pub key: Key,
    slot: Slot,
    pub value: f64,
    pub bounds: Bounds,
    pub unit: f64,
}

/// Where a parameter lives: a material number by name, or an effect's (its place in the model's
/// effects) parameter.
#[derive(Clone, Debug)]
enum Slot {
    Material(String),
    Effect(usize, usize),
}

/// The line of `[effects.EFFECT] sets."KEY"` in a model file's text.
fn expression_line(text: &str, effect: &str, key: &str) -> Option<usize> {
    #[derive(serde::Deserialize)]
    struct File {
        #[serde(default)]
        effects: std::collections::BTreeMap<String, Sets>,
    }
    #[derive(serde::Deserialize)]
    struct Sets {
        #[serde(default)]
        sets: std::collections::BTreeMap<String, toml::Spanned<toml::Value>>,
    }
    let f: File = toml::from_str(text).ok()?;
    let at = f.effects.get(effect)?.sets.get(key)?.span().start;
    Some(text[..at].matches('\n').count() + 1)
}

/// Set `key` (dotted; numbers and x/y/z index arrays) in a TOML document to `v`, creating the
/// tables on the way and replacing a non-table value with one (`z_min = "free_slip"` becomes
/// `z_min = { friction = { mu = v } }`).
pub fn set_path(doc: &mut toml::Table, key: &str, v: f64) -> Result<(), MeasureError> {
    let parts: Vec<&str> = key.split('.').collect();
    let mut at: &mut toml::Value =
        doc.entry(parts[0].to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if parts.len() == 1 {
        *at = toml::Value::Float(v);
        return Ok(());
    }
    for (i, part) in parts[1..].iter().enumerate() {
        let last = i + 2 == parts.len();
        if let toml::Value::Array(a) = at {
            let idx = part.parse::<usize>().ok().or_else(|| ["x", "y", "z"].iter().position(|x| x == part));
            let len = a.len();
            at = idx
                .and_then(|j| a.get_mut(j))
                .ok_or_else(|| MeasureError::Model(format!("'{key}': index '{part}' is not in an array of {len}")))?;
        } else {
            if !at.is_table() {
                *at = toml::Value::Table(toml::Table::new());
            }
            let t = at.as_table_mut().expect("made a table");
            at = t.entry(part.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        }
        if last {
            *at = toml::Value::Float(v);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const M: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\n\
        viscosity = 20.0\nyield_stress = 100.0\n[effects.thixotropy]\na_thix = 0.5\n";

    /// The bulk modulus's age law (evp_bingham): its keys are parameters of the loop like every
    /// number of `[material]`, and a bad one is refused by the material, naming the key.
    #[test]
    fn the_age_law_keys_of_evp_bingham_are_model_parameters() {
        let law = "bulk_modulus_rate = 2e3\nbulk_modulus_late_rate = 5e3\nbulk_modulus_transition_age = 600.0\n\
            age_at_start = 60.0\n";
        let m = Model::from_table(
            &M.replace("yield_stress = 100.0\n", &format!("yield_stress = 100.0\n{law}")).parse().unwrap(),
        )
        .unwrap();
        let names = m.param_names();
        for k in [
            "material.bulk_modulus_rate",
            "material.bulk_modulus_late_rate",
            "material.bulk_modulus_transition_age",
            "material.age_at_start",
        ] {
            assert!(names.iter().any(|n| n == k), "{k} in {names:?}");
        }
        assert_eq!(m.get("material.bulk_modulus_late_rate").unwrap(), 5e3);
        let bad = M.replace(
            "yield_stress = 100.0\n",
            "yield_stress = 100.0\nbulk_modulus_rate = 1e3\nbulk_modulus_late_rate = 2e3\n",
        );
        let e = Model::from_table(&bad.parse().unwrap()).unwrap_err().to_string();
        assert!(e.contains("material.bulk_modulus_transition_age is required"), "{e}");
        // a material number's bounds are [0, inf) or above: a falling law (a negative rate),
        // which the material itself accepts, is not a model of the loop
        let falling = M.replace("yield_stress = 100.0\n", "yield_stress = 100.0\nbulk_modulus_rate = -1e2\n");
        let e = Model::from_table(&falling.parse().unwrap()).unwrap_err().to_string();
        assert!(e.contains("material.bulk_modulus_rate = -100 is outside"), "{e}");
    }

    #[test]
    fn a_model_reads_writes_and_names_its_parameters() {
        let m = Model::from_table(&M.parse().unwrap()).unwrap();
        assert_eq!(m.get("thixotropy.a_thix").unwrap(), 0.5);
        assert_eq!(m.get("thixotropy.alpha").unwrap(), 0.0);
        let keys = m.keys(&Covariates { rest_time: 100.0, ..Default::default() }).unwrap();
        assert_eq!(keys["material.lambda0"], 0.5 * 100.0 / 100.0);
        let back = Model::from_table(&m.to_toml().parse().unwrap()).unwrap();
        assert_eq!(back.param_names(), m.param_names());
        for (bad, want) in [
            (M.replace("a_thix = 0.5", "a_thx = 0.5"), "unknown parameter 'a_thx'"),
            (M.replace("effects.thixotropy", "effects.thixo"), "unknown effect 'thixo'"),
            (M.replace("a_thix = 0.5", "a_thix = -0.5"), "thixotropy.a_thix = -0.5 is outside"),
        ] {
            let e = Model::from_table(&bad.parse().unwrap()).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
        let e = m.get("ageing.rate").unwrap_err().to_string();
        assert!(e.contains("not in the model"), "{e}");
    }

    #[test]
    fn set_path_makes_a_friction_wall_of_a_free_slip_one() {
        let mut doc: toml::Table =
            "[boundary]\nz_min = \"free_slip\"\n[print]\npath = [{ speed = 1.0 }]\n".parse().unwrap();
        set_path(&mut doc, "boundary.z_min.friction.mu", 0.3).unwrap();
        set_path(&mut doc, "print.path.0.speed", 2.0).unwrap();
        assert_eq!(doc["boundary"]["z_min"]["friction"]["mu"].as_float(), Some(0.3));
        assert_eq!(doc["print"]["path"][0]["speed"].as_float(), Some(2.0));
        assert!(set_path(&mut doc, "print.path.3.speed", 2.0).unwrap_err().to_string().contains("index '3'"));
    }
}
