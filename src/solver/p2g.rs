//! P2G: the grid cleared, then particles scattered to it block by block in colour order; and
//! P2G's adjoint, which gathers from the grid's adjoint as G2P gathers from the grid.

use super::adjoint::{Adjoint, Fields, Tape};
use super::binning::{balanced, colour, Scratch};
use super::neighbourhood::{block_origin, flush_local, gather_local};
use super::Simulation;
use crate::grid::{GridGeom, NODES_PER_BLOCK};
use crate::kernels::transfer::{p2g_block, P2gInput, TransferParams, NEIGHBOURHOOD_NODES};
use crate::kernels::transfer_adjoint::{p2g_block_adjoint, P2gAdjoint};
use crate::kernels::Real;
use crate::particles::Particles;
use crate::threads::SharedSlice;
use std::sync::atomic::Ordering::{Acquire, Relaxed, Release};
use std::sync::atomic::{AtomicU32, AtomicUsize};

/// P2G's inputs: the pool's masses and initial volumes, and x, v, C, stress and J from `tape`
/// (the step's start, for the adjoint) or else from the pool.
fn p2g_input<'a>(p: &'a Particles, tape: Option<&'a Fields>) -> P2gInput<'a> {
    let n = p.n;
    let (xg, v, c, stress, j) = match tape {
        Some(f) => (&f.xg, &f.v, &f.c, &f.stress, &f.j),
        None => (&p.xg, &p.v, &p.c, &p.stress, &p.j),
    };
    P2gInput {
        xg: &xg.as_slice()[..n],
        v: &v.as_slice()[..n],
        c: &c.as_slice()[..n],
        stress: &stress.as_slice()[..n],
        mass: &p.mass.as_slice()[..n],
        vol0: &p.vol0.as_slice()[..n],
        j: &j.as_slice()[..n],
    }
}

impl Simulation {
    pub(crate) fn clear_grid(&mut self) {
        let n = self.grid.n_active * NODES_PER_BLOCK;
        self.team.for_each_share(&mut self.grid.nodes.as_mut_slice()[..n], 1, |_, nodes| nodes.fill([0.0; 7]));
    }

    /// Each particle block scatters into a neighbourhood buffer of its own, then adds the buffer to
    /// the grid once every block of a lower colour whose neighbourhood overlaps its own has added
    /// its buffer. Every node so sums the blocks' buffers in colour order, as 8 colour passes
    /// would, whatever the number of threads and their timing; but a thread never waits for a
    /// whole colour to end: it takes the next block (in colour order) as soon as it is free, and
    /// waits, if at all, only for the neighbours its buffer's nodes share.
    pub(crate) fn p2g(&mut self, dt: Real) {
        let pass = self.scratch.next_p2g_pass();
        let input = p2g_input(&self.particles, None);
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &mut self.scratch;
        let (geom, slot_block, table) = (&self.grid.geom, self.grid.slot_block.as_slice(), self.grid.table.as_slice());
        let npb = self.grid.n_particle_blocks;
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let split = self.scenario.simulation.flip > 0.0;
        let (starts, order, nbr) = (sc.slot_start.as_slice(), sc.order.as_slice(), sc.nbr.as_slice());
        let in_colour_order = &sc.colour_blocks.as_slice()[..npb];
        let flushed = Scratch::flushed_flags(&mut sc.flushed);
        let next = AtomicUsize::new(0);
        self.team.run(|_| {
            let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
            loop {
                let i = next.fetch_add(1, Relaxed);
                let Some(&s) = in_colour_order.get(i) else { break };
                let s = s as usize;
                let origin = block_origin(geom, slot_block[s]);
                local.iter_mut().for_each(|n| *n = [0.0; 7]);
                let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                if split {
                    p2g_block::<true>(origin, ord, &input, &tp, &mut local);
                } else {
                    p2g_block::<false>(origin, ord, &input, &tp, &mut local);
                }
                for t in overlapping_before(geom, table, npb, geom.block_coords(slot_block[s])) {
                    wait_for_pass(&flushed[t as usize], pass);
                }
                // SAFETY: a block whose neighbourhood overlaps this one's is of another colour (blocks
                // of one colour have disjoint 2x2x2 neighbourhoods), and of the two the one of the
                // higher colour adds its buffer only after the other has (the wait above).
                unsafe { flush_local(&local, &nbr[s], &nodes) };
                flushed[s].store(pass, Release);
            }
        });
    }

    /// P2G's adjoint: from the grid's adjoint to those of the particle state at the step's start
    /// (`a.cur`), the masses and the initial volumes; particle blocks split across threads by
    /// particle count.
    pub(crate) fn p2g_adjoint(&self, tape: &Tape, a: &mut Adjoint, dt: Real) {
        let n = self.particles.n;
        let sc = &self.scratch;
        let npb = self.grid.n_particle_blocks;
        let starts = &sc.slot_start.as_slice()[..npb + 1];
        let (order, nbr) = (sc.order.as_slice(), sc.nbr.as_slice());
        let (geom, slot_block) = (&self.grid.geom, self.grid.slot_block.as_slice());
        let input = p2g_input(&self.particles, Some(&tape.particles));
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let split = self.scenario.simulation.flip > 0.0;
        let grid_bar = a.grid_bar.as_slice();
        let cur = (
            SharedSlice::new(&mut a.cur.xg.as_mut_slice()[..n]),
            SharedSlice::new(&mut a.cur.v.as_mut_slice()[..n]),
            SharedSlice::new(&mut a.cur.c.as_mut_slice()[..n]),
            SharedSlice::new(&mut a.cur.stress.as_mut_slice()[..n]),
            SharedSlice::new(&mut a.cur.j.as_mut_slice()[..n]),
        );
        let mass_bar = SharedSlice::new(&mut a.mass_bar.as_mut_slice()[..n]);
        let vol0_bar = SharedSlice::new(&mut a.vol0_bar.as_mut_slice()[..n]);
        let threads = self.team.threads();
        self.team.run(|tid| {
            let (lo, hi) = balanced(&starts[..npb], starts[npb], tid, threads);
            let mut local_bar = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
            let (mut dt_bar, mut dx_bar) = (0.0, 0.0);
            for s in lo..hi {
                gather_local(&mut local_bar, &nbr[s], grid_bar);
                let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                // SAFETY: every particle belongs to one block and every block to one thread.
                let mut out = unsafe {
                    P2gAdjoint {
                        xg_bar: cur.0.slice_mut(0..n),
                        v_bar: cur.1.slice_mut(0..n),
                        c_bar: cur.2.slice_mut(0..n),
                        stress_bar: cur.3.slice_mut(0..n),
                        mass_bar: mass_bar.slice_mut(0..n),
                        vol0_bar: vol0_bar.slice_mut(0..n),
                        jac_bar: cur.4.slice_mut(0..n),
                        dt_bar: &mut dt_bar,
                        dx_bar: &mut dx_bar,
                    }
                };
                let origin = block_origin(geom, slot_block[s]);
                if split {
                    p2g_block_adjoint::<true>(origin, ord, &input, &tp, &local_bar, &mut out);
                } else {
                    p2g_block_adjoint::<false>(origin, ord, &input, &tp, &local_bar, &mut out);
                }
            }
        });
    }
}

/// The particle blocks (slots below `npb`) of a lower colour than block `b` whose 2x2x2
/// neighbourhoods overlap its own: those within one block along every axis.
fn overlapping_before<'a>(geom: &'a GridGeom, table: &'a [u32], npb: usize, b: [i32; 3]) -> impl Iterator<Item = u32> + 'a {
    let own = colour(b);
    (0..27).filter(|&d| d != 13).filter_map(move |d| {
        let o = [d / 9 - 1, d / 3 % 3 - 1, d % 3 - 1];
        let mut n = [b[0] + o[0], b[1] + o[1], b[2] + o[2]];
        for a in 0..3 {
            if !geom.periodic[a] && !(0..geom.nb[a]).contains(&n[a]) {
                return None;
            }
        }
        n = geom.wrap_block(n);
        let t = table[geom.block_index(n) as usize];
        ((t as usize) < npb && colour(n) < own).then_some(t)
    })
}

/// Spin until `flag` holds `pass`, giving the core away between tries after a while (the thread
/// waited for may need it, when the machine has more busy threads than cores).
fn wait_for_pass(flag: &AtomicU32, pass: u32) {
    let mut tries = 0u32;
    while flag.load(Acquire) != pass {
        tries += 1;
        if tries < 1 << 12 {
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}
