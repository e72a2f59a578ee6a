//! The transfer adjoints over several particles at once: the bodies of the AVX2 copies of
//! [`crate::transfer_adjoint`]'s kernels, each particle's sweep over its 27 stencil nodes in one
//! lane of a 256-bit register (4 particles in f64, 8 in f32; the register is
//! [`crate::wide`]'s).
//!
//! Enters: one particle block's `order`, its neighbourhood (and its adjoint), the particle state
//! and output adjoints. Leaves the same adjoints as the one-particle bodies, bit for bit: every
//! lane performs that body's IEEE operations in the same order (no FMA, each sum in the same
//! order). What several particles add to one place is added particle by particle in `order`:
//! the block sums (`dt_bar`, `dx_bar` and the scales') in the one-particle code that runs before
//! each sweep, and the node adjoints G2P's adjoint scatters, which the lanes write to a stack
//! scratch that is then added to the nodes one particle after another. A group any of whose
//! stencils leaves the block runs its sweeps through the one-particle code, so such input
//! behaves exactly as there.

use crate::real::{r, Real, V3};
use crate::real::M3;
use crate::transfer::{Node, P2gInput, TransferParams, NEIGHBOURHOOD_EDGE, NEIGHBOURHOOD_NODES};
use crate::transfer_adjoint::{
    g2p_adjoint_finish, g2p_adjoint_nodes, g2p_adjoint_start, p2g_adjoint_finish, p2g_adjoint_nodes, G2pAdjointIn, G2pAdjointOut, G2pCells, G2pNodeSweep, G2pSums, P2gAdjoint,
    P2gParticle, P2gSums, P2gSweep,
};
use crate::wide::{R, W};
use crate::transfer_lanes::{node_channels, starts_in_block, CHANNELS};
use std::array::from_fn;

/// The 27 stencil nodes' offsets from the stencil's base node in a neighbourhood, in the order
/// the one-particle sweeps visit them.
const STENCIL_OFFSETS: [usize; 27] = {
    let mut o = [0; 27];
    let mut n = 0;
    while n < 27 {
        o[n] = (n / 9 * NEIGHBOURHOOD_EDGE + n / 3 % 3) * NEIGHBOURHOOD_EDGE + n % 3;
        n += 1;
    }
    o
};

/// [`crate::transfer_adjoint::g2p_block_adjoint`]'s body over W particles at a time: the
/// one-particle code up to each particle's node sweep (its J-bar, growth, C, move and FLIP
/// adjoints and the block sums, in `order`), the sweeps of W particles in lanes, then each
/// particle's node adjoints and position adjoint added in `order`. `order` holds distinct
/// particles (as every particle block's does).
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn g2p_block_adjoint_lanes(
    origin: [i32; 3],
    order: &[u32],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    inp: &G2pAdjointIn,
    out: &mut G2pAdjointOut,
) {
    let dx = tp.dx;
    let cells = G2pCells::of(origin, order, flip, j_bar, tp, inp);
    let mut sums = G2pSums::default();
    // the node adjoints of a group's sweeps: [node of the stencil][channel][lane]
    let mut v_bar = [[[r(0.0); W]; 3]; 27];
    let mut v_old_bar = [[[r(0.0); W]; 3]; 27];
    for group in order.chunks(W) {
        let n = group.len();
        let p: [usize; W] = from_fn(|l| group[l.min(n - 1)] as usize);
        // lanes past the group repeat its last particle's sweep, and are not written back
        let first = g2p_adjoint_start(origin, flip, j_bar, tp, inp, &cells, p[0], out, &mut sums);
        let mut s = [first; W];
        for l in 1..n {
            s[l] = g2p_adjoint_start(origin, flip, j_bar, tp, inp, &cells, p[l], out, &mut sums);
        }
        for l in n..W {
            s[l] = s[n - 1];
        }
        let Some(node0) = starts_in_block(from_fn(|l| s[l].stencil.base)) else {
            for l in 0..n {
                let w_bar = g2p_adjoint_nodes(&s[l], flip, dx, inp.local, out.local_bar);
                g2p_adjoint_finish(&s[l], &w_bar, p[l], out);
            }
            continue;
        };
        // SAFETY: every stencil lies in the block, so in the neighbourhood; AVX2
        let w_bar = g2p_sweeps(&s, flip, dx, inp.local, &node0, &mut v_bar, &mut v_old_bar);
        let mut w_bar_lanes = [[[r(0.0); W]; 3]; 3];
        for k in 0..3 {
            for d in 0..3 {
                w_bar_lanes[k][d] = w_bar[k][d].to_array();
            }
        }
        let w_bar = w_bar_lanes;
        for l in 0..n {
            let w_bar_l: [V3; 3] = from_fn(|k| V3::new(w_bar[k][0][l], w_bar[k][1][l], w_bar[k][2][l]));
            g2p_adjoint_finish(&s[l], &w_bar_l, p[l], out);
            for (k, &offset) in STENCIL_OFFSETS.iter().enumerate() {
                let nb = &mut out.local_bar[node0[l] + offset];
                nb[1] += v_bar[k][0][l];
                nb[2] += v_bar[k][1][l];
                nb[3] += v_bar[k][2][l];
                if flip > r(0.0) {
                    nb[4] -= v_old_bar[k][0][l];
                    nb[5] -= v_old_bar[k][1][l];
                    nb[6] -= v_old_bar[k][2][l];
                }
            }
        }
    }
    sums.add_to(tp, out);
}

/// The node sweeps of W particles (`g2p_adjoint_nodes` lane by lane): writes each lane's
/// adjoints of its nodes' new velocities to `v_bar` and, with FLIP, those its nodes' old
/// velocities are to lose to `v_old_bar`; returns the adjoints of the per-axis weights,
/// `[k][axis]`.
///
/// # Safety
/// Every lane's stencil, starting at `node0[l]`, lies in `local`; AVX2.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn g2p_sweeps(
    s: &[G2pNodeSweep; W],
    flip: Real,
    dx: Real,
    local: &[Node; NEIGHBOURHOOD_NODES],
    node0: &[usize; W],
    v_bar: &mut [[[Real; W]; 3]; 27],
    v_old_bar: &mut [[[Real; W]; 3]; 27],
) -> [[R; 3]; 3] {
    let zero = R::splat(r(0.0));
    let (mut w, mut v_sens, mut dv_bar, mut bmat_bar) = ([[zero; 3]; 3], [zero; 3], [zero; 3], [[zero; 3]; 3]);
    // dpos along each axis at the stencil's three offsets e: (e - fx) dx
    let mut dpos = [[zero; 3]; 3];
    for d in 0..3 {
        for k in 0..3 {
            w[k][d] = R::from_array(from_fn(|l| s[l].stencil.w[k][d]));
            bmat_bar[k][d] = R::from_array(from_fn(|l| s[l].bmat_bar.col(k)[d]));
        }
        v_sens[d] = R::from_array(from_fn(|l| s[l].v_sens[d]));
        dv_bar[d] = R::from_array(from_fn(|l| s[l].dv_bar[d]));
        let fx = R::from_array(from_fn(|l| s[l].stencil.fx[d]));
        for (e, dpos) in dpos[d].iter_mut().enumerate() {
            *dpos = (R::splat(e as Real) - fx) * R::splat(dx);
        }
    }
    let mut w_bar = [[zero; 3]; 3];
    for a in 0..3 {
        // B_bar dpos = (B_bar e_x dpos_x + B_bar e_y dpos_y) + B_bar e_z dpos_z, built up axis by axis
        let mut bx = [zero; 3];
        for ch in 0..3 {
            bx[ch] = bmat_bar[0][ch] * dpos[0][a];
        }
        for b in 0..3 {
            let wab = w[a][0] * w[b][1];
            let mut bxy = [zero; 3];
            for ch in 0..3 {
                bxy[ch] = bx[ch] + bmat_bar[1][ch] * dpos[1][b];
            }
            for c in 0..3 {
                let k = (a * 3 + b) * 3 + c;
                let weight = wab * w[c][2];
                // SAFETY: the caller's promise
                let vi = node_channels::<1>(local, node0, STENCIL_OFFSETS[k]);
                let mut vi_sens = [zero; 3];
                for ch in 0..3 {
                    vi_sens[ch] = v_sens[ch] + (bxy[ch] + bmat_bar[2][ch] * dpos[2][c]);
                }
                let mut weight_bar = vi[0] * vi_sens[0] + vi[1] * vi_sens[1] + vi[2] * vi_sens[2];
                for ch in 0..3 {
                    v_bar[k][ch] = (vi_sens[ch] * weight).to_array();
                }
                if flip > r(0.0) {
                    let v_old = node_channels::<4>(local, node0, STENCIL_OFFSETS[k]);
                    weight_bar = weight_bar - (v_old[0] * dv_bar[0] + v_old[1] * dv_bar[1] + v_old[2] * dv_bar[2]);
                    for ch in 0..3 {
                        v_old_bar[k][ch] = (dv_bar[ch] * weight).to_array();
                    }
                }
                w_bar[a][0] = w_bar[a][0] + weight_bar * w[b][1] * w[c][2];
                w_bar[b][1] = w_bar[b][1] + weight_bar * w[a][0] * w[c][2];
                w_bar[c][2] = w_bar[c][2] + weight_bar * w[a][0] * w[b][1];
            }
        }
    }
    w_bar
}

/// [`crate::transfer_adjoint::p2g_block_adjoint`]'s body over W particles at a time: each
/// particle's recomputed P2G contribution, the sweeps of W particles over the node adjoints in
/// lanes, then each particle's adjoints and its terms of the block sums added in `order`.
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn p2g_block_adjoint_lanes<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local_bar: &[Node; NEIGHBOURHOOD_NODES],
    out: &mut P2gAdjoint,
) {
    let mut sums = P2gSums::default();
    for group in order.chunks(W) {
        let n = group.len();
        let pi: [usize; W] = from_fn(|l| group[l.min(n - 1)] as usize);
        // lanes past the group repeat its last particle, and are not written back
        let q: [P2gParticle; W] = from_fn(|l| P2gParticle::new::<SPLIT>(origin, p, tp, pi[l]));
        let Some(node0) = starts_in_block(from_fn(|l| q[l].stencil.base)) else {
            for l in 0..n {
                let sweep = p2g_adjoint_nodes::<SPLIT>(&q[l], tp.dx, local_bar);
                p2g_adjoint_finish::<SPLIT>(&q[l], &sweep, p, tp, pi[l], out, &mut sums);
            }
            continue;
        };
        // SAFETY: every stencil lies in the block, so in the neighbourhood; AVX2
        let sweeps = p2g_sweeps::<SPLIT>(&q, tp.dx, local_bar, &node0);
        for l in 0..n {
            p2g_adjoint_finish::<SPLIT>(&q[l], &sweeps[l], p, tp, pi[l], out, &mut sums);
        }
    }
    sums.add_to(tp, out);
}

/// The register of each lane's `col`-th column of `m(lane)`, one register per row.
///
/// # Safety
/// AVX2.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn column(m: [M3; W], col: usize) -> [R; 3] {
    let mut c = [[r(0.0); W]; 3];
    for l in 0..W {
        let v = m[l].col(col);
        (c[0][l], c[1][l], c[2][l]) = (v.x, v.y, v.z);
    }
    [R::from_array(c[0]), R::from_array(c[1]), R::from_array(c[2])]
}

/// `(M e_x dpos_x + M e_y dpos_y) + M e_z dpos_z` (glam's `M * dpos`) with `m[col][row]`, the
/// first two terms given as `mxy`.
#[inline(always)]
fn mul_dpos(mxy: &[R; 3], m: &[[R; 3]; 3], dpos_z: R) -> [R; 3] {
    [mxy[0] + m[2][0] * dpos_z, mxy[1] + m[2][1] * dpos_z, mxy[2] + m[2][2] * dpos_z]
}

/// `a.x b.x + a.y b.y + a.z b.z`, summed in glam's order.
#[inline(always)]
fn dot(a: &[R; 3], b: &[R; 3]) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The node sweeps of W particles (`p2g_adjoint_nodes` lane by lane).
///
/// # Safety
/// Every lane's stencil, starting at `node0[l]`, lies in `local_bar`; AVX2.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn p2g_sweeps<const SPLIT: bool>(q: &[P2gParticle; W], dx: Real, local_bar: &[Node; NEIGHBOURHOOD_NODES], node0: &[usize; W]) -> [P2gSweep; W] {
    let zero = R::splat(r(0.0));
    let (mut w, mut dpos) = ([[zero; 3]; 3], [[zero; 3]; 3]);
    for d in 0..3 {
        for (k, w) in w.iter_mut().enumerate() {
            w[d] = R::from_array(from_fn(|l| q[l].stencil.w[k][d]));
        }
        // dpos along axis d at the stencil's three offsets e: (e - fx) dx
        let fx = R::from_array(from_fn(|l| q[l].stencil.fx[d]));
        for (e, dpos) in dpos[d].iter_mut().enumerate() {
            *dpos = (R::splat(e as Real) - fx) * R::splat(dx);
        }
    }
    let m = R::from_array(from_fn(|l| q[l].m));
    let mv = [R::from_array(from_fn(|l| q[l].mv.x)), R::from_array(from_fn(|l| q[l].mv.y)), R::from_array(from_fn(|l| q[l].mv.z))];
    let (affine_m, impulse_m): ([M3; W], [M3; W]) = (from_fn(|l| q[l].affine), from_fn(|l| q[l].impulse));
    let affine = [column(affine_m, 0), column(affine_m, 1), column(affine_m, 2)];
    let impulse = if SPLIT { [column(impulse_m, 0), column(impulse_m, 1), column(impulse_m, 2)] } else { [[zero; 3]; 3] };
    let mut m_bar = zero;
    let (mut mv_bar, mut imp_sum) = ([zero; 3], [zero; 3]);
    let (mut affine_bar, mut impulse_bar, mut w_bar) = ([[zero; 3]; 3], [[zero; 3]; 3], [[zero; 3]; 3]);
    let nodes = local_bar.as_ptr().cast::<Real>();
    for a in 0..3 {
        let ax: [R; 3] = [affine[0][0] * dpos[0][a], affine[0][1] * dpos[0][a], affine[0][2] * dpos[0][a]];
        let ix: [R; 3] = [impulse[0][0] * dpos[0][a], impulse[0][1] * dpos[0][a], impulse[0][2] * dpos[0][a]];
        for b in 0..3 {
            let wab = w[a][0] * w[b][1];
            let axy: [R; 3] = [ax[0] + affine[1][0] * dpos[1][b], ax[1] + affine[1][1] * dpos[1][b], ax[2] + affine[1][2] * dpos[1][b]];
            let ixy: [R; 3] = [ix[0] + impulse[1][0] * dpos[1][b], ix[1] + impulse[1][1] * dpos[1][b], ix[2] + impulse[1][2] * dpos[1][b]];
            for c in 0..3 {
                let k = (a * 3 + b) * 3 + c;
                let weight = wab * w[c][2];
                let d = [dpos[0][a], dpos[1][b], dpos[2][c]];
                // SAFETY: the caller's promise
                let mom_bar = node_channels::<1>(local_bar, node0, STENCIL_OFFSETS[k]);
                let mut mass_bar = [r(0.0); W];
                for l in 0..W {
                    mass_bar[l] = *nodes.add((node0[l] + STENCIL_OFFSETS[k]) * CHANNELS);
                }
                let mass_bar = R::from_array(mass_bar);
                let am = mul_dpos(&axy, &affine, d[2]);
                let mut weight_bar = mass_bar * m + dot(&mom_bar, &[mv[0] + am[0], mv[1] + am[1], mv[2] + am[2]]);
                m_bar = m_bar + weight * mass_bar;
                for ch in 0..3 {
                    let mw = mom_bar[ch] * weight;
                    mv_bar[ch] = mv_bar[ch] + mw;
                    for (col, d) in d.iter().enumerate() {
                        affine_bar[col][ch] = affine_bar[col][ch] + mw * *d;
                    }
                }
                if SPLIT {
                    let imp_bar = node_channels::<4>(local_bar, node0, STENCIL_OFFSETS[k]);
                    weight_bar = weight_bar + dot(&imp_bar, &mul_dpos(&ixy, &impulse, d[2]));
                    for ch in 0..3 {
                        let iw = imp_bar[ch] * weight;
                        imp_sum[ch] = imp_sum[ch] + iw;
                        for (col, d) in d.iter().enumerate() {
                            impulse_bar[col][ch] = impulse_bar[col][ch] + iw * *d;
                        }
                    }
                }
                w_bar[a][0] = w_bar[a][0] + weight_bar * w[b][1] * w[c][2];
                w_bar[b][1] = w_bar[b][1] + weight_bar * w[a][0] * w[c][2];
                w_bar[c][2] = w_bar[c][2] + weight_bar * w[a][0] * w[b][1];
            }
        }
    }
    // back to one particle a lane: [m_bar, mv_bar, imp_sum, affine_bar's columns, impulse_bar's,
    // w_bar] (explicit loops: every register operation stays in this AVX2 function)
    let mut lanes = [[[r(0.0); W]; 3]; 12];
    for ch in 0..3 {
        lanes[0][ch] = m_bar.to_array();
        lanes[1][ch] = mv_bar[ch].to_array();
        lanes[2][ch] = imp_sum[ch].to_array();
        for k in 0..3 {
            lanes[3 + k][ch] = affine_bar[k][ch].to_array();
            lanes[6 + k][ch] = impulse_bar[k][ch].to_array();
            lanes[9 + k][ch] = w_bar[k][ch].to_array();
        }
    }
    let v3 = |i: usize, l: usize| V3::new(lanes[i][0][l], lanes[i][1][l], lanes[i][2][l]);
    from_fn(|l| P2gSweep {
        m_bar: lanes[0][0][l],
        mv_bar: v3(1, l),
        affine_bar: M3::from_cols(v3(3, l), v3(4, l), v3(5, l)),
        impulse_bar: M3::from_cols(v3(6, l), v3(7, l), v3(8, l)),
        imp_sum: v3(2, l),
        w_bar: [v3(9, l), v3(10, l), v3(11, l)],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::M3;
    use crate::transfer::{g2p_block, G2pOutput};
    use crate::transfer_adjoint::{g2p_block_adjoint_body, p2g_block_adjoint_body};

    /// Uniform numbers in [-1, 1) from a 64-bit LCG.
    struct Lcg(u64);

    impl Lcg {
        fn u(&mut self) -> Real {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            r((self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
        }
        fn v3(&mut self) -> V3 {
            V3::new(self.u(), self.u(), self.u())
        }
        fn m3(&mut self) -> M3 {
            M3::from_cols(self.v3(), self.v3(), self.v3())
        }
    }

    const ORIGIN: [i32; 3] = [8, -4, 12];
    const P: usize = 37;

    /// Positions whose stencil bases cover the block [`ORIGIN`] + 0..4, a third of them in its
    /// first or last cell along some axis (and one on a base cell's face).
    fn positions(rng: &mut Lcg) -> Vec<V3> {
        (0..P)
            .map(|k| {
                let mut x: [Real; 3] = from_fn(|d| ORIGIN[d] as Real + r(0.5) + (rng.u() + r(1.0)) * r(2.0 * 0.999));
                if k % 3 == 0 {
                    let d = k / 3 % 3;
                    x[d] = ORIGIN[d] as Real + r(0.5) + if k % 2 == 0 { r(0.01) } else { r(3.99) };
                }
                if k == 4 {
                    x[1] = (ORIGIN[1] + 2) as Real + r(0.5);
                }
                V3::from_array(x)
            })
            .collect()
    }

    /// The lanes against the one-particle body: groups cut short at the end of the block,
    /// particles at the block's faces moving out of their J-bar cell or out of the block, with and
    /// without FLIP, J-bar and the forward's outputs, all give the body's bits.
    #[test]
    fn g2p_adjoint_lanes_give_the_one_particle_bits() {
        if !crate::cpu::has_avx2() {
            return;
        }
        let mut rng = Lcg(0x9e37_79b9_7f4a_7c15);
        let mut local = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
        for n in local.iter_mut() {
            *n = from_fn(|c| if c == 0 { r(1.0) + rng.u() } else { rng.u() });
        }
        let xg = positions(&mut rng);
        let v: Vec<V3> = (0..P).map(|_| rng.v3()).collect();
        let j: Vec<Real> = (0..P).map(|_| r(1.0) + r(0.05) * rng.u()).collect();
        let vol0: Vec<Real> = (0..P).map(|k| r(1e-6 * (k % 5) as f64)).collect(); // some massless
        let (xg_bar, v_bar): (Vec<V3>, Vec<V3>) = ((0..P).map(|_| rng.v3()).collect(), (0..P).map(|_| rng.v3()).collect());
        let c_bar: Vec<M3> = (0..P).map(|_| rng.m3()).collect();
        let jac_bar: Vec<Real> = (0..P).map(|_| rng.u()).collect();
        // a step of up to about half a cell: particles change cells and leave the block
        let tp = TransferParams { dx: r(2.5e-3), dt: r(1.25e-3) };
        for n in [1usize, 3, 8, 9, P] {
            let order: Vec<u32> = if n == P { (0..P as u32).map(|k| (k * 7) % P as u32).collect() } else { (10..10 + n as u32).collect() };
            for (flip, jb, forward) in [(0.0, false, false), (0.0, false, true), (0.0, true, true), (0.95, false, false), (0.95, true, false)] {
                let (flip, jb) = (r(flip), jb.then_some(&vol0[..]));
                let (mut v_fwd, mut c_fwd, mut x_fwd, mut j_fwd) = (v.clone(), vec![M3::ZERO; P], xg.clone(), j.clone());
                g2p_block(ORIGIN, &order, &local, flip, jb, &tp, &mut G2pOutput { xg: &mut x_fwd, v: &mut v_fwd, c: &mut c_fwd, j: &mut j_fwd });
                let inp = G2pAdjointIn {
                    local: &local,
                    xg: &xg,
                    v: &v,
                    j: &j,
                    forward: forward.then_some((&v_fwd[..], &c_fwd[..])),
                    xg_bar: &xg_bar,
                    v_bar: &v_bar,
                    c_bar: &c_bar,
                    jac_bar: &jac_bar,
                };
                let run = |lanes: bool| {
                    // accumulators that already hold something
                    let mut acc = Lcg(5);
                    let mut local_bar = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
                    local_bar.iter_mut().for_each(|n| n.iter_mut().for_each(|x| *x = acc.u()));
                    let (mut xo, mut vo) = ((0..P).map(|_| acc.v3()).collect::<Vec<_>>(), (0..P).map(|_| acc.v3()).collect::<Vec<_>>());
                    let (mut jo, mut vol0o) = ((0..P).map(|_| acc.u()).collect::<Vec<_>>(), (0..P).map(|_| acc.u()).collect::<Vec<_>>());
                    let (mut dt_bar, mut dx_bar) = (acc.u(), acc.u());
                    let mut out = G2pAdjointOut { local_bar: &mut local_bar, xg_bar: &mut xo, v_bar: &mut vo, jac_bar: &mut jo, vol0_bar: &mut vol0o, dt_bar: &mut dt_bar, dx_bar: &mut dx_bar };
                    if lanes {
                        // SAFETY: the CPU has AVX2
                        unsafe { g2p_block_adjoint_lanes(ORIGIN, &order, flip, jb, &tp, &inp, &mut out) };
                    } else {
                        g2p_block_adjoint_body(ORIGIN, &order, flip, jb, &tp, &inp, &mut out);
                    }
                    let mut all: Vec<Real> = vec![dt_bar, dx_bar];
                    all.extend(local_bar.iter().flatten());
                    all.extend(xo.iter().chain(&vo).flat_map(|a| a.to_array()));
                    all.extend(jo.iter().chain(&vol0o));
                    all.iter().map(|a| a.to_bits()).collect::<Vec<_>>()
                };
                let (lanes, body) = (run(true), run(false));
                assert!(lanes == body, "{n} particles, flip {flip}, J-bar {}, forward outputs {forward}", jb.is_some());
            }
        }
    }

    /// The P2G adjoint's lanes against its one-particle body, folded and split: groups cut short
    /// at the end of the block and particles at the block's faces give the body's bits.
    #[test]
    fn p2g_adjoint_lanes_give_the_one_particle_bits() {
        if !crate::cpu::has_avx2() {
            return;
        }
        let mut rng = Lcg(0x2545_f491_4f6c_dd1d);
        let mut local_bar = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
        local_bar.iter_mut().for_each(|n| n.iter_mut().for_each(|x| *x = rng.u()));
        let xg = positions(&mut rng);
        let v: Vec<V3> = (0..P).map(|_| rng.v3()).collect();
        let c: Vec<M3> = (0..P).map(|_| rng.m3()).collect();
        let stress: Vec<M3> = (0..P).map(|_| rng.m3() * r(100.0)).collect();
        let mass: Vec<Real> = (0..P).map(|k| r(1e-3 * (1 + k % 7) as f64)).collect();
        let vol0: Vec<Real> = (0..P).map(|_| r(2e-6) * (r(1.0) + r(0.5) * rng.u())).collect();
        let j: Vec<Real> = (0..P).map(|_| r(1.0) + r(0.05) * rng.u()).collect();
        let input = P2gInput { xg: &xg, v: &v, c: &c, stress: &stress, mass: &mass, vol0: &vol0, j: &j };
        let tp = TransferParams { dx: r(2.5e-3), dt: r(2.5e-5) };
        fn run<const SPLIT: bool>(lanes: bool, order: &[u32], input: &P2gInput, tp: &TransferParams, local_bar: &[Node; NEIGHBOURHOOD_NODES]) -> Vec<u8> {
            // accumulators that already hold something
            let mut acc = Lcg(6);
            let mut v3s = || (0..P).map(|_| acc.v3()).collect::<Vec<_>>();
            let (mut xg_bar, mut v_bar) = (v3s(), v3s());
            let mut m3s = || (0..P).map(|_| acc.m3()).collect::<Vec<_>>();
            let (mut c_bar, mut stress_bar) = (m3s(), m3s());
            let mut reals = || (0..P).map(|_| acc.u()).collect::<Vec<_>>();
            let (mut mass_bar, mut vol0_bar, mut jac_bar) = (reals(), reals(), reals());
            let (mut dt_bar, mut dx_bar) = (acc.u(), acc.u());
            let mut out = P2gAdjoint {
                xg_bar: &mut xg_bar,
                v_bar: &mut v_bar,
                c_bar: &mut c_bar,
                stress_bar: &mut stress_bar,
                mass_bar: &mut mass_bar,
                vol0_bar: &mut vol0_bar,
                jac_bar: &mut jac_bar,
                dt_bar: &mut dt_bar,
                dx_bar: &mut dx_bar,
            };
            if lanes {
                // SAFETY: the CPU has AVX2
                unsafe { p2g_block_adjoint_lanes::<SPLIT>(ORIGIN, order, input, tp, local_bar, &mut out) };
            } else {
                p2g_block_adjoint_body::<SPLIT>(ORIGIN, order, input, tp, local_bar, &mut out);
            }
            let mut all: Vec<Real> = vec![dt_bar, dx_bar];
            all.extend(xg_bar.iter().chain(&v_bar).flat_map(|a| a.to_array()));
            all.extend(c_bar.iter().chain(&stress_bar).flat_map(|m| m.to_cols_array()));
            all.extend(mass_bar.iter().chain(&vol0_bar).chain(&jac_bar));
            all.iter().flat_map(|a| a.to_ne_bytes()).collect()
        }
        for n in [1usize, 3, 8, 9, P] {
            let order: Vec<u32> = if n == P { (0..P as u32).map(|k| (k * 7) % P as u32).collect() } else { (10..10 + n as u32).collect() };
            assert!(run::<false>(true, &order, &input, &tp, &local_bar) == run::<false>(false, &order, &input, &tp, &local_bar), "{n} particles, folded");
            assert!(run::<true>(true, &order, &input, &tp, &local_bar) == run::<true>(false, &order, &input, &tp, &local_bar), "{n} particles, split");
        }
    }
}
