//! The model's value of every observation and, on request, its gradient with respect to named
//! model parameters — by the adjoints: the solver's reverse pass for a simulation (one forward
//! and one reverse sweep for all the observations of an experiment that its run passes, an
//! adjoint each: `strand grad`'s driver), the rheometer's for a rheometer test, then the model's
//! effects backwards ([`Model::keys_adjoint`]).
//!
//! Simulations here run the way a gradient run does (fixed step, every particle awake, one sort
//! by block up front), values and gradients alike, so a fit compares like with like; their values
//! can differ from `strand compare`'s in the last bits. An observation at an earlier time is taken
//! after the step of the whole run that reaches it (to the step control's rounding of 1e-9 dt),
//! not from a run that ends there: the two differ by that rounding of the last step's length.

use super::compare::{experiment_keys, find, group, job_threads, observable_plan, par_map, parse_scenario, reading_index, rheometer_setup, scenario_text, ungroup};
use super::data::{Experiment, Experiments, Observable, Observation};
use super::effects::Keys;
use super::model::Model;
use super::rheometer::Rheometer;
use crate::grad::driver::Seeded;
use crate::grad::{driver, params, GradOptions, Objective};

/// Values (one per observation) and, when asked, d value / d parameter (a row per observation).
pub struct Sensitivity {
    pub values: Vec<f64>,
    pub jacobian: Option<Vec<Vec<f64>>>,
}

/// Values of every observation under `model`, with their gradients in `names` when given;
/// experiments run `jobs` at a time.
pub fn sensitivity(model: &Model, data: &[Observation], exps: &Experiments, names: Option<&[String]>, jobs: usize) -> Result<Sensitivity, String> {
    let wanted = group(data);
    let threads = job_threads(jobs);
    let per = par_map(wanted.len(), jobs, |k| one(model, exps, &wanted[k].0, &wanted[k].1, names, threads))?;
    Ok(assemble(data, &wanted, &per, names))
}

/// One experiment's values of `wanted` and, with `names`, their gradients: the unit of work
/// [`sensitivity`] runs side by side and a scheduler's job runs alone (`engine.rs`).
pub fn one(model: &Model, exps: &Experiments, id: &str, wanted: &[Observable], names: Option<&[String]>, threads: Option<usize>) -> Result<Vec<Valued>, String> {
    let x = find(exps, id)?;
    experiment(model, exps, x, wanted, names, threads).map_err(|e| format!("experiment '{id}': {e}"))
}

/// The experiments' results ([`one`] each, in `wanted`'s order) in the data's order.
pub fn assemble(data: &[Observation], wanted: &[(String, Vec<Observable>)], per: &[Vec<Valued>], names: Option<&[String]>) -> Sensitivity {
    let flat = ungroup(data, wanted, per);
    Sensitivity {
        values: flat.iter().map(|(v, _)| *v).collect(),
        jacobian: names.map(|_| flat.into_iter().map(|(_, g)| g.expect("asked")).collect()),
    }
}

/// An observation's value and, when asked, its gradient.
pub type Valued = (f64, Option<Vec<f64>>);

fn experiment(model: &Model, exps: &Experiments, x: &Experiment, wanted: &[Observable], names: Option<&[String]>, threads: Option<usize>) -> Result<Vec<Valued>, String> {
    let keys = experiment_keys(model, x)?;
    // an override cuts the key from the model
    let chain = |mut keys_bar: Keys| -> Result<Vec<f64>, String> {
        for k in x.set.keys() {
            keys_bar.remove(k);
        }
        model.keys_adjoint(&x.covariates(), keys_bar, names.expect("gradients asked"))
    };
    match (&x.scenario, &x.protocol) {
        (Some(s), _) => {
            let path = exps.base_dir.join(s);
            let text = scenario_text(model, &keys, &path)?;
            let whole = parse_scenario(&text, &path)?;
            let end = whole.simulation.end_time;
            // each model key with the scenario key it landed on (the floor's friction on the
            // platform or the z_min face)
            let (wrt, placed): (Vec<String>, Vec<String>) = match names {
                Some(_) => {
                    let known = params::known(&driver::prepare(&whole, threads)?);
                    let doc: toml::Table = text.parse().map_err(|e| format!("{e}"))?;
                    keys.keys().filter(|k| !x.set.contains_key(*k)).map(|k| (k.clone(), super::effects::placed(k, &doc))).filter(|(_, p)| known.contains(p)).unzip()
                }
                None => (Vec::new(), Vec::new()),
            };
            // the observations the whole run passes share its forward and reverse sweeps (an
            // adjoint each); the others (between two of its steps, or at t = 0) run to their time
            let plans: Vec<(f64, Objective)> = wanted.iter().map(|o| observable_plan(o, end)).collect::<Result<_, _>>()?;
            let sim = driver::prepare(&whole, threads)?;
            let steps: Vec<Option<u64>> = plans.iter().map(|(t, _)| driver::step_at(&sim, *t)).collect();
            drop(sim);
            let shared: Vec<usize> = (0..plans.len()).filter(|&k| steps[k].is_some()).collect();
            let seeds: Vec<Seeded> = shared.iter().map(|&k| Seeded { objective: plans[k].1.clone(), step: steps[k] }).collect();
            let opts = GradOptions { ram_bytes: 2 << 30, disk_bytes: 0, disk_dir: std::env::temp_dir(), threads, schedule: None, until_rest: None };
            let mut out: Vec<Option<Valued>> = vec![None; plans.len()];
            if names.is_none() {
                for (&k, v) in shared.iter().zip(driver::forward_values(&whole, &seeds, threads)?) {
                    out[k] = Some((v, None));
                }
            } else {
                for (&k, r) in shared.iter().zip(driver::gradients(&whole, &seeds, &placed, &opts)?) {
                    out[k] = Some((r.value, Some(chain(wrt.iter().cloned().zip(r.gradient).collect())?)));
                }
            }
            for (k, (t, obj)) in plans.iter().enumerate().filter(|(k, _)| steps[*k].is_none()) {
                let sc = parse_scenario(&params::with_value(&text, "simulation.end_time", *t)?, &path)?;
                out[k] = Some(if names.is_none() {
                    let steps = driver::count_steps(&driver::prepare(&sc, threads)?);
                    (driver::forward_value(&sc, obj, threads, steps)?, None)
                } else {
                    let r = driver::gradient(&sc, obj, &placed, &opts)?;
                    (r.value, Some(chain(wrt.iter().cloned().zip(r.gradient).collect())?))
                });
            }
            Ok(out.into_iter().map(|v| v.expect("every observation valued")).collect())
        }
        (None, Some(p)) => {
            let (material, proto) = rheometer_setup(model, &keys, &exps.base_dir, p)?;
            let rh = Rheometer::new(&*material, &proto)?;
            let readings = rh.run();
            wanted
                .iter()
                .map(|o| {
                    let k = reading_index(o, &readings)?;
                    if names.is_none() {
                        return Ok((readings[k].stress, None));
                    }
                    let mut w = vec![0.0; readings.len()];
                    w[k] = 1.0;
                    let (_, g) = rh.gradient(&w)?;
                    let kb: Keys = material.param_names().iter().map(|n| format!("material.{n}")).zip(g).collect();
                    Ok((readings[k].stress, Some(chain(kb)?)))
                })
                .collect()
        }
        (None, None) => Err("neither scenario nor protocol".into()),
    }
}
