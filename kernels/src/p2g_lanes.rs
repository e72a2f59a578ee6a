//! P2G over several particles at once: the body of [`crate::transfer::p2g_block`]'s AVX2 copy,
//! each particle's arithmetic in one lane of a 256-bit register (4 particles in f64, 8 in f32;
//! the register is [`crate::wide`]'s).
//!
//! Enters: one particle block's `order`, the particle state, the block's neighbourhood buffer.
//! Leaves the same node sums as the one-particle body ([`crate::transfer::p2g_particle`]), bit
//! for bit: every lane performs that body's IEEE operations in the same order (no FMA), and the
//! particles then add themselves to their nodes one after the other in `order`, through that
//! body's own node loop ([`crate::transfer::p2g_scatter`]), so every node channel sums the same
//! terms in the same order. A group any of whose stencils leaves the block, or whose coordinates
//! are not finite and small, runs through the one-particle body instead, so such input behaves
//! exactly as there.
//!
//! What the lanes take: a particle's weights, momentum at the stencil centre and its slopes (and
//! the impulse's), the arithmetic before the node loop. The node loop stays one particle at a
//! time: building 27 nodes' contributions in lanes, staging them and adding them particle by
//! particle measured slower (more work per node than the loop's own three operations and add).

use crate::real::{r, Real, M3, V3};
use crate::transfer::{p2g_particle, p2g_scatter, p2g_stress_scale, Node, NodeLanes, P2gInput, TransferParams, NEIGHBOURHOOD_NODES};
use crate::wide::{R, W};
use crate::transfer_lanes::{fx_and_weights, lanes_of, stencil_starts};
use std::array::from_fn;

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

/// The lanes of three registers.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn arrays(x: &[R; 3]) -> [[Real; W]; 3] {
    [x[0].to_array(), x[1].to_array(), x[2].to_array()]
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
        // p2g_particle's arithmetic before its node loop, lane by lane (explicit loops, no
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
        // the slopes of momentum and (split) impulse along axis k: `[k][ch]`
        let (mut qk, mut ik) = ([[one; 3]; 3], [[one; 3]; 3]);
        for k in 0..3 {
            for ch in 0..3 {
                qk[k][ch] = affine[k][ch] * splat(dx);
                if SPLIT {
                    ik[k][ch] = impulse[k][ch] * splat(dx);
                }
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
        // each lane's particle adds itself to its nodes, in order, through the one-particle
        // body's own node loop
        let (w, m, q0) = ([arrays(&w[0]), arrays(&w[1]), arrays(&w[2])], m.to_array(), arrays(&q0));
        let (qk, i0, ik) = ([arrays(&qk[0]), arrays(&qk[1]), arrays(&qk[2])], arrays(&i0), [arrays(&ik[0]), arrays(&ik[1]), arrays(&ik[2])]);
        for l in 0..n {
            let v3 = |x: &[[Real; W]; 3]| V3::new(x[0][l], x[1][l], x[2][l]);
            let (wl, qkl) = ([v3(&w[0]), v3(&w[1]), v3(&w[2])], [L::slope(v3(&qk[0])), L::slope(v3(&qk[1])), L::slope(v3(&qk[2]))]);
            let (i0l, ikl) = if SPLIT { (v3(&i0), [v3(&ik[0]), v3(&ik[1]), v3(&ik[2])]) } else { (V3::ZERO, [V3::ZERO; 3]) };
            p2g_scatter::<SPLIT, L>(local, node0[l], &wl, m[l], L::mass_momentum(m[l], v3(&q0)), qkl, i0l, ikl);
        }
    }
}
