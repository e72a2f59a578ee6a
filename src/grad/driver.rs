//! The gradient driver: runs a checkpoint schedule's actions on the simulator and the step
//! adjoint, and turns the adjoint of the initial state and the accumulated parameter adjoints
//! into dJ/dtheta.
//!
//! What a gradient run holds fixed: the time step (the scenario must set `simulation.dt`, so the
//! perturbed runs of a central difference take the same steps), the pool order (no reordering
//! by block after the start, so an adjoint array means the same particle in every step), and
//! everything piecewise constant in the state (stencil bases, J-bar cells, which particle is
//! extreme in an objective, which branch a material or wall took).

use super::fields::state_bytes;
use crate::observables::{Frame, Objective};
use super::params::{parse, Param};
use crate::key::Key;
use super::schedule::{choose, Action, Budget, Kind, OnlineSchedule, Plan};
use super::step_adjoint::StepAdjoint;
use super::store::{DiskSlots, RamSlots, Store, DISK_TIER_BUFFERS};
use super::GradError;
use crate::memory::{fmt_bytes, Backing, MemoryPlan};
use crate::pools::Counts;
use crate::scenario::Scenario;
use super::print_adjoint::PrintParams;
use crate::print::SyncEmission;
use crate::solver::{for_each_lattice_point, Adjoint, Simulation};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct GradOptions {
    /// Bytes for the backward pass's own memory: the adjoint arrays, the tape of one step and the
    /// RAM checkpoints (the simulator's pools are under the scenario's `[memory] budget`).
    pub ram_bytes: u64,
    /// Bytes of checkpoints on disk, in `disk_dir`.
    pub disk_bytes: u64,
    pub disk_dir: PathBuf,
    pub threads: Option<usize>,
    /// Force a schedule instead of choosing one from the budgets.
    pub schedule: Option<Kind>,
    /// Stop the run once the largest particle speed, having exceeded this [m/s], falls back
    /// below it (or at the end time): its length is then unknown in advance and the online
    /// schedule is used.
    pub until_rest: Option<f64>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct GradResult {
    pub objective: String,
    pub value: f64,
    pub params: Vec<String>,
    pub values: Vec<f64>,
    pub gradient: Vec<f64>,
    pub steps: u64,
    pub schedule: String,
    pub forward_steps: u64,
    pub peak_ram_slots: usize,
    pub peak_disk_slots: usize,
    pub state_bytes: u64,
    pub adjoint_bytes: u64,
    pub disk_written_bytes: u64,
    pub forward_s: f64,
    pub reverse_s: f64,
    /// The reverse sweep's wall time: the recompute, then each phase's adjoint.
    pub reverse_phases_s: Vec<(String, f64)>,
    /// Objectives carried together by the run's reverse sweep (its costs are theirs together).
    pub seeds: usize,
    pub wall_s: f64,
}

/// A simulation set up for a gradient run (or for the forward runs that check one).
pub fn prepare(sc: &Scenario, threads: Option<usize>) -> Result<Simulation, GradError> {
    if sc.sleep.as_ref().is_some_and(|s| s.coarsen) {
        return Err(GradError::Unsupported(
            "strand grad does not merge sleeping particles: remove [sleep] coarsen (a merge ends particles and averages their state, which the adjoint does not follow)".into(),
        ));
    }
    if sc.simulation.dt.is_none() {
        return Err(GradError::Unsupported("strand grad needs a fixed time step: set simulation.dt (the gradient holds the step fixed so perturbed runs take the same steps)".into()));
    }
    let mut sc = sc.clone();
    sc.checkpoint.enabled = false;
    if let Some(t) = threads {
        sc.simulation.threads = t;
    }
    let mut sim = Simulation::new(&sc)?;
    if let Some(p) = &mut sim.printer {
        // the stepper emits itself: a gradient run jumps back in time, which a queue filled
        // ahead by the emitter thread cannot follow
        p.emitter = None;
        p.sync = Some(SyncEmission::new(&p.plan, 0));
    }
    // one sort by block up front (the step's binning then reorders nothing), then frozen
    sim.freeze_order()?;
    Ok(sim)
}

/// Units of `sim`'s sleep tables (0 when it does not sleep).
fn sleep_units(sim: &Simulation) -> usize {
    sim.sleep.as_ref().map_or(0, |s| s.clocks().len())
}

/// Steps from t = 0 to the end time, counted with the time-step control's own arithmetic.
pub fn count_steps(sim: &Simulation) -> u64 {
    let end = sim.scenario.simulation.end_time;
    let dt = sim.scenario.simulation.dt.unwrap_or(f64::INFINITY);
    let (mut t, mut n) = (0.0f64, 0u64);
    while t < end * (1.0 - 1e-12) {
        let left = end - t;
        t += if left <= dt * (1.0 + 1e-9) { left } else { dt };
        n += 1;
    }
    n
}

fn advance_to_end(sim: &mut Simulation, steps: u64) -> Result<(), GradError> {
    let end = sim.scenario.simulation.end_time;
    for _ in 0..steps {
        sim.step_until(end)?;
    }
    Ok(())
}

/// The objective after a forward run of `sc` over `steps` steps (what central differences
/// evaluate: the step count of the differentiated run is held fixed, also when a stop condition
/// chose it).
pub fn forward_value(sc: &Scenario, objective: &Objective, threads: Option<usize>, steps: u64) -> Result<f64, GradError> {
    Ok(forward_values_after(sc, std::slice::from_ref(objective), &[steps], threads)?[0])
}

/// [`forward_value`] of several objectives on one forward run, `objectives[k]` after `steps[k]`
/// steps.
pub fn forward_values_after(sc: &Scenario, objectives: &[Objective], steps: &[u64], threads: Option<usize>) -> Result<Vec<f64>, GradError> {
    let mut sim = prepare(sc, threads)?;
    let last = steps.iter().copied().max().unwrap_or(0);
    values_along(&mut sim, objectives, steps, last)
}

/// `objectives[k]` after `steps[k]` steps of `sim`, which runs `run_to` steps in all (an
/// objective after a later step stays NaN).
fn values_along(sim: &mut Simulation, objectives: &[Objective], steps: &[u64], run_to: u64) -> Result<Vec<f64>, GradError> {
    let frame = Frame::of(sim);
    let mut order: Vec<usize> = (0..objectives.len()).filter(|&k| steps[k] <= run_to).collect();
    order.sort_by_key(|&k| steps[k]);
    let (mut values, mut done) = (vec![f64::NAN; objectives.len()], 0);
    for k in order {
        advance_to_end(sim, steps[k] - done)?;
        done = steps[k];
        values[k] = objectives[k].evaluate(sim, &frame, None)?;
    }
    advance_to_end(sim, run_to - done)?;
    Ok(values)
}

/// The step of `sim`'s run (to its end time) after which the time is `t`, to the rounding the
/// time-step control allows (a step within 1e-9 of dt of the end is taken as the rest): the
/// objectives at earlier times share the whole run's forward and reverse sweeps. `None` when
/// the run's steps pass `t` between two of them, or at `t` = 0 (a run of its own then).
pub fn step_at(sim: &Simulation, t: f64) -> Option<u64> {
    let end = sim.scenario.simulation.end_time;
    let dt = sim.scenario.simulation.dt?;
    if t >= end {
        return Some(count_steps(sim)).filter(|&n| n > 0);
    }
    let (mut time, mut n) = (0.0f64, 0u64);
    while time < end * (1.0 - 1e-12) {
        let left = end - time;
        time += if left <= dt * (1.0 + 1e-9) { left } else { dt };
        n += 1;
        if (time - t).abs() <= dt * 1e-9 {
            return Some(n);
        }
        if time > t {
            return None;
        }
    }
    None
}

/// The objectives after a forward run of `sc`, each taken after its step (`None`: the last).
pub fn forward_values(sc: &Scenario, seeds: &[Seeded], threads: Option<usize>) -> Result<Vec<f64>, GradError> {
    let mut sim = prepare(sc, threads)?;
    let n = count_steps(&sim);
    let objectives: Vec<Objective> = seeds.iter().map(|s| s.objective.clone()).collect();
    let stops: Vec<u64> = seeds.iter().map(|s| s.step.unwrap_or(n)).collect();
    values_along(&mut sim, &objectives, &stops, n)
}

/// Ranges of particle ids per body (bodies are filled in order, ids are creation order).
fn body_ids(sc: &Scenario) -> Vec<std::ops::Range<u32>> {
    let mut start = 0u32;
    sc.bodies
        .iter()
        .map(|b| {
            let mut k = 0u32;
            for_each_lattice_point(sc, b, |_| k += 1);
            let r = start..start + k;
            start += k;
            r
        })
        .collect()
}

pub fn gradient(sc: &Scenario, objective: &Objective, wrt: &[String], opts: &GradOptions) -> Result<GradResult, GradError> {
    let mut r = gradients(sc, &[Seeded { objective: objective.clone(), step: None }], wrt, opts)?;
    Ok(r.remove(0))
}

/// An objective of a gradient run and the step after which it is taken (`None`: the run's last).
#[derive(Clone, Debug)]
pub struct Seeded {
    pub objective: Objective,
    pub step: Option<u64>,
}

/// The gradients of several objectives of one run: one forward sweep (with its recomputations)
/// and one reverse sweep carrying an adjoint per objective (a vector adjoint), each seeded at its
/// objective's step. The step's recomputation, the checkpoint schedule and its forward runs are
/// shared; only the adjoint phases are done once per objective. When the adjoint arrays of all
/// objectives would take more than half of `opts.ram_bytes` (leaving too little for the
/// checkpoints), the objectives are split into batches, one run each. Each result carries its
/// run's costs.
pub fn gradients(sc: &Scenario, seeds: &[Seeded], wrt: &[String], opts: &GradOptions) -> Result<Vec<GradResult>, GradError> {
    if seeds.is_empty() {
        return Ok(Vec::new());
    }
    let sim = prepare(sc, opts.threads)?;
    let (cap, sl) = (Counts::capacity(sim.particles.capacity(), sim.grid.max_blocks()), sim.particles.state_len);
    let units = sleep_units(&sim);
    let bytes = |k: usize| {
        let mut plan = MemoryPlan::default();
        StepAdjoint::plan(&mut plan, &cap, sl, units, k);
        plan.total()
    };
    let per_seed = bytes(2) - bytes(1);
    let fit = ((opts.ram_bytes / 2).saturating_sub(bytes(0)) / per_seed.max(1)).max(1) as usize;
    let mut out = Vec::with_capacity(seeds.len());
    for batch in seeds.chunks(fit) {
        out.extend(gradient_run(sc, batch, wrt, opts)?);
    }
    Ok(out)
}

fn gradient_run(sc: &Scenario, seeds: &[Seeded], wrt: &[String], opts: &GradOptions) -> Result<Vec<GradResult>, GradError> {
    let wall = Instant::now();
    let sim = prepare(sc, opts.threads)?;
    let (keys, params): (Vec<Key>, Vec<Param>) = wrt.iter().map(|k| parse(&sim, k)).collect::<Result<Vec<_>, _>>()?.into_iter().unzip();
    let values: Vec<f64> = keys.iter().map(|k| super::params::value(&sc.source, k)).collect::<Result<_, _>>()?;
    let frame = Frame::of(&sim);
    let n0 = sim.particles.n;
    let print_keys: Vec<(String, f64)> =
        wrt.iter().zip(&values).filter(|(k, _)| k.starts_with("print.")).map(|(k, v)| (k.clone(), *v)).collect();
    let prints = match &sim.printer {
        Some(p) => seeds.iter().map(|_| PrintParams::new(sc, &p.plan, &print_keys).map(Some)).collect::<Result<Vec<_>, _>>()?,
        None if print_keys.is_empty() => seeds.iter().map(|_| None).collect(),
        None => return Err(GradError::Param(format!("'{}': the scenario does not print", print_keys[0].0))),
    };
    if opts.until_rest.is_some() && seeds.iter().any(|s| s.step.is_some()) {
        return Err(GradError::Unsupported("a run stopped at rest takes its objectives at its last step".into()));
    }
    let memory = Memory::plan(&sim, seeds.len(), opts)?;
    let backing = Backing { dir: sc.memory.dir.clone() };
    let adj = StepAdjoint::new(&sim, &backing, seeds.len())?;
    let end = sc.simulation.end_time;
    let k = seeds.len();
    let mut ex = Executor {
        sim,
        adj,
        store: None,
        seeds,
        frame,
        prints,
        end,
        stops: Vec::new(),
        active: vec![false; k],
        due: Vec::with_capacity(k),
        values: vec![None; k],
        forward_steps: 0,
        forward_s: 0.0,
        reverse_s: 0.0,
    };
    let run = match opts.until_rest {
        None => ex.run_to_end(opts, &memory, &backing, n0)?,
        Some(v_rest) => ex.run_until_rest(v_rest, &memory, &backing, n0)?,
    };
    ex.results(wrt, &values, &params, n0, &memory, &run, wall.elapsed().as_secs_f64())
}

/// What a gradient run's memory holds: its adjoint arrays, and the schedule's stored states
/// within the rest of the budget.
struct Memory {
    adjoint_bytes: u64,
    /// One stored state (a print grows: every slot is sized for the full pool).
    state_bytes: u64,
    budget: Budget,
}

impl Memory {
    fn plan(sim: &Simulation, seeds: usize, opts: &GradOptions) -> Result<Memory, GradError> {
        let (cap, sl) = (sim.particles.capacity(), sim.particles.state_len);
        let mut grad_plan = MemoryPlan::default();
        StepAdjoint::plan(&mut grad_plan, &Counts::capacity(cap, sim.grid.max_blocks()), sl, sleep_units(sim), seeds);
        let adjoint_bytes = grad_plan.total();
        let sbytes = state_bytes(sim) as u64;
        if opts.ram_bytes < adjoint_bytes {
            return Err(GradError::Budget { ram_bytes: opts.ram_bytes, adjoint_bytes, state_bytes: sbytes, plan: Box::new(grad_plan) });
        }
        // a disk tier's staging buffers are RAM: with a disk budget they come out of the RAM one
        let staging = if opts.disk_bytes >= sbytes { DISK_TIER_BUFFERS * sbytes } else { 0 };
        let ram_bytes = (opts.ram_bytes - adjoint_bytes).saturating_sub(staging);
        let budget = Budget { state_bytes: sbytes, ram_bytes, disk_bytes: opts.disk_bytes };
        Ok(Memory { adjoint_bytes, state_bytes: sbytes, budget })
    }
}

/// How a gradient run went: its schedule, the peak RAM and disk slots, and its steps.
struct RunShape {
    schedule: String,
    peak: (usize, usize),
    n_steps: u64,
}

impl Executor<'_> {
    /// The run to its end time, reversed by the budget's schedule (or `opts.schedule`).
    fn run_to_end(&mut self, opts: &GradOptions, memory: &Memory, backing: &Backing, n0: usize) -> Result<RunShape, GradError> {
        let n_steps = count_steps(&self.sim);
        self.set_stops(n_steps)?;
        let plan = match opts.schedule {
            Some(Kind::TwoLevel { segment: 0 }) => Plan::two_level(n_steps),
            Some(kind) => Plan::new(kind, n_steps)?,
            None => choose(n_steps, &memory.budget)?,
        };
        let (ram_slots, disk_slots) = plan.peak_slots();
        let sbytes = memory.state_bytes as usize;
        self.store = Some(Store {
            ram: RamSlots::new(ram_slots, sbytes, backing)?,
            disk: if disk_slots > 0 { Some(DiskSlots::new(&opts.disk_dir, sbytes, disk_slots)?) } else { None },
        });
        if n_steps == 0 {
            self.seed_initial(n0)?;
        }
        for action in plan.actions() {
            self.run(action)?;
        }
        Ok(RunShape { schedule: format!("{:?}", plan.kind()), peak: (ram_slots, disk_slots), n_steps })
    }

    /// The run until the material released from rest comes to rest again (its speed, having
    /// exceeded `v_rest`, falls back below it) or the end time: its length is known only when it
    /// stops, so the online schedule, in RAM only.
    fn run_until_rest(&mut self, v_rest: f64, memory: &Memory, backing: &Backing, n0: usize) -> Result<RunShape, GradError> {
        let slots = usize::try_from(memory.budget.ram_bytes / memory.state_bytes).unwrap_or(usize::MAX).min(1 << 20);
        let mut online = OnlineSchedule::new(slots)?;
        self.store = Some(Store { ram: RamSlots::new(slots, memory.state_bytes as usize, backing)?, disk: None });
        let mut moved = false;
        while self.sim.time < self.end * (1.0 - 1e-12) {
            moved |= self.sim.vmax >= v_rest;
            if moved && self.sim.vmax < v_rest {
                break;
            }
            for action in online.on_step() {
                self.run(action)?;
            }
            let s = self.sim.step;
            self.run(Action::Advance { from: s, to: s + 1 })?;
        }
        let n_steps = online.steps();
        self.set_stops(n_steps)?;
        if n_steps == 0 {
            self.seed_initial(n0)?;
        }
        for action in online.finish() {
            self.run(action)?;
        }
        let schedule = format!("Online {{ slots: {slots}, stopped at rest (max speed < {v_rest} m/s) or at the end time }}");
        Ok(RunShape { schedule, peak: (slots, 0), n_steps })
    }

    /// Each seed's value and gradient in `wrt` (at `values`), with the run's costs.
    #[allow(clippy::too_many_arguments)]
    fn results(self, wrt: &[String], values: &[f64], params: &[Param], n0: usize, memory: &Memory, run: &RunShape, wall_s: f64) -> Result<Vec<GradResult>, GradError> {
        let Executor { sim, adj, store, prints, values: seeded, forward_steps, forward_s, reverse_s, seeds, .. } = self;
        let disk_written_bytes = store.as_ref().and_then(|s| s.disk.as_ref()).map_or(0, |d| d.written);
        let reverse_phases_s = adj.phase_seconds();
        seeds
            .iter()
            .zip(&adj.seeds)
            .zip(prints)
            .zip(seeded)
            .map(|(((seed, a), print), value)| {
                let value = value.ok_or(GradError::StepNotReached)?;
                let mut gradient = assemble(&sim, n0, a, params);
                if let Some(pp) = print {
                    let g = pp.gradient();
                    let mut k = 0;
                    for (i, key) in wrt.iter().enumerate() {
                        if key.starts_with("print.") {
                            gradient[i] = g[k];
                            k += 1;
                        }
                    }
                }
                Ok(GradResult {
                    objective: seed.objective.name(),
                    value,
                    params: wrt.to_vec(),
                    values: values.to_vec(),
                    gradient,
                    steps: seed.step.unwrap_or(run.n_steps),
                    schedule: run.schedule.clone(),
                    forward_steps,
                    peak_ram_slots: run.peak.0,
                    peak_disk_slots: run.peak.1,
                    state_bytes: memory.state_bytes,
                    adjoint_bytes: memory.adjoint_bytes,
                    disk_written_bytes,
                    forward_s,
                    reverse_s,
                    reverse_phases_s: reverse_phases_s.clone(),
                    seeds: seeds.len(),
                    wall_s,
                })
            })
            .collect()
    }
}

/// Carries out schedule actions on the simulation, the step adjoint and the checkpoint store.
struct Executor<'a> {
    sim: Simulation,
    adj: StepAdjoint,
    store: Option<Store>,
    seeds: &'a [Seeded],
    frame: Frame,
    prints: Vec<Option<PrintParams>>,
    end: f64,
    /// The step after which each seed's objective is taken (the run's last by default).
    stops: Vec<u64>,
    /// Which seeds the step being reversed carries (those whose objective comes after it).
    active: Vec<bool>,
    /// The seeds whose objective the step being reversed evaluates.
    due: Vec<(usize, &'a Objective)>,
    values: Vec<Option<f64>>,
    forward_steps: u64,
    forward_s: f64,
    reverse_s: f64,
}

impl Executor<'_> {
    /// The run has `n_steps` steps: resolve and check each seed's step.
    fn set_stops(&mut self, n_steps: u64) -> Result<(), GradError> {
        self.stops = self.seeds.iter().map(|s| s.step.unwrap_or(n_steps)).collect();
        for (s, &k) in self.seeds.iter().zip(&self.stops) {
            if k > n_steps || (k == 0 && n_steps > 0) {
                return Err(GradError::Objective(format!("objective {} at step {k} of a run of {n_steps} steps: it takes steps 1..={n_steps}", s.objective.name())));
            }
        }
        Ok(())
    }

    fn run(&mut self, action: Action) -> Result<(), GradError> {
        let store = self.store.as_mut().ok_or(GradError::NoStore)?;
        match action {
            Action::Advance { from, to } => {
                debug_assert_eq!(self.sim.step, from);
                let t = Instant::now();
                for _ in from..to {
                    self.sim.step_until(self.end)?;
                }
                self.forward_steps += to - from;
                self.forward_s += t.elapsed().as_secs_f64();
            }
            Action::Store { step, tier } => {
                debug_assert_eq!(self.sim.step, step);
                store.store(&self.sim, tier)?;
            }
            Action::Restore { step, tier } => store.restore(&mut self.sim, step, tier)?,
            Action::Free { step, tier } => store.free(step, tier)?,
            Action::Reverse { step } => {
                debug_assert_eq!(self.sim.step, step);
                let t = Instant::now();
                let seeds = self.seeds;
                self.due.clear();
                self.due.extend(seeds.iter().enumerate().filter(|(k, _)| self.stops[*k] == step + 1).map(|(k, s)| (k, &s.objective)));
                for (a, &stop) in self.active.iter_mut().zip(&self.stops) {
                    *a = step < stop;
                }
                let got = self.adj.reverse(&mut self.sim, self.end, &self.due, &self.frame, &self.active, &mut self.prints)?;
                for ((k, _), v) in self.due.iter().zip(got) {
                    self.values[*k] = Some(v);
                }
                self.reverse_s += t.elapsed().as_secs_f64();
            }
        }
        Ok(())
    }

    /// A run of no steps: the objectives of the initial state seed their adjoints directly.
    fn seed_initial(&mut self, n0: usize) -> Result<(), GradError> {
        for (k, s) in self.seeds.iter().enumerate() {
            let a = &mut self.adj.seeds[k];
            let p = &mut a.next;
            let seed = crate::observables::Seed {
                xg: &mut p.xg.as_mut_slice()[..n0],
                v: &mut p.v.as_mut_slice()[..n0],
                j: &mut p.j.as_mut_slice()[..n0],
                mass: &mut a.mass_bar.as_mut_slice()[..n0],
                vol0: &mut a.vol0_bar.as_mut_slice()[..n0],
            };
            self.values[k] = Some(s.objective.evaluate(&self.sim, &self.frame, Some(seed))?);
        }
        Ok(())
    }
}

/// dJ/dtheta from the adjoint of the initial state (in `adj.next` after the last reversed
/// step) and the parameter adjoints accumulated over the steps.
/// `n0` particles existed at the start (the bodies); the toolpath parameters are filled in by
/// the caller.
fn assemble(sim: &Simulation, n0: usize, adj: &Adjoint, params: &[Param]) -> Vec<f64> {
    let p = &sim.particles;
    let n = n0;
    let sc = &sim.scenario;
    let rho = sim.material.density() as f64;
    let g = &adj.grid_params_bar;
    let state_bar = &adj.next.state.as_slice()[..n * p.state_len];
    let mut init_bar = vec![0.0 as crate::Real; adj.material_bar.len()];
    for i in 0..n {
        let sl = p.state_len;
        sim.material.init_state_adjoint(&state_bar[i * sl..(i + 1) * sl], &mut init_bar);
    }
    let ids = body_ids(sc);
    params
        .iter()
        .map(|&param| match param {
            Param::Material(k) => adj.material_bar[k] + init_bar[k] as f64,
            Param::Density => {
                // every particle that ever existed: emitted ones too (slots never used hold 0)
                let (mb, vol0) = (adj.mass_bar.as_slice(), p.vol0.as_slice());
                let through_mass: f64 = mb.iter().zip(vol0).map(|(m, v)| (m * v) as f64).sum();
                let f = sc.simulation.body_force;
                through_mass + adj.density_bar - (0..3).map(|c| g.accel[c] * f[c] / (rho * rho)).sum::<f64>()
            }
            Param::BodyForce(c) => g.accel[c] / rho,
            Param::Gravity(c) => g.accel[c],
            Param::BodyVelocity { body, axis } => {
                let (v_bar, id) = (adj.next.v.as_slice(), p.id.as_slice());
                (0..n).filter(|&i| ids[body].contains(&id[i])).map(|i| v_bar[i][axis] as f64).sum()
            }
            Param::WallFriction { axis, side } => g.wall_mu[axis][side],
            Param::PlatformFriction => g.platform_mu,
            Param::Toolpath => 0.0,
        })
        .collect()
}

/// The human-readable report of a gradient (and its check).
pub fn report(r: &GradResult, check: Option<&super::check::Check>) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "J = {} = {:.9e} after {} steps", r.objective, r.value, r.steps);
    let _ = writeln!(
        s,
        "schedule {} ({} forward steps, peak {} RAM + {} disk states of {}), adjoint arrays {}, disk written {}",
        r.schedule,
        r.forward_steps,
        r.peak_ram_slots,
        r.peak_disk_slots,
        fmt_bytes(r.state_bytes),
        fmt_bytes(r.adjoint_bytes),
        fmt_bytes(r.disk_written_bytes)
    );
    let _ = writeln!(s, "time: forward {:.2} s, reverse {:.2} s, total {:.2} s", r.forward_s, r.reverse_s, r.wall_s);
    let phases: Vec<String> = r.reverse_phases_s.iter().map(|(p, t)| format!("{p} {t:.2} s")).collect();
    let _ = writeln!(s, "reverse by phase: {}", phases.join(", "));
    for (k, p) in r.params.iter().enumerate() {
        let _ = writeln!(s, "dJ/d {p} = {:.9e}   (at {p} = {})", r.gradient[k], r.values[k]);
    }
    if let Some(c) = check {
        for p in &c.params {
            for (h, fd, e) in &p.central {
                let _ = writeln!(s, "  check {}: central difference h = {h:.3e}: {fd:.9e} (relative difference {e:.2e})", p.param);
            }
        }
        let _ = writeln!(s, "  {} central-difference runs in {:.1} s", c.central_runs, c.central_s);
        let _ = writeln!(s, "  Taylor remainder slope {:.3} (2 when the gradient is right; {:.1} s):", c.taylor_slope, c.taylor_s);
        for (h, rem) in &c.taylor {
            let _ = writeln!(s, "    h = {h:.3e}: {rem:.3e}");
        }
    }
    s
}
