//! An earlier run's files in the output folder: which they are, and when a fresh run may
//! replace them.

use super::{io_err, RunError, RunOptions};
use crate::checkpoint::{self, Checkpoint};
use crate::scenario::Scenario;
use std::path::{Path, PathBuf};

/// Whether `name` is a file a run writes into its output folder. Only these are ever deleted
/// there: the folder may hold the user's own files too.
fn is_output_file(name: &str) -> bool {
    let numbered = |prefix: &str, suffix: &str| name.strip_prefix(prefix).and_then(|r| r.strip_suffix(suffix)).is_some();
    matches!(
        name,
        "globals.csv" | "globals.csv.tmp" | "particles.pvd" | "failed_state.vtu" | "sections.csv" | "profiles.csv" | "layers.csv" | "spread.csv"
    ) || numbered("particles_", ".vtu")
        || numbered("section_x", "mm.png")
}

/// Whether `name` is a file the checkpoint writer leaves in `OUT/checkpoints`.
fn is_checkpoint_file(name: &str) -> bool {
    let step = |n: &str| n.strip_prefix("step_").is_some_and(|r| r.ends_with(".ckpt") || r.ends_with(".ckpt.corrupt"));
    name == checkpoint::writer::LATEST || name == ".LATEST.tmp" || step(name) || name.strip_prefix('.').is_some_and(|n| step(n.trim_end_matches(".tmp")))
}

/// The files of an earlier run in `out`: its outputs and its checkpoints.
pub(super) fn previous_run_files(out: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for (dir, keep) in [(out.to_path_buf(), is_output_file as fn(&str) -> bool), (checkpoint::dir_of(out), is_checkpoint_file)] {
        if let Ok(rd) = std::fs::read_dir(&dir) {
            files.extend(rd.flatten().filter(|e| e.file_type().is_ok_and(|t| t.is_file()) && keep(&e.file_name().to_string_lossy())).map(|e| e.path()));
        }
    }
    files.sort();
    files
}

/// Delete an earlier run's files (and its checkpoint folder once empty); nothing else.
fn remove_previous_run(out: &Path) -> Result<(), RunError> {
    for f in previous_run_files(out) {
        std::fs::remove_file(&f).map_err(io_err(&f))?;
    }
    let _ = std::fs::remove_dir(checkpoint::dir_of(out)); // fails, harmlessly, if not empty
    Ok(())
}

/// A fresh run replaces an earlier run's files only when that run is known to be the same
/// scenario, finished: otherwise they could be days of work, or another scenario's results that
/// its new files would silently mix with. `--overwrite` deletes them first, whatever they are.
pub(super) fn clear_previous_run(out: &Path, sc: &Scenario, opts: &RunOptions) -> Result<(), RunError> {
    if previous_run_files(out).is_empty() {
        return Ok(());
    }
    if opts.overwrite {
        return remove_previous_run(out);
    }
    let dir = checkpoint::dir_of(out);
    let start_over = format!("{} --overwrite", opts.command);
    let newest = checkpoint::writer::list(&dir).iter().rev().find_map(|(_, p)| Checkpoint::open(p).ok());
    let Some(ck) = newest else {
        return Err(RunError::Resume(format!(
            "{} holds the outputs of a run that left no checkpoint: it was stopped before its first one \
             ([checkpoint] wall_interval, 10 minutes by default) or ran with checkpoints disabled, so \
             nothing there can be resumed\n  start over (deleting that run's files) with: {start_over}\n  \
             or choose another --out",
            out.display()
        )));
    };
    let then = Scenario::parse(&ck.header.scenario_text).ok();
    let end = then.as_ref().map_or(f64::INFINITY, |s| s.simulation.end_time);
    // the checkpoint is inside a step: the run had finished if that step reaches the end
    if ck.header.time + ck.header.dt < end * (1.0 - 1e-12) {
        return Err(RunError::Resume(format!(
            "{} holds an unfinished run (step {}, t = {:.6} s of {end} s); continue it with --resume, \
             start over with --overwrite (deletes its files), or choose another --out",
            dir.display(),
            ck.header.step,
            ck.header.time
        )));
    }
    let diffs = checkpoint::scenario_differences(&ck.header.scenario_text, &sc.source).unwrap_or_else(|e| vec![e.to_string()]);
    if !diffs.is_empty() {
        let list = diffs.iter().take(5).map(|d| format!("\n    {d}")).collect::<String>();
        return Err(RunError::Resume(format!(
            "{} holds a finished run of another scenario (t = {end} s), which this run would overwrite; it differs in:{list}\n  \
             choose another --out, or start over (deleting that run's files) with: {start_over}",
            out.display()
        )));
    }
    let lost = then.as_ref().map_or(Vec::new(), |then| not_written_again(then, sc));
    if !lost.is_empty() {
        return Err(RunError::Resume(format!(
            "{} holds a finished run of this scenario (t = {end} s) that this run would not write again: {}\n  \
             choose another --out, or start over (deleting that run's files) with: {start_over}",
            out.display(),
            lost.join("; ")
        )));
    }
    remove_previous_run(out)
}

/// What of a finished run of the same scenario (`then`) a fresh run of `now` would delete and
/// not write again (the keys scenario_differences leaves free: the end time, whether snapshots
/// and checkpoints are written). A run that writes at least as much replaces it with the same
/// results; one that writes less would lose them silently.
fn not_written_again(then: &Scenario, now: &Scenario) -> Vec<String> {
    let mut lost = Vec::new();
    let (t0, t1) = (then.simulation.end_time, now.simulation.end_time);
    if t1 < t0 {
        lost.push(format!("it ends at simulation.end_time = {t1} s, before that run's {t0} s, so the outputs and checkpoints after {t1} s would be lost"));
    }
    if then.output.vtu && !now.output.vtu {
        lost.push("output.vtu = false, so that run's VTU snapshots and particles.pvd would be lost".to_string());
    }
    if then.checkpoint.enabled && !now.checkpoint.enabled {
        lost.push("checkpoint.enabled = false, so that run's checkpoints would be lost".to_string());
    }
    lost
}
