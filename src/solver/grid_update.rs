//! The grid update: momentum to velocity, gravity, sleeping holds, the nozzle drive, walls,
//! solid bodies, then the ghost nodes beyond the walls.

use super::walls::apply_walls;
use super::Simulation;
use crate::grid::{GridGeom, NODES_PER_BLOCK};
use crate::kernels::{Real, V3};
use crate::print::NozzleDrive;
use crate::threads::{SharedSlice, ThreadTeam};

impl Simulation {
    /// Momentum to velocity, gravity, sleeping holds, the nozzle `drive` of this step, walls.
    pub(crate) fn grid_update(&mut self, dt: Real, drive: Option<&NozzleDrive>) {
        let na = self.grid.n_active;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let accel = self.accel;
        let walls = &self.walls;
        let threads = self.team.threads();
        let drive_box = drive.map(|d| d.bounds());
        // solids hook (issue 30): placements now, and a reaction slot per block and solid
        let toolpath = self.printer.as_ref().map(|p| &*p.toolpath);
        let (solids, solid_reactions) = match self.solids.as_mut() {
            Some(z) => {
                let (at, r) = z.for_grid_update(self.time, toolpath);
                (Some(at), Some(SharedSlice::new(r)))
            }
            None => (None, None),
        };
        // reactions only for the load test: the speed rule needs just the holds
        let (holds, reactions) = match self.sleep.as_mut() {
            Some(z) => {
                let loads = z.tests_loads();
                let (h, r) = z.holds_and_reactions();
                (Some(h), loads.then(|| SharedSlice::new(r)))
            }
            None => (None, None),
        };
        self.team.run(|tid| {
            for s in ThreadTeam::share(na, tid, threads) {
                let b = geom.block_coords(slot_block[s]);
                let window = holds.as_ref().and_then(|z| z.block(geom, b));
                let driven = drive_box.is_some_and(|bx| geom.block_overlaps(b, bx));
                // SAFETY: each slot belongs to one thread.
                let blk = unsafe { nodes.slice_mut(s * NODES_PER_BLOCK..(s + 1) * NODES_PER_BLOCK) };
                // the reaction of each held node: the momentum holding it removes, over dt
                let mut held = match (&reactions, &window) {
                    // SAFETY: as for the nodes
                    (Some(r), Some(_)) => Some(unsafe { r.slice_mut(s * NODES_PER_BLOCK..(s + 1) * NODES_PER_BLOCK) }),
                    _ => None,
                };
                // solids hook (issue 30)
                let solid_mask = solids.as_ref().map_or(0, |z| z.block_mask(geom, b));
                let n_solids = solids.as_ref().map_or(0, |z| z.len());
                // SAFETY: as for the nodes
                let mut solid_react = solid_reactions.as_ref().map(|r| unsafe { r.slice_mut(s * n_solids..(s + 1) * n_solids) });
                if let Some(r) = solid_react.as_deref_mut() {
                    r.fill([0.0; 3]);
                }
                for (li, node) in blk.iter_mut().enumerate() {
                    if let Some(h) = held.as_mut() {
                        h[li] = [0.0; 3];
                    }
                    let m = node[0];
                    if m <= 0.0 {
                        *node = [0.0; 7];
                        continue;
                    }
                    let g = geom.node_of(b, li);
                    let old = V3::new(node[1], node[2], node[3]) / m;
                    let mut v = old + V3::new(node[4], node[5], node[6]) / m + accel * dt;
                    if window.as_ref().is_some_and(|w| w.holds(li)) {
                        if let Some(h) = held.as_mut() {
                            let f = v * (m / dt);
                            h[li] = [f.x as f32, f.y as f32, f.z as f32];
                        }
                        v = V3::ZERO;
                    }
                    if driven {
                        v = apply_drive(geom, drive, g, v);
                    }
                    v = apply_walls(geom, walls, g, v);
                    if let (Some(z), Some(r)) = (solids.as_ref().filter(|_| solid_mask != 0), solid_react.as_deref_mut()) {
                        v = z.apply(solid_mask, geom.node_position(g), m, v, r); // solids hook (issue 30)
                    }
                    *node = [m, v.x, v.y, v.z, old.x, old.y, old.z];
                }
            }
        });
        self.mirror_ghosts();
        if let Some(z) = self.solids.as_mut() {
            z.total_forces(na, dt as f64); // solids hook (issue 30)
        }
    }
}

/// Blend the nozzle's velocity into a node inside its tube (000 Table 2, line 7).
#[inline]
pub(crate) fn apply_drive(geom: &GridGeom, drive: Option<&NozzleDrive>, g: [i32; 3], v: V3) -> V3 {
    let Some(d) = drive else { return v };
    let x = geom.node_position(g);
    let w = d.weight(x);
    if w <= 0.0 {
        return v;
    }
    let vd = V3::new(d.velocity[0] as Real, d.velocity[1] as Real, d.velocity[2] as Real);
    vd * w + v * (1.0 - w)
}
