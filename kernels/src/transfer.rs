//! The two particle-grid transfers of MLS-MPM (paper 000 eqs. 9-15), as pure kernels over one
//! particle block.
//!
//! The grid is cut into blocks of `BLOCK_EDGE^3` nodes. All particles whose stencil base node lies in the
//! same block (the "particle block") touch only nodes `origin + 0..BLOCK_EDGE+2` along each axis, a
//! `NEIGHBOURHOOD_EDGE^3` neighbourhood. P2G scatters into a private neighbourhood buffer that the caller later
//! adds to the grid, and G2P gathers from one, so the kernels never see the sparse grid, never
//! race, and run unchanged on any thread.

use crate::bspline::{base_and_fx, weights};
use crate::real::{r, Real, M3, V3, V3A};
use std::ops::{Add, AddAssign, Mul, Sub, SubAssign};

/// Nodes per block edge.
pub const BLOCK_EDGE: usize = 4;
/// Neighbourhood edge: a block plus the two extra nodes a quadratic stencil reaches.
pub const NEIGHBOURHOOD_EDGE: usize = BLOCK_EDGE + 2;
/// Nodes in a neighbourhood.
pub const NEIGHBOURHOOD_NODES: usize = NEIGHBOURHOOD_EDGE * NEIGHBOURHOOD_EDGE * NEIGHBOURHOOD_EDGE;

/// Nodes from a stencil's first node to its last, in a neighbourhood buffer.
pub(crate) const STENCIL_SPAN: usize = local_index(2, 2, 2) + 1;

/// Index of local node (i, j, k) in a neighbourhood buffer.
#[inline(always)]
pub const fn local_index(i: usize, j: usize, k: usize) -> usize {
    (i * NEIGHBOURHOOD_EDGE + j) * NEIGHBOURHOOD_EDGE + k
}

/// Grid node accumulator: `[mass, momentum x, y, z, stress impulse x, y, z]`; after the grid
/// update, `[mass, new velocity x, y, z, old velocity x, y, z]`. The impulse is kept apart from the
/// momentum only when particles take FLIP increments (see [`g2p_block`]); otherwise it is folded
/// into the momentum and channels 4..7 stay unused.
pub type Node = [Real; 7];

/// The node registers of the copies of P2G and G2P (see [`NodeLanes`]), chosen by paired
/// measurement on the peer scene; every choice gives the same bits. f64: [`V3A`] in the baseline
/// copies, [`crate::cpu::AvxLanes`] in the AVX2 ones. f32: [`crate::cpu::SseLanes`] in P2G's
/// copies (its one add of a node's four channels: P2G x1.06), [`V3A`] in G2P's (`SseLanes`' one
/// unaligned load of a node measured no faster there than glam's three scalar ones, x0.98-1.01).
mod lanes {
    #[cfg(all(target_arch = "x86_64", feature = "f32"))]
    pub type P2gBaseline = crate::cpu::SseLanes;
    #[cfg(not(all(target_arch = "x86_64", feature = "f32")))]
    pub type P2gBaseline = crate::real::V3A;
    pub type G2pBaseline = crate::real::V3A;
    #[cfg(all(target_arch = "x86_64", feature = "f32"))]
    pub type P2gAvx2 = crate::cpu::SseLanes;
    #[cfg(all(target_arch = "x86_64", not(feature = "f32")))]
    pub type P2gAvx2 = crate::cpu::AvxLanes;
    #[cfg(all(target_arch = "x86_64", feature = "f32"))]
    pub type G2pAvx2 = crate::real::V3A;
    #[cfg(all(target_arch = "x86_64", not(feature = "f32")))]
    pub type G2pAvx2 = crate::cpu::AvxLanes;
}

/// Constants of one transfer.
#[derive(Clone, Copy, Debug)]
pub struct TransferParams {
    /// Grid spacing.
    pub dx: Real,
    /// Time step.
    pub dt: Real,
}

/// Particle data P2G reads, as parallel slices indexed through `order`.
pub struct P2gInput<'a> {
    /// Positions in grid coordinates (x / dx relative to the grid origin).
    pub xg: &'a [V3],
    pub v: &'a [V3],
    pub c: &'a [M3],
    pub stress: &'a [M3],
    pub mass: &'a [Real],
    /// Current volume V = J V0.
    pub vol0: &'a [Real],
    pub j: &'a [Real],
}

/// P2G for the particles `order[..]` of one particle block whose first node is `origin`.
///
/// Adds to `local` the APIC/MLS momentum `w (m v + m C (x_i - x_p))` and the stress impulse
/// `-w dt V 4/dx^2 sigma (x_i - x_p)` (paper 000 eqs. 10, 14), folded together unless `SPLIT`.
pub fn p2g_block<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local: &mut [Node; NEIGHBOURHOOD_NODES],
) {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { p2g_block_avx2::<SPLIT>(origin, order, p, tp, local) };
    }
    p2g_block_body::<SPLIT, lanes::P2gBaseline>(origin, order, p, tp, local)
}

/// [`p2g_block`] compiled for AVX2, several particles at once (see [`crate::p2g_lanes`] and
/// [`crate::cpu`]: the same IEEE operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn p2g_block_avx2<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local: &mut [Node; NEIGHBOURHOOD_NODES],
) {
    crate::p2g_lanes::p2g_block_lanes::<SPLIT, lanes::P2gAvx2>(origin, order, p, tp, local)
}

#[inline(always)]
fn p2g_block_body<const SPLIT: bool, L: NodeLanes>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local: &mut [Node; NEIGHBOURHOOD_NODES],
) {
    let stress_scale = p2g_stress_scale(tp);
    for &pi in order {
        p2g_particle::<SPLIT, L>(pi as usize, origin, p, tp, stress_scale, local);
    }
}

/// The factor `-dt 4/dx^2` of P2G's stress impulse, times a particle's stress and volume.
#[inline(always)]
pub(crate) fn p2g_stress_scale(tp: &TransferParams) -> Real {
    -tp.dt * r(4.0) / (tp.dx * tp.dx)
}

/// One particle's P2G (see [`p2g_block`]) into the neighbourhood of the block whose first node
/// is `origin`; `stress_scale` from [`p2g_stress_scale`]. `L` as in [`NodeLanes`].
#[inline(always)]
pub(crate) fn p2g_particle<const SPLIT: bool, L: NodeLanes>(
    pi: usize,
    origin: [i32; 3],
    p: &P2gInput,
    tp: &TransferParams,
    stress_scale: Real,
    local: &mut [Node; NEIGHBOURHOOD_NODES],
) {
    let dx = tp.dx;
    let (base, fx) = base_and_fx(p.xg[pi]);
    let w = weights(fx);
    let m = p.mass[pi];
    let vol = p.vol0[pi] * p.j[pi];
    let impulse = p.stress[pi] * (stress_scale * vol);
    let affine = if SPLIT { p.c[pi] * m } else { p.c[pi] * m + impulse };
    // A node's momentum is affine in its offset e = (a, b, c) - 1 from the stencil centre:
    // mv + affine (e - (fx - 1)) dx. Building it axis by axis costs three additions per node
    // instead of a matrix-vector product.
    let centre = (fx - V3::ONE) * dx;
    let (ax, ay, az) = (L::slope(affine.x_axis * dx), L::slope(affine.y_axis * dx), L::slope(affine.z_axis * dx));
    let q0 = L::mass_momentum(m, p.v[pi] * m - affine * centre);
    let (ix, iy, iz) = (impulse.x_axis * dx, impulse.y_axis * dx, impulse.z_axis * dx);
    let i0 = if SPLIT { -(impulse * centre) } else { V3::ZERO };
    let (oi, oj, ok) = (
        (base[0] - origin[0]) as usize,
        (base[1] - origin[1]) as usize,
        (base[2] - origin[2]) as usize,
    );
    p2g_scatter::<SPLIT, L>(local, local_index(oi, oj, ok), &w, m, q0, [ax, ay, az], i0, [ix, iy, iz]);
}

/// Adds one particle's mass, momentum and (with SPLIT) impulse to its 27 stencil nodes, the first
/// of which is local node `node0`: the weights `w`, the mass `m`, the momentum `q0` at the
/// stencil centre and its slopes `q[k]` along axis k (per unit offset), the same for the impulse.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn p2g_scatter<const SPLIT: bool, L: NodeLanes>(
    local: &mut [Node; NEIGHBOURHOOD_NODES],
    node0: usize,
    w: &[V3; 3],
    m: Real,
    q0: L,
    q: [L; 3],
    i0: V3,
    i: [V3; 3],
) {
    let ([ax, ay, az], [ix, iy, iz]) = (q, i);
    // the stencil's span as an array: every node index below is a constant once the planes are
    // unrolled, so none is checked at run time (the one check is this conversion)
    let stencil: &mut [Node; STENCIL_SPAN] = (&mut local[node0..node0 + STENCIL_SPAN]).try_into().unwrap();
    // a-planes unrolled by hand: the offsets e become constants (no conversion per plane)
    let plane = p2g_scatter_plane::<SPLIT, L>;
    plane(stencil, 0, w, m, q0 + ax * r(-1.0), [ay, az], i0 + ix * r(-1.0), [iy, iz]);
    plane(stencil, 1, w, m, q0 + ax * r(0.0), [ay, az], i0 + ix * r(0.0), [iy, iz]);
    plane(stencil, 2, w, m, q0 + ax * r(1.0), [ay, az], i0 + ix * r(1.0), [iy, iz]);
}

/// [`p2g_scatter`]'s nodes of the stencil's `a`-plane, whose momentum and impulse at offset
/// `(b, c) = 1` are `qa` and `ia`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn p2g_scatter_plane<const SPLIT: bool, L: NodeLanes>(stencil: &mut [Node; STENCIL_SPAN], a: usize, w: &[V3; 3], m: Real, qa: L, [ay, az]: [L; 2], ia: V3, [iy, iz]: [V3; 2]) {
    for b in 0..3 {
        let eb = b as Real - r(1.0);
        let wab = w[a].x * w[b].y;
        let (qab, iab) = (qa + ay * eb, ia + iy * eb);
        let row = local_index(a, b, 0);
        for c in 0..3 {
            let ec = c as Real - r(1.0);
            let weight = wab * w[c].z;
            let node = &mut stencil[row + c];
            (qab + az * ec).scatter(node, weight, m);
            if SPLIT {
                let imp = (iab + iz * ec) * weight;
                node[4] += imp.x;
                node[5] += imp.y;
                node[6] += imp.z;
            }
        }
    }
}

/// The register P2G builds a node's mass and momentum in and G2P's gather sums a node's three
/// velocity channels in. Each implementation performs, lane by lane, the IEEE operations of
/// [`V3`] in the same order (padding lanes are dropped), so the results have the same bits
/// whichever runs.
pub trait NodeLanes: Copy + Add<Output = Self> + Sub<Output = Self> + AddAssign + SubAssign + Mul<Real, Output = Self> {
    fn zero() -> Self;
    /// Channels `CH..CH + 3` of a node.
    fn node<const CH: usize>(n: &Node) -> Self;
    /// The three vector lanes.
    fn v3(self) -> V3;
    /// P2G's momentum `q` of a particle of mass `m`; a four-lane register carries `m` in lane 0.
    fn mass_momentum(m: Real, q: V3) -> Self;
    /// A slope of the momentum along one axis (lane 0, if any, zero: `m + 0 e` stays `m`).
    fn slope(col: V3) -> Self;
    /// Adds `weight m` and `weight q` to channels 0 and 1..4 of `node`, `self` being `q` as
    /// built from [`NodeLanes::mass_momentum`] and slopes.
    fn scatter(self, node: &mut Node, weight: Real, m: Real);
}

// `V3 -> V3A` is the identity in f64 and Vec3 -> Vec3A in f32
#[allow(clippy::useless_conversion)]
impl NodeLanes for V3A {
    #[inline(always)]
    fn zero() -> Self {
        V3A::ZERO
    }
    #[inline(always)]
    fn node<const CH: usize>(n: &Node) -> Self {
        V3A::new(n[CH], n[CH + 1], n[CH + 2])
    }
    #[inline(always)]
    fn v3(self) -> V3 {
        V3::from(self)
    }
    #[inline(always)]
    fn mass_momentum(_: Real, q: V3) -> Self {
        q.into()
    }
    #[inline(always)]
    fn slope(col: V3) -> Self {
        col.into()
    }
    #[inline(always)]
    fn scatter(self, node: &mut Node, weight: Real, m: Real) {
        let mom = self * weight;
        node[0] += weight * m;
        node[1] += mom.x;
        node[2] += mom.y;
        node[3] += mom.z;
    }
}

/// The velocity `v = sum w v_i` and `B = sum w v_i (x_i - x_p)^T` a particle gathers from the
/// node velocities in channels `CH..CH + 3` of its stencil, whose base is local node `o`.
///
/// B is separable: with node offsets `e = (a, b, c) - 1` from the stencil centre, its column k is
/// `dx (sum w v_i e_k - v (fx_k - 1))`, and the inner sums build up axis by axis (three
/// multiply-adds per node instead of twelve). Centred offsets keep the cancellation against
/// `v (fx_k - 1)` small. The adjoint recomputes through this same function, bit for bit.
/// `L` is the register the sums run in (see [`NodeLanes`]); every choice gives the same bits.
#[inline(always)]
pub fn gather_velocity<const CH: usize, L: NodeLanes>(local: &[Node; NEIGHBOURHOOD_NODES], o: [usize; 3], fx: V3, w: &[V3; 3], dx: Real) -> (V3, M3) {
    let mut v = L::zero();
    let mut mx = L::zero();
    let mut my = L::zero();
    let mut mz = L::zero();
    for a in 0..3 {
        // sums over b and c of this a-plane: plain, times e_b, times e_c
        let (mut t0, mut tb, mut tc) = (L::zero(), L::zero(), L::zero());
        for b in 0..3 {
            let row = local_index(o[0] + a, o[1] + b, o[2]);
            let node = |c: usize| L::node::<CH>(&local[row + c]) * w[c].z;
            let (n0, n1, n2) = (node(0), node(1), node(2));
            let s0 = n0 + n1 + n2;
            let s1 = n2 - n0;
            t0 += s0 * w[b].y;
            tc += s1 * w[b].y;
            match b {
                0 => tb -= s0 * w[0].y,
                2 => tb += s0 * w[2].y,
                _ => {}
            }
        }
        v += t0 * w[a].x;
        my += tb * w[a].x;
        mz += tc * w[a].x;
        match a {
            0 => mx -= t0 * w[0].x,
            2 => mx += t0 * w[2].x,
            _ => {}
        }
    }
    let (v, mx, my, mz) = (v.v3(), mx.v3(), my.v3(), mz.v3());
    let centre = fx - V3::ONE;
    let bmat = M3::from_cols(mx - v * centre.x, my - v * centre.y, mz - v * centre.z) * dx;
    (v, bmat)
}

/// Particle data G2P writes.
pub struct G2pOutput<'a> {
    pub xg: &'a mut [V3],
    pub v: &'a mut [V3],
    pub c: &'a mut [M3],
    pub j: &'a mut [Real],
}

/// G2P for the particles `order[..]` of one particle block: velocity, MLS velocity gradient
/// `C = 4/dx^2 sum w v_i (x_i - x_p)^T`, position `x += dt v` (eq. 16) and volume ratio
/// `J *= 1 + dt tr C` (eq. 17).
///
/// With `j_bar = Some(vol0)`, J is then replaced by its V0-weighted average over the particles of
/// this block that share a cell (their stencil base after the move) — the cell-averaged
/// volumetric strain of F-bar/B-bar methods, which keeps a particle-wise constraint on J from
/// locking nearly isochoric (plastic) flow. The average conserves sum(V0 J) per cell and only
/// mixes particles of one cell, so it does not bias J near free surfaces and walls.
/// `local` holds the block neighbourhood's nodes after the grid update.
///
/// With `flip = 0` the particle takes the grid velocity (APIC). With `flip = alpha > 0` it keeps
/// a share alpha of its own velocity plus the grid's increment (FLIP): the per-step resampling of
/// APIC, not exact where a wall cuts the stencil, then no longer acts as a drag that grows with
/// the number of steps (see DESIGN.md), and steady states stop depending on dt.
/// Returns the largest particle speed seen (for the time-step control).
pub fn g2p_block(
    origin: [i32; 3],
    order: &[u32],
    local: &[Node; NEIGHBOURHOOD_NODES],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    out: &mut G2pOutput,
) -> Real {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { g2p_block_avx2(origin, order, local, flip, j_bar, tp, out) };
    }
    g2p_block_body::<lanes::G2pBaseline>(origin, order, local, flip, j_bar, tp, out)
}

/// [`g2p_block`] compiled for AVX2, several particles at once (see [`crate::transfer_lanes`] and
/// [`crate::cpu`]: the same IEEE operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn g2p_block_avx2(
    origin: [i32; 3],
    order: &[u32],
    local: &[Node; NEIGHBOURHOOD_NODES],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    out: &mut G2pOutput,
) -> Real {
    crate::transfer_lanes::g2p_block_lanes::<lanes::G2pAvx2>(origin, order, local, flip, j_bar, tp, out)
}

#[inline(always)]
fn g2p_block_body<L: NodeLanes>(
    origin: [i32; 3],
    order: &[u32],
    local: &[Node; NEIGHBOURHOOD_NODES],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    out: &mut G2pOutput,
) -> Real {
    let mut vmax2: Real = r(0.0);
    let mut cells = JBarCells::new();
    for &pi in order {
        let pi = pi as usize;
        vmax2 = vmax2.max(g2p_particle::<L>(pi, origin, local, flip, tp, out));
        if let Some(vol0) = j_bar {
            cells.add(jbar_cell(origin, out.xg[pi]), vol0[pi], out.j[pi]);
        }
    }
    if j_bar.is_some() {
        for &pi in order {
            if let Some(j) = cells.average(jbar_cell(origin, out.xg[pi as usize])) {
                out.j[pi as usize] = j;
            }
        }
    }
    vmax2.sqrt()
}

/// One particle's G2P up to the J-bar average (see [`g2p_block`]): writes its C, position,
/// velocity and J, and returns its squared speed. `L` as in [`gather_velocity`].
#[inline(always)]
pub(crate) fn g2p_particle<L: NodeLanes>(pi: usize, origin: [i32; 3], local: &[Node; NEIGHBOURHOOD_NODES], flip: Real, tp: &TransferParams, out: &mut G2pOutput) -> Real {
    let dx = tp.dx;
    let inv_dx = r(1.0) / dx;
    let c_scale = r(4.0) * inv_dx * inv_dx;
    let (base, fx) = base_and_fx(out.xg[pi]);
    let w = weights(fx);
    let (oi, oj, ok) = (
        (base[0] - origin[0]) as usize,
        (base[1] - origin[1]) as usize,
        (base[2] - origin[2]) as usize,
    );
    let (v, bmat) = gather_velocity::<1, L>(local, [oi, oj, ok], fx, &w, dx);
    let dv = if flip > r(0.0) { v - gather_velocity::<4, L>(local, [oi, oj, ok], fx, &w, dx).0 } else { V3::ZERO };
    let cm = bmat * c_scale;
    out.c[pi] = cm;
    out.xg[pi] += v * (tp.dt * inv_dx);
    let v = if flip > r(0.0) { (out.v[pi] + dv) * flip + v * (r(1.0) - flip) } else { v };
    out.v[pi] = v;
    out.j[pi] *= r(1.0) + tp.dt * (cm.x_axis.x + cm.y_axis.y + cm.z_axis.z);
    v.length_squared()
}

/// The J-bar cell of a block whose first node is `origin` that a particle at `xg` (after the
/// move) falls in: its stencil base's cell, `None` outside the block.
#[inline(always)]
pub(crate) fn jbar_cell(origin: [i32; 3], xg: V3) -> Option<usize> {
    let (b, _) = base_and_fx(xg);
    jbar_cell_of_base(origin, b)
}

/// [`jbar_cell`] from the stencil base.
#[inline(always)]
pub(crate) fn jbar_cell_of_base(origin: [i32; 3], b: [i32; 3]) -> Option<usize> {
    let l = [b[0] - origin[0], b[1] - origin[1], b[2] - origin[2]];
    let inside = l.iter().all(|&k| (0..BLOCK_EDGE as i32).contains(&k));
    inside.then(|| (l[0] as usize * BLOCK_EDGE + l[1] as usize) * BLOCK_EDGE + l[2] as usize)
}

/// J-bar's sums of V0 J and V0 per cell of one block, added in particle order.
pub(crate) struct JBarCells {
    vj: [Real; BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
    v: [Real; BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
}

impl JBarCells {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        JBarCells { vj: [r(0.0); BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE], v: [r(0.0); BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE] }
    }
    /// Adds a particle of volume `vol0` and ratio `j` to `cell` (nothing outside the block).
    #[inline(always)]
    pub(crate) fn add(&mut self, cell: Option<usize>, vol0: Real, j: Real) {
        if let Some(k) = cell {
            self.vj[k] += vol0 * j;
            self.v[k] += vol0;
        }
    }
    /// The cell's average J; `None` outside the block and for a cell holding only massless
    /// particles (a slab that just began to enter), whose particles keep their J.
    #[inline(always)]
    pub(crate) fn average(&self, cell: Option<usize>) -> Option<Real> {
        match cell {
            Some(k) if self.v[k] > r(0.0) => Some(self.vj[k] / self.v[k]),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_particle(xg: V3, v: V3, c: M3) -> ([Node; NEIGHBOURHOOD_NODES], [i32; 3]) {
        let (base, _) = base_and_fx(xg);
        let origin = [base[0] - 1, base[1] - 2, base[2]];
        let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
        let zero = [M3::ZERO];
        let input = P2gInput { xg: &[xg], v: &[v], c: &[c], stress: &zero, mass: &[2.0], vol0: &[0.1], j: &[0.9] };
        p2g_block::<false>(origin, &[0], &input, &TransferParams { dx: 0.5, dt: 1e-3 }, &mut local);
        (local, origin)
    }

    #[test]
    fn p2g_conserves_mass_and_momentum() {
        let v = V3::new(0.3, -1.0, 2.0);
        let (local, _) = one_particle(V3::new(5.3, 6.9, 7.5), v, M3::from_cols_array(&[0.1, 0.2, 0.3, -0.4, 0.5, 0.6, 0.7, 0.8, -0.9]));
        let m: Real = local.iter().map(|n| n[0]).sum();
        let p = local.iter().fold(V3::ZERO, |a, n| a + V3::new(n[1], n[2], n[3]));
        assert!((m - 2.0).abs() < 1e-5);
        // the affine term has zero first moment, so total momentum is m v
        assert!((p - v * 2.0).abs().max_element() < 1e-5, "{p:?}");
    }

    #[test]
    fn affine_field_round_trips_through_p2g_g2p() {
        // A linear velocity field is reproduced exactly by APIC: P2G a particle carrying (v, C),
        // divide by mass, G2P at the same point: v and C come back.
        let xg = V3::new(5.3, 6.9, 7.5);
        let v = V3::new(0.3, -1.0, 2.0);
        let c = M3::from_cols_array(&[0.1, 0.2, 0.3, -0.4, 0.5, 0.6, 0.7, 0.8, -0.9]);
        let (local, origin) = one_particle(xg, v, c);
        let mut grid = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
        for (g, n) in grid.iter_mut().zip(local.iter()) {
            if n[0] > 0.0 {
                *g = [n[0], n[1] / n[0], n[2] / n[0], n[3] / n[0], 0.0, 0.0, 0.0];
            }
        }
        let (mut x, mut vv, mut cc, mut j) = ([xg], [V3::ZERO], [M3::ZERO], [0.9 as Real]);
        let mut out = G2pOutput { xg: &mut x, v: &mut vv, c: &mut cc, j: &mut j };
        g2p_block(origin, &[0], &grid, 0.0, Some(&[0.1]), &TransferParams { dx: 0.5, dt: 0.0 }, &mut out);
        assert_eq!(j[0], 0.9, "dt = 0 leaves J alone");
        assert!((vv[0] - v).abs().max_element() < 1e-5, "{:?}", vv[0]);
        assert!((cc[0] - c).abs_diff_eq(M3::ZERO, 1e-4), "{:?}", cc[0]);
    }

    #[cfg(target_arch = "x86_64")]
    type Block = (Vec<V3>, Vec<V3>, Vec<M3>, Vec<M3>, Vec<Real>);
    /// A block of particles with scattered positions, velocities, affine fields and stresses.
    #[cfg(target_arch = "x86_64")]
    fn scattered_block(n: usize) -> Block {
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut u = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut v3 = |lo: f64, span: f64| V3::new(r(lo + span * u()), r(lo + span * u()), r(lo + span * u()));
        let xg: Vec<V3> = (0..n).map(|_| v3(8.5, 3.99)).collect(); // stencil bases 8..12: block origin 8
        let v = (0..n).map(|_| v3(-1.0, 2.0)).collect();
        let mut m3 = || M3::from_cols(v3(-5.0, 10.0), v3(-5.0, 10.0), v3(-5.0, 10.0));
        let c = (0..n).map(|_| m3()).collect();
        let stress = (0..n).map(|_| m3() * r(100.0)).collect();
        let mass = (0..n).map(|k| r(1e-3 * (1.0 + (k % 7) as f64))).collect();
        (xg, v, c, stress, mass)
    }

    /// Nodes whose channels are scattered in [-1, 1), the mass channel's shifted by `mass_shift`.
    #[cfg(target_arch = "x86_64")]
    fn scattered_nodes(mut seed: u64, mass_shift: Real) -> [Node; NEIGHBOURHOOD_NODES] {
        let mut u = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            r((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
        };
        let mut nodes = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
        for n in nodes.iter_mut() {
            *n = [mass_shift + u(), u(), u(), u(), u(), u(), u()];
        }
        nodes
    }

    /// The variants of P2G and G2P the tests compare: the reference register [`V3A`], the baseline
    /// copies' register, the AVX2 copies.
    #[cfg(target_arch = "x86_64")]
    #[derive(Clone, Copy, Debug)]
    enum Variant {
        Reference,
        Baseline,
        Avx2,
    }

    #[cfg(target_arch = "x86_64")]
    fn p2g_copy<const SPLIT: bool>(copy: Variant, p: &P2gInput, order: &[u32], local: &mut [Node; NEIGHBOURHOOD_NODES]) {
        let tp = TransferParams { dx: r(2.5e-3), dt: r(2.5e-5) };
        match copy {
            Variant::Reference => p2g_block_body::<SPLIT, V3A>([8; 3], order, p, &tp, local),
            Variant::Baseline => p2g_block_body::<SPLIT, lanes::P2gBaseline>([8; 3], order, p, &tp, local),
            // SAFETY: only called where the CPU has AVX2
            Variant::Avx2 => unsafe { p2g_block_avx2::<SPLIT>([8; 3], order, p, &tp, local) },
        }
    }

    /// The AVX2 copy of G2P takes several particles at once: groups cut short at the end of the
    /// block, a group holding a particle whose stencil leaves the block (that group runs one
    /// particle at a time), particles moving out of their J-bar cell or out of the block, with
    /// and without FLIP and J-bar, all give the one-particle body's bits.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn g2p_lanes_give_the_one_particle_bits() {
        if !crate::cpu::has_avx2() {
            return;
        }
        let grid = scattered_nodes(0x9e37_79b9_7f4a_7c15, r(1.0));
        let (mut xg, v, c, _, _) = scattered_block(37);
        xg[5] = V3::new(r(9.0), r(9.0), r(12.7)); // stencil base (8, 8, 12): past the block along z
        let vol0: Vec<Real> = (0..37).map(|k| r(1e-6 * (k % 5) as f64)).collect(); // some massless
        let j = vec![r(0.97); 37];
        // a step of up to half a cell: particles change cells and leave the block
        let tp = TransferParams { dx: r(2.5e-3), dt: r(1.25e-3) };
        for n in [1usize, 3, 8, 9, 37] {
            // all 37 in a scrambled order, or a run of n from particle 10
            let order: Vec<u32> = if n == 37 { (0..37).map(|k| (k * 7) % 37).collect() } else { (10..10 + n as u32).collect() };
            for (flip, jbar) in [(r(0.0), None), (r(0.0), Some(&vol0[..])), (r(0.95), None), (r(0.95), Some(&vol0[..]))] {
                let run = |lanes: bool| {
                    let (mut x, mut vv, mut cc, mut jj) = (xg.clone(), v.clone(), c.clone(), j.clone());
                    let mut out = G2pOutput { xg: &mut x, v: &mut vv, c: &mut cc, j: &mut jj };
                    let vmax = if lanes {
                        // SAFETY: the CPU has AVX2
                        unsafe { g2p_block_avx2([8; 3], &order, &grid, flip, jbar, &tp, &mut out) }
                    } else {
                        g2p_block_body::<V3A>([8; 3], &order, &grid, flip, jbar, &tp, &mut out)
                    };
                    let mut all: Vec<Real> = vec![vmax];
                    all.extend(x.iter().chain(&vv).flat_map(|a| a.to_array()));
                    all.extend(cc.iter().flat_map(|m| m.to_cols_array()));
                    all.extend(jj);
                    all.iter().map(|a| a.to_bits()).collect::<Vec<_>>()
                };
                assert!(run(true) == run(false), "{n} particles, flip {flip}, J-bar {}", jbar.is_some());
            }
        }
    }

    /// The AVX2 copy of P2G takes several particles at once: groups cut short at the end of the
    /// block, groups holding a particle whose stencil leaves the block (those run one particle at
    /// a time), particles on a cell's edge, scrambled orders that revisit nodes from several
    /// lanes, into nodes already holding sums, folded and SPLIT, all give the one-particle
    /// body's bits.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn p2g_lanes_give_the_one_particle_bits() {
        if !crate::cpu::has_avx2() {
            return;
        }
        let start = scattered_nodes(0x6a09_e667_f3bc_c909, r(0.0));
        let (mut xg, v, c, stress, mass) = scattered_block(41);
        xg[5] = V3::new(r(9.0), r(9.0), r(12.7)); // stencil base (8, 8, 12): past the block along z
        xg[20] = V3::new(r(9.0), r(12.6), r(9.0)); // base y 12: past the block along y
        xg[12] = V3::new(r(8.5), r(11.5), r(12.0)); // on cell edges: bases 8 and 11 exactly
        xg[13] = V3::new(r(12.5) - r(12.5) * Real::EPSILON, r(9.5), r(10.25)); // just inside at x
        let vol0: Vec<Real> = (0..41).map(|k| r(2e-6 * (k % 5) as f64)).collect(); // some volumeless
        let j: Vec<Real> = (0..41).map(|k| r(0.95) + r(0.01) * (k % 7) as Real).collect();
        let tp = TransferParams { dx: r(2.5e-3), dt: r(2.5e-5) };
        let input = P2gInput { xg: &xg, v: &v, c: &c, stress: &stress, mass: &mass, vol0: &vol0, j: &j };
        let bits = |nodes: &[Node]| nodes.iter().flat_map(|n| n.map(|x| x.to_bits())).collect::<Vec<_>>();
        for n in [1usize, 3, 4, 8, 9, 17, 41] {
            // all 41 in a scrambled order, or a run of n from particle 2 (which holds 5, 12, 13)
            let order: Vec<u32> = if n == 41 { (0..41).map(|k| (k * 11) % 41).collect() } else { (2..2 + n as u32).collect() };
            for split in [false, true] {
                let run = |lanes: bool| {
                    let mut local = start;
                    match (lanes, split) {
                        // SAFETY: the CPU has AVX2
                        (true, false) => unsafe { p2g_block_avx2::<false>([8; 3], &order, &input, &tp, &mut local) },
                        (true, true) => unsafe { p2g_block_avx2::<true>([8; 3], &order, &input, &tp, &mut local) },
                        (false, false) => p2g_block_body::<false, V3A>([8; 3], &order, &input, &tp, &mut local),
                        (false, true) => p2g_block_body::<true, V3A>([8; 3], &order, &input, &tp, &mut local),
                    }
                    bits(&local)
                };
                let reference = run(false);
                assert!(reference != bits(&start), "{n} particles add something");
                assert!(run(true) == reference, "{n} particles, SPLIT {split}");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_copies_give_the_baseline_bits() {
        let copies: &[Variant] = if crate::cpu::has_avx2() { &[Variant::Reference, Variant::Baseline, Variant::Avx2] } else { &[Variant::Reference, Variant::Baseline] };
        let bits = |nodes: &[Node]| nodes.iter().flat_map(|n| n.map(|x| x.to_bits())).collect::<Vec<_>>();
        let (xg, v, c, stress, mass) = scattered_block(300);
        let (vol0, j) = (vec![r(2e-6); 300], vec![r(0.97); 300]);
        let order: Vec<u32> = (0..300u32).rev().collect();
        let tp = TransferParams { dx: r(2.5e-3), dt: r(2.5e-5) };
        let input = P2gInput { xg: &xg, v: &v, c: &c, stress: &stress, mass: &mass, vol0: &vol0, j: &j };
        let p2g = |copy: Variant| {
            let mut local = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
            p2g_copy::<true>(copy, &input, &order, &mut local);
            let split = bits(&local);
            p2g_copy::<false>(copy, &input, &order, &mut local);
            (split, bits(&local), local)
        };
        let (split, folded, grid) = p2g(Variant::Reference);
        for &copy in &copies[1..] {
            let (s, f, _) = p2g(copy);
            assert!(s == split && f == folded, "P2G, {copy:?} copy");
        }
        for (flip, jbar) in [(r(0.0), None), (r(0.95), Some(&vol0[..]))] {
            let run = |copy: Variant| {
                let (mut x, mut vv, mut cc, mut jj) = (xg.clone(), v.clone(), c.clone(), j.clone());
                let mut out = G2pOutput { xg: &mut x, v: &mut vv, c: &mut cc, j: &mut jj };
                let vmax = match copy {
                    Variant::Reference => g2p_block_body::<V3A>([8; 3], &order, &grid, flip, jbar, &tp, &mut out),
                    Variant::Baseline => g2p_block_body::<lanes::G2pBaseline>([8; 3], &order, &grid, flip, jbar, &tp, &mut out),
                    // SAFETY: only called where the CPU has AVX2
                    Variant::Avx2 => unsafe { g2p_block_avx2([8; 3], &order, &grid, flip, jbar, &tp, &mut out) },
                };
                let mut all: Vec<Real> = vec![vmax];
                all.extend(x.iter().chain(&vv).flat_map(|a| a.to_array()));
                all.extend(cc.iter().flat_map(|m| m.to_cols_array()));
                all.extend(jj);
                all.iter().map(|a| a.to_bits()).collect::<Vec<_>>()
            };
            let reference = run(Variant::Reference);
            for &copy in &copies[1..] {
                assert!(run(copy) == reference, "G2P flip {flip}, {copy:?} copy");
            }
        }
    }
}
