//! What the adjoint of a step works on: the tape its recompute keeps (the phases' [`Saved`]
//! hooks fill it), the adjoint arrays of one objective, and where the adjoints of the toolpath's
//! closed forms go. The adjoint of each phase stands beside its forward, in the phase's file.

use super::{AdjointError, Simulation};
use crate::kernels::transfer::Node;
use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::grid::NODES_PER_BLOCK;
use crate::pools::{map_pools, plan_pools, with_role, Counts, Per, PoolDecl, Pools, Role};
use crate::print::emitter::EmissionPlan;

/// Most internal state reals any material keeps per particle, for its adjoint.
pub(crate) const MAX_STATE: usize = 16;
/// Most parameters a material may offer, for its adjoint.
pub(crate) const MAX_PARAMS: usize = 16;
/// Particles per partial sum of the material parameters' adjoints: fixed, so the sums do not
/// depend on the thread count.
pub(crate) const CHUNK: usize = 256;

/// What a phase overwrites that its own or an earlier phase's adjoint reads: the recompute
/// saves it into the [`Tape`] just before the phase runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Saved {
    /// The particle state at the step's start (x, v, C, stress, J and the material state; G2P
    /// and the material update overwrite it).
    Particles,
    /// The grid nodes as P2G left them (the grid update overwrites them).
    Grid,
    /// Before the sleep update, in a sleeping run: the ids in pool order, the sleeping prefix's
    /// length and the units' clocks (the update moves particles and ends the rest of the units
    /// it wakes).
    Order,
}

/// The per-particle arrays a step changes, as one group of pools: the tape of one step (the
/// state it started from) and the adjoints of a state. One pool per particle pool a step changes
/// ([`Role::changes_in_step`]), in the same order.
///
/// Masses and initial volumes are not here: without emission they never change, so their
/// adjoints accumulate in place.
#[derive(Default)]
pub struct Fields {
    /// Pool names are `PREFIX.x` and so on.
    prefix: String,
    state_len: usize,
    pub xg: Pool<V3>,
    pub v: Pool<V3>,
    pub c: Pool<M3>,
    pub stress: Pool<M3>,
    pub j: Pool<Real>,
    pub state: Pool<Real>,
}

impl Pools for Fields {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        let (sl, name) = (self.state_len, |field: &str| format!("{}.{field}", self.prefix));
        let decl = PoolDecl::<Self>::new;
        vec![
            decl(name("x"), Per::Particle(1), Role::Scratch, |f| &f.xg, |f| &mut f.xg),
            decl(name("v"), Per::Particle(1), Role::Scratch, |f| &f.v, |f| &mut f.v),
            decl(name("C"), Per::Particle(1), Role::Scratch, |f| &f.c, |f| &mut f.c),
            decl(name("stress"), Per::Particle(1), Role::Scratch, |f| &f.stress, |f| &mut f.stress),
            decl(name("J"), Per::Particle(1), Role::Scratch, |f| &f.j, |f| &mut f.j),
            decl(name("state"), Per::Particle(sl), Role::Scratch, |f| &f.state, |f| &mut f.state),
        ]
    }
}

impl Fields {
    /// The pools `PREFIX.x` ... for particles of `state_len` state values, declared but not
    /// mapped.
    fn declared(prefix: &str, state_len: usize) -> Fields {
        Fields { prefix: prefix.into(), state_len, ..Default::default() }
    }

    /// Copy particles `r` of `from` in.
    pub(crate) fn copy_range(&mut self, from: &Fields, r: std::ops::Range<usize>) {
        let (lo, hi) = (Counts::particles(r.start), Counts::particles(r.end));
        for (d, s) in self.pools().into_iter().zip(from.pools()) {
            let (a, b) = (d.bytes_for(self, &lo), d.bytes_for(self, &hi));
            d.of_mut(self).bytes_mut()[a..b].copy_from_slice(&s.of(from).bytes()[a..b]);
        }
    }

    /// Particle `i` of `from` into slot `to(i)`, for particles `0..n`.
    pub(crate) fn scatter_from(&mut self, from: &Fields, n: usize, to: impl Fn(usize) -> usize) {
        for (d, s) in self.pools().into_iter().zip(from.pools()) {
            let w = d.of(self).elem_bytes() * d.per.len(&Counts::particles(1));
            let (dst, src) = (d.of_mut(self).bytes_mut(), s.of(from).bytes());
            for i in 0..n {
                let t = to(i);
                dst[t * w..(t + 1) * w].copy_from_slice(&src[i * w..(i + 1) * w]);
            }
        }
    }

    /// Zero particles `r`.
    pub fn zero_range(&mut self, r: std::ops::Range<usize>) {
        let (from, to) = (Counts::particles(r.start), Counts::particles(r.end));
        for d in self.pools() {
            let (a, b) = (d.bytes_for(self, &from), d.bytes_for(self, &to));
            // every type here is floats, whose zero is all bits zero
            d.of_mut(self).bytes_mut()[a..b].fill(0);
        }
    }

    /// Copy the simulation's first `n` particles' changing arrays in.
    fn copy_from(&mut self, sim: &Simulation) {
        let p = &sim.particles;
        let now = Counts::particles(p.n);
        for (d, src) in self.pools().into_iter().zip(with_role(p, Role::changes_in_step)) {
            debug_assert_eq!(d.name.rsplit('.').next(), src.name.rsplit('.').next());
            d.live_mut(self, &now).copy_from_slice(src.live(p, &now));
        }
    }
}

/// What the recompute of a step keeps for its adjoint, shared by all objectives.
pub struct Tape {
    /// The particle state at the start of the step being reversed.
    pub(crate) particles: Fields,
    /// Grid nodes after P2G, before the grid update; `grid_used` of them hold this step's.
    pub(crate) grid: Pool<Node>,
    pub(crate) grid_used: usize,
    /// Partial sums of the material parameters' adjoints, one per [`CHUNK`] particles.
    pub(crate) chunks: Vec<[f64; MAX_PARAMS]>,
    /// A sleeping run's sleep tape ([`Saved::Order`]; empty otherwise): the ids in pool order
    /// before the sleep update, the pool slot each id had then (filled by the sleep adjoint), and
    /// the units' clocks.
    pub(crate) ids_before: Pool<u32>,
    pub(crate) slot_before: Pool<u32>,
    pub(crate) clocks_before: Pool<f32>,
    pub(crate) n_sleep_before: usize,
    /// Units in the sleep tables (0 when the run does not sleep).
    sleep_units: usize,
}

impl Pools for Tape {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        let mut v = vec![PoolDecl::<Tape>::new("grad.grid_tape", Per::Block(NODES_PER_BLOCK), Role::Scratch, |t| &t.grid, |t| &mut t.grid)];
        if self.sleep_units > 0 {
            v.extend([
                PoolDecl::<Tape>::new("grad.ids_before_sleep", Per::Particle(1), Role::Scratch, |t| &t.ids_before, |t| &mut t.ids_before),
                PoolDecl::<Tape>::new("grad.slot_before_sleep", Per::Particle(1), Role::Scratch, |t| &t.slot_before, |t| &mut t.slot_before),
                PoolDecl::<Tape>::new("grad.clocks_before_sleep", Per::Table(self.sleep_units), Role::Scratch, |t| &t.clocks_before, |t| &mut t.clocks_before),
            ]);
        }
        v
    }

    fn plan_memory(&self, plan: &mut MemoryPlan, cap: &Counts) {
        self.particles.plan_memory(plan, cap);
        plan_pools(self, plan, cap);
    }

    fn map_pools(&mut self, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
        self.particles.map_pools(cap, backing)?;
        map_pools(self, cap, backing)
    }
}

impl Tape {
    /// The tape for particles of `state_len` state values and `sleep_units` sleep units (0: the
    /// run does not sleep), declared but not mapped.
    fn declared(state_len: usize, sleep_units: usize) -> Tape {
        Tape {
            particles: Fields::declared("grad.tape", state_len),
            grid: Pool::default(),
            grid_used: 0,
            chunks: Vec::new(),
            ids_before: Pool::default(),
            slot_before: Pool::default(),
            clocks_before: Pool::default(),
            n_sleep_before: 0,
            sleep_units,
        }
    }

    /// Bytes of the tape for room `cap`, `state_len` state values and `sleep_units` sleep units
    /// into `plan`.
    pub fn plan(plan: &mut MemoryPlan, cap: &Counts, state_len: usize, sleep_units: usize) {
        Tape::declared(state_len, sleep_units).plan_memory(plan, cap);
    }

    /// The tape for `sim`'s pools; fails for a material whose adjoint does not fit the fixed
    /// buffers (more than [`MAX_PARAMS`] parameters or [`MAX_STATE`] state values).
    pub fn new(sim: &Simulation, b: &Backing) -> Result<Tape, AdjointError> {
        if sim.material.param_names().len() > MAX_PARAMS || sim.particles.state_len > MAX_STATE {
            return Err(AdjointError::TooManyValues { material: sim.material.name().to_string() });
        }
        let mut tape = Tape::declared(sim.particles.state_len, sim.sleep.as_ref().map_or(0, |s| s.clocks().len()));
        tape.map_pools(&capacity(sim), b)?;
        tape.chunks = vec![[0.0; MAX_PARAMS]; sim.particles.capacity().div_ceil(CHUNK)];
        Ok(tape)
    }

    /// Save what a phase is about to overwrite.
    pub fn save(&mut self, what: Saved, sim: &Simulation) {
        match what {
            Saved::Particles => self.particles.copy_from(sim),
            Saved::Grid => {
                let used = sim.grid.n_active * crate::grid::NODES_PER_BLOCK;
                self.grid.as_mut_slice()[..used].copy_from_slice(&sim.grid.nodes.as_slice()[..used]);
                self.grid_used = used;
            }
            Saved::Order => {
                let (Some(sl), p) = (&sim.sleep, &sim.particles) else { return };
                self.ids_before.as_mut_slice()[..p.n].copy_from_slice(&p.id.as_slice()[..p.n]);
                self.clocks_before.as_mut_slice().copy_from_slice(sl.clocks());
                self.n_sleep_before = p.n_sleep;
            }
        }
    }
}

/// Adjoints of the grid update's parameters, accumulated over nodes and steps.
#[derive(Clone, Copy, Debug, Default)]
pub struct GridParamsBar {
    /// Of the body acceleration g + F / rho.
    pub accel: [f64; 3],
    /// Of the Coulomb coefficient of each friction wall, [axis][side].
    pub wall_mu: [[f64; 2]; 3],
    pub platform_mu: f64,
    /// Of the nozzle drive's outlet position and imposed velocity, this step only (the grid
    /// update's adjoint hands them to the [`ToolpathBar`] and resets them).
    pub drive_outlet: [f64; 3],
    pub drive_velocity: [f64; 3],
}

/// The adjoint arrays of one objective. `next` holds the adjoint of the state after the step
/// and `cur` receives that of the state before it; they swap roles every step
/// ([`Adjoint::end_step`]). Masses and initial volumes change only when emission sets them (a
/// partial slab's fraction), so their adjoints accumulate over the steps in one array each, and
/// are settled and cleared at the step that set them.
#[derive(Default)]
pub struct Adjoint {
    /// Which objective's (its pools' names end in `.k` from the second on).
    seed: usize,
    pub cur: Fields,
    pub next: Fields,
    pub mass_bar: Pool<Real>,
    pub vol0_bar: Pool<Real>,
    pub(crate) grid_bar: Pool<Node>,
    /// Adjoints of the material's parameters, in `param_names` order.
    pub material_bar: Vec<f64>,
    /// Density's adjoint through the masses emission set, settled step by step (the masses that
    /// never change are settled once at the end, from `mass_bar`).
    pub density_bar: f64,
    pub grid_params_bar: GridParamsBar,
    /// This step's adjoints of the newest slab's fraction and of the feed velocity through the
    /// blend with the feed, set by its adjoint and chained by those of the grid update and of
    /// the newest masses.
    pub(crate) feed_fraction_bar: f64,
    pub(crate) feed_velocity_bar: [f64; 3],
}

/// Room for `sim`'s particles and grid slots.
fn capacity(sim: &Simulation) -> Counts {
    Counts::capacity(sim.particles.capacity(), sim.grid.max_blocks())
}

/// A pool name for seed `k` (seed 0 keeps the plain names; mapped pools need distinct names).
fn named(name: &str, k: usize) -> String {
    if k == 0 {
        name.to_string()
    } else {
        format!("{name}.{k}")
    }
}

impl Pools for Adjoint {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        let (k, decl) = (self.seed, PoolDecl::<Self>::new);
        vec![
            decl(named("grad.mass_bar", k), Per::Particle(1), Role::Scratch, |a| &a.mass_bar, |a| &mut a.mass_bar),
            decl(named("grad.vol0_bar", k), Per::Particle(1), Role::Scratch, |a| &a.vol0_bar, |a| &mut a.vol0_bar),
            decl(named("grad.grid_bar", k), Per::Block(NODES_PER_BLOCK), Role::Scratch, |a| &a.grid_bar, |a| &mut a.grid_bar),
        ]
    }

    fn plan_memory(&self, plan: &mut MemoryPlan, cap: &Counts) {
        self.cur.plan_memory(plan, cap);
        self.next.plan_memory(plan, cap);
        plan_pools(self, plan, cap);
    }

    fn map_pools(&mut self, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
        self.cur.map_pools(cap, backing)?;
        self.next.map_pools(cap, backing)?;
        map_pools(self, cap, backing)
    }
}

impl Adjoint {
    /// Seed `k`'s arrays for particles of `state_len` state values, declared but not mapped.
    fn declared(k: usize, state_len: usize) -> Adjoint {
        let (cur, next) = (Fields::declared(&named("grad.adjoint_a", k), state_len), Fields::declared(&named("grad.adjoint_b", k), state_len));
        Adjoint { seed: k, cur, next, ..Default::default() }
    }

    /// Bytes of seed `k`'s adjoint arrays for room `cap` and `state_len` state values into
    /// `plan`.
    pub fn plan(plan: &mut MemoryPlan, k: usize, cap: &Counts, state_len: usize) {
        Adjoint::declared(k, state_len).plan_memory(plan, cap);
    }

    /// Seed `k`'s adjoint arrays for `sim`'s pools, zero.
    pub fn new(sim: &Simulation, k: usize, b: &Backing) -> Result<Adjoint, MemoryError> {
        let mut a = Adjoint::declared(k, sim.particles.state_len);
        a.map_pools(&capacity(sim), b)?;
        a.material_bar = vec![0.0; sim.material.param_names().len()];
        Ok(a)
    }

    /// After the last phase's adjoint: the adjoint of the state before the step becomes the one
    /// the earlier step's adjoint starts from, and the other array is cleared for it.
    pub fn end_step(&mut self, n: usize) {
        std::mem::swap(&mut self.cur, &mut self.next);
        // particles beyond n were never touched by this step's adjoint
        self.cur.zero_range(0..n);
    }
}

/// Where the adjoints of the toolpath's closed forms at a step go — the nozzle drive, the
/// extruded length that sets the newest slab's fraction, the emitted particles — each at the
/// base toolpath's move `k` and step time `t` (`grad/print_adjoint.rs` chains them into the
/// toolpath's parameters).
pub trait ToolpathBar {
    /// Of the drive's outlet position and imposed velocity.
    fn drive(&mut self, k: usize, t: f64, outlet_bar: [f64; 3], velocity_bar: [f64; 3]);
    /// Of the extruded length.
    fn extruded(&mut self, k: usize, t: f64, length_bar: f64);
    /// Of the world positions and velocities of the particles slabs `first_slab..` added, in
    /// the order they were added.
    fn emission(&mut self, plan: &EmissionPlan, first_slab: u64, t: f64, x_bar: &[[f64; 3]], v_bar: &[[f64; 3]]) -> Result<(), AdjointError>;
}
