//! The layout of a stored state of the gradient schedule: step, time, particle count and the
//! next slab to emit, then the live part of each particle pool a step changes
//! ([`Role::changes_in_step`], the arrays of `solver::Fields`), in declaration order.
//!
//! Masses, initial volumes and ids are not here in a run that does not sleep: without
//! reordering or merging they never change (emission sets them for the particles it adds), so a
//! gradient run does not store them.
//!
//! A sleeping run stores more, because its sleep update moves particles in and out of the
//! sleeping prefix of the pool and decides from what the previous step left: the masses,
//! initial volumes and ids (the swaps move them), the sleeping prefix's length, the sleep tables
//! a restart checkpoint stores (the pools of [`Role::Sparse`], here whole), and the previous
//! step's per-unit activity (where it lies against the thresholds) with the binning it is
//! indexed by (its particle blocks' keys). A restart checkpoint, taken in the middle of a step,
//! rebuilds the last two by binning again and by G2P; a stored state at a step boundary cannot,
//! so it keeps them. With them the replayed step takes the same sleep decisions as the first
//! forward sweep, bit for bit.

use crate::grid::EMPTY;
use crate::kernels::Real;
use crate::particles::Particles;
use crate::pools::{with_role, Counts, PoolDecl, Role};
use crate::sleep::{Sleep, EMPTY_UNIT, UNITS};
use crate::solver::Simulation;

const HEADER: usize = 32;
/// A sleeping run's second header: the sleeping prefix's length, the particle blocks of the last
/// binning and the last step's length (the sleep clocks tick by it).
const SLEEP_HEADER: usize = 24;

/// The particle pools a stored state holds (with `sleeping`, the ids and what follows them too).
fn stored(p: &Particles, sleeping: bool) -> Vec<PoolDecl<Particles>> {
    with_role(p, |r| r.changes_in_step() || (sleeping && matches!(r, Role::Ids | Role::FromIds)))
}

/// The sleep tables a stored state holds: those a restart checkpoint stores.
fn sleep_tables(s: &Sleep) -> Vec<PoolDecl<Sleep>> {
    with_role(s, |r| r == Role::Sparse)
}

/// Bytes of one stored state of `sim` at its full pool (and as many particle blocks, when it
/// sleeps).
pub fn state_bytes(sim: &Simulation) -> usize {
    let p = &sim.particles;
    // every particle block holds a particle
    let cap = Counts::capacity(p.capacity(), sim.grid.max_blocks().min(p.capacity()));
    let particles: usize = stored(p, sim.sleep.is_some()).iter().map(|d| d.bytes_for(p, &cap)).sum();
    let sleep = sim.sleep.as_ref().map_or(0, |s| {
        let tables: usize = sleep_tables(s).iter().map(|d| d.bytes_for(s, &cap)).sum();
        SLEEP_HEADER + tables + activity_bytes(cap.particle_blocks) + cap.particle_blocks * 4
    });
    HEADER + particles + sleep
}

/// A byte per unit of each particle block: the activity's place against the sleep thresholds.
fn activity_bytes(particle_blocks: usize) -> usize {
    particle_blocks * UNITS
}

/// The thresholds the sleep update compares a unit's (max speed, max strain rate) with, in the
/// solver's precision as it takes them (`sleep/passes.rs`): the rest speed, wake speed and
/// arrive speed (increasing, as the scenario checks), and the rest strain rate.
fn thresholds(s: &Sleep) -> ([Real; 3], Real) {
    let c = &s.cfg;
    ([c.speed as Real, c.wake_speed as Real, c.arrive_speed as Real], c.strain_rate as Real)
}

/// Which side of each threshold a unit's activity lies on, in a byte: every sleep decision
/// compares the activity with the thresholds only (`v < rest`, `v > wake`, `v <= wake`,
/// `v > arrive`, `v <= arrive`, `rate < rest rate`, or empty), so the byte keeps them all, at a
/// sixteenth of the activity's size.
fn activity_code(a: [Real; 2], (speeds, rest_rate): ([Real; 3], Real)) -> u8 {
    if a == EMPTY_UNIT {
        return u8::MAX;
    }
    let class = if a[0] < speeds[0] {
        0
    } else if a[0] <= speeds[1] {
        1
    } else if a[0] <= speeds[2] {
        2
    } else {
        3
    };
    class | ((a[1] >= rest_rate) as u8) << 2
}

/// An activity on the same side of every threshold as the one `code` was taken from.
fn activity_of(code: u8, (speeds, rest_rate): ([Real; 3], Real)) -> [Real; 2] {
    if code == u8::MAX {
        return EMPTY_UNIT;
    }
    // below the rest speed (> 0 when anything is), at it (<= wake), at the arrive speed
    // (> wake when anything lies between), above every one
    let v = [0.0, speeds[0], speeds[2], Real::INFINITY][(code & 3) as usize];
    [v, if code & 4 != 0 { rest_rate } else { 0.0 }]
}

fn next_slab(sim: &Simulation) -> u64 {
    sim.printer.as_ref().map_or(0, |p| p.emitted())
}

/// Write the live state into `out` (at least [`state_bytes`] long).
pub fn save(sim: &Simulation, out: &mut [u8]) {
    out[..8].copy_from_slice(&sim.step.to_le_bytes());
    out[8..16].copy_from_slice(&sim.time.to_le_bytes());
    out[16..24].copy_from_slice(&(sim.particles.n as u64).to_le_bytes());
    out[24..32].copy_from_slice(&next_slab(sim).to_le_bytes());
    let p = &sim.particles;
    let now = Counts::particles(p.n);
    let mut put = |at: &mut usize, a: &[u8]| {
        out[*at..*at + a.len()].copy_from_slice(a);
        *at += a.len();
    };
    let mut at = HEADER;
    for d in stored(p, sim.sleep.is_some()) {
        put(&mut at, d.live(p, &now));
    }
    if let Some(s) = &sim.sleep {
        let npb = sim.grid.n_particle_blocks;
        put(&mut at, &(p.n_sleep as u64).to_le_bytes());
        put(&mut at, &(npb as u64).to_le_bytes());
        put(&mut at, &sim.last_dt.to_le_bytes());
        let all = Counts::capacity(0, 0);
        for d in sleep_tables(s) {
            put(&mut at, d.live(s, &all));
        }
        let lim = thresholds(s);
        for a in s.activity.as_slice()[..npb].iter().flatten() {
            put(&mut at, &[activity_code(*a, lim)]);
        }
        put(&mut at, bytemuck::cast_slice(&sim.grid.slot_block.as_slice()[..npb]));
    }
    debug_assert!(at <= out.len());
}

/// Make the state saved in `bytes` live.
pub fn load(sim: &mut Simulation, bytes: &[u8]) -> Result<(), crate::sleep::BadUnitState> {
    let word = |k: usize| u64::from_le_bytes(bytes[8 * k..8 * k + 8].try_into().expect("8 bytes"));
    sim.step = word(0);
    sim.time = f64::from_bits(word(1));
    if let Some(sync) = sim.printer.as_mut().and_then(|p| p.sync.as_mut()) {
        sync.next = word(3);
    }
    let sleeping = sim.sleep.is_some();
    let p = &mut sim.particles;
    p.n = word(2) as usize;
    // nothing merges in a gradient run (`prepare` refuses merging): ids are 0..n, in any order
    p.next_id = p.n as u32;
    let now = Counts::particles(p.n);
    let mut at = HEADER;
    let take = |at: &mut usize, dst: &mut [u8]| {
        dst.copy_from_slice(&bytes[*at..*at + dst.len()]);
        *at += dst.len();
    };
    for d in stored(p, sleeping) {
        take(&mut at, d.live_mut(p, &now));
    }
    let Some(s) = &mut sim.sleep else { return Ok(()) };
    let mut w = [0u8; 8];
    take(&mut at, &mut w);
    p.n_sleep = u64::from_le_bytes(w) as usize;
    take(&mut at, &mut w);
    let npb = u64::from_le_bytes(w) as usize;
    take(&mut at, &mut w);
    sim.last_dt = f64::from_le_bytes(w);
    let all = Counts::capacity(0, 0);
    for d in sleep_tables(s) {
        take(&mut at, d.live_mut(s, &all));
    }
    let lim = thresholds(s);
    for (k, a) in s.activity.as_mut_slice()[..npb].iter_mut().flatten().enumerate() {
        *a = activity_of(bytes[at + k], lim);
    }
    at += activity_bytes(npb);
    s.restored()?;
    // the last binning's particle blocks, in slot order: what the sleep update reads of the grid
    // (the next binning starts from nothing)
    let grid = &mut sim.grid;
    grid.reset();
    let keys = bytes[at..at + 4 * npb].chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
    let (table, slots) = (grid.table.as_mut_slice(), grid.slot_block.as_mut_slice());
    for (s, k) in keys.enumerate() {
        debug_assert_eq!(table[k as usize], EMPTY);
        table[k as usize] = s as u32;
        slots[s] = k;
    }
    (grid.n_active, grid.n_particle_blocks) = (npb, npb);
    Ok(())
}
