//! P2G over several particles at once: the body of [`crate::transfer::p2g_block`]'s AVX2 copy,
//! each particle's arithmetic in one lane of a 256-bit register (4 particles in f64, 8 in f32;
//! the register is [`crate::transfer_lanes`]'s).
//!
//! Enters: one particle block's `order`, the particle state, the block's neighbourhood buffer.
//! Leaves the same node sums as the one-particle body ([`crate::transfer::p2g_particle`]), bit
//! for bit: every lane performs that body's IEEE operations in the same order (no FMA), and a
//! group's contributions are added to the nodes particle by particle in `order`, so every node
//! channel sums the same terms in the same order. A group any of whose stencils leaves the block,
//! or whose coordinates are not finite and small, runs through the one-particle body instead, so
//! such input behaves exactly as there.
//!
//! Staging: a group's weights, momenta and impulses for its 27 stencil nodes are built one node
//! at a time in registers (one lane a particle), transposed to each particle's channels 0..4
//! (mass and momentum; with SPLIT also channels 3..7, the impulse) and kept on the stack; each
//! particle's 27 nodes then take one vector add per channel run.

use crate::real::{r, Real, M3};
use crate::transfer::{local_index, p2g_particle, p2g_stress_scale, Node, NodeLanes, P2gInput, TransferParams, NEIGHBOURHOOD_NODES};
use crate::transfer_lanes::wide::{R, W};
use crate::transfer_lanes::{fx_and_weights, lanes_of, stencil_starts};
use std::array::from_fn;

/// Nodes in a quadratic stencil.
const STENCIL_NODES: usize = 27;

/// A group's staged node contributions: `[lane][stencil node]`, four channels each.
type Staged = [[[Real; 4]; STENCIL_NODES]; W];

/// A scalar of each lane's particle.
///
/// # Safety
/// The CPU has AVX2 (as for every function below: compiled for it, so that the intrinsics
/// inline).
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn scalar_lanes(p: &[usize; W], of: &[Real]) -> R {
    R::from_array(from_fn(|l| of[p[l]]))
}

/// The nine entries of a matrix of each lane's particle, `[column][row]`.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn matrix_lanes(p: &[usize; W], of: &[M3]) -> [[R; 3]; 3] {
    let mut a = [[[r(0.0); W]; 3]; 3];
    for l in 0..W {
        let m = of[p[l]];
        for (k, col) in [m.x_axis, m.y_axis, m.z_axis].into_iter().enumerate() {
            (a[k][0][l], a[k][1][l], a[k][2][l]) = (col.x, col.y, col.z);
        }
    }
    let mut m = [[R::splat(r(0.0)); 3]; 3];
    for k in 0..3 {
        for ch in 0..3 {
            m[k][ch] = R::from_array(a[k][ch]);
        }
    }
    m
}

/// [`crate::transfer::p2g_block`]'s body over W particles at a time; `L` is the register of the
/// one-particle body that the groups the lanes cannot take run through.
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn p2g_block_lanes<const SPLIT: bool, L: NodeLanes>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local: &mut [Node; NEIGHBOURHOOD_NODES],
) {
    let dx = tp.dx;
    let stress_scale = p2g_stress_scale(tp);
    let splat = R::splat;
    // node k of a stencil, in the one-particle body's order, from the stencil's first node
    let stencil: [usize; STENCIL_NODES] = from_fn(|k| local_index(k / 9, k / 3 % 3, k % 3));
    // channels 0..4 of each lane's nodes, and with SPLIT channels 3..7 (3 repeats the momentum's z)
    let mut lo: Staged = [[[r(0.0); 4]; STENCIL_NODES]; W];
    let mut hi: Staged = [[[r(0.0); 4]; STENCIL_NODES]; W];
    for group in order.chunks(W) {
        let n = group.len();
        // lanes past the group repeat its last particle, and are not added to the nodes
        let pi: [usize; W] = from_fn(|l| group[l.min(n - 1)] as usize);
        let xg = lanes_of(&pi, p.xg);
        let Some(node0) = stencil_starts(origin, &xg) else {
            for &q in group {
                p2g_particle::<SPLIT, L>(q as usize, origin, p, tp, stress_scale, local);
            }
            continue;
        };
        // p2g_particle's arithmetic up to its node loop, lane by lane (explicit loops, no
        // closures: every register operation stays inline in this AVX2 function)
        let (fx, w) = fx_and_weights(&xg);
        let m = scalar_lanes(&pi, p.mass);
        let vol = scalar_lanes(&pi, p.vol0) * scalar_lanes(&pi, p.j);
        let s = splat(stress_scale) * vol;
        let v = lanes_of(&pi, p.v);
        let c = matrix_lanes(&pi, p.c);
        let mut impulse = matrix_lanes(&pi, p.stress);
        let mut affine = c;
        for k in 0..3 {
            for ch in 0..3 {
                impulse[k][ch] = impulse[k][ch] * s;
                affine[k][ch] = if SPLIT { c[k][ch] * m } else { c[k][ch] * m + impulse[k][ch] };
            }
        }
        let one = splat(r(1.0));
        let centre = [(fx[0] - one) * splat(dx), (fx[1] - one) * splat(dx), (fx[2] - one) * splat(dx)];
        // the slopes of momentum and impulse along axis k: `[k][ch]`
        let (mut qk, mut ik) = ([[one; 3]; 3], [[one; 3]; 3]);
        for k in 0..3 {
            for ch in 0..3 {
                qk[k][ch] = affine[k][ch] * splat(dx);
                ik[k][ch] = impulse[k][ch] * splat(dx);
            }
        }
        let (mut q0, mut i0) = ([one; 3], [one; 3]);
        for ch in 0..3 {
            let ac = affine[0][ch] * centre[0] + affine[1][ch] * centre[1] + affine[2][ch] * centre[2];
            q0[ch] = v[ch] * m - ac;
            if SPLIT {
                let ic = impulse[0][ch] * centre[0] + impulse[1][ch] * centre[1] + impulse[2][ch] * centre[2];
                i0[ch] = R::from_array(ic.to_array().map(|x| -x));
            }
        }
        let mut k = 0;
        for a in 0..3 {
            let ea = splat(a as Real - r(1.0));
            let (mut qa, mut ia) = ([one; 3], [one; 3]);
            for ch in 0..3 {
                qa[ch] = q0[ch] + qk[0][ch] * ea;
                ia[ch] = i0[ch] + ik[0][ch] * ea;
            }
            for b in 0..3 {
                let eb = splat(b as Real - r(1.0));
                let wab = w[a][0] * w[b][1];
                let (mut qab, mut iab) = ([one; 3], [one; 3]);
                for ch in 0..3 {
                    qab[ch] = qa[ch] + qk[1][ch] * eb;
                    iab[ch] = ia[ch] + ik[1][ch] * eb;
                }
                for c in 0..3 {
                    let ec = splat(c as Real - r(1.0));
                    let weight = wab * w[c][2];
                    let mut mom = [one; 3];
                    for ch in 0..3 {
                        mom[ch] = (qab[ch] + qk[2][ch] * ec) * weight;
                    }
                    quads::store_transposed([weight * m, mom[0], mom[1], mom[2]], &mut lo, k);
                    if SPLIT {
                        let mut imp = [one; 3];
                        for ch in 0..3 {
                            imp[ch] = (iab[ch] + ik[2][ch] * ec) * weight;
                        }
                        quads::store_transposed([mom[2], imp[0], imp[1], imp[2]], &mut hi, k);
                    }
                    k += 1;
                }
            }
        }
        for l in 0..n {
            for k in 0..STENCIL_NODES {
                let node = &mut local[node0[l] + stencil[k]];
                if SPLIT {
                    quads::add_split(node, &lo[l][k], &hi[l][k]);
                } else {
                    quads::add_lo(node, &lo[l][k]);
                }
            }
        }
    }
}

/// The transposition of four registers into each lane's four channels, and the adds of those
/// to a node, per precision. Each add is the node's channel plus the contribution, as the
/// one-particle body's `+=`; with SPLIT, channel 3 is written twice with the same sum.
#[cfg(not(feature = "f32"))]
mod quads {
    use super::{Staged, R};
    use crate::real::Real;
    use crate::transfer::Node;
    use std::arch::x86_64::*;

    #[inline(always)]
    unsafe fn raw(x: R) -> __m256d {
        _mm256_loadu_pd(x.to_array().as_ptr())
    }

    /// `to[l][k] = [q[0][l], q[1][l], q[2][l], q[3][l]]` for every lane `l`.
    #[inline(always)]
    pub unsafe fn store_transposed(q: [R; 4], to: &mut Staged, k: usize) {
        let [a, b, c, d] = [raw(q[0]), raw(q[1]), raw(q[2]), raw(q[3])];
        // [a0 b0 a2 b2], [a1 b1 a3 b3], [c0 d0 c2 d2], [c1 d1 c3 d3]
        let (t0, t1) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
        let (t2, t3) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
        _mm256_storeu_pd(to[0][k].as_mut_ptr(), _mm256_permute2f128_pd::<0x20>(t0, t2));
        _mm256_storeu_pd(to[1][k].as_mut_ptr(), _mm256_permute2f128_pd::<0x20>(t1, t3));
        _mm256_storeu_pd(to[2][k].as_mut_ptr(), _mm256_permute2f128_pd::<0x31>(t0, t2));
        _mm256_storeu_pd(to[3][k].as_mut_ptr(), _mm256_permute2f128_pd::<0x31>(t1, t3));
    }

    /// Adds `lo` to channels 0..4.
    #[inline(always)]
    pub unsafe fn add_lo(node: &mut Node, lo: &[Real; 4]) {
        let sum = _mm256_add_pd(_mm256_loadu_pd(node.as_ptr()), _mm256_loadu_pd(lo.as_ptr()));
        _mm256_storeu_pd(node.as_mut_ptr(), sum);
    }

    /// Adds `lo` to channels 0..4 and `hi` to channels 3..7, both to the node as it was.
    #[inline(always)]
    pub unsafe fn add_split(node: &mut Node, lo: &[Real; 4], hi: &[Real; 4]) {
        let (n0, n3) = (_mm256_loadu_pd(node.as_ptr()), _mm256_loadu_pd(node.as_ptr().add(3)));
        _mm256_storeu_pd(node.as_mut_ptr(), _mm256_add_pd(n0, _mm256_loadu_pd(lo.as_ptr())));
        _mm256_storeu_pd(node.as_mut_ptr().add(3), _mm256_add_pd(n3, _mm256_loadu_pd(hi.as_ptr())));
    }
}

#[cfg(feature = "f32")]
mod quads {
    use super::{Staged, R};
    use crate::real::Real;
    use crate::transfer::Node;
    use std::arch::x86_64::*;

    #[inline(always)]
    unsafe fn raw(x: R) -> __m256 {
        _mm256_loadu_ps(x.to_array().as_ptr())
    }

    /// `to[l][k] = [q[0][l], q[1][l], q[2][l], q[3][l]]` for every lane `l`.
    #[inline(always)]
    pub unsafe fn store_transposed(q: [R; 4], to: &mut Staged, k: usize) {
        let [a, b, c, d] = [raw(q[0]), raw(q[1]), raw(q[2]), raw(q[3])];
        // in each half: [a0 b0 a1 b1], [a2 b2 a3 b3], [c0 d0 c1 d1], [c2 d2 c3 d3]
        let (t0, t1) = (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
        let (t2, t3) = (_mm256_unpacklo_ps(c, d), _mm256_unpackhi_ps(c, d));
        // lanes l (low half) and l + 4 (high half)
        let quads = [_mm256_shuffle_ps::<0x44>(t0, t2), _mm256_shuffle_ps::<0xee>(t0, t2), _mm256_shuffle_ps::<0x44>(t1, t3), _mm256_shuffle_ps::<0xee>(t1, t3)];
        for (l, q) in quads.into_iter().enumerate() {
            _mm_storeu_ps(to[l][k].as_mut_ptr(), _mm256_castps256_ps128(q));
            _mm_storeu_ps(to[l + 4][k].as_mut_ptr(), _mm256_extractf128_ps::<1>(q));
        }
    }

    /// Adds `lo` to channels 0..4.
    #[inline(always)]
    pub unsafe fn add_lo(node: &mut Node, lo: &[Real; 4]) {
        let sum = _mm_add_ps(_mm_loadu_ps(node.as_ptr()), _mm_loadu_ps(lo.as_ptr()));
        _mm_storeu_ps(node.as_mut_ptr(), sum);
    }

    /// Adds `lo` to channels 0..4 and `hi` to channels 3..7, both to the node as it was.
    #[inline(always)]
    pub unsafe fn add_split(node: &mut Node, lo: &[Real; 4], hi: &[Real; 4]) {
        let (n0, n3) = (_mm_loadu_ps(node.as_ptr()), _mm_loadu_ps(node.as_ptr().add(3)));
        _mm_storeu_ps(node.as_mut_ptr(), _mm_add_ps(n0, _mm_loadu_ps(lo.as_ptr())));
        _mm_storeu_ps(node.as_mut_ptr().add(3), _mm_add_ps(n3, _mm_loadu_ps(hi.as_ptr())));
    }
}
