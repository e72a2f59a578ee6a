//! The sparse-block grid: nodes live in blocks of 4^3, stored in a fixed number of slots; a dense
//! block table maps block coordinates to slots. Each step the particles are binned by the block
//! of their stencil base ("particle blocks"), and every particle block's 2x2x2 neighbourhood of
//! blocks is activated, so P2G and G2P only ever touch active slots.

use crate::kernels::transfer::{Node, BLOCK_EDGE};
use crate::kernels::{Real, V3};
use crate::memory::{Backing, MemoryError, Pool};
use crate::pools::{map_pools, Counts, Per, PoolDecl, Pools, Role};

pub const EMPTY: u32 = u32::MAX;
pub const NODES_PER_BLOCK: usize = BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE;

/// Grid geometry: where node 0 sits, how many cells each axis has, which axes wrap.
#[derive(Clone, Debug)]
pub struct GridGeom {
    pub dx: f64,
    /// Physical position of node (0, 0, 0).
    pub origin: [f64; 3],
    /// Cells along each axis (walled axes include `PAD` cells of margin on both sides).
    pub cells: [i32; 3],
    /// Block-table extent along each axis.
    pub nb: [i32; 3],
    pub periodic: [bool; 3],
    /// Grid-coordinate range particles may occupy on walled axes (the walls).
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

/// Margin cells outside each wall, so a particle at the wall keeps its whole stencil in the grid.
pub const PAD: i32 = 3;

impl GridGeom {
    /// The grid of cells `dx` over the box `min`..`max` (a scenario's `simulation.dx` and
    /// `[domain]`), periodic along the axes `periodic` names.
    pub fn new(dx: f64, min: [f64; 3], max: [f64; 3], periodic: [bool; 3]) -> Self {
        let mut g = GridGeom { dx, origin: [0.0; 3], cells: [0; 3], nb: [0; 3], periodic, lo: [0.0; 3], hi: [0.0; 3] };
        for a in 0..3 {
            let n = ((max[a] - min[a]) / dx).round() as i32;
            if periodic[a] {
                g.origin[a] = min[a] - 0.5 * dx;
                g.cells[a] = n;
                g.nb[a] = n / BLOCK_EDGE as i32;
                // stored positions wrap into [0.5, n + 0.5): the stencil base is then in 0..n
                g.lo[a] = 0.5;
                g.hi[a] = n as f64 + 0.5;
            } else {
                g.origin[a] = min[a] - PAD as f64 * dx;
                g.cells[a] = n + 2 * PAD;
                g.nb[a] = g.cells[a] / BLOCK_EDGE as i32 + 2;
                g.lo[a] = PAD as f64;
                g.hi[a] = (n + PAD) as f64;
            }
        }
        g
    }

    pub fn table_len(&self) -> usize {
        (self.nb[0] as usize) * (self.nb[1] as usize) * (self.nb[2] as usize)
    }

    /// Physical position of a grid-coordinate point.
    pub fn to_world(&self, xg: V3) -> [f64; 3] {
        [
            self.origin[0] + xg.x as f64 * self.dx,
            self.origin[1] + xg.y as f64 * self.dx,
            self.origin[2] + xg.z as f64 * self.dx,
        ]
    }

    pub fn to_grid(&self, x: [f64; 3]) -> V3 {
        V3::new(
            ((x[0] - self.origin[0]) / self.dx) as Real,
            ((x[1] - self.origin[1]) / self.dx) as Real,
            ((x[2] - self.origin[2]) / self.dx) as Real,
        )
    }

    /// Linear block-table index of (wrapped) block coordinates.
    #[inline(always)]
    pub fn block_index(&self, b: [i32; 3]) -> u32 {
        ((b[0] * self.nb[1] + b[1]) * self.nb[2] + b[2]) as u32
    }

    #[inline(always)]
    pub fn block_coords(&self, idx: u32) -> [i32; 3] {
        let i = idx as i32;
        let z = i % self.nb[2];
        let y = (i / self.nb[2]) % self.nb[1];
        let x = i / (self.nb[2] * self.nb[1]);
        [x, y, z]
    }

    /// Wrap a block coordinate on periodic axes.
    #[inline(always)]
    pub fn wrap_block(&self, mut b: [i32; 3]) -> [i32; 3] {
        for a in 0..3 {
            if self.periodic[a] {
                b[a] = b[a].rem_euclid(self.nb[a]);
            }
        }
        b
    }

    /// Grid index of node `li` (0..BLOCK_EDGE^3, z fastest) of block `b`.
    #[inline(always)]
    pub fn node_of(&self, b: [i32; 3], li: usize) -> [i32; 3] {
        [
            b[0] * BLOCK_EDGE as i32 + (li / (BLOCK_EDGE * BLOCK_EDGE)) as i32,
            b[1] * BLOCK_EDGE as i32 + ((li / BLOCK_EDGE) % BLOCK_EDGE) as i32,
            b[2] * BLOCK_EDGE as i32 + (li % BLOCK_EDGE) as i32,
        ]
    }

    /// Whether node index `g` lies beyond a wall (strictly outside the walls) on walled axis `a`.
    #[inline(always)]
    pub fn beyond_wall(&self, a: usize, g: i32) -> bool {
        !self.periodic[a] && (g < PAD || g > self.cells[a] - PAD)
    }

    /// Whether block `b` holds any node beyond a wall.
    pub fn block_reaches_beyond_walls(&self, b: [i32; 3]) -> bool {
        (0..3).any(|a| self.beyond_wall(a, b[a] * BLOCK_EDGE as i32) || self.beyond_wall(a, b[a] * BLOCK_EDGE as i32 + BLOCK_EDGE as i32 - 1))
    }

    /// Physical position of node `g`.
    #[inline(always)]
    pub fn node_position(&self, g: [i32; 3]) -> [f64; 3] {
        [
            self.origin[0] + g[0] as f64 * self.dx,
            self.origin[1] + g[1] as f64 * self.dx,
            self.origin[2] + g[2] as f64 * self.dx,
        ]
    }

    /// Whether block `b`'s nodes reach into the world box `bx` (no wrap: boxes are local).
    pub fn block_overlaps(&self, b: [i32; 3], bx: ([f64; 3], [f64; 3])) -> bool {
        let lo = self.node_position([b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32]);
        let span = (BLOCK_EDGE - 1) as f64 * self.dx;
        (0..3).all(|a| lo[a] <= bx.1[a] && lo[a] + span >= bx.0[a])
    }

    /// Block of the stencil base of a particle at grid coordinate `xg`.
    #[inline(always)]
    pub fn particle_block(&self, xg: V3) -> [i32; 3] {
        let (base, _) = crate::kernels::bspline::base_and_fx(xg);
        base.map(|b| b.div_euclid(BLOCK_EDGE as i32))
    }
}

/// Node storage and the block table.
pub struct Grid {
    pub geom: GridGeom,
    /// Block coordinates (linear index) -> slot, or EMPTY.
    pub table: Pool<u32>,
    /// `NODES_PER_BLOCK` nodes per slot: (mass, momentum) after P2G, (mass, velocity) after the
    /// grid update.
    pub nodes: Pool<Node>,
    /// Linear block index of each active slot.
    pub slot_block: Pool<u32>,
    /// Active slots: `0..n_active`; the first `n_particle_blocks` hold particles.
    pub n_active: usize,
    pub n_particle_blocks: usize,
}

impl Pools for Grid {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        use Role::*;
        vec![
            // rebuilt by binning the restored particles
            PoolDecl::new("grid.table", Per::Table(self.geom.table_len()), Scratch, |g| &g.table, |g| &mut g.table),
            PoolDecl::new("grid.nodes", Per::Block(NODES_PER_BLOCK), Nodes { moving: "grid.moving", velocity: "grid.velocity" }, |g| &g.nodes, |g| &mut g.nodes),
            PoolDecl::new("grid.slot_block", Per::Block(1), Stored, |g| &g.slot_block, |g| &mut g.slot_block),
        ]
    }

    fn map_pools(&mut self, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
        map_pools(self, cap, backing)?;
        self.table.as_mut_slice().fill(EMPTY);
        Ok(())
    }
}

impl Grid {
    /// The grid of `geom`, its pools declared but not mapped ([`Pools::map_pools`] maps them).
    pub fn declared(geom: GridGeom) -> Self {
        Grid { geom, table: Pool::default(), nodes: Pool::default(), slot_block: Pool::default(), n_active: 0, n_particle_blocks: 0 }
    }

    /// The grid of `geom` with `max_blocks` slots, mapped.
    pub fn new(geom: GridGeom, max_blocks: usize, backing: &Backing) -> Result<Self, MemoryError> {
        let mut g = Grid::declared(geom);
        g.map_pools(&Counts::capacity(0, max_blocks), backing)?;
        Ok(g)
    }

    pub fn max_blocks(&self) -> usize {
        self.slot_block.len()
    }

    /// Forget every active block (the table is cleared entry by entry, not wholesale).
    pub fn reset(&mut self) {
        let table = self.table.as_mut_slice();
        for &b in &self.slot_block.as_slice()[..self.n_active] {
            table[b as usize] = EMPTY;
        }
        self.n_active = 0;
        self.n_particle_blocks = 0;
    }

    /// Slot of a block, activating it if needed.
    #[inline]
    pub fn activate(&mut self, block: u32) -> Result<u32, MemoryError> {
        let t = &mut self.table.as_mut_slice()[block as usize];
        if *t != EMPTY {
            return Ok(*t);
        }
        let s = self.n_active;
        if s >= self.slot_block.len() {
            return Err(MemoryError::PoolFull {
                pool: "grid blocks",
                needed: s + 1,
                capacity: self.slot_block.len(),
                hint: "[memory] max_blocks",
            });
        }
        *t = s as u32;
        self.slot_block.as_mut_slice()[s] = block;
        self.n_active += 1;
        Ok(s as u32)
    }

    /// Slot of an active block.
    #[inline(always)]
    pub fn slot(&self, block: u32) -> u32 {
        self.table.as_slice()[block as usize]
    }
}
