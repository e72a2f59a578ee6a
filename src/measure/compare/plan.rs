//! Comparisons that outgrow one machine: `strand compare --plan DIR` writes one command per
//! experiment (`DIR/jobs.txt`, a line each, for GNU parallel or a Slurm job array, with
//! `DIR/slurm.sh` for the latter); each command runs its experiment alone (`--only ID`) and saves
//! its values (`--save DIR/ID.json`); `strand compare --collect DIR` then compares from the
//! saved values, exactly as a local run would (each experiment is independent, so the numbers
//! are the same, and saved exactly). Each saved file carries the [`Provenance`] of its values,
//! and collect refuses one computed under another model, scenario, experiments entry or binary.

use crate::measure::error::{io_error, MeasureError};
use crate::measure::campaign::experiments::Experiments;
use crate::measure::model::Model;
use crate::measure::observation::{Observable, Observation};
use crate::measure::campaign::provenance::{exact, plain, Exact, Provenance};
use crate::measure::campaign::runner::{find, group};
use std::path::{Path, PathBuf};

/// One experiment's values, as a job saves them.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
pub struct Saved {
    pub experiment: String,
    pub provenance: Provenance,
    /// `name` or `name@at`, in the data's order.
    pub observables: Vec<String>,
    pub values: Vec<Exact>,
}

/// The observations of experiment `id` (an error when the data have none).
pub fn only(data: &[Observation], id: &str) -> Result<Vec<Observation>, MeasureError> {
    let mine: Vec<Observation> = data.iter().filter(|o| o.experiment == id).cloned().collect();
    if mine.is_empty() {
        let ids: Vec<String> = group(data).into_iter().map(|(i, _)| i).collect();
        return Err(MeasureError::Jobs(format!(
            "--only {id}: the data have no observation of it (they have {})",
            ids.join(", ")
        )));
    }
    Ok(mine)
}

/// Save experiment `id`'s `values` of `data` under `model`.
pub fn save(
    path: &Path,
    model: &Model,
    exps: &Experiments,
    id: &str,
    data: &[Observation],
    values: &[f64],
) -> Result<(), MeasureError> {
    let provenance = Provenance::of(model, exps, find(exps, id)?);
    let s = Saved {
        experiment: id.to_string(),
        provenance,
        observables: data.iter().map(|o| o.observable.to_string()).collect(),
        values: exact(values),
    };
    let text = serde_json::to_string_pretty(&s)?;
    std::fs::write(path, text).map_err(io_error(path))
}

/// Absolute form of a path the jobs will run with from anywhere.
fn absolute(p: &Path) -> Result<PathBuf, MeasureError> {
    std::path::absolute(p).map_err(io_error(p))
}

/// Write `DIR/jobs.txt` (one command per experiment of the data) and `DIR/slurm.sh`; returns
/// the number of jobs.
pub fn plan(
    dir: &Path,
    exe: &Path,
    model: &Path,
    data_path: &Path,
    experiments: &Path,
    data: &[Observation],
) -> Result<usize, MeasureError> {
    std::fs::create_dir_all(dir).map_err(|e| MeasureError::Jobs(format!("--plan {}: {e}", dir.display())))?;
    let dir = absolute(dir)?;
    let quote = |p: &Path| format!("'{}'", p.display().to_string().replace('\'', "'\\''"));
    let (exe, model, data_path, experiments) =
        (absolute(exe)?, absolute(model)?, absolute(data_path)?, absolute(experiments)?);
    let ids: Vec<String> = group(data).into_iter().map(|(id, _)| id).collect();
    let mut jobs = String::new();
    for id in &ids {
        if id.contains(['/', '\'', '\n']) {
            return Err(MeasureError::Jobs(format!("experiment id '{id}' cannot name a job's file")));
        }
        jobs.push_str(&format!(
            "{} compare --model {} --data {} --experiments {} --only '{id}' --save {}\n",
            quote(&exe),
            quote(&model),
            quote(&data_path),
            quote(&experiments),
            quote(&dir.join(format!("{id}.json")))
        ));
    }
    let jobs_path = dir.join("jobs.txt");
    std::fs::write(&jobs_path, jobs).map_err(io_error(&jobs_path))?;
    let slurm = format!(
        "#!/bin/bash\n# One experiment per array task: sbatch {}\n#SBATCH --array=1-{}\n#SBATCH --cpus-per-task=1\nsed \
            -n \"${{SLURM_ARRAY_TASK_ID}}p\" {} | bash\n",
        quote(&dir.join("slurm.sh")),
        ids.len(),
        quote(&jobs_path)
    );
    std::fs::write(dir.join("slurm.sh"), slurm).map_err(io_error(&dir))?;
    Ok(ids.len())
}

/// The values of every observation, in the data's order, from the jobs' saved files in `dir`,
/// each computed under `model` with the experiments as they are now.
pub fn collect(dir: &Path, model: &Model, exps: &Experiments, data: &[Observation]) -> Result<Vec<f64>, MeasureError> {
    let wanted = group(data);
    let per: Vec<Vec<f64>> = wanted
        .iter()
        .map(|(id, obs)| {
            let path = dir.join(format!("{id}.json"));
            let text = std::fs::read_to_string(&path).map_err(|e| {
                MeasureError::Jobs(format!(
                    "experiment '{id}' has no result in {} ({e}): run its job from jobs.txt",
                    dir.display()
                ))
            })?;
            let s: Saved = serde_json::from_str(&text).map_err(|e| {
                MeasureError::Jobs(format!(
                    "experiment '{id}': {} is not a result of this strand ({e}): run its job from jobs.txt again",
                    path.display()
                ))
            })?;
            Provenance::of(model, exps, find(exps, id)?).check(&s.provenance, id, &path).map_err(|e| {
                MeasureError::Jobs(format!("{e}: plan and run the jobs again under the current model and files"))
            })?;
            let want: Vec<String> = obs.iter().map(Observable::to_string).collect();
            if s.experiment != *id || s.observables != want || s.values.len() != want.len() {
                return Err(MeasureError::Jobs(format!(
                    "{}: it holds {} {:?}, the data ask {id} {want:?}: plan and run the jobs again",
                    path.display(),
                    s.experiment,
                    s.observables
                )));
            }
            Ok(plain(&s.values))
        })
        .collect::<Result<_, MeasureError>>()?;
    Ok(crate::measure::campaign::runner::ungroup(data, &wanted, &per))
}
