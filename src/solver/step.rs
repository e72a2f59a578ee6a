//! One step: the time step control and the phases in order. [`PHASES`] is the step, run as it
//! stands by [`Simulation::advance`] (in two halves, for restart checkpoints) and by the
//! gradient's recompute, which saves what each phase's [`Phase::saves`] names before it runs;
//! the reverse step walks the same list backwards through [`Simulation::phase_adjoint`]. A new
//! phase is a variant, its place in `PHASES` and its arms in `run_phase` and `phase_adjoint`
//! (the compiler asks for the arms); its adjoint goes beside its forward, in the phase's file.

use super::adjoint::{Adjoint, Saved, Tape, ToolpathBar};
use super::{AdjointError, DtLimit, SimError, Simulation};
use crate::kernels::Real;
use crate::print::NozzleDrive;

/// A phase of the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// The printer's due slabs enter the pool (`emit.rs`).
    Emit,
    /// Sleeping units fall asleep and wake (`sleep/`).
    Sleep,
    /// Particles grouped by the block of their stencil base, blocks by colour (`binning.rs`).
    Bin,
    /// Particles moved into block order, every `reorder_interval` steps and when sleeping moved
    /// some (`binning.rs`).
    Reorder,
    /// The masses emission changed this step, set after reordering (`emit.rs`).
    NewestMasses,
    /// The active grid nodes zeroed (`p2g.rs`).
    ClearGrid,
    /// Particles scattered to the grid in 8 colour passes (`p2g.rs`).
    P2g,
    /// Momentum to velocity, gravity, sleeping holds, the nozzle drive, walls, solids, ghosts
    /// (`grid_update.rs`).
    GridUpdate,
    /// Sleeping blocks take the loads of their held nodes (`sleep/loads.rs`).
    Loads,
    /// Velocities, affine fields and positions gathered back, positions kept inside the walls
    /// (`g2p.rs`).
    G2p,
    /// The newest slab blended with the feed (`emit.rs`).
    FollowFeed,
    /// The material update and the finiteness check (`materials.rs`).
    Materials,
}

/// The step's phases, in order.
pub const PHASES: [Phase; 12] = [
    Phase::Emit,
    Phase::Sleep,
    Phase::Bin,
    Phase::Reorder,
    Phase::NewestMasses,
    Phase::ClearGrid,
    Phase::P2g,
    Phase::GridUpdate,
    Phase::Loads,
    Phase::G2p,
    Phase::FollowFeed,
    Phase::Materials,
];

/// Where [`Simulation::begin_step`] ends and [`Simulation::finish_step`] begins: at G2P, when
/// the rest of the step needs only the grid's node velocities and per particle x, J, the
/// material state and id (v too with FLIP). Restart checkpoints are taken there.
const SECOND_HALF: usize = {
    let mut i = 0;
    while !matches!(PHASES[i], Phase::G2p) {
        i += 1;
    }
    i
};

impl Phase {
    pub fn name(self) -> &'static str {
        match self {
            Phase::Emit => "emit",
            Phase::Sleep => "sleep",
            Phase::Bin => "bin",
            Phase::Reorder => "reorder",
            Phase::NewestMasses => "newest_masses",
            Phase::ClearGrid => "clear_grid",
            Phase::P2g => "p2g",
            Phase::GridUpdate => "grid_update",
            Phase::Loads => "loads",
            Phase::G2p => "g2p",
            Phase::FollowFeed => "follow_feed",
            Phase::Materials => "materials",
        }
    }

    /// What the phase overwrites that an adjoint reads (its own or an earlier phase's): the
    /// recompute saves it just before the phase runs. G2P is the first phase to overwrite the
    /// particle state, the grid update the grid as P2G left it.
    pub fn saves(self) -> Option<Saved> {
        match self {
            Phase::Sleep => Some(Saved::Order),
            Phase::G2p => Some(Saved::Particles),
            Phase::GridUpdate => Some(Saved::Grid),
            _ => None,
        }
    }

    /// Whether the phase has an adjoint. The sleep update's decisions are discrete and held
    /// fixed, but the particles it moves and puts at rest are not (`sleep_adjoint.rs`); the
    /// loads only decide which units wake; gradient runs freeze the pool order (no reordering);
    /// the binning is piecewise constant, held fixed; clearing the grid leaves nothing to
    /// differentiate (G2P's adjoint starts the grid's adjoint from zero).
    pub fn has_adjoint(self) -> bool {
        !matches!(self, Phase::Bin | Phase::Reorder | Phase::ClearGrid | Phase::Loads)
    }

    /// Whether an adjoint reads what the phase computes. The material update's outputs (stress
    /// and material state after the step) feed only the next step, whose reverse has its own
    /// tape, and the objectives: the recompute runs it only when objectives are evaluated.
    pub fn read_by_adjoints(self) -> bool {
        self != Phase::Materials
    }
}

/// One step's inputs, and what its phases hand on to later phases and to the adjoint.
pub struct Step {
    pub dt: f64,
    /// The nozzle drive during the step (a pure function of the step's start time).
    pub drive: Option<NozzleDrive>,
    /// The sleep update moved particles between the awake and sleeping ranges.
    pub(crate) moved: bool,
    /// Particles before emission, and the first slab it added (for its adjoint).
    pub n_before: usize,
    pub first_slab: u64,
}

impl Step {
    /// The step of length `dt` starting at `sim`'s time.
    pub fn new(sim: &Simulation, dt: f64) -> Step {
        let drive = sim.printer.as_ref().and_then(|p| p.drive(sim.time));
        Step { dt, drive, moved: false, n_before: sim.particles.n, first_slab: 0 }
    }
}

struct PhaseClock(std::time::Instant);
impl PhaseClock {
    fn start() -> Self {
        PhaseClock(std::time::Instant::now())
    }
    fn lap(&mut self, acc: &mut f64) {
        let now = std::time::Instant::now();
        *acc += (now - self.0).as_secs_f64();
        self.0 = now;
    }
}

impl Simulation {
    /// The time step for the next step and the bound that set it.
    pub fn choose_dt(&self, until: f64) -> (f64, DtLimit) {
        let s = &self.scenario.simulation;
        let (mut dt, mut limit) = match s.dt {
            Some(dt) => (dt, DtLimit::Fixed),
            None => {
                // the moduli at the oldest age any particle can have during this step
                let st = self.material.stability_at(self.time);
                // mass scaling: the inertia is that of a density s rho (the stresses and
                // viscosity stay real), so the wave speed falls as 1 / sqrt(s) and the viscous
                // bound rho dx^2 / 2 mu grows as s; a fixed `dt` stays the user's
                let rho = st.density as f64 * s.mass_scaling;
                let c = ((st.bulk_modulus as f64 + 4.0 / 3.0 * st.shear_modulus as f64) / rho).sqrt();
                let dt_wave = s.cfl * s.dx / (c + self.vmax);
                // a shear-thickening material's viscosity grows with the rate: bound the rate
                // by the particle speeds (see `max_shear_rate`)
                let mu = st.viscosity_up_to(max_shear_rate(self.vmax, s.dx));
                let dt_visc = if mu > 0.0 {
                    s.cfl * rho * s.dx * s.dx / (2.0 * mu)
                } else {
                    f64::INFINITY
                };
                let mut best = if dt_visc < dt_wave { (dt_visc, DtLimit::Viscous) } else { (dt_wave, DtLimit::Wave) };
                if let Some(m) = s.max_dt {
                    if m < best.0 {
                        best = (m, DtLimit::MaxDt);
                    }
                }
                best
            }
        };
        let left = until - self.time;
        if left <= dt * (1.0 + 1e-9) {
            dt = left;
            limit = DtLimit::Schedule;
        }
        (dt, limit)
    }

    /// The impulse step of a step of length `dt`: dt / s with s = `simulation.mass_scaling`.
    /// Mass scaling gives every node an inertia s m while its weight and the stresses on it
    /// stay real, so v_new = v_old + (f_internal / m + g) dt / s: P2G's stress impulse and the
    /// grid update's gravity impulse are taken over dt / s (with APIC P2G folds the stress
    /// impulse into the node momentum, so the factor has to enter there, not after). A held
    /// node's or a solid's reaction, the momentum removed over dt / s, is then s m dv / dt, the
    /// true force. Everything else (G2P's advection, the material update, the age clock, the
    /// nozzle) takes the real dt. With s = 1, dt / 1 is dt exactly: runs are bit-identical.
    pub fn impulse_dt(&self, dt: f64) -> Real {
        (dt / self.scenario.simulation.mass_scaling) as Real
    }

    /// Advance by one step, not going past time `until`.
    pub fn step_until(&mut self, until: f64) -> Result<(), SimError> {
        let (dt, limit) = self.choose_dt(until);
        self.advance(dt)?;
        self.last_dt = dt;
        self.last_limit = limit;
        Ok(())
    }

    /// One MLS-MPM step of length `dt`.
    pub fn advance(&mut self, dt: f64) -> Result<(), SimError> {
        self.begin_step(dt)?;
        self.finish_step(dt)
    }

    /// The first half of a step: the phases before G2P. Restart checkpoints are taken after it
    /// (`checkpoint/state.rs`).
    pub fn begin_step(&mut self, dt: f64) -> Result<(), SimError> {
        self.run_timed(&PHASES[..SECOND_HALF], &mut Step::new(self, dt))
    }

    /// The second half of a step begun by [`Simulation::begin_step`] with the same `dt` (or put
    /// back by a checkpoint restore): G2P and what follows it; then the clock moves on.
    pub fn finish_step(&mut self, dt: f64) -> Result<(), SimError> {
        self.run_timed(&PHASES[SECOND_HALF..], &mut Step::new(self, dt))?;
        self.accumulate_external_work(dt);
        self.step += 1;
        self.time += dt;
        Ok(())
    }

    /// Run `phases` in order, each timed into `phase_seconds`.
    fn run_timed(&mut self, phases: &[Phase], step: &mut Step) -> Result<(), SimError> {
        let mut clock = PhaseClock::start();
        for &phase in phases {
            self.run_phase(phase, step)?;
            clock.lap(&mut self.phase_seconds[phase as usize]);
        }
        Ok(())
    }

    /// Run one phase of `step`.
    pub fn run_phase(&mut self, phase: Phase, step: &mut Step) -> Result<(), SimError> {
        let dt = step.dt as Real;
        let di = self.impulse_dt(step.dt);
        match phase {
            Phase::Emit => {
                (step.n_before, step.first_slab) = (self.particles.n, self.printer.as_ref().map_or(0, |p| p.emitted()));
                self.emit()?;
            }
            Phase::Sleep => step.moved = self.sleep_update(step.drive.as_ref()),
            Phase::Bin => self.bin_particles()?,
            Phase::Reorder => {
                if !self.frozen_order && (step.moved || self.step.is_multiple_of(self.scenario.simulation.reorder_interval)) {
                    self.reorder_particles();
                }
            }
            Phase::NewestMasses => self.newest_masses(self.particles.n_sleep),
            Phase::ClearGrid => self.clear_grid(),
            Phase::P2g => self.p2g(di),
            Phase::GridUpdate => self.grid_update(di, step.drive.as_ref()),
            Phase::Loads => {
                if let Some(sl) = &mut self.sleep {
                    sl.take_loads(&self.grid, step.dt, self.step, self.time + step.dt, &*self.material);
                }
            }
            Phase::G2p => self.g2p(dt),
            Phase::FollowFeed => self.follow_feed(dt, step.drive.as_ref()),
            Phase::Materials => self.update_materials(dt)?,
        }
        Ok(())
    }

    /// The adjoint of one phase of `step` for one objective's adjoint `a`, after the step was
    /// recomputed into `tape` and the live state; `toolpath` takes the adjoints of the
    /// toolpath's closed forms. Gradient runs freeze the pool order but for the sleep update's
    /// moves, whose adjoint moves the adjoints back.
    pub fn phase_adjoint(&mut self, phase: Phase, step: &Step, tape: &mut Tape, a: &mut Adjoint, toolpath: Option<&mut dyn ToolpathBar>) -> Result<(), AdjointError> {
        let dt = step.dt as Real;
        // the forward's impulse step: the adjoints carry the same mass scaling
        let di = self.impulse_dt(step.dt);
        match phase {
            Phase::Emit => self.emission_adjoint(step, a, toolpath)?,
            Phase::NewestMasses => self.newest_masses_adjoint(a, toolpath),
            Phase::P2g => self.p2g_adjoint(tape, a, di),
            Phase::GridUpdate => self.grid_update_adjoint(step.drive.as_ref(), tape, a, di, toolpath),
            Phase::G2p => self.g2p_adjoint(tape, a, dt),
            Phase::FollowFeed => self.follow_feed_adjoint(a, dt),
            Phase::Materials => self.materials_adjoint(tape, a, dt),
            Phase::Sleep => self.sleep_adjoint(step.moved, tape, a)?,
            Phase::Bin | Phase::Reorder | Phase::ClearGrid | Phase::Loads => {}
        }
        Ok(())
    }

    /// Add the step's work of gravity and the body force on the true masses to
    /// `external_work`: dt sum_p m_p a . v_p over the awake particles with the velocities G2P
    /// just gave them (the ones the positions moved with; sleeping particles are at rest). A
    /// serial sum in pool order: the same for any thread count, no allocation, a few flops per
    /// awake particle against the hundreds of the transfers. It reads the state and never
    /// writes it, so the state (and its hash) is unchanged.
    fn accumulate_external_work(&mut self, dt: f64) {
        let p = &self.particles;
        let a = [self.accel.x as f64, self.accel.y as f64, self.accel.z as f64];
        let (v, m) = (&p.v.as_slice()[p.n_sleep..p.n], &p.mass.as_slice()[p.n_sleep..p.n]);
        let mut power = 0.0;
        for (v, &m) in v.iter().zip(m) {
            power += m as f64 * (a[0] * v.x as f64 + a[1] * v.y as f64 + a[2] * v.z as f64);
        }
        self.external_work += dt * power;
    }

    /// Sleeping units fall asleep and wake; returns whether particles moved between the awake
    /// and sleeping ranges. Counts the awake particles the step works on.
    fn sleep_update(&mut self, drive: Option<&NozzleDrive>) -> bool {
        let mut moved = false;
        if let Some(sl) = &mut self.sleep {
            if self.step > 0 {
                let check = self.step.is_multiple_of(sl.cfg.check_interval);
                let mat = &*self.material;
                // A still nozzle (a pause) holds its tube's nodes at rest, as sleeping material's held
                // nodes are: material resting under or in it may sleep through the dwell.
                let moving_tube = drive.filter(|d| d.velocity != [0.0; 3]).map(|d| d.bounds());
                moved = sl.update(&self.grid, &mut self.particles, mat, self.last_dt, self.time, self.step, check, moving_tube);
            }
        }
        self.awake_particle_steps += (self.particles.n - self.particles.n_sleep) as u64;
        moved
    }
}

/// An upper bound on the shear rate gamma_dot = sqrt(2 D':D') MLS-MPM can give a particle when
/// no grid node moves faster than `speed`: with quadratic B-splines, C = (4 / dx^2) sum_i w_i v_i
/// (x_i - x_p)^T, sum_i w_i = 1 and sum_i w_i |x_i - x_p|^2 = 3 dx^2 / 4, so by Cauchy-Schwarz
/// |C|_F <= 2 sqrt(3) speed / dx, and gamma_dot <= sqrt(2) |D|_F <= sqrt(2) |C|_F. The step
/// control passes the particles' largest speed, as the wave bound does.
pub fn max_shear_rate(speed: f64, dx: f64) -> f64 {
    2.0 * 6f64.sqrt() * speed / dx
}

// `phase_seconds` is indexed by a phase's discriminant: the variants stand in `PHASES`' order
const _: () = {
    let mut i = 0;
    while i < PHASES.len() {
        assert!(PHASES[i] as usize == i);
        i += 1;
    }
};
