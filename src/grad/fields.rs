//! The layout of a stored state of the gradient schedule: step, time, particle count and the
//! next slab to emit, then the live part of each particle pool a step changes
//! ([`Role::changes_in_step`], the arrays of `solver::Fields`), in declaration order.
//!
//! Masses, initial volumes and ids are not here: without emission, reordering or merging they
//! never change, so a gradient run does not store them.

use crate::particles::Particles;
use crate::pools::{with_role, Counts, PoolDecl, Role};
use crate::solver::Simulation;

const HEADER: usize = 32;

/// The particle pools a stored state holds.
fn stored(p: &Particles) -> Vec<PoolDecl<Particles>> {
    with_role(p, Role::changes_in_step)
}

/// Bytes of one stored state of a full pool of `p`'s particles.
pub fn state_bytes(p: &Particles) -> usize {
    let cap = Counts::particles(p.capacity());
    HEADER + stored(p).iter().map(|d| d.bytes_for(p, &cap)).sum::<usize>()
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
    let mut at = HEADER;
    for d in stored(p) {
        let a = d.live(p, &now);
        out[at..at + a.len()].copy_from_slice(a);
        at += a.len();
    }
    debug_assert!(at <= out.len());
}

/// Make the state saved in `bytes` live.
pub fn load(sim: &mut Simulation, bytes: &[u8]) {
    let word = |k: usize| u64::from_le_bytes(bytes[8 * k..8 * k + 8].try_into().expect("8 bytes"));
    sim.step = word(0);
    sim.time = f64::from_bits(word(1));
    if let Some(sync) = sim.printer.as_mut().and_then(|p| p.sync.as_mut()) {
        sync.next = word(3);
    }
    let p = &mut sim.particles;
    p.n = word(2) as usize;
    // nothing merges without sleeping (which gradients refuse): ids are 0..n
    p.next_id = p.n as u32;
    let now = Counts::particles(p.n);
    let mut at = HEADER;
    for d in stored(p) {
        let dst = d.live_mut(p, &now);
        dst.copy_from_slice(&bytes[at..at + dst.len()]);
        at += dst.len();
    }
}
