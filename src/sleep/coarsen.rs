//! Coarsening sleeping material: the interior of a deposit at rest is carried by one particle
//! per cell instead of `particles_per_cell_axis`^3 (`[sleep] coarsen`, off by default).
//!
//! Why: per-step cost follows the awake particles (160-175 ns each, any layer; BENCHMARKS.md
//! "Dwells between layers"), and from the second layer on, the part of the layer below that the
//! nozzle's squeeze reaches must be awake for the section to come out right. It is about as large
//! as the active part of the layer being printed, so each layer after the first cost ~2x the
//! first. Carried by one particle per cell, that region costs a fraction of that.
//!
//! What is merged: when units fall asleep, the particles of each of their cells (a cell is a
//! particle's stencil base, so a merged particle stays in its unit) whose 26 neighbour cells all
//! hold material. Cells on the surface keep their particles, so the surface the observables see
//! (widths, heights, profiles: extents of the particle cloud with the emitted spacing) is drawn
//! at the emitted resolution; the cross-section area's B-spline window (one cell wide by
//! default) integrates rows one cell apart exactly, and merged rows are nearly that. A layer's
//! top cells become interior, and are merged, once the next layer covers them and they fall
//! asleep again.
//!
//! The merged particle keeps the mass, the initial volume and the current volume (so J) of its
//! cell's particles; it sits at their centre of mass; its internal state is their
//! volume-weighted mean (every material's state here is stresses, structure and accumulated
//! strains, which average to the homogenised value); it is put at rest like any sleeping particle
//! (`sleep::put_at_rest`), and keeps the smallest id of the group. Merging is not differentiable, as
//! sleeping is not (`strand grad` refuses `[sleep]`).

use crate::grid::GridGeom;
use crate::kernels::material::Material;
use crate::kernels::{Real, V3};
use crate::memory::{Backing, MemoryError, Pool};
use crate::pools::{Counts, Per, PoolDecl, Pools, Role};
use crate::particles::Particles;
use super::units::{offsets_26, unit_coords, unit_in_table, unit_index, wrap_unit, UNITS, UNIT_CELLS};

/// Scratch for merging, preallocated.
pub struct Coarsen {
    /// Units of the domain.
    units: usize,
    /// Per unit (sleep tables' layout), one bit per cell: whether a particle has its stencil
    /// base there.
    occupied: Pool<u8>,
    /// Sort keys (cell << 32 | particle index) of the particles just fallen asleep.
    keys: Pool<u64>,
}

/// Removed-particle mark, in `id`, between merging and compaction.
const GONE: u32 = u32::MAX;

impl Pools for Coarsen {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        vec![
            PoolDecl::new("coarsen.occupied", Per::Table(self.units), Role::Scratch, |c| &c.occupied, |c| &mut c.occupied),
            PoolDecl::new("coarsen.keys", Per::Particle(1), Role::Scratch, |c| &c.keys, |c| &mut c.keys),
        ]
    }
}

impl Coarsen {
    /// Scratch for `geom`'s domain, declared but not mapped ([`Pools::map_pools`] maps it).
    pub fn declared(geom: &GridGeom) -> Self {
        Coarsen { units: geom.table_len() * UNITS, occupied: Pool::default(), keys: Pool::default() }
    }

    /// Scratch for `geom`'s domain and `capacity` particles, mapped.
    pub fn new(geom: &GridGeom, capacity: usize, b: &Backing) -> Result<Self, MemoryError> {
        let mut c = Coarsen::declared(geom);
        c.map_pools(&Counts::capacity(capacity, 0), b)?;
        Ok(c)
    }

    /// Merge the particles of each interior cell among `from..p.n_sleep` (the particles that
    /// have just fallen asleep, settled) into one, and close the gaps (moving awake particles
    /// from the end of the pool into them). Returns how many particles went.
    pub fn merge_interior(&mut self, geom: &GridGeom, p: &mut Particles, from: usize, material: &dyn Material) -> usize {
        let to = p.n_sleep;
        if to - from < 2 {
            return 0;
        }
        let occupied = self.occupied.as_mut_slice();
        occupied.fill(0);
        for &x in &p.xg.as_slice()[..p.n] {
            if let Some((u, bit)) = cell_of(geom, stencil_base(x)) {
                occupied[u as usize] |= 1 << bit;
            }
        }
        let keys = &mut self.keys.as_mut_slice()[..to - from];
        for (k, i) in keys.iter_mut().zip(from..to) {
            let c = cell_of(geom, stencil_base(p.xg.as_slice()[i])).map_or(u32::MAX, |(u, bit)| u * 8 + bit);
            *k = (c as u64) << 32 | i as u64;
        }
        keys.sort_unstable();
        let mut removed = 0;
        let mut g = 0;
        while g < keys.len() {
            let cell = keys[g] >> 32;
            let end = g + keys[g..].iter().take_while(|&&k| k >> 32 == cell).count();
            if end - g >= 2 && cell != u32::MAX as u64 && interior(geom, occupied, cell as u32) {
                merge(p, keys[g..end].iter().map(|&k| k as u32 as usize), material);
                removed += end - g - 1;
            }
            g = end;
        }
        if removed > 0 {
            close_gaps(p, from, removed);
        }
        removed
    }
}

/// Stencil base of grid position `x` (the cell a particle belongs to).
#[inline]
fn stencil_base(x: V3) -> [i32; 3] {
    crate::kernels::bspline::base_and_fx(x).0
}

/// Unit table index and bit (0..8) of cell `c`, if it lies in the table.
#[inline]
fn cell_of(geom: &GridGeom, c: [i32; 3]) -> Option<(u32, u32)> {
    let u = wrap_unit(geom, c.map(|x| x.div_euclid(UNIT_CELLS)));
    if !unit_in_table(geom, u) {
        return None;
    }
    let l = c.map(|x| x.rem_euclid(UNIT_CELLS) as u32);
    Some((unit_index(geom, u), (l[0] * 2 + l[1]) * 2 + l[2]))
}

/// Whether all 26 neighbours of cell `key` (unit index * 8 + bit) hold material.
fn interior(geom: &GridGeom, occupied: &[u8], key: u32) -> bool {
    let (u, bit) = (key / 8, key % 8);
    let uc = unit_coords(geom, u);
    let c = [uc[0] * UNIT_CELLS + (bit >> 2) as i32, uc[1] * UNIT_CELLS + (bit >> 1 & 1) as i32, uc[2] * UNIT_CELLS + (bit & 1) as i32];
    offsets_26().all(|off| {
        let n = [c[0] + off[0], c[1] + off[1], c[2] + off[2]];
        cell_of(geom, n).is_some_and(|(nu, nb)| occupied[nu as usize] >> nb & 1 == 1)
    })
}

/// Merge the particles `group` (ascending indices) into the first; mark the rest [`GONE`].
fn merge(p: &mut Particles, group: impl Iterator<Item = usize> + Clone, material: &dyn Material) {
    let sl = p.state_len;
    let first = group.clone().next().expect("a group has particles");
    let (mut m, mut v0, mut vol) = (0.0f64, 0.0f64, 0.0f64);
    let mut mx = [0.0f64; 3];
    let mut id = u32::MAX;
    // summed apart, in f64: the first particle's own values are summands
    let mut state = [0.0f64; 32];
    assert!(sl <= state.len(), "a material state of {sl} values is longer than coarsening sums");
    for i in group.clone() {
        let (mi, v0i, ji) = (p.mass.as_slice()[i] as f64, p.vol0.as_slice()[i] as f64, p.j.as_slice()[i] as f64);
        let x = p.xg.as_slice()[i];
        m += mi;
        v0 += v0i;
        vol += v0i * ji;
        for a in 0..3 {
            mx[a] += mi * x[a] as f64;
        }
        for (s, &x) in state[..sl].iter_mut().zip(&p.state.as_slice()[i * sl..(i + 1) * sl]) {
            *s += v0i * ji * x as f64;
        }
        id = id.min(p.id.as_slice()[i]);
    }
    for i in group.skip(1) {
        p.id.as_mut_slice()[i] = GONE;
    }
    p.mass.as_mut_slice()[first] = m as Real;
    p.vol0.as_mut_slice()[first] = v0 as Real;
    p.j.as_mut_slice()[first] = (vol / v0) as Real;
    p.xg.as_mut_slice()[first] = V3::new((mx[0] / m) as Real, (mx[1] / m) as Real, (mx[2] / m) as Real);
    for (dst, s) in p.state.as_mut_slice()[first * sl..(first + 1) * sl].iter_mut().zip(&state[..sl]) {
        *dst = (s / vol) as Real;
    }
    p.id.as_mut_slice()[first] = id;
    super::at_rest::put_at_rest(p, first, material);
}

/// Squeeze the `removed` particles marked [`GONE`] out of `from..p.n_sleep` (keeping the order
/// of the rest), then fill the gap this leaves before the awake particles with the last awake
/// ones.
fn close_gaps(p: &mut Particles, from: usize, removed: usize) {
    let to = p.n_sleep;
    let mut kept = from;
    for i in from..to {
        if p.id.as_slice()[i] != GONE {
            p.swap(kept, i);
            kept += 1;
        }
    }
    debug_assert_eq!(to - kept, removed);
    let awake = p.n - to;
    for k in 0..removed.min(awake) {
        p.swap(kept + k, p.n - 1 - k);
    }
    p.n_sleep = kept;
    p.n -= removed;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geom() -> GridGeom {
        let nb = [4, 4, 4];
        GridGeom { dx: 0.01, origin: [0.0; 3], cells: nb.map(|n| n * 4), nb, periodic: [false; 3], lo: [0.0; 3], hi: [0.16; 3] }
    }

    fn bingham() -> Box<dyn Material> {
        let text = "kind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";
        crate::materials::build_material(&text.parse::<toml::Table>().unwrap()).unwrap()
    }

    /// A cube of `n`^3 cells from cell 2, `ppc`^3 particles each (every 7th a little heavier),
    /// all asleep, then `awake` particles at cell 12.
    fn cube(n: usize, ppc: usize, awake: usize) -> Particles {
        let backing = Backing::default();
        let cap = n * n * n * ppc * ppc * ppc + awake;
        let mut p = Particles::new(cap, 0, &backing).unwrap();
        let h = 1.0 / ppc as f64;
        for c in 0..n * ppc {
            for d in 0..n * ppc {
                for e in 0..n * ppc {
                    let x = [c, d, e].map(|k| (2.5 + (k as f64 + 0.5) * h) as Real);
                    let i = p.n;
                    let m = if i.is_multiple_of(7) { 1.5 } else { 1.0 };
                    p.push(V3::new(x[0], x[1], x[2]), V3::ZERO, m, m * 0.5).unwrap();
                    p.j.as_mut_slice()[i] = 1.0 + 0.01 * (i % 3) as Real;
                }
            }
        }
        p.n_sleep = p.n;
        for _ in 0..awake {
            p.push(V3::splat(12.0), V3::new(1.0, 0.0, 0.0), 1.0, 0.5).unwrap();
        }
        p
    }

    fn sums(p: &Particles, r: std::ops::Range<usize>) -> (f64, f64, [f64; 3]) {
        let (mut m, mut vol, mut mx) = (0.0, 0.0, [0.0; 3]);
        for i in r {
            let mi = p.mass.as_slice()[i] as f64;
            m += mi;
            vol += p.vol0.as_slice()[i] as f64 * p.j.as_slice()[i] as f64;
            for a in 0..3 {
                mx[a] += mi * p.xg.as_slice()[i][a] as f64;
            }
        }
        (m, vol, mx)
    }

    #[test]
    fn interior_cells_merge_to_one_particle_keeping_mass_volume_and_centre() {
        let g = geom();
        let mut p = cube(5, 2, 3);
        let before = sums(&p, 0..p.n_sleep);
        let (n0, asleep0) = (p.n, p.n_sleep);
        let mut c = Coarsen::new(&g, p.capacity(), &Backing::default()).unwrap();
        let material = bingham();
        let removed = c.merge_interior(&g, &mut p, 0, &*material);
        // the 3^3 interior cells of the 5^3 cube: 27 x (8 - 1)
        assert_eq!(removed, 27 * 7);
        assert_eq!((p.n, p.n_sleep), (n0 - removed, asleep0 - removed));
        let after = sums(&p, 0..p.n_sleep);
        assert!((after.0 - before.0).abs() < 1e-9 * before.0, "mass {before:?} {after:?}");
        assert!((after.1 - before.1).abs() < 1e-6 * before.1, "volume {before:?} {after:?}");
        for a in 0..3 {
            assert!((after.2[a] - before.2[a]).abs() < 1e-5 * before.2[a], "first moment {before:?} {after:?}");
        }
        // the awake particles follow the sleeping ones, untouched
        for i in p.n_sleep..p.n {
            assert_eq!(p.xg.as_slice()[i], V3::splat(12.0));
            assert_eq!(p.v.as_slice()[i], V3::new(1.0, 0.0, 0.0));
        }
        // ids stay unique; the heavy particles now are the merged ones and the surface's own
        let mut ids: Vec<u32> = p.id.as_slice()[..p.n].to_vec();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), p.n);
        let heavy = p.mass.as_slice()[..p.n_sleep].iter().filter(|&&m| m > 2.0).count();
        assert_eq!(heavy, 27);
        // merged again, nothing changes: the interior is one particle per cell already
        assert_eq!(c.merge_interior(&g, &mut p, 0, &*material), 0);
    }

    #[test]
    fn a_cube_too_thin_for_an_interior_is_left_alone() {
        let g = geom();
        let mut p = cube(2, 2, 0);
        let mut c = Coarsen::new(&g, p.capacity(), &Backing::default()).unwrap();
        let material = bingham();
        assert_eq!(c.merge_interior(&g, &mut p, 0, &*material), 0);
        assert_eq!(p.n, 64);
    }

    #[test]
    fn fewer_awake_particles_than_removed_ones_all_move_down() {
        let g = geom();
        let mut p = cube(3, 2, 2);
        let mut c = Coarsen::new(&g, p.capacity(), &Backing::default()).unwrap();
        let material = bingham();
        assert_eq!(c.merge_interior(&g, &mut p, 0, &*material), 7);
        assert_eq!((p.n, p.n_sleep), (216 + 2 - 7, 216 - 7));
        assert!(p.xg.as_slice()[p.n_sleep..p.n].iter().all(|&x| x == V3::splat(12.0)));
    }
}
