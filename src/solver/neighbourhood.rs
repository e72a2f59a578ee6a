//! The 6^3 node neighbourhood of a particle block, read from and added into the grid's 2x2x2
//! blocks.

use crate::grid::{GridGeom, NODES_PER_BLOCK};
use crate::kernels::transfer::{local_index, Node, BLOCK_EDGE, NEIGHBOURHOOD_EDGE, NEIGHBOURHOOD_NODES};
use crate::threads::SharedSlice;

/// Visit the nodes of a particle block's 6^3 neighbourhood as (local index, index in the grid's
/// node pool), walking its 2x2x2 blocks.
#[inline(always)]
fn for_each_neighbourhood_node(nbr: &[u32; 8], mut f: impl FnMut(usize, usize)) {
    for (d, &slot) in nbr.iter().enumerate() {
        let o = [(d >> 2) & 1, (d >> 1) & 1, d & 1];
        let base = slot as usize * NODES_PER_BLOCK;
        let ext = |k: usize| if o[k] == 0 { BLOCK_EDGE } else { NEIGHBOURHOOD_EDGE - BLOCK_EDGE };
        for i in 0..ext(0) {
            for jj in 0..ext(1) {
                for k in 0..ext(2) {
                    f(local_index(o[0] * BLOCK_EDGE + i, o[1] * BLOCK_EDGE + jj, o[2] * BLOCK_EDGE + k), base + (i * BLOCK_EDGE + jj) * BLOCK_EDGE + k);
                }
            }
        }
    }
}

/// Add a P2G neighbourhood buffer into the grid's 2x2x2 blocks.
///
/// # Safety
/// No other thread may touch the blocks in `nbr` meanwhile.
pub(crate) unsafe fn flush_local(local: &[Node; NEIGHBOURHOOD_NODES], nbr: &[u32; 8], nodes: &SharedSlice<Node>) {
    for_each_neighbourhood_node(nbr, |l, g| {
        let dst = nodes.get_mut(g);
        for (d, s) in dst.iter_mut().zip(local[l].iter()) {
            *d += *s;
        }
    });
}

/// Gather the nodes of a particle block's neighbourhood.
pub(crate) fn gather_local(local: &mut [Node; NEIGHBOURHOOD_NODES], nbr: &[u32; 8], nodes: &[Node]) {
    for_each_neighbourhood_node(nbr, |l, g| local[l] = nodes[g]);
}

/// The first node of the particle block at grid block index `block`.
#[inline]
pub(crate) fn block_origin(geom: &GridGeom, block: u32) -> [i32; 3] {
    let b = geom.block_coords(block);
    [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32]
}
