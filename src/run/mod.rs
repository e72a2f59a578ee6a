//! `strand run`: drive a simulation to its end time, writing VTU snapshots, a CSV of global
//! quantities, observables and restart checkpoints, with progress; `--resume` continues from the
//! newest good checkpoint, and Ctrl-C (SIGINT) or SIGTERM stops the run with a fresh one.

mod checkpoints;
mod error;
mod layer_cost;
mod outputs;
mod preflight;
mod previous;
mod progress;
mod resume;
mod signals;

pub use checkpoints::plan_checkpoint_staging;
pub use error::RunError;
use error::io_err;
pub use outputs::{process_cpu_seconds, write_snapshot, Globals, GLOBALS_HEADER};
pub use crate::solver::preflight;
pub use preflight::{planned_steps, scenario_warnings};

use crate::checkpoint::state;
use crate::memory::fmt_bytes;
use crate::scenario::Scenario;
use crate::solver::{DtLimit, SimError, Simulation};
use checkpoints::Checkpoints;
use layer_cost::LayerCost;
use outputs::Outputs;
use previous::clear_previous_run;
use progress::progress_bar;
use resume::{restore, resume_checkpoint};
use signals::Signals;
use std::path::PathBuf;
use std::time::Instant;

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Override the scenario's thread count.
    pub threads: Option<usize>,
    pub quiet: bool,
    /// Continue from the newest good checkpoint in `out/checkpoints`.
    pub resume: bool,
    /// Resume even though the scenario changed since the checkpoint.
    pub force: bool,
    /// Start afresh even though `out` holds checkpoints of an unfinished run (they are deleted).
    pub overwrite: bool,
    /// The command that started the run (without `--resume`), for the resume hint.
    pub command: String,
}

pub struct RunSummary {
    pub steps: u64,
    pub time: f64,
    pub wall_s: f64,
    pub particles: usize,
    /// Observables at each output, when the scenario asks for them.
    pub observations: Vec<crate::report::Observation>,
    /// Wall seconds spent in each phase of the step (see `solver::PHASES`).
    pub phase_seconds: [f64; crate::solver::PHASES.len()],
    /// Awake particles summed over the steps of this run (see `Simulation`).
    pub awake_particle_steps: u64,
    /// Hash of the final state (as `strand inspect` shows for a checkpoint of it).
    pub state_hash: u64,
    /// The checkpoint the run resumed from.
    pub resumed_from: Option<PathBuf>,
    /// The newest checkpoint written (the final one when `[checkpoint] at_end`).
    pub last_checkpoint: Option<PathBuf>,
    /// The print's failure (`failure.rs`), when it failed.
    pub failure: Option<crate::failure::Failure>,
    /// The inertia mass scaling adds (`outputs.rs`): peaks over this run's outputs.
    pub inertia: outputs::Inertia,
    /// Work of gravity and the body force on the material since t = 0 [J].
    pub external_work: f64,
}

impl RunOptions {
    /// A progress message on stderr, unless quiet.
    fn say(&self, m: String) {
        if !self.quiet {
            eprintln!("{m}");
        }
    }
}

/// A run in progress: the simulation, its outputs and checkpoints, the signals that stop it and
/// its progress display. [`run_scenario`] drives one from [`Run::open`] to [`Run::finish`].
pub struct Run<'a> {
    opts: &'a RunOptions,
    sc: Scenario,
    sim: Simulation,
    outputs: Outputs<'a>,
    ckpts: Option<Checkpoints>,
    signals: Signals,
    bar: Option<indicatif::ProgressBar>,
    resumed_from: Option<PathBuf>,
    /// The step a resumed checkpoint was taken in, to finish first: (dt, its bound).
    pending: Option<(f64, DtLimit)>,
    /// The end time: the scenario's, or earlier once a failed print's `stop_after` has passed.
    end: f64,
    first_step: u64,
    last_line: Instant,
    resume_cmd: String,
    /// The print's cost per layer, for the log.
    layer_cost: LayerCost,
}

/// What opening a run gives: the run, or the summary of a resumed run that had already finished.
pub enum Opened<'a> {
    Run(Box<Run<'a>>),
    Finished(Box<RunSummary>),
}

/// Run a scenario to its end, writing outputs into `opts.out`.
pub fn run_scenario(scenario: &Scenario, opts: &RunOptions) -> Result<RunSummary, RunError> {
    let mut run = match Run::open(scenario, opts)? {
        Opened::Run(run) => run,
        Opened::Finished(done) => return Ok(*done),
    };
    run.finish_pending_step()?;
    while !run.ended() {
        let next_out = run.next_output_time();
        while run.sim.time < next_out * (1.0 - 1e-12) {
            run.step(next_out)?;
        }
        run.output()?;
    }
    run.finish()
}

impl<'a> Run<'a> {
    /// Open a run in `opts.out`: afresh (refusing to lose an unfinished run's checkpoints) or,
    /// with `opts.resume`, from the newest good checkpoint. A fresh run writes its initial output.
    pub fn open(scenario: &Scenario, opts: &'a RunOptions) -> Result<Opened<'a>, RunError> {
        let mut sc = scenario.clone();
        if let Some(t) = opts.threads {
            sc.simulation.threads = t;
        }
        // refused over the budget before the output folder is touched
        preflight(&sc).map_err(|e| RunError::Sim(SimError::Invalid(e)))?;
        std::fs::create_dir_all(&opts.out).map_err(io_err(&opts.out))?;
        let resume_from = if opts.resume {
            Some(resume_checkpoint(&sc, opts)?)
        } else {
            clear_previous_run(&opts.out, &sc, opts)?;
            None
        };
        let mut sim = Simulation::new(&sc)?;
        plan_checkpoint_staging(&mut sim)?;
        for w in scenario_warnings(&sc, &sim) {
            eprintln!("{w}");
        }
        let csv_path = opts.out.join("globals.csv");
        let resumed = match &resume_from {
            Some(ck) => match restore(&mut sim, ck, &sc, opts, &csv_path)? {
                Ok(resumed) => Some(resumed),
                Err(done) => return Ok(Opened::Finished(Box::new(done))),
            },
            None => None,
        };
        opts.say(format!(
            "strand: '{}' — {} particles, {} threads, {} precision\nmemory plan (budget {}):\n{}",
            sc.name,
            sim.particles.n,
            sim.threads(),
            crate::kernels::real::NAME,
            fmt_bytes(sim.budget),
            sim.memory
        ));
        let (dt0, lim0) = sim.choose_dt(f64::INFINITY);
        let steps = planned_steps(&sim, sc.simulation.end_time).map_err(|e| RunError::Sim(SimError::Invalid(e)))?;
        opts.say(format!("time step: {dt0:.3e} s, bound by {lim0:?} (about {steps:.0} steps to t = {} s at this step)", sc.simulation.end_time));

        let (pending, k_out, progress) = match resumed {
            Some(r) => (Some(r.pending), r.k_out, r.progress),
            None => (None, 0, state::Progress::default()),
        };
        let staging_bytes = state::staging_bytes(&sim);
        let mut outputs = Outputs::open(&sc, &sim, &opts.out, csv_path, pending.is_some(), k_out, progress, staging_bytes)?;
        let resume_cmd = format!("{} --resume", opts.command);
        let ckpts = if sc.checkpoint.enabled {
            let last_good = resume_from.as_ref().map(|c| (c.path.clone(), c.header.step));
            let disk_limit = outputs.disk.as_ref().map(|d| d.limit);
            Some(Checkpoints::open(&sc, &sim, &opts.out, disk_limit, staging_bytes, last_good, resume_cmd.clone())?)
        } else {
            None
        };
        let resumed_from = resume_from.map(|c| c.path.clone());
        let signals = Signals::register();
        if resumed_from.is_none() {
            outputs.write(&sim)?;
        }
        let end = sc.simulation.end_time;
        let bar = progress_bar(opts, ((end - sim.time) / dt0).ceil().max(1.0) as u64);
        let first_step = sim.step;
        let last_line = Instant::now();
        let starts = sim.printer.as_ref().map_or(Vec::new(), |p| p.toolpath.layers().iter().map(|l| l.1).collect());
        let layer_cost = LayerCost::new(starts, &sim);
        let run = Run { opts, sc, sim, outputs, ckpts, signals, bar, resumed_from, pending, end, first_step, last_line, resume_cmd, layer_cost };
        Ok(Opened::Run(Box::new(run)))
    }

    /// The simulation as it stands.
    pub fn sim(&self) -> &Simulation {
        &self.sim
    }

    /// Whether the run has reached its end time.
    pub fn ended(&self) -> bool {
        self.sim.time >= self.end * (1.0 - 1e-12)
    }

    /// The time of the next output (or the end, if sooner).
    pub fn next_output_time(&self) -> f64 {
        ((self.outputs.k_out + 1) as f64 * self.sc.output.interval).min(self.end)
    }

    /// Finish the step a resumed checkpoint was taken in the middle of.
    pub fn finish_pending_step(&mut self) -> Result<(), RunError> {
        if let Some((dt, limit)) = self.pending.take() {
            if let Err(source) = self.sim.finish_step(dt) {
                return Err(self.failed_step(source));
            }
            self.sim.last_dt = dt;
            self.sim.last_limit = limit;
        }
        Ok(())
    }

    /// One step, not going past `next_out`.
    pub fn step(&mut self, next_out: f64) -> Result<(), RunError> {
        let (dt, limit) = self.sim.choose_dt(next_out);
        if let Err(source) = self.sim.begin_step(dt) {
            return Err(self.failed_step(source));
        }
        self.middle_of_step(dt, limit, next_out)?;
        if let Err(source) = self.sim.finish_step(dt) {
            return Err(self.failed_step(source));
        }
        self.sim.last_dt = dt;
        self.sim.last_limit = limit;
        if let Some(line) = self.layer_cost.after_step(&self.sim) {
            self.opts.say(line);
        }
        self.show_progress();
        Ok(())
    }

    /// The middle of the step, where checkpoints are taken (see checkpoint/state.rs) and a
    /// caught signal stops the run with one.
    fn middle_of_step(&mut self, dt: f64, limit: DtLimit, next_out: f64) -> Result<(), RunError> {
        if let Some(ck) = &mut self.ckpts {
            ck.this_step = false;
            if let Err(e) = ck.poll() {
                return Err(self.stopped(e));
            }
        }
        if let Some(signal) = self.signals.caught() {
            return Err(self.interrupted(signal, dt, limit));
        }
        if let Some(ck) = &mut self.ckpts {
            // the same sum finish_step makes: whether this step ends on the output
            let ends_on_output = self.sim.time + dt >= next_out * (1.0 - 1e-12);
            let r = if ck.due(&self.sim) {
                ck.submit(&self.sim, dt, limit, &self.outputs)
            } else if ends_on_output {
                ck.stage(&self.sim, dt, limit, &self.outputs)
            } else {
                Ok(())
            };
            if let Err(e) = r {
                return Err(self.stopped(e));
            }
        }
        Ok(())
    }

    /// Stop on a signal, with a checkpoint of the middle of this step when checkpoints are on.
    fn interrupted(&mut self, signal: &'static str, dt: f64, limit: DtLimit) -> RunError {
        if let Some(b) = &self.bar {
            b.abandon();
        }
        let saved = match &mut self.ckpts {
            Some(ck) => {
                if let Err(e) = ck.write_now(&self.sim, dt, limit, &self.outputs) {
                    return self.stopped(e);
                }
                format!("checkpoint {}", ck.last_good.as_ref().map_or(String::new(), |(p, _)| p.display().to_string()))
            }
            None => "no checkpoint written: [checkpoint] enabled = false, the run cannot be resumed".into(),
        };
        RunError::Interrupted { signal, step: self.sim.step, time: self.sim.time, saved, resume: self.resume_cmd.clone() }
    }

    /// Write the output the last step ended on; a failed print's `stop_after` may end the run
    /// there.
    pub fn output(&mut self) -> Result<(), RunError> {
        self.outputs.k_out += 1;
        if let Err(e) = self.outputs.write(&self.sim) {
            // a snapshot over the disk budget: stop with a checkpoint of the middle of the step
            // before this output (room was kept for it)
            if let (RunError::DiskBudget(_), Some(ck)) = (&e, &mut self.ckpts) {
                let _ = ck.write_staged();
            }
            return Err(self.stopped(e));
        }
        // `[observe] failure.stop_after`: this output ends the run once that time after the
        // print's failure has passed
        if let Some(stop) = self.outputs.reporter.as_ref().and_then(|r| r.stop_time()) {
            if self.sim.time >= stop * (1.0 - 1e-12) && self.sim.time < self.end {
                self.opts.say(format!("the print has failed; the run ends stop_after later, at t = {:.4} s", self.sim.time));
                self.end = self.sim.time;
            }
        }
        let last = self.ended();
        if let Some(ck) = &mut self.ckpts {
            if !(last && self.sc.checkpoint.at_end) {
                ck.release_staged();
            }
        }
        Ok(())
    }

    /// The end checkpoint, the closing messages and the run's summary.
    pub fn finish(mut self) -> Result<RunSummary, RunError> {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        if let Some(ck) = &mut self.ckpts {
            // the end checkpoint is the middle of the last step (staged there), unless the run
            // resumed from it and had nothing left to do
            let r = if self.sc.checkpoint.at_end { ck.write_staged() } else { ck.drain() };
            if let Err(e) = r {
                return Err(self.stopped(e));
            }
        }
        if self.layer_cost.counting() {
            self.opts.say(self.layer_cost.finish_layer(&self.sim));
        }
        let (sim, opts) = (&self.sim, self.opts);
        let wall = self.outputs.start.elapsed().as_secs_f64();
        let failure = self.outputs.reporter.as_ref().and_then(|r| r.failure);
        if let Some(f) = failure {
            use crate::failure::FailureRule;
            let how = match f.rule {
                FailureRule::Sinking => format!("the top sinking faster than {:.2} mm/s", f.sink_rate * 1e3),
                FailureRule::Lost => "the top a layer short of the nominal".to_string(),
                FailureRule::Spread => "the section spreading".to_string(),
                FailureRule::Sway => format!("the top {:.1} mm to the side of where it was laid", f.sway * 1e3),
            };
            opts.say(format!(
                "the print failed by {} in layer {} at t = {:.3} s (nominal height {:.1} mm; at x = {} m, {how})",
                f.mode.name(),
                f.layer,
                f.time,
                f.height * 1e3,
                f.station,
            ));
        }
        let inertia = self.outputs.inertia;
        if inertia.mass_scaling > 1.0 {
            opts.say(format!(
                "mass scaling {}: kinetic energy at most {:.2} % of the external work from t = {:.3} s on (at t = {:.4} s{}), Froude-like s v^2/(g h) at most {:.3}",
                inertia.mass_scaling,
                inertia.from,
                100.0 * inertia.peak_kinetic_to_external,
                inertia.peak_time,
                if failure.is_some() { ", before the failure" } else { "" },
                inertia.peak_froude
            ));
        }
        opts.say(format!(
            "done: {} steps to t = {:.4} s in {:.1} s ({:.0} steps/s), {} particles{}, peak memory {}; output in {}",
            sim.step,
            sim.time,
            wall,
            (sim.step - self.first_step) as f64 / wall,
            sim.particles.n,
            if sim.particles.n_sleep > 0 { format!(" ({} asleep)", sim.particles.n_sleep) } else { String::new() },
            crate::verify::peak_rss_bytes().map_or("unknown".into(), fmt_bytes),
            opts.out.display()
        ));
        Ok(RunSummary {
            steps: sim.step,
            time: sim.time,
            wall_s: wall,
            particles: sim.particles.n,
            observations: self.outputs.reporter.take().map(|r| r.history).unwrap_or_default(),
            phase_seconds: sim.phase_seconds,
            awake_particle_steps: sim.awake_particle_steps,
            state_hash: state::current_state_hash(sim),
            resumed_from: self.resumed_from.take(),
            last_checkpoint: self.ckpts.take().and_then(|c| c.last_good.map(|g| g.0)),
            failure,
            inertia,
            external_work: sim.external_work,
        })
    }

    /// An error once the run has started, with what is on disk to go on from.
    fn stopped(&self, e: RunError) -> RunError {
        let note = self.ckpts.as_ref().map_or("checkpoints are disabled ([checkpoint] enabled = false)".to_string(), |c| c.note());
        RunError::Stopped { source: Box::new(e), note }
    }

    /// A failed step: the state it produced is kept for diagnosis in ParaView.
    fn failed_step(&self, source: SimError) -> RunError {
        let snapshot = self.opts.out.join("failed_state.vtu");
        let e = match write_snapshot(&self.sim, &snapshot, &mut Vec::new(), |_| Ok(())) {
            Ok(()) => RunError::Failed { source, snapshot },
            Err(_) => RunError::Sim(source),
        };
        self.stopped(e)
    }
}
