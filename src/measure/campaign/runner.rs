//! Running experiments under a model: the scenario keys each runs with, a simulation or a
//! virtual-rheometer test producing every observable asked of it, and many experiments as
//! independent jobs (`strand compare`, `synth`, `calibrate` and `diagnose` all run them here).
//!
//! A model file holds the `[material]` every experiment uses and the effects switched on
//! (`model.rs`): its material replaces the scenario's own, its keys and its effects' keys are set,
//! and an experiment's `set` overrides apply after them (a speed, a geometry). Each experiment
//! runs once, producing every observable asked of it; experiments are independent jobs, run
//! `jobs` at a time, and give the same numbers however many run together.

use crate::measure::error::{io_error, toml_error, MeasureError};
use crate::measure::effects::{Effect, Keys};
use super::experiments::{Experiment, Experiments};
use crate::measure::front::FrontTrace;
use crate::measure::passing::PassingTrace;
use crate::measure::model::{set_path, Model};
use crate::measure::observables::{observable_plan, reading_index};
use crate::measure::observation::{Observable, Observation};
use super::rheometer::{Protocol, Rheometer};
use super::spare::Spare;
use crate::observables::{Frame, Objective};
use crate::kernels::material::Material;
use crate::scenario::Scenario;
use crate::solver::Simulation;
use std::path::Path;

/// A model applied to one experiment: the scenario keys it runs with (the model's for the
/// experiment's covariates, then the experiment's own `set` overrides), the `[material]` it runs
/// with before its keys are set (the model's, less every number whose `material.KEY` the keys
/// lack: an effect removed it, as the moduli replace `poisson_ratio` by `shear_modulus`) and the
/// effects switched on, which its scenario must accept. Built once for an experiment and a model:
/// the experiment's runs, its scenario and the record of it are made from it, not from the model
/// again.
#[derive(Clone)]
pub struct Applied {
    pub keys: Keys,
    material: toml::Table,
    effects: Vec<&'static dyn Effect>,
}

impl Applied {
    /// `model` applied to experiment `x`.
    pub fn new(model: &Model, x: &Experiment) -> Result<Applied, MeasureError> {
        let mut keys = model.keys(&x.covariates())?;
        for (k, v) in &x.set {
            keys.insert(k.clone(), number(v));
        }
        Ok(Applied::with_keys(model, keys))
    }

    /// `model` run with scenario keys `keys` (its own for some covariates).
    pub fn with_keys(model: &Model, keys: Keys) -> Applied {
        let mut material = model.material.clone();
        material.retain(|k, v| {
            crate::measure::observation::number(v).is_none() || keys.contains_key(&format!("material.{k}"))
        });
        Applied { material, effects: model.effects.iter().map(|(e, _)| *e).collect(), keys }
    }

    /// The scenario table of a simulation experiment: the file's, with the model's `[material]`
    /// in place of its own and every key set.
    pub fn scenario_table(&self, scenario: &Path) -> Result<toml::Table, MeasureError> {
        let text = std::fs::read_to_string(scenario).map_err(io_error(scenario))?;
        let mut doc: toml::Table = text.parse().map_err(toml_error(scenario))?;
        doc.insert("material".into(), toml::Value::Table(self.material.clone()));
        for e in &self.effects {
            e.check_scenario(&doc)
                .map_err(|m| MeasureError::Effect(format!("effect '{}' {m} in {}", e.name(), scenario.display())))?;
        }
        for (k, v) in &self.keys {
            let at = crate::measure::effects::placed(k, &doc);
            set_path(&mut doc, &at, *v).map_err(|e| e.within(format!("set.{k}")))?;
        }
        Ok(doc)
    }

    /// The text of [`Applied::scenario_table`]: what a saved result records of the scenario it
    /// ran.
    pub fn scenario_text(&self, scenario: &Path) -> Result<String, MeasureError> {
        Ok(toml::to_string(&self.scenario_table(scenario)?)?)
    }

    /// The scenario a simulation experiment runs: [`Applied::scenario_table`], read as a scenario
    /// from the table (no text written and read back per run).
    pub fn scenario(&self, scenario: &Path) -> Result<Scenario, MeasureError> {
        scenario_from_table(self.scenario_table(scenario)?, scenario)
    }

    /// The material of a rheometer experiment (see [`Applied::material`]) and its protocol.
    pub fn rheometer_setup(
        &self,
        base: &Path,
        protocol: &toml::Value,
    ) -> Result<(Box<dyn Material>, Protocol), MeasureError> {
        let material = self.material()?;
        let proto: Protocol = match protocol {
            toml::Value::String(file) => {
                let p = base.join(file);
                let text = std::fs::read_to_string(&p).map_err(io_error(&p))?;
                toml::from_str(&text).map_err(|e| MeasureError::Run(format!("{}: {}", p.display(), e.message())))?
            }
            v => v
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| MeasureError::Run(format!("protocol: {}", e.message())))?,
        };
        Ok((material, proto))
    }

    /// The material a rheometer test runs: the model's, with its `material.*` keys set (walls and
    /// the printing process do not reach a rheometer; another key is refused).
    pub fn material(&self) -> Result<Box<dyn Material>, MeasureError> {
        let mut mat = self.material.clone();
        for (k, v) in &self.keys {
            match k.strip_prefix("material.") {
                Some(key) => {
                    mat.insert(key.to_string(), toml::Value::Float(*v));
                }
                None if k.starts_with("boundary.") || k.starts_with("print.") => {}
                None => return Err(MeasureError::Run(format!("set.{k}: a rheometer test takes material keys only"))),
            }
        }
        Ok(crate::materials::build_material(&mat)?)
    }
}

/// An override's value (validated as a number when the experiments were loaded).
fn number(v: &toml::Value) -> f64 {
    crate::measure::observation::number(v).unwrap_or(f64::NAN)
}

/// The model's values of `wanted` for experiment `x`; a simulation with `threads` threads (its
/// scenario's when `None`).
pub fn evaluate(
    model: &Model,
    exps: &Experiments,
    x: &Experiment,
    wanted: &[Observable],
    threads: Option<usize>,
) -> Result<Vec<f64>, MeasureError> {
    let r = Applied::new(model, x).and_then(|applied| match (&x.scenario, &x.protocol) {
        (Some(s), _) => simulate(&applied, &exps.base_dir.join(s), wanted, threads),
        (None, Some(p)) => {
            let (material, proto) = applied.rheometer_setup(&exps.base_dir, p)?;
            let readings = Rheometer::new(&*material, &proto)?.run();
            wanted.iter().map(|o| reading_index(o, &readings).map(|k| readings[k].stress)).collect()
        }
        (None, None) => Err(MeasureError::Run("neither scenario nor protocol".into())),
    });
    r.map_err(|e| e.within(format!("experiment '{}'", x.id)))
}

/// The scenario of table `doc`, read from file `scenario`: its files relative to the file's
/// folder, no checkpoints (an experiment's run is not resumed).
pub fn scenario_from_table(doc: toml::Table, scenario: &Path) -> Result<Scenario, MeasureError> {
    let sc = Scenario::from_table(doc).map_err(|e| MeasureError::from(e).within(scenario.display()))?;
    Ok(as_experiment(sc, scenario))
}

/// A scenario's text, read as experiment `scenario`'s (see [`scenario_from_table`]).
pub fn parse_scenario(text: &str, scenario: &Path) -> Result<Scenario, MeasureError> {
    let sc = Scenario::parse(text).map_err(|e| MeasureError::from(e).within(scenario.display()))?;
    Ok(as_experiment(sc, scenario))
}

fn as_experiment(mut sc: Scenario, scenario: &Path) -> Scenario {
    sc.base_dir = scenario.parent().map(Path::to_path_buf).unwrap_or_default();
    sc.checkpoint.enabled = false;
    sc
}

fn simulate(
    applied: &Applied,
    scenario: &Path,
    wanted: &[Observable],
    threads: Option<usize>,
) -> Result<Vec<f64>, MeasureError> {
    let mut sc = applied.scenario(scenario)?;
    if let Some(t) = threads {
        sc.simulation.threads = t;
    }
    let end = sc.simulation.end_time;
    let mut values = vec![0.0; wanted.len()];
    // a print's failure layer and time: one run to the failure, observed as `strand run` does
    let failing: Vec<usize> =
        (0..wanted.len()).filter(|&k| crate::failure::OBSERVABLES.contains(&wanted[k].name.as_str())).collect();
    if !failing.is_empty() {
        let (failure, layers) = crate::report::failure_of(&sc)?;
        for &k in &failing {
            values[k] = crate::failure::observable(&wanted[k].name, failure.as_ref(), layers, end)?;
        }
    }
    // the front's arrival and stop, the mass passed below a plane: histories over the whole run
    // (`front.rs`, `passing.rs`)
    let of = |names: &[&str]| -> Vec<usize> {
        (0..wanted.len()).filter(|&k| names.contains(&wanted[k].name.as_str())).collect()
    };
    let (fronts, passed) = (of(crate::measure::front::OBSERVABLES), of(crate::measure::passing::OBSERVABLES));
    let rest: Vec<usize> =
        (0..wanted.len()).filter(|k| !failing.contains(k) && !fronts.contains(k) && !passed.contains(k)).collect();
    if rest.is_empty() && fronts.is_empty() && passed.is_empty() {
        return Ok(values);
    }
    let mut plan: Vec<(usize, f64, Objective)> =
        rest.iter().map(|&k| observable_plan(&wanted[k], end).map(|(t, o)| (k, t, o))).collect::<Result<_, _>>()?;
    plan.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut sim = Simulation::new(&sc)?;
    // each plane recorded once, however many fractions of it are observed
    let mut planes: Vec<f64> = passed.iter().filter_map(|&k| wanted[k].at).collect();
    planes.sort_by(f64::total_cmp);
    planes.dedup();
    let mut history = Histories {
        front: if fronts.is_empty() { None } else { Some(FrontTrace::start(&sim)?) },
        passing: if passed.is_empty() { None } else { Some(PassingTrace::start(&sim, planes)?) },
    };
    for (k, t, obj) in plan {
        step_to(&mut sim, t, &mut history)?;
        values[k] = obj.evaluate(&sim, &Frame::of(&sim), None)?;
    }
    if !fronts.is_empty() || !passed.is_empty() {
        step_to(&mut sim, end, &mut history)?;
    }
    if let Some(trace) = &history.front {
        for &k in &fronts {
            values[k] = trace.value(&wanted[k])?;
        }
    }
    if let Some(trace) = &history.passing {
        for &k in &passed {
            values[k] = trace.value(&wanted[k])?;
        }
    }
    Ok(values)
}

/// What a run records after every step for the observables read from its history.
struct Histories {
    front: Option<FrontTrace>,
    passing: Option<PassingTrace>,
}

/// Step `sim` to time `t`, recording the histories after each step.
fn step_to(sim: &mut Simulation, t: f64, history: &mut Histories) -> Result<(), MeasureError> {
    while sim.time < t * (1.0 - 1e-12) {
        sim.step_until(t)?;
        if let Some(tr) = history.front.as_mut() {
            tr.record(sim)?;
        }
        if let Some(tr) = history.passing.as_mut() {
            tr.record(sim)?;
        }
    }
    Ok(())
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
pub fn model_values(
    model: &Model,
    data: &[Observation],
    exps: &Experiments,
    jobs: usize,
) -> Result<Vec<f64>, MeasureError> {
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
pub fn evaluate_all(
    model: &Model,
    exps: &Experiments,
    wanted: &[(String, Vec<Observable>)],
    jobs: usize,
) -> Result<Vec<Vec<f64>>, MeasureError> {
    let threads = job_threads(jobs, wanted.len());
    par_map_experiments(wanted, jobs, |k, _| {
        let (id, obs) = &wanted[k];
        evaluate(model, exps, find(exps, id)?, obs, threads)
    })
}

/// Threads of each simulation when up to `jobs` of `experiments` run side by side: the cores
/// shared out among the jobs that run at once, at most one per experiment (at least one thread
/// each), so the jobs' thread teams together do not outnumber the cores (teams beyond the cores
/// wait on each other: system time, not work) and an experiment run alone takes them all.
/// `None` (the scenario's own) for one job.
pub fn job_threads(jobs: usize, experiments: usize) -> Option<usize> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let side_by_side = jobs.min(experiments);
    (side_by_side > 1).then(|| (cores / side_by_side).max(1))
}

/// Experiment `id`, or an error listing the ids there are.
pub fn find<'a>(exps: &'a Experiments, id: &str) -> Result<&'a Experiment, MeasureError> {
    exps.get(id).ok_or_else(|| {
        MeasureError::Run(format!(
            "experiment '{id}' is not in the experiments file (it has {})",
            exps.experiment.iter().map(|e| e.id.as_str()).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// How an evaluation's experiments run here: `n` at a time, and `done` called as each one ends
/// (the command's progress counts its runs then, not only when the whole evaluation ends: a
/// Jacobian of a print campaign is minutes of runs).
#[derive(Clone, Copy)]
pub struct Jobs<'a> {
    pub n: usize,
    pub done: &'a (dyn Fn() + Sync),
}

impl Jobs<'_> {
    /// `n` at a time, counted nowhere.
    pub fn new(n: usize) -> Jobs<'static> {
        Jobs { n, done: &|| {} }
    }
}

/// `f(k)` for each of the experiments `wanted` (`f(k)` runs `wanted[k]`) as independent jobs,
/// `jobs` at a time, results in index order (the first error by index if any failed), handed out
/// longest first by the seconds each took last in this process (those not yet run first, in their
/// order), so that a long experiment does not start last while the other workers stand idle.
/// The order is scheduling only: the results, and each job's threads, are the same in any order.
/// A worker left without an experiment joins the runs of those still running that go through
/// the [`Spare`] `f` is given.
pub fn par_map_experiments<T: Send>(
    wanted: &[(String, Vec<Observable>)],
    jobs: usize,
    f: impl Fn(usize, &Spare) -> Result<T, MeasureError> + Sync,
) -> Result<Vec<T>, MeasureError> {
    let last: Vec<f64> = {
        let took = LAST_SECONDS.lock().unwrap_or_else(|e| e.into_inner());
        wanted.iter().map(|(id, _)| took.get(id).copied().unwrap_or(f64::INFINITY)).collect()
    };
    let mut order: Vec<usize> = (0..wanted.len()).collect();
    order.sort_by(|&a, &b| last[b].total_cmp(&last[a]).then(a.cmp(&b)));
    let workers = jobs.clamp(1, order.len().max(1));
    let spare = Spare::new(workers);
    in_order(&order, workers, &spare, |k| {
        let t = std::time::Instant::now();
        let r = f(k, &spare);
        LAST_SECONDS.lock().unwrap_or_else(|e| e.into_inner()).insert(wanted[k].0.clone(), t.elapsed().as_secs_f64());
        r
    })
}

/// Seconds each experiment's last job took in this process ([`par_map_experiments`]).
static LAST_SECONDS: std::sync::Mutex<std::collections::BTreeMap<String, f64>> =
    std::sync::Mutex::new(std::collections::BTreeMap::new());

/// `f(k)` for every k of `order` as independent jobs, handed out in that order by `workers`
/// threads, each of which leaves its slot to `spare` when none is left; results in index order,
/// the first error (by index) if any failed.
fn in_order<T: Send>(
    order: &[usize],
    workers: usize,
    spare: &Spare,
    f: impl Fn(usize) -> Result<T, MeasureError> + Sync,
) -> Result<Vec<T>, MeasureError> {
    let n = order.len();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<std::sync::Mutex<Option<Result<T, MeasureError>>>> =
        (0..n).map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    let k = order[i];
                    let r = f(k);
                    *results[k].lock().unwrap() = Some(r);
                }
                spare.leave();
            });
        }
    });
    results.into_iter().map(|m| m.into_inner().unwrap().expect("every job ran")).collect()
}

#[cfg(test)]
mod tests {
    use super::fixture::setup;
    use super::*;

    #[test]
    fn unknown_experiments_and_readings_are_named() {
        let (m, e) = setup();
        let data = vec![Observation {
            experiment: "nope".into(),
            observable: Observable::parse("stress@5").unwrap(),
            value: 1.0,
            uncertainty: 1.0,
        }];
        let err = model_values(&m, &data, &e, 1).unwrap_err().to_string();
        assert!(err.contains("'nope'") && err.contains("flow, weak"), "{err}");
        let data = vec![Observation {
            experiment: "flow".into(),
            observable: Observable::parse("stress@7").unwrap(),
            value: 1.0,
            uncertainty: 1.0,
        }];
        let err = model_values(&m, &data, &e, 1).unwrap_err().to_string();
        assert!(err.contains("flow") && err.contains("no reading at rate 7"), "{err}");
    }
}

/// Two rheometer experiments under a Bingham model: the fixture of the runner's, the
/// comparison's and the synthesis's unit tests.
#[cfg(test)]
pub(crate) mod fixture {
    use super::{Experiments, Model};

    pub const MODEL: &str =
        "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";
    pub const EXPS: &str = "[[experiment]]\nid = \"flow\"\nobserve = [\"stress@20\", \"stress@5\"]\n\
        [experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0]\nhold = 0.5\n\n\
                        [[experiment]]\nid = \"weak\"\nset = { \"material.yield_stress\" = 300.0 }\nobserve = \
                            [\"stress@5\"]\n[experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"shear\"\n\
                            rate = 5.0\nduration = 0.5\n";

    pub fn setup() -> (Model, Experiments) {
        let m = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let e: Experiments = toml::from_str(EXPS).unwrap();
        e.validate().unwrap();
        (m, e)
    }
}
