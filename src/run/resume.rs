//! `--resume`: the newest good checkpoint, checked against the scenario and the toolpath, put
//! back into the simulation; or the summary of a run that had already finished.

use super::previous::previous_run_files;
use super::{RunError, RunOptions, RunSummary};
use crate::checkpoint::{self, state, Checkpoint};
use crate::report::Reporter;
use crate::scenario::Scenario;
use crate::solver::{DtLimit, Simulation};
use std::path::Path;

/// Where a resumed run goes on from: the step its checkpoint was taken in, the outputs written
/// and the run's progress then.
pub(super) struct Resumed {
    pub(super) pending: (f64, DtLimit),
    pub(super) k_out: u64,
    pub(super) progress: state::Progress,
}

/// The newest good checkpoint in `opts.out` to resume from, refused if the scenario changed since
/// (unless `opts.force`).
pub(super) fn resume_checkpoint(sc: &Scenario, opts: &RunOptions) -> Result<Checkpoint, RunError> {
    let ckpt_dir = checkpoint::dir_of(&opts.out);
    let (ck, notes) = checkpoint::newest_valid(&ckpt_dir).map_err(|e| RunError::Resume(no_checkpoint(&opts.out, &e.to_string(), opts)))?;
    for n in notes {
        eprintln!("warning: {n}");
    }
    let diffs = checkpoint::scenario_differences(&ck.header.scenario_text, &sc.source).map_err(|e| RunError::Resume(format!("cannot resume: {e}")))?;
    if !diffs.is_empty() {
        let list = diffs.iter().map(|d| format!("\n    {d}")).collect::<String>();
        if !opts.force {
            return Err(RunError::Resume(format!(
                "cannot resume: the scenario changed since {} was written:{list}\n  \
                 run with --force to resume anyway, or start afresh in another --out folder",
                ck.path.display()
            )));
        }
        eprintln!("warning: resuming with a changed scenario (--force):{list}");
    }
    Ok(ck)
}

/// Put `sim` back to checkpoint `ck`: where the run goes on from, or (as the error side) the
/// summary of a run that had already finished there.
pub(super) fn restore(sim: &mut Simulation, ck: &Checkpoint, sc: &Scenario, opts: &RunOptions, csv_path: &Path) -> Result<Result<Resumed, RunSummary>, RunError> {
    if ck.header.toolpath_hash != state::toolpath_hash(sim) && !opts.force {
        return Err(RunError::Resume(format!(
            "cannot resume: the print's toolpath (its G-code file?) changed since {} was written; run with --force to resume anyway",
            ck.path.display()
        )));
    }
    let pending = state::restore(sim, ck).map_err(|e| RunError::Resume(format!("cannot resume from {}: {e}", ck.path.display())))?;
    if let Some(mut done) = finished_run(sim, ck, pending.0, csv_path, sc.simulation.end_time)? {
        // the finished run's observations and failure, as its own summary gave them
        let progress: state::Progress = serde_json::from_str(&ck.header.progress_json)
            .map_err(|e| RunError::Resume(format!("cannot read {}: run progress does not decode: {e}", ck.path.display())))?;
        if let Some(mut r) = Reporter::new(sc, sim).map_err(RunError::Report)? {
            r.history = progress.observations;
            r.detect_failure();
            done.failure = r.failure;
            done.observations = r.history;
        }
        opts.say(format!(
            "the run in {} has finished (step {}, t = {:.6} s = simulation.end_time): nothing to resume, nothing changed",
            opts.out.display(),
            done.steps,
            done.time
        ));
        return Ok(Err(done));
    }
    let progress = serde_json::from_str(&ck.header.progress_json)
        .map_err(|e| RunError::Resume(format!("cannot resume from {}: run progress does not decode: {e}", ck.path.display())))?;
    opts.say(format!("resuming from {} (step {}, t = {:.6} s, {} particles)", ck.path.display(), sim.step, sim.time, sim.particles.n));
    Ok(Ok(Resumed { pending, k_out: ck.header.outputs, progress }))
}

/// Why `--resume` found nothing to resume from, and the one command that goes on.
fn no_checkpoint(out: &Path, error: &str, opts: &RunOptions) -> String {
    let start_over = format!("{} --overwrite", opts.command);
    let files = previous_run_files(out);
    if files.is_empty() {
        return format!("cannot resume: {} holds no run (no checkpoint, no outputs)\n  start it with: {}", out.display(), opts.command);
    }
    if checkpoint::writer::list(&checkpoint::dir_of(out)).is_empty() && !files.iter().any(|f| f.to_string_lossy().contains(".ckpt")) {
        return format!(
            "cannot resume: the run in {} was stopped before it wrote its first checkpoint ([checkpoint] wall_interval, \
             10 minutes by default), so it cannot be continued\n  start over (deleting its files) with: {start_over}",
            out.display()
        );
    }
    format!("cannot resume: {error}\n  start over (deleting that run's files) with: {start_over}")
}

/// The time of the last row of `globals.csv`, if any.
fn last_output_time(csv: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(csv).ok()?;
    text.lines().skip(1).last()?.split(',').next()?.parse().ok()
}

/// On `--resume`: the summary of a run whose checkpoint is of its last step (a resume must then
/// change nothing), or an error when `end` lies before what the run has computed (resuming
/// would delete those outputs); `None` when there is a run left to do. A checkpoint before the
/// last step resumes, rewriting the outputs after it bit-identically. `sim` holds the
/// checkpoint's state, in the middle of a step of length `dt`.
fn finished_run(sim: &mut Simulation, ck: &Checkpoint, dt: f64, csv: &Path, end: f64) -> Result<Option<RunSummary>, RunError> {
    let step_end = ck.header.time + dt;
    let computed = last_output_time(csv).map_or(step_end, |t| t.max(step_end));
    if computed > end * (1.0 + 1e-9) + 1e-300 {
        return Err(RunError::Resume(format!(
            "cannot resume: simulation.end_time = {end} s lies before what the run has computed (t = {computed:.6} s, \
             checkpoint {}); resuming would delete those outputs. Raise end_time, or start a shorter run in another --out",
            ck.path.display()
        )));
    }
    if step_end < end * (1.0 - 1e-12) {
        return Ok(None);
    }
    sim.finish_step(dt)?;
    Ok(Some(RunSummary {
        steps: sim.step,
        time: sim.time,
        wall_s: 0.0,
        particles: sim.particles.n,
        observations: Vec::new(),
        phase_seconds: [0.0; crate::solver::PHASES.len()],
        awake_particle_steps: 0,
        state_hash: state::current_state_hash(sim),
        resumed_from: Some(ck.path.clone()),
        last_checkpoint: Some(ck.path.clone()),
        failure: None,
        inertia: super::outputs::Inertia { mass_scaling: sim.scenario.simulation.mass_scaling, ..Default::default() },
        external_work: sim.external_work,
    }))
}
