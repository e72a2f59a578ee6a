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
//! test wakes it when the added load approaches its margin (`load_fraction`, half by default),
//! so sleeping does not hide a plastic collapse (tests/print.rs prints a wall to failure with and without sleeping; the cost against
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
//! that for a vertical load on a free-standing column; the triangle inequality bounds the sum
//! with the stress already there). Only the load added since the unit fell asleep counts: what
//! lay on it then is in its frozen stress. A unit sleeps with the mean margin to yield of its
//! particles ([`Material::yield_margin`]), which grows while it sleeps as its material builds up
//! structure ([`Material::strength_gain`]), and a load must pass `load_fraction` of that
//! margin by `load_floor` (a load the unit takes at once overshoots to twice its static effect).
//! The load reaches through the sleeping material below the unit, so it wakes the contiguous
//! sleeping units under it in its column down to the deepest whose margin it passes: a layer at
//! its yield stress at the bottom wakes under the next layer's weight, one that has built up
//! enough strength stays asleep.
//!
//! Why units and not the grid's 4-cell blocks: the awake region is what moves plus a one-unit
//! halo around it (the calm and wake tests look at the 26 neighbours), and a printed layer is
//! only a few cells thick. With 4-cell blocks the halo under a fresh layer was as thick as a
//! layer, and blocks straddling two layers kept both awake (BENCHMARKS.md, "Sleeping").
//!
//! Sleeping freezes the stress. The internal state is not stepped either, but material at rest
//! still builds up structure (thixotropy): a unit remembers when it fell asleep, and on waking
//! its particles get the whole rest interval at once ([`Material::rest_for`]), so a deposited
//! layer gains the strength it would have had awake. A particle falling asleep is settled: its
//! velocity and velocity gradient (below the rest thresholds anyway) become zero and its stress
//! the material's stress at rest for its state and J, so a restart checkpoint rebuilds all three
//! from (state, J) instead of storing 84 bytes per sleeping particle in f32. Going to sleep is
//! checked every `check_interval` steps (it moves particles, O(awake particles)); waking is
//! checked every step and moves particles only when a unit actually wakes (O(sleeping
//! particles), rare).
//!
//! With `coarsen`, the interior of material falling asleep merges to one particle per cell
//! (`coarsen.rs`), so what the next layer wakes costs less.

use crate::grid::{Grid, GridGeom, EMPTY, NODES_PER_BLOCK};
use crate::kernels::transfer::BS;
use crate::kernels::material::Material;
use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::coarsen::Coarsen;
use crate::particles::Particles;
pub use crate::config::SleepConfig;

const AWAKE: u8 = 0;
const ASLEEP: u8 = 1;
/// Within one update: woken, its sleep start still in `rest` until its particles had their rest.
const WOKEN: u8 = 2;
/// Asleep, and loaded past its margin in the step just taken: the next update wakes it. (Its
/// particles are still in the sleeping prefix, so its nodes stay held until then.)
const LOADED: u8 = 3;

#[inline]
fn asleep(s: u8) -> bool {
    s == ASLEEP || s == LOADED
}

/// Share of a traction's magnitude that reaches tau = sqrt(J2): 1/sqrt(3), exact for a
/// vertical load on a free-standing column (see the module notes).
const LOAD_SHARE: f32 = 0.577_350_26;

#[inline]
fn wake(b: u32, state: &mut [u8], woken: &mut [u32], n_woken: &mut usize) {
    if asleep(state[b as usize]) {
        state[b as usize] = WOKEN;
        woken[*n_woken] = b;
        *n_woken += 1;
    }
}

/// The speeds and strain rate of [`SleepConfig`] in the solver's precision.
struct Limits {
    rest_speed: Real,
    rest_rate: Real,
    wake_speed: Real,
    /// `arrive_speed` (infinite: material above wakes by its load alone).
    arrive_speed: Real,
}

impl Limits {
    fn of(cfg: &SleepConfig) -> Self {
        Limits {
            rest_speed: cfg.speed as Real,
            rest_rate: cfg.strain_rate as Real,
            wake_speed: cfg.wake_speed as Real,
            arrive_speed: cfg.arrive_speed as Real,
        }
    }
}

/// One step of an awake unit's clock `rest` (see [`Sleep`]) under its material's (max speed,
/// max strain rate): the new clock, and whether the unit wakes its sleeping neighbours.
///
/// A unit that has just woken settles for `wake_grace` first (negative clock) and wakes nobody
/// meanwhile. Why: a sleeping unit is held still, so the weight of the layers printed onto it
/// while it slept rests on its held nodes, not on its stress. When it wakes, that load reaches
/// its material at once and sends an elastic pulse through it (the weight of a 12.5 mm layer
/// on K = 1 MPa concrete moves it at about 4 mm/s, above `wake_speed`); without the grace the
/// pulse woke the next unit, whose own load woke the next, down the whole stack, several times a
/// layer (BENCHMARKS.md "Sleeping"). Material that really flows keeps flowing after the grace and
/// wakes its neighbours then.
#[inline]
fn tick(rest: f32, [v, rate]: [Real; 2], dt: f32, lim: &Limits) -> (f32, bool) {
    if rest < 0.0 {
        return ((rest + dt).min(0.0), false);
    }
    let at_rest = v < lim.rest_speed && rate < lim.rest_rate;
    (if at_rest { rest + dt } else { 0.0 }, v > lim.wake_speed)
}

/// Per-unit sleep bookkeeping, over the dense block table refined to units.
pub struct Sleep {
    pub cfg: SleepConfig,
    /// ASLEEP or AWAKE per unit (WOKEN only inside `update`), indexed by [`unit_index`].
    state: Pool<u8>,
    /// Awake unit: time its material has been at rest [s], or, negative, minus the settling
    /// time left since it woke (`wake_grace`). Sleeping unit: the simulation time at which it
    /// fell asleep [s] (for the build-up owed on waking).
    rest: Pool<f32>,
    /// Units woken by the current update (scratch; never more than the table holds).
    woken: Pool<u32>,
    /// Sleeping units per grid block, for the cheap pre-test of [`Holds::block`].
    asleep_in_block: Pool<u8>,
    /// (max speed, max strain rate) of each unit of each particle block of the last step, by
    /// slot; [`EMPTY_UNIT`] where the unit held no particle.
    pub activity: Pool<UnitActivity>,
    /// Units asleep now.
    pub sleeping_units: usize,
    /// The load tables, `load` to `reactions`, are empty unless loads are tested. Sleeping
    /// unit: the load on it [N], averaged over `load_time` (an exponential average, brought up
    /// to date whenever a step loads it).
    load: Pool<[f32; 3]>,
    /// Sleeping unit: the step whose load `load` last took in.
    load_step: Pool<u32>,
    /// Sleeping unit: the mean margin to yield of its particles when it fell asleep [Pa] (the
    /// least is near zero in material that just stopped flowing; see `load_floor`).
    margin: Pool<f32>,
    /// Sleeping unit: |load| [N] once its average had run long enough to be unbiased (NaN
    /// before): the load its frozen stress already carries, from the material that lay on it
    /// when it fell asleep.
    base: Pool<f32>,
    /// Units the last step loaded past their margin (state LOADED), for the next update.
    loaded: Pool<u32>,
    n_loaded: usize,
    /// Per grid node of the last grid update: the reaction of a held node [N] (zero elsewhere;
    /// written only in blocks near a sleeping unit).
    reactions: Pool<[f32; 3]>,
    /// Axis and sign of gravity (down), when gravity lies along an axis and loads are tested.
    down: Option<(usize, i32)>,
    /// 1 / (a unit's face area) [1/m^2].
    per_area: f32,
    /// Merging scratch, with `coarsen`.
    coarsen: Option<Coarsen>,
}

/// What the grid update needs of the sleeping units: which nodes they hold.
pub struct Holds<'a> {
    state: &'a [u8],
    asleep_in_block: &'a [u8],
    sleeping_units: usize,
}

/// Edge of a sleep unit in cells.
pub const US: i32 = 2;
/// Units per grid block.
pub const UNITS: usize = (BS / US as usize).pow(3);
/// (max speed, max strain rate) of the particles of each unit of a block.
pub type UnitActivity = [[Real; 2]; UNITS];
/// Activity of a unit without particles: below every threshold, and told apart from material at
/// rest (an empty unit must never sleep: it would hold the nodes of empty space).
pub const EMPTY_UNIT: [Real; 2] = [-1.0, -1.0];

/// Index of unit `u` (unit lattice coordinates, wrapped and inside the table) in the unit
/// tables: its block's index times [`UNITS`] plus its place in the block, so a block's units
/// are contiguous and the tables are the block table's layout, refined.
#[inline]
pub fn unit_index(geom: &GridGeom, u: [i32; 3]) -> u32 {
    let per = BS as i32 / US;
    let b = u.map(|c| c.div_euclid(per));
    let l = u.map(|c| c.rem_euclid(per) as u32);
    geom.block_index(b) * UNITS as u32 + (l[0] * per as u32 + l[1]) * per as u32 + l[2]
}

/// Unit lattice coordinates of the unit with table index `idx`.
#[inline]
pub(crate) fn unit_coords(geom: &GridGeom, idx: u32) -> [i32; 3] {
    let per = BS as i32 / US;
    let b = geom.block_coords(idx / UNITS as u32);
    let k = (idx % UNITS as u32) as i32;
    [b[0] * per + k / (per * per), b[1] * per + (k / per) % per, b[2] * per + k % per]
}

/// Place (0..UNITS) within its block of the unit of stencil base `base`, clamped to block
/// `origin`'s units (a particle that left its block this step counts in the nearest unit).
#[inline]
pub fn unit_in_block(origin: [i32; 3], base: [i32; 3]) -> usize {
    let per = BS as i32 / US;
    let l = std::array::from_fn::<i32, 3, _>(|a| ((base[a] - origin[a]).div_euclid(US)).clamp(0, per - 1));
    ((l[0] * per + l[1]) * per + l[2]) as usize
}

/// Unit of a particle at grid position `xg` (by its stencil base).
#[inline]
fn particle_unit(xg: V3) -> [i32; 3] {
    let (base, _) = crate::kernels::bspline::base_and_fx(xg);
    base.map(|b| b.div_euclid(US))
}

/// Wrap a unit coordinate on periodic axes.
#[inline]
pub(crate) fn wrap_unit(geom: &GridGeom, mut u: [i32; 3]) -> [i32; 3] {
    let per = BS as i32 / US;
    for a in 0..3 {
        if geom.periodic[a] {
            u[a] = u[a].rem_euclid(geom.nb[a] * per);
        }
    }
    u
}

#[inline]
pub(crate) fn unit_in_table(geom: &GridGeom, u: [i32; 3]) -> bool {
    let per = BS as i32 / US;
    (0..3).all(|a| u[a] >= 0 && u[a] < geom.nb[a] * per)
}

impl Sleep {
    pub fn plan(plan: &mut MemoryPlan, cfg: &SleepConfig, geom: &GridGeom, max_blocks: usize, capacity: usize, gravity: [f64; 3]) {
        let units = geom.table_len() * UNITS;
        plan.add::<u8>("sleep.state", units);
        plan.add::<f32>("sleep.rest", units);
        plan.add::<u32>("sleep.woken", units);
        plan.add::<u8>("sleep.asleep_in_block", geom.table_len());
        plan.add::<UnitActivity>("sleep.activity", max_blocks);
        if cfg.tests_loads(gravity) {
            plan.add::<[f32; 3]>("sleep.load", units);
            plan.add::<u32>("sleep.load_step", units);
            plan.add::<f32>("sleep.margin", units);
            plan.add::<f32>("sleep.base", units);
            plan.add::<u32>("sleep.loaded", units);
            plan.add::<[f32; 3]>("sleep.reactions", max_blocks * NODES_PER_BLOCK);
        }
        if cfg.coarsen {
            Coarsen::plan(plan, geom, capacity);
        }
    }

    /// Tables for `geom`'s domain with `max_blocks` grid slots and room for `capacity`
    /// particles, under `gravity` (the load tables empty unless loads are tested).
    pub fn new(cfg: SleepConfig, geom: &GridGeom, max_blocks: usize, capacity: usize, gravity: [f64; 3], b: &Backing) -> Result<Self, MemoryError> {
        let units = geom.table_len() * UNITS;
        let down = cfg.down(gravity);
        let per_unit = if down.is_some() { units } else { 0 };
        let per_node = if down.is_some() { max_blocks * NODES_PER_BLOCK } else { 0 };
        let face = US as f64 * geom.dx;
        let coarsen = if cfg.coarsen { Some(Coarsen::new(geom, capacity, b)?) } else { None };
        Ok(Sleep {
            cfg,
            coarsen,
            state: Pool::new("sleep.state", units, b)?,
            rest: Pool::new("sleep.rest", units, b)?,
            woken: Pool::new("sleep.woken", units, b)?,
            asleep_in_block: Pool::new("sleep.asleep_in_block", geom.table_len(), b)?,
            activity: Pool::new("sleep.activity", max_blocks, b)?,
            sleeping_units: 0,
            load: Pool::new("sleep.load", per_unit, b)?,
            load_step: Pool::new("sleep.load_step", per_unit, b)?,
            margin: Pool::new("sleep.margin", per_unit, b)?,
            base: Pool::new("sleep.base", per_unit, b)?,
            loaded: Pool::new("sleep.loaded", per_unit, b)?,
            n_loaded: 0,
            reactions: Pool::new("sleep.reactions", per_node, b)?,
            down,
            per_area: (1.0 / (face * face)) as f32,
        })
    }

    /// The per-unit tables, for checkpoints.
    pub fn tables(&self) -> SleepTables<'_> {
        SleepTables {
            state: self.state.as_slice(),
            rest: self.rest.as_slice(),
            load: self.load.as_slice(),
            load_step: self.load_step.as_slice(),
            margin: self.margin.as_slice(),
            base: self.base.as_slice(),
        }
    }

    pub fn tables_mut(&mut self) -> SleepTablesMut<'_> {
        SleepTablesMut {
            state: self.state.as_mut_slice(),
            rest: self.rest.as_mut_slice(),
            load: self.load.as_mut_slice(),
            load_step: self.load_step.as_mut_slice(),
            margin: self.margin.as_mut_slice(),
            base: self.base.as_mut_slice(),
        }
    }

    /// Rebuild what follows from the state table (after a checkpoint wrote it).
    pub fn recount(&mut self) {
        if !self.tests_loads() {
            // a checkpoint of a run with the load test, resumed without it: a unit its last step
            // loaded past its margin just sleeps on
            self.state.as_mut_slice().iter_mut().filter(|s| **s == LOADED).for_each(|s| *s = ASLEEP);
        }
        let state = self.state.as_slice();
        let per_block = self.asleep_in_block.as_mut_slice();
        self.sleeping_units = 0;
        for (b, n) in per_block.iter_mut().enumerate() {
            *n = state[b * UNITS..(b + 1) * UNITS].iter().filter(|&&s| asleep(s)).count() as u8;
            self.sleeping_units += *n as usize;
        }
        let loaded = self.loaded.as_mut_slice();
        self.n_loaded = 0;
        for (u, _) in state.iter().enumerate().filter(|(_, &s)| s == LOADED) {
            loaded[self.n_loaded] = u as u32;
            self.n_loaded += 1;
        }
    }

    /// Which nodes the sleeping units hold.
    pub fn holds(&self) -> Holds<'_> {
        Holds { state: self.state.as_slice(), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units }
    }

    /// Whether loads wake sleeping units (`wake_by_load`, under gravity along an axis): only
    /// then does the grid update need to leave held nodes' reactions for [`Sleep::take_loads`].
    pub fn tests_loads(&self) -> bool {
        self.down.is_some()
    }

    /// [`Sleep::holds`], and the per-node buffer the grid update leaves held nodes' reactions in.
    pub fn holds_and_reactions(&mut self) -> (Holds<'_>, &mut [[f32; 3]]) {
        let holds = Holds { state: self.state.as_slice(), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units };
        (holds, self.reactions.as_mut_slice())
    }

    /// Update rest times from the last step's activity (grid still binned as in that step, of
    /// length `dt`, ending at time `now`), wake and put units to sleep, and move particles
    /// accordingly. Units reaching into `keep_awake` (the nozzle tube: its material must follow
    /// the nozzle even while it rests) neither sleep nor stay asleep. Returns whether particles
    /// moved.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        grid: &Grid,
        particles: &mut Particles,
        material: &dyn Material,
        dt: f64,
        now: f64,
        step: u64,
        check_sleep: bool,
        keep_awake: Option<([f64; 3], [f64; 3])>,
    ) -> bool {
        let geom = &grid.geom;
        let npb = grid.n_particle_blocks;
        let slot_block = grid.slot_block.as_slice();
        let table = grid.table.as_slice();
        let activity = &self.activity.as_slice()[..npb];
        let limits = Limits::of(&self.cfg);
        let loads = self.tests_loads();
        let state = self.state.as_mut_slice();
        let rest = self.rest.as_mut_slice();
        let woken = self.woken.as_mut_slice();
        let mut n_woken = 0usize;
        // below (what a unit's speed may not wake) and above (what a unit falling asleep may
        // lie under while it moves) when loads are tested; without, the speed rule looks at all
        // 26 neighbours
        let (below, above) = match self.down {
            Some((a, sign)) => (Some((a, sign)), Some((a, -sign))),
            None => (None, None),
        };
        for &u in &self.loaded.as_slice()[..self.n_loaded] {
            wake(u, state, woken, &mut n_woken);
        }
        self.n_loaded = 0;
        for s in 0..npb {
            for (k, &[v, rate]) in activity[s].iter().enumerate() {
                let u = slot_block[s] * UNITS as u32 + k as u32;
                if [v, rate] == EMPTY_UNIT {
                    // no material: keep the clock at zero so that empty space never sleeps
                    if state[u as usize] == AWAKE {
                        rest[u as usize] = 0.0;
                    }
                    continue;
                }
                // awake material inside a sleeping unit, or fast material next to one, wakes it
                let wakes_neighbours = if state[u as usize] == AWAKE {
                    let (r, loud) = tick(rest[u as usize], [v, rate], dt as f32, &limits);
                    rest[u as usize] = r;
                    loud
                } else {
                    wake(u, state, woken, &mut n_woken);
                    v > limits.wake_speed
                };
                if wakes_neighbours {
                    // material arriving fast enough wakes the units under it too
                    let skip = if v > limits.arrive_speed { None } else { below };
                    for (off, nb) in neighbours(geom, u) {
                        if !on_side(skip, off) {
                            wake(nb, state, woken, &mut n_woken);
                        }
                    }
                }
            }
        }
        if let Some(bx) = keep_awake {
            // units whose stencil reach (one unit further) touches the tube
            let lo = unit_of_point(geom, bx.0, -1);
            let hi = unit_of_point(geom, bx.1, 0);
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        let u = wrap_unit(geom, [i, j, k]);
                        if unit_in_table(geom, u) {
                            let idx = unit_index(geom, u);
                            if state[idx as usize] == AWAKE {
                                rest[idx as usize] = rest[idx as usize].min(0.0);
                            } else {
                                wake(idx, state, woken, &mut n_woken);
                            }
                        }
                    }
                }
            }
        }
        let woke = n_woken;
        let grace = self.cfg.wake_grace as f32;
        let per_block = self.asleep_in_block.as_mut_slice();
        let mut slept = 0usize;
        if check_sleep {
            let rest_time = self.cfg.rest_time as f32;
            for s in 0..npb {
                for k in 0..UNITS {
                    let u = slot_block[s] * UNITS as u32 + k as u32;
                    if rest[u as usize] < rest_time || state[u as usize] != AWAKE || activity[s][k] == EMPTY_UNIT {
                        continue;
                    }
                    // material above may move up to `arrive_speed` (loads tested), the rest up to
                    // `wake_speed`
                    let calm = neighbours(geom, u).all(|(off, nb)| {
                        let limit = if on_side(above, off) { limits.arrive_speed } else { limits.wake_speed };
                        let t = table[nb as usize / UNITS];
                        t == EMPTY || (t as usize) >= npb || activity[t as usize][nb as usize % UNITS][0] <= limit
                    });
                    if calm {
                        state[u as usize] = ASLEEP;
                        rest[u as usize] = now as f32;
                        per_block[u as usize / UNITS] += 1;
                        woken[n_woken + slept] = u;
                        slept += 1;
                        if loads {
                            self.margin.as_mut_slice()[u as usize] = 0.0;
                            self.base.as_mut_slice()[u as usize] = f32::NAN;
                            self.load.as_mut_slice()[u as usize] = [0.0; 3];
                            self.load_step.as_mut_slice()[u as usize] = step as u32;
                        }
                    }
                }
            }
        }
        self.sleeping_units = self.sleeping_units + slept - woke;
        if woke > 0 {
            // the rest each woken unit owes its particles, then they leave the sleeping prefix
            for &u in &woken[..woke] {
                rest[u as usize] = (now - rest[u as usize] as f64).max(0.0) as f32;
                per_block[u as usize / UNITS] -= 1;
            }
            let sl = particles.state_len;
            let mut i = 0;
            while i < particles.n_sleep {
                let u = unit_index(geom, particle_unit(particles.xg.as_slice()[i]));
                if asleep(state[u as usize]) {
                    i += 1;
                } else {
                    let st = &mut particles.state.as_mut_slice()[i * sl..(i + 1) * sl];
                    material.rest_for(st, rest[u as usize] as Real);
                    particles.stress.as_mut_slice()[i] = material.stress_at_rest(st, particles.j.as_slice()[i]);
                    particles.n_sleep -= 1;
                    particles.swap(i, particles.n_sleep);
                }
            }
            for &u in &woken[..woke] {
                state[u as usize] = AWAKE;
                rest[u as usize] = -grace;
            }
            if loads {
                let (load, load_step) = (self.load.as_mut_slice(), self.load_step.as_mut_slice());
                let (margin, base) = (self.margin.as_mut_slice(), self.base.as_mut_slice());
                for &u in &woken[..woke] {
                    // zero, so that checkpoints store only sleeping units' entries
                    (load[u as usize], load_step[u as usize], margin[u as usize], base[u as usize]) = ([0.0; 3], 0, 0.0, 0.0);
                }
            }
        }
        if slept > 0 {
            let from = particles.n_sleep;
            let margin = self.margin.as_mut_slice();
            let sl = particles.state_len;
            for i in particles.n_sleep..particles.n {
                let u = unit_index(geom, particle_unit(particles.xg.as_slice()[i]));
                if state[u as usize] == ASLEEP {
                    particles.swap(i, particles.n_sleep);
                    let k = particles.n_sleep;
                    settle(particles, k, material);
                    if loads {
                        // summed here, counted in the unit's load (still zero), divided below
                        margin[u as usize] += material.yield_margin(&particles.state.as_slice()[k * sl..(k + 1) * sl]) as f32;
                        self.load.as_mut_slice()[u as usize][0] += 1.0;
                    }
                    particles.n_sleep += 1;
                }
            }
            if loads {
                // the mean margin of each unit's particles
                let load = self.load.as_mut_slice();
                for &u in &woken[woke..woke + slept] {
                    margin[u as usize] /= load[u as usize][0].max(1.0);
                    load[u as usize][0] = 0.0;
                }
            }
            if let Some(c) = &mut self.coarsen {
                c.merge_interior(geom, particles, from, material);
            }
        }
        woke > 0 || slept > 0
    }

    /// Take in the load of the grid update just done (its held nodes' reactions in
    /// `reactions`, step `step` of length `dt`, ending at `now`): each held node's reaction is
    /// shared among the sleeping units holding it, each unit's average load brought up to date,
    /// and units whose load passes the margin of the sleeping column under them are marked
    /// LOADED for the next update to wake (module notes).
    pub fn take_loads(&mut self, grid: &Grid, dt: f64, step: u64, now: f64, material: &dyn Material) {
        if self.sleeping_units == 0 || !self.tests_loads() {
            return;
        }
        let geom = &grid.geom;
        let slot_block = grid.slot_block.as_slice();
        let a = if self.cfg.load_time > 0.0 { (dt / self.cfg.load_time).min(1.0) as f32 } else { 1.0 };
        let step32 = step as u32;
        let touched = self.woken.as_mut_slice();
        let mut n_touched = 0usize;
        let holds = Holds { state: self.state.as_slice(), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units };
        let (load, load_step) = (self.load.as_mut_slice(), self.load_step.as_mut_slice());
        let reactions = self.reactions.as_slice();
        for (s, &bi) in slot_block[..grid.n_active].iter().enumerate() {
            let Some(window) = holds.block(geom, geom.block_coords(bi)) else {
                continue;
            };
            for li in 0..NODES_PER_BLOCK {
                let f = reactions[s * NODES_PER_BLOCK + li];
                if f == [0.0; 3] {
                    continue;
                }
                let mut holders = [0u32; 8];
                let mut n = 0;
                for u in window.holders(li) {
                    holders[n] = u;
                    n += 1;
                }
                let share = a / n as f32;
                for &u in &holders[..n] {
                    let (l, last) = (&mut load[u as usize], &mut load_step[u as usize]);
                    if *last != step32 {
                        // first share this step: decay over the steps since the last one
                        let gap = step32.wrapping_sub(*last).min(1 << 16) as i32;
                        let keep = (1.0 - a).powi(gap);
                        *l = l.map(|x| x * keep);
                        *last = step32;
                        touched[n_touched] = u;
                        n_touched += 1;
                    }
                    for k in 0..3 {
                        l[k] += share * f[k];
                    }
                }
            }
        }
        let (down_axis, sign) = self.down.expect("checked above");
        let (state, rest, margin) = (self.state.as_mut_slice(), self.rest.as_slice(), self.margin.as_slice());
        let base = self.base.as_mut_slice();
        let loaded = self.loaded.as_mut_slice();
        let tau = self.cfg.load_time;
        let (floor, fraction) = (self.cfg.load_floor as f32, self.cfg.load_fraction as f32);
        let column = geom.nb[down_axis] * (BS as i32 / US);
        for &u in &touched[..n_touched] {
            let l = load[u as usize];
            // the average has run since the unit fell asleep, from zero: unbias it
            let slept = now - rest[u as usize] as f64;
            let weight = if tau > 0.0 { 1.0 - (-slept / tau).exp() } else { 1.0 };
            if weight < 0.9 {
                continue;
            }
            let size = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt() / weight as f32;
            if base[u as usize].is_nan() {
                base[u as usize] = size;
                continue;
            }
            // only what was added since: the load it fell asleep under is in its stress
            let t = LOAD_SHARE * self.per_area * (size - base[u as usize]);
            // the deepest unit of the sleeping column from u down whose margin the load passes
            let mut c = unit_coords(geom, u);
            let (mut w, mut deepest) = (u, None);
            for depth in 1.. {
                let gain = material.strength_gain((now - rest[w as usize] as f64).max(0.0) as Real) as f32;
                if t > fraction * (margin[w as usize].max(0.0) + gain) + floor {
                    deepest = Some(c[down_axis]);
                }
                c[down_axis] += sign;
                let next = wrap_unit(geom, c);
                // (a column asleep all round a periodic axis ends where it began)
                if depth == column || !unit_in_table(geom, next) || !asleep(state[unit_index(geom, next) as usize]) {
                    break;
                }
                w = unit_index(geom, next);
            }
            let Some(last) = deepest else { continue };
            let mut c = unit_coords(geom, u);
            loop {
                let w = unit_index(geom, wrap_unit(geom, c));
                if state[w as usize] == ASLEEP {
                    state[w as usize] = LOADED;
                    loaded[self.n_loaded] = w;
                    self.n_loaded += 1;
                }
                if c[down_axis] == last {
                    break;
                }
                c[down_axis] += sign;
            }
        }
    }
}

impl Holds<'_> {
    /// The sleeping units whose stencil reach overlaps grid block `b` (None when there are
    /// none near it): a unit holds nodes 2u..=2u+3 on each axis, so these are the block's own
    /// units and one more below it on each axis. Looked up once per block, because the grid
    /// update and the load test ask for every node of a block near sleeping material.
    pub fn block(&self, geom: &GridGeom, b: [i32; 3]) -> Option<BlockHolds> {
        if self.sleeping_units == 0 {
            return None;
        }
        // block b and the blocks one below it on some axes (bit 2 - a of `d` set: below on
        // axis a), where they are in the table and hold a sleeping unit
        let mut near = [None; 8];
        for (d, slot) in near.iter_mut().enumerate() {
            let c = geom.wrap_block([b[0] - (d >> 2 & 1) as i32, b[1] - (d >> 1 & 1) as i32, b[2] - (d & 1) as i32]);
            if in_table(geom, c) {
                let bi = geom.block_index(c);
                *slot = (self.asleep_in_block[bi as usize] > 0).then_some(bi);
            }
        }
        if near == [None; 8] {
            return None;
        }
        let mut units = [NO_UNIT; WINDOW];
        for (w, slot) in units.iter_mut().enumerate() {
            // window coordinate 0 is the last unit of the block below, 1..=PER block b's units
            let wa = [w / (WE * WE), w / WE % WE, w % WE];
            let d = ((wa[0] == 0) as usize) << 2 | ((wa[1] == 0) as usize) << 1 | (wa[2] == 0) as usize;
            let Some(bi) = near[d] else { continue };
            let l = wa.map(|x| if x == 0 { PER - 1 } else { x - 1 });
            let idx = bi * UNITS as u32 + ((l[0] * PER + l[1]) * PER + l[2]) as u32;
            if asleep(self.state[idx as usize]) {
                *slot = idx;
            }
        }
        Some(BlockHolds { units })
    }
}

/// Units per block edge.
const PER: usize = BS / US as usize;
/// Edge of the window of units that can hold a block's nodes, and its size.
const WE: usize = PER + 1;
const WINDOW: usize = WE * WE * WE;
const NO_UNIT: u32 = u32::MAX;

/// The sleeping units that can hold the nodes of one grid block ([`Holds::block`]).
pub struct BlockHolds {
    /// Table index of each unit of the window, or NO_UNIT where it is awake or outside the table.
    units: [u32; WINDOW],
}

impl BlockHolds {
    /// Whether node `li` of the block is held.
    #[inline]
    pub fn holds(&self, li: usize) -> bool {
        self.holders(li).next().is_some()
    }

    /// The sleeping units holding node `li` of the block (at most 8): the units c - o, o in
    /// {0, 1}^3, of the node's unit c.
    #[inline]
    pub fn holders(&self, li: usize) -> impl Iterator<Item = u32> + '_ {
        let l = [li / (BS * BS), li / BS % BS, li % BS].map(|c| c / US as usize + 1);
        (0..8).filter_map(move |d| {
            let u = self.units[((l[0] - (d >> 2 & 1)) * WE + l[1] - (d >> 1 & 1)) * WE + l[2] - (d & 1)];
            (u != NO_UNIT).then_some(u)
        })
    }
}

/// The per-unit tables a checkpoint stores.
pub struct SleepTables<'a> {
    pub state: &'a [u8],
    pub rest: &'a [f32],
    pub load: &'a [[f32; 3]],
    pub load_step: &'a [u32],
    pub margin: &'a [f32],
    pub base: &'a [f32],
}

/// [`SleepTables`], to restore.
pub struct SleepTablesMut<'a> {
    pub state: &'a mut [u8],
    pub rest: &'a mut [f32],
    pub load: &'a mut [[f32; 3]],
    pub load_step: &'a mut [u32],
    pub margin: &'a mut [f32],
    pub base: &'a mut [f32],
}

/// Put particle `i` at rest: zero velocity and velocity gradient, and the stress its material
/// has at rest with its state and J (see the module notes: what a sleeping particle holds
/// besides its state and J is rebuilt, not stored).
pub fn settle(p: &mut Particles, i: usize, material: &dyn Material) {
    let sl = p.state_len;
    p.v.as_mut_slice()[i] = V3::ZERO;
    p.c.as_mut_slice()[i] = M3::ZERO;
    let state = &p.state.as_slice()[i * sl..(i + 1) * sl];
    p.stress.as_mut_slice()[i] = material.stress_at_rest(state, p.j.as_slice()[i]);
}

/// Unit holding world point `x`, shifted by `shift` units on every axis.
fn unit_of_point(geom: &GridGeom, x: [f64; 3], shift: i32) -> [i32; 3] {
    let us = US as f64;
    std::array::from_fn(|a| ((x[a] - geom.origin[a]) / geom.dx / us).floor() as i32 + shift)
}

#[inline]
fn in_table(geom: &GridGeom, b: [i32; 3]) -> bool {
    (0..3).all(|a| b[a] >= 0 && b[a] < geom.nb[a])
}

/// The offsets of the 26 neighbours of a lattice point (units here, cells in `coarsen.rs`).
pub(crate) fn offsets_26() -> impl Iterator<Item = [i32; 3]> + Clone {
    (0..27).filter(|&d| d != 13).map(|d| [d / 9 - 1, (d / 3) % 3 - 1, d % 3 - 1])
}

/// The 26 neighbours of unit `u` inside the table, each with its offset from `u`.
fn neighbours(geom: &GridGeom, u: u32) -> impl Iterator<Item = ([i32; 3], u32)> + '_ {
    let c = unit_coords(geom, u);
    offsets_26().filter_map(move |off| {
        let n = wrap_unit(geom, [c[0] + off[0], c[1] + off[1], c[2] + off[2]]);
        unit_in_table(geom, n).then(|| (off, unit_index(geom, n)))
    })
}

/// Whether a neighbour at offset `off` lies on `side` (`(axis, sign)`; e.g. `(2, -1)`: one of
/// the nine below); never when there is no side.
fn on_side(side: Option<(usize, i32)>, off: [i32; 3]) -> bool {
    side.is_some_and(|(a, sign)| off[a] == sign)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geom(periodic: [bool; 3]) -> GridGeom {
        let nb = [3, 2, 4];
        let cells = nb.map(|n| n * BS as i32);
        GridGeom { dx: 0.01, origin: [0.0; 3], cells, nb, periodic, lo: [0.0; 3], hi: [0.1; 3] }
    }

    /// Sleep tables for `geom` under gravity along -z, `config` its `[sleep]` keys, with units
    /// `asleep` asleep.
    fn sleep_with(geom: &GridGeom, config: &str, asleep: &[[i32; 3]]) -> Sleep {
        let cfg: SleepConfig = toml::from_str(config).unwrap();
        let mut s = Sleep::new(cfg, geom, geom.table_len(), 1, [0.0, 0.0, -9.81], &Backing::default()).unwrap();
        for &u in asleep {
            s.state.as_mut_slice()[unit_index(geom, u) as usize] = ASLEEP;
        }
        s.recount();
        s
    }

    #[test]
    fn a_woken_unit_settles_before_it_wakes_neighbours() {
        let cfg: SleepConfig = toml::from_str("wake_grace = 0.01").unwrap();
        let lim = Limits::of(&cfg);
        let (fast, calm, slow) = ([5e-3, 1.0], [1e-4, 1e-3], [1.5e-3, 1e-3]);
        let dt = 1e-3;
        // just woken: fast material wakes nobody until the grace is over, and does not rest
        let mut rest = -cfg.wake_grace as f32;
        let mut steps = 0;
        loop {
            let (r, loud) = tick(rest, fast, dt, &lim);
            rest = r;
            steps += 1;
            if loud {
                break;
            }
            assert!(rest <= 0.0 && steps < 100, "step {steps}: clock {rest}");
        }
        assert!((10..=12).contains(&steps), "woke neighbours after {steps} steps of 1 ms, grace 10 ms");
        assert_eq!(rest, 0.0, "fast material is not at rest");
        // after the grace: at rest counts up, moving (above the rest speed) resets, fast is loud
        let (r, loud) = tick(0.0, calm, dt, &lim);
        assert!(r == dt && !loud);
        let (r, loud) = tick(r, slow, dt, &lim);
        assert!(r == 0.0 && !loud, "1.5 mm/s is neither at rest nor loud");
        assert!(tick(0.02, fast, dt, &lim) == (0.0, true));
        // without a grace, a woken unit is loud at once
        let cfg: SleepConfig = toml::from_str("wake_grace = 0.0").unwrap();
        assert!(tick(-0.0, fast, dt, &Limits::of(&cfg)).1);
    }

    #[test]
    fn unit_index_is_a_bijection_onto_the_refined_table() {
        let g = geom([false; 3]);
        let per = BS as i32 / US;
        let mut seen = vec![false; g.table_len() * UNITS];
        for i in 0..g.nb[0] * per {
            for j in 0..g.nb[1] * per {
                for k in 0..g.nb[2] * per {
                    let idx = unit_index(&g, [i, j, k]);
                    assert!(!seen[idx as usize], "unit {:?} shares index {idx}", [i, j, k]);
                    seen[idx as usize] = true;
                    assert_eq!(unit_coords(&g, idx), [i, j, k]);
                    assert_eq!(idx as usize / UNITS, g.block_index([i / per, j / per, k / per]) as usize);
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
    }

    /// A node is held exactly by the sleeping units whose stencil reach 2u..=2u+3 holds it,
    /// in every block of the table.
    #[test]
    fn held_nodes_are_the_stencil_reach_of_sleeping_units() {
        for periodic in [[false; 3], [true, false, true]] {
            let g = geom(periodic);
            let asleep = [[0, 0, 0], [3, 1, 5], [5, 3, 7], [2, 2, 2]];
            let s = sleep_with(&g, "", &asleep);
            assert_eq!(s.sleeping_units, asleep.len());
            let mut held = 0;
            for bi in 0..g.table_len() as u32 {
                let b = g.block_coords(bi);
                let window = s.holds().block(&g, b);
                for li in 0..NODES_PER_BLOCK {
                    let n = g.node_of(b, li);
                    // offset of the node from the unit's first reach node (around the period on
                    // periodic axes)
                    let off = |u: &[i32; 3], a: usize| {
                        let d = n[a] - 2 * u[a];
                        if periodic[a] { d.rem_euclid(g.cells[a]) } else { d }
                    };
                    let mut want: Vec<u32> = asleep.iter().filter(|u| (0..3).all(|a| (0..=3).contains(&off(u, a)))).map(|&u| unit_index(&g, u)).collect();
                    let mut got: Vec<u32> = window.as_ref().map(|w| w.holders(li).collect()).unwrap_or_default();
                    want.sort();
                    got.sort();
                    assert_eq!(got, want, "node {n:?}");
                    assert_eq!(window.as_ref().is_some_and(|w| w.holds(li)), !want.is_empty());
                    held += !want.is_empty() as usize;
                }
            }
            // [0, 0, 0] and [2, 2, 2] hold 4^3 nodes each; the others fewer where the grid ends
            assert!(held >= 2 * 64, "{held} nodes held");
        }
    }

    #[test]
    fn the_load_keys_parse_with_their_defaults_and_validate() {
        let cfg: SleepConfig = toml::from_str("").unwrap();
        assert_eq!(cfg.wake_by_load, None, "the scenario resolves it from its layers");
        assert_eq!((cfg.load_time, cfg.load_floor, cfg.load_fraction, cfg.arrive_speed), (0.02, 20.0, 0.5, 0.01));
        assert!(cfg.validate().is_ok());
        assert!(cfg.tests_loads([0.0, 0.0, -9.81]), "unresolved, the safe side");
        let off: SleepConfig = toml::from_str("wake_by_load = false").unwrap();
        assert!(!off.tests_loads([0.0, 0.0, -9.81]));
        let on: SleepConfig = toml::from_str("wake_by_load = true\nload_floor = 5.0\nload_time = 0.01").unwrap();
        assert!(on.wake_by_load == Some(true) && on.load_floor == 5.0 && on.load_time == 0.01);
        assert!(on.validate().is_ok());
        assert!(on.tests_loads([0.0, 0.0, -9.81]) && on.tests_loads([9.81, 0.0, 0.0]));
        assert!(!on.tests_loads([0.0, 1.0, -9.81]) && !on.tests_loads([0.0; 3]), "no axis is down");
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            let cfg = SleepConfig { load_floor: bad, ..on.clone() };
            let e = cfg.validate().expect_err("an invalid floor passed");
            assert!(e.contains("sleep.load_floor"), "{e}");
        }
        let e = toml::from_str::<SleepConfig>("load_floor = nan").unwrap().validate().unwrap_err();
        assert!(e.contains("sleep.load_floor"), "{e}");
        for bad in [0.0, -0.5, 1.5, f64::NAN] {
            let cfg = SleepConfig { load_fraction: bad, ..on.clone() };
            let e = cfg.validate().expect_err("an invalid fraction passed");
            assert!(e.contains("sleep.load_fraction"), "{e}");
        }
        assert!(SleepConfig { load_fraction: 1.0, ..on.clone() }.validate().is_ok());
        for bad in [1e-3, -1.0, f64::NAN] {
            let cfg = SleepConfig { arrive_speed: bad, ..on.clone() };
            let e = cfg.validate().expect_err("an invalid arrival speed passed");
            assert!(e.contains("sleep.arrive_speed"), "{e}");
        }
        let by_load_alone: SleepConfig = toml::from_str("wake_by_load = true\narrive_speed = inf").unwrap();
        assert!(by_load_alone.validate().is_ok() && by_load_alone.arrive_speed == f64::INFINITY);
    }

    fn evp(a_thix: f64) -> Box<dyn Material> {
        let text = format!(
            "kind = \"evp_bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\npoisson_ratio = 0.3\nviscosity = 7.5\nyield_stress = 630.0\na_thix = {a_thix}\n"
        );
        crate::materials::build_material(&text.parse::<toml::Table>().unwrap()).unwrap()
    }

    /// A grid on `geom` whose first active slots are `first` (then every other block), the
    /// first `particle_blocks` of them holding particles.
    fn grid_with(geom: &GridGeom, first: &[[i32; 3]], particle_blocks: usize) -> Grid {
        let mut grid = Grid::new(geom.clone(), geom.table_len(), &Backing::default()).unwrap();
        for &b in first {
            grid.activate(geom.block_index(b)).unwrap();
        }
        for b in 0..geom.table_len() as u32 {
            grid.activate(b).unwrap();
        }
        grid.n_particle_blocks = particle_blocks;
        grid
    }

    /// Under the speed rule fast material above a sleeping unit wakes it. With the load test it
    /// does not (its load does, if it can make the unit yield), unless it is faster than
    /// `arrive_speed`.
    #[test]
    fn fast_material_above_wakes_a_sleeping_unit_only_under_the_speed_rule() {
        let g = geom([false; 3]);
        let mat = evp(0.0);
        let (below, above): ([i32; 3], [i32; 3]) = ([2, 1, 4], [2, 1, 5]);
        let block = above.map(|c| c.div_euclid(BS as i32 / US));
        let k = unit_index(&g, above) as usize % UNITS;
        let configs = [
            ("wake_by_load = false", true),
            ("wake_by_load = true\narrive_speed = inf", false),
            ("wake_by_load = true\narrive_speed = 0.004", true),
            ("wake_by_load = true\narrive_speed = 0.02", false),
        ];
        for (config, wakes) in configs {
            let mut s = sleep_with(&g, config, &[below]);
            assert_eq!(s.tests_loads(), config.starts_with("wake_by_load = true"));
            let grid = grid_with(&g, &[block], 1);
            let mut act = [EMPTY_UNIT; UNITS];
            act[k] = [5.0 * s.cfg.wake_speed as Real, 1.0];
            s.activity.as_mut_slice()[0] = act;
            let mut particles = Particles::new(1, mat.state_names().len(), &Backing::default()).unwrap();
            let moved = s.update(&grid, &mut particles, &*mat, 1e-3, 1.0, 1000, false, None);
            let state = s.state.as_slice()[unit_index(&g, below) as usize];
            assert_eq!((moved, state == AWAKE, s.sleeping_units), (wakes, wakes, !wakes as usize), "config '{config}'");
        }
    }

    /// With the load test, material moving above a unit at rest keeps it awake only when faster
    /// than `arrive_speed`; under the speed rule, when faster than `wake_speed`.
    #[test]
    fn material_above_keeps_a_unit_awake_only_when_it_arrives_fast() {
        let g = geom([false; 3]);
        let mat = evp(0.0);
        let (below, above): ([i32; 3], [i32; 3]) = ([2, 1, 4], [2, 1, 5]);
        let block = above.map(|c| c.div_euclid(BS as i32 / US));
        let configs = [
            ("wake_by_load = false", false),
            ("wake_by_load = true\narrive_speed = inf", true),
            ("wake_by_load = true\narrive_speed = 0.004", false),
            ("wake_by_load = true\narrive_speed = 0.02", true),
        ];
        for (config, sleeps) in configs {
            let mut s = sleep_with(&g, config, &[]);
            s.rest.as_mut_slice()[unit_index(&g, below) as usize] = 1.0;
            let grid = grid_with(&g, &[block], 1);
            let mut act = [EMPTY_UNIT; UNITS];
            act[unit_index(&g, below) as usize % UNITS] = [0.0, 0.0];
            act[unit_index(&g, above) as usize % UNITS] = [5.0 * s.cfg.wake_speed as Real, 1.0];
            s.activity.as_mut_slice()[0] = act;
            let mut particles = Particles::new(1, mat.state_names().len(), &Backing::default()).unwrap();
            s.update(&grid, &mut particles, &*mat, 1e-3, 1.0, 1000, true, None);
            let state = s.state.as_slice()[unit_index(&g, below) as usize];
            assert_eq!((state == ASLEEP, s.sleeping_units), (sleeps, sleeps as usize), "config '{config}'");
        }
    }

    /// A sleeping column for the load rule under `config`, top to bottom, with these margins
    /// [Pa] (A_thix = 10 Pa/s): the load it fell asleep under sets its base and never wakes it,
    /// and 25 Pa more wakes nothing (that passes the bottom-but-one unit's 10 Pa margin, plus
    /// under 6 Pa of build-up, but not by the 20 Pa floor). Then `extra` Pa over the base: the
    /// column's states, the time, the step, and what `update` needs to wake the loaded units.
    fn loaded_column(config: &str, extra: f32) -> ([u8; 4], Sleep, Grid, Box<dyn Material>, f64, u64) {
        let g = geom([false; 3]);
        let mat = evp(10.0);
        let column = [([2, 1, 4], 30.0), ([2, 1, 3], 80.0), ([2, 1, 2], 10.0), ([2, 1, 1], 150.0)];
        let units: Vec<[i32; 3]> = column.iter().map(|c| c.0).collect();
        let mut s = sleep_with(&g, config, &units);
        for &(u, m) in &column {
            let i = unit_index(&g, u) as usize;
            // fell asleep at t = 0 in step 0, as `update` leaves a unit falling asleep
            (s.rest.as_mut_slice()[i], s.margin.as_mut_slice()[i], s.base.as_mut_slice()[i]) = (0.0, m, f32::NAN);
        }
        // a node only the top unit holds (its stencil reach is nodes 2u..=2u+3): the weight on
        // the column
        let node: [i32; 3] = [5, 3, 11];
        let b = node.map(|c| c.div_euclid(BS as i32));
        let li = (0..NODES_PER_BLOCK).find(|&li| g.node_of(b, li) == node).unwrap();
        let holders: Vec<u32> = s.holds().block(&g, b).unwrap().holders(li).collect();
        assert_eq!(holders, [unit_index(&g, column[0].0)]);
        let grid = grid_with(&g, &[b], 0);
        let at = grid.slot(g.block_index(b)) as usize * NODES_PER_BLOCK + li;
        // the load whose share of tau is `tau` [Pa] (what it adds on the unit's face)
        let share = LOAD_SHARE * s.per_area;
        let force = |tau: f32| tau / share;
        let dt = 1e-3;
        let mut step = 0u64;
        // ten `load_time`s a phase: the average has converged
        let mut carry = |s: &mut Sleep, load: f32| {
            for _ in 0..200 {
                step += 1;
                s.reactions.as_mut_slice()[at] = [0.0, 0.0, -load];
                s.take_loads(&grid, dt, step, step as f64 * dt, &*mat);
            }
            step as f64 * dt
        };
        let states = |s: &Sleep| column.map(|(u, _)| s.state.as_slice()[unit_index(&g, u) as usize]);
        let weight = force(300.0);
        carry(&mut s, weight);
        let base = s.base.as_slice()[holders[0] as usize];
        assert!((base / weight - 1.0).abs() < 0.01, "base {base} N under a {weight} N load");
        assert_eq!(states(&s), [ASLEEP; 4]);
        let now = carry(&mut s, weight + force(25.0));
        assert!(mat.strength_gain(now as Real) < 6.0);
        assert_eq!((states(&s), s.n_loaded), ([ASLEEP; 4], 0), "config '{config}'");
        let now = carry(&mut s, weight + force(extra));
        (states(&s), s, grid, mat, now, step)
    }

    /// The load rule on a sleeping column: the load added on its top unit since it fell asleep,
    /// averaged, wakes the column down to the deepest unit whose margin (plus its build-up and
    /// `load_floor`) the load's share of tau passes, and no unit when it passes none.
    #[test]
    fn a_load_wakes_the_sleeping_column_down_to_the_deepest_unit_it_makes_yield() {
        // 70 Pa more passes the top unit's and the bottom-but-one's margins: the three upper
        // units are loaded, the bottom one (150 Pa) is not
        let (states, mut s, grid, mat, now, step) = loaded_column("wake_by_load = true", 70.0);
        assert_eq!(states, [LOADED, LOADED, LOADED, ASLEEP]);
        assert_eq!(s.n_loaded, 3);
        // the next update wakes them; their nodes were held until then
        let mut particles = Particles::new(1, mat.state_names().len(), &Backing::default()).unwrap();
        assert!(s.update(&grid, &mut particles, &*mat, 1e-3, now, step, false, None));
        let g = geom([false; 3]);
        let after = [[2, 1, 4], [2, 1, 3], [2, 1, 2], [2, 1, 1]].map(|u| s.state.as_slice()[unit_index(&g, u) as usize]);
        assert_eq!(after, [AWAKE, AWAKE, AWAKE, ASLEEP]);
        assert_eq!((s.sleeping_units, s.n_loaded), (1, 0));
    }

    /// `load_fraction` (0.5 by default): a unit wakes once the load passes that share of its
    /// margin. 100 Pa passes half the bottom unit's 150 Pa (plus the floor) but not all of it.
    #[test]
    fn a_load_wakes_at_its_fraction_of_the_margin() {
        let (whole, ..) = loaded_column("wake_by_load = true\nload_fraction = 1.0", 100.0);
        assert_eq!(whole, [LOADED, LOADED, LOADED, ASLEEP]);
        let (half, ..) = loaded_column("wake_by_load = true", 100.0);
        assert_eq!(half, [LOADED; 4]);
    }
}
