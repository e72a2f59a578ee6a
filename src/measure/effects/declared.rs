//! Effects declared in a model file: scenario keys set by expressions over the keys, the effect's
//! parameters and the experiment's covariates, with no Rust, adjoint or rebuild.
//!
//! ```toml
//! [effects.yield_growth]
//! about = "yield stress growing as a power of age"            # optional
//! sets = { "material.yield_stress" = "yield_stress * (1 + a * age^b)" }
//! params = { a = { null = 0, min = 0, max = 1e-2 }, b = { null = 1, min = 0.2, max = 3 } }
//! a = 2e-3                                                     # values; left out = the null
//! # candidate = true    # declared only: diagnose tests it, the model runs without it
//! ```
//!
//! A symbol in an expression is, in this order: a parameter of the effect; `rest_time` or `age`;
//! a covariate the effect lists in `covariates = ["temperature"]` (each experiment gives it as
//! `covariates = { temperature = 31.0 }`); a key written in full (`material.viscosity`); or a
//! number of the model's `[material]` by its bare name (`yield_stress`). Every expression reads
//! the keys as they are before the effect, and its keys are set together after. The effect's
//! derivatives, and so its adjoint, come from the expressions (forward-mode dual numbers,
//! `measure/expression.rs`). A parameter spec gives `null` (where the effect vanishes), `min`,
//! `max`, and optionally `scale` (a typical magnitude, the fit's unit step: by default a tenth of
//! max - min) and `unit`. The model is refused when an expression does not give back the
//! material's own value at the null.
//!
//! A declared effect lives as long as the program: the [`Effect`] trait hands out `'static`
//! names and parameter specs, as the library's do, so each distinct declaration is kept once
//! ([`intern`]) however often a model is loaded or cloned.

use super::super::error::MeasureError;
use super::effect::{add_bar, bar, read, Covariates, Effect, Keys, ParamSpec};
use crate::measure::expression::Expression;
use std::sync::Mutex;

/// The keys of a declaration's table that are not parameter values.
const DECLARATION: &[&str] = &["about", "sets", "params", "covariates"];
/// The key that declares without switching on.
pub const CANDIDATE: &str = "candidate";

#[derive(Debug)]
pub struct Declared {
    name: &'static str,
    about: &'static str,
    params: &'static [ParamSpec],
    sets: Vec<Assignment>,
    /// The declaration as written (`about`, `sets`, `params`, `covariates`), for the model file.
    declaration: toml::Table,
}

#[derive(Debug)]
struct Assignment {
    key: String,
    expression: Expression,
    /// What each of the expression's symbols is, in its order.
    reads: Vec<Read>,
}

#[derive(Debug, PartialEq)]
enum Read {
    Param(usize),
    RestTime,
    Age,
    Covariate(String),
    Key(String),
}

/// A declaration read from a model file: the effect, its parameter values, and whether it is
/// only a candidate.
#[derive(Debug)]
pub struct Declaration {
    pub effect: &'static Declared,
    pub values: Vec<f64>,
    pub candidate: bool,
}

/// Whether an `[effects.NAME]` table declares an effect (rather than setting a library one's
/// parameters).
pub fn is_declaration(table: &toml::Table) -> bool {
    table.contains_key("sets")
}

/// Read `[effects.NAME]`. `material` is the model's `[material]`, whose numbers bare names
/// refer to; `line_of(key)` is the line of `sets.KEY` in the model file, when known.
pub fn declare(
    name: &str,
    table: &toml::Table,
    material: &toml::Table,
    line_of: &dyn Fn(&str) -> Option<usize>,
) -> Result<Declaration, MeasureError> {
    let here = format!("effects.{name}");
    if super::REGISTRY.iter().any(|e| e.name() == name) {
        return Err(MeasureError::Effect(format!(
            "{here}: '{name}' is an effect of the library; a declared effect (with `sets`) needs a name of its own"
        )));
    }
    if name.contains('.') {
        return Err(MeasureError::Effect(format!("{here}: a declared effect's name cannot contain '.'")));
    }
    let about = match table.get("about") {
        None => format!("declared in the model file: {}", describe_sets(table)),
        Some(v) => {
            v.as_str().ok_or_else(|| MeasureError::Effect(format!("{here}.about must be a string")))?.to_string()
        }
    };
    let covariates: Vec<String> = match table.get("covariates") {
        None => vec![],
        Some(v) => v
            .as_array()
            .and_then(|a| a.iter().map(|c| c.as_str().map(str::to_string)).collect::<Option<Vec<_>>>())
            .ok_or_else(|| {
                MeasureError::Effect(format!(
                    "{here}.covariates must be a list of names, e.g. covariates = [\"temperature\"]"
                ))
            })?,
    };
    if let Some(c) = covariates.iter().find(|c| ["rest_time", "age"].contains(&c.as_str())) {
        return Err(MeasureError::Effect(format!(
            "{here}.covariates: '{c}' is always there; list only the covariates experiments declare"
        )));
    }
    let params = read_params(&here, table.get("params"))?;
    for p in &params {
        let clash = if ["rest_time", "age"].contains(&p.name.as_str()) || covariates.contains(&p.name) {
            Some("a covariate")
        } else if material.get(&p.name).and_then(crate::measure::observation::number).is_some() {
            Some("a number of [material]")
        } else {
            None
        };
        if let Some(what) = clash {
            return Err(MeasureError::Effect(format!(
                "{here}.params: parameter '{}' has the name of {what}; rename it",
                p.name
            )));
        }
    }
    let sets_table = table
        .get("sets")
        .and_then(|s| s.as_table())
        .ok_or_else(|| MeasureError::Effect(format!("{here}.sets must be a table of KEY = \"expression\"")))?;
    if sets_table.is_empty() {
        return Err(MeasureError::Effect(format!("{here}.sets sets nothing")));
    }
    let sets = read_sets(&here, sets_table, (&params, &covariates, material), line_of)?;
    let mut values: Vec<f64> = params.iter().map(|p| p.null).collect();
    let mut candidate = false;
    for (k, v) in table {
        if DECLARATION.contains(&k.as_str()) {
            continue;
        }
        if k == CANDIDATE {
            candidate =
                v.as_bool().ok_or_else(|| MeasureError::Effect(format!("{here}.{CANDIDATE} must be true or false")))?;
            continue;
        }
        let i = params.iter().position(|p| p.name == *k).ok_or_else(|| {
            MeasureError::Effect(format!(
                "{here}: unknown key '{k}'; a declared effect has {}, {CANDIDATE}, and the values of its \
                    parameters ({})",
                DECLARATION.join(", "),
                names_or_none(params.iter().map(|p| p.name.as_str()))
            ))
        })?;
        values[i] = crate::measure::observation::number(v)
            .ok_or_else(|| MeasureError::Effect(format!("{here}.{k} must be a number")))?;
    }
    let declaration: toml::Table =
        table.iter().filter(|(k, _)| DECLARATION.contains(&k.as_str())).map(|(k, v)| (k.clone(), v.clone())).collect();
    let effect = intern(name, about, params, sets, declaration);
    effect.check_null(material)?;
    Ok(Declaration { effect, values, candidate })
}

/// The assignments of a declared effect's `sets` table, each expression parsed and its symbols
/// resolved against the effect's parameters, its covariates and the material.
fn read_sets(
    here: &str,
    sets_table: &toml::Table,
    (params, covariates, material): (&[Spec], &[String], &toml::Table),
    line_of: &dyn Fn(&str) -> Option<usize>,
) -> Result<Vec<Assignment>, MeasureError> {
    let mut sets = Vec::new();
    for (key, v) in sets_table {
        let line = line_of(key).map_or(String::new(), |l| format!(" (line {l})"));
        let text = v.as_str().ok_or_else(|| {
            MeasureError::Effect(format!("{here}.sets.\"{key}\"{line} must be an expression in a string"))
        })?;
        let expression =
            Expression::parse(text).map_err(|e| e.within(format!("{here}.sets.\"{key}\"{line}: in '{text}'")))?;
        let reads = expression
            .symbols()
            .iter()
            .map(|s| {
                resolve(s, params, covariates, material).ok_or_else(|| {
                    MeasureError::Effect(format!(
                        "{here}.sets.\"{key}\"{line}: unknown symbol '{s}' in '{text}'; an expression reads the \
                            effect's parameters ({}), rest_time, age, the covariates it lists in `covariates` ({}), a \
                            key in full (material.KEY) or a number of [material] by name ({})",
                        names_or_none(params.iter().map(|p| p.name.as_str())),
                        names_or_none(covariates.iter().map(String::as_str)),
                        names_or_none(
                            material
                                .iter()
                                .filter(|(_, v)| crate::measure::observation::number(v).is_some())
                                .map(|(k, _)| k.as_str())
                        ),
                    ))
                })
            })
            .collect::<Result<Vec<Read>, MeasureError>>()?;
        sets.push(Assignment { key: key.clone(), expression, reads });
    }
    Ok(sets)
}

fn names_or_none<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<&str> = names.collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

fn describe_sets(table: &toml::Table) -> String {
    match table.get("sets").and_then(|s| s.as_table()) {
        Some(s) => s.iter().map(|(k, v)| format!("{k} = {}", v.as_str().unwrap_or("?"))).collect::<Vec<_>>().join("; "),
        None => String::new(),
    }
}

fn resolve(symbol: &str, params: &[Spec], covariates: &[String], material: &toml::Table) -> Option<Read> {
    if let Some(i) = params.iter().position(|p| p.name == symbol) {
        return Some(Read::Param(i));
    }
    match symbol {
        "rest_time" => return Some(Read::RestTime),
        "age" => return Some(Read::Age),
        _ => {}
    }
    if covariates.iter().any(|c| c == symbol) {
        return Some(Read::Covariate(symbol.to_string()));
    }
    if symbol.contains('.') {
        return Some(Read::Key(symbol.to_string()));
    }
    material.get(symbol).and_then(crate::measure::observation::number).map(|_| Read::Key(format!("material.{symbol}")))
}

/// A parameter as declared, before the effect is kept (see [`intern`]).
struct Spec {
    name: String,
    null: f64,
    lower: f64,
    upper: f64,
    scale: f64,
    unit: String,
}

fn read_params(here: &str, v: Option<&toml::Value>) -> Result<Vec<Spec>, MeasureError> {
    let t = v.and_then(|v| v.as_table()).ok_or_else(|| {
        MeasureError::Effect(format!("{here}.params must be a table of NAME = {{ null = ..., min = ..., max = ... }}"))
    })?;
    if t.is_empty() {
        return Err(MeasureError::Effect(format!("{here}.params: a declared effect needs a parameter")));
    }
    let mut out = Vec::new();
    for (name, spec) in t {
        let at = format!("{here}.params.{name}");
        if name.contains('.') {
            return Err(MeasureError::Effect(format!("{at}: a parameter's name cannot contain '.'")));
        }
        let spec = spec
            .as_table()
            .ok_or_else(|| MeasureError::Effect(format!("{at} must be {{ null = ..., min = ..., max = ... }}")))?;
        if let Some(k) = spec.keys().find(|k| !["null", "min", "max", "scale", "unit"].contains(&k.as_str())) {
            return Err(MeasureError::Effect(format!(
                "{at}: unknown key '{k}' (a parameter has null, min, max, scale, unit)"
            )));
        }
        let num = |k: &str, default: Option<f64>| -> Result<f64, MeasureError> {
            match spec.get(k) {
                Some(v) => crate::measure::observation::number(v)
                    .ok_or_else(|| MeasureError::Effect(format!("{at}.{k} must be a number"))),
                None => default.ok_or_else(|| MeasureError::Effect(format!("{at}: give {k}"))),
            }
        };
        let null = num("null", None)?;
        let lower = num("min", Some(f64::NEG_INFINITY))?;
        let upper = num("max", Some(f64::INFINITY))?;
        if !(null.is_finite() && lower <= null && null <= upper) || lower >= upper {
            return Err(MeasureError::Effect(format!(
                "{at}: needs a finite null within min < max (null {null}, min {lower}, max {upper})"
            )));
        }
        let spread = upper - lower;
        let scale = match spec.get("scale") {
            Some(_) => num("scale", None)?,
            None if spread.is_finite() => spread / 10.0,
            None if null != 0.0 => null.abs(),
            None => return Err(MeasureError::Effect(format!(
                "{at}: give scale (a typical magnitude, the fit's unit step): its bounds are open and its null is 0"
            ))),
        };
        if !(scale.is_finite() && scale > 0.0) {
            return Err(MeasureError::Effect(format!("{at}.scale must be > 0, got {scale}")));
        }
        let unit = match spec.get("unit") {
            None => "-",
            Some(u) => u.as_str().ok_or_else(|| MeasureError::Effect(format!("{at}.unit must be a string")))?,
        };
        out.push(Spec { name: name.clone(), null, lower, upper, scale, unit: unit.to_string() });
    }
    Ok(out)
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_string().into_boxed_str())
}

/// The one kept copy of a declaration: the same name and declaration give the same effect, so
/// loading a model again keeps nothing more.
fn intern(
    name: &str,
    about: String,
    params: Vec<Spec>,
    sets: Vec<Assignment>,
    declaration: toml::Table,
) -> &'static Declared {
    static KEPT: Mutex<Vec<&'static Declared>> = Mutex::new(Vec::new());
    let mut kept = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(k) = kept.iter().find(|k| k.name == name && k.declaration == declaration) {
        return k;
    }
    let params: Vec<ParamSpec> = params
        .into_iter()
        .map(|p| ParamSpec {
            name: leak(&p.name),
            null: p.null,
            lower: p.lower,
            upper: p.upper,
            scale: p.scale,
            unit: leak(&p.unit),
        })
        .collect();
    let k: &'static Declared = Box::leak(Box::new(Declared {
        name: leak(name),
        about: leak(&about),
        params: Box::leak(params.into_boxed_slice()),
        sets,
        declaration,
    }));
    kept.push(k);
    k
}

impl Declared {
    /// `[effects.NAME]` as the model file gives it: the declaration and, with `values`, the
    /// parameters' values (none for a candidate).
    pub fn to_table(&self, values: Option<&[f64]>) -> toml::Table {
        let mut t = self.declaration.clone();
        match values {
            Some(v) => t.extend(self.params.iter().zip(v).map(|(s, v)| (s.name.to_string(), toml::Value::Float(*v)))),
            None => {
                t.insert(CANDIDATE.into(), toml::Value::Boolean(true));
            }
        }
        t
    }

    fn values(&self, a: &Assignment, p: &[f64], x: &Covariates, keys: &Keys) -> Result<Vec<f64>, MeasureError> {
        a.reads
            .iter()
            .map(|r| match r {
                Read::Param(i) => Ok(p[*i]),
                Read::RestTime => Ok(x.rest_time),
                Read::Age => Ok(x.age),
                Read::Covariate(c) => x.declared.get(c).copied().ok_or_else(|| MeasureError::Effect(format!("effect \
                    '{}' reads the covariate '{c}', which the experiment does not declare (covariates = {{ {c} = ... \
                    }})", self.name))),
                Read::Key(k) => read(keys, self.name, k),
            })
            .collect()
    }

    /// Refuse a declaration that does not vanish at its null: each key it sets that the
    /// material gives must come back unchanged, at a few values of the covariates.
    fn check_null(&self, material: &toml::Table) -> Result<(), MeasureError> {
        let keys: Keys = material
            .iter()
            .filter_map(|(k, v)| crate::measure::observation::number(v).map(|n| (format!("material.{k}"), n)))
            .collect();
        let null: Vec<f64> = self.params.iter().map(|s| s.null).collect();
        for (rest_time, age, c) in [(0.0, 0.0, 0.0), (240.0, 1800.0, 1.0), (600.0, 7200.0, 25.0)] {
            let mut x = Covariates { rest_time, age, ..Default::default() };
            for a in &self.sets {
                for r in &a.reads {
                    if let Read::Covariate(n) = r {
                        x.declared.insert(n.clone(), c);
                    }
                }
            }
            for a in &self.sets {
                let (Some(&before), Ok(values)) = (keys.get(&a.key), self.values(a, &null, &x, &keys)) else {
                    continue;
                };
                let after = a.expression.eval(&values);
                if !((after - before).abs() <= 1e-12 * before.abs().max(1e-300)) {
                    let at: Vec<String> = self.params.iter().map(|s| format!("{} = {}", s.name, s.null)).collect();
                    return Err(MeasureError::Effect(format!(
                        "effects.{}: at its null ({}) '{}' gives {} = {after}, not the material's {before} (rest_time \
                            {rest_time}, age {age}): an effect must vanish at its null",
                        self.name,
                        at.join(", "),
                        a.expression.text(),
                        a.key
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Assignment `a`'s value at `values`, refused when it is not a finite number (a division by
/// zero, an overflow, a root of a negative): named by its expression and the values it read,
/// where the material's own check would only see a bad `material.*` value.
fn finite(a: &Assignment, values: &[f64]) -> Result<f64, MeasureError> {
    let v = a.expression.eval(values);
    if v.is_finite() {
        return Ok(v);
    }
    let at: Vec<String> = a.expression.symbols().iter().zip(values).map(|(s, x)| format!("{s} = {x}")).collect();
    Err(MeasureError::Effect(format!(
        "'{}' gives {} = {v}, not a finite number (at {})",
        a.expression.text(),
        a.key,
        at.join(", ")
    )))
}

impl Effect for Declared {
    fn name(&self) -> &'static str {
        self.name
    }
    fn about(&self) -> &'static str {
        self.about
    }
    fn params(&self) -> &'static [ParamSpec] {
        self.params
    }
    fn apply(&self, p: &[f64], x: &Covariates, keys: &mut Keys) -> Result<(), MeasureError> {
        let out: Vec<f64> = self
            .sets
            .iter()
            .map(|a| self.values(a, p, x, keys).and_then(|v| finite(a, &v)))
            .collect::<Result<_, _>>()?;
        for (a, v) in self.sets.iter().zip(out) {
            keys.insert(a.key.clone(), v);
        }
        Ok(())
    }
    fn apply_adjoint(&self, p: &[f64], x: &Covariates, keys_in: &Keys, keys_bar: &mut Keys, p_bar: &mut [f64]) {
        // every key set is overwritten: its adjoint goes to what its expression read
        let out_bar: Vec<f64> = self.sets.iter().map(|a| bar(keys_bar, &a.key)).collect();
        for a in &self.sets {
            keys_bar.insert(a.key.clone(), 0.0);
        }
        for (a, ob) in self.sets.iter().zip(out_bar) {
            let values = self.values(a, p, x, keys_in).expect("apply read the same");
            let (_, grad) = a.expression.eval_grad(&values);
            for (r, g) in a.reads.iter().zip(grad) {
                match r {
                    Read::Param(i) => p_bar[*i] += ob * g,
                    Read::Key(k) => add_bar(keys_bar, k, ob * g),
                    Read::RestTime | Read::Age | Read::Covariate(_) => {}
                }
            }
        }
    }
    /// An expression at its null equals its key in exact arithmetic, not always in floating
    /// point (`tau0 * (1 + a)^2 / (1 + a)^2`), so a declared effect's start is run.
    fn start_runs_as_model(&self) -> bool {
        false
    }
}

/// Every effect a model can take: the library's, then those its file declares (`declared`).
pub fn available(declared: &[&'static Declared]) -> Vec<&'static dyn Effect> {
    super::REGISTRY.iter().copied().chain(declared.iter().map(|d| *d as &dyn Effect)).collect()
}

/// Declarations the registry's tests run on, as a model file gives them.
#[cfg(test)]
pub const EXAMPLES: &[&str] = &[
    "[effects.yield_growth]\nsets = { \"material.yield_stress\" = \"yield_stress * (1 + a * age^b)\" }\nparams = { a = \
        { null = 0, min = 0, max = 1e-2 }, b = { null = 1, min = 0.2, max = 3 } }\n",
    "[effects.hot_thinning]\ncovariates = [\"temperature\"]\nsets = { \"material.viscosity\" = \"viscosity * exp(-e * \
        (temperature - 20))\" }\nparams = { e = { null = 0, min = -0.2, max = 0.2, unit = \"1/K\" } }\n",
    "[effects.water]\nsets = { \"material.yield_stress\" = \"yield_stress / (1 + w)^3\", \"material.viscosity\" = \
        \"material.viscosity * exp(-2 * w) + 0 * material.yield_stress\" }\nparams = { w = { null = 0, min = 0, max = \
        0.5 } }\n",
];

#[cfg(test)]
mod tests {
    use super::*;

    const MATERIAL: &str = "kind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\n\
        viscosity = 20.0\nyield_stress = 100.0\n";

    fn parse(effect: &str) -> Result<Declaration, MeasureError> {
        let t: toml::Table = effect.parse().unwrap();
        let (name, table) = t["effects"].as_table().unwrap().iter().next().unwrap();
        declare(name, table.as_table().unwrap(), &MATERIAL.parse().unwrap(), &|_| Some(7))
    }

    #[test]
    fn a_declaration_reads_its_parameters_and_is_kept_once() {
        let d = parse(&format!("{}a = 2e-3\nb = 0.5\n", EXAMPLES[0])).unwrap();
        assert_eq!((d.effect.name(), d.values.clone(), d.candidate), ("yield_growth", vec![2e-3, 0.5], false));
        let b = d.effect.params()[1];
        assert_eq!((b.null, b.lower, b.upper), (1.0, 0.2, 3.0));
        assert!((b.scale - 0.28).abs() < 1e-12);
        let mut keys: Keys = [("material.yield_stress".to_string(), 100.0)].into_iter().collect();
        d.effect.apply(&d.values, &Covariates { age: 3600.0, ..Default::default() }, &mut keys).unwrap();
        assert!((keys["material.yield_stress"] - 100.0 * (1.0 + 2e-3 * 60.0)).abs() < 1e-9);
        // loaded again: the same effect
        let again = parse(&format!("{}{CANDIDATE} = true\n", EXAMPLES[0])).unwrap();
        assert!(std::ptr::eq(d.effect, again.effect) && again.candidate);
        // written and read back
        let back: toml::Table = [(
            "effects".to_string(),
            toml::Value::Table(
                [("yield_growth".to_string(), toml::Value::Table(d.effect.to_table(Some(&d.values))))]
                    .into_iter()
                    .collect(),
            ),
        )]
        .into_iter()
        .collect();
        let back = parse(&toml::to_string(&back).unwrap()).unwrap();
        assert!(std::ptr::eq(d.effect, back.effect) && back.values == d.values);
    }

    #[test]
    fn bad_declarations_name_the_symbol_the_expression_and_the_line() {
        let e = parse(&EXAMPLES[0].replace("age^b", "agee^b")).unwrap_err().to_string();
        assert!(
            e.contains("unknown symbol 'agee'")
                && e.contains("'yield_stress * (1 + a * agee^b)'")
                && e.contains("(line 7)"),
            "{e}"
        );
        assert!(e.contains("parameters (a, b)") && e.contains("yield_stress"), "{e}");
        for (bad, want) in [
            (EXAMPLES[0].replace("age^b", "age^^b"), "in 'yield_stress * (1 + a * age^^b)': expected a number"),
            (EXAMPLES[0].replace("(1 + a * age^b)", "(2 + a * age^b)"), "gives material.yield_stress = 200"),
            (EXAMPLES[0].replace("null = 1,", "null = 5,"), "needs a finite null within min < max"),
            (EXAMPLES[0].replace("yield_growth", "ageing"), "is an effect of the library"),
            (format!("{}c = 1.0\n", EXAMPLES[0]), "unknown key 'c'"),
            (EXAMPLES[1].replace("covariates = [\"temperature\"]\n", ""), "unknown symbol 'temperature'"),
            (
                EXAMPLES[0].replace("b = {", "viscosity = {").replace("age^b", "age^viscosity"),
                "parameter 'viscosity' has the name of a number of [material]",
            ),
            (EXAMPLES[0].replace("min = 0, max = 1e-2", "min = 0"), "give scale"),
        ] {
            let e = parse(&bad).unwrap_err().to_string();
            assert!(e.contains(want), "{bad}: {e}");
        }
        // a covariate the experiment does not give is named when the effect runs
        let d = parse(EXAMPLES[1]).unwrap();
        let mut keys: Keys = [("material.viscosity".to_string(), 20.0)].into_iter().collect();
        let e = d.effect.apply(&[0.01], &Covariates::default(), &mut keys).unwrap_err().to_string();
        assert!(e.contains("covariate 'temperature'") && e.contains("hot_thinning"), "{e}");
    }
}
