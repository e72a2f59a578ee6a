//! G2P: velocities, affine fields and positions gathered back from the grid, with each sleep
//! unit's activity for the sleep test; and G2P's adjoint, which scatters into the grid's adjoint
//! as P2G scatters into the grid.

use super::adjoint::{Adjoint, Tape};
use super::binning::balanced;
use super::neighbourhood::{block_origin, flush_local, gather_local};
use super::walls::keep_inside;
use super::Simulation;
use crate::kernels::transfer::{g2p_block, G2pOutput, TransferParams, NEIGHBOURHOOD_NODES};
use crate::kernels::transfer_adjoint::{g2p_block_adjoint, G2pAdjointIn, G2pAdjointOut};
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
                let origin = block_origin(geom, slot_block[s]);
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

    /// G2P's adjoint, the walls' clamp of positions first: from the adjoints of G2P's outputs
    /// (`a.next`) to those of the particle state at the step's start (`a.cur`), the initial
    /// volumes and the grid (`a.grid_bar`, zeroed first: the grid is rebuilt every step). It
    /// scatters by colour, so threads never add to the same node and every node sums in the
    /// same order.
    pub(crate) fn g2p_adjoint(&self, tape: &Tape, a: &mut Adjoint, dt: Real) {
        self.keep_inside_adjoint(a.next.xg.as_mut_slice());
        a.grid_bar.as_mut_slice()[..tape.grid_used].fill([0.0; 7]);
        let n = self.particles.n;
        let sc = &self.scratch;
        let (starts, order, nbr) = (sc.slot_start.as_slice(), sc.order.as_slice(), sc.nbr.as_slice());
        let (geom, slot_block) = (&self.grid.geom, self.grid.slot_block.as_slice());
        let nodes = self.grid.nodes.as_slice();
        let tp = TransferParams { dx: self.scenario.simulation.dx as Real, dt };
        let flip = self.scenario.simulation.flip as Real;
        let vol0 = &self.particles.vol0.as_slice()[..n];
        let j_bar_avg = self.scenario.simulation.j_bar.then_some(vol0);
        let grid_bar = SharedSlice::new(a.grid_bar.as_mut_slice());
        let f = &tape.particles;
        let (x0, v0, j0) = (&f.xg.as_slice()[..n], &f.v.as_slice()[..n], &f.j.as_slice()[..n]);
        // the recomputed G2P's v and C are still in the pool (the blend with the feed undone)
        let forward = (flip == 0.0).then(|| (&self.particles.v.as_slice()[..n], &self.particles.c.as_slice()[..n]));
        let next = (&a.next.xg.as_slice()[..n], &a.next.v.as_slice()[..n], &a.next.c.as_slice()[..n], &a.next.j.as_slice()[..n]);
        let cur_xg = SharedSlice::new(&mut a.cur.xg.as_mut_slice()[..n]);
        let cur_v = SharedSlice::new(&mut a.cur.v.as_mut_slice()[..n]);
        let cur_j = SharedSlice::new(&mut a.cur.j.as_mut_slice()[..n]);
        let vol0_bar = SharedSlice::new(&mut a.vol0_bar.as_mut_slice()[..n]);
        let threads = self.team.threads();
        for c in 0..8 {
            let Some((blocks, cum, total)) = sc.colour(c) else { continue };
            self.team.run(|tid| {
                let (lo, hi) = balanced(cum, total, tid, threads);
                let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                let mut local_bar = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                let (mut dt_bar, mut dx_bar) = (0.0, 0.0);
                for &s in &blocks[lo..hi] {
                    let s = s as usize;
                    gather_local(&mut local, &nbr[s], nodes);
                    local_bar.iter_mut().for_each(|l| *l = [0.0; 7]);
                    let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                    let inp = G2pAdjointIn { local: &local, xg: x0, v: v0, j: j0, forward, xg_bar: next.0, v_bar: next.1, c_bar: next.2, jac_bar: next.3 };
                    // SAFETY: a particle belongs to one block and a block to one thread; within a
                    // colour, block neighbourhoods are disjoint.
                    let mut out = unsafe {
                        G2pAdjointOut {
                            local_bar: &mut local_bar,
                            xg_bar: cur_xg.slice_mut(0..n),
                            v_bar: cur_v.slice_mut(0..n),
                            jac_bar: cur_j.slice_mut(0..n),
                            vol0_bar: vol0_bar.slice_mut(0..n),
                            dt_bar: &mut dt_bar,
                            dx_bar: &mut dx_bar,
                        }
                    };
                    g2p_block_adjoint(block_origin(geom, slot_block[s]), ord, flip, j_bar_avg, &tp, &inp, &mut out);
                    unsafe { flush_local(&local_bar, &nbr[s], &grid_bar) };
                }
            });
        }
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
