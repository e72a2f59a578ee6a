//! The per-particle arrays a step changes, as one group of pools: the tape of one step (the
//! state it started from), the adjoints of a state, and the layout of a stored checkpoint.
//!
//! Masses and initial volumes are not here: without emission they never change, so a gradient
//! run neither stores them nor keeps two copies of their adjoints (they accumulate in place).

use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::solver::Simulation;

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
    pub fn copy_from(&mut self, sim: &Simulation) {
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
