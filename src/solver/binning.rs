//! Binning: particles grouped by the grid block of their stencil base, each particle block's
//! 2x2x2 neighbourhood activated, particle blocks grouped by colour for the P2G passes, and the
//! particles reordered into block order.

use super::{SimError, Simulation};
use crate::memory::Pool;
use crate::particles::Particles;
use crate::pools::{Per, PoolDecl, Pools, Role};
use std::sync::atomic::AtomicU32;

/// Buffers the binning and the parallel phases share.
#[derive(Default)]
pub(crate) struct Scratch {
    max_blocks: usize,
    state_len: usize,
    /// Slot of each particle's block.
    pub(crate) pslot: Pool<u32>,
    /// Particle indices grouped by particle block (a stable counting sort).
    pub(crate) order: Pool<u32>,
    /// First `order` entry of each particle block; `n_particle_blocks + 1` entries used.
    pub(crate) slot_start: Pool<u32>,
    cursor: Pool<u32>,
    /// Slots of the 2x2x2 block neighbourhood of each particle block.
    pub(crate) nbr: Pool<[u32; 8]>,
    /// Particle blocks grouped by colour, and the running particle count before each.
    pub(crate) colour_blocks: Pool<u32>,
    pub(crate) colour_cum: Pool<u32>,
    pub(crate) colour_start: [usize; 9],
    /// The P2G pass that last added each particle block's neighbourhood to the grid (see
    /// `p2g.rs`), and the number of the current pass.
    pub(crate) flushed: Pool<u32>,
    pub(crate) p2g_pass: u32,
    permute: Pool<u8>,
}

impl Pools for Scratch {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        let scratch = Role::Scratch;
        let permute = Particles::permute_scratch_per_particle(self.state_len);
        vec![
            PoolDecl::new("scratch.pslot", Per::Particle(1), scratch, |s| &s.pslot, |s| &mut s.pslot),
            PoolDecl::new("scratch.order", Per::Particle(1), scratch, |s| &s.order, |s| &mut s.order),
            PoolDecl::new("scratch.slot_start", Per::Table(self.max_blocks + 1), scratch, |s| &s.slot_start, |s| &mut s.slot_start),
            PoolDecl::new("scratch.cursor", Per::Block(1), scratch, |s| &s.cursor, |s| &mut s.cursor),
            PoolDecl::new("scratch.neighbours", Per::Block(1), scratch, |s| &s.nbr, |s| &mut s.nbr),
            PoolDecl::new("scratch.colour_blocks", Per::Block(1), scratch, |s| &s.colour_blocks, |s| &mut s.colour_blocks),
            PoolDecl::new("scratch.colour_cum", Per::Block(1), scratch, |s| &s.colour_cum, |s| &mut s.colour_cum),
            PoolDecl::new("scratch.flushed", Per::Block(1), scratch, |s| &s.flushed, |s| &mut s.flushed),
            PoolDecl::new("scratch.permute", Per::Particle(permute), scratch, |s| &s.permute, |s| &mut s.permute),
        ]
    }
}

impl Scratch {
    /// The buffers for `max_blocks` grid slots and particles of `state_len` state values,
    /// declared but not mapped ([`Pools::map_pools`] maps them).
    pub(super) fn declared(max_blocks: usize, state_len: usize) -> Self {
        Scratch { max_blocks, state_len, ..Default::default() }
    }
}

impl Scratch {
    /// The number of a new P2G pass (never 0, which the flags hold when mapped); the flags are
    /// cleared when the count wraps, so no flag can hold a pass from before.
    pub(crate) fn next_p2g_pass(&mut self) -> u32 {
        self.p2g_pass = self.p2g_pass.wrapping_add(1);
        if self.p2g_pass == 0 {
            self.flushed.as_mut_slice().fill(0);
            self.p2g_pass = 1;
        }
        self.p2g_pass
    }

    /// The flags of [`Scratch::flushed`] as atomics, for P2G's threads to share.
    pub(crate) fn flushed_flags(flushed: &mut Pool<u32>) -> &[AtomicU32] {
        let f = flushed.as_mut_slice();
        // SAFETY: AtomicU32 has u32's size and alignment, and the exclusive borrow makes the
        // atomics the only access while the view lives
        unsafe { std::slice::from_raw_parts(f.as_mut_ptr().cast::<AtomicU32>(), f.len()) }
    }
}

impl Scratch {
    /// The particle blocks of colour `c`, the running particle count before each and the
    /// colour's particle total; None when no block has the colour.
    pub(crate) fn colour(&self, c: usize) -> Option<(&[u32], &[u32], u32)> {
        let (c0, c1) = (self.colour_start[c], self.colour_start[c + 1]);
        if c0 == c1 {
            return None;
        }
        let blocks = &self.colour_blocks.as_slice()[c0..c1];
        let cum = &self.colour_cum.as_slice()[c0..c1];
        let starts = self.slot_start.as_slice();
        let last = *blocks.last().unwrap() as usize;
        Some((blocks, cum, cum[cum.len() - 1] + (starts[last + 1] - starts[last])))
    }
}

impl Simulation {
    /// Sort the pool by block once and keep that order from then on: a gradient run indexes its
    /// adjoint arrays by pool position, which must mean the same particle in every step.
    pub fn freeze_order(&mut self) -> Result<(), SimError> {
        self.bin_particles()?;
        self.reorder_particles();
        self.frozen_order = true;
        Ok(())
    }

    /// Bin particles by the block of their stencil base, activate each particle block's 2x2x2
    /// neighbourhood, and group particle blocks by colour. Serial: it is a few operations per
    /// particle, and doing it in one order makes slot numbering deterministic.
    pub(crate) fn bin_particles(&mut self) -> Result<(), SimError> {
        let n = self.particles.n;
        let first = self.particles.n_sleep;
        let grid = &mut self.grid;
        let sc = &mut self.scratch;
        grid.reset();
        // each particle's block key, in parallel; slots are then handed out serially in particle
        // order, so that they do not depend on the number of threads
        let pslot = sc.pslot.as_mut_slice();
        let (xg, geom) = (&self.particles.xg.as_slice()[first..n], &grid.geom);
        self.team.for_each_share(&mut pslot[first..n], 1, |r, keys| {
            for (key, &x) in keys.iter_mut().zip(&xg[r]) {
                *key = geom.block_index(geom.particle_block(x));
            }
        });
        let count = sc.cursor.as_mut_slice();
        let mut last_key = u32::MAX;
        let mut last_slot = 0u32;
        for p in first..n {
            let key = pslot[p];
            if key != last_key {
                let before = grid.n_active;
                last_slot = grid.activate(key)?;
                if grid.n_active > before {
                    count[last_slot as usize] = 0;
                }
                last_key = key;
            }
            count[last_slot as usize] += 1;
            pslot[p] = last_slot;
        }
        let npb = grid.n_active;
        grid.n_particle_blocks = npb;

        // neighbourhoods and colours
        let mut per_colour = [0usize; 8];
        for s in 0..npb {
            let b = grid.geom.block_coords(grid.slot_block.as_slice()[s]);
            let mut nb = [0u32; 8];
            for (d, slot) in nb.iter_mut().enumerate() {
                let o = [(d >> 2) as i32 & 1, (d >> 1) as i32 & 1, d as i32 & 1];
                let w = grid.geom.wrap_block([b[0] + o[0], b[1] + o[1], b[2] + o[2]]);
                *slot = grid.activate(grid.geom.block_index(w))?;
            }
            sc.nbr.as_mut_slice()[s] = nb;
            per_colour[colour(b)] += 1;
        }
        let mut cs = [0usize; 9];
        for c in 0..8 {
            cs[c + 1] = cs[c] + per_colour[c];
        }
        sc.colour_start = cs;

        // counting sort of particles by slot (stable)
        let starts = sc.slot_start.as_mut_slice();
        let mut acc = 0u32;
        for s in 0..npb {
            let c = count[s];
            starts[s] = acc;
            count[s] = acc; // becomes the write cursor
            acc += c;
        }
        starts[npb] = acc;
        let order = sc.order.as_mut_slice();
        for p in first..n {
            let s = pslot[p] as usize;
            order[count[s] as usize] = p as u32;
            count[s] += 1;
        }

        // colour lists, with running particle counts for load balance
        let mut fill = cs;
        let blocks = sc.colour_blocks.as_mut_slice();
        let cum = sc.colour_cum.as_mut_slice();
        let mut run = [0u32; 8];
        for s in 0..npb {
            let c = colour(grid.geom.block_coords(grid.slot_block.as_slice()[s]));
            blocks[fill[c]] = s as u32;
            cum[fill[c]] = run[c];
            run[c] += starts[s + 1] - starts[s];
            fill[c] += 1;
        }
        Ok(())
    }

    /// Move particles into block order so the transfers stream through memory.
    pub(crate) fn reorder_particles(&mut self) {
        let (first, n) = (self.particles.n_sleep, self.particles.n);
        self.particles.permute(&self.scratch.order.as_slice()[..n - first], self.scratch.permute.as_mut_slice(), &self.team);
        for (k, o) in self.scratch.order.as_mut_slice()[..n - first].iter_mut().enumerate() {
            *o = (first + k) as u32;
        }
    }
}

#[inline]
pub(crate) fn colour(b: [i32; 3]) -> usize {
    ((b[0] & 1) << 2 | (b[1] & 1) << 1 | (b[2] & 1)) as usize
}

/// Split items with running weights `cum` (exclusive prefix sums, total `total`) into `threads`
/// contiguous shares of about equal weight; returns thread `tid`'s item range.
pub(crate) fn balanced(cum: &[u32], total: u32, tid: usize, threads: usize) -> (usize, usize) {
    let at = |t: usize| {
        let target = (total as u64 * t as u64 / threads as u64) as u32;
        if t == threads {
            cum.len()
        } else if t == 0 {
            0
        } else {
            cum.partition_point(|&c| c < target)
        }
    };
    (at(tid), at(tid + 1))
}
