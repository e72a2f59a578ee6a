//! G2P over several particles at once: the body of [`crate::transfer::g2p_block`]'s AVX2 copy,
//! each particle's arithmetic in one lane of a 256-bit register (4 particles in f64, 8 in f32).
//!
//! Enters: one particle block's `order`, its neighbourhood nodes, the particle state. Leaves the
//! same outputs as the one-particle body ([`crate::transfer::g2p_particle`]), bit for bit: every
//! lane performs that body's IEEE operations in the same order (no FMA, each sum in the same
//! order), and the J-bar cell sums are added particle by particle in `order`. A group any of
//! whose stencils leaves the block, or whose coordinates are not finite and small, runs through
//! the one-particle body instead, so such input behaves exactly as there.
//!
//! Staging: a group's positions, velocities and J are loaded lane by lane; a stencil node's three
//! channels for the group are loaded 128 bits per particle and transposed into one register per
//! channel.

use crate::real::{r, Real, M3, V3};
use crate::transfer::{g2p_particle, jbar_cell, jbar_cell_of_base, local_index, G2pOutput, JBarCells, Node, NodeLanes, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};
use std::array::from_fn;
use crate::wide::{R, W};

/// Lanes whose stencil coordinate `xg - 0.5` reaches this many cells run through the
/// one-particle body: below it, a lane's `floor` and its conversion to an integer are exact and
/// equal [`crate::bspline::floor_i32`] (f32 holds every integer up to 2^24).
const SMALL: Real = 4_194_304.0; // 2^22

/// The three components of a vector of each lane's particle.
///
/// # Safety
/// The CPU has AVX2 (as for every function below: compiled for it, so that the intrinsics and
/// the closures inline).
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn lanes_of(p: &[usize; W], of: &[V3]) -> [R; 3] {
    let mut a = [[r(0.0); W]; 3];
    for l in 0..W {
        let x = of[p[l]];
        (a[0][l], a[1][l], a[2][l]) = (x.x, x.y, x.z);
    }
    [R::from_array(a[0]), R::from_array(a[1]), R::from_array(a[2])]
}

/// Each lane's stencil base, where every lane's coordinate is small (see [`SMALL`]).
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn bases(xg: &[R; 3]) -> Option<[[i32; 3]; W]> {
    let half = R::splat(r(0.5));
    let s = [xg[0] - half, xg[1] - half, xg[2] - half];
    if !(s[0].all_abs_below(SMALL) && s[1].all_abs_below(SMALL) && s[2].all_abs_below(SMALL)) {
        return None;
    }
    let b = [s[0].floor().to_i32(), s[1].floor().to_i32(), s[2].floor().to_i32()];
    let mut base = [[0; 3]; W];
    for l in 0..W {
        base[l] = [b[0][l], b[1][l], b[2][l]];
    }
    Some(base)
}

/// Each lane's first stencil node in the neighbourhood of the block whose first node is
/// `origin`, if every lane's stencil lies in that block (and every coordinate is small).
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn stencil_starts(origin: [i32; 3], xg: &[R; 3]) -> Option<[usize; W]> {
    let b = bases(xg)?;
    // a base below the block wraps to a large offset, which lies outside it too
    starts_in_block(from_fn(|l| from_fn(|a| b[l][a].wrapping_sub(origin[a]) as usize)))
}

/// Each lane's first stencil node in its block's neighbourhood, from the lanes' stencil bases
/// relative to the block's first node, if every lane's stencil lies in the block.
#[inline(always)]
pub(crate) fn starts_in_block(base: [[usize; 3]; W]) -> Option<[usize; W]> {
    let inside = base.iter().all(|b| b.iter().all(|&k| k < BLOCK_EDGE));
    inside.then(|| from_fn(|l| local_index(base[l][0], base[l][1], base[l][2])))
}

/// [`crate::bspline::base_and_fx`]'s `fx` and [`crate::bspline::weights`] lane by lane, where
/// [`stencil_starts`] holds: `w[k][d]` for node offset `k`, axis `d` (explicit loops, no
/// closures: every register operation stays inline in the AVX2 callers).
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn fx_and_weights(xg: &[R; 3]) -> ([R; 3], [[R; 3]; 3]) {
    let (one, half) = (R::splat(r(1.0)), R::splat(r(0.5)));
    let (mut fx, mut w) = ([one; 3], [[one; 3]; 3]);
    for d in 0..3 {
        fx[d] = xg[d] - (xg[d] - half).floor();
        let a = R::splat(r(1.5)) - fx[d];
        w[0][d] = a * a * half;
        let b = fx[d] - one;
        w[1][d] = R::splat(r(0.75)) - b * b;
        let c = fx[d] - half;
        w[2][d] = c * c * half;
    }
    (fx, w)
}

/// Real values per node, the stride of a node's channels in memory.
pub(crate) const CHANNELS: usize = std::mem::size_of::<Node>() / std::mem::size_of::<Real>();

/// Channels `CH..CH + 3` of the node `offset` past each lane's first stencil node `node0[l]`,
/// one register per channel.
///
/// # Safety
/// `node0[l] + offset < NEIGHBOURHOOD_NODES` for every lane, `CH` is 1 or 4 (`gather3` reads
/// channels `CH - 1 ..= CH + 2`); AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn node_channels<const CH: usize>(local: &[Node; NEIGHBOURHOOD_NODES], node0: &[usize; W], offset: usize) -> [R; 3] {
    let nodes = local.as_ptr().cast::<Real>();
    let mut p = [nodes; W];
    for l in 0..W {
        // SAFETY: the node lies in `local` (the caller's promise)
        p[l] = nodes.add((node0[l] + offset) * CHANNELS + CH);
    }
    R::gather3(p)
}

/// [`crate::transfer::gather_velocity`] of W particles: the velocity `v[ch]` and, with `B`, the
/// sums `m[k][ch] = sum w v_i e_k` of B's columns, from the channels `CH..CH + 3` of the stencils
/// whose first nodes are `node0`; `w[k][d]` are the weights.
///
/// # Safety
/// `node0[l] + local_index(2, 2, 2) < NEIGHBOURHOOD_NODES` for every lane; `CH` is 1 or 4; AVX2.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather<const CH: usize, const B: bool>(local: &[Node; NEIGHBOURHOOD_NODES], node0: &[usize; W], w: &[[R; 3]; 3]) -> ([R; 3], [[R; 3]; 3]) {
    let zero = R::splat(r(0.0));
    let mut v = [zero; 3];
    let mut m = [[zero; 3]; 3];
    for a in 0..3 {
        let (mut t0, mut tb, mut tc) = ([zero; 3], [zero; 3], [zero; 3]);
        for b in 0..3 {
            let row = local_index(a, b, 0);
            // node c of the row, times its weight; SAFETY: the stencil's nodes lie in `local`
            // (the caller's promise)
            let mut n = [[zero; 3]; 3];
            for (c, n) in n.iter_mut().enumerate() {
                let g = node_channels::<CH>(local, node0, row + c);
                for ch in 0..3 {
                    n[ch] = g[ch] * w[c][2];
                }
            }
            let [n0, n1, n2] = n;
            for ch in 0..3 {
                let s0 = n0[ch] + n1[ch] + n2[ch];
                t0[ch] = t0[ch] + s0 * w[b][1];
                if B {
                    tc[ch] = tc[ch] + (n2[ch] - n0[ch]) * w[b][1];
                    match b {
                        0 => tb[ch] = tb[ch] - s0 * w[0][1],
                        2 => tb[ch] = tb[ch] + s0 * w[2][1],
                        _ => {}
                    }
                }
            }
        }
        for ch in 0..3 {
            v[ch] = v[ch] + t0[ch] * w[a][0];
            if B {
                m[1][ch] = m[1][ch] + tb[ch] * w[a][0];
                m[2][ch] = m[2][ch] + tc[ch] * w[a][0];
                match a {
                    0 => m[0][ch] = m[0][ch] - t0[ch] * w[0][0],
                    2 => m[0][ch] = m[0][ch] + t0[ch] * w[2][0],
                    _ => {}
                }
            }
        }
    }
    (v, m)
}

/// [`crate::transfer::g2p_block`]'s body over W particles at a time; `L` is the register of the
/// one-particle body that the groups the lanes cannot take run through. `order` holds distinct
/// particles (as every particle block's does).
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn g2p_block_lanes<L: NodeLanes>(
    origin: [i32; 3],
    order: &[u32],
    local: &[Node; NEIGHBOURHOOD_NODES],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    out: &mut G2pOutput,
) -> Real {
    let dx = tp.dx;
    let inv_dx = r(1.0) / dx;
    let c_scale = r(4.0) * inv_dx * inv_dx;
    let splat = R::splat;
    let mut vmax2 = splat(r(0.0));
    let mut vmax2_one: Real = r(0.0);
    let mut cells = JBarCells::new();
    for group in order.chunks(W) {
        let n = group.len();
        // lanes past the group repeat its last particle, and are not written back
        let p: [usize; W] = from_fn(|l| group[l.min(n - 1)] as usize);
        let xg = lanes_of(&p, &*out.xg);
        let Some(node0) = stencil_starts(origin, &xg) else {
            for &pi in group {
                let pi = pi as usize;
                vmax2_one = vmax2_one.max(g2p_particle::<L>(pi, origin, local, flip, tp, out));
                if let Some(vol0) = j_bar {
                    cells.add(jbar_cell(origin, out.xg[pi]), vol0[pi], out.j[pi]);
                }
            }
            continue;
        };
        let (fx, w) = fx_and_weights(&xg);
        let one = splat(r(1.0));
        let centre = [fx[0] - one, fx[1] - one, fx[2] - one];
        // SAFETY: every stencil lies in the block, so in `local`
        let (mut v, m) = gather::<1, true>(local, &node0, &w);
        // C = B 4/dx^2, B's column k = dx (m_k - v (fx_k - 1))
        let mut cm = [[one; 3]; 3];
        for k in 0..3 {
            for ch in 0..3 {
                cm[k][ch] = (m[k][ch] - v[ch] * centre[k]) * splat(dx) * splat(c_scale);
            }
        }
        let mut xg_new = [one; 3];
        for ch in 0..3 {
            xg_new[ch] = xg[ch] + v[ch] * splat(tp.dt * inv_dx);
        }
        if flip > r(0.0) {
            // SAFETY: as above
            let v_old = gather::<4, false>(local, &node0, &w).0;
            let vp = lanes_of(&p, &*out.v);
            for ch in 0..3 {
                v[ch] = (vp[ch] + (v[ch] - v_old[ch])) * splat(flip) + v[ch] * splat(r(1.0) - flip);
            }
        }
        let mut j = [r(0.0); W];
        for l in 0..W {
            j[l] = out.j[p[l]];
        }
        let j = R::from_array(j) * (one + splat(tp.dt) * (cm[0][0] + cm[1][1] + cm[2][2]));
        vmax2 = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).max_or(vmax2);
        let mut cm_l = [[[r(0.0); W]; 3]; 3];
        let (mut xg_l, mut v_l) = ([[r(0.0); W]; 3], [[r(0.0); W]; 3]);
        for k in 0..3 {
            for ch in 0..3 {
                cm_l[k][ch] = cm[k][ch].to_array();
            }
            xg_l[k] = xg_new[k].to_array();
            v_l[k] = v[k].to_array();
        }
        let j = j.to_array();
        for l in 0..n {
            let pi = p[l];
            let col = |k: usize| V3::new(cm_l[k][0][l], cm_l[k][1][l], cm_l[k][2][l]);
            out.c[pi] = M3::from_cols(col(0), col(1), col(2));
            out.xg[pi] = V3::new(xg_l[0][l], xg_l[1][l], xg_l[2][l]);
            out.v[pi] = V3::new(v_l[0][l], v_l[1][l], v_l[2][l]);
            out.j[pi] = j[l];
        }
        if let Some(vol0) = j_bar {
            let b = bases(&xg_new);
            for (l, &pi) in p[..n].iter().enumerate() {
                let cell = match b {
                    Some(b) => jbar_cell_of_base(origin, b[l]),
                    None => jbar_cell(origin, out.xg[pi]),
                };
                cells.add(cell, vol0[pi], out.j[pi]);
            }
        }
    }
    if j_bar.is_some() {
        for group in order.chunks(W) {
            let n = group.len();
            let p: [usize; W] = from_fn(|l| group[l.min(n - 1)] as usize);
            let b = bases(&lanes_of(&p, &*out.xg));
            for (l, &pi) in p[..n].iter().enumerate() {
                let cell = match b {
                    Some(b) => jbar_cell_of_base(origin, b[l]),
                    None => jbar_cell(origin, out.xg[pi]),
                };
                if let Some(j) = cells.average(cell) {
                    out.j[pi] = j;
                }
            }
        }
    }
    vmax2.to_array().into_iter().fold(vmax2_one, Real::max).sqrt()
}
