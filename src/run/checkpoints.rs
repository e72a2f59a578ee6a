//! The checkpoint stage of a run: when a checkpoint is due, queueing and staging it in the
//! middle of a step, and what the writer thread reports back.

use super::outputs::Outputs;
use super::{io_err, RunError};
use crate::checkpoint::{self, state, writer::CheckpointWriter, writer::Event, writer::Staged};
use crate::memory::{fmt_bytes, Backing, Pool};
use crate::scenario::Scenario;
use crate::solver::{DtLimit, SimError, Simulation};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The checkpoint stage as the run loop drives it. Checkpoints are taken in the middle of a
/// step (see `checkpoint/state.rs`), so one the run needs after a step (at its end, or when the
/// disk budget refuses a snapshot) is the middle of that step, staged while it was there.
pub(super) struct Checkpoints {
    writer: CheckpointWriter,
    cfg: checkpoint::CheckpointConfig,
    last_wall: Instant,
    last_step: u64,
    /// Newest checkpoint known to be on disk, and its step.
    pub(super) last_good: Option<(PathBuf, u64)>,
    resume: String,
    /// The middle of the current step when it ends on an output (or the end).
    staged: Option<Staged>,
    /// Whether a checkpoint was queued in the middle of the current step.
    pub(super) this_step: bool,
}

impl Checkpoints {
    /// The checkpoint stage of a run in `out`, its writer thread started with a staging buffer
    /// of `staging_bytes`.
    pub(super) fn open(sc: &Scenario, sim: &Simulation, out: &Path, disk_limit: Option<u64>, staging_bytes: usize, last_good: Option<(PathBuf, u64)>, resume: String) -> Result<Self, RunError> {
        let ckpt_dir = checkpoint::dir_of(out);
        let backing = Backing { dir: sc.memory.dir.clone() };
        let staging = Pool::<u8>::new("checkpoint.staging", staging_bytes, &backing).map_err(SimError::from)?;
        let place = checkpoint::writer::Placement { dir: ckpt_dir.clone(), keep: sc.checkpoint.keep, out: out.to_path_buf(), disk_limit };
        let writer = CheckpointWriter::spawn(place, staging).map_err(io_err(&ckpt_dir))?;
        Ok(Checkpoints {
            writer,
            cfg: sc.checkpoint.clone(),
            last_wall: Instant::now(),
            last_step: sim.step,
            last_good,
            resume,
            staged: None,
            this_step: false,
        })
    }

    pub(super) fn due(&self, sim: &Simulation) -> bool {
        self.cfg.step_interval.is_some_and(|k| sim.step >= self.last_step + k)
            || self.last_wall.elapsed().as_secs_f64() >= self.cfg.wall_interval
    }

    /// Queue a checkpoint of `sim`, in the middle of a step of length `dt`.
    pub(super) fn submit(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
        let header = state::header(sim, dt, limit, out.k_out, &out.progress(sim), Vec::new());
        self.writer.submit(header, &state::sections(sim))?;
        self.last_wall = Instant::now();
        self.last_step = sim.step;
        self.this_step = true;
        Ok(())
    }

    /// Copy the middle of a step ending on an output, in case the run stops after the output.
    pub(super) fn stage(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
        let header = state::header(sim, dt, limit, out.k_out, &out.progress(sim), Vec::new());
        self.staged = Some(self.writer.stage(header, &state::sections(sim))?);
        Ok(())
    }

    /// After the step: write the staged middle of it (unless one was queued there anyway) and
    /// wait until every checkpoint is on disk.
    pub(super) fn write_staged(&mut self) -> Result<(), RunError> {
        if let Some(s) = self.staged.take() {
            if self.this_step {
                self.writer.release(s);
            } else {
                self.last_step = s.step();
                self.writer.submit_staged(s)?;
            }
        }
        self.drain()
    }

    pub(super) fn release_staged(&mut self) {
        if let Some(s) = self.staged.take() {
            self.writer.release(s);
        }
    }

    /// Write a checkpoint of `sim` (in the middle of a step) and wait until it (and any before
    /// it) is on disk.
    pub(super) fn write_now(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
        self.submit(sim, dt, limit, out)?;
        self.drain()
    }

    fn handle(&mut self, ev: Event) -> Result<(), RunError> {
        match ev {
            Event::Written { path, step, .. } => {
                self.last_good = Some((path, step));
                Ok(())
            }
            Event::NoRoom { step, needed, used, limit } => Err(RunError::DiskBudget(format!(
                "no room for the checkpoint of step {step} ({}): the output folder holds {} of its {} budget \
                 with every older checkpoint but the newest removed; raise [output] disk_budget",
                fmt_bytes(needed),
                fmt_bytes(used),
                fmt_bytes(limit)
            ))),
            Event::Failed { step, error } => Err(RunError::CheckpointWrite { step, source: error }),
        }
    }

    pub(super) fn poll(&mut self) -> Result<(), RunError> {
        while let Some(ev) = self.writer.poll() {
            self.handle(ev)?;
        }
        Ok(())
    }

    /// Wait for the writer; the first failure, if any.
    pub(super) fn drain(&mut self) -> Result<(), RunError> {
        let mut first = Ok(());
        for ev in self.writer.drain() {
            let r = self.handle(ev);
            if first.is_ok() {
                first = r;
            }
        }
        first
    }

    /// What is on disk to go on from, for a message.
    pub(super) fn note(&self) -> String {
        match &self.last_good {
            Some((p, step)) => format!("the last good checkpoint is {} (step {step}); resume with: {}", p.display(), self.resume),
            None => "no checkpoint was written by this run".to_string(),
        }
    }
}

/// Add the checkpoint staging buffer a run maps (when its scenario writes checkpoints) to
/// `sim`'s memory plan, and check the plan against the budget again.
pub fn plan_checkpoint_staging(sim: &mut Simulation) -> Result<(), SimError> {
    if sim.scenario.checkpoint.enabled {
        sim.memory.add::<u8>("checkpoint.staging", state::staging_bytes(sim));
        sim.memory.check(sim.budget)?;
    }
    Ok(())
}
