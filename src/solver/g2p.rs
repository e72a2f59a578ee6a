//! G2P: velocities, affine fields and positions gathered back from the grid, with each sleep
//! unit's activity for the sleep test.

use super::binning::balanced;
use super::neighbourhood::gather_local;
use super::walls::keep_inside;
use super::Simulation;
use crate::kernels::transfer::{g2p_block, G2pOutput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};
use crate::kernels::{Real, M3, V3};
use crate::sleep::{unit_in_block, UnitActivity, EMPTY_UNIT, UNITS};
use crate::threads::SharedSlice;
use std::sync::atomic::Ordering;

impl Simulation {
    pub(crate) fn g2p(&mut self, dt: Real) {
        let npb = self.grid.n_particle_blocks;
        let n = self.particles.n;
        let p = &mut self.particles;
        let xg = SharedSlice::new(&mut p.xg.as_mut_slice()[..n]);
        let v = SharedSlice::new(&mut p.v.as_mut_slice()[..n]);
        let c = SharedSlice::new(&mut p.c.as_mut_slice()[..n]);
        let j = SharedSlice::new(&mut p.j.as_mut_slice()[..n]);
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let sc = &self.scratch;
        let starts = &sc.slot_start.as_slice()[..npb + 1];
        let order = sc.order.as_slice();
        let nbr = sc.nbr.as_slice();
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = self.grid.nodes.as_slice();
        let threads = self.team.threads();
        let platform = self.walls.platform;
        let flip = self.scenario.simulation.flip as Real;
        let j_bar = self.scenario.simulation.j_bar.then_some(&p.vol0.as_slice()[..n]);
        let out = &self.thread_out;
        let activity = self.sleep.as_mut().map(|z| SharedSlice::new(&mut z.activity.as_mut_slice()[..npb]));
        self.team.run(|tid| {
            let (lo, hi) = balanced(&starts[..npb], starts[npb], tid, threads);
            let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
            let mut vmax: Real = 0.0;
            for s in lo..hi {
                let b = geom.block_coords(slot_block[s]);
                let origin = [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32];
                gather_local(&mut local, &nbr[s], nodes);
                let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                // SAFETY: every particle belongs to exactly one particle block, and each block to
                // one thread, so the indices written here are disjoint across threads.
                let mut o = unsafe { G2pOutput { xg: xg.slice_mut(0..n), v: v.slice_mut(0..n), c: c.slice_mut(0..n), j: j.slice_mut(0..n) } };
                vmax = vmax.max(g2p_block(origin, ord, &local, flip, j_bar, &tp, &mut o));
                for &pi in ord {
                    keep_inside(geom, platform, &mut o.xg[pi as usize]);
                }
                if let Some(act) = &activity {
                    // SAFETY: slot s belongs to this thread.
                    unsafe { *act.get_mut(s) = unit_activity(origin, ord, &*o.xg, &*o.v, &*o.c) };
                }
            }
            out[tid].store((vmax as f64).to_bits(), Ordering::Relaxed);
        });
        self.vmax = (0..threads).map(|t| f64::from_bits(out[t].load(Ordering::Relaxed))).fold(0.0, f64::max);
    }
}

/// Largest speed and strain rate |sym(C)| of the particles of each sleep unit of a block (by
/// their new stencil base), for the sleep test.
fn unit_activity(origin: [i32; 3], ord: &[u32], xg: &[V3], v: &[V3], c: &[M3]) -> UnitActivity {
    let mut a = [EMPTY_UNIT; UNITS];
    for &pi in ord {
        let pi = pi as usize;
        let e = crate::kernels::real::sym(&c[pi]);
        let rate = (e.x_axis.length_squared() + e.y_axis.length_squared() + e.z_axis.length_squared()).sqrt();
        let u = &mut a[unit_in_block(origin, crate::kernels::bspline::base_and_fx(xg[pi]).0)];
        u[0] = u[0].max(v[pi].length());
        u[1] = u[1].max(rate);
    }
    a
}
