//! Sleeping blocks: deposited material at rest stops costing anything.
//!
//! A block of the grid sleeps when the particles binned to it (by their stencil base) have moved
//! slower than `speed` and strained slower than `strain_rate` for `rest_time`, and no neighbour
//! block holds material faster than `wake_speed`. Its particles move into the sleeping prefix
//! `0..n_sleep` of the pool, out of every per-step loop. Active material that reaches them sees
//! a still, no-slip body: grid nodes inside a sleeping block's stencil reach are held at rest. A
//! sleeping block wakes as soon as material faster than `wake_speed` is binned next to it (new
//! material arriving, or a load making its neighbour move), when an awake particle enters it, or
//! when the nozzle tube reaches it (material in the tube must follow the nozzle).
//!
//! Sleeping freezes the stress. The internal state is not stepped either, but material at rest
//! still builds up structure (thixotropy): a block remembers when it fell asleep, and on waking
//! its particles get the whole rest interval at once ([`Material::rest_for`]), so a deposited
//! layer gains the strength it would have had awake. A particle falling asleep is settled: its
//! velocity and velocity gradient (below the rest thresholds anyway) become zero and its stress
//! the material's stress at rest for its state and J, so a restart checkpoint rebuilds all three
//! from (state, J) instead of storing 84 bytes per sleeping particle in f32. Going to sleep is
//! checked every `check_interval` steps (it moves particles, O(awake particles)); waking is
//! checked every step and moves particles only when a block actually wakes (O(sleeping
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
    /// Time at rest before a block sleeps [s].
    #[serde(default = "default_rest")]
    pub rest_time: f64,
    /// Speed of neighbouring material that wakes a sleeping block [m/s].
    #[serde(default = "default_wake")]
    pub wake_speed: f64,
    /// Steps between checks for blocks to put to sleep.
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
    1e-2
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

/// Per-block sleep bookkeeping, over the dense block table.
pub struct Sleep {
    pub cfg: SleepConfig,
    /// ASLEEP or AWAKE per block (WOKEN only inside `update`).
    state: Pool<u8>,
    /// Awake block: time its material has been at rest [s]. Sleeping block: the simulation time
    /// at which it fell asleep [s] (for the build-up owed on waking).
    rest: Pool<f32>,
    /// Blocks woken by the current update (scratch; never more than the table holds).
    woken: Pool<u32>,
    /// (max speed, max strain rate) of each particle block of the last step, by slot.
    pub activity: Pool<[Real; 2]>,
    /// Blocks asleep now.
    pub sleeping_blocks: usize,
}

impl Sleep {
    pub fn plan(plan: &mut MemoryPlan, geom: &GridGeom, max_blocks: usize) {
        plan.add::<u8>("sleep.state", geom.table_len());
        plan.add::<f32>("sleep.rest", geom.table_len());
        plan.add::<u32>("sleep.woken", geom.table_len());
        plan.add::<[Real; 2]>("sleep.activity", max_blocks);
    }

    pub fn new(cfg: SleepConfig, geom: &GridGeom, max_blocks: usize, b: &Backing) -> Result<Self, MemoryError> {
        Ok(Sleep {
            cfg,
            state: Pool::new("sleep.state", geom.table_len(), b)?,
            rest: Pool::new("sleep.rest", geom.table_len(), b)?,
            woken: Pool::new("sleep.woken", geom.table_len(), b)?,
            activity: Pool::new("sleep.activity", max_blocks, b)?,
            sleeping_blocks: 0,
        })
    }

    /// The per-block tables (state, rest time), for checkpoints.
    pub fn tables(&self) -> (&[u8], &[f32]) {
        (self.state.as_slice(), self.rest.as_slice())
    }

    pub fn tables_mut(&mut self) -> (&mut [u8], &mut [f32]) {
        (self.state.as_mut_slice(), self.rest.as_mut_slice())
    }

    #[inline]
    pub fn is_asleep(&self, block: u32) -> bool {
        self.state.as_slice()[block as usize] == ASLEEP
    }

    /// Update rest times from the last step's activity (grid still binned as in that step, of
    /// length `dt`, ending at time `now`), wake and put blocks to sleep, and move particles
    /// accordingly. Blocks reaching into `keep_awake` (the nozzle tube: its material must follow
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
        let (wake_v, rest_v, rest_rate) = (self.cfg.wake_speed as Real, self.cfg.speed as Real, self.cfg.strain_rate as Real);
        let state = self.state.as_mut_slice();
        let rest = self.rest.as_mut_slice();
        let woken = self.woken.as_mut_slice();
        let mut n_woken = 0usize;
        for s in 0..npb {
            let b = slot_block[s];
            let [v, rate] = activity[s];
            // awake material inside a sleeping block, or fast material next to one, wakes it
            if state[b as usize] != AWAKE {
                wake(b, state, woken, &mut n_woken);
            } else if v < rest_v && rate < rest_rate {
                rest[b as usize] += dt as f32;
            } else {
                rest[b as usize] = 0.0;
            }
            if v > wake_v {
                for nb in neighbours(geom, b) {
                    wake(nb, state, woken, &mut n_woken);
                }
            }
        }
        if let Some(bx) = keep_awake {
            // blocks whose stencil reach (one block further) touches the tube
            let lo = grid_block_of(geom, bx.0, -1);
            let hi = grid_block_of(geom, bx.1, 0);
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        let b = geom.wrap_block([i, j, k]);
                        if in_table(geom, b) {
                            let idx = geom.block_index(b);
                            if state[idx as usize] == AWAKE {
                                rest[idx as usize] = 0.0;
                            } else {
                                wake(idx, state, woken, &mut n_woken);
                            }
                        }
                    }
                }
            }
        }
        let woke = n_woken;
        let mut slept = 0usize;
        if check_sleep {
            let rest_time = self.cfg.rest_time as f32;
            for &b in &slot_block[..npb] {
                if rest[b as usize] < rest_time || state[b as usize] != AWAKE {
                    continue;
                }
                let calm = neighbours(geom, b).all(|nb| {
                    let t = table[nb as usize];
                    t == EMPTY || (t as usize) >= npb || activity[t as usize][0] <= wake_v
                });
                if calm {
                    state[b as usize] = ASLEEP;
                    rest[b as usize] = now as f32;
                    slept += 1;
                }
            }
        }
        self.sleeping_blocks = self.sleeping_blocks + slept - woke;
        if woke > 0 {
            // the rest each woken block owes its particles, then they leave the sleeping prefix
            for &b in &woken[..woke] {
                rest[b as usize] = (now - rest[b as usize] as f64).max(0.0) as f32;
            }
            let sl = particles.state_len;
            let mut i = 0;
            while i < particles.n_sleep {
                let b = geom.block_index(geom.particle_block(particles.xg.as_slice()[i]));
                if state[b as usize] == ASLEEP {
                    i += 1;
                } else {
                    let st = &mut particles.state.as_mut_slice()[i * sl..(i + 1) * sl];
                    material.rest_for(st, rest[b as usize] as Real);
                    particles.stress.as_mut_slice()[i] = material.stress_at_rest(st, particles.j.as_slice()[i]);
                    particles.n_sleep -= 1;
                    particles.swap(i, particles.n_sleep);
                }
            }
            for &b in &woken[..woke] {
                state[b as usize] = AWAKE;
                rest[b as usize] = 0.0;
            }
        }
        if slept > 0 {
            for i in particles.n_sleep..particles.n {
                let b = geom.block_index(geom.particle_block(particles.xg.as_slice()[i]));
                if state[b as usize] == ASLEEP {
                    particles.swap(i, particles.n_sleep);
                    settle(particles, particles.n_sleep, material);
                    particles.n_sleep += 1;
                }
            }
        }
        woke > 0 || slept > 0
    }

    /// Whether grid node `g` lies in the stencil reach of a sleeping block: its nodes
    /// 4b..=4b+5 on each axis, the nodes a particle binned to block b can touch.
    #[inline]
    pub fn holds_node(&self, geom: &GridGeom, g: [i32; 3]) -> bool {
        let bs = BS as i32;
        let mut cand = [[0i32; 2]; 3];
        let mut cnt = [0usize; 3];
        for a in 0..3 {
            let b = g[a].div_euclid(bs);
            cand[a][0] = b;
            cnt[a] = 1;
            if g[a].rem_euclid(bs) <= 1 {
                cand[a][1] = b - 1;
                cnt[a] = 2;
            }
        }
        for i in 0..cnt[0] {
            for j in 0..cnt[1] {
                for k in 0..cnt[2] {
                    let b = geom.wrap_block([cand[0][i], cand[1][j], cand[2][k]]);
                    if in_table(geom, b) && self.is_asleep(geom.block_index(b)) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Whether any block whose stencil reach overlaps block `b` sleeps (a cheap pre-test).
    #[inline]
    pub fn near_block(&self, geom: &GridGeom, b: [i32; 3]) -> bool {
        if self.sleeping_blocks == 0 {
            return false;
        }
        (0..8).any(|d| {
            let c = geom.wrap_block([b[0] - (d >> 2 & 1), b[1] - (d >> 1 & 1), b[2] - (d & 1)]);
            in_table(geom, c) && self.is_asleep(geom.block_index(c))
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

/// Block holding world point `x`, shifted by `shift` blocks on every axis.
fn grid_block_of(geom: &GridGeom, x: [f64; 3], shift: i32) -> [i32; 3] {
    let bs = BS as f64;
    std::array::from_fn(|a| ((x[a] - geom.origin[a]) / geom.dx / bs).floor() as i32 + shift)
}

#[inline]
fn in_table(geom: &GridGeom, b: [i32; 3]) -> bool {
    (0..3).all(|a| b[a] >= 0 && b[a] < geom.nb[a])
}

/// The 26 neighbours of block `b` inside the table.
fn neighbours(geom: &GridGeom, b: u32) -> impl Iterator<Item = u32> + '_ {
    let c = geom.block_coords(b);
    (0..27).filter(|&d| d != 13).filter_map(move |d| {
        let n = geom.wrap_block([c[0] + d / 9 - 1, c[1] + (d / 3) % 3 - 1, c[2] + d % 3 - 1]);
        in_table(geom, n).then(|| geom.block_index(n))
    })
}
