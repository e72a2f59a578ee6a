//! What the adjoint of a step works on: the tape its recompute keeps (the phases' [`Saved`]
//! hooks fill it), the adjoint arrays of one objective, and where the adjoints of the toolpath's
//! closed forms go. The adjoint of each phase stands beside its forward, in the phase's file.

use super::Simulation;
use crate::kernels::transfer::Node;
use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
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
}

/// The per-particle arrays a step changes, as one group of pools: the tape of one step (the
/// state it started from) and the adjoints of a state.
///
/// Masses and initial volumes are not here: without emission they never change, so their
/// adjoints accumulate in place.
pub struct Fields {
    pub xg: Pool<V3>,
    pub v: Pool<V3>,
    pub c: Pool<M3>,
    pub stress: Pool<M3>,
    pub j: Pool<Real>,
    pub state: Pool<Real>,
}

const NAMES: [&str; 6] = ["x", "v", "C", "stress", "J", "state"];

impl Fields {
    pub fn plan(plan: &mut MemoryPlan, prefix: &str, n: usize, state_len: usize) {
        plan.add::<V3>(&format!("{prefix}.{}", NAMES[0]), n);
        plan.add::<V3>(&format!("{prefix}.{}", NAMES[1]), n);
        plan.add::<M3>(&format!("{prefix}.{}", NAMES[2]), n);
        plan.add::<M3>(&format!("{prefix}.{}", NAMES[3]), n);
        plan.add::<Real>(&format!("{prefix}.{}", NAMES[4]), n);
        plan.add::<Real>(&format!("{prefix}.{}", NAMES[5]), n * state_len);
    }

    pub fn new(prefix: &str, n: usize, state_len: usize, b: &Backing) -> Result<Fields, MemoryError> {
        let name = |k: usize| format!("{prefix}.{}", NAMES[k]);
        Ok(Fields {
            xg: Pool::new(&name(0), n, b)?,
            v: Pool::new(&name(1), n, b)?,
            c: Pool::new(&name(2), n, b)?,
            stress: Pool::new(&name(3), n, b)?,
            j: Pool::new(&name(4), n, b)?,
            state: Pool::new(&name(5), n * state_len, b)?,
        })
    }

    /// Zero particles `r` (with `state_len` state values each).
    pub fn zero_range(&mut self, r: std::ops::Range<usize>, state_len: usize) {
        self.xg.as_mut_slice()[r.clone()].fill(V3::ZERO);
        self.v.as_mut_slice()[r.clone()].fill(V3::ZERO);
        self.c.as_mut_slice()[r.clone()].fill(M3::ZERO);
        self.stress.as_mut_slice()[r.clone()].fill(M3::ZERO);
        self.j.as_mut_slice()[r.clone()].fill(0.0);
        self.state.as_mut_slice()[r.start * state_len..r.end * state_len].fill(0.0);
    }

    /// Copy the simulation's first `n` particles' changing arrays in.
    fn copy_from(&mut self, sim: &Simulation) {
        let p = &sim.particles;
        let n = p.n;
        self.xg.as_mut_slice()[..n].copy_from_slice(&p.xg.as_slice()[..n]);
        self.v.as_mut_slice()[..n].copy_from_slice(&p.v.as_slice()[..n]);
        self.c.as_mut_slice()[..n].copy_from_slice(&p.c.as_slice()[..n]);
        self.stress.as_mut_slice()[..n].copy_from_slice(&p.stress.as_slice()[..n]);
        self.j.as_mut_slice()[..n].copy_from_slice(&p.j.as_slice()[..n]);
        let s = n * p.state_len;
        self.state.as_mut_slice()[..s].copy_from_slice(&p.state.as_slice()[..s]);
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
}

impl Tape {
    pub fn plan(plan: &mut MemoryPlan, n: usize, state_len: usize, grid_nodes: usize) {
        Fields::plan(plan, "grad.tape", n, state_len);
        plan.add::<Node>("grad.grid_tape", grid_nodes);
    }

    /// The tape for `sim`'s pools; fails for a material whose adjoint does not fit the fixed
    /// buffers (more than [`MAX_PARAMS`] parameters or [`MAX_STATE`] state values).
    pub fn new(sim: &Simulation, b: &Backing) -> Result<Tape, String> {
        if sim.material.param_names().len() > MAX_PARAMS || sim.particles.state_len > MAX_STATE {
            return Err(format!("material {}: the gradient driver takes at most {MAX_PARAMS} parameters and {MAX_STATE} state values", sim.material.name()));
        }
        let n = sim.particles.capacity();
        let pools = || -> Result<Tape, MemoryError> {
            Ok(Tape {
                particles: Fields::new("grad.tape", n, sim.particles.state_len, b)?,
                grid: Pool::new("grad.grid_tape", sim.grid.nodes.len(), b)?,
                grid_used: 0,
                chunks: vec![[0.0; MAX_PARAMS]; n.div_ceil(CHUNK)],
            })
        };
        pools().map_err(|e| e.to_string())
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
pub struct Adjoint {
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

/// A pool name for seed `k` (seed 0 keeps the plain names; mapped pools need distinct names).
fn named(name: &str, k: usize) -> String {
    if k == 0 {
        name.to_string()
    } else {
        format!("{name}.{k}")
    }
}

impl Adjoint {
    /// Bytes of seed `k`'s adjoint arrays into `plan`.
    pub fn plan(plan: &mut MemoryPlan, k: usize, n: usize, state_len: usize, grid_nodes: usize) {
        Fields::plan(plan, &named("grad.adjoint_a", k), n, state_len);
        Fields::plan(plan, &named("grad.adjoint_b", k), n, state_len);
        plan.add::<Real>(&named("grad.mass_bar", k), n);
        plan.add::<Real>(&named("grad.vol0_bar", k), n);
        plan.add::<Node>(&named("grad.grid_bar", k), grid_nodes);
    }

    /// Seed `k`'s adjoint arrays for `sim`'s pools, zero.
    pub fn new(sim: &Simulation, k: usize, b: &Backing) -> Result<Adjoint, MemoryError> {
        let (n, sl) = (sim.particles.capacity(), sim.particles.state_len);
        Ok(Adjoint {
            cur: Fields::new(&named("grad.adjoint_a", k), n, sl, b)?,
            next: Fields::new(&named("grad.adjoint_b", k), n, sl, b)?,
            mass_bar: Pool::new(&named("grad.mass_bar", k), n, b)?,
            vol0_bar: Pool::new(&named("grad.vol0_bar", k), n, b)?,
            grid_bar: Pool::new(&named("grad.grid_bar", k), sim.grid.nodes.len(), b)?,
            material_bar: vec![0.0; sim.material.param_names().len()],
            density_bar: 0.0,
            grid_params_bar: GridParamsBar::default(),
            feed_fraction_bar: 0.0,
            feed_velocity_bar: [0.0; 3],
        })
    }

    /// After the last phase's adjoint: the adjoint of the state before the step becomes the one
    /// the earlier step's adjoint starts from, and the other array is cleared for it.
    pub fn end_step(&mut self, n: usize, state_len: usize) {
        std::mem::swap(&mut self.cur, &mut self.next);
        // particles beyond n were never touched by this step's adjoint
        self.cur.zero_range(0..n, state_len);
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
    fn emission(&mut self, plan: &EmissionPlan, first_slab: u64, t: f64, x_bar: &[[f64; 3]], v_bar: &[[f64; 3]]) -> Result<(), String>;
}
