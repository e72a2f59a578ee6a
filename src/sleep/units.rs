//! The unit lattice: units of `UNIT_CELLS`^3 cells, `UNITS` to a grid block, their indices in the
//! unit tables (the block table's layout, refined), neighbours, and the state of a unit.

use crate::grid::GridGeom;
use crate::kernels::transfer::BLOCK_EDGE;
use crate::kernels::{Real, V3};

/// What a unit is doing: one byte per unit in the state table.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::NoUninit, bytemuck::CheckedBitPattern)]
pub enum UnitState {
    Awake = 0,
    Asleep = 1,
    /// Within one update: woken, its sleep start still in `rest` until its particles had their rest.
    Woken = 2,
    /// Asleep, and loaded past its margin in the step just taken: the next update wakes it. (Its
    /// particles are still in the sleeping prefix, so its nodes stay held until then.)
    Loaded = 3,
}

impl UnitState {
    #[inline]
    pub fn is_asleep(self) -> bool {
        self == UnitState::Asleep || self == UnitState::Loaded
    }
}

/// The state table's bytes as unit states. Every byte of the table is one: the pool starts
/// zeroed (`Awake`), the passes write only `UnitState`s, and a checkpoint's table is checked
/// before it is taken in ([`super::Sleep::restored`]).
#[inline]
pub(super) fn states(b: &[u8]) -> &[UnitState] {
    // SAFETY: UnitState is repr(u8) and every byte of the table is a valid UnitState (above)
    unsafe { &*(b as *const [u8] as *const [UnitState]) }
}

#[inline]
pub(super) fn states_mut(b: &mut [u8]) -> &mut [UnitState] {
    // SAFETY: as in `states`; UnitState values written through it keep the table valid
    unsafe { &mut *(b as *mut [u8] as *mut [UnitState]) }
}

/// Whether every byte of `b` is a [`UnitState`].
pub(super) fn valid_states(b: &[u8]) -> bool {
    bytemuck::checked::try_cast_slice::<u8, UnitState>(b).is_ok()
}

/// Cells along a unit's edge.
pub const UNIT_CELLS: i32 = 2;
/// Units along a grid block's edge.
pub const UNITS_PER_EDGE: usize = BLOCK_EDGE / UNIT_CELLS as usize;
/// Units per grid block.
pub const UNITS: usize = UNITS_PER_EDGE.pow(3);
/// (max speed, max strain rate) of the particles of each unit of a block.
pub type UnitActivity = [[Real; 2]; UNITS];
/// Activity of a unit without particles: below every threshold, and told apart from material at
/// rest (an empty unit must never sleep: it would hold the nodes of empty space).
pub const EMPTY_UNIT: [Real; 2] = [-1.0, -1.0];

/// Index of unit `u` (unit lattice coordinates, wrapped and inside the table) in the unit
/// tables: its block's index times [`UNITS`] plus its place in the block, so a block's units
/// are contiguous and the tables are the block table's layout, refined.
#[inline]
pub fn unit_index(geom: &GridGeom, u: [i32; 3]) -> u32 {
    let per = UNITS_PER_EDGE as i32;
    let b = u.map(|c| c.div_euclid(per));
    let l = u.map(|c| c.rem_euclid(per) as u32);
    geom.block_index(b) * UNITS as u32 + (l[0] * per as u32 + l[1]) * per as u32 + l[2]
}

/// Unit lattice coordinates of the unit with table index `idx`.
#[inline]
pub(crate) fn unit_coords(geom: &GridGeom, idx: u32) -> [i32; 3] {
    let per = UNITS_PER_EDGE as i32;
    let b = geom.block_coords(idx / UNITS as u32);
    let k = (idx % UNITS as u32) as i32;
    [b[0] * per + k / (per * per), b[1] * per + (k / per) % per, b[2] * per + k % per]
}

/// Place (0..UNITS) within its block of the unit of stencil base `base`, clamped to block
/// `origin`'s units (a particle that left its block this step counts in the nearest unit).
#[inline]
pub fn unit_in_block(origin: [i32; 3], base: [i32; 3]) -> usize {
    let per = UNITS_PER_EDGE as i32;
    let l = std::array::from_fn::<i32, 3, _>(|a| ((base[a] - origin[a]).div_euclid(UNIT_CELLS)).clamp(0, per - 1));
    ((l[0] * per + l[1]) * per + l[2]) as usize
}

/// Table index of the unit of a particle at grid position `xg` (by its stencil base).
#[inline]
pub fn unit_of_particle(geom: &GridGeom, xg: V3) -> u32 {
    unit_index(geom, particle_unit(xg))
}

/// Unit of a particle at grid position `xg` (by its stencil base).
#[inline]
pub(super) fn particle_unit(xg: V3) -> [i32; 3] {
    let (base, _) = crate::kernels::bspline::base_and_fx(xg);
    base.map(|b| b.div_euclid(UNIT_CELLS))
}

/// Wrap a unit coordinate on periodic axes.
#[inline]
pub(crate) fn wrap_unit(geom: &GridGeom, mut u: [i32; 3]) -> [i32; 3] {
    let per = UNITS_PER_EDGE as i32;
    for a in 0..3 {
        if geom.periodic[a] {
            u[a] = u[a].rem_euclid(geom.nb[a] * per);
        }
    }
    u
}

#[inline]
pub(crate) fn unit_in_table(geom: &GridGeom, u: [i32; 3]) -> bool {
    let per = UNITS_PER_EDGE as i32;
    (0..3).all(|a| u[a] >= 0 && u[a] < geom.nb[a] * per)
}

/// Unit holding world point `x`, shifted by `shift` units on every axis.
pub(super) fn unit_of_point(geom: &GridGeom, x: [f64; 3], shift: i32) -> [i32; 3] {
    let us = UNIT_CELLS as f64;
    std::array::from_fn(|a| ((x[a] - geom.origin[a]) / geom.dx / us).floor() as i32 + shift)
}

/// Whether block `b` lies inside the block table.
#[inline]
pub(super) fn block_in_table(geom: &GridGeom, b: [i32; 3]) -> bool {
    (0..3).all(|a| b[a] >= 0 && b[a] < geom.nb[a])
}

/// The offsets of the 26 neighbours of a lattice point (units here, cells in `coarsen.rs`).
pub(crate) fn offsets_26() -> impl Iterator<Item = [i32; 3]> + Clone {
    (0..27).filter(|&d| d != 13).map(|d| [d / 9 - 1, (d / 3) % 3 - 1, d % 3 - 1])
}

/// The 26 neighbours of unit `u` inside the table, each with its offset from `u`.
pub(super) fn neighbours(geom: &GridGeom, u: u32) -> impl Iterator<Item = ([i32; 3], u32)> + '_ {
    let c = unit_coords(geom, u);
    offsets_26().filter_map(move |off| {
        let n = wrap_unit(geom, [c[0] + off[0], c[1] + off[1], c[2] + off[2]]);
        unit_in_table(geom, n).then(|| (off, unit_index(geom, n)))
    })
}

/// Whether a neighbour at offset `off` lies on `side` (`(axis, sign)`; e.g. `(2, -1)`: one of
/// the nine below); never when there is no side.
pub(super) fn on_side(side: Option<(usize, i32)>, off: [i32; 3]) -> bool {
    side.is_some_and(|(a, sign)| off[a] == sign)
}
