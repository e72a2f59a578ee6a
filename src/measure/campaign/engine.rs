//! Where calibrate's and diagnose's per-experiment evaluations run: in this process (`local`,
//! experiments side by side on threads), or as jobs of an existing scheduler — GNU parallel, a
//! Slurm job array, HyperQueue, or any command given as a template. The unit of work is one
//! experiment's values, and their Jacobian when the fit needs it ([`sensitivity::one`]); each
//! evaluation of a campaign is planned as job files in the engine's folder, run elsewhere by
//! `strand evaluate JOB --out RESULT`, and collected.
//!
//! The folder:
//! - `jobs/KEY.json`: what to compute: the model (as strand writes it), the experiment's entry
//!   and the folder its paths are relative to, the observables, the parameters differentiated,
//!   and the [`Provenance`] all this has at planning;
//! - `results/KEY.json`: what the job computed (the values, or the model's own failure, such as
//!   a material that will not build) with its provenance;
//! - `logs/KEY.log`: the job's output, appended on every attempt;
//! - `batches/NNNN.txt`: one submission's commands, a line per job (GNU parallel's input), and
//!   `NNNN.sh`, a job array's task (runs line `$1`, `$SLURM_ARRAY_TASK_ID` or `$HQ_TASK_ID`);
//!   `NNNN.log` the scheduler's own output.
//!
//! KEY is the experiment's id and a hash of everything its result depends on. A result already
//! in the folder with that provenance is collected instead of computed again, so a campaign
//! stopped by a failed job loses nothing: run again, it submits only what is missing. The job
//! recomputes the provenance from the files it reads and refuses to run if they changed since
//! planning; the collector checks the result's provenance again.
//!
//! Results are bit-identical to a local run: the job runs the same function on the same model
//! (the model file strand writes, whose numbers read back to the same bits, checked by the
//! model's hash), every number is saved exactly ([`Exact`]), and a run's result does not depend
//! on its thread count.

use crate::measure::error::{io_error, MeasureError};
use super::experiments::{Experiment, Experiments};
use crate::measure::model::Model;
use crate::measure::observation::{Observable, Observation};
use super::provenance::{self, exact, plain, Exact, Provenance};
use super::runner::{find, group, Applied, Jobs};
use super::gather::{Gather, Request, Submitted};
use super::sensitivity::{self, Differences, Known, Sensitivity, Valued};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The preset schedulers and their command templates: GNU parallel on this machine, a Slurm job
/// array, a HyperQueue task array (docs/distributed.md).
pub const PRESETS: &[(&str, &str)] = &[
    ("parallel", "parallel --will-cite < {jobs}"),
    ("slurm", "sbatch --wait --job-name=strand --array=1-{n} --output={dir}/batches/slurm-%A_%a.out {task}"),
    ("hq", "hq submit --wait --name=strand --cwd={dir}/batches --array=1-{n} {task}"),
];

/// Where evaluations run.
#[derive(Clone, Debug, Default)]
pub enum Engine {
    /// In this process, `jobs` experiments at a time.
    #[default]
    Local,
    Scheduler(Scheduler),
}

/// An existing scheduler, driven by a command template run with `bash -c` once per evaluation
/// of a campaign. In the template `{jobs}` is the file of commands (a line per job), `{task}`
/// the job array's task script, `{n}` the number of jobs and `{dir}` the engine's folder, paths
/// shell-quoted; the command returns once every job has finished (or failed). Evaluations made
/// side by side ([`Engine::side_by_side`]) are submitted together (`gather.rs`).
#[derive(Clone, Debug)]
pub struct Scheduler {
    pub template: String,
    pub dir: PathBuf,
    /// The strand binary the jobs run.
    pub exe: PathBuf,
    /// Threads per job (None: all the job is given).
    pub threads: Option<usize>,
    pub gather: Arc<Gather>,
}

/// The model's answer for a campaign: the values (and Jacobian), or why the model cannot give
/// them (calibrate rejects such a trial step). Distinct from the engine failing to run a job.
pub type Answer = Result<Sensitivity, MeasureError>;

impl Engine {
    /// `local`, a preset's name ([`PRESETS`]) or a command template, with the folder the jobs
    /// go in (created).
    pub fn new(name: &str, dir: Option<&Path>, exe: &Path, threads: Option<usize>) -> Result<Engine, MeasureError> {
        if name == "local" {
            return match dir {
                None => Ok(Engine::Local),
                Some(d) => Err(MeasureError::Engine(format!("--engine-dir {} is the folder of a scheduler's jobs; the \
                    local engine runs in this process (name a scheduler with --engine)", d.display()))),
            };
        }
        let template = match PRESETS.iter().find(|(n, _)| *n == name) {
            Some((_, t)) => t.to_string(),
            None if name.contains("{jobs}") || name.contains("{task}") => name.to_string(),
            None => {
                let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
                return Err(MeasureError::Engine(format!("--engine {name}: not an engine; give local, {}, or a command \
                    template naming {{jobs}} (the file of job commands) or {{task}} (a job array's task \
                    script)", names.join(", "))));
            }
        };
        let dir = dir.ok_or_else(|| MeasureError::Engine(format!("--engine {name} needs --engine-dir DIR, a folder \
            every job can read and write (the results are kept there)")))?;
        for sub in ["jobs", "results", "logs", "batches"] {
            std::fs::create_dir_all(dir.join(sub))
                .map_err(|e| MeasureError::Io(e).within(format!("--engine-dir {}", dir.display())))?;
        }
        let dir = std::path::absolute(dir)
            .map_err(|e| MeasureError::Io(e).within(format!("--engine-dir {}", dir.display())))?;
        let exe = std::path::absolute(exe).map_err(io_error(exe))?;
        Ok(Engine::Scheduler(Scheduler { template, dir, exe, threads, gather: Arc::default() }))
    }

    /// `f(0) .. f(n - 1)`, tasks that may evaluate through this engine, and their results in
    /// order. A scheduler runs them side by side and submits their evaluations together
    /// (`gather.rs`); here they run one after another, each with all the jobs (side by side they
    /// would share the cores and the memory budget each experiment is planned within).
    pub fn side_by_side<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
        match self {
            Engine::Local => (0..n).map(f).collect(),
            Engine::Scheduler(s) => s.gather.side_by_side(n, f),
        }
    }

    /// The values of every observation under `model`, with their gradients in `names` when
    /// given, at a model whose values are known where `at` gives them (as
    /// [`sensitivity::evaluate`] takes them). `Err` is the engine failing (a job that left no
    /// result, named with its log); `Ok(Err)` the model's own failure, as a local run gives it.
    /// Here the experiments run as `jobs` says, and those differenced throughout take the known
    /// values instead of running them again; a scheduler runs them all at once, computes the
    /// values again (to the same bits) and counts none of them as it goes.
    pub fn evaluate(
        &self,
        jobs: Jobs,
        model: &Model,
        (data, exps): (&[Observation], &Experiments),
        (names, at): (Option<&[String]>, Known),
    ) -> Result<Answer, MeasureError> {
        match self {
            Engine::Local => Ok(sensitivity::evaluate(model, data, exps, (names, jobs), at)),
            Engine::Scheduler(s) => s.sensitivity(model, data, exps, names, match at {
                Some((_, Differences::Forward(scatter))) => Some(scatter),
                _ => None,
            }),
        }
    }
}

/// One job: what `strand evaluate` computes.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Job {
    pub provenance: Provenance,
    /// The model file ([`Model::to_toml`]).
    pub model: String,
    /// The experiment's entry (TOML) and the folder its scenario or protocol is relative to.
    pub experiment: String,
    pub base_dir: PathBuf,
    /// `name` or `name@at`.
    pub observables: Vec<String>,
    /// Parameters differentiated; none for values only.
    pub names: Option<Vec<String>>,
    /// The model's units ([`Model::unit`]), which its file does not hold: they set the
    /// differences' steps.
    pub units: std::collections::BTreeMap<String, f64>,
    pub threads: Option<usize>,
    /// The values' scatter, one per observable, where the differences are one-sided
    /// ([`Differences::Forward`]); absent for central ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scatter: Option<Vec<Exact>>,
}

/// What a job computed.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Computed {
    pub experiment: String,
    pub observables: Vec<String>,
    pub names: Option<Vec<String>>,
    pub provenance: Provenance,
    pub outcome: Outcome,
}

#[derive(serde::Serialize, serde::Deserialize)]
pub enum Outcome {
    /// A value per observable and, with names, a gradient row per observable; the scatter of
    /// each ([`Sensitivity::scatter`], [`Sensitivity::jacobian_scatter`]).
    Values {
        values: Vec<Exact>,
        jacobian: Option<Vec<Vec<Exact>>>,
        scatter: Vec<Exact>,
        jacobian_scatter: Option<Vec<Vec<Exact>>>,
    },
    /// The model's failure, as the local evaluation reports it.
    Failed(String),
}

impl Job {
    /// The file stem of this job and of its result and log: the experiment id (made safe for a
    /// file name) and a hash of what the result depends on.
    fn key(&self, id: &str) -> String {
        let safe: String =
            id.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
        let what = match &self.scatter {
            None => serde_json::to_string(&(&self.provenance, &self.observables, &self.names, &self.units)),
            Some(s) => serde_json::to_string(&(&self.provenance, &self.observables, &self.names, &self.units, s)),
        }
        .expect("serialises");
        format!("{safe}-{}", &provenance::hash(&what)[..16])
    }
}

/// `'text'` for bash.
fn quote(p: &Path) -> String {
    format!("'{}'", p.display().to_string().replace('\'', "'\\''"))
}

/// Write `text` to `path` whole or not at all (a job killed mid-write leaves no result).
fn write_atomic(path: &Path, text: &str) -> Result<(), MeasureError> {
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, text).and_then(|_| std::fs::rename(&tmp, path)).map_err(io_error(path))
}

/// The last lines of a log, for an error message; `none` when it is empty or absent.
fn tail(path: &Path, none: &str) -> String {
    match std::fs::read_to_string(path) {
        Ok(t) if !t.trim().is_empty() => {
            let lines: Vec<&str> = t.trim_end().lines().filter(|l| !l.trim().is_empty()).collect();
            lines[lines.len().saturating_sub(6)..].iter().map(|l| format!("\n      | {l}")).collect()
        }
        _ => format!(" ({none})"),
    }
}

impl Scheduler {
    /// As [`Engine::evaluate`]; `scatter` (in the data's order) makes the differences
    /// one-sided ([`Differences::Forward`]).
    fn sensitivity(
        &self,
        model: &Model,
        data: &[Observation],
        exps: &Experiments,
        names: Option<&[String]>,
        scatter: Option<&[f64]>,
    ) -> Result<Answer, MeasureError> {
        let wanted = group(data);
        let scatter = scatter.map(|s| sensitivity::regroup(data, &wanted, s));
        // each experiment: its answer when known (collected, or the experiment is not in the
        // file), else the job that computes it
        let mut answers: Vec<Option<Result<Vec<Valued>, MeasureError>>> = Vec::with_capacity(wanted.len());
        let mut pending: Vec<(usize, String, Job)> = Vec::new();
        let mut collected = 0;
        for (k, (id, obs)) in wanted.iter().enumerate() {
            let x = match find(exps, id) {
                Ok(x) => x,
                Err(e) => {
                    answers.push(Some(Err(e)));
                    continue;
                }
            };
            let job = self.job(model, exps, x, obs, names, scatter.as_ref().map(|s| &s[k][..]))?;
            let key = job.key(id);
            let result = self.dir.join("results").join(format!("{key}.json"));
            if result.exists() {
                answers.push(Some(read_result(&result, &job, id)?));
                collected += 1;
                continue;
            }
            let text = serde_json::to_string_pretty(&job)?;
            write_atomic(&self.dir.join("jobs").join(format!("{key}.json")), &text)?;
            answers.push(None);
            pending.push((k, key, job));
        }
        if !pending.is_empty() {
            self.submit(&wanted, &pending, collected)?;
            for (k, key, job) in &pending {
                answers[*k] =
                    Some(read_result(&self.dir.join("results").join(format!("{key}.json")), job, &wanted[*k].0)?);
            }
        }
        let per: Vec<Vec<Valued>> =
            match answers.into_iter().map(|a| a.expect("every experiment answered")).collect::<Result<_, _>>() {
                Ok(per) => per,
                Err(e) => return Ok(Err(e)),
            };
        Ok(Ok(sensitivity::assemble(data, &wanted, &per, names)))
    }

    fn job(
        &self,
        model: &Model,
        exps: &Experiments,
        x: &Experiment,
        obs: &[Observable],
        names: Option<&[String]>,
        scatter: Option<&[f64]>,
    ) -> Result<Job, MeasureError> {
        let model_text = model.to_toml();
        Ok(Job {
            provenance: Provenance::of_applied(&model_text, Applied::new(model, x).as_ref(), exps, x),
            model: model_text,
            experiment: toml::to_string(x).map_err(|e| MeasureError::from(e).within(format!("experiment '{}'", x.id)))?,
            // an experiments file named without a folder sits in the current one
            base_dir: std::path::absolute(Path::new(".").join(&exps.base_dir)).map_err(io_error(&exps.base_dir))?,
            observables: obs.iter().map(Observable::to_string).collect(),
            names: names.map(<[String]>::to_vec),
            units: model.units.clone(),
            threads: self.threads,
            scatter: scatter.map(exact),
        })
    }

    /// Submit the `pending` jobs, with the evaluations made beside this one (`gather.rs`); every
    /// job must leave its result, or the error names each one missing with its log.
    fn submit(
        &self,
        wanted: &[(String, Vec<Observable>)],
        pending: &[(usize, String, Job)],
        collected: usize,
    ) -> Result<(), MeasureError> {
        let path = |sub: &str, key: &str, ext: &str| self.dir.join(sub).join(format!("{key}.{ext}"));
        let lines = pending
            .iter()
            .map(|(_, key, _)| {
                format!(
                    "{} evaluate {} --out {} >> {} 2>&1",
                    quote(&self.exe),
                    quote(&path("jobs", key, "json")),
                    quote(&path("results", key, "json")),
                    quote(&path("logs", key, "log"))
                )
            })
            .collect();
        let ran = self
            .gather
            .submit(Request { lines, collected }, |lines, collected| self.run_batch(lines, collected))
            .map_err(MeasureError::Engine)?;
        let missing: Vec<String> = pending
            .iter()
            .filter(|(_, key, _)| !path("results", key, "json").exists())
            .map(|(k, key, _)| {
                format!(
                    "  experiment '{}': no result; job {}, log {}{}",
                    wanted[*k].0,
                    path("jobs", key, "json").display(),
                    path("logs", key, "log").display(),
                    tail(&path("logs", key, "log"), "empty: the job did not start")
                )
            })
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        Err(MeasureError::Engine(format!(
            "the engine's command {} and {} of {} jobs left no result:\n{}\n  the command: {}\n  its output: \
                {}{}\nThe results computed are kept in {}: run the same command again to compute only what is missing.",
            ran.status,
            missing.len(),
            pending.len(),
            missing.join("\n"),
            ran.command,
            ran.log.display(),
            tail(&ran.log, "empty"),
            self.dir.join("results").display()
        )))
    }

    /// Write a batch of job command `lines` and run the scheduler's command on it; `collected`
    /// results of the evaluations in it were collected from earlier runs. The error is the
    /// command's failing to start.
    fn run_batch(&self, lines: &[String], collected: usize) -> Result<Submitted, String> {
        let batches = self.dir.join("batches");
        let mut number = 1;
        let lines_path = loop {
            let p = batches.join(format!("{number:04}.txt"));
            match std::fs::OpenOptions::new().write(true).create_new(true).open(&p) {
                Ok(_) => break p,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => number += 1,
                Err(e) => return Err(io_error(&p)(e).to_string()),
            }
        };
        let text: String = lines.iter().map(|l| format!("{l}\n")).collect();
        std::fs::write(&lines_path, &text).map_err(|e| io_error(&lines_path)(e).to_string())?;
        let task = lines_path.with_extension("sh");
        let script = format!(
            "#!/bin/bash\n# Job K of batch {number:04}: bash {0} K, or a job array's task (K from the scheduler)\n\
                k=${{1:-${{SLURM_ARRAY_TASK_ID:-${{HQ_TASK_ID:?no task index: give it as the first argument}}}}}}\nsed \
                -n \"${{k}}p\" {1} | bash\n",
            quote(&task),
            quote(&lines_path)
        );
        std::fs::write(&task, script).map_err(|e| io_error(&task)(e).to_string())?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&task, std::fs::Permissions::from_mode(0o755))
                .map_err(|e| io_error(&task)(e).to_string())?;
        }
        let command = self
            .template
            .replace("{jobs}", &quote(&lines_path))
            .replace("{task}", &quote(&task))
            .replace("{n}", &lines.len().to_string())
            .replace("{dir}", &quote(&self.dir));
        let log = lines_path.with_extension("log");
        let out = std::fs::File::create(&log).map_err(|e| io_error(&log)(e).to_string())?;
        let err = out.try_clone().map_err(|e| MeasureError::Io(e).to_string())?;
        eprintln!(
            "engine: batch {number:04}, {} jobs submitted ({collected} collected from earlier runs): {command}",
            lines.len()
        );
        let status = std::process::Command::new("bash")
            .arg("-c")
            .arg(&command)
            .stdin(std::process::Stdio::null())
            .stdout(out)
            .stderr(err)
            .status()
            .map_err(|source| MeasureError::EngineStart { command: command.clone(), source }.to_string())?;
        let status = status.code().map_or("was stopped by a signal".to_string(), |c| format!("exited with status {c}"));
        Ok(Submitted { number, command, status, log })
    }
}

/// A result file of `job`, checked against it: the model's answer, or an error naming
/// experiment `id` and what differs.
fn read_result(path: &Path, job: &Job, id: &str) -> Result<Result<Vec<Valued>, MeasureError>, MeasureError> {
    let text = std::fs::read_to_string(path).map_err(|e| io_error(path)(e).within(format!("experiment '{id}'")))?;
    let c: Computed = serde_json::from_str(&text).map_err(|e| {
        MeasureError::Engine(format!(
            "experiment '{id}': {} is not a result of this strand ({e}): delete it to compute it again",
            path.display()
        ))
    })?;
    job.provenance.check(&c.provenance, id, path)?;
    if c.experiment != id || c.observables != job.observables || c.names != job.names {
        return Err(MeasureError::Engine(format!("experiment '{id}': {} holds {} {:?} differentiated in {:?}, the \
            campaign asks {:?} in {:?}: delete it to compute it \
            again", path.display(), c.experiment, c.observables, c.names, job.observables, job.names)));
    }
    Ok(match c.outcome {
        Outcome::Failed(e) => Err(MeasureError::InJob(e)),
        Outcome::Values { values, jacobian, scatter, jacobian_scatter } => {
            let n = job.observables.len();
            let rows = jacobian.map(|j| j.iter().map(|r| plain(r)).collect::<Vec<_>>());
            let row_scatter = jacobian_scatter.map(|j| j.iter().map(|r| plain(r)).collect::<Vec<_>>());
            let shaped = |r: &Option<Vec<Vec<f64>>>| {
                r.as_ref().is_none_or(|r| r.len() == n) && r.is_some() == job.names.is_some()
            };
            if values.len() != n || scatter.len() != n || !shaped(&rows) || !shaped(&row_scatter) {
                return Err(MeasureError::Engine(format!(
                    "experiment '{id}': {} holds {} values for {n} observables: delete it to compute it again",
                    path.display(),
                    values.len()
                )));
            }
            let (mut rows, mut row_scatter) = (rows.map(Vec::into_iter), row_scatter.map(Vec::into_iter));
            Ok(plain(&values)
                .into_iter()
                .zip(plain(&scatter))
                .map(|(value, scatter)| Valued {
                    value,
                    gradient: rows.as_mut().and_then(Iterator::next),
                    scatter,
                    gradient_scatter: row_scatter.as_mut().and_then(Iterator::next),
                })
                .collect())
        }
    })
}

/// The model of a job: exactly the numbers written, without the checks a model file read by a
/// user gets (a trial model that will not build must fail in the evaluation, as it does
/// locally, not here), with the units of the model it was planned from.
fn job_model(job: &Job) -> Result<Model, MeasureError> {
    let t: toml::Table = job.model.parse().map_err(|e| MeasureError::from(e).within("the job's model"))?;
    let mut model = Model::from_table_as_written(&t).map_err(|e| e.within("the job's model"))?;
    model.units = job.units.clone();
    Ok(model)
}

/// `strand evaluate JOB --out RESULT`: compute one planned job and save its result; the line
/// to print.
pub fn evaluate(job_path: &Path, out: &Path) -> Result<String, MeasureError> {
    let text = std::fs::read_to_string(job_path).map_err(io_error(job_path))?;
    let job: Job = serde_json::from_str(&text)
        .map_err(|e| MeasureError::Engine(format!("{}: not a job of this strand ({e})", job_path.display())))?;
    let x: Experiment = toml::from_str(&job.experiment)
        .map_err(|e| MeasureError::Engine(format!("{}: the experiment: {}", job_path.display(), e.message())))?;
    let id = x.id.clone();
    let exps = Experiments { experiment: vec![x], base_dir: job.base_dir.clone(), resolution: None };
    let model = job_model(&job).map_err(|e| e.within(job_path.display()))?;
    // the files as they are now must be those the job was planned with
    Provenance::of(&model, &exps, &exps.experiment[0]).check(&job.provenance, &id, job_path).map_err(|e| {
        MeasureError::Engine(format!(
            "{e}: the job was planned with other files or another strand; run the campaign again to plan it anew"
        ))
    })?;
    // the experiment's memory planned before it runs: over the budget is the job's error, not a result
    super::preflight::plan_experiments(&model, &exps, [id.as_str()])?;
    let obs: Vec<Observable> = job.observables.iter().map(|o| Observable::parse(o)).collect::<Result<_, _>>()?;
    if job.scatter.as_ref().is_some_and(|s| s.len() != obs.len()) {
        return Err(MeasureError::Engine(format!(
            "{}: {} scatters for {} observables: not a job of this strand",
            job_path.display(),
            job.scatter.as_ref().map_or(0, Vec::len),
            obs.len()
        )));
    }
    let scatter = job.scatter.as_ref().map(|s| plain(s));
    let outcome =
        match sensitivity::one(&model, &exps, &id, &obs, (job.names.as_deref(), job.threads), scatter.as_deref()) {
            Ok(per) => Outcome::Values {
                values: exact(&per.iter().map(|v| v.value).collect::<Vec<_>>()),
                jacobian: job
                    .names
                    .as_ref()
                    .map(|_| per.iter().map(|v| exact(v.gradient.as_deref().unwrap_or_default())).collect()),
                scatter: exact(&per.iter().map(|v| v.scatter).collect::<Vec<_>>()),
                jacobian_scatter: job
                    .names
                    .as_ref()
                    .map(|_| per.iter().map(|v| exact(v.gradient_scatter.as_deref().unwrap_or_default())).collect()),
            },
            Err(e) => Outcome::Failed(e.to_string()),
        };
    let line = match &outcome {
        Outcome::Values { values, jacobian, .. } => format!(
            "experiment '{id}': {} values{} saved to {}",
            values.len(),
            if jacobian.is_some() { " and their gradients" } else { "" },
            out.display()
        ),
        Outcome::Failed(e) => {
            format!("experiment '{id}': the model fails here ({e}); saved as its result to {}", out.display())
        }
    };
    let c = Computed {
        experiment: id,
        observables: job.observables,
        names: job.names,
        provenance: job.provenance,
        outcome,
    };
    write_atomic(out, &serde_json::to_string_pretty(&c)?)?;
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: &str =
        "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";
    const EXPS: &str = "[[experiment]]\nid = \"flow\"\nobserve = [\"stress@20\"]\n[experiment.protocol]\n\
        [[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0]\nhold = 0.5\n";

    /// A job's model keeps the units of the model it was planned from, which its file does not
    /// hold, so a job differences a parameter fitted towards 0 over the step a local run takes;
    /// and the units are part of the job's key.
    #[test]
    fn a_job_carries_the_models_units() {
        let mut model = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        model.set("material.viscosity", 1e-5).unwrap();
        let exps: Experiments = toml::from_str(EXPS).unwrap();
        let s = Scheduler {
            template: "true".into(),
            dir: PathBuf::from("unused"),
            exe: PathBuf::from("strand"),
            threads: None,
            gather: Arc::default(),
        };
        let names = vec!["material.viscosity".to_string()];
        let job = s
            .job(&model, &exps, &exps.experiment[0], &[Observable::parse("stress@20").unwrap()], Some(&names), None)
            .unwrap();
        let read: Job = serde_json::from_str(&serde_json::to_string(&job).unwrap()).unwrap();
        let there = job_model(&read).unwrap();
        assert_eq!(there.get("material.viscosity").unwrap(), 1e-5);
        assert_eq!(there.unit("material.viscosity").unwrap(), 7.5);
        assert_eq!(there.unit("material.viscosity").unwrap(), model.unit("material.viscosity").unwrap());
        // a model read from the job's file alone would take its written value as the unit
        let written = Model::from_table_as_written(&read.model.parse().unwrap()).unwrap();
        assert_eq!(written.unit("material.viscosity").unwrap(), 1e-5);
        let mut other = read;
        other.units.insert("viscosity".into(), 1.0);
        assert_ne!(other.key("flow"), job.key("flow"));
        // one-sided differences carry the values' scatter, exactly, in the job and its key
        let forward = s
            .job(
                &model,
                &exps,
                &exps.experiment[0],
                &[Observable::parse("stress@20").unwrap()],
                Some(&names),
                Some(&[0.1 + 0.2]),
            )
            .unwrap();
        let read: Job = serde_json::from_str(&serde_json::to_string(&forward).unwrap()).unwrap();
        assert_eq!(read.scatter.as_deref().map(plain), Some(vec![0.1 + 0.2]));
        assert_ne!(forward.key("flow"), job.key("flow"));
    }

    /// Issue 53: a job whose experiment is over the memory budget is refused by `evaluate`
    /// before it allocates, naming the experiment, and leaves no result to be collected.
    #[test]
    fn evaluate_refuses_a_job_over_the_budget_before_it_runs() {
        let dir = tempfile::tempdir().unwrap();
        let slump = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/slump/slump.toml");
        std::fs::copy(&slump, dir.path().join("slump.toml")).unwrap();
        let text = "[[experiment]]\nid = \"SF\"\nscenario = \"slump.toml\"\nobserve = [\"spread\"]\n\
                    set = { \"simulation.dx\" = 1e-5, \"simulation.end_time\" = 0.1 }\n";
        let mut exps: Experiments = toml::from_str(text).unwrap();
        exps.base_dir = dir.path().to_path_buf();
        let model = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let s = Scheduler {
            template: "true".into(),
            dir: dir.path().join("jobs"),
            exe: PathBuf::from("strand"),
            threads: None,
            gather: Arc::default(),
        };
        let job =
            s.job(&model, &exps, &exps.experiment[0], &[Observable::parse("spread").unwrap()], None, None).unwrap();
        let (job_path, out) = (dir.path().join("SF.json"), dir.path().join("SF.result.json"));
        std::fs::write(&job_path, serde_json::to_string(&job).unwrap()).unwrap();
        let clock = std::time::Instant::now();
        let err = evaluate(&job_path, &out).unwrap_err().to_string();
        assert!(clock.elapsed() < std::time::Duration::from_secs(5), "took {:?}", clock.elapsed());
        assert!(
            err.contains("over the budget of") && err.contains("need at least") && err.contains("experiment 'SF'"),
            "{err}"
        );
        assert!(!out.exists(), "a refused job must leave no result");
        // the same job at the fixture's own cell size is planned and passes the refusal
        let fits: Experiments = toml::from_str(&text.replace("1e-5", "0.02")).unwrap();
        let fits = Experiments { base_dir: dir.path().to_path_buf(), ..fits };
        assert!(super::super::preflight::plan_experiments(&model, &fits, ["SF"]).is_ok());
    }
}
