//! P2G: the grid cleared, then particles scattered to it in 8 colour passes; and P2G's adjoint,
//! which gathers from the grid's adjoint as G2P gathers from the grid.

use super::adjoint::{Adjoint, Fields, Tape};
use super::binning::balanced;
use super::neighbourhood::{block_origin, flush_local, gather_local};
use super::Simulation;
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::transfer::{p2g_block, P2gInput, TransferParams, NEIGHBOURHOOD_NODES};
use crate::kernels::transfer_adjoint::{p2g_block_adjoint, P2gAdjoint};
use crate::kernels::Real;
use crate::particles::Particles;
use crate::threads::SharedSlice;

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

    pub(crate) fn p2g(&mut self, dt: Real) {
        let input = p2g_input(&self.particles, None);
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &self.scratch;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let threads = self.team.threads();
        let split = self.scenario.simulation.flip > 0.0;
        let (starts, order, nbr) = (sc.slot_start.as_slice(), sc.order.as_slice(), sc.nbr.as_slice());
        for c in 0..8 {
            let Some((blocks, cum, total)) = sc.colour(c) else { continue };
            self.team.run(|tid| {
                let (lo, hi) = balanced(cum, total, tid, threads);
                let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                for &s in &blocks[lo..hi] {
                    let s = s as usize;
                    let origin = block_origin(geom, slot_block[s]);
                    local.iter_mut().for_each(|n| *n = [0.0; 7]);
                    let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                    if split {
                        p2g_block::<true>(origin, ord, &input, &tp, &mut local);
                    } else {
                        p2g_block::<false>(origin, ord, &input, &tp, &mut local);
                    }
                    // SAFETY: blocks of one colour have disjoint 2x2x2 neighbourhoods.
                    unsafe { flush_local(&local, &nbr[s], &nodes) };
                }
            });
        }
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
