//! Running the experiments under a model, comparing with measurements, and synthesising
//! measurements from a model (`strand compare`, `strand synth`).
//!
//! A model file holds the `[material]` every experiment uses and the effects switched on
//! (`model.rs`): its material replaces the scenario's own, its keys and its effects' keys are set,
//! and an experiment's `set` overrides apply after them (a speed, a geometry). Each experiment runs once, producing every observable asked of it;
//! experiments are independent jobs, run `jobs` at a time, and give the same numbers however
//! many run together.

use super::data::{at_text, Experiment, Experiments, Observable, Observation, RHEOMETER_OBSERVABLES, SIMULATION_OBSERVABLES};
use super::effects::Keys;
use super::model::set_path;
use super::rheometer::{Protocol, Reading, Rheometer};
use crate::grad::objective::{Frame, Objective};
use crate::kernels::material::Material;
use crate::scenario::Scenario;
use crate::solver::Simulation;
use std::path::Path;

pub use super::model::Model;

/// The scenario keys experiment `x` runs with: the model's for its covariates, then its own
/// `set` overrides.
pub fn experiment_keys(model: &Model, x: &Experiment) -> Result<Keys, String> {
    let mut keys = model.keys(&x.covariates())?;
    for (k, v) in &x.set {
        keys.insert(k.clone(), number(v));
    }
    Ok(keys)
}

/// An override's value (validated as a number when the experiments were loaded).
fn number(v: &toml::Value) -> f64 {
    super::data::number(v).unwrap_or(f64::NAN)
}

/// The model's values of `wanted` for experiment `x`; a simulation with `threads` threads (its
/// scenario's when `None`).
pub fn evaluate(model: &Model, exps: &Experiments, x: &Experiment, wanted: &[Observable], threads: Option<usize>) -> Result<Vec<f64>, String> {
    let r = experiment_keys(model, x).and_then(|keys| match (&x.scenario, &x.protocol) {
        (Some(s), _) => simulate(model, &keys, &exps.base_dir.join(s), wanted, threads),
        (None, Some(p)) => {
            let (material, proto) = rheometer_setup(model, &keys, &exps.base_dir, p)?;
            let readings = Rheometer::new(&*material, &proto)?.run();
            wanted.iter().map(|o| reading_index(o, &readings).map(|k| readings[k].stress)).collect()
        }
        (None, None) => Err("neither scenario nor protocol".into()),
    });
    r.map_err(|e| format!("experiment '{}': {e}", x.id))
}

/// The scenario of a simulation experiment: the file's, with the model's `[material]` in place
/// of its own and every key set.
pub fn scenario_text(model: &Model, keys: &Keys, scenario: &Path) -> Result<String, String> {
    let text = std::fs::read_to_string(scenario).map_err(|e| format!("{}: {e}", scenario.display()))?;
    let mut doc: toml::Table = text.parse().map_err(|e| format!("{}: {e}", scenario.display()))?;
    doc.insert("material".into(), toml::Value::Table(model.material_for(keys)));
    for (e, _) in &model.effects {
        e.check_scenario(&doc).map_err(|m| format!("effect '{}' {m} in {}", e.name(), scenario.display()))?;
    }
    for (k, v) in keys {
        let at = super::effects::placed(k, &doc);
        set_path(&mut doc, &at, *v).map_err(|e| format!("set.{k}: {e}"))?;
    }
    toml::to_string(&doc).map_err(|e| e.to_string())
}

pub fn parse_scenario(text: &str, scenario: &Path) -> Result<Scenario, String> {
    let mut sc = Scenario::parse(text).map_err(|e| format!("{}: {e}", scenario.display()))?;
    sc.base_dir = scenario.parent().map(Path::to_path_buf).unwrap_or_default();
    sc.checkpoint.enabled = false;
    Ok(sc)
}

/// When (time) and what (objective) a simulation observable is: those of the whole material
/// (spread, front, vx_max, kinetic_energy, mean_z) may be taken during the run, `@T`; a section's
/// (width, height, area, profile, layers), whose `@` is a station, at its end `end`.
pub fn observable_plan(o: &Observable, end: f64) -> Result<(f64, Objective), String> {
    let second = match o.name.as_str() {
        "profile" => Some("a station and a lateral position: profile@X:Y (metres)"),
        "layer_height" => Some("a station and a layer: layer_height@X:K (K = 1 the bottom layer)"),
        "layer_width" => Some("a station and a layer: layer_width@X:K (K = 1 the bottom layer)"),
        _ => None,
    };
    if o.at2.is_some() && second.is_none() && SIMULATION_OBSERVABLES.contains(&o.name.as_str()) {
        return Err(format!("'{o}': {} takes one coordinate after '@', not two", o.name));
    }
    let station = || o.at.ok_or_else(|| format!("'{}' needs a station: {}@X", o.name, o.name));
    let both = || match (o.at, o.at2, second) {
        (Some(x), Some(y), _) => Ok((x, y)),
        (_, _, what) => Err(format!("'{o}' needs {}", what.unwrap_or("two coordinates"))),
    };
    let layer = || {
        let (x, k) = both()?;
        if k >= 1.0 && k.fract() == 0.0 && k <= u32::MAX as f64 {
            Ok((x, k as usize))
        } else {
            Err(format!("'{o}': the layer must be a whole number from 1 (the bottom layer), got {k}"))
        }
    };
    let (t, obj) = match o.name.as_str() {
        "spread" => (o.at.unwrap_or(end), Objective::Spread),
        "front" => (o.at.unwrap_or(end), Objective::Front),
        "width" => (end, Objective::Width { stations: vec![station()?] }),
        "height" => (end, Objective::Height { stations: vec![station()?] }),
        "level" => (end, Objective::Level { station: station()? }),
        "area" => (end, Objective::Area { stations: vec![station()?] }),
        "profile" => {
            let (station, y) = both()?;
            (end, Objective::Profile { station, y })
        }
        "layer_height" => {
            let (station, layer) = layer()?;
            (end, Objective::LayerHeight { station, layer })
        }
        "layer_width" => {
            let (station, layer) = layer()?;
            (end, Objective::LayerWidth { station, layer })
        }
        "vx_max" => (o.at.unwrap_or(end), Objective::VxMax),
        "kinetic_energy" => (o.at.unwrap_or(end), Objective::KineticEnergy),
        "mean_z" => (o.at.unwrap_or(end), Objective::MeanZ),
        name if super::front::OBSERVABLES.contains(&name) => return Err(format!("'{o}' is read from the front's history over the run, not at one time: it has no adjoint")),
        other => return Err(format!("a simulation cannot observe '{other}'")),
    };
    if !(0.0..=end).contains(&t) {
        return Err(format!("'{o}': time {t} s is outside the run [0, {end}] s"));
    }
    Ok((t, obj))
}

fn simulate(model: &Model, keys: &Keys, scenario: &Path, wanted: &[Observable], threads: Option<usize>) -> Result<Vec<f64>, String> {
    let mut sc = parse_scenario(&scenario_text(model, keys, scenario)?, scenario)?;
    if let Some(t) = threads {
        sc.simulation.threads = t;
    }
    let end = sc.simulation.end_time;
    let mut values = vec![0.0; wanted.len()];
    // a print's failure layer and time: one run to the failure, observed as `strand run` does
    let failing: Vec<usize> = (0..wanted.len()).filter(|&k| crate::failure::OBSERVABLES.contains(&wanted[k].name.as_str())).collect();
    if !failing.is_empty() {
        let (failure, layers) = crate::report::failure_of(&sc)?;
        for &k in &failing {
            values[k] = crate::failure::observable(&wanted[k].name, failure.as_ref(), layers, end)?;
        }
    }
    // the front's arrival and stop: its history over the whole run (`front.rs`)
    let history: Vec<usize> = (0..wanted.len()).filter(|&k| super::front::OBSERVABLES.contains(&wanted[k].name.as_str())).collect();
    let rest: Vec<usize> = (0..wanted.len()).filter(|k| !failing.contains(k) && !history.contains(k)).collect();
    if rest.is_empty() && history.is_empty() {
        return Ok(values);
    }
    let mut plan: Vec<(usize, f64, Objective)> = rest.iter().map(|&k| observable_plan(&wanted[k], end).map(|(t, o)| (k, t, o))).collect::<Result<_, _>>()?;
    plan.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut sim = Simulation::new(&sc).map_err(|e| e.to_string())?;
    let mut trace = if history.is_empty() { None } else { Some(super::front::FrontTrace::start(&sim)?) };
    for (k, t, obj) in plan {
        step_to(&mut sim, t, trace.as_mut())?;
        values[k] = obj.evaluate(&sim, &Frame::of(&sim), None)?;
    }
    if let Some(mut trace) = trace {
        step_to(&mut sim, end, Some(&mut trace))?;
        for k in history {
            values[k] = trace.value(&wanted[k])?;
        }
    }
    Ok(values)
}

/// Step `sim` to time `t`, recording the front after each step into `trace` when given.
fn step_to(sim: &mut Simulation, t: f64, mut trace: Option<&mut super::front::FrontTrace>) -> Result<(), String> {
    while sim.time < t * (1.0 - 1e-12) {
        sim.step_until(t).map_err(|e| e.to_string())?;
        if let Some(tr) = trace.as_mut() {
            tr.record(sim)?;
        }
    }
    Ok(())
}

/// The material of a rheometer experiment (the model's, with its `material.*` keys; walls and the
/// printing process do not reach a rheometer) and its protocol.
pub fn rheometer_setup(model: &Model, keys: &Keys, base: &Path, protocol: &toml::Value) -> Result<(Box<dyn Material>, Protocol), String> {
    let mut mat = model.material_for(keys);
    for (k, v) in keys {
        match k.strip_prefix("material.") {
            Some(key) => {
                mat.insert(key.to_string(), toml::Value::Float(*v));
            }
            None if k.starts_with("boundary.") || k.starts_with("print.") => {}
            None => return Err(format!("set.{k}: a rheometer test takes material keys only")),
        }
    }
    let material = crate::materials::build_material(&mat)?;
    let proto: Protocol = match protocol {
        toml::Value::String(file) => {
            let p = base.join(file);
            let text = std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            toml::from_str(&text).map_err(|e| format!("{}: {}", p.display(), e.message()))?
        }
        v => v.clone().try_into().map_err(|e: toml::de::Error| format!("protocol: {}", e.message()))?,
    };
    Ok((material, proto))
}

/// Which reading a rheometer observable is: the last one at its shear rate.
pub fn reading_index(o: &Observable, readings: &[Reading]) -> Result<usize, String> {
    let rate = reading_rate(o)?;
    readings.iter().rposition(|r| (r.rate - rate).abs() <= 1e-9 * rate.abs().max(1.0)).ok_or_else(|| {
        format!("'{o}': the protocol records no reading at rate {rate} (it records {:?})", readings.iter().map(|r| r.rate).collect::<Vec<_>>())
    })
}

/// The shear rate of a rheometer observable, `stress@RATE`.
pub fn reading_rate(o: &Observable) -> Result<f64, String> {
    if !RHEOMETER_OBSERVABLES.contains(&o.name.as_str()) {
        return Err(format!("a rheometer test cannot observe '{}'; it can observe {}", o.name, RHEOMETER_OBSERVABLES.join(", ")));
    }
    match (o.at, o.at2) {
        (Some(rate), None) => Ok(rate),
        (Some(_), Some(_)) => Err(format!("'{o}': stress takes one coordinate, the shear rate: stress@RATE")),
        (None, _) => Err("'stress' needs the shear rate: stress@RATE".into()),
    }
}

/// The observations grouped by experiment, in order of first appearance.
pub fn group(data: &[Observation]) -> Vec<(String, Vec<Observable>)> {
    let mut wanted: Vec<(String, Vec<Observable>)> = Vec::new();
    for o in data {
        match wanted.iter_mut().find(|(id, _)| *id == o.experiment) {
            Some((_, v)) => v.push(o.observable.clone()),
            None => wanted.push((o.experiment.clone(), vec![o.observable.clone()])),
        }
    }
    wanted
}

/// The model's value of every observation, in the data's order.
pub fn model_values(model: &Model, data: &[Observation], exps: &Experiments, jobs: usize) -> Result<Vec<f64>, String> {
    let wanted = group(data);
    let values = evaluate_all(model, exps, &wanted, jobs)?;
    Ok(ungroup(data, &wanted, &values))
}

/// Per-experiment results back in the data's order.
pub fn ungroup<T: Clone>(data: &[Observation], wanted: &[(String, Vec<Observable>)], per: &[Vec<T>]) -> Vec<T> {
    let mut seen = vec![0usize; wanted.len()];
    data.iter()
        .map(|o| {
            let e = wanted.iter().position(|(id, _)| *id == o.experiment).expect("grouped");
            seen[e] += 1;
            per[e][seen[e] - 1].clone()
        })
        .collect()
}

/// Evaluate each experiment's `wanted` observables, `jobs` experiments at a time.
pub fn evaluate_all(model: &Model, exps: &Experiments, wanted: &[(String, Vec<Observable>)], jobs: usize) -> Result<Vec<Vec<f64>>, String> {
    let threads = job_threads(jobs);
    par_map(wanted.len(), jobs, |k| {
        let (id, obs) = &wanted[k];
        evaluate(model, exps, find(exps, id)?, obs, threads)
    })
}

/// Threads of each simulation when `jobs` run side by side: the cores shared out (at least one
/// each), so the jobs' thread teams together do not outnumber the cores (teams beyond the cores
/// wait on each other: system time, not work). `None` (the scenario's own) for one job.
pub fn job_threads(jobs: usize) -> Option<usize> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (jobs > 1).then(|| (cores / jobs).max(1))
}

/// Experiment `id`, or an error listing the ids there are.
pub fn find<'a>(exps: &'a Experiments, id: &str) -> Result<&'a Experiment, String> {
    exps.get(id).ok_or_else(|| format!("experiment '{id}' is not in the experiments file (it has {})", exps.experiment.iter().map(|e| e.id.as_str()).collect::<Vec<_>>().join(", ")))
}

/// `f(0..n)` as independent jobs, `jobs` at a time; results in index order whatever the number
/// of jobs, the first error (by index) if any failed.
pub fn par_map<T: Send>(n: usize, jobs: usize, f: impl Fn(usize) -> Result<T, String> + Sync) -> Result<Vec<T>, String> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<std::sync::Mutex<Option<Result<T, String>>>> = (0..n).map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, n.max(1)) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if k >= n {
                    break;
                }
                let r = f(k);
                *results[k].lock().unwrap() = Some(r);
            });
        }
    });
    results.into_iter().map(|m| m.into_inner().unwrap().expect("every job ran")).collect()
}

/// One observation against the model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    pub experiment: String,
    pub observable: String,
    pub at: Option<f64>,
    /// The second coordinate (`profile@X:Y`'s y, `layer_height@X:K`'s layer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at2: Option<f64>,
    pub measured: f64,
    pub uncertainty: f64,
    pub model: f64,
    /// model - measured.
    pub residual: f64,
    /// residual / uncertainty, or with the discretisation error added in quadrature:
    /// residual / sqrt(uncertainty^2 + discretisation^2).
    pub z: f64,
    /// The model's estimated discretisation error (`resolution.rs`): its value at its cell size
    /// minus the Richardson extrapolation; absent without `[resolution]` and for rheometer tests.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub discretisation: Option<f64>,
}

impl Row {
    /// Where the observation was taken, as a table cell: `X`, `X:Y`, or `-` for none.
    pub fn at_cell(&self) -> String {
        if self.at.is_some() {
            at_text(self.at, self.at2)
        } else {
            "-".to_string()
        }
    }

    /// The observable as written in the data: `name`, `name@X` or `name@X:Y`.
    pub fn label(&self) -> String {
        Observable { name: self.observable.clone(), at: self.at, at2: self.at2 }.to_string()
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Summary {
    pub name: String,
    pub n: usize,
    /// sqrt(mean z^2).
    pub rms_z: f64,
    /// Mean |residual| / |measured|.
    pub mean_rel_error: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Comparison {
    pub rows: Vec<Row>,
    pub by_experiment: Vec<Summary>,
    pub by_observable: Vec<Summary>,
    /// Sum of z^2: the loss a calibration minimises.
    pub chi2: f64,
}

fn summarise<'a>(rows: impl Iterator<Item = &'a Row>, key: impl Fn(&Row) -> String) -> Vec<Summary> {
    let mut out: Vec<(String, Vec<&Row>)> = Vec::new();
    for r in rows {
        let k = key(r);
        match out.iter_mut().find(|(n, _)| *n == k) {
            Some((_, v)) => v.push(r),
            None => out.push((k, vec![r])),
        }
    }
    out.into_iter()
        .map(|(name, rs)| {
            let n = rs.len();
            let rms_z = (rs.iter().map(|r| r.z * r.z).sum::<f64>() / n as f64).sqrt();
            let mean_rel_error = rs.iter().map(|r| (r.residual / r.measured).abs()).sum::<f64>() / n as f64;
            Summary { name, n, rms_z, mean_rel_error }
        })
        .collect()
}

/// Run every experiment the data name and compare.
pub fn compare(model: &Model, data: &[Observation], exps: &Experiments, jobs: usize) -> Result<Comparison, String> {
    Ok(comparison(data, &model_values(model, data, exps, jobs)?))
}

/// The comparison of `data` with the model's values of it.
pub fn comparison(data: &[Observation], values: &[f64]) -> Comparison {
    comparison_with_discretisation(data, values, &vec![None; data.len()])
}

/// The comparison with each observation's discretisation error (if any) added in quadrature to
/// its uncertainty in z.
pub fn comparison_with_discretisation(data: &[Observation], values: &[f64], discretisation: &[Option<f64>]) -> Comparison {
    let rows: Vec<Row> = data
        .iter()
        .zip(values)
        .zip(discretisation)
        .map(|((o, &model), &d)| {
            let residual = model - o.value;
            let sigma = o.uncertainty.hypot(d.unwrap_or(0.0));
            Row { experiment: o.experiment.clone(), observable: o.observable.name.clone(), at: o.observable.at, at2: o.observable.at2, measured: o.value, uncertainty: o.uncertainty, model, residual, z: residual / sigma, discretisation: d }
        })
        .collect();
    let by_experiment = summarise(rows.iter(), |r| r.experiment.clone());
    let by_observable = summarise(rows.iter(), |r| r.observable.clone());
    let chi2 = rows.iter().map(|r| r.z * r.z).sum();
    Comparison { rows, by_experiment, by_observable, chi2 }
}

/// The comparison as text: every observation, the summaries, and where the model fails most.
pub fn report(c: &Comparison) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // the discretisation column only when the experiments declare [resolution]
    let counted = c.rows.iter().any(|r| r.discretisation.is_some());
    let cell = |r: &Row| match (counted, r.discretisation) {
        (false, _) => String::new(),
        (true, Some(d)) => format!(" {d:>13.4e}"),
        (true, None) => format!(" {:>13}", "-"),
    };
    let head = if counted { format!(" {:>13}", "discretis.") } else { String::new() };
    let _ = writeln!(s, "{:<14} {:<16} {:>10} {:>13} {:>13} {:>13}{head} {:>8}", "experiment", "observable", "at", "measured", "model", "residual", "z");
    for r in &c.rows {
        let _ = writeln!(s, "{:<14} {:<16} {:>10} {:>13.6e} {:>13.6e} {:>13.4e}{} {:>8.2}", r.experiment, r.observable, r.at_cell(), r.measured, r.model, r.residual, cell(r), r.z);
    }
    if counted {
        let _ = writeln!(s, "(discretis.: the model's estimated discretisation error, added in quadrature to the uncertainty in z)");
    }
    for (title, list) in [("per experiment", &c.by_experiment), ("per observable", &c.by_observable)] {
        let _ = writeln!(s, "\n{title}:");
        for m in list {
            let _ = writeln!(s, "  {:<16} n = {:<4} rms z = {:<10.3} mean |relative error| = {:.2} %", m.name, m.n, m.rms_z, 100.0 * m.mean_rel_error);
        }
    }
    let mut worst: Vec<&Row> = c.rows.iter().collect();
    worst.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    let _ = writeln!(s, "\nwhere the model fails most (largest |z|):");
    for r in worst.iter().take(5) {
        let dir = if r.residual > 0.0 { "over" } else { "under" };
        let _ = writeln!(s, "  {} {}: z = {:.2} (model {dir}-predicts by {:.2} %)", r.experiment, r.label(), r.z, 100.0 * (r.residual / r.measured).abs());
    }
    let _ = writeln!(s, "\nchi^2 = {:.6e} over {} observations", c.chi2, c.rows.len());
    s
}

/// Measurements of every experiment's `observe` list under `model`, each value times
/// (1 + noise N(0, 1)) from a seeded generator, with uncertainty noise |value| (at least 1e-6 of
/// it, so z-scores stay finite without noise).
pub fn synth(model: &Model, exps: &Experiments, noise: f64, seed: u64, jobs: usize) -> Result<Vec<Observation>, String> {
    if !(noise.is_finite() && noise >= 0.0) {
        return Err(format!("--noise must be >= 0, got {noise}"));
    }
    let wanted: Vec<(String, Vec<Observable>)> = exps
        .experiment
        .iter()
        .map(|x| Ok((x.id.clone(), x.observe.iter().map(|o| Observable::parse(o)).collect::<Result<Vec<_>, _>>()?)))
        .collect::<Result<_, String>>()?;
    if wanted.iter().all(|(_, o)| o.is_empty()) {
        return Err("no experiment lists anything to observe (observe = [...])".into());
    }
    let values = evaluate_all(model, exps, &wanted, jobs)?;
    let mut rng = Normal::new(seed);
    let mut out = Vec::new();
    for ((id, obs), vals) in wanted.iter().zip(values) {
        for (o, v) in obs.iter().zip(vals) {
            let value = v * (1.0 + noise * rng.sample());
            out.push(Observation { experiment: id.clone(), observable: o.clone(), value, uncertainty: noise.max(1e-6) * v.abs().max(1e-300) });
        }
    }
    Ok(out)
}

/// Standard normal samples: splitmix64 and Box-Muller, so a seed gives the same data anywhere.
struct Normal {
    state: u64,
    spare: Option<f64>,
}

impl Normal {
    fn new(seed: u64) -> Normal {
        Normal { state: seed, spare: None }
    }

    fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn sample(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u, v) = (self.uniform(), self.uniform());
        let r = (-2.0 * u.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * v;
        self.spare = Some(r * a.sin());
        r * a.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: &str = "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";
    const EXPS: &str = "[[experiment]]\nid = \"flow\"\nobserve = [\"stress@20\", \"stress@5\"]\n[experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0]\nhold = 0.5\n\n\
                        [[experiment]]\nid = \"weak\"\nset = { \"material.yield_stress\" = 300.0 }\nobserve = [\"stress@5\"]\n[experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"shear\"\nrate = 5.0\nduration = 0.5\n";

    fn setup() -> (Model, Experiments) {
        let m = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let e: Experiments = toml::from_str(EXPS).unwrap();
        e.validate().unwrap();
        (m, e)
    }

    #[test]
    fn synthetic_data_of_the_model_itself_has_no_residual_and_another_model_has() {
        let (m, e) = setup();
        let data = synth(&m, &e, 0.0, 1, 2).unwrap();
        assert_eq!(data.len(), 3);
        // tau0 + eta gamma_dot, the override reaching the second experiment only
        let expect = [630.0 + 7.5 * 20.0, 630.0 + 7.5 * 5.0, 300.0 + 7.5 * 5.0];
        for (o, x) in data.iter().zip(expect) {
            assert!((o.value / x - 1.0).abs() < 1e-3, "{o:?} vs {x}");
        }
        let c = compare(&m, &data, &e, 1).unwrap();
        assert!(c.rows.iter().all(|r| r.residual == 0.0), "{c:?}");
        let other = Model::from_table(&MODEL.replace("viscosity = 7.5", "viscosity = 9.0").parse().unwrap()).unwrap();
        let c = compare(&other, &data, &e, 1).unwrap();
        assert!(c.rows.iter().all(|r| r.residual > 0.0) && c.chi2 > 0.0, "{c:?}");
        let text = report(&c);
        assert!(text.contains("where the model fails most") && text.contains("flow stress@20"), "{text}");
    }

    #[test]
    fn noise_is_seeded_and_jobs_do_not_change_results() {
        let (m, e) = setup();
        let a = synth(&m, &e, 0.05, 7, 1).unwrap();
        assert_eq!(a, synth(&m, &e, 0.05, 7, 3).unwrap());
        assert_ne!(a, synth(&m, &e, 0.05, 8, 1).unwrap());
        let rel: Vec<f64> = a.iter().zip(synth(&m, &e, 0.0, 7, 1).unwrap()).map(|(n, c)| n.value / c.value - 1.0).collect();
        assert!(rel.iter().all(|r| r.abs() < 0.25) && rel.iter().any(|r| r.abs() > 1e-4), "{rel:?}");
    }

    /// Issue 27 finding 4: a rheometer reading is the stress; any other name is refused, as for
    /// simulations, instead of being computed as the stress.
    #[test]
    fn a_rheometer_observes_only_the_stress() {
        for name in ["banana@1", "strain@1", "spread@1", "spread"] {
            let e = reading_rate(&Observable::parse(name).unwrap()).unwrap_err();
            assert!(e.contains("rheometer test cannot observe") && e.contains("stress"), "{name}: {e}");
        }
        assert_eq!(reading_rate(&Observable::parse("stress@2.5").unwrap()), Ok(2.5));
    }

    #[test]
    fn printed_geometry_observables_are_their_objectives_at_the_end() {
        let plan = |s: &str| observable_plan(&Observable::parse(s).unwrap(), 2.0);
        assert_eq!(plan("profile@0.075:0.01").unwrap(), (2.0, Objective::Profile { station: 0.075, y: 0.01 }));
        assert_eq!(plan("layer_height@0.075:2").unwrap(), (2.0, Objective::LayerHeight { station: 0.075, layer: 2 }));
        assert_eq!(plan("layer_width@0.075:1").unwrap(), (2.0, Objective::LayerWidth { station: 0.075, layer: 1 }));
        // each objective's name is the observable's own
        for s in ["profile@0.075:0.01", "layer_height@0.075:2", "layer_width@0.075:1", "height@0.075"] {
            assert_eq!(plan(s).unwrap().1.name(), s);
        }
        let e = plan("layer_height@0.075:-2").unwrap_err();
        assert!(e.contains("'layer_height@0.075:-2'") && e.contains("whole number from 1"), "{e}");
        let e = plan("profile").unwrap_err();
        assert!(e.contains("profile@X:Y"), "{e}");
        // the whole material's observables at a time during the run, or at its end
        for name in ["spread", "front", "vx_max", "kinetic_energy", "mean_z"] {
            assert_eq!(plan(&format!("{name}@0.5")).unwrap().0, 0.5, "{name}");
            assert_eq!(plan(name).unwrap().0, 2.0, "{name}");
        }
        assert!(plan("mean_z@3").unwrap_err().contains("outside the run"));
        let e = plan("front@1:2").unwrap_err();
        assert!(e.contains("front takes one coordinate"), "{e}");
        let e = reading_rate(&Observable::parse("stress@1:2").unwrap()).unwrap_err();
        assert!(e.contains("stress@RATE"), "{e}");
    }

    #[test]
    fn the_report_shows_both_coordinates() {
        let data: Vec<Observation> = ["profile@0.075:0.01", "layer_height@0.075:2"]
            .iter()
            .map(|s| Observation { experiment: "print".into(), observable: Observable::parse(s).unwrap(), value: 0.01, uncertainty: 1e-4 })
            .collect();
        let c = comparison(&data, &[0.011, 0.012]);
        assert_eq!((c.rows[0].at, c.rows[0].at2), (Some(0.075), Some(0.01)));
        let text = report(&c);
        assert!(text.contains("print profile@0.075:0.01: z = 10.00") && text.contains("0.075:2"), "{text}");
        let json = serde_json::to_value(&c).unwrap();
        assert_eq!(json["rows"][1]["at2"], 2.0);
    }

    #[test]
    fn unknown_experiments_and_readings_are_named() {
        let (m, e) = setup();
        let data = vec![Observation { experiment: "nope".into(), observable: Observable::parse("stress@5").unwrap(), value: 1.0, uncertainty: 1.0 }];
        let err = compare(&m, &data, &e, 1).unwrap_err();
        assert!(err.contains("'nope'") && err.contains("flow, weak"), "{err}");
        let data = vec![Observation { experiment: "flow".into(), observable: Observable::parse("stress@7").unwrap(), value: 1.0, uncertainty: 1.0 }];
        let err = compare(&m, &data, &e, 1).unwrap_err();
        assert!(err.contains("flow") && err.contains("no reading at rate 7"), "{err}");
    }
}
