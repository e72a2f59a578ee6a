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
//! the nozzle; a still tube holds its nodes at rest, as a sleeping unit does).
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

use crate::grid::{Grid, GridGeom, EMPTY};
use crate::kernels::transfer::BS;
use crate::kernels::material::Material;
use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::particles::Particles;
use serde::Deserialize;

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SleepConfig {
    /// Particle speed below which material counts as at rest [m/s].
    #[serde(default = "default_speed")]
    pub speed: f64,
    /// Strain rate |sym(grad v)| below which material counts as at rest [1/s].
    #[serde(default = "default_rate")]
    pub strain_rate: f64,
    /// Time at rest before a unit sleeps [s].
    #[serde(default = "default_rest")]
    pub rest_time: f64,
    /// Speed of neighbouring material that wakes a sleeping unit [m/s].
    #[serde(default = "default_wake")]
    pub wake_speed: f64,
    /// Time a woken unit settles before its own speed can wake its neighbours [s].
    #[serde(default = "default_grace")]
    pub wake_grace: f64,
    /// Steps between checks for units to put to sleep.
    #[serde(default = "default_check")]
    pub check_interval: u64,
}

fn default_speed() -> f64 {
    // Each emitted slab sends an elastic pulse through deposited EVP material: block maxima of
    // 1e-4-5e-4 m/s pass every slab interval (measured on case 1), so a lower threshold never
    // lets a block rest while the nozzle runs. Material still creeping at 1 mm/s for the rest
    // time moves 0.05 mm: below 1 % of a layer.
    1e-3
}
fn default_rate() -> f64 {
    // Elastic waves from the nozzle keep deposited EVP material straining at ~1e-2 /s (speeds
    // ~3e-5 m/s over a 2.5 mm cell, measured on case 1) without changing its shape; 0.1 /s sits
    // above that noise and far below flow under the nozzle (~10 /s).
    0.1
}
fn default_rest() -> f64 {
    0.05
}
fn default_wake() -> f64 {
    // Slow enough to wake the flanks of a layer that the next layer spreads (1-2 mm/s); well
    // above the elastic pulses of emission (1e-4-5e-4 m/s). Measured on the three-layer print at
    // 2.5 mm (BENCHMARKS.md "Sleeping"): with 1e-2 the first layer's flanks slept through the
    // second layer's passage and the section came out 1.37 % narrower than all-awake; with
    // 4e-3, 1.02 %; with 2e-3, 0.26 %.
    2e-3
}
fn default_grace() -> f64 {
    // Many times the pulse's passage through a unit (5 mm at c ~ 28 m/s: 0.2 ms), leaving room
    // for the ringing after it; short enough that flow reaching a sleeping neighbour is held
    // back by at most 0.02 s x 2 mm/s = 0.04 mm. Measured, ten layers at 5 mm: 268 CPU s with
    // 0.02 s, 295 s with 0.1 s, 423 s without (BENCHMARKS.md "Sleeping").
    0.02
}
fn default_check() -> u64 {
    64
}

impl SleepConfig {
    pub fn validate(&self) -> Result<(), String> {
        for (k, v) in [
            ("sleep.speed", self.speed),
            ("sleep.strain_rate", self.strain_rate),
            ("sleep.rest_time", self.rest_time),
            ("sleep.wake_speed", self.wake_speed),
            ("sleep.wake_grace", self.wake_grace),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(format!("{k} must be >= 0, got {v}"));
            }
        }
        if self.wake_speed < self.speed {
            return Err(format!(
                "sleep.wake_speed ({}) must be >= sleep.speed ({}), or blocks would wake at rest",
                self.wake_speed, self.speed
            ));
        }
        if self.check_interval == 0 {
            return Err("sleep.check_interval must be >= 1".into());
        }
        Ok(())
    }
}

const AWAKE: u8 = 0;
const ASLEEP: u8 = 1;
/// Within one update: woken, its sleep start still in `rest` until its particles had their rest.
const WOKEN: u8 = 2;

#[inline]
fn wake(b: u32, state: &mut [u8], woken: &mut [u32], n_woken: &mut usize) {
    if state[b as usize] == ASLEEP {
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
}

impl Limits {
    fn of(cfg: &SleepConfig) -> Self {
        Limits { rest_speed: cfg.speed as Real, rest_rate: cfg.strain_rate as Real, wake_speed: cfg.wake_speed as Real }
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
    /// Sleeping units per grid block, for the cheap test of [`Sleep::near_block`].
    asleep_in_block: Pool<u8>,
    /// (max speed, max strain rate) of each unit of each particle block of the last step, by
    /// slot; [`EMPTY_UNIT`] where the unit held no particle.
    pub activity: Pool<UnitActivity>,
    /// Units asleep now.
    pub sleeping_units: usize,
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
fn unit_coords(geom: &GridGeom, idx: u32) -> [i32; 3] {
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
fn wrap_unit(geom: &GridGeom, mut u: [i32; 3]) -> [i32; 3] {
    let per = BS as i32 / US;
    for a in 0..3 {
        if geom.periodic[a] {
            u[a] = u[a].rem_euclid(geom.nb[a] * per);
        }
    }
    u
}

#[inline]
fn unit_in_table(geom: &GridGeom, u: [i32; 3]) -> bool {
    let per = BS as i32 / US;
    (0..3).all(|a| u[a] >= 0 && u[a] < geom.nb[a] * per)
}

impl Sleep {
    pub fn plan(plan: &mut MemoryPlan, geom: &GridGeom, max_blocks: usize) {
        plan.add::<u8>("sleep.state", geom.table_len() * UNITS);
        plan.add::<f32>("sleep.rest", geom.table_len() * UNITS);
        plan.add::<u32>("sleep.woken", geom.table_len() * UNITS);
        plan.add::<u8>("sleep.asleep_in_block", geom.table_len());
        plan.add::<UnitActivity>("sleep.activity", max_blocks);
    }

    pub fn new(cfg: SleepConfig, geom: &GridGeom, max_blocks: usize, b: &Backing) -> Result<Self, MemoryError> {
        Ok(Sleep {
            cfg,
            state: Pool::new("sleep.state", geom.table_len() * UNITS, b)?,
            rest: Pool::new("sleep.rest", geom.table_len() * UNITS, b)?,
            woken: Pool::new("sleep.woken", geom.table_len() * UNITS, b)?,
            asleep_in_block: Pool::new("sleep.asleep_in_block", geom.table_len(), b)?,
            activity: Pool::new("sleep.activity", max_blocks, b)?,
            sleeping_units: 0,
        })
    }

    /// The per-unit tables (state, rest time), for checkpoints.
    pub fn tables(&self) -> (&[u8], &[f32]) {
        (self.state.as_slice(), self.rest.as_slice())
    }

    pub fn tables_mut(&mut self) -> (&mut [u8], &mut [f32]) {
        (self.state.as_mut_slice(), self.rest.as_mut_slice())
    }

    /// Rebuild what follows from the state table (after a checkpoint wrote it).
    pub fn recount(&mut self) {
        let state = self.state.as_slice();
        let per_block = self.asleep_in_block.as_mut_slice();
        self.sleeping_units = 0;
        for (b, n) in per_block.iter_mut().enumerate() {
            *n = state[b * UNITS..(b + 1) * UNITS].iter().filter(|&&s| s == ASLEEP).count() as u8;
            self.sleeping_units += *n as usize;
        }
    }

    #[inline]
    fn is_asleep(&self, unit: u32) -> bool {
        self.state.as_slice()[unit as usize] == ASLEEP
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
        check_sleep: bool,
        keep_awake: Option<([f64; 3], [f64; 3])>,
    ) -> bool {
        let geom = &grid.geom;
        let npb = grid.n_particle_blocks;
        let slot_block = grid.slot_block.as_slice();
        let table = grid.table.as_slice();
        let activity = &self.activity.as_slice()[..npb];
        let limits = Limits::of(&self.cfg);
        let state = self.state.as_mut_slice();
        let rest = self.rest.as_mut_slice();
        let woken = self.woken.as_mut_slice();
        let mut n_woken = 0usize;
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
                    for nb in neighbours(geom, u) {
                        wake(nb, state, woken, &mut n_woken);
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
                    let calm = neighbours(geom, u).all(|nb| {
                        let t = table[nb as usize / UNITS];
                        t == EMPTY || (t as usize) >= npb || activity[t as usize][nb as usize % UNITS][0] <= limits.wake_speed
                    });
                    if calm {
                        state[u as usize] = ASLEEP;
                        rest[u as usize] = now as f32;
                        per_block[u as usize / UNITS] += 1;
                        slept += 1;
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
                if state[u as usize] == ASLEEP {
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
        }
        if slept > 0 {
            for i in particles.n_sleep..particles.n {
                let u = unit_index(geom, particle_unit(particles.xg.as_slice()[i]));
                if state[u as usize] == ASLEEP {
                    particles.swap(i, particles.n_sleep);
                    settle(particles, particles.n_sleep, material);
                    particles.n_sleep += 1;
                }
            }
        }
        woke > 0 || slept > 0
    }

    /// Whether grid node `g` lies in the stencil reach of a sleeping unit: nodes
    /// 2u..=2u+3 on each axis, the nodes a particle of unit u can touch.
    #[inline]
    pub fn holds_node(&self, geom: &GridGeom, g: [i32; 3]) -> bool {
        let c = g.map(|x| x.div_euclid(US));
        (0..8).any(|d| {
            let u = wrap_unit(geom, [c[0] - (d >> 2 & 1), c[1] - (d >> 1 & 1), c[2] - (d & 1)]);
            unit_in_table(geom, u) && self.is_asleep(unit_index(geom, u))
        })
    }

    /// Whether any unit whose stencil reach overlaps grid block `b` sleeps (a cheap pre-test):
    /// such a unit lies in block b or in a block one below it on some axes.
    #[inline]
    pub fn near_block(&self, geom: &GridGeom, b: [i32; 3]) -> bool {
        if self.sleeping_units == 0 {
            return false;
        }
        let per_block = self.asleep_in_block.as_slice();
        (0..8).any(|d| {
            let c = geom.wrap_block([b[0] - (d >> 2 & 1), b[1] - (d >> 1 & 1), b[2] - (d & 1)]);
            in_table(geom, c) && per_block[geom.block_index(c) as usize] > 0
        })
    }
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

/// The 26 neighbours of unit `u` inside the table.
fn neighbours(geom: &GridGeom, u: u32) -> impl Iterator<Item = u32> + '_ {
    let c = unit_coords(geom, u);
    (0..27).filter(|&d| d != 13).filter_map(move |d| {
        let n = wrap_unit(geom, [c[0] + d / 9 - 1, c[1] + (d / 3) % 3 - 1, c[2] + d % 3 - 1]);
        unit_in_table(geom, n).then(|| unit_index(geom, n))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geom(periodic: [bool; 3]) -> GridGeom {
        let nb = [3, 2, 4];
        let cells = nb.map(|n| n * BS as i32);
        GridGeom { dx: 0.01, origin: [0.0; 3], cells, nb, periodic, lo: [0.0; 3], hi: [0.1; 3] }
    }

    fn sleep_with(geom: &GridGeom, asleep: &[[i32; 3]]) -> Sleep {
        let cfg: SleepConfig = toml::from_str("").unwrap();
        let mut s = Sleep::new(cfg, geom, 4, &Backing::default()).unwrap();
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

    /// A node is held exactly when it lies in the stencil reach 2u..=2u+3 of a sleeping unit,
    /// and `near_block` passes every grid block holding such a node (it is the pre-test).
    #[test]
    fn held_nodes_are_the_stencil_reach_of_sleeping_units() {
        for periodic in [[false; 3], [true, false, true]] {
            let g = geom(periodic);
            let asleep = [[0, 0, 0], [3, 1, 5], [5, 3, 7], [2, 2, 2]];
            let s = sleep_with(&g, &asleep);
            assert_eq!(s.sleeping_units, asleep.len());
            for x in -2..g.cells[0] + 2 {
                for y in -2..g.cells[1] + 2 {
                    for z in -2..g.cells[2] + 2 {
                        let n = [x, y, z];
                        // offset of the node from the unit's first reach node (around the
                        // period on periodic axes)
                        let off = |u: &[i32; 3], a: usize| {
                            let d = n[a] - 2 * u[a];
                            if periodic[a] { d.rem_euclid(g.cells[a]) } else { d }
                        };
                        let want = asleep.iter().any(|u| (0..3).all(|a| (0..=3).contains(&off(u, a))));
                        assert_eq!(s.holds_node(&g, n), want, "node {n:?}");
                        let b = n.map(|c| c.div_euclid(BS as i32));
                        if want && in_table(&g, g.wrap_block(b)) {
                            assert!(s.near_block(&g, b), "block {b:?} holds node {n:?} but fails the pre-test");
                        }
                    }
                }
            }
        }
    }
}
