//! P2G: the grid cleared, then particles scattered to it in 8 colour passes.

use super::binning::balanced;
use super::neighbourhood::flush_local;
use super::Simulation;
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::transfer::{p2g_block, P2gInput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};
use crate::kernels::Real;
use crate::threads::SharedSlice;

impl Simulation {
    pub(crate) fn clear_grid(&mut self) {
        let n = self.grid.n_active * NODES_PER_BLOCK;
        self.team.for_each_share(&mut self.grid.nodes.as_mut_slice()[..n], 1, |_, nodes| nodes.fill([0.0; 7]));
    }

    pub(crate) fn p2g(&mut self, dt: Real) {
        let p = &self.particles;
        let n = p.n;
        let input = P2gInput {
            xg: &p.xg.as_slice()[..n],
            v: &p.v.as_slice()[..n],
            c: &p.c.as_slice()[..n],
            stress: &p.stress.as_slice()[..n],
            mass: &p.mass.as_slice()[..n],
            vol0: &p.vol0.as_slice()[..n],
            j: &p.j.as_slice()[..n],
        };
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &self.scratch;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let threads = self.team.threads();
        let split = self.scenario.simulation.flip > 0.0;
        for c in 0..8 {
            let (c0, c1) = (sc.colour_start[c], sc.colour_start[c + 1]);
            if c0 == c1 {
                continue;
            }
            let blocks = &sc.colour_blocks.as_slice()[c0..c1];
            let cum = &sc.colour_cum.as_slice()[c0..c1];
            let starts = sc.slot_start.as_slice();
            let last = *blocks.last().unwrap() as usize;
            let total = cum[cum.len() - 1] + (starts[last + 1] - starts[last]);
            let order = sc.order.as_slice();
            let nbr = sc.nbr.as_slice();
            self.team.run(|tid| {
                let (lo, hi) = balanced(cum, total, tid, threads);
                let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                for &s in &blocks[lo..hi] {
                    let s = s as usize;
                    let b = geom.block_coords(slot_block[s]);
                    let origin = [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32];
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
}
