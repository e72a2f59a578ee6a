//! Adjoint of the grid update (`Simulation::grid_update`): momentum to velocity, body
//! acceleration, the wall conditions on wall nodes and the mirrored ghost nodes beyond them.
//!
//! The forward turns a node `[m, p, f]` (mass, momentum, impulse kept apart under FLIP) into
//! `[m, v_new, v_old]` with `v_old = p / m`, `v_new = walls(v_old + f / m + a dt)`, and then
//! overwrites the velocity of every ghost node with the signed velocity of its mirror partner.
//! The adjoint runs the two passes backwards on the node adjoints in place: first the ghosts hand
//! their adjoint to their partners, then every node maps `[m_bar, v_new_bar, v_old_bar]` to
//! `[m_bar, p_bar, f_bar]`, the layout P2G's adjoint reads.

use crate::grid::NODES_PER_BLOCK;
use crate::kernels::boundary::{apply_wall, apply_wall_adjoint, WallKind};
use crate::kernels::transfer::Node;
use crate::kernels::{Real, V3};
use crate::grid::GridGeom;
use crate::print::NozzleDrive;
use crate::solver::{apply_drive, ghost_source, wall_sequence, Simulation, Walls};

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

/// Adjoints of the grid update's parameters, accumulated over nodes and steps.
#[derive(Clone, Copy, Debug, Default)]
pub struct GridParamsBar {
    /// Of the body acceleration g + F / rho.
    pub accel: [f64; 3],
    /// Of the Coulomb coefficient of each friction wall, [axis][side].
    pub wall_mu: [[f64; 2]; 3],
    pub platform_mu: f64,
    /// Of the nozzle drive's outlet position and imposed velocity, this step only (the caller
    /// chains them into the toolpath's parameters and resets them).
    pub drive_outlet: [f64; 3],
    pub drive_velocity: [f64; 3],
}

/// Adjoint of `apply_walls` at node `g` for input velocity `v`: the adjoint of `v` for the
/// adjoint `v_bar` of the result; friction coefficients' adjoints go to `bar`.
fn apply_walls_adjoint(geom: &GridGeom, walls: &Walls, g: [i32; 3], v: V3, v_bar: V3, bar: &mut GridParamsBar) -> V3 {
    let mut seq = [(WallKind::NoSlip, V3::ZERO, None); 4];
    let k = wall_sequence(geom, walls, g, &mut seq);
    if k == 0 {
        return v_bar;
    }
    // inputs of each application, recomputed forward
    let mut inputs = [V3::ZERO; 4];
    let mut at = v;
    for (i, (kind, nrm, _)) in seq[..k].iter().enumerate() {
        inputs[i] = at;
        at = apply_wall(*kind, *nrm, V3::ZERO, at);
    }
    let mut b = v_bar;
    for i in (0..k).rev() {
        let (kind, nrm, face) = seq[i];
        let (vb, mu_bar) = apply_wall_adjoint(kind, nrm, V3::ZERO, inputs[i], b);
        b = vb;
        match face {
            Some((a, s)) => bar.wall_mu[a][s] += mu_bar as f64,
            None => bar.platform_mu += mu_bar as f64,
        }
    }
    b
}

/// Run the grid update's adjoint on `grid_bar` in place. `before` holds the nodes as P2G left
/// them, the simulation's grid the nodes after the update (the same active blocks), `dt` the
/// step, `drive` the nozzle drive of the step. Sleeping holds have no adjoint (gradient runs keep
/// every particle awake).
pub fn grid_update_adjoint(sim: &Simulation, drive: Option<&NozzleDrive>, before: &[Node], grid_bar: &mut [Node], dt: Real, bar: &mut GridParamsBar) {
    let grid = &sim.grid;
    let geom = &grid.geom;
    let na = grid.n_active;
    let slot_block = grid.slot_block.as_slice();
    let table = grid.table.as_slice();
    let after = grid.nodes.as_slice();
    let walls = &sim.walls;
    // ghosts: their velocity was overwritten by their partner's, so their adjoint goes there
    for s in 0..na {
        let b = geom.block_coords(slot_block[s]);
        if !geom.block_reaches_beyond_walls(b) {
            continue;
        }
        for li in 0..NODES_PER_BLOCK {
            let at = s * NODES_PER_BLOCK + li;
            if after[at][0] <= 0.0 {
                continue;
            }
            let Some((src, sign)) = ghost_source(geom, walls, geom.node_of(b, li), table) else { continue };
            let gb = [grid_bar[at][1], grid_bar[at][2], grid_bar[at][3]];
            grid_bar[at][1..4].fill(0.0);
            if let Some(i) = src {
                for c in 0..3 {
                    grid_bar[i][1 + c] += gb[c] * sign[c];
                }
            }
        }
    }
    let accel = sim.accel;
    let mut accel_bar = [0.0f64; 3];
    let drive_box = drive.map(|d| d.bounds());
    // solids hook (issue 30): the solids where the forward placed them (sim.time is the step's)
    let solids = sim.solids.as_ref().map(|z| z.at(sim.time, sim.printer.as_ref().map(|p| &*p.toolpath)));
    let mut solids_bar = crate::solid::SolidsBar::default();
    for s in 0..na {
        let b = geom.block_coords(slot_block[s]);
        let driven = drive.filter(|_| drive_box.is_some_and(|bx| geom.block_overlaps(b, bx)));
        let solid_mask = solids.as_ref().map_or(0, |z| z.block_mask(geom, b));
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
            let v = old + f / m + accel * dt;
            let driven_v = driven.map_or(v, |d| apply_drive(geom, Some(d), g, v));
            let mut v_bar = V3::new(nb[1], nb[2], nb[3]);
            if let Some(z) = solids.as_ref().filter(|_| solid_mask != 0) {
                // solids hook (issue 30): they act after the walls
                let walled = crate::solver::apply_walls(geom, walls, g, driven_v);
                v_bar = z.apply_adjoint(solid_mask, geom.node_position(g), walled, v_bar, &mut solids_bar);
            }
            let mut v_bar = apply_walls_adjoint(geom, walls, g, driven_v, v_bar, bar);
            if let Some(d) = driven {
                v_bar = drive_adjoint(geom, d, g, v, v_bar, bar);
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
}

