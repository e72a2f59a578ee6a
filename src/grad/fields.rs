//! The layout of a stored state of the gradient schedule: the per-particle arrays a step changes
//! (those of `solver::Fields`).
//!
//! Masses and initial volumes are not here: without emission they never change, so a gradient
//! run does not store them.

use crate::kernels::{Real, M3, V3};
use crate::solver::Simulation;

const HEADER: usize = 32;

/// Bytes of one stored state of `n` particles: step, time, particle count and the next slab to
/// emit, then the arrays of [`Fields`].
pub fn state_bytes(n: usize, state_len: usize) -> usize {
    HEADER + n * (2 * size_of::<V3>() + 2 * size_of::<M3>() + size_of::<Real>() * (1 + state_len))
}

/// The simulation's changing arrays (and step, time) as byte ranges, in stored order.
fn arrays(sim: &Simulation) -> [&[u8]; 6] {
    let p = &sim.particles;
    let n = p.n;
    [
        bytemuck::cast_slice(&p.xg.as_slice()[..n]),
        bytemuck::cast_slice(&p.v.as_slice()[..n]),
        bytemuck::cast_slice(&p.c.as_slice()[..n]),
        bytemuck::cast_slice(&p.stress.as_slice()[..n]),
        bytemuck::cast_slice(&p.j.as_slice()[..n]),
        bytemuck::cast_slice(&p.state.as_slice()[..n * p.state_len]),
    ]
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
    let mut at = HEADER;
    for a in arrays(sim) {
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
    let n = p.n;
    let sl = p.state_len;
    let mut at = HEADER;
    let mut take = |dst: &mut [u8]| {
        dst.copy_from_slice(&bytes[at..at + dst.len()]);
        at += dst.len();
    };
    take(bytemuck::cast_slice_mut(&mut p.xg.as_mut_slice()[..n]));
    take(bytemuck::cast_slice_mut(&mut p.v.as_mut_slice()[..n]));
    take(bytemuck::cast_slice_mut(&mut p.c.as_mut_slice()[..n]));
    take(bytemuck::cast_slice_mut(&mut p.stress.as_mut_slice()[..n]));
    take(bytemuck::cast_slice_mut(&mut p.j.as_mut_slice()[..n]));
    take(bytemuck::cast_slice_mut(&mut p.state.as_mut_slice()[..n * sl]));
}
