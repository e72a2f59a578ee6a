//! The grid update: momentum to velocity, gravity, sleeping holds, the nozzle drive, walls,
//! solid bodies, then the ghost nodes beyond the walls; and its adjoint.
//!
//! The forward turns a node `[m, p, f]` (mass, momentum, impulse kept apart under FLIP) into
//! `[m, v_new, v_old]` with `v_old = p / m`, `v_new = walls(v_old + f / m + a dt)`, and then
//! overwrites the velocity of every ghost node with the signed velocity of its mirror partner.
//! The adjoint runs the two passes backwards on the node adjoints in place: first the ghosts hand
//! their adjoint to their partners, then every node maps `[m_bar, v_new_bar, v_old_bar]` to
//! `[m_bar, p_bar, f_bar]`, the layout P2G's adjoint reads.

use super::adjoint::{Adjoint, GridParamsBar, Tape, ToolpathBar};
use super::walls::{apply_walls, apply_walls_adjoint};
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
                let walled = walls.reach(geom, b);
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
                    if walled {
                        v = apply_walls(geom, walls, g, v);
                    }
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
fn apply_drive(geom: &GridGeom, drive: Option<&NozzleDrive>, g: [i32; 3], v: V3) -> V3 {
    let Some(d) = drive else { return v };
    let x = geom.node_position(g);
    let w = d.weight(x);
    if w <= 0.0 {
        return v;
    }
    let vd = V3::new(d.velocity[0] as Real, d.velocity[1] as Real, d.velocity[2] as Real);
    vd * w + v * (1.0 - w)
}

/// Adjoint of the drive's blend `w vd + (1 - w) v` at node `g` for the velocity `v` before it:
/// returns the adjoint of `v`; those of the outlet position (through the indicator weight) and
/// of the imposed velocity go to `bar`. The tube's height range is a hard cut, held fixed.
fn drive_adjoint(geom: &GridGeom, d: &NozzleDrive, g: [i32; 3], v: V3, v_bar: V3, bar: &mut GridParamsBar) -> V3 {
    let x = geom.node_position(g);
    let w = d.weight(x);
    if w <= 0.0 {
        return v_bar;
    }
    let vd = V3::new(d.velocity[0] as Real, d.velocity[1] as Real, d.velocity[2] as Real);
    for c in 0..3 {
        bar.drive_velocity[c] += (v_bar[c] * w) as f64;
    }
    let w_bar = v_bar.dot(vd - v);
    let (ox, oy) = (x[0] - d.outlet[0], x[1] - d.outlet[1]);
    let (dist, radius) = d.shape.distance(ox, oy);
    let (dist_bar, _) = crate::kernels::nozzle::weight_adjoint(d.indicator, dist as Real, radius as Real, w_bar);
    let grad = d.shape.distance_gradient(ox, oy);
    // the offset is x - outlet
    bar.drive_outlet[0] -= dist_bar as f64 * grad[0];
    bar.drive_outlet[1] -= dist_bar as f64 * grad[1];
    v_bar * (1.0 - w)
}

impl Simulation {
    /// The grid update's adjoint on `a.grid_bar` in place, from the grid as P2G left it (in
    /// `tape`) and as the update left it (live); `drive` is the step's nozzle drive. The drive's
    /// adjoints (with the feed velocity's from the blend's adjoint) go to `toolpath`. A node
    /// sleeping units hold is set to rest whatever reached it, so its adjoint stops there.
    pub(crate) fn grid_update_adjoint(&self, drive: Option<&NozzleDrive>, tape: &Tape, a: &mut Adjoint, dt: Real, toolpath: Option<&mut dyn ToolpathBar>) {
        let used = tape.grid_used;
        let (before, grid_bar) = (&tape.grid.as_slice()[..used], &mut a.grid_bar.as_mut_slice()[..used]);
        let bar = &mut a.grid_params_bar;
        self.mirror_ghosts_adjoint(grid_bar);
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let walls = &self.walls;
        let accel = self.accel;
        let mut accel_bar = [0.0f64; 3];
        let drive_box = drive.map(|d| d.bounds());
        // solids hook (issue 30): the solids where the forward placed them (sim.time is the step's)
        let solids = self.solids.as_ref().map(|z| z.at(self.time, self.printer.as_ref().map(|p| &*p.toolpath)));
        let mut solids_bar = crate::solid::SolidsBar::default();
        // the holds as the update saw them (the loads after it only mark units to wake)
        let holds = self.sleep.as_ref().map(|z| z.holds());
        for s in 0..self.grid.n_active {
            let b = geom.block_coords(slot_block[s]);
            let window = holds.as_ref().and_then(|z| z.block(geom, b));
            let driven = drive.filter(|_| drive_box.is_some_and(|bx| geom.block_overlaps(b, bx)));
            let solid_mask = solids.as_ref().map_or(0, |z| z.block_mask(geom, b));
            let walled = walls.reach(geom, b);
            for li in 0..NODES_PER_BLOCK {
                let at = s * NODES_PER_BLOCK + li;
                let n0 = &before[at];
                let m = n0[0];
                let nb = &mut grid_bar[at];
                if m <= 0.0 {
                    *nb = [0.0; 7];
                    continue;
                }
                let p = V3::new(n0[1], n0[2], n0[3]);
                let f = V3::new(n0[4], n0[5], n0[6]);
                let old = p / m;
                let g = geom.node_of(b, li);
                let held = window.as_ref().is_some_and(|w| w.holds(li));
                let v = if held { V3::ZERO } else { old + f / m + accel * dt };
                let driven_v = driven.map_or(v, |d| apply_drive(geom, Some(d), g, v));
                let mut v_bar = V3::new(nb[1], nb[2], nb[3]);
                if let Some(z) = solids.as_ref().filter(|_| solid_mask != 0) {
                    // solids hook (issue 30): they act after the walls
                    let after_walls = if walled { apply_walls(geom, walls, g, driven_v) } else { driven_v };
                    v_bar = z.apply_adjoint(solid_mask, geom.node_position(g), after_walls, v_bar, &mut solids_bar);
                }
                let mut v_bar = if walled { apply_walls_adjoint(geom, walls, g, driven_v, v_bar, bar) } else { v_bar };
                if let Some(d) = driven {
                    v_bar = drive_adjoint(geom, d, g, v, v_bar, bar);
                }
                if held {
                    v_bar = V3::ZERO;
                }
                let old_bar = V3::new(nb[4], nb[5], nb[6]) + v_bar;
                for c in 0..3 {
                    accel_bar[c] += (v_bar[c] * dt) as f64;
                }
                let m_bar = nb[0] - old_bar.dot(p) / (m * m) - v_bar.dot(f) / (m * m);
                let p_bar = old_bar / m;
                let f_bar = v_bar / m;
                *nb = [m_bar, p_bar.x, p_bar.y, p_bar.z, f_bar.x, f_bar.y, f_bar.z];
            }
        }
        for c in 0..3 {
            bar.accel[c] += accel_bar[c];
            bar.drive_outlet[c] += solids_bar.outlet[c];
            bar.drive_velocity[c] += solids_bar.nozzle_velocity[c];
        }
        let (outlet_bar, velocity_bar) = (std::mem::take(&mut bar.drive_outlet), std::mem::take(&mut bar.drive_velocity));
        if let (Some(tb), Some(_)) = (toolpath, drive) {
            let fv = a.feed_velocity_bar;
            tb.drive(self.toolpath_move(), self.time, outlet_bar, [velocity_bar[0] + fv[0], velocity_bar[1] + fv[1], velocity_bar[2] + fv[2]]);
        }
    }
}
