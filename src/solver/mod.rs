//! The MLS-MPM step (paper 000 eqs. 8-17):
//!
//! ```text
//! bin particles by block ─▶ clear grid ─▶ P2G (8 colours) ─▶ grid update ─▶ G2P ─▶ materials
//! ```
//!
//! Every buffer is a mapped pool sized at start-up; the step allocates nothing. P2G runs the 8
//! block colours one after the other: blocks of one colour never write the same nodes, so
//! threads add into the grid without atomics, and each node receives its sums in the same order
//! whatever the thread count, which makes runs bit-identical for any number of threads.//!
//! Files, one phase each with its adjoint beside it: `step.rs` (the time step and the list of
//! phases, [`PHASES`]), `emit.rs`, `binning.rs`, `p2g.rs`, `grid_update.rs`, `g2p.rs`,
//! `materials.rs`; `neighbourhood.rs` (a particle block's nodes) and `walls.rs` (walls, ghosts,
//! platform) serve the transfers and the grid update; `adjoint.rs` holds what the adjoints work
//! on (the tape, the adjoint arrays); `setup.rs` (pools, walls, threads) and `bodies.rs`
//! (initial particles) build the simulation.

mod adjoint;
mod binning;
mod bodies;
mod emit;
mod g2p;
mod grid_update;
mod materials;
mod neighbourhood;
mod p2g;
mod preflight;
mod setup;
mod sleep_adjoint;
mod step;
mod walls;

pub use adjoint::{Adjoint, Fields, GridParamsBar, Saved, Tape, ToolpathBar};
use adjoint::{MAX_PARAMS, MAX_STATE};
pub(crate) use binning::Scratch;
pub use bodies::{count_body_particles, for_each_lattice_point};
pub use preflight::preflight;
pub(crate) use emit::note_newest;
pub use step::{max_shear_rate, Phase, Step, PHASES};
pub(crate) use walls::Walls;

use crate::grid::Grid;
use crate::kernels::material::Material;
use crate::kernels::{M3, V3};
use crate::memory::{MemoryError, MemoryPlan};
use crate::particles::Particles;
use crate::print::Printer;
use crate::scenario::Scenario;
use crate::sleep::Sleep;
use crate::threads::ThreadTeam;
use std::sync::atomic::AtomicU64;

pub const MAX_THREADS: usize = 64;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Memory(#[from] MemoryError),
    /// The scenario fails its own validation.
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    /// The folder the pools are mapped in cannot be created.
    #[error("memory.dir {}: {source}", dir.display())]
    MemoryDir { dir: std::path::PathBuf, source: std::io::Error },
    /// `[memory] max_particles` is smaller than the initial bodies plus the whole print.
    #[error("particle pool: the scenario needs {} particles ({initial} initial + {emitted} emitted by the whole print) \
             but [memory] max_particles = {capacity}; raise it or leave it out to size the pool for the whole print",
            initial + emitted)]
    ParticlePool { initial: usize, emitted: usize, capacity: usize },
    /// A scenario value the solver's setup refuses (the material's parameters).
    #[error(transparent)]
    Invalid(#[from] crate::invalid::Invalid),
    /// The print cannot be set up (boxed: a G-code error is large, and every step's `Result`
    /// carries this type).
    #[error(transparent)]
    Print(Box<crate::print::PrintError>),
    #[error("blow-up at step {step} (t = {time:.6e} s): particle {index} (id {id}) has {field} = {value}; \
             try a smaller simulation.cfl or simulation.dt")]
    BlowUp { step: u64, time: f64, index: usize, id: u32, field: &'static str, value: String },
}

/// Why a step's adjoint cannot be taken: the material's adjoint does not fit the tape's fixed
/// buffers, its pools cannot be mapped, or the toolpath's parameters do not chain through an
/// emission.
#[derive(Debug, thiserror::Error)]
pub enum AdjointError {
    #[error("material {material}: the gradient driver takes at most {MAX_PARAMS} parameters and {MAX_STATE} state values")]
    TooManyValues { material: String },
    #[error(transparent)]
    Memory(#[from] MemoryError),
    #[error("emission without a printer")]
    NoPrinter,
    /// A unit woke whose material has no adjoint of waking.
    #[error("step {step}: sleeping material woke, and the gradient has no adjoint of waking for material {material} in this configuration (waking has one for newtonian, bingham, papanastasiou_roussel and evp_bingham without an age law or a Maxwell branch): remove [sleep], or make it wake no unit")]
    Wake { material: String, step: u64 },
    /// A perturbed toolpath puts a different number of a slab's particles inside the domain.
    #[error("slab {slab}: the toolpath parameters' perturbation changes how many of its particles lie inside the domain")]
    SlabCount { slab: u64 },
}

impl From<crate::print::PrintError> for SimError {
    fn from(e: crate::print::PrintError) -> SimError {
        SimError::Print(Box::new(e))
    }
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
    pub phase_seconds: [f64; PHASES.len()],
    /// The printing process, when the scenario prints.
    pub printer: Option<Printer>,
    /// Sleeping blocks, when enabled.
    pub sleep: Option<Sleep>,
    /// Awake particles summed over the steps taken: the work the step loops did, a cost
    /// measure no other job on the machine can distort.
    pub awake_particle_steps: u64,
    /// Work done on the material by gravity and the body force since t = 0 [J], on the true
    /// masses (mass scaling leaves the weight real): the external work the kinetic energy of
    /// the scaled inertia is judged against (`run/outputs.rs`). Carried by restart checkpoints.
    pub external_work: f64,
    /// Keep the pool order fixed (no reordering by block): the gradient driver indexes its
    /// adjoint arrays by pool position, which must then mean the same particle in every step.
    pub frozen_order: bool,
    /// Solid bodies inside the domain (`src/solid/`; issue 30 hook), None without `[[solid]]`.
    pub solids: Option<crate::solid::Solids>,
}

impl Simulation {
    pub fn threads(&self) -> usize {
        self.team.threads()
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
