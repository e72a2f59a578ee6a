//! Which grid nodes the sleeping units hold still: a unit holds the nodes of its particles'
//! stencil reach, so active material reaching them sees a still, no-slip body.

use super::units::{block_in_table, UnitState, UNITS, UNITS_PER_EDGE, UNIT_CELLS};
use crate::grid::GridGeom;
use crate::kernels::transfer::BLOCK_EDGE;

/// What the grid update needs of the sleeping units: which nodes they hold.
pub struct Holds<'a> {
    pub(super) state: &'a [UnitState],
    pub(super) asleep_in_block: &'a [u8],
    pub(super) sleeping_units: usize,
}

impl Holds<'_> {
    /// The sleeping units whose stencil reach overlaps grid block `b` (None when there are
    /// none near it): a unit holds nodes 2u..=2u+3 on each axis, so these are the block's own
    /// units and one more below it on each axis. Looked up once per block, because the grid
    /// update and the load test ask for every node of a block near sleeping material.
    pub fn block(&self, geom: &GridGeom, b: [i32; 3]) -> Option<BlockHolds> {
        if self.sleeping_units == 0 {
            return None;
        }
        // block b and the blocks one below it on some axes (bit 2 - a of `d` set: below on
        // axis a), where they are in the table and hold a sleeping unit
        let mut near = [None; 8];
        for (d, slot) in near.iter_mut().enumerate() {
            let c = geom.wrap_block([b[0] - (d >> 2 & 1) as i32, b[1] - (d >> 1 & 1) as i32, b[2] - (d & 1) as i32]);
            if block_in_table(geom, c) {
                let bi = geom.block_index(c);
                *slot = (self.asleep_in_block[bi as usize] > 0).then_some(bi);
            }
        }
        if near == [None; 8] {
            return None;
        }
        let mut units = [NO_UNIT; WINDOW];
        for (w, slot) in units.iter_mut().enumerate() {
            // window coordinate 0 is the last unit of the block below, 1..=UNITS_PER_EDGE block b's units
            let wa = [w / (WINDOW_EDGE * WINDOW_EDGE), w / WINDOW_EDGE % WINDOW_EDGE, w % WINDOW_EDGE];
            let d = ((wa[0] == 0) as usize) << 2 | ((wa[1] == 0) as usize) << 1 | (wa[2] == 0) as usize;
            let Some(bi) = near[d] else { continue };
            let l = wa.map(|x| if x == 0 { UNITS_PER_EDGE - 1 } else { x - 1 });
            let idx = bi * UNITS as u32 + ((l[0] * UNITS_PER_EDGE + l[1]) * UNITS_PER_EDGE + l[2]) as u32;
            if (self.state[idx as usize]).is_asleep() {
                *slot = idx;
            }
        }
        Some(BlockHolds { units })
    }
}

/// Edge of the window of units that can hold a block's nodes, and its size.
const WINDOW_EDGE: usize = UNITS_PER_EDGE + 1;
const WINDOW: usize = WINDOW_EDGE * WINDOW_EDGE * WINDOW_EDGE;
const NO_UNIT: u32 = u32::MAX;

/// The sleeping units that can hold the nodes of one grid block ([`Holds::block`]).
pub struct BlockHolds {
    /// Table index of each unit of the window, or NO_UNIT where it is awake or outside the table.
    units: [u32; WINDOW],
}

impl BlockHolds {
    /// Whether node `li` of the block is held.
    #[inline]
    pub fn holds(&self, li: usize) -> bool {
        self.holders(li).next().is_some()
    }

    /// The sleeping units holding node `li` of the block (at most 8): the units c - o, o in
    /// {0, 1}^3, of the node's unit c.
    #[inline]
    pub fn holders(&self, li: usize) -> impl Iterator<Item = u32> + '_ {
        let l = [li / (BLOCK_EDGE * BLOCK_EDGE), li / BLOCK_EDGE % BLOCK_EDGE, li % BLOCK_EDGE].map(|c| c / UNIT_CELLS as usize + 1);
        (0..8).filter_map(move |d| {
            let u = self.units[((l[0] - (d >> 2 & 1)) * WINDOW_EDGE + l[1] - (d >> 1 & 1)) * WINDOW_EDGE + l[2] - (d & 1)];
            (u != NO_UNIT).then_some(u)
        })
    }
}
