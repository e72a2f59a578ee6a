//! Sleeping blocks: deposited material at rest stops costing anything.
//!
//! Material sleeps by *units* of 2 x 2 x 2 cells (8 to a grid block; a particle belongs to the
//! unit of its stencil base). A unit sleeps when its particles have moved slower than `speed`
//! and strained slower than `strain_rate` for `rest_time`, and no neighbour unit holds material
//! faster than `wake_speed`. Its particles move into the sleeping prefix `0..n_sleep` of the
//! pool, out of every per-step loop. Active material that reaches them sees a still, no-slip
//! body: grid nodes inside a sleeping unit's stencil reach are held at rest. A sleeping unit
//! wakes as soon as material faster than `wake_speed` is binned next to it (new material
//! arriving, or a load making its neighbour move), when an awake particle enters it, or when the
//! nozzle tube reaches it while the nozzle moves or extrudes (material in the tube must follow
//! the nozzle; a still tube holds its nodes at rest, as a sleeping unit does). That speed rule is
//! the default.
//!
//! The wake test on load (`wake_by_load`; on by default for prints of two or more layers, off
//! otherwise). Material arriving above a sleeping
//! unit then wakes it by its load, not its speed, and moving material above a unit no longer
//! keeps it from falling asleep; the speed of material beside or below a unit still wakes it (a
//! load test cannot see material sliding past or giving way under it). Why: under the speed rule
//! the new layer's arrival wakes the layer below over the nozzle's whole zone, and it sleeps
//! again only once the new layer has settled above it, ~30 mm behind the nozzle; that layer is
//! what every layer after the first costs above the first (BENCHMARKS.md "Sleeping"). The load
//! rule pays only when the layer below has built up strength by the time the next one arrives
//! (real layer times, dwells): material that just stopped flowing rests at its yield stress and
//! the next layer's weight makes it yield, so on a print with short layer times the load rule
//! costs as much as the speed rule (measured on ten layers at 5 mm, BENCHMARKS.md).
//!
//!
//! Why on by default for multi-layer prints: under the speed rule alone, a layer asleep under a
//! stack that grows slowly enough never sees fast material next to it, and stays frozen while the
//! weight above passes its yield stress; the print would stand where it collapses awake. The load
//! test wakes it when the added load approaches its margin (`load_fraction`, half by default, a
//! quarter with column loads below),
//! so sleeping does not hide a plastic collapse (tests/suite/print.rs prints a wall to failure with and without sleeping; the cost against
//! the speed rule is in BENCHMARKS.md "Printing to failure").
//!
//! Material arriving faster than `arrive_speed` still wakes the units under it, and keeps them
//! awake, by its speed. Why: the nozzle squeezes the material it lays down, and the layer below
//! gives way a little under the squeeze; held still there, it made the new layer spread further
//! (the dwell print at 2.5 mm, two layers: +1.6 % width against the speed rule without
//! `arrive_speed`, -0.05 % with 1 cm/s). Behind the nozzle the new layer only settles, slower
//! than that, and the layer below may sleep under it.
//!
//! How loads are tested. Material printed onto a sleeping layer rests on the layer's held nodes;
//! what those nodes take from it each step (the momentum they remove, over dt) is the load on the
//! sleeping units holding them. Averaged over `load_time`, that force over a unit's face is a
//! traction t, and a traction adds at most |t| / sqrt(3) to tau = sqrt(J2) under a column (it is
//! that for a vertical load on a free-standing column; the triangle inequality bounds the sum with
//! the stress already there). Only the load added since the unit fell asleep counts: what lay on it
//! then is in its frozen stress. A unit sleeps with the mean margin to yield of its particles
//! ([`Material::yield_margin`]), which grows while it sleeps as its material builds up structure
//! ([`Material::strength_gain`]), and a load must pass `load_fraction` of that margin by
//! `load_floor` (a load the unit takes at once overshoots to twice its static effect). The load
//! reaches through the sleeping material below the unit, so it wakes the contiguous sleeping units
//! under it in its column down to the deepest whose margin it passes: a layer at its yield stress
//! at the bottom wakes under the next layer's weight, one that has built up enough strength stays
//! asleep. With a material whose margin is many layers' weight (`Material::column_loads`:
//! `early_age_solid`) each unit of the column is tested against what the column added on it since
//! it fell asleep: the load on the top and the weights of the sleeping units between, whose own
//! weight rests on no node. Why: tested against the top's load alone, a deep unit never saw the
//! layers that had fallen asleep above it, and the printed cylinder asleep (bench/cylinder.py, 10
//! mm cells) stood all 40 layers where it fails in layer 24 awake. Three rules keep that sound. A
//! column is walked from its top only (a unit under sleeping ones takes on its own nodes only what
//! presses on its sides). A held node's load goes to the column it lies in the middle of, not
//! shared among the columns holding it (shared, a column's weight counted partly on its neighbour,
//! then came back as an added load when that weight fell asleep: spurious wakes). And a unit keeps
//! the compression its column added since it fell asleep, which its particles' stress takes when
//! they wake (`Material::take_column_load`): without it a deep unit woke without the weight of the
//! layers laid while it slept, took it at once (a step load), and the printed cylinder asleep fell
//! in layer 11 where it stands to 24 awake. The sleeping part is held rigid while the awake part
//! deforms, so such a material wakes at a quarter of its margin by default, not half; even so the
//! cylinder fails asleep one to five layers before it fails awake, and the laid early-age wall two
//! (the figures at `config::sleep`'s default), which is why sleeping is no default for such a
//! print. The layer asleep is also erratic under the sleep keys: the laid wall, which fails in
//! layer 19 awake (also at cfl 0.27 and mass scaling 3.5), fails asleep anywhere from 14 to 19 as
//! `load_fraction`, `load_floor`, `wake_grace` or `speed` change, often by buckling. Units hold
//! particles by their stencil base, half a cell off the wall's mid-plane, so sleep and wake
//! decisions are not symmetric across a wall: awake its section stays centred within 0.005 mm to
//! the failure, asleep it drifts sideways (docs/failure.md "Sleeping and failure").
//!
//! Why units and not the grid's 4-cell blocks: the awake region is what moves plus a one-unit
//! halo around it (the calm and wake tests look at the 26 neighbours), and a printed layer is
//! only a few cells thick. With 4-cell blocks the halo under a fresh layer was as thick as a
//! layer, and blocks straddling two layers kept both awake (BENCHMARKS.md, "Sleeping").
//!
//! Sleeping freezes the stress. The internal state is not stepped either, but material at rest
//! still builds up structure (thixotropy): a unit remembers when it fell asleep, and on waking
//! its particles get the whole rest interval at once ([`Material::rest_for_at`]), so a deposited
//! layer gains the strength it would have had awake. A particle falling asleep is put at rest: its
//! velocity and velocity gradient (below the rest thresholds anyway) become zero and its stress
//! the material's stress at rest for its state and J, so a restart checkpoint rebuilds all three
//! from (state, J) instead of storing 84 bytes per sleeping particle in f32. Going to sleep is
//! checked every `check_interval` steps (it moves particles, O(awake particles)); waking is
//! checked every step and moves particles only when a unit actually wakes (O(sleeping
//! particles), rare).
//!
//! With `coarsen`, the interior of material falling asleep merges to one particle per cell
//! (`coarsen.rs`), so what the next layer wakes costs less.
//!
//! Files: `units.rs` (the unit lattice and a unit's state), `holds.rs` (the nodes sleeping units
//! hold), `at_rest.rs` (a particle put at rest), `passes.rs` (the wake and sleep passes of each
//! step), `loads.rs` (the wake test on load), `coarsen.rs` (merging), this file (the tables,
//! their memory plan, and what a checkpoint stores of them).

mod at_rest;
mod coarsen;
mod holds;
mod loads;
mod passes;
mod units;
#[cfg(test)]
mod tests;

pub use crate::config::SleepConfig;
pub use at_rest::put_at_rest;
pub use coarsen::Coarsen;
pub use holds::{BlockHolds, Holds};
pub use units::{unit_in_block, unit_of_particle, UnitActivity, UnitState, EMPTY_UNIT, UNITS, UNIT_CELLS};

use crate::grid::{GridGeom, NODES_PER_BLOCK};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::pools::{map_pools, plan_pools, Counts, Per, PoolDecl, Pools, Role};
use units::{states, states_mut, valid_states};

/// A restored `sleep.state` table holding a byte that is no [`UnitState`].
#[derive(Debug, thiserror::Error)]
#[error("section 'sleep.state' holds a value that is no unit state")]
pub struct BadUnitState;

/// Per-unit sleep bookkeeping, over the dense block table refined to units.
pub struct Sleep {
    pub cfg: SleepConfig,
    /// Blocks of the domain's dense table (the per-unit tables have [`UNITS`] entries each).
    table_len: usize,
    /// A [`UnitState`] per unit, `Asleep` or `Awake` (`Woken` only inside `update`, `Loaded`
    /// between a step and the next update), indexed by [`units::unit_index`]; stored as bytes
    /// (`units::states` views them).
    state: Pool<u8>,
    /// Each unit's clock [s], read by its state: awake, the time its material has been at rest,
    /// or, negative, minus the settling time left since it woke (`wake_grace`); asleep, the
    /// simulation time at which it fell asleep; woken, within an update, the rest it owes its
    /// particles (the build-up of its time asleep). Its checkpoint section keeps the name
    /// `sleep.rest`.
    clock: Pool<f32>,
    /// Units woken by the current update (scratch; never more than the table holds).
    woken: Pool<u32>,
    /// Sleeping units per grid block, for the cheap pre-test of [`Holds::block`].
    asleep_in_block: Pool<u8>,
    /// (max speed, max strain rate) of each unit of each particle block of the last step, by
    /// slot; [`EMPTY_UNIT`] where the unit held no particle.
    pub activity: Pool<UnitActivity>,
    /// Units asleep now.
    pub sleeping_units: usize,
    /// Units woken since the run began: by load (`wake_by_load`), by material (awake material
    /// entering them or fast material next to them), by the nozzle tube. For the run's log;
    /// no checkpoint keeps them.
    pub woken_by: [u64; 3],
    /// The load tables, `load` to `reactions`, are empty unless loads are tested. Sleeping
    /// unit: the load on it [N], averaged over `load_time` (an exponential average, brought up
    /// to date whenever a step loads it).
    load: Pool<[f32; 3]>,
    /// Sleeping unit: the step whose load `load` last took in.
    load_step: Pool<u32>,
    /// Sleeping unit: the mean margin to yield of its particles when it fell asleep [Pa] (the
    /// least is near zero in material that just stopped flowing; see `load_floor`).
    margin: Pool<f32>,
    /// Sleeping unit: the load its frozen stress already carries [N], from the material that
    /// lay on it when it fell asleep: |load| once its average had run long enough to be unbiased,
    /// plus the weight of the sleeping units then above it in its column (NaN before).
    base: Pool<f32>,
    /// Sleeping unit: the weight of its particles [N]. Why: a sleeping unit's weight rests on
    /// no node, so the load a unit below it carries is the load on the column's top plus the
    /// weights of the sleeping units between (`loads.rs`).
    weight: Pool<f32>,
    /// Sleeping unit (with `column_loads`): the compression its column added on it since it fell
    /// asleep [Pa], as last measured; its particles' stress takes it when they wake
    /// ([`crate::kernels::material::Material::take_column_load`]).
    pressed: Pool<f32>,
    /// Units the last step loaded past their margin (state `Loaded`), for the next update.
    loaded: Pool<u32>,
    /// Unit just fallen asleep: how many of its particles' margins `margin` sums, until the sum
    /// becomes their mean (scratch of the sleep pass).
    count: Pool<u32>,
    n_loaded: usize,
    /// Per grid node of the last grid update: the reaction of a held node [N] (zero elsewhere;
    /// written only in blocks near a sleeping unit).
    reactions: Pool<[f32; 3]>,
    /// Axis and sign of gravity (down), when gravity lies along an axis and loads are tested.
    down: Option<(usize, i32)>,
    /// |gravity| [m/s^2].
    g: f32,
    /// Whether loads are tested on the whole column ([`crate::kernels::material::Material::column_loads`]; `weight`
    /// `pressed` exist only then).
    column_loads: bool,
    /// 1 / (a unit's face area) [1/m^2].
    per_area: f32,
    /// Merging scratch, with `coarsen`.
    coarsen: Option<Coarsen>,
}

impl Pools for Sleep {
    /// The per-unit tables a checkpoint stores, sparse (a unit's entries are zero away from
    /// material, and the load tables away from sleeping units), come first; the load tables
    /// exist only when loads are tested.
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        use Role::*;
        let (units, blocks) = (Per::Table(self.table_len * UNITS), Per::Table(self.table_len));
        let decl = PoolDecl::<Self>::new;
        let mut v = vec![
            decl("sleep.state", units, Sparse, |s| &s.state, |s| &mut s.state),
            decl("sleep.rest", units, Sparse, |s| &s.clock, |s| &mut s.clock),
        ];
        if self.tests_loads() {
            v.extend([
                decl("sleep.load", units, Sparse, |s| &s.load, |s| &mut s.load),
                decl("sleep.load_step", units, Sparse, |s| &s.load_step, |s| &mut s.load_step),
                decl("sleep.margin", units, Sparse, |s| &s.margin, |s| &mut s.margin),
                decl("sleep.base", units, Sparse, |s| &s.base, |s| &mut s.base),
            ]);
            if self.column_loads {
                v.extend([
                    decl("sleep.weight", units, Sparse, |s| &s.weight, |s| &mut s.weight),
                    decl("sleep.pressed", units, Sparse, |s| &s.pressed, |s| &mut s.pressed),
                ]);
            }
        }
        v.extend([
            decl("sleep.woken", units, Scratch, |s| &s.woken, |s| &mut s.woken),
            // counted again from the state table ([`Sleep::restored`])
            decl("sleep.asleep_in_block", blocks, Scratch, |s| &s.asleep_in_block, |s| &mut s.asleep_in_block),
            // written again by this step's G2P
            decl("sleep.activity", Per::ParticleBlock(1), Rebuilt, |s| &s.activity, |s| &mut s.activity),
        ]);
        if self.tests_loads() {
            v.extend([
                decl("sleep.loaded", units, Scratch, |s| &s.loaded, |s| &mut s.loaded),
                decl("sleep.count", units, Scratch, |s| &s.count, |s| &mut s.count),
                decl("sleep.reactions", Per::Block(NODES_PER_BLOCK), Scratch, |s| &s.reactions, |s| &mut s.reactions),
            ]);
        }
        v
    }

    fn plan_memory(&self, plan: &mut MemoryPlan, cap: &Counts) {
        plan_pools(self, plan, cap);
        if let Some(c) = &self.coarsen {
            c.plan_memory(plan, cap);
        }
    }

    fn map_pools(&mut self, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
        map_pools(self, cap, backing)?;
        if let Some(c) = &mut self.coarsen {
            c.map_pools(cap, backing)?;
        }
        Ok(())
    }
}

impl Sleep {
    /// Tables for `geom`'s domain under `gravity`, declared but not mapped ([`Pools::map_pools`]
    /// maps them for a number of grid slots and particles; the load tables only when loads are
    /// tested).
    pub fn declared(cfg: SleepConfig, geom: &GridGeom, gravity: [f64; 3]) -> Self {
        let face = UNIT_CELLS as f64 * geom.dx;
        Sleep {
            coarsen: cfg.coarsen.then(|| Coarsen::declared(geom)),
            down: cfg.down(gravity),
            g: gravity.iter().map(|x| x * x).sum::<f64>().sqrt() as f32,
            column_loads: false,
            cfg,
            table_len: geom.table_len(),
            state: Pool::default(),
            clock: Pool::default(),
            woken: Pool::default(),
            asleep_in_block: Pool::default(),
            activity: Pool::default(),
            sleeping_units: 0,
            woken_by: [0; 3],
            load: Pool::default(),
            load_step: Pool::default(),
            margin: Pool::default(),
            base: Pool::default(),
            weight: Pool::default(),
            pressed: Pool::default(),
            loaded: Pool::default(),
            count: Pool::default(),
            n_loaded: 0,
            reactions: Pool::default(),
            per_area: (1.0 / (face * face)) as f32,
        }
    }

    /// The same tables, testing loads on the whole column when `on` (the material's
    /// [`crate::kernels::material::Material::column_loads`]; before the tables are mapped).
    pub fn with_column_loads(mut self, on: bool) -> Self {
        self.column_loads = on;
        self
    }

    /// Tables for `geom`'s domain with `max_blocks` grid slots and room for `capacity`
    /// particles, under `gravity`, mapped.
    pub fn new(cfg: SleepConfig, geom: &GridGeom, max_blocks: usize, capacity: usize, gravity: [f64; 3], b: &Backing) -> Result<Self, MemoryError> {
        let mut s = Sleep::declared(cfg, geom, gravity);
        s.map_pools(&Counts::capacity(capacity, max_blocks), b)?;
        Ok(s)
    }

    /// Check and take in the tables a checkpoint restored (its [`Role::Sparse`] pools) and
    /// rebuild what follows from them.
    pub fn restored(&mut self) -> Result<(), BadUnitState> {
        if !valid_states(self.state.as_slice()) {
            return Err(BadUnitState);
        }
        self.recount();
        Ok(())
    }

    /// Rebuild what follows from the state table.
    fn recount(&mut self) {
        if !self.tests_loads() {
            // a checkpoint of a run with the load test, resumed without it: a unit its last step
            // loaded past its margin just sleeps on
            states_mut(self.state.as_mut_slice()).iter_mut().filter(|s| **s == UnitState::Loaded).for_each(|s| *s = UnitState::Asleep);
        }
        let state = states(self.state.as_slice());
        let per_block = self.asleep_in_block.as_mut_slice();
        self.sleeping_units = 0;
        for (b, n) in per_block.iter_mut().enumerate() {
            *n = state[b * UNITS..(b + 1) * UNITS].iter().filter(|s| s.is_asleep()).count() as u8;
            self.sleeping_units += *n as usize;
        }
        let loaded = self.loaded.as_mut_slice();
        self.n_loaded = 0;
        for (u, _) in state.iter().enumerate().filter(|(_, &s)| s == UnitState::Loaded) {
            loaded[self.n_loaded] = u as u32;
            self.n_loaded += 1;
        }
    }

    /// Each unit's clock (see the field): the gradient's tape keeps them from before a sleep
    /// update, for the rest the units it wakes had.
    pub fn clocks(&self) -> &[f32] {
        self.clock.as_slice()
    }

    /// Which nodes the sleeping units hold.
    pub fn holds(&self) -> Holds<'_> {
        Holds { state: states(self.state.as_slice()), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units }
    }

    /// Whether loads wake sleeping units (`wake_by_load`, under gravity along an axis): only
    /// then does the grid update need to leave held nodes' reactions for [`Sleep::take_loads`].
    pub fn tests_loads(&self) -> bool {
        self.down.is_some()
    }

    /// [`Sleep::holds`], and the per-node buffer the grid update leaves held nodes' reactions in.
    pub fn holds_and_reactions(&mut self) -> (Holds<'_>, &mut [[f32; 3]]) {
        let holds = Holds { state: states(self.state.as_slice()), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units };
        (holds, self.reactions.as_mut_slice())
    }

}

