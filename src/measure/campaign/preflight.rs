//! Before any experiment runs: every simulation a measurement command will build, planned.
//!
//! compare, synth, calibrate and diagnose run each experiment's scenario under the model, with the
//! experiment's `set` overrides and, for `[resolution]`, once more at the finer cells. Any of those
//! runs may be over the scenario's `[memory] budget` (a `set = { "simulation.dx" = 1e-5 }` asks
//! for terabytes), and a run found over it only when it starts may come after hours of others. So
//! each scenario is built and its memory planned (`solver::preflight`, the lower bound every
//! simulation's setup checks) up front, and the finer cells are checked to be finer, before the
//! first run: the refusal names the experiment, its `set`, and `[resolution] fine` when it was
//! the finer run.
//! `Simulation::new` plans again, so a path that misses this still refuses before it allocates.

use crate::measure::error::MeasureError;
use super::experiments::{Experiment, Experiments, ResolutionTable};
use crate::measure::model::Model;
use super::runner::Applied;
use crate::scenario::Scenario;

/// What the up-front planning saw: the experiments that print (whose cell size's discretisation
/// error matters most; see [`super::resolution::uncounted_warning`]).
#[derive(Debug, Default)]
pub struct Planned {
    pub prints: Vec<String>,
}

/// Plan every simulation the experiments `ids` (of `exps`, under `model`) will run: the
/// experiment's own and, with `[resolution]`, its finer one. An error names the first that
/// cannot be built or is over its budget, or whose finer cell is not finer.
pub fn plan_experiments<'a>(
    model: &Model,
    exps: &Experiments,
    ids: impl IntoIterator<Item = &'a str>,
) -> Result<Planned, MeasureError> {
    let mut planned = Planned::default();
    for id in ids {
        let Some(x) = exps.get(id) else { continue }; // an unknown id is the runner's to name
        let Some(file) = &x.scenario else { continue }; // a rheometer test allocates no pools
        let sc = scenario_of(model, exps, x).map_err(|e| e.within(format!("experiment '{id}'{}", with_set(&x.set))))?;
        crate::solver::preflight(&sc).map_err(|e| {
            MeasureError::Memory(format!("experiment '{id}' ({}{}): {e}", file.display(), with_set(&x.set)))
        })?;
        if sc.print.is_some() {
            planned.prints.push(id.to_string());
        }
        if let Some(table) = &exps.resolution {
            let fine = fine_scenario(model, exps, x, table)?;
            let (dx, fine_dx) = (sc.simulation.dx, fine.simulation.dx);
            if fine_dx >= dx {
                return Err(MeasureError::Resolution(format!(
                    "experiment '{id}': [resolution] fine.\"simulation.dx\" = {fine_dx} is not finer than the cell \
                        size the model runs it at, {dx}"
                )));
            }
            crate::solver::preflight(&fine).map_err(|e| {
                MeasureError::Memory(format!(
                    "experiment '{id}', its finer run of [resolution] fine = {}: {e}",
                    show(&table.fine)
                ))
            })?;
        }
    }
    Ok(planned)
}

/// Experiment `x`'s scenario under `model`, as the runner builds it.
fn scenario_of(model: &Model, exps: &Experiments, x: &Experiment) -> Result<Scenario, MeasureError> {
    let path = exps.base_dir.join(x.scenario.as_ref().expect("a simulation"));
    Applied::new(model, x)?.scenario(&path)
}

/// Experiment `x`'s finer run of `[resolution]`. When it cannot be built though `x` can, the
/// error names the `fine` key at fault (tried one at a time) rather than a line of the scenario
/// text the keys were set into, which the user never wrote.
fn fine_scenario(
    model: &Model,
    exps: &Experiments,
    x: &Experiment,
    table: &ResolutionTable,
) -> Result<Scenario, MeasureError> {
    let with = |keys: &mut dyn Iterator<Item = (&String, &toml::Value)>| {
        let mut f = x.clone();
        for (k, v) in keys {
            f.set.insert(k.clone(), v.clone());
        }
        scenario_of(model, exps, &f)
    };
    with(&mut table.fine.iter()).map_err(|all| {
        let culprit = table.fine.iter().find_map(|(k, v)| with(&mut std::iter::once((k, v))).err().map(|e| (k, e)));
        let (key, e) = match culprit {
            Some((k, e)) => (format!("fine.\"{k}\""), e),
            None => ("fine".to_string(), all),
        };
        // the error's last line says what is wrong; the lines above quote the generated text
        let text = e.to_string();
        let why = text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_string();
        MeasureError::Resolution(format!(
            "experiment '{}': [resolution] {key}: the finer run's scenario cannot be built: {why}",
            x.id
        ))
    })
}

/// ` with set = { ... }` when the experiment sets keys, for the messages.
fn with_set(set: &toml::Table) -> String {
    if set.is_empty() {
        String::new()
    } else {
        format!(" with set = {}", show(set))
    }
}

/// Overrides as written in the experiments file: `{ "simulation.dx" = 1e-5 }`.
fn show(t: &toml::Table) -> String {
    format!("{{ {} }}", t.iter().map(|(k, v)| format!("\"{k}\" = {v}")).collect::<Vec<_>>().join(", "))
}
