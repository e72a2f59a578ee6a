//! `strand run`: drive a simulation to its end time, writing VTU snapshots, a CSV of global
//! quantities, observables and restart checkpoints, with progress; `--resume` continues from the
//! newest good checkpoint, and Ctrl-C (SIGINT) or SIGTERM stops the run with a fresh one.

use crate::checkpoint::{self, state, writer::CheckpointWriter, writer::Event, writer::Staged, Checkpoint};
use crate::disk::{self, DiskFullPolicy};
use crate::memory::{fmt_bytes, parse_size, Backing, Pool};
use crate::output::vtu::{vtu_size, write_pvd, write_vtu, VtuData, VtuField};
use crate::report::Reporter;
use crate::scenario::Scenario;
use crate::solver::{DtLimit, SimError, Simulation};
use crate::Real;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{source}\n  the state after the failing step is in {} (outputs before it are kept)", snapshot.display())]
    Failed { source: SimError, snapshot: PathBuf },
    #[error("output {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{0}")]
    Report(String),
    /// Resuming (or refusing to start over) failed.
    #[error("{0}")]
    Resume(String),
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("stopped by {signal} at step {step} (t = {time:.6} s); {saved}\n  resume with: {resume}")]
    Interrupted { signal: &'static str, step: u64, time: f64, saved: String, resume: String },
    #[error("disk budget: {0}")]
    DiskBudget(String),
    /// A run stopped by an error after it started: what is on disk and how to go on.
    #[error("{source}\n  {note}")]
    Stopped { source: Box<RunError>, note: String },
}

impl RunError {
    /// Process exit status: 128 + the signal's number after SIGINT (130) or SIGTERM (143), the
    /// shell convention, else 2.
    pub fn exit_code(&self) -> u8 {
        match self {
            RunError::Interrupted { signal: "SIGTERM", .. } => 143,
            RunError::Interrupted { .. } => 130,
            _ => 2,
        }
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io { path: path.to_path_buf(), source }
}

/// Global quantities of the particle state, one CSV row per output.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Globals {
    pub time: f64,
    pub step: u64,
    pub dt: f64,
    pub dt_limit: String,
    pub particles: usize,
    pub kinetic_energy: f64,
    pub max_speed: f64,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    pub mean_j: f64,
    /// Particles asleep (see `sleep.rs`).
    pub asleep: usize,
    /// Wall time since the run started [s] (per-step cost over any interval is the ratio of
    /// its wall and step increments).
    pub wall_s: f64,
    /// CPU time of the process since it started, all threads [s]: the cost measure that other
    /// jobs sharing the machine do not distort.
    pub cpu_s: f64,
}

pub const GLOBALS_HEADER: &str =
    "time,step,dt,dt_limit,particles,kinetic_energy,max_speed,x_min,y_min,z_min,x_max,y_max,z_max,mean_J,asleep,wall_s,cpu_s";

impl Globals {
    pub fn of(sim: &Simulation) -> Globals {
        let p = &sim.particles;
        let n = p.n;
        let mut g = Globals {
            time: sim.time,
            step: sim.step,
            dt: sim.last_dt,
            dt_limit: format!("{:?}", sim.last_limit).to_lowercase(),
            particles: n,
            asleep: p.n_sleep,
            bbox_min: [f64::INFINITY; 3],
            bbox_max: [f64::NEG_INFINITY; 3],
            ..Default::default()
        };
        let (v, m, j) = (p.v.as_slice(), p.mass.as_slice(), p.j.as_slice());
        for i in 0..n {
            let s2 = v[i].length_squared() as f64;
            g.kinetic_energy += 0.5 * m[i] as f64 * s2;
            g.max_speed = g.max_speed.max(s2.sqrt());
            g.mean_j += j[i] as f64;
            let x = sim.position(i);
            for a in 0..3 {
                g.bbox_min[a] = g.bbox_min[a].min(x[a]);
                g.bbox_max[a] = g.bbox_max[a].max(x[a]);
            }
        }
        if n > 0 {
            g.mean_j /= n as f64;
        }
        g
    }

    pub fn csv_row(&self) -> String {
        format!(
            "{:.9e},{},{:.6e},{},{},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.12},{},{:.3},{:.2}",
            self.time,
            self.step,
            self.dt,
            self.dt_limit,
            self.particles,
            self.kinetic_energy,
            self.max_speed,
            self.bbox_min[0],
            self.bbox_min[1],
            self.bbox_min[2],
            self.bbox_max[0],
            self.bbox_max[1],
            self.bbox_max[2],
            self.mean_j,
            self.asleep,
            self.wall_s,
            self.cpu_s
        )
    }
}

/// User + system CPU time of this process [s], from /proc/self/stat (0 where unavailable).
pub fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // fields after the parenthesised command name; utime and stime are the 12th and 13th
    let Some(rest) = stat.rsplit_once(')').map(|r| r.1) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // the kernel reports in USER_HZ, 100 on every Linux architecture strand targets
    (ticks(11) + ticks(12)) / 100.0
}

fn real_data(s: &[Real]) -> VtuData<'_> {
    #[cfg(not(feature = "f32"))]
    return VtuData::F64(s);
    #[cfg(feature = "f32")]
    return VtuData::F32(s);
}

/// Write the particles of `sim` as a VTU file, after `fits(size)` agrees to its size.
pub fn write_snapshot(
    sim: &Simulation,
    path: &Path,
    staging: &mut Vec<f64>,
    fits: impl FnOnce(u64) -> Result<(), RunError>,
) -> Result<(), RunError> {
    let p = &sim.particles;
    let n = p.n;
    let sl = p.state_len;
    staging.clear();
    for i in 0..n {
        staging.extend_from_slice(&sim.position(i));
    }
    for i in 0..n {
        staging.push(sim.pressure(i));
    }
    for k in 0..sl {
        for i in 0..n {
            staging.push(p.state.as_slice()[i * sl + k] as f64);
        }
    }
    let (pos, rest) = staging.split_at(3 * n);
    let (pressure, state) = rest.split_at(n);
    let names = sim.material.state_names();
    let mut fields = vec![
        VtuField { name: "velocity", components: 3, data: real_data(bytemuck::cast_slice(&p.v.as_slice()[..n])) },
        VtuField { name: "pressure", components: 1, data: VtuData::F64(pressure) },
        VtuField { name: "J", components: 1, data: real_data(&p.j.as_slice()[..n]) },
        VtuField { name: "stress", components: 9, data: real_data(bytemuck::cast_slice(&p.stress.as_slice()[..n])) },
        VtuField { name: "id", components: 1, data: VtuData::U32(&p.id.as_slice()[..n]) },
    ];
    for (k, name) in names.iter().enumerate() {
        fields.push(VtuField { name, components: 1, data: VtuData::F64(&state[k * n..(k + 1) * n]) });
    }
    let size = vtu_size(&VtuData::F64(pos), &fields).map_err(io_err(path))?;
    fits(size)?;
    disk::fault_check(size).map_err(io_err(path))?;
    write_vtu(path, VtuData::F64(pos), &fields).map_err(io_err(path))
}

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
}

/// The run's output files and what a resumed run needs to continue them.
struct Outputs<'a> {
    out: &'a Path,
    vtu: bool,
    csv_path: PathBuf,
    csv: std::io::BufWriter<std::fs::File>,
    pvd: Vec<(f64, String)>,
    staging: Vec<f64>,
    reporter: Option<Reporter>,
    start: Instant,
    /// Outputs written: the next is number `k_out + 1` (number 0 is the initial state).
    k_out: u64,
    disk: Option<DiskGuard>,
}

/// The disk budget as the output stage applies it (policy in `disk.rs`).
struct DiskGuard {
    limit: u64,
    policy: DiskFullPolicy,
    /// Kept free for a checkpoint at full pool capacity and the small files.
    reserve: u64,
}

impl<'a> Outputs<'a> {
    /// The output files of a run in `out`: a resumed run's CSV and snapshots cut back to the
    /// `k_out` outputs its checkpoint had written, a fresh run's CSV begun with its header.
    #[allow(clippy::too_many_arguments)]
    fn open(sc: &Scenario, sim: &Simulation, out: &'a Path, csv_path: PathBuf, resumed: bool, k_out: u64, mut progress: state::Progress, staging_bytes: usize) -> Result<Self, RunError> {
        if resumed {
            keep_first_rows(&csv_path, k_out + 1).map_err(io_err(&csv_path))?;
            remove_snapshots_after(out, k_out);
        } else {
            std::fs::write(&csv_path, format!("{GLOBALS_HEADER}\n")).map_err(io_err(&csv_path))?;
        }
        let csv = std::fs::OpenOptions::new().append(true).open(&csv_path).map_err(io_err(&csv_path))?;
        let mut reporter = Reporter::new(sc, sim).map_err(RunError::Report)?;
        if let Some(r) = &mut reporter {
            r.history = std::mem::take(&mut progress.observations);
            r.detect_failure();
        }
        let disk = match &sc.output.disk_budget {
            Some(b) => Some(DiskGuard {
                limit: parse_size(b).map_err(|e| RunError::DiskBudget(format!("output.disk_budget: {e}")))?,
                policy: sc.output.on_disk_full,
                reserve: disk::SMALL_FILE_RESERVE + if sc.checkpoint.enabled { staging_bytes as u64 + (1 << 20) } else { 0 },
            }),
            None => None,
        };
        Ok(Outputs {
            out,
            vtu: sc.output.vtu,
            csv_path,
            csv: std::io::BufWriter::new(csv),
            pvd: progress.pvd,
            staging: Vec::with_capacity(sim.particles.capacity() * (4 + sim.particles.state_len)),
            reporter,
            start: Instant::now(),
            k_out,
            disk,
        })
    }
}

impl Outputs<'_> {
    fn write(&mut self, sim: &Simulation) -> Result<(), RunError> {
        // the snapshot first: if the disk budget refuses it, nothing of this output is written,
        // so a checkpoint taken then resumes into exactly this output again
        if self.vtu {
            let name = format!("particles_{:05}.vtu", self.k_out);
            let path = self.out.join(&name);
            let mut staging = std::mem::take(&mut self.staging);
            let r = write_snapshot(sim, &path, &mut staging, |size| self.make_room(size));
            self.staging = staging;
            r?;
            self.pvd.push((sim.time, name));
            let pvd_path = self.out.join("particles.pvd");
            write_pvd(&pvd_path, &self.pvd).map_err(io_err(&pvd_path))?;
        }
        let g = Globals { wall_s: self.start.elapsed().as_secs_f64(), cpu_s: process_cpu_seconds(), ..Globals::of(sim) };
        writeln!(self.csv, "{}", g.csv_row()).map_err(io_err(&self.csv_path))?;
        self.csv.flush().map_err(io_err(&self.csv_path))?;
        if let Some(r) = &mut self.reporter {
            r.observe(sim);
            r.write(self.out).map_err(RunError::Report)?;
        }
        Ok(())
    }

    /// Room for a snapshot of `size` bytes under the disk budget, pruning old snapshots if the
    /// policy says so.
    fn make_room(&mut self, size: u64) -> Result<(), RunError> {
        let Some(d) = &self.disk else { return Ok(()) };
        loop {
            let used = disk::usage(self.out);
            if used + size + d.reserve <= d.limit {
                return Ok(());
            }
            if d.policy == DiskFullPolicy::PruneSnapshots && self.pvd.len() > 1 {
                let (_, old) = self.pvd.remove(0);
                std::fs::remove_file(self.out.join(&old)).map_err(io_err(&self.out.join(&old)))?;
                let pvd_path = self.out.join("particles.pvd");
                write_pvd(&pvd_path, &self.pvd).map_err(io_err(&pvd_path))?;
                continue;
            }
            return Err(RunError::DiskBudget(format!(
                "the next snapshot ({}) would take {} to {} of its {} budget, with {} kept free for a \
                 final checkpoint and the CSV files; raise [output] disk_budget{}",
                fmt_bytes(size),
                self.out.display(),
                fmt_bytes(used + size),
                fmt_bytes(d.limit),
                fmt_bytes(d.reserve),
                if d.policy == DiskFullPolicy::Stop { ", or set [output] on_disk_full = \"prune_snapshots\"" } else { "" }
            )));
        }
    }

    fn progress(&self) -> state::Progress {
        state::Progress { pvd: self.pvd.clone(), observations: self.reporter.as_ref().map(|r| r.history.clone()).unwrap_or_default() }
    }
}

/// The checkpoint stage as the run loop drives it. Checkpoints are taken in the middle of a
/// step (see `checkpoint/state.rs`), so one the run needs after a step (at its end, or when the
/// disk budget refuses a snapshot) is the middle of that step, staged while it was there.
struct Checkpoints {
    writer: CheckpointWriter,
    cfg: checkpoint::CheckpointConfig,
    last_wall: Instant,
    last_step: u64,
    /// Newest checkpoint known to be on disk, and its step.
    last_good: Option<(PathBuf, u64)>,
    resume: String,
    /// The middle of the current step when it ends on an output (or the end).
    staged: Option<Staged>,
    /// Whether a checkpoint was queued in the middle of the current step.
    this_step: bool,
}

impl Checkpoints {
    /// The checkpoint stage of a run in `out`, its writer thread started with a staging buffer
    /// of `staging_bytes`.
    fn open(sc: &Scenario, sim: &Simulation, out: &Path, disk_limit: Option<u64>, staging_bytes: usize, last_good: Option<(PathBuf, u64)>, resume: String) -> Result<Self, RunError> {
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

    fn due(&self, sim: &Simulation) -> bool {
        self.cfg.step_interval.is_some_and(|k| sim.step >= self.last_step + k)
            || self.last_wall.elapsed().as_secs_f64() >= self.cfg.wall_interval
    }

    /// Queue a checkpoint of `sim`, in the middle of a step of length `dt`.
    fn submit(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
        let header = state::header(sim, dt, limit, out.k_out, &out.progress(), Vec::new());
        self.writer.submit(header, &state::sections(sim)).map_err(RunError::Checkpoint)?;
        self.last_wall = Instant::now();
        self.last_step = sim.step;
        self.this_step = true;
        Ok(())
    }

    /// Copy the middle of a step ending on an output, in case the run stops after the output.
    fn stage(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
        let header = state::header(sim, dt, limit, out.k_out, &out.progress(), Vec::new());
        self.staged = Some(self.writer.stage(header, &state::sections(sim)).map_err(RunError::Checkpoint)?);
        Ok(())
    }

    /// After the step: write the staged middle of it (unless one was queued there anyway) and
    /// wait until every checkpoint is on disk.
    fn write_staged(&mut self) -> Result<(), RunError> {
        if let Some(s) = self.staged.take() {
            if self.this_step {
                self.writer.release(s);
            } else {
                self.last_step = s.step();
                self.writer.submit_staged(s).map_err(RunError::Checkpoint)?;
            }
        }
        self.drain()
    }

    fn release_staged(&mut self) {
        if let Some(s) = self.staged.take() {
            self.writer.release(s);
        }
    }

    /// Write a checkpoint of `sim` (in the middle of a step) and wait until it (and any before
    /// it) is on disk.
    fn write_now(&mut self, sim: &Simulation, dt: f64, limit: DtLimit, out: &Outputs) -> Result<(), RunError> {
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
            Event::Failed { step, error } => {
                Err(RunError::Checkpoint(format!("writing the checkpoint of step {step} failed: {error}")))
            }
        }
    }

    fn poll(&mut self) -> Result<(), RunError> {
        while let Some(ev) = self.writer.poll() {
            self.handle(ev)?;
        }
        Ok(())
    }

    /// Wait for the writer; the first failure, if any.
    fn drain(&mut self) -> Result<(), RunError> {
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
    fn note(&self) -> String {
        match &self.last_good {
            Some((p, step)) => format!("the last good checkpoint is {} (step {step}); resume with: {}", p.display(), self.resume),
            None => "no checkpoint was written by this run".to_string(),
        }
    }
}

/// SIGINT and SIGTERM set a flag the run loop checks in the middle of every step; a second signal ends the
/// process at once. Unregistered when dropped, so a library caller keeps its own handlers.
struct Signals {
    flag: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    ids: Vec<signal_hook::SigId>,
}

impl Signals {
    fn register() -> Signals {
        use signal_hook::consts::{SIGINT, SIGTERM};
        use std::sync::atomic::{AtomicBool, AtomicUsize};
        use std::sync::Arc;
        let flag = Arc::new(AtomicUsize::new(0));
        let again = Arc::new(AtomicBool::new(false));
        let mut ids = Vec::new();
        for (sig, code) in [(SIGINT, 130), (SIGTERM, 143)] {
            // order matters: the shutdown check sees the flag as the previous signal left it
            if let Ok(id) = signal_hook::flag::register_conditional_shutdown(sig, code, again.clone()) {
                ids.push(id);
            }
            if let Ok(id) = signal_hook::flag::register(sig, again.clone()) {
                ids.push(id);
            }
            if let Ok(id) = signal_hook::flag::register_usize(sig, flag.clone(), sig as usize) {
                ids.push(id);
            }
        }
        Signals { flag, ids }
    }

    fn caught(&self) -> Option<&'static str> {
        match self.flag.load(std::sync::atomic::Ordering::Relaxed) as i32 {
            0 => None,
            signal_hook::consts::SIGINT => Some("SIGINT"),
            _ => Some("SIGTERM"),
        }
    }
}

impl Drop for Signals {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
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
}

/// What opening a run gives: the run, or the summary of a resumed run that had already finished.
pub enum Opened<'a> {
    Run(Box<Run<'a>>),
    Finished(Box<RunSummary>),
}

/// Where a resumed run goes on from: the step its checkpoint was taken in, the outputs written
/// and the run's progress then.
struct Resumed {
    pending: (f64, DtLimit),
    k_out: u64,
    progress: state::Progress,
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
        std::fs::create_dir_all(&opts.out).map_err(io_err(&opts.out))?;
        let resume_from = if opts.resume {
            Some(resume_checkpoint(&sc, opts)?)
        } else {
            clear_previous_run(&opts.out, &sc, opts)?;
            None
        };
        preflight(&sc).map_err(|e| RunError::Sim(SimError::Setup(e)))?;
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
        let steps = planned_steps(&sim, sc.simulation.end_time).map_err(|e| RunError::Sim(SimError::Setup(e)))?;
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
        let run = Run { opts, sc, sim, outputs, ckpts, signals, bar, resumed_from, pending, end, first_step, last_line, resume_cmd };
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

    /// The progress bar on a terminal, else a line every 10 s.
    fn show_progress(&mut self) {
        let sim = &self.sim;
        let (first_step, end, start) = (self.first_step, self.end, self.outputs.start);
        if let Some(b) = &self.bar {
            if sim.step.is_multiple_of(16) {
                let rate = (sim.step - first_step) as f64 / start.elapsed().as_secs_f64();
                let remaining = ((end - sim.time) / sim.last_dt.max(1e-300)).ceil() as u64;
                b.set_length(sim.step - first_step + remaining);
                b.set_position(sim.step - first_step);
                b.set_message(format!("{rate:.0} steps/s  t = {:.4} s  {} particles", sim.time, sim.particles.n));
            }
        } else if !self.opts.quiet && self.last_line.elapsed().as_secs_f64() > 10.0 {
            self.last_line = Instant::now();
            let rate = (sim.step - first_step) as f64 / start.elapsed().as_secs_f64();
            let remaining = (end - sim.time) / sim.last_dt.max(1e-300) / rate.max(1e-9);
            eprintln!(
                "step {} t = {:.4e} s dt = {:.2e} ({:?}) {:.0} steps/s ETA {:.0} s, {} particles",
                sim.step, sim.time, sim.last_dt, sim.last_limit, rate, remaining, sim.particles.n
            );
        }
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
        let (sim, opts) = (&self.sim, self.opts);
        let wall = self.outputs.start.elapsed().as_secs_f64();
        let failure = self.outputs.reporter.as_ref().and_then(|r| r.failure);
        if let Some(f) = failure {
            opts.say(format!(
                "the print failed in layer {} at t = {:.3} s (nominal height {:.1} mm; top at x = {} m sinking faster than {:.2} mm/s)",
                f.layer,
                f.time,
                f.height * 1e3,
                f.station,
                f.sink_rate * 1e3
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

/// The newest good checkpoint in `opts.out` to resume from, refused if the scenario changed since
/// (unless `opts.force`).
fn resume_checkpoint(sc: &Scenario, opts: &RunOptions) -> Result<Checkpoint, RunError> {
    let ckpt_dir = checkpoint::dir_of(&opts.out);
    let (ck, notes) = checkpoint::newest_valid(&ckpt_dir).map_err(|e| RunError::Resume(no_checkpoint(&opts.out, &e, opts)))?;
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
fn restore(sim: &mut Simulation, ck: &Checkpoint, sc: &Scenario, opts: &RunOptions, csv_path: &Path) -> Result<Result<Resumed, RunSummary>, RunError> {
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

/// A progress bar of `steps` estimated steps, on a terminal unless quiet.
fn progress_bar(opts: &RunOptions, steps: u64) -> Option<indicatif::ProgressBar> {
    if opts.quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let b = indicatif::ProgressBar::new(steps);
    b.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} steps  {msg}  ETA {eta}").unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    Some(b)
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

/// Before anything is allocated or counted: refuse a scenario whose memory plan is over its
/// budget even with the fewest particles its bodies can hold (a lower bound from each body's
/// lattice, cheap at any resolution), so `check` and `run` answer at once where counting the
/// particles one by one would take hours.
pub fn preflight(sc: &Scenario) -> Result<(), String> {
    use crate::memory::MemoryPlan;
    use crate::pools::Pools;
    let budget = parse_size(&sc.memory.budget).map_err(|e| format!("memory.budget: {e}"))?;
    let state_len = crate::materials::build_material(&sc.material)?.state_names().len();
    let fewest: f64 = sc.bodies.iter().map(|b| fewest_particles(sc, b)).sum();
    let geom = crate::grid::GridGeom::new(sc.simulation.dx, sc.domain.min, sc.domain.max, sc.domain.periodic);
    let capacity = crate::pools::Counts::capacity(fewest.min(1e15) as usize, sc.memory.max_blocks.unwrap_or(geom.table_len()).max(8));
    let mut plan = MemoryPlan::default();
    crate::particles::Particles::declared(state_len).plan_memory(&mut plan, &capacity);
    crate::grid::Grid::declared(geom).plan_memory(&mut plan, &capacity);
    if plan.total() > budget {
        return Err(format!(
            "memory plan: the grid and the at least {fewest:.4e} particles of the bodies at dx = {} m need at least {}, over the budget of {} \
             (raise [memory] budget, or lower resolution / max_blocks):\n{plan}",
            sc.simulation.dx,
            fmt_bytes(plan.total()),
            fmt_bytes(budget)
        ));
    }
    Ok(())
}

/// The fewest particles `body` holds: its lattice over the largest box inside it and the
/// domain.
fn fewest_particles(sc: &Scenario, body: &crate::scenario::Body) -> f64 {
    use crate::scenario::Body;
    let h = sc.simulation.dx / body.particles_per_cell_axis() as f64;
    let (lo, hi) = match body {
        Body::Box { min, max, .. } => (*min, *max),
        Body::Frustum { base_center: c, bottom_radius, top_radius, height, .. } => {
            let r = bottom_radius.min(*top_radius) / std::f64::consts::SQRT_2;
            ([c[0] - r, c[1] - r, c[2]], [c[0] + r, c[1] + r, c[2] + height])
        }
    };
    let d = &sc.domain;
    (0..3).map(|a| ((hi[a].min(d.max[a]) - lo[a].max(d.min[a])) / h - 1.0).floor().max(0.0)).product()
}

/// What a scenario does that its author may not expect, said before it runs, one line each
/// (`warning: ...` or `note: ...`): a wall moved to the nearest cell face, nothing to simulate,
/// a body cut by the domain, bodies overlapping, what the G-code import skipped.
pub fn scenario_warnings(sc: &Scenario, sim: &Simulation) -> Vec<String> {
    use crate::solver::for_each_lattice_point;
    let mut w = Vec::new();
    let (d, dx) = (&sc.domain, sc.simulation.dx);
    for a in 0..3 {
        let cells = (d.max[a] - d.min[a]) / dx;
        let n = cells.round();
        if !d.periodic[a] && (cells - n).abs() > 1e-6 * n.max(1.0) {
            w.push(format!(
                "domain.max[{a}] = {} is not a whole number of cells of dx = {dx} from domain.min[{a}] = {} ({cells:.4} cells): \
                 the wall is at {} ({n} cells)",
                d.max[a],
                d.min[a],
                d.min[a] + n * dx
            ));
        }
    }
    // a printed section needs the nozzle resolved by enough cells
    if let Some(r) = sc.print.as_ref().and_then(|p| p.nozzle.resolution_warning(dx, sc.simulation.j_bar)) {
        w.push(r);
    }
    if sim.particles.n == 0 && sc.print.is_none() {
        w.push(if sc.bodies.is_empty() {
            "nothing to simulate: the scenario has no [[body]] and no [print]".to_string()
        } else {
            format!("nothing to simulate: the bodies hold no particle at dx = {dx} (each is smaller than a particle spacing, or dx exceeds the domain)")
        });
    }
    if let Some(file) = sc.print.as_ref().and_then(|p| p.gcode.as_ref().map(|f| (f, &p.gcode_options))) {
        let path = sc.base_dir.join(file.0);
        let notes = std::fs::read_to_string(&path).ok().and_then(|t| crate::print::gcode::parse_gcode_with_notes(&t, file.1).ok().map(|(_, n)| n));
        if let Some(n) = notes.filter(|n| !n.is_empty()) {
            w.push(format!("note: {}: {n}", path.display()));
        }
    }
    for (i, b) in sc.bodies.iter().enumerate() {
        let (lo, hi) = b.bounds();
        let cut: Vec<String> = (0..3)
            .filter(|&a| lo[a] < d.min[a] - 1e-9 * dx || hi[a] > d.max[a] + 1e-9 * dx)
            .map(|a| format!("axis {a}: [{}, {}] against the domain's [{}, {}]", lo[a], hi[a], d.min[a], d.max[a]))
            .collect();
        if !cut.is_empty() {
            let mut n = 0usize;
            for_each_lattice_point(sc, b, |_| n += 1);
            w.push(format!("body[{i}] reaches outside the domain ({}): the part outside is cut off, {n} particles remain", cut.join("; ")));
        }
        for (j, other) in sc.bodies.iter().enumerate().take(i) {
            let (olo, ohi) = other.bounds();
            if (0..3).any(|a| hi[a] <= olo[a] || lo[a] >= ohi[a]) {
                continue;
            }
            let mut n = 0usize;
            for_each_lattice_point(sc, b, |p| n += other.contains(p) as usize);
            if n > 0 {
                w.push(format!("body[{i}] overlaps body[{j}]: {n} of its particles lie inside body[{j}], doubling the material there"));
            }
        }
    }
    w.into_iter().map(|x| if x.starts_with("note: ") { x } else { format!("warning: {x}") }).collect()
}

/// The steps the run needs at its first time step, refused over `MAX_STEPS`.
pub fn planned_steps(sim: &Simulation, end: f64) -> Result<f64, String> {
    let (dt, limit) = sim.choose_dt(f64::INFINITY);
    let steps = ((end - sim.time) / dt).max(0.0).ceil();
    if steps > crate::scenario::MAX_STEPS {
        return Err(format!(
            "the first time step, {dt:.3e} s (bound by {limit:?}), takes {steps:.3e} steps to simulation.end_time = {end} s, \
             more than the {:e} a run may plan",
            crate::scenario::MAX_STEPS
        ));
    }
    Ok(steps)
}

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
fn previous_run_files(out: &Path) -> Vec<PathBuf> {
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
fn clear_previous_run(out: &Path, sc: &Scenario, opts: &RunOptions) -> Result<(), RunError> {
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
    let end = Scenario::parse(&ck.header.scenario_text).map_or(f64::INFINITY, |s| s.simulation.end_time);
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
    let diffs = checkpoint::scenario_differences(&ck.header.scenario_text, &sc.source).unwrap_or_else(|e| vec![e]);
    if !diffs.is_empty() {
        let list = diffs.iter().take(5).map(|d| format!("\n    {d}")).collect::<String>();
        return Err(RunError::Resume(format!(
            "{} holds a finished run of another scenario (t = {end} s), which this run would overwrite; it differs in:{list}\n  \
             choose another --out, or start over (deleting that run's files) with: {start_over}",
            out.display()
        )));
    }
    remove_previous_run(out)
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
    }))
}

/// Keep the header and the first `rows` data rows of a CSV file (the outputs a checkpoint
/// covers), written atomically; a missing file gets just its header.
fn keep_first_rows(path: &Path, rows: u64) -> std::io::Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => format!("{GLOBALS_HEADER}\n"),
        Err(e) => return Err(e),
    };
    let kept: String = text.lines().take(1 + rows as usize).map(|l| format!("{l}\n")).collect();
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, kept)?;
    std::fs::rename(&tmp, path)
}

/// Delete snapshots numbered after `k_out`: a killed run wrote them after its last checkpoint,
/// and the resumed run writes them again.
fn remove_snapshots_after(out: &Path, k_out: u64) {
    let Ok(rd) = std::fs::read_dir(out) else { return };
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let k = name.strip_prefix("particles_").and_then(|r| r.strip_suffix(".vtu")).and_then(|k| k.parse::<u64>().ok());
        if k.is_some_and(|k| k > k_out) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}
