//! The domain's walls and platform: the conditions a grid node takes, the ghost nodes beyond
//! the walls, and the particles kept inside.

use crate::grid::{GridGeom, NODES_PER_BLOCK, PAD};
use super::adjoint::GridParamsBar;
use crate::kernels::boundary::{apply_wall, apply_wall_adjoint, WallKind};
use crate::kernels::transfer::{Node, BLOCK_EDGE};
use crate::kernels::{Real, V3};
use super::Simulation;
use crate::scenario::Boundary;
use crate::threads::{SharedSlice, ThreadTeam};

/// Wall conditions resolved for the grid update.
#[derive(Clone, Debug)]
pub(crate) struct Walls {
    /// [axis][0 = min side, 1 = max side]
    pub(crate) faces: [[WallKind; 2]; 3],
    /// Platform: grid-coordinate top z, xy extent in grid coordinates, kind.
    pub(crate) platform: Option<(Real, [Real; 4], WallKind)>,
}

impl Walls {
    /// The scenario's `[boundary]` in grid coordinates.
    pub(crate) fn new(b: &Boundary, g: &GridGeom) -> Walls {
        Walls {
            faces: [[b.x_min, b.x_max], [b.y_min, b.y_max], [b.z_min, b.z_max]],
            platform: b.platform.as_ref().map(|p| {
                let lo = g.to_grid([p.xy_min[0], p.xy_min[1], p.z]);
                let hi = g.to_grid([p.xy_max[0], p.xy_max[1], p.z]);
                (lo.z, [lo.x, lo.y, hi.x, hi.y], p.kind)
            }),
        }
    }
}

impl Walls {
    /// Whether a node of block `b` can take a wall condition ([`wall_sequence`]): one lies on or
    /// beyond a wall of a walled axis, or there is a platform. Elsewhere the walls leave every
    /// velocity as it is, and the grid update skips them.
    #[inline]
    pub(crate) fn reach(&self, geom: &GridGeom, b: [i32; 3]) -> bool {
        let edge = BLOCK_EDGE as i32;
        self.platform.is_some()
            || (0..3).any(|a| !geom.periodic[a] && (b[a] * edge <= PAD || b[a] * edge + edge > geom.cells[a] - PAD))
    }
}

/// Wall conditions for the node at grid index `g`.
#[inline]
pub(crate) fn apply_walls(geom: &GridGeom, walls: &Walls, g: [i32; 3], v: V3) -> V3 {
    let mut seq = [(WallKind::NoSlip, V3::ZERO, None); 4];
    let k = wall_sequence(geom, walls, g, &mut seq);
    seq[..k].iter().fold(v, |v, &(kind, nrm, _)| apply_wall(kind, nrm, V3::ZERO, v))
}

/// Adjoint of [`apply_walls`] at node `g` for input velocity `v`: the adjoint of `v` for the
/// adjoint `v_bar` of the result; friction coefficients' adjoints go to `bar`.
pub(crate) fn apply_walls_adjoint(geom: &GridGeom, walls: &Walls, g: [i32; 3], v: V3, v_bar: V3, bar: &mut GridParamsBar) -> V3 {
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

/// One wall condition at a node: kind, outward normal, and the wall as (axis, side) or None for
/// the platform.
pub(crate) type WallAt = (WallKind, V3, Option<(usize, usize)>);

/// The wall conditions node `g` takes, in the order they apply (one per non-periodic axis whose
/// wall it lies on, then the platform): (kind, outward normal, the wall as (axis, side), or None
/// for the platform). Returns how many; the grid update and its adjoint both walk this list.
fn wall_sequence(geom: &GridGeom, walls: &Walls, g: [i32; 3], out: &mut [WallAt; 4]) -> usize {
    let mut k = 0;
    for a in 0..3 {
        if geom.periodic[a] {
            continue;
        }
        let mut nrm = V3::ZERO;
        if g[a] <= PAD {
            nrm[a] = -1.0;
            out[k] = (walls.faces[a][0], nrm, Some((a, 0)));
            k += 1;
        } else if g[a] >= geom.cells[a] - PAD {
            nrm[a] = 1.0;
            out[k] = (walls.faces[a][1], nrm, Some((a, 1)));
            k += 1;
        }
    }
    if let Some((z, xy, kind)) = walls.platform {
        let (x, y) = (g[0] as Real, g[1] as Real);
        if (g[2] as Real) <= z && x >= xy[0] && x <= xy[2] && y >= xy[1] && y <= xy[3] {
            out[k] = (kind, V3::new(0.0, 0.0, -1.0), None);
            k += 1;
        }
    }
    k
}

impl Simulation {
    /// Ghost nodes beyond no-slip and free-slip walls take the mirror image of the velocity
    /// inside, so G2P sees a field that is odd (no-slip) or has an odd normal part (free-slip)
    /// across the wall. Zeroing them instead destroys the momentum of the material near the
    /// wall once per step: a drag proportional to the number of steps, not to time (measured:
    /// a channel flow lost 20-70 % of its speed as dt shrank).
    pub(crate) fn mirror_ghosts(&mut self) {
        let na = self.grid.n_active;
        let geom = &self.grid.geom;
        let slot_block = self.grid.slot_block.as_slice();
        let table = self.grid.table.as_slice();
        let nodes = SharedSlice::new(self.grid.nodes.as_mut_slice());
        let walls = &self.walls;
        let threads = self.team.threads();
        self.team.run(|tid| {
            for s in ThreadTeam::share(na, tid, threads) {
                let b = geom.block_coords(slot_block[s]);
                if !geom.block_reaches_beyond_walls(b) {
                    continue;
                }
                for li in 0..NODES_PER_BLOCK {
                    let g = geom.node_of(b, li);
                    // SAFETY: this pass writes only ghost nodes and reads only nodes that are
                    // not ghosts on any axis; each ghost node belongs to one slot and thread.
                    unsafe { mirror_ghost(geom, walls, g, s * NODES_PER_BLOCK + li, &nodes, table) };
                }
            }
        });
    }
}

impl Simulation {
    /// Adjoint of [`Simulation::mirror_ghosts`] on the grid's adjoint `grid_bar`: a ghost's
    /// velocity was overwritten by its partner's, so its adjoint goes there. Reads the grid as
    /// the update left it.
    pub(crate) fn mirror_ghosts_adjoint(&self, grid_bar: &mut [Node]) {
        let grid = &self.grid;
        let geom = &grid.geom;
        let slot_block = grid.slot_block.as_slice();
        let table = grid.table.as_slice();
        let after = grid.nodes.as_slice();
        for s in 0..grid.n_active {
            let b = geom.block_coords(slot_block[s]);
            if !geom.block_reaches_beyond_walls(b) {
                continue;
            }
            for li in 0..NODES_PER_BLOCK {
                let at = s * NODES_PER_BLOCK + li;
                if after[at][0] <= 0.0 {
                    continue;
                }
                let Some((src, sign)) = ghost_source(geom, &self.walls, geom.node_of(b, li), table) else { continue };
                let gb = [grid_bar[at][1], grid_bar[at][2], grid_bar[at][3]];
                grid_bar[at][1..4].fill(0.0);
                if let Some(i) = src {
                    for c in 0..3 {
                        grid_bar[i][1 + c] += gb[c] * sign[c];
                    }
                }
            }
        }
    }
}

/// Where a ghost node `g` (beyond a wall on at least one axis) takes its velocity from: the pool
/// index of its mirror partner inside (None when the partner's block is inactive, which reads as
/// zero) and the sign of each component (negated for no-slip, the normal one for free-slip; a
/// corner negates once per wall). None when `g` is no ghost, or a ghost of a friction wall, which
/// keeps its own velocity.
#[inline]
fn ghost_source(geom: &GridGeom, walls: &Walls, g: [i32; 3], table: &[u32]) -> Option<(Option<usize>, [Real; 3])> {
    let mut mirror = g;
    let mut sign = [1.0 as Real; 3];
    let mut ghost = false;
    for a in 0..3 {
        if !geom.beyond_wall(a, g[a]) {
            continue;
        }
        let hi = geom.cells[a] - PAD;
        let (side, m) = if g[a] < PAD { (0, 2 * PAD - g[a]) } else { (1, 2 * hi - g[a]) };
        ghost = true;
        mirror[a] = m;
        match walls.faces[a][side] {
            WallKind::NoSlip => sign.iter_mut().for_each(|s| *s = -*s),
            WallKind::FreeSlip | WallKind::Symmetry => sign[a] = -sign[a],
            WallKind::Friction { .. } => return None,
        }
    }
    if !ghost {
        return None;
    }
    let blk = [mirror[0].div_euclid(BLOCK_EDGE as i32), mirror[1].div_euclid(BLOCK_EDGE as i32), mirror[2].div_euclid(BLOCK_EDGE as i32)];
    let slot = table[geom.block_index(blk) as usize];
    let src = (slot != crate::grid::EMPTY).then(|| {
        let l = (mirror[0].rem_euclid(BLOCK_EDGE as i32) as usize * BLOCK_EDGE + mirror[1].rem_euclid(BLOCK_EDGE as i32) as usize) * BLOCK_EDGE
            + mirror[2].rem_euclid(BLOCK_EDGE as i32) as usize;
        slot as usize * NODES_PER_BLOCK + l
    });
    Some((src, sign))
}

/// Set a ghost node to the mirror image of its partner inside ([`ghost_source`]); nodes that are
/// not ghosts, ghosts of friction walls and empty ghosts keep their velocity.
///
/// # Safety
/// Only this node may be written concurrently; non-ghost nodes must not be written meanwhile.
pub(crate) unsafe fn mirror_ghost(geom: &GridGeom, walls: &Walls, g: [i32; 3], at: usize, nodes: &SharedSlice<Node>, table: &[u32]) {
    // most nodes beyond a wall are empty: their mass first, the mirror only where it counts
    if !(0..3).any(|a| geom.beyond_wall(a, g[a])) {
        return;
    }
    let node = nodes.get_mut(at);
    if node[0] <= 0.0 {
        return;
    }
    let Some((src, sign)) = ghost_source(geom, walls, g, table) else { return };
    let v = src.map_or([0.0; 3], |i| {
        let s = &nodes.as_slice()[i];
        [s[1], s[2], s[3]]
    });
    for c in 0..3 {
        node[1 + c] = v[c] * sign[c];
    }
}

impl Simulation {
    /// Adjoint of [`keep_inside`] on G2P's positions, on their adjoints `xg_bar`: a coordinate
    /// projected onto a wall (or the platform) no longer depends on anything; a periodic wrap
    /// shifts by a constant and passes the adjoint through. Sleeping particles are not moved.
    pub(crate) fn keep_inside_adjoint(&self, xg_bar: &mut [V3]) {
        let geom = &self.grid.geom;
        let x1 = self.particles.xg.as_slice();
        let platform = self.walls.platform;
        for i in self.particles.n_sleep..self.particles.n {
            for a in 0..3 {
                if !geom.periodic[a] && (x1[i][a] == geom.lo[a] as Real || x1[i][a] == geom.hi[a] as Real) {
                    xg_bar[i][a] = 0.0;
                }
            }
            if let Some((z, xy, _)) = platform {
                let x = x1[i];
                if x.z == z && x.x >= xy[0] && x.x <= xy[2] && x.y >= xy[1] && x.y <= xy[3] {
                    xg_bar[i].z = 0.0;
                }
            }
        }
    }
}

/// Keep a particle inside the walls (projected onto them) and wrap it on periodic axes.
#[inline]
pub(crate) fn keep_inside(geom: &GridGeom, platform: Option<(Real, [Real; 4], WallKind)>, x: &mut V3) {
    for a in 0..3 {
        let (lo, hi) = (geom.lo[a] as Real, geom.hi[a] as Real);
        if geom.periodic[a] {
            let n = geom.cells[a] as Real;
            if x[a] < lo {
                x[a] += n;
            } else if x[a] >= hi {
                x[a] -= n;
            }
        } else {
            x[a] = x[a].clamp(lo, hi);
        }
    }
    if let Some((z, xy, _)) = platform {
        if x.z < z && x.x >= xy[0] && x.x <= xy[2] && x.y >= xy[1] && x.y <= xy[3] {
            x.z = z;
        }
    }
}
