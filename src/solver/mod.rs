//! The MLS-MPM step (paper 000 eqs. 8-17):
//!
//! ```text
//! bin particles by block ─▶ clear grid ─▶ P2G (8 colours) ─▶ grid update ─▶ G2P ─▶ materials
//! ```
//!
//! Every buffer is a mapped pool sized at start-up; the step allocates nothing. P2G runs the 8
//! block colours one after the other: blocks of one colour never write the same nodes, so
//! threads add into the grid without atomics, and each node receives its sums in the same order
//! whatever the thread count, which makes runs bit-identical for any number of threads.

use crate::grid::{Grid, GridGeom, NODES_PER_BLOCK, PAD};
use crate::kernels::boundary::{apply_wall, WallKind};
use crate::kernels::material::Material;
use crate::kernels::transfer::{g2p_block, local_index, p2g_block, G2pOutput, Node, P2gInput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_EDGE, NEIGHBOURHOOD_NODES};
use crate::kernels::{Real, M3, V3};
use crate::materials::build_material;
use crate::memory::{parse_size, Backing, MemoryError, MemoryPlan, Pool};
use crate::particles::Particles;
use crate::print::emitter::Slab;
use crate::print::{NozzleDrive, Printer};
use crate::scenario::{Body, Scenario};
use crate::sleep::{unit_in_block, Sleep, UnitActivity, EMPTY_UNIT, UNITS};
use crate::threads::{SharedSlice, ThreadTeam};
use std::sync::atomic::{AtomicU64, Ordering};

pub const MAX_THREADS: usize = 64;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Memory(#[from] MemoryError),
    #[error("{0}")]
    Setup(String),
    #[error("blow-up at step {step} (t = {time:.6e} s): particle {index} (id {id}) has {field} = {value}; \
             try a smaller simulation.cfl or simulation.dt")]
    BlowUp { step: u64, time: f64, index: usize, id: u32, field: &'static str, value: String },
}

/// Which bound set the time step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DtLimit {
    Fixed,
    Wave,
    Viscous,
    MaxDt,
    /// Shortened to land exactly on an output time or the end.
    Schedule,
}

impl DtLimit {
    const ALL: [DtLimit; 5] = [DtLimit::Fixed, DtLimit::Wave, DtLimit::Viscous, DtLimit::MaxDt, DtLimit::Schedule];

    pub fn name(self) -> &'static str {
        match self {
            DtLimit::Fixed => "fixed",
            DtLimit::Wave => "wave",
            DtLimit::Viscous => "viscous",
            DtLimit::MaxDt => "max_dt",
            DtLimit::Schedule => "schedule",
        }
    }

    pub fn from_name(s: &str) -> Option<DtLimit> {
        Self::ALL.into_iter().find(|l| l.name() == s)
    }
}

/// Buffers the binning and the parallel phases share.
pub(crate) struct Scratch {
    /// Slot of each particle's block.
    pub(crate) pslot: Pool<u32>,
    /// Particle indices grouped by particle block (a stable counting sort).
    pub(crate) order: Pool<u32>,
    /// First `order` entry of each particle block; `n_particle_blocks + 1` entries used.
    pub(crate) slot_start: Pool<u32>,
    cursor: Pool<u32>,
    /// Slots of the 2x2x2 block neighbourhood of each particle block.
    pub(crate) nbr: Pool<[u32; 8]>,
    /// Particle blocks grouped by colour, and the running particle count before each.
    pub(crate) colour_blocks: Pool<u32>,
    pub(crate) colour_cum: Pool<u32>,
    pub(crate) colour_start: [usize; 9],
    permute: Pool<u8>,
}

impl Scratch {
    fn plan(plan: &mut MemoryPlan, cap: usize, max_blocks: usize, state_len: usize) {
        plan.add::<u32>("scratch.pslot", cap);
        plan.add::<u32>("scratch.order", cap);
        plan.add::<u32>("scratch.slot_start", max_blocks + 1);
        plan.add::<u32>("scratch.cursor", max_blocks);
        plan.add::<[u32; 8]>("scratch.neighbours", max_blocks);
        plan.add::<u32>("scratch.colour_blocks", max_blocks);
        plan.add::<u32>("scratch.colour_cum", max_blocks);
        plan.add::<u8>("scratch.permute", Particles::permute_scratch_bytes(cap, state_len));
    }
    fn new(cap: usize, max_blocks: usize, state_len: usize, b: &Backing) -> Result<Self, MemoryError> {
        Ok(Scratch {
            pslot: Pool::new("scratch.pslot", cap, b)?,
            order: Pool::new("scratch.order", cap, b)?,
            slot_start: Pool::new("scratch.slot_start", max_blocks + 1, b)?,
            cursor: Pool::new("scratch.cursor", max_blocks, b)?,
            nbr: Pool::new("scratch.neighbours", max_blocks, b)?,
            colour_blocks: Pool::new("scratch.colour_blocks", max_blocks, b)?,
            colour_cum: Pool::new("scratch.colour_cum", max_blocks, b)?,
            colour_start: [0; 9],
            permute: Pool::new("scratch.permute", Particles::permute_scratch_bytes(cap, state_len), b)?,
        })
    }
}

/// Wall conditions resolved for the grid update.
#[derive(Clone, Debug)]
pub(crate) struct Walls {
    /// [axis][0 = min side, 1 = max side]
    pub(crate) faces: [[WallKind; 2]; 3],
    /// Platform: grid-coordinate top z, xy extent in grid coordinates, kind.
    pub(crate) platform: Option<(Real, [Real; 4], WallKind)>,
}

pub struct Simulation {
    pub scenario: Scenario,
    pub material: Box<dyn Material>,
    pub particles: Particles,
    pub grid: Grid,
    pub(crate) scratch: Scratch,
    pub(crate) team: ThreadTeam,
    pub(crate) walls: Walls,
    /// Gravity plus body force per unit mass.
    pub(crate) accel: V3,
    pub time: f64,
    pub step: u64,
    /// Largest particle speed after the last G2P.
    pub vmax: f64,
    pub last_dt: f64,
    pub last_limit: DtLimit,
    pub memory: MemoryPlan,
    pub budget: u64,
    thread_out: [AtomicU64; MAX_THREADS],
    /// Wall time spent in each phase of the step, in the order of [`PHASES`].
    pub phase_seconds: [f64; 6],
    /// The printing process, when the scenario prints.
    pub printer: Option<Printer>,
    /// Sleeping blocks, when enabled.
    pub sleep: Option<Sleep>,
    /// Awake particles summed over the steps taken: the work the step loops did, a cost
    /// measure no other job on the machine can distort.
    pub awake_particle_steps: u64,
    /// Keep the pool order fixed (no reordering by block): the gradient driver indexes its
    /// adjoint arrays by pool position, which must then mean the same particle in every step.
    pub frozen_order: bool,
    /// Solid bodies inside the domain (`src/solid/`; issue 30 hook), None without `[[solid]]`.
    pub solids: Option<crate::solid::Solids>,
}

/// Names of the step's phases, as accumulated in `Simulation::phase_seconds`.
pub const PHASES: [&str; 6] = ["emit+sleep+bin+reorder", "clear grid", "P2G", "grid update", "G2P", "materials"];

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
    /// Size every pool from the scenario, check the budget, map the pools and create the
    /// initial particles.
    pub fn new(scenario: &Scenario) -> Result<Self, SimError> {
        scenario.validate().map_err(|e| SimError::Setup(e.to_string()))?;
        let material = build_material(&scenario.material).map_err(SimError::Setup)?;
        let geom = GridGeom::new(scenario.simulation.dx, scenario.domain.min, scenario.domain.max, scenario.domain.periodic);
        let state_len = material.state_names().len();

        let printer = match &scenario.print {
            Some(cfg) => {
                let d = &scenario.domain;
                Some(Printer::new(cfg, scenario.simulation.dx, (d.min, d.max), &scenario.base_dir).map_err(SimError::Setup)?)
            }
            None => None,
        };
        if let Some(p) = &printer {
            check_print_inside_domain(scenario, p)?;
        }
        let initial = count_body_particles(scenario);
        let emitted = printer.as_ref().map_or(0, |p| p.plan.total_particles() as usize);
        let cap = scenario.memory.max_particles.unwrap_or(initial + emitted).max(1);
        if initial + emitted > cap {
            return Err(SimError::Setup(format!(
                "particle pool: the scenario needs {} particles ({initial} initial + {emitted} emitted by the whole print) \
                 but [memory] max_particles = {cap}; raise it or leave it out to size the pool for the whole print",
                initial + emitted
            )));
        }
        let max_blocks = scenario.memory.max_blocks.unwrap_or(geom.table_len()).max(8);
        let budget = parse_size(&scenario.memory.budget)?;
        let mut memory = MemoryPlan::default();
        Particles::plan(&mut memory, cap, state_len);
        Grid::plan(&mut memory, &geom, max_blocks);
        Scratch::plan(&mut memory, cap, max_blocks, state_len);
        crate::solid::Solids::plan(&mut memory, scenario.solids.len(), max_blocks); // solids hook (issue 30)
        if let Some(cfg) = &scenario.sleep {
            Sleep::plan(&mut memory, cfg, &geom, max_blocks, cap, scenario.simulation.gravity);
        }
        if let Some(p) = &printer {
            let q = scenario.print.as_ref().map_or(0, |c| c.queue);
            memory.add::<[f64; 3]>("emission.queue", (q + 1) * p.plan.particles_per_slab());
        }
        memory.check(budget)?;

        let backing = Backing { dir: scenario.memory.dir.clone() };
        if let Some(d) = &backing.dir {
            std::fs::create_dir_all(d)
                .map_err(|e| SimError::Setup(format!("memory.dir {}: {e}", d.display())))?;
        }
        let particles = Particles::new(cap, state_len, &backing)?;
        let grid = Grid::new(geom, max_blocks, &backing)?;
        let scratch = Scratch::new(cap, max_blocks, state_len, &backing)?;
        let sleep = match &scenario.sleep {
            Some(cfg) => Some(Sleep::new(cfg.clone(), &grid.geom, max_blocks, cap, scenario.simulation.gravity, &backing)?),
            None => None,
        };

        // solids hook (issue 30)
        let nozzle = printer.as_ref().and_then(|p| match p.shape {
            crate::print::nozzle::NozzleShape::Circle { diameter } => Some((diameter, p.tube_height)),
            _ => None,
        });
        let solids = crate::solid::Solids::new(&scenario.solids, scenario.simulation.dx, nozzle, max_blocks, &backing).map_err(SimError::Setup)?;

        let threads = match scenario.simulation.threads {
            0 => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            t => t,
        }
        .min(MAX_THREADS);

        let s = &scenario.simulation;
        let rho = material.density() as f64;
        let accel = V3::new(
            (s.gravity[0] + s.body_force[0] / rho) as Real,
            (s.gravity[1] + s.body_force[1] / rho) as Real,
            (s.gravity[2] + s.body_force[2] / rho) as Real,
        );
        let b = &scenario.boundary;
        let walls = Walls {
            faces: [[b.x_min, b.x_max], [b.y_min, b.y_max], [b.z_min, b.z_max]],
            platform: b.platform.as_ref().map(|p| {
                let g = &grid.geom;
                let lo = g.to_grid([p.xy_min[0], p.xy_min[1], p.z]);
                let hi = g.to_grid([p.xy_max[0], p.xy_max[1], p.z]);
                (lo.z, [lo.x, lo.y, hi.x, hi.y], p.kind)
            }),
        };

        let mut sim = Simulation {
            scenario: scenario.clone(),
            material,
            particles,
            grid,
            scratch,
            team: ThreadTeam::new(threads),
            walls,
            accel,
            time: 0.0,
            step: 0,
            vmax: 0.0,
            last_dt: 0.0,
            last_limit: DtLimit::Fixed,
            memory,
            budget,
            thread_out: std::array::from_fn(|_| AtomicU64::new(0)),
            phase_seconds: [0.0; 6],
            printer,
            sleep,
            awake_particle_steps: 0,
            frozen_order: false,
            solids,
        };
        if let Some(p) = &mut sim.printer {
            p.start(scenario.print.as_ref().map_or(64, |c| c.queue), 0);
        }
        for body in &scenario.bodies {
            sim.add_body(body)?;
        }
        sim.vmax = sim.particles.v.as_slice()[..sim.particles.n].iter().map(|v| v.length() as f64).fold(0.0, f64::max);
        Ok(sim)
    }

    pub fn threads(&self) -> usize {
        self.team.threads()
    }

    /// Fill a body with particles on a lattice of `ppc^3` points per cell.
    fn add_body(&mut self, body: &Body) -> Result<(), SimError> {
        let dx = self.scenario.simulation.dx;
        let ppc = body.particles_per_cell_axis();
        let vol = (dx / ppc as f64).powi(3);
        let vel = body.velocity();
        let mut err = None;
        let sc = self.scenario.clone();
        for_each_lattice_point(&sc, body, |p| {
            if err.is_none() {
                err = self.add_particle(p, vel, vol).err();
            }
        });
        err.map_or(Ok(()), Err)
    }

    /// Add one particle at world position `x` with velocity `v` and initial volume `vol0`.
    pub fn add_particle(&mut self, x: [f64; 3], v: [f64; 3], vol0: f64) -> Result<usize, SimError> {
        let xg = self.grid.geom.to_grid(x);
        let rho = self.material.density() as f64;
        let i = self.particles.push(xg, V3::new(v[0] as Real, v[1] as Real, v[2] as Real), (rho * vol0) as Real, vol0 as Real)?;
        let s = self.particles.state_len;
        self.material.init_state(&mut self.particles.state.as_mut_slice()[i * s..(i + 1) * s]);
        Ok(i)
    }

    /// The time step for the next step and the bound that set it.
    pub fn choose_dt(&self, until: f64) -> (f64, DtLimit) {
        let s = &self.scenario.simulation;
        let (mut dt, mut limit) = match s.dt {
            Some(dt) => (dt, DtLimit::Fixed),
            None => {
                let st = self.material.stability();
                let rho = st.density as f64;
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

    /// The first half of a step: emission, sleeping, binning, P2G and the grid update. Between
    /// the halves the rest of the step needs only the grid's node velocities, and per particle
    /// x, J, the material state and id (v too with FLIP): C and stress are rebuilt by G2P and
    /// the material update. That is where restart checkpoints are taken
    /// (`checkpoint/state.rs`).
    pub fn begin_step(&mut self, dt: f64) -> Result<(), SimError> {
        let mut clock = PhaseClock::start();
        self.emit()?;
        let drive = self.printer.as_ref().and_then(|p| p.drive(self.time));
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
        self.bin_particles()?;
        if !self.frozen_order && (moved || self.step.is_multiple_of(self.scenario.simulation.reorder_interval)) {
            self.reorder_particles();
        }
        self.newest_masses(self.particles.n_sleep);
        clock.lap(&mut self.phase_seconds[0]);
        self.clear_grid();
        clock.lap(&mut self.phase_seconds[1]);
        self.p2g(dt as Real);
        clock.lap(&mut self.phase_seconds[2]);
        self.grid_update(dt as Real, drive.as_ref());
        if let Some(sl) = &mut self.sleep {
            sl.take_loads(&self.grid, dt, self.step, self.time + dt, &*self.material);
        }
        clock.lap(&mut self.phase_seconds[3]);
        Ok(())
    }

    /// The second half of a step begun by [`Simulation::begin_step`] with the same `dt` (or put
    /// back by a checkpoint restore): G2P, the newest slab's blend, the material update.
    pub fn finish_step(&mut self, dt: f64) -> Result<(), SimError> {
        let mut clock = PhaseClock::start();
        let drive = self.printer.as_ref().and_then(|p| p.drive(self.time));
        self.g2p(dt as Real);
        self.follow_feed(dt as Real, drive.as_ref());
        clock.lap(&mut self.phase_seconds[4]);
        self.update_materials(dt as Real)?;
        clock.lap(&mut self.phase_seconds[5]);
        self.step += 1;
        self.time += dt;
        Ok(())
    }

    /// Add the emitter's slabs that are due by now, and note which slab is the newest and what
    /// fraction of it has been extruded.
    pub(crate) fn emit(&mut self) -> Result<(), SimError> {
        let Some(pr) = &mut self.printer else { return Ok(()) };
        let t = self.time;
        let vol = pr.particle_volume;
        let (before, id_before) = (pr.emitted(), self.particles.next_id);
        let (geom, particles, mat) = (&self.grid.geom, &mut self.particles, &*self.material);
        let add = |slab: &Slab| add_slab(geom, particles, mat, vol, t, slab);
        if let Some(sync) = &mut pr.sync {
            sync.drain_due(&pr.plan, t, add)?;
        } else if let Some(em) = &mut pr.emitter {
            em.drain_due(t, add)?;
        }
        note_newest(pr, t, self.particles.next_id, before, id_before);
        Ok(())
    }

    /// Set the masses emission changed this step among particles `from..` (see
    /// `print/newest.rs`); after reordering.
    pub(crate) fn newest_masses(&mut self, from: usize) {
        if let Some(pr) = &mut self.printer {
            let rho = self.material.density() as f64;
            pr.newest.set_masses(&mut self.particles, rho, pr.particle_volume, from);
        }
    }

    /// After G2P: the newest slab moves with the feed in proportion to what is still in it.
    pub(crate) fn follow_feed(&mut self, dt: Real, drive: Option<&NozzleDrive>) {
        if let Some(pr) = &mut self.printer {
            let v = drive.map_or([0.0; 3], |d| d.velocity);
            let inv_dx = (1.0 / self.scenario.simulation.dx) as Real;
            pr.newest.follow_feed(&mut self.particles, dt, inv_dx, V3::new(v[0] as Real, v[1] as Real, v[2] as Real));
        }
    }

    /// Bin particles by the block of their stencil base, activate each particle block's 2x2x2
    /// neighbourhood, and group particle blocks by colour. Serial: it is a few operations per
    /// particle, and doing it in one order makes slot numbering deterministic.
    pub(crate) fn bin_particles(&mut self) -> Result<(), SimError> {
        let n = self.particles.n;
        let first = self.particles.n_sleep;
        let grid = &mut self.grid;
        let sc = &mut self.scratch;
        grid.reset();
        // each particle's block key, in parallel; slots are then handed out serially in particle
        // order, so that they do not depend on the number of threads
        let pslot = sc.pslot.as_mut_slice();
        let (xg, geom) = (&self.particles.xg.as_slice()[first..n], &grid.geom);
        self.team.for_each_share(&mut pslot[first..n], 1, |r, keys| {
            for (key, &x) in keys.iter_mut().zip(&xg[r]) {
                *key = geom.block_index(geom.particle_block(x));
            }
        });
        let count = sc.cursor.as_mut_slice();
        let mut last_key = u32::MAX;
        let mut last_slot = 0u32;
        for p in first..n {
            let key = pslot[p];
            if key != last_key {
                let before = grid.n_active;
                last_slot = grid.activate(key)?;
                if grid.n_active > before {
                    count[last_slot as usize] = 0;
                }
                last_key = key;
            }
            count[last_slot as usize] += 1;
            pslot[p] = last_slot;
        }
        let npb = grid.n_active;
        grid.n_particle_blocks = npb;

        // neighbourhoods and colours
        let mut per_colour = [0usize; 8];
        for s in 0..npb {
            let b = grid.geom.block_coords(grid.slot_block.as_slice()[s]);
            let mut nb = [0u32; 8];
            for (d, slot) in nb.iter_mut().enumerate() {
                let o = [(d >> 2) as i32 & 1, (d >> 1) as i32 & 1, d as i32 & 1];
                let w = grid.geom.wrap_block([b[0] + o[0], b[1] + o[1], b[2] + o[2]]);
                *slot = grid.activate(grid.geom.block_index(w))?;
            }
            sc.nbr.as_mut_slice()[s] = nb;
            per_colour[colour(b)] += 1;
        }
        let mut cs = [0usize; 9];
        for c in 0..8 {
            cs[c + 1] = cs[c] + per_colour[c];
        }
        sc.colour_start = cs;

        // counting sort of particles by slot (stable)
        let starts = sc.slot_start.as_mut_slice();
        let mut acc = 0u32;
        for s in 0..npb {
            let c = count[s];
            starts[s] = acc;
            count[s] = acc; // becomes the write cursor
            acc += c;
        }
        starts[npb] = acc;
        let order = sc.order.as_mut_slice();
        for p in first..n {
            let s = pslot[p] as usize;
            order[count[s] as usize] = p as u32;
            count[s] += 1;
        }

        // colour lists, with running particle counts for load balance
        let mut fill = cs;
        let blocks = sc.colour_blocks.as_mut_slice();
        let cum = sc.colour_cum.as_mut_slice();
        let mut run = [0u32; 8];
        for s in 0..npb {
            let c = colour(grid.geom.block_coords(grid.slot_block.as_slice()[s]));
            blocks[fill[c]] = s as u32;
            cum[fill[c]] = run[c];
            run[c] += starts[s + 1] - starts[s];
            fill[c] += 1;
        }
        Ok(())
    }

    /// Move particles into block order so the transfers stream through memory.
    pub(crate) fn reorder_particles(&mut self) {
        let (first, n) = (self.particles.n_sleep, self.particles.n);
        self.particles.permute(&self.scratch.order.as_slice()[..n - first], self.scratch.permute.as_mut_slice(), &self.team);
        for (k, o) in self.scratch.order.as_mut_slice()[..n - first].iter_mut().enumerate() {
            *o = (first + k) as u32;
        }
    }

    pub(crate) fn clear_grid(&mut self) {
        let n = self.grid.n_active * NODES_PER_BLOCK;
        self.team.for_each_share(&mut self.grid.nodes.as_mut_slice()[..n], 1, |_, nodes| nodes.fill([0.0; 7]));
    }

    pub(crate) fn p2g(&mut self, dt: Real) {
        let p = &self.particles;
        let n = p.n;
        let input = P2gInput {
            xg: &p.xg.as_slice()[..n],
            v: &p.v.as_slice()[..n],
            c: &p.c.as_slice()[..n],
            stress: &p.stress.as_slice()[..n],
            mass: &p.mass.as_slice()[..n],
            vol0: &p.vol0.as_slice()[..n],
            j: &p.j.as_slice()[..n],
        };
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &self.scratch;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let threads = self.team.threads();
        let split = self.scenario.simulation.flip > 0.0;
        for c in 0..8 {
            let (c0, c1) = (sc.colour_start[c], sc.colour_start[c + 1]);
            if c0 == c1 {
                continue;
            }
            let blocks = &sc.colour_blocks.as_slice()[c0..c1];
            let cum = &sc.colour_cum.as_slice()[c0..c1];
            let starts = sc.slot_start.as_slice();
            let last = *blocks.last().unwrap() as usize;
            let total = cum[cum.len() - 1] + (starts[last + 1] - starts[last]);
            let order = sc.order.as_slice();
            let nbr = sc.nbr.as_slice();
            self.team.run(|tid| {
                let (lo, hi) = balanced(cum, total, tid, threads);
                let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                for &s in &blocks[lo..hi] {
                    let s = s as usize;
                    let b = geom.block_coords(slot_block[s]);
                    let origin = [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32];
                    local.iter_mut().for_each(|n| *n = [0.0; 7]);
                    let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                    if split {
                        p2g_block::<true>(origin, ord, &input, &tp, &mut local);
                    } else {
                        p2g_block::<false>(origin, ord, &input, &tp, &mut local);
                    }
                    // SAFETY: blocks of one colour have disjoint 2x2x2 neighbourhoods.
                    unsafe { flush_local(&local, &nbr[s], &nodes) };
                }
            });
        }
    }

    /// Momentum to velocity, gravity, sleeping holds, the nozzle `drive` of this step, walls.
    pub(crate) fn grid_update(&mut self, dt: Real, drive: Option<&NozzleDrive>) {
        let na = self.grid.n_active;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let accel = self.accel;
        let walls = &self.walls;
        let table = self.grid.table.as_slice();
        let threads = self.team.threads();
        let drive_box = drive.map(|d| d.bounds());
        // solids hook (issue 30): placements now, and a reaction slot per block and solid
        let toolpath = self.printer.as_ref().map(|p| &*p.toolpath);
        let (solids, solid_reactions) = match self.solids.as_mut() {
            Some(z) => {
                let (at, r) = z.for_grid_update(self.time, toolpath);
                (Some(at), Some(SharedSlice::new(r)))
            }
            None => (None, None),
        };
        // reactions only for the load test: the speed rule needs just the holds
        let (holds, reactions) = match self.sleep.as_mut() {
            Some(z) => {
                let loads = z.tests_loads();
                let (h, r) = z.holds_and_reactions();
                (Some(h), loads.then(|| SharedSlice::new(r)))
            }
            None => (None, None),
        };
        self.team.run(|tid| {
            for s in ThreadTeam::share(na, tid, threads) {
                let b = geom.block_coords(slot_block[s]);
                let window = holds.as_ref().and_then(|z| z.block(geom, b));
                let driven = drive_box.is_some_and(|bx| geom.block_overlaps(b, bx));
                // SAFETY: each slot belongs to one thread.
                let blk = unsafe { nodes.slice_mut(s * NODES_PER_BLOCK..(s + 1) * NODES_PER_BLOCK) };
                // the reaction of each held node: the momentum holding it removes, over dt
                let mut held = match (&reactions, &window) {
                    // SAFETY: as for the nodes
                    (Some(r), Some(_)) => Some(unsafe { r.slice_mut(s * NODES_PER_BLOCK..(s + 1) * NODES_PER_BLOCK) }),
                    _ => None,
                };
                // solids hook (issue 30)
                let solid_mask = solids.as_ref().map_or(0, |z| z.block_mask(geom, b));
                let n_solids = solids.as_ref().map_or(0, |z| z.len());
                // SAFETY: as for the nodes
                let mut solid_react = solid_reactions.as_ref().map(|r| unsafe { r.slice_mut(s * n_solids..(s + 1) * n_solids) });
                if let Some(r) = solid_react.as_deref_mut() {
                    r.fill([0.0; 3]);
                }
                for (li, node) in blk.iter_mut().enumerate() {
                    if let Some(h) = held.as_mut() {
                        h[li] = [0.0; 3];
                    }
                    let m = node[0];
                    if m <= 0.0 {
                        *node = [0.0; 7];
                        continue;
                    }
                    let g = geom.node_of(b, li);
                    let old = V3::new(node[1], node[2], node[3]) / m;
                    let mut v = old + V3::new(node[4], node[5], node[6]) / m + accel * dt;
                    if window.as_ref().is_some_and(|w| w.holds(li)) {
                        if let Some(h) = held.as_mut() {
                            let f = v * (m / dt);
                            h[li] = [f.x as f32, f.y as f32, f.z as f32];
                        }
                        v = V3::ZERO;
                    }
                    if driven {
                        v = apply_drive(geom, drive, g, v);
                    }
                    v = apply_walls(geom, walls, g, v);
                    if let (Some(z), Some(r)) = (solids.as_ref().filter(|_| solid_mask != 0), solid_react.as_deref_mut()) {
                        v = z.apply(solid_mask, geom.node_position(g), m, v, r); // solids hook (issue 30)
                    }
                    *node = [m, v.x, v.y, v.z, old.x, old.y, old.z];
                }
            }
        });
        // Ghost nodes beyond no-slip and free-slip walls take the mirror image of the velocity
        // inside, so G2P sees a field that is odd (no-slip) or has an odd normal part (free-slip)
        // across the wall. Zeroing them instead destroys the momentum of the material near the
        // wall once per step: a drag proportional to the number of steps, not to time (measured:
        // a channel flow lost 20-70 % of its speed as dt shrank).
        self.team.run(|tid| {
            for s in ThreadTeam::share(na, tid, threads) {
                let b = geom.block_coords(slot_block[s]);
                if !geom.block_reaches_beyond_walls(b) {
                    continue;
                }
                for li in 0..NODES_PER_BLOCK {
                    let g = geom.node_of(b, li);
                    // SAFETY: this pass writes only ghost nodes and reads only nodes that are
                    // not ghosts on any axis; each ghost node belongs to one slot and thread.
                    unsafe { mirror_ghost(geom, walls, g, s * NODES_PER_BLOCK + li, &nodes, table) };
                }
            }
        });
        if let Some(z) = self.solids.as_mut() {
            z.total_forces(na, dt as f64); // solids hook (issue 30)
        }
    }

    pub(crate) fn g2p(&mut self, dt: Real) {
        let npb = self.grid.n_particle_blocks;
        let n = self.particles.n;
        let p = &mut self.particles;
        let xg = SharedSlice::new(&mut p.xg.as_mut_slice()[..n]);
        let v = SharedSlice::new(&mut p.v.as_mut_slice()[..n]);
        let c = SharedSlice::new(&mut p.c.as_mut_slice()[..n]);
        let j = SharedSlice::new(&mut p.j.as_mut_slice()[..n]);
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &self.scratch;
        let starts = &sc.slot_start.as_slice()[..npb + 1];
        let order = sc.order.as_slice();
        let nbr = sc.nbr.as_slice();
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = self.grid.nodes.as_slice();
        let threads = self.team.threads();
        let platform = self.walls.platform;
        let flip = self.scenario.simulation.flip as Real;
        let j_bar = self.scenario.simulation.j_bar.then_some(&p.vol0.as_slice()[..n]);
        let out = &self.thread_out;
        let activity = self.sleep.as_mut().map(|z| SharedSlice::new(&mut z.activity.as_mut_slice()[..npb]));
        self.team.run(|tid| {
            let (lo, hi) = balanced(&starts[..npb], starts[npb], tid, threads);
            let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
            let mut vmax: Real = 0.0;
            for s in lo..hi {
                let b = geom.block_coords(slot_block[s]);
                let origin = [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32];
                gather_local(&mut local, &nbr[s], nodes);
                let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                // SAFETY: every particle belongs to exactly one particle block, and each block to
                // one thread, so the indices written here are disjoint across threads.
                let mut o = unsafe { G2pOutput { xg: xg.slice_mut(0..n), v: v.slice_mut(0..n), c: c.slice_mut(0..n), j: j.slice_mut(0..n) } };
                vmax = vmax.max(g2p_block(origin, ord, &local, flip, j_bar, &tp, &mut o));
                for &pi in ord {
                    keep_inside(geom, platform, &mut o.xg[pi as usize]);
                }
                if let Some(act) = &activity {
                    // SAFETY: slot s belongs to this thread.
                    unsafe { *act.get_mut(s) = unit_activity(origin, ord, &*o.xg, &*o.v, &*o.c) };
                }
            }
            out[tid].store((vmax as f64).to_bits(), Ordering::Relaxed);
        });
        self.vmax = (0..threads).map(|t| f64::from_bits(out[t].load(Ordering::Relaxed))).fold(0.0, f64::max);
    }

    /// Material update over contiguous particle ranges, then a finiteness check that names the
    /// first bad particle.
    pub(crate) fn update_materials(&mut self, dt: Real) -> Result<(), SimError> {
        let (first, n) = (self.particles.n_sleep, self.particles.n);
        let p = &mut self.particles;
        let sl = p.state_len;
        let c = &p.c.as_slice()[..n];
        let jv = &p.j.as_slice()[..n];
        let vv = &p.v.as_slice()[..n];
        let state = SharedSlice::new(&mut p.state.as_mut_slice()[..n * sl]);
        let stress = SharedSlice::new(&mut p.stress.as_mut_slice()[..n]);
        let mat = &*self.material;
        let threads = self.team.threads();
        let out = &self.thread_out;
        self.team.run(|tid| {
            let r = ThreadTeam::share(n - first, tid, threads);
            let r = first + r.start..first + r.end;
            // SAFETY: ranges are disjoint.
            let (st, sg) = unsafe { (state.slice_mut(r.start * sl..r.end * sl), stress.slice_mut(r.clone())) };
            mat.update_batch(&c[r.clone()], &jv[r.clone()], dt, st, sg);
            let mut bad = u64::MAX;
            for i in r.clone() {
                let s = &sg[i - r.start];
                if !(jv[i] > 0.0 && jv[i].is_finite() && vv[i].is_finite() && s.is_finite()) {
                    bad = i as u64;
                    break;
                }
            }
            out[tid].store(bad, Ordering::Relaxed);
        });
        let bad = (0..threads).map(|t| out[t].load(Ordering::Relaxed)).min().unwrap_or(u64::MAX);
        if bad != u64::MAX {
            let i = bad as usize;
            let p = &self.particles;
            let sci = scientific;
            let (field, value) = if !p.v.as_slice()[i].is_finite() {
                ("velocity", format!("[{}]", sci(&p.v.as_slice()[i].to_array())))
            } else if !(p.j.as_slice()[i] > 0.0 && p.j.as_slice()[i].is_finite()) {
                ("volume ratio J", sci(&[p.j.as_slice()[i]]))
            } else {
                ("stress", format!("[{}]", sci(&p.stress.as_slice()[i].to_cols_array())))
            };
            return Err(SimError::BlowUp { step: self.step, time: self.time, index: i, id: p.id.as_slice()[i], field, value });
        }
        Ok(())
    }

    /// World position of particle `i`.
    pub fn position(&self, i: usize) -> [f64; 3] {
        self.grid.geom.to_world(self.particles.xg.as_slice()[i])
    }

    /// Pressure -tr(sigma)/3 of particle `i`.
    pub fn pressure(&self, i: usize) -> f64 {
        let s: M3 = self.particles.stress.as_slice()[i];
        -((s.x_axis.x + s.y_axis.y + s.z_axis.z) / 3.0) as f64
    }
}

/// Note which slab is the newest at time `t` and what fraction of it has been extruded, after
/// emission took the slab count from `before` (the next particle id then `id_before`) to the
/// printer's `emitted()` (the next id now `next_id`). Derived from the slab counts and ids
/// alone: ids are creation order, whether or not merging has removed particles since.
pub(crate) fn note_newest(pr: &mut Printer, t: f64, next_id: u32, before: u64, id_before: u32) {
    let after = pr.emitted();
    let nw = &mut pr.newest;
    if !pr.plan.partial || after == 0 {
        (nw.set_from, nw.moving) = (u32::MAX, false);
        return;
    }
    nw.slab = after - 1;
    nw.first = next_id - pr.plan.count(after - 1) as u32;
    nw.set_from = if after > before && before > 0 { id_before - pr.plan.count(before - 1) as u32 } else { nw.first };
    (nw.fraction, nw.moving) = pr.plan.fraction(after - 1, t);
}

/// Append a slab's particles, moved ballistically from its due time to `t` (inside the tube the
/// grid moves them at exactly that velocity).
fn add_slab(geom: &GridGeom, particles: &mut Particles, mat: &dyn Material, vol: f64, t: f64, slab: &Slab) -> Result<(), MemoryError> {
    let rho = mat.density() as f64;
    let sl = particles.state_len;
    let lag = t - slab.due;
    let v = slab.velocity;
    let vel = V3::new(v[0] as Real, v[1] as Real, v[2] as Real);
    for x in &slab.positions {
        let xg = geom.to_grid([x[0] + lag * v[0], x[1] + lag * v[1], x[2] + lag * v[2]]);
        let i = particles.push(xg, vel, (rho * vol) as Real, vol as Real)?;
        mat.init_state(&mut particles.state.as_mut_slice()[i * sl..(i + 1) * sl]);
    }
    Ok(())
}

#[inline]
pub(crate) fn colour(b: [i32; 3]) -> usize {
    ((b[0] & 1) << 2 | (b[1] & 1) << 1 | (b[2] & 1)) as usize
}

/// Split items with running weights `cum` (exclusive prefix sums, total `total`) into `threads`
/// contiguous shares of about equal weight; returns thread `tid`'s item range.
pub(crate) fn balanced(cum: &[u32], total: u32, tid: usize, threads: usize) -> (usize, usize) {
    let at = |t: usize| {
        let target = (total as u64 * t as u64 / threads as u64) as u32;
        if t == threads {
            cum.len()
        } else if t == 0 {
            0
        } else {
            cum.partition_point(|&c| c < target)
        }
    };
    (at(tid), at(tid + 1))
}

/// Visit the nodes of a particle block's 6^3 neighbourhood as (local index, index in the grid's
/// node pool), walking its 2x2x2 blocks.
#[inline(always)]
fn for_each_neighbourhood_node(nbr: &[u32; 8], mut f: impl FnMut(usize, usize)) {
    for (d, &slot) in nbr.iter().enumerate() {
        let o = [(d >> 2) & 1, (d >> 1) & 1, d & 1];
        let base = slot as usize * NODES_PER_BLOCK;
        let ext = |k: usize| if o[k] == 0 { BLOCK_EDGE } else { NEIGHBOURHOOD_EDGE - BLOCK_EDGE };
        for i in 0..ext(0) {
            for jj in 0..ext(1) {
                for k in 0..ext(2) {
                    f(local_index(o[0] * BLOCK_EDGE + i, o[1] * BLOCK_EDGE + jj, o[2] * BLOCK_EDGE + k), base + (i * BLOCK_EDGE + jj) * BLOCK_EDGE + k);
                }
            }
        }
    }
}

/// Add a P2G neighbourhood buffer into the grid's 2x2x2 blocks.
///
/// # Safety
/// No other thread may touch the blocks in `nbr` meanwhile.
pub(crate) unsafe fn flush_local(local: &[Node; NEIGHBOURHOOD_NODES], nbr: &[u32; 8], nodes: &SharedSlice<Node>) {
    for_each_neighbourhood_node(nbr, |l, g| {
        let dst = nodes.get_mut(g);
        for (d, s) in dst.iter_mut().zip(local[l].iter()) {
            *d += *s;
        }
    });
}

/// Gather the nodes of a particle block's neighbourhood.
pub(crate) fn gather_local(local: &mut [Node; NEIGHBOURHOOD_NODES], nbr: &[u32; 8], nodes: &[Node]) {
    for_each_neighbourhood_node(nbr, |l, g| local[l] = nodes[g]);
}

/// Wall conditions for the node at grid index `g`.
#[inline]
pub(crate) fn apply_walls(geom: &GridGeom, walls: &Walls, g: [i32; 3], v: V3) -> V3 {
    let mut seq = [(WallKind::NoSlip, V3::ZERO, None); 4];
    let k = wall_sequence(geom, walls, g, &mut seq);
    seq[..k].iter().fold(v, |v, &(kind, nrm, _)| apply_wall(kind, nrm, V3::ZERO, v))
}

/// One wall condition at a node: kind, outward normal, and the wall as (axis, side) or None for
/// the platform.
pub(crate) type WallAt = (WallKind, V3, Option<(usize, usize)>);

/// The wall conditions node `g` takes, in the order they apply (one per non-periodic axis whose
/// wall it lies on, then the platform): (kind, outward normal, the wall as (axis, side), or None
/// for the platform). Returns how many; the grid update and its adjoint both walk this list.
pub(crate) fn wall_sequence(geom: &GridGeom, walls: &Walls, g: [i32; 3], out: &mut [WallAt; 4]) -> usize {
    let mut k = 0;
    for a in 0..3 {
        if geom.periodic[a] {
            continue;
        }
        let mut nrm = V3::ZERO;
        if g[a] <= PAD {
            nrm[a] = -1.0;
            out[k] = (walls.faces[a][0], nrm, Some((a, 0)));
            k += 1;
        } else if g[a] >= geom.cells[a] - PAD {
            nrm[a] = 1.0;
            out[k] = (walls.faces[a][1], nrm, Some((a, 1)));
            k += 1;
        }
    }
    if let Some((z, xy, kind)) = walls.platform {
        let (x, y) = (g[0] as Real, g[1] as Real);
        if (g[2] as Real) <= z && x >= xy[0] && x <= xy[2] && y >= xy[1] && y <= xy[3] {
            out[k] = (kind, V3::new(0.0, 0.0, -1.0), None);
            k += 1;
        }
    }
    k
}

/// Blend the nozzle's velocity into a node inside its tube (000 Table 2, line 7).
#[inline]
pub(crate) fn apply_drive(geom: &GridGeom, drive: Option<&NozzleDrive>, g: [i32; 3], v: V3) -> V3 {
    let Some(d) = drive else { return v };
    let x = geom.node_position(g);
    let w = d.weight(x);
    if w <= 0.0 {
        return v;
    }
    let vd = V3::new(d.velocity[0] as Real, d.velocity[1] as Real, d.velocity[2] as Real);
    vd * w + v * (1.0 - w)
}

/// Largest speed and strain rate |sym(C)| of the particles of each sleep unit of a block (by
/// their new stencil base), for the sleep test.
fn unit_activity(origin: [i32; 3], ord: &[u32], xg: &[V3], v: &[V3], c: &[M3]) -> UnitActivity {
    let mut a = [EMPTY_UNIT; UNITS];
    for &pi in ord {
        let pi = pi as usize;
        let e = crate::kernels::real::sym(&c[pi]);
        let rate = (e.x_axis.length_squared() + e.y_axis.length_squared() + e.z_axis.length_squared()).sqrt();
        let u = &mut a[unit_in_block(origin, crate::kernels::bspline::base_and_fx(xg[pi]).0)];
        u[0] = u[0].max(v[pi].length());
        u[1] = u[1].max(rate);
    }
    a
}

/// Start-up check: the tube must stay inside the domain along the whole toolpath, with room above
/// it for the slab that is entering (continuous emission), whose lattice points outside the
/// domain would be lost. It may cross a symmetry plane as long as the nozzle axis itself stays
/// inside.
fn check_print_inside_domain(sc: &Scenario, p: &Printer) -> Result<(), SimError> {
    let (lo, hi) = p.toolpath.bounds();
    let [ex, ey] = p.shape.half_extent();
    let b = &sc.boundary;
    let sides = [[b.x_min, b.x_max], [b.y_min, b.y_max], [b.z_min, b.z_max]];
    let reach = [ex, ey, 0.0];
    for a in 0..3 {
        let lo_need = if sides[a][0] == WallKind::Symmetry { lo[a] } else { lo[a] - reach[a] };
        let hi_need = if sides[a][1] == WallKind::Symmetry { hi[a] } else { hi[a] + reach[a] };
        let feed = if p.plan.partial { p.plan.slab_thickness() } else { 0.0 };
        let hi_need = if a == 2 { hi[a] + p.tube_height + feed } else { hi_need };
        if lo_need < sc.domain.min[a] - 1e-12 || hi_need > sc.domain.max[a] + 1e-12 {
            let what = if a == 2 && feed > 0.0 { "nozzle tube and the slab entering it" } else { "nozzle tube" };
            return Err(SimError::Setup(format!(
                "print: the {what} span [{lo_need:.4}, {hi_need:.4}] m on axis {a} along the toolpath, \
                 outside the domain [{}, {}]",
                sc.domain.min[a], sc.domain.max[a]
            )));
        }
    }
    Ok(())
}

/// Where a ghost node `g` (beyond a wall on at least one axis) takes its velocity from: the pool
/// index of its mirror partner inside (None when the partner's block is inactive, which reads as
/// zero) and the sign of each component (negated for no-slip, the normal one for free-slip; a
/// corner negates once per wall). None when `g` is no ghost, or a ghost of a friction wall, which
/// keeps its own velocity.
pub(crate) fn ghost_source(geom: &GridGeom, walls: &Walls, g: [i32; 3], table: &[u32]) -> Option<(Option<usize>, [Real; 3])> {
    let mut mirror = g;
    let mut sign = [1.0 as Real; 3];
    let mut ghost = false;
    for a in 0..3 {
        if !geom.beyond_wall(a, g[a]) {
            continue;
        }
        let hi = geom.cells[a] - PAD;
        let (side, m) = if g[a] < PAD { (0, 2 * PAD - g[a]) } else { (1, 2 * hi - g[a]) };
        ghost = true;
        mirror[a] = m;
        match walls.faces[a][side] {
            WallKind::NoSlip => sign.iter_mut().for_each(|s| *s = -*s),
            WallKind::FreeSlip | WallKind::Symmetry => sign[a] = -sign[a],
            WallKind::Friction { .. } => return None,
        }
    }
    if !ghost {
        return None;
    }
    let blk = [mirror[0].div_euclid(BLOCK_EDGE as i32), mirror[1].div_euclid(BLOCK_EDGE as i32), mirror[2].div_euclid(BLOCK_EDGE as i32)];
    let slot = table[geom.block_index(blk) as usize];
    let src = (slot != crate::grid::EMPTY).then(|| {
        let l = (mirror[0].rem_euclid(BLOCK_EDGE as i32) as usize * BLOCK_EDGE + mirror[1].rem_euclid(BLOCK_EDGE as i32) as usize) * BLOCK_EDGE
            + mirror[2].rem_euclid(BLOCK_EDGE as i32) as usize;
        slot as usize * NODES_PER_BLOCK + l
    });
    Some((src, sign))
}

/// Set a ghost node to the mirror image of its partner inside ([`ghost_source`]); nodes that are
/// not ghosts, ghosts of friction walls and empty ghosts keep their velocity.
///
/// # Safety
/// Only this node may be written concurrently; non-ghost nodes must not be written meanwhile.
pub(crate) unsafe fn mirror_ghost(geom: &GridGeom, walls: &Walls, g: [i32; 3], at: usize, nodes: &SharedSlice<Node>, table: &[u32]) {
    let Some((src, sign)) = ghost_source(geom, walls, g, table) else { return };
    let node = nodes.get_mut(at);
    if node[0] <= 0.0 {
        return;
    }
    let v = src.map_or([0.0; 3], |i| {
        let s = &nodes.as_slice()[i];
        [s[1], s[2], s[3]]
    });
    for c in 0..3 {
        node[1 + c] = v[c] * sign[c];
    }
}

/// Keep a particle inside the walls (projected onto them) and wrap it on periodic axes.
#[inline]
pub(crate) fn keep_inside(geom: &GridGeom, platform: Option<(Real, [Real; 4], WallKind)>, x: &mut V3) {
    for a in 0..3 {
        let (lo, hi) = (geom.lo[a] as Real, geom.hi[a] as Real);
        if geom.periodic[a] {
            let n = geom.cells[a] as Real;
            if x[a] < lo {
                x[a] += n;
            } else if x[a] >= hi {
                x[a] -= n;
            }
        } else {
            x[a] = x[a].clamp(lo, hi);
        }
    }
    if let Some((z, xy, _)) = platform {
        if x.z < z && x.x >= xy[0] && x.x <= xy[2] && x.y >= xy[1] && x.y <= xy[3] {
            x.z = z;
        }
    }
}

/// Lattice points of a body: `ppc^3` per cell, on cells aligned with the domain's lower corner.
/// An upper bound on the shear rate gamma_dot = sqrt(2 D':D') MLS-MPM can give a particle when
/// no grid node moves faster than `speed`: with quadratic B-splines, C = (4 / dx^2) sum_i w_i v_i
/// (x_i - x_p)^T, sum_i w_i = 1 and sum_i w_i |x_i - x_p|^2 = 3 dx^2 / 4, so by Cauchy-Schwarz
/// |C|_F <= 2 sqrt(3) speed / dx, and gamma_dot <= sqrt(2) |D|_F <= sqrt(2) |C|_F. The step
/// control passes the particles' largest speed, as the wave bound does.
pub fn max_shear_rate(speed: f64, dx: f64) -> f64 {
    2.0 * 6f64.sqrt() * speed / dx
}

pub fn for_each_lattice_point(sc: &Scenario, body: &Body, mut f: impl FnMut([f64; 3])) {
    let dx = sc.simulation.dx;
    let ppc = body.particles_per_cell_axis() as usize;
    let h = dx / ppc as f64;
    let (lo, hi) = body.bounds();
    let mut range = [(0i64, 0i64); 3];
    for a in 0..3 {
        let m = sc.domain.min[a];
        range[a] = (((lo[a] - m) / h - 0.5).ceil() as i64, ((hi[a] - m) / h - 0.5).floor() as i64);
    }
    for i in range[0].0..=range[0].1 {
        for jj in range[1].0..=range[1].1 {
            for k in range[2].0..=range[2].1 {
                let p = [
                    sc.domain.min[0] + (i as f64 + 0.5) * h,
                    sc.domain.min[1] + (jj as f64 + 0.5) * h,
                    sc.domain.min[2] + (k as f64 + 0.5) * h,
                ];
                let inside = (0..3).all(|a| p[a] >= sc.domain.min[a] && p[a] <= sc.domain.max[a]);
                if inside && body.contains(p) {
                    f(p);
                }
            }
        }
    }
}

pub fn count_body_particles(sc: &Scenario) -> usize {
    let mut n = 0;
    for b in &sc.bodies {
        for_each_lattice_point(sc, b, |_| n += 1);
    }
    n
}

/// Values for a message in scientific notation: plain formatting spells 1e-300 with 300 digits.
fn scientific(values: &[Real]) -> String {
    values.iter().map(|x| format!("{x:.6e}")).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    /// Issue 27 finding 9: a blow-up message shows J and the other fields in a few digits.
    #[test]
    fn blow_up_values_are_short() {
        let s = super::scientific(&[-1e-30, 1e30, -62.088_41]);
        assert!(s.starts_with("-1.000000e-30, 1.000000e30, -6.20884") && s.len() < 50, "{s}");
    }
}
