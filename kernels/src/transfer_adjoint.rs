//! Reverse-mode adjoints (vector-Jacobian products) of the two transfers of [`crate::transfer`],
//! for a discrete-adjoint backward pass through the time loop.
//!
//! Conventions:
//!
//! - **Recompute, don't store.** Each adjoint takes again everything its forward kernel read and
//!   recomputes the intermediates (stencil, weights, gathered velocity, C, the J-bar cell sums)
//!   from it. A backward pass over up to 10^7 steps can afford a second forward per step, not a
//!   tape of per-node intermediates. The recomputation repeats the forward's operations in the
//!   same order, so it reproduces the forward bit for bit, including which cell a particle lands
//!   in.
//! - **Adjoints of inputs are accumulated (`+=`), never overwritten**, and adjoints of outputs
//!   (the cotangents) are only read. A step reads the same particle state in P2G and, before
//!   overwriting it, in G2P, so both adjoints add into one set of start-of-step adjoints that the
//!   caller zeroes once per step; and neighbouring blocks share nodes, so `local_bar` of G2P is
//!   scatter-added into the grid adjoint exactly as the forward's P2G `local` is added to the grid.
//!   `dt_bar` and `dx_bar` sum over all blocks and steps.
//! - **Held constant**, i.e. treated as having zero derivative: the stencil base
//!   `floor(xg - 1/2)` and the J-bar cell of a particle (the base after the move). Both are
//!   piecewise constant in the position, so their derivative is zero almost everywhere; where
//!   they jump (a particle on a cell face) the kernels are not differentiable and these adjoints
//!   are the one-sided derivative of the side the forward took. `flip` and the J-bar switch are
//!   modelling choices and not differentiated. The speed G2P returns only steers the time-step
//!   control and is not differentiated: `dt` is an independent input here, and whether `dt_bar`
//!   is propagated back through the controller is the caller's choice.
//! - Positions `xg` are grid coordinates, independent of `dx`: `dx_bar` is the derivative at
//!   fixed `xg`, through `dpos = (node - xg) dx` and the scales `4 / dx^2`, `dt / dx`.
//! - Node channels: P2G's adjoint reads channel 0 (mass), 1..4 (momentum) and, with `SPLIT`,
//!   4..7 (impulse) of `local_bar`; without `SPLIT` the forward does not write 4..7 and their
//!   adjoints are ignored. G2P's adjoint adds to channels 1..4 (new velocity) and, with
//!   `flip > 0`, 4..7 (old velocity); G2P never reads the node mass, so channel 0 is untouched.
//! - G2P does not read the particle's C (it overwrites it), so the adjoint of the pre-G2P C is
//!   zero and [`G2pAdjointOut`] has no field for it.

use crate::bspline::{base_and_fx, weights, weights_adjoint};
use crate::real::{ddot, r, trace, Real, M3, V3};
use crate::transfer::{gather_velocity, local_index, Node, P2gInput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};

/// Adjoints of the particle data and parameters P2G reads, indexed like [`P2gInput`]; all
/// accumulated.
pub struct P2gAdjoint<'a> {
    pub xg_bar: &'a mut [V3],
    pub v_bar: &'a mut [V3],
    pub c_bar: &'a mut [M3],
    pub stress_bar: &'a mut [M3],
    pub mass_bar: &'a mut [Real],
    pub vol0_bar: &'a mut [Real],
    /// Adjoint of the volume ratio J (named apart from G2P's J-bar average).
    pub jac_bar: &'a mut [Real],
    pub dt_bar: &'a mut Real,
    pub dx_bar: &'a mut Real,
}

/// What [`g2p_block_adjoint`] reads: the forward's inputs, to recompute from, and the adjoints of
/// its outputs.
pub struct G2pAdjointIn<'a> {
    /// The block neighbourhood the forward gathered from (after the grid update).
    pub local: &'a [Node; NEIGHBOURHOOD_NODES],
    /// Particle state before the G2P, which the forward then overwrote in place.
    pub xg: &'a [V3],
    pub v: &'a [V3],
    pub j: &'a [Real],
    /// The forward's own outputs v and C, when it ran without FLIP (`flip = 0`, so v is the
    /// gathered grid velocity): they spare the adjoint its gather over the 27 nodes. None
    /// recomputes them.
    pub forward: Option<(&'a [V3], &'a [M3])>,
    /// Adjoints of the G2P outputs ([`crate::transfer::G2pOutput`] after the call).
    pub xg_bar: &'a [V3],
    pub v_bar: &'a [V3],
    pub c_bar: &'a [M3],
    pub jac_bar: &'a [Real],
}

/// Adjoints of what G2P reads; all accumulated.
pub struct G2pAdjointOut<'a> {
    pub local_bar: &'a mut [Node; NEIGHBOURHOOD_NODES],
    /// Adjoints of the pre-G2P particle state.
    pub xg_bar: &'a mut [V3],
    pub v_bar: &'a mut [V3],
    pub jac_bar: &'a mut [Real],
    /// Only reached through the J-bar average; untouched (and may be empty) when `j_bar` is None.
    pub vol0_bar: &'a mut [Real],
    pub dt_bar: &'a mut Real,
    pub dx_bar: &'a mut Real,
}

/// The 27 stencil nodes as (a, b, c) offsets, in the order the forward loops visit them (the
/// order matters for reproducing its sums bit for bit).
#[inline(always)]
fn stencil_nodes() -> impl Iterator<Item = (usize, usize, usize)> {
    (0..27).map(|n| (n / 9, n / 3 % 3, n % 3))
}

#[inline(always)]
fn outer(a: V3, b: V3) -> M3 {
    M3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// A particle's quadratic stencil within a block neighbourhood.
#[derive(Clone, Copy)]
pub(crate) struct Stencil {
    /// Local indices of the base node along each axis.
    pub(crate) base: [usize; 3],
    pub(crate) fx: V3,
    pub(crate) w: [V3; 3],
}

impl Stencil {
    #[inline(always)]
    fn new(origin: [i32; 3], xg: V3) -> Self {
        let (base, fx) = base_and_fx(xg);
        let base = [
            (base[0] - origin[0]) as usize,
            (base[1] - origin[1]) as usize,
            (base[2] - origin[2]) as usize,
        ];
        Self { base, fx, w: weights(fx) }
    }

    #[inline(always)]
    fn node(&self, a: usize, b: usize, c: usize) -> usize {
        local_index(self.base[0] + a, self.base[1] + b, self.base[2] + c)
    }

    #[inline(always)]
    fn weight(&self, a: usize, b: usize, c: usize) -> Real {
        self.w[a].x * self.w[b].y * self.w[c].z
    }

    /// Node minus particle, in cells: `dpos / dx`.
    #[inline(always)]
    fn offset(&self, a: usize, b: usize, c: usize) -> V3 {
        V3::new(a as Real, b as Real, c as Real) - self.fx
    }

    /// Adds the adjoint of `weight(a, b, c)` to the adjoints of the per-axis weights.
    #[inline(always)]
    fn weight_adjoint(&self, a: usize, b: usize, c: usize, weight_bar: Real, w_bar: &mut [V3; 3]) {
        w_bar[a].x += weight_bar * self.w[b].y * self.w[c].z;
        w_bar[b].y += weight_bar * self.w[a].x * self.w[c].z;
        w_bar[c].z += weight_bar * self.w[a].x * self.w[b].y;
    }
}

/// Adjoint of [`crate::transfer::p2g_block`]: given the adjoint `local_bar` of the neighbourhood
/// accumulators it added to, accumulate the adjoints of everything it read into `out`.
///
/// `p` and `tp` must be what the forward read; `order` the same particles (their order only
/// changes the rounding of `dt_bar` and `dx_bar`).
pub fn p2g_block_adjoint<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local_bar: &[Node; NEIGHBOURHOOD_NODES],
    out: &mut P2gAdjoint,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { p2g_block_adjoint_avx2::<SPLIT>(origin, order, p, tp, local_bar, out) };
    }
    p2g_block_adjoint_body::<SPLIT>(origin, order, p, tp, local_bar, out)
}

/// [`p2g_block_adjoint`] compiled for AVX2, several particles' node sweeps at once (see
/// [`crate::transfer_adjoint_lanes`]: the same IEEE operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn p2g_block_adjoint_avx2<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local_bar: &[Node; NEIGHBOURHOOD_NODES],
    out: &mut P2gAdjoint,
) {
    crate::transfer_adjoint_lanes::p2g_block_adjoint_lanes::<SPLIT>(origin, order, p, tp, local_bar, out)
}

#[inline(always)]
pub(crate) fn p2g_block_adjoint_body<const SPLIT: bool>(
    origin: [i32; 3],
    order: &[u32],
    p: &P2gInput,
    tp: &TransferParams,
    local_bar: &[Node; NEIGHBOURHOOD_NODES],
    out: &mut P2gAdjoint,
) {
    let mut sums = P2gSums::default();
    for &pi in order {
        let pi = pi as usize;
        let q = P2gParticle::new::<SPLIT>(origin, p, tp, pi);
        let sweep = p2g_adjoint_nodes::<SPLIT>(&q, tp.dx, local_bar);
        p2g_adjoint_finish::<SPLIT>(&q, &sweep, p, tp, pi, out, &mut sums);
    }
    sums.add_to(tp, out);
}

/// The adjoints P2G's adjoint sums over the whole block, particle by particle in `order`.
#[derive(Default)]
pub(crate) struct P2gSums {
    stress_scale_bar: Real,
    dx_bar: Real,
}

impl P2gSums {
    /// Adds the block's sums to the adjoints of dt and dx, through `stress_scale = -4 dt / dx^2`.
    #[inline(always)]
    pub(crate) fn add_to(&self, tp: &TransferParams, out: &mut P2gAdjoint) {
        let dx = tp.dx;
        let stress_scale = -tp.dt * r(4.0) / (dx * dx);
        *out.dt_bar += self.stress_scale_bar * r(-4.0) / (dx * dx);
        *out.dx_bar += self.dx_bar - r(2.0) * self.stress_scale_bar * stress_scale / dx;
    }
}

/// What one particle added to its stencil's nodes in P2G, recomputed.
#[derive(Clone, Copy)]
pub(crate) struct P2gParticle {
    pub(crate) stencil: Stencil,
    pub(crate) m: Real,
    pub(crate) vol: Real,
    pub(crate) impulse_scale: Real,
    pub(crate) impulse: M3,
    /// `m C`, plus the impulse unless `SPLIT`.
    pub(crate) affine: M3,
    pub(crate) mv: V3,
}

impl P2gParticle {
    #[inline(always)]
    pub(crate) fn new<const SPLIT: bool>(origin: [i32; 3], p: &P2gInput, tp: &TransferParams, pi: usize) -> Self {
        let dx = tp.dx;
        let stress_scale = -tp.dt * r(4.0) / (dx * dx);
        let m = p.mass[pi];
        let vol = p.vol0[pi] * p.j[pi];
        let impulse_scale = stress_scale * vol;
        let impulse = p.stress[pi] * impulse_scale;
        let affine = if SPLIT { p.c[pi] * m } else { p.c[pi] * m + impulse };
        P2gParticle { stencil: Stencil::new(origin, p.xg[pi]), m, vol, impulse_scale, impulse, affine, mv: p.v[pi] * m }
    }
}

/// The sums of one particle's sweep over its 27 stencil nodes.
pub(crate) struct P2gSweep {
    pub(crate) m_bar: Real,
    pub(crate) mv_bar: V3,
    pub(crate) affine_bar: M3,
    /// With `SPLIT`: the impulse's adjoint and `sum w imp_bar_i`.
    pub(crate) impulse_bar: M3,
    pub(crate) imp_sum: V3,
    /// Adjoints of the per-axis weights.
    pub(crate) w_bar: [V3; 3],
}

/// The sweep over one particle's 27 stencil nodes, reading the adjoints of what it added to them.
#[inline(always)]
pub(crate) fn p2g_adjoint_nodes<const SPLIT: bool>(q: &P2gParticle, dx: Real, local_bar: &[Node; NEIGHBOURHOOD_NODES]) -> P2gSweep {
    let st = &q.stencil;
    let (m, mv, affine, impulse) = (q.m, q.mv, q.affine, q.impulse);
    let mut m_bar = r(0.0);
    let mut mv_bar = V3::ZERO;
    let mut affine_bar = M3::ZERO;
    let mut impulse_bar = M3::ZERO;
    let mut w_bar = [V3::ZERO; 3];
    let mut imp_sum = V3::ZERO;
    for (a, b, c) in stencil_nodes() {
        let weight = st.weight(a, b, c);
        let dpos = st.offset(a, b, c) * dx;
        let nb = &local_bar[st.node(a, b, c)];
        let mom_bar = V3::new(nb[1], nb[2], nb[3]);
        let mut weight_bar = nb[0] * m + mom_bar.dot(mv + affine * dpos);
        m_bar += weight * nb[0];
        mv_bar += mom_bar * weight;
        affine_bar += outer(mom_bar * weight, dpos);
        if SPLIT {
            let imp_bar = V3::new(nb[4], nb[5], nb[6]);
            weight_bar += imp_bar.dot(impulse * dpos);
            imp_sum += imp_bar * weight;
            impulse_bar += outer(imp_bar * weight, dpos);
        }
        st.weight_adjoint(a, b, c, weight_bar, &mut w_bar);
    }
    P2gSweep { m_bar, mv_bar, affine_bar, impulse_bar, imp_sum, w_bar }
}

/// Adds particle `pi`'s adjoints, given its sweep's sums, to `out` and its terms to `sums`.
#[inline(always)]
pub(crate) fn p2g_adjoint_finish<const SPLIT: bool>(q: &P2gParticle, sweep: &P2gSweep, p: &P2gInput, tp: &TransferParams, pi: usize, out: &mut P2gAdjoint, sums: &mut P2gSums) {
    let dx = tp.dx;
    let stress_scale = -tp.dt * r(4.0) / (dx * dx);
    let (m, affine, impulse) = (q.m, q.affine, q.impulse);
    let (affine_bar, mut impulse_bar, mv_bar) = (sweep.affine_bar, sweep.impulse_bar, sweep.mv_bar);
    // the node sums make the adjoint through dpos = (node - fx) dx need no work per node:
    // -dx (A^T sum_i w_i mom_bar_i) for fx and <A, A_bar> / dx for dx (A the affine matrix,
    // A_bar its adjoint so far), and the same for the impulse
    let mut fx_bar = -(affine.transpose() * mv_bar) * dx;
    sums.dx_bar += ddot(&affine, &affine_bar) / dx;
    if SPLIT {
        fx_bar -= (impulse.transpose() * sweep.imp_sum) * dx;
        sums.dx_bar += ddot(&impulse, &impulse_bar) / dx;
    }

    if !SPLIT {
        // the impulse was folded into the affine matrix
        impulse_bar += affine_bar;
    }
    out.c_bar[pi] += affine_bar * m;
    out.v_bar[pi] += mv_bar * m;
    out.mass_bar[pi] += sweep.m_bar + ddot(&affine_bar, &p.c[pi]) + mv_bar.dot(p.v[pi]);
    out.stress_bar[pi] += impulse_bar * q.impulse_scale;
    let impulse_scale_bar = ddot(&impulse_bar, &p.stress[pi]);
    sums.stress_scale_bar += impulse_scale_bar * q.vol;
    let vol_bar = impulse_scale_bar * stress_scale;
    out.vol0_bar[pi] += vol_bar * p.j[pi];
    out.jac_bar[pi] += vol_bar * p.vol0[pi];
    // fx = xg - base with the base held constant
    out.xg_bar[pi] += fx_bar + weights_adjoint(q.stencil.fx, &sweep.w_bar);
}

/// One particle's G2P up to the J-bar average, as [`crate::transfer::g2p_block`] computes it.
struct G2pParticle {
    stencil: Stencil,
    /// Grid velocity at the particle.
    v: V3,
    /// `sum w v_i dpos^T`; C is this times `4 / dx^2`.
    bmat: M3,
    tr_c: Real,
    xg_new: V3,
}

#[inline(always)]
fn g2p_particle(origin: [i32; 3], local: &[Node; NEIGHBOURHOOD_NODES], tp: &TransferParams, xg: V3) -> G2pParticle {
    let dx = tp.dx;
    let inv_dx = r(1.0) / dx;
    let c_scale = r(4.0) * inv_dx * inv_dx;
    let stencil = Stencil::new(origin, xg);
    let (v, bmat) = gather_velocity::<1, crate::real::V3A>(local, stencil.base, stencil.fx, &stencil.w, dx);
    let tr_c = trace(&(bmat * c_scale));
    G2pParticle { stencil, v, bmat, tr_c, xg_new: xg + v * (tp.dt * inv_dx) }
}

/// [`g2p_particle`] from the forward's outputs v and C (see `G2pAdjointIn::forward`); the
/// position after the move is the forward's bit for bit, so J-bar cells agree.
#[inline(always)]
fn g2p_particle_from(origin: [i32; 3], tp: &TransferParams, xg: V3, v: V3, c: &M3) -> G2pParticle {
    let inv_dx = r(1.0) / tp.dx;
    let c_scale = r(4.0) * inv_dx * inv_dx;
    G2pParticle { stencil: Stencil::new(origin, xg), v, bmat: *c * (r(1.0) / c_scale), tr_c: trace(c), xg_new: xg + v * (tp.dt * inv_dx) }
}

/// The J-bar cell (within the block) of a particle at `xg` after the move, as g2p_block assigns
/// it; None outside the block, where the particle keeps its own J.
#[inline(always)]
fn cell_of(origin: [i32; 3], xg: V3) -> Option<usize> {
    let (b, _) = base_and_fx(xg);
    let l = [b[0] - origin[0], b[1] - origin[1], b[2] - origin[2]];
    let inside = l.iter().all(|&k| (0..BLOCK_EDGE as i32).contains(&k));
    inside.then(|| (l[0] as usize * BLOCK_EDGE + l[1] as usize) * BLOCK_EDGE + l[2] as usize)
}

/// Adjoint of [`crate::transfer::g2p_block`]: given the adjoints of its outputs (`inp.xg_bar`,
/// `v_bar`, `c_bar`, `jac_bar`), accumulate the adjoints of the neighbourhood nodes and of the
/// particle state before the G2P into `out`.
///
/// `origin`, `order`, `flip`, `j_bar`, `tp` and the state in `inp` must be what the forward read.
/// With J-bar, particle p of cell k ends with `J_p = S_k / V_k`, `S_k = sum_q V0_q J_q`,
/// `V_k = sum_q V0_q` over the particles q of the block in that cell, so with `G_k` the sum of
/// the output adjoints of J over the cell, each q gets `J_q_bar = V0_q G_k / V_k` and
/// `V0_q_bar = G_k (J_q - S_k / V_k) / V_k`: the adjoint mixes exactly the particles the forward
/// mixed. That takes a first pass over the block for the cell sums.
pub fn g2p_block_adjoint(
    origin: [i32; 3],
    order: &[u32],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    inp: &G2pAdjointIn,
    out: &mut G2pAdjointOut,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { g2p_block_adjoint_avx2(origin, order, flip, j_bar, tp, inp, out) };
    }
    g2p_block_adjoint_body(origin, order, flip, j_bar, tp, inp, out)
}

/// [`g2p_block_adjoint`] compiled for AVX2, several particles' node sweeps at once (see
/// [`crate::transfer_adjoint_lanes`]: the same IEEE operations, the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn g2p_block_adjoint_avx2(
    origin: [i32; 3],
    order: &[u32],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    inp: &G2pAdjointIn,
    out: &mut G2pAdjointOut,
) {
    crate::transfer_adjoint_lanes::g2p_block_adjoint_lanes(origin, order, flip, j_bar, tp, inp, out)
}

#[inline(always)]
pub(crate) fn g2p_block_adjoint_body(
    origin: [i32; 3],
    order: &[u32],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    inp: &G2pAdjointIn,
    out: &mut G2pAdjointOut,
) {
    let cells = G2pCells::of(origin, order, flip, j_bar, tp, inp);
    let mut sums = G2pSums::default();
    for &pi in order {
        let pi = pi as usize;
        let s = g2p_adjoint_start(origin, flip, j_bar, tp, inp, &cells, pi, out, &mut sums);
        let w_bar = g2p_adjoint_nodes(&s, flip, tp.dx, inp.local, out.local_bar);
        g2p_adjoint_finish(&s, &w_bar, pi, out);
    }
    sums.add_to(tp, out);
}

/// A function, not a closure: it inlines into (and takes the target features of) each copy.
#[inline(always)]
fn g2p_adjoint_particle(origin: [i32; 3], flip: Real, tp: &TransferParams, inp: &G2pAdjointIn, pi: usize) -> G2pParticle {
    match inp.forward {
        Some((v, c)) if flip == r(0.0) => g2p_particle_from(origin, tp, inp.xg[pi], v[pi], &c[pi]),
        _ => g2p_particle(origin, inp.local, tp, inp.xg[pi]),
    }
}

/// The J-bar sums of each cell of the block after the move: `sum V0 J`, `sum V0` and the sum of
/// the output adjoints of J (all zero without J-bar).
pub(crate) struct G2pCells {
    vj: [Real; BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
    v: [Real; BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
    j_bar_sum: [Real; BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
}

impl G2pCells {
    #[inline(always)]
    pub(crate) fn of(origin: [i32; 3], order: &[u32], flip: Real, j_bar: Option<&[Real]>, tp: &TransferParams, inp: &G2pAdjointIn) -> Self {
        let mut cells = G2pCells {
            vj: [r(0.0); BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
            v: [r(0.0); BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
            j_bar_sum: [r(0.0); BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE],
        };
        if let Some(vol0) = j_bar {
            for &pi in order {
                let pi = pi as usize;
                let g = g2p_adjoint_particle(origin, flip, tp, inp, pi);
                if let Some(k) = cell_of(origin, g.xg_new) {
                    cells.vj[k] += vol0[pi] * (inp.j[pi] * (r(1.0) + tp.dt * g.tr_c));
                    cells.v[k] += vol0[pi];
                    cells.j_bar_sum[k] += inp.jac_bar[pi];
                }
            }
        }
        cells
    }
}

/// The adjoints G2P's adjoint sums over the whole block, particle by particle in `order`.
#[derive(Default)]
pub(crate) struct G2pSums {
    dt_bar: Real,
    dx_bar: Real,
    c_scale_bar: Real,
    move_scale_bar: Real,
}

impl G2pSums {
    /// Adds the block's sums to the adjoints of dt and dx, through `move_scale = dt / dx` and
    /// `c_scale = 4 / dx^2`.
    #[inline(always)]
    pub(crate) fn add_to(&self, tp: &TransferParams, out: &mut G2pAdjointOut) {
        let inv_dx = r(1.0) / tp.dx;
        let c_scale = r(4.0) * inv_dx * inv_dx;
        let move_scale = tp.dt * inv_dx;
        *out.dt_bar += self.dt_bar + self.move_scale_bar * inv_dx;
        *out.dx_bar += self.dx_bar - (self.move_scale_bar * move_scale + r(2.0) * self.c_scale_bar * c_scale) * inv_dx;
    }
}

/// One particle's adjoint before its sweep over the 27 stencil nodes: what the sweep reads.
#[derive(Clone, Copy)]
pub(crate) struct G2pNodeSweep {
    pub(crate) stencil: Stencil,
    /// The node velocity's sensitivity apart from B's: `v_grid_bar + dv_bar`.
    pub(crate) v_sens: V3,
    /// The adjoint of the FLIP increment (zero under APIC).
    pub(crate) dv_bar: V3,
    /// The adjoint of `B = sum w v_i dpos^T`.
    pub(crate) bmat_bar: M3,
    /// The particle's position adjoint apart from the weights': the moved position's adjoint
    /// plus the adjoint through `dpos`.
    pub(crate) xg_bar: V3,
}

/// Particle `pi`'s adjoint through the J-bar average, the growth of J, C, the move and FLIP: adds
/// the adjoints of its J, V0 and v to `out` and its terms to `sums`, and returns what the node
/// sweep reads.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn g2p_adjoint_start(
    origin: [i32; 3],
    flip: Real,
    j_bar: Option<&[Real]>,
    tp: &TransferParams,
    inp: &G2pAdjointIn,
    cells: &G2pCells,
    pi: usize,
    out: &mut G2pAdjointOut,
    sums: &mut G2pSums,
) -> G2pNodeSweep {
    let dx = tp.dx;
    let inv_dx = r(1.0) / dx;
    let c_scale = r(4.0) * inv_dx * inv_dx;
    let move_scale = tp.dt * inv_dx;
    let g = g2p_adjoint_particle(origin, flip, tp, inp, pi);
    let growth = r(1.0) + tp.dt * g.tr_c;
    // adjoint of J after the growth, before the cell average
    let j_grown_bar = match (j_bar, cell_of(origin, g.xg_new)) {
        (Some(vol0), Some(k)) if cells.v[k] > r(0.0) => {
            let inv_v = r(1.0) / cells.v[k];
            let j_grown = inp.j[pi] * growth;
            out.vol0_bar[pi] += cells.j_bar_sum[k] * (j_grown - cells.vj[k] * inv_v) * inv_v;
            cells.j_bar_sum[k] * vol0[pi] * inv_v
        }
        _ => inp.jac_bar[pi],
    };
    out.jac_bar[pi] += j_grown_bar * growth;
    let tr_c_bar = j_grown_bar * inp.j[pi] * tp.dt;
    sums.dt_bar += j_grown_bar * inp.j[pi] * g.tr_c;
    let cm_bar = inp.c_bar[pi] + M3::from_diagonal(V3::splat(tr_c_bar));
    sums.c_scale_bar += ddot(&cm_bar, &g.bmat);
    let bmat_bar = cm_bar * c_scale;

    let xg_new_bar = inp.xg_bar[pi];
    sums.move_scale_bar += xg_new_bar.dot(g.v);
    let (mut v_grid_bar, dv_bar) = if flip > r(0.0) {
        let v_new_bar = inp.v_bar[pi];
        out.v_bar[pi] += v_new_bar * flip;
        (v_new_bar * (r(1.0) - flip), v_new_bar * flip)
    } else {
        (inp.v_bar[pi], V3::ZERO)
    };
    v_grid_bar += xg_new_bar * move_scale;
    // B = sum_i w_i v_i dpos_i^T with dpos_i = (node_i - fx) dx: summed over the nodes, the
    // adjoint through dpos is -dx B_bar^T v (v the gathered velocity) for fx, and
    // <B_bar, B> / dx for dx, so it needs no work per node
    let fx_bar = -(bmat_bar.transpose() * g.v) * dx;
    sums.dx_bar += ddot(&bmat_bar, &g.bmat) * inv_dx;
    G2pNodeSweep { stencil: g.stencil, v_sens: v_grid_bar + dv_bar, dv_bar, bmat_bar, xg_bar: xg_new_bar + fx_bar }
}

/// The sweep over one particle's 27 stencil nodes: adds the adjoints of the node velocities it
/// read to `local_bar` and returns the adjoints of its per-axis weights.
#[inline(always)]
pub(crate) fn g2p_adjoint_nodes(s: &G2pNodeSweep, flip: Real, dx: Real, local: &[Node; NEIGHBOURHOOD_NODES], local_bar: &mut [Node; NEIGHBOURHOOD_NODES]) -> [V3; 3] {
    let st = &s.stencil;
    let mut w_bar = [V3::ZERO; 3];
    for (a, b, c) in stencil_nodes() {
        let weight = st.weight(a, b, c);
        let dpos = st.offset(a, b, c) * dx;
        let node = st.node(a, b, c);
        let n = &local[node];
        let vi = V3::new(n[1], n[2], n[3]);
        // the node velocity enters v, dv and B each times the weight
        let vi_sens = s.v_sens + s.bmat_bar * dpos;
        let mut weight_bar = vi.dot(vi_sens);
        let vi_bar = vi_sens * weight;
        let nb = &mut local_bar[node];
        nb[1] += vi_bar.x;
        nb[2] += vi_bar.y;
        nb[3] += vi_bar.z;
        if flip > r(0.0) {
            let v_old = V3::new(n[4], n[5], n[6]);
            weight_bar -= v_old.dot(s.dv_bar);
            let v_old_bar = s.dv_bar * weight;
            nb[4] -= v_old_bar.x;
            nb[5] -= v_old_bar.y;
            nb[6] -= v_old_bar.z;
        }
        st.weight_adjoint(a, b, c, weight_bar, &mut w_bar);
    }
    w_bar
}

/// Adds particle `pi`'s position adjoint, given the adjoints `w_bar` of its per-axis weights.
#[inline(always)]
pub(crate) fn g2p_adjoint_finish(s: &G2pNodeSweep, w_bar: &[V3; 3], pi: usize, out: &mut G2pAdjointOut) {
    // fx = xg - base with the base held constant
    out.xg_bar[pi] += s.xg_bar + weights_adjoint(s.stencil.fx, w_bar);
}

/// The adjoints against their forward kernels, each flattened to a map of one vector of inputs:
/// central differences of `<cotangent, forward>` along a random direction in one input group at a
/// time, and the Taylor remainder along a direction in all of them. In f32 the differences would
/// be rounding noise, hence f64 only.
#[cfg(all(test, not(feature = "f32")))]
mod tests {
    use super::*;
    use crate::transfer::{g2p_block, p2g_block, G2pOutput};
    use std::ops::Range;

    const ORIGIN: [i32; 3] = [8, -4, 12];
    const DT: Real = 0.02;
    const DX: Real = 0.3;
    /// Particles per case: two sharing a cell, and two elsewhere.
    const N: usize = 4;
    /// Not the identity, so a particle index mixed up with a loop counter shows.
    const ORDER: [u32; N] = [2, 0, 3, 1];
    const CASES: usize = 4;
    /// Difference step, relative to each group's scale. The outputs reach |x| ~ 16 (positions),
    /// so a second-order difference with h = 1e-6 has rounding noise of ~1e-9 in the loss, near
    /// 1e-6 of a small directional derivative; the fourth-order one below allows h = 1e-4
    /// (truncation ~h^4 ~ 1e-16, rounding ~1e-11).
    const H: Real = 1e-4;
    const TOL: Real = 1e-6;

    /// splitmix64
    struct Rng(u64);

    impl Rng {
        fn uniform(&mut self, lo: Real, hi: Real) -> Real {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            lo + (hi - lo) * ((z >> 11) as Real / (1u64 << 53) as Real)
        }

        fn below(&mut self, n: usize) -> i32 {
            (self.uniform(0.0, n as Real) as i32).min(n as i32 - 1)
        }

        fn vec(&mut self, len: usize, lo: Real, hi: Real) -> Vec<Real> {
            (0..len).map(|_| self.uniform(lo, hi)).collect()
        }

        /// Bounded away from zero, so that a one-entry group (dt, dx) never gets a vanishing
        /// direction whose derivative drowns in the rounding of the loss.
        fn direction(&mut self, scale: Real) -> Real {
            let magnitude = scale * self.uniform(0.5, 1.0);
            if self.uniform(0.0, 1.0) < 0.5 {
                -magnitude
            } else {
                magnitude
            }
        }

        fn cell(&mut self) -> [i32; 3] {
            [self.below(BLOCK_EDGE), self.below(BLOCK_EDGE), self.below(BLOCK_EDGE)]
        }
    }

    /// One group of a kernel's flattened inputs, and the size of a typical value of it.
    struct Group {
        name: &'static str,
        range: Range<usize>,
        scale: Real,
    }

    fn layout(fields: &[(&'static str, usize, Real)]) -> Vec<Group> {
        let mut start = 0;
        fields
            .iter()
            .map(|&(name, len, scale)| {
                start += len;
                Group { name, range: start - len..start, scale }
            })
            .collect()
    }

    fn v3s(x: &[Real]) -> Vec<V3> {
        x.chunks(3).map(V3::from_slice).collect()
    }

    fn m3s(x: &[Real]) -> Vec<M3> {
        x.chunks(9).map(M3::from_cols_slice).collect()
    }

    fn flat_v3(v: &[V3]) -> impl Iterator<Item = Real> + '_ {
        v.iter().flat_map(|a| a.to_array())
    }

    fn flat_m3(m: &[M3]) -> impl Iterator<Item = Real> + '_ {
        m.iter().flat_map(|a| a.to_cols_array())
    }

    fn nodes(x: &[Real]) -> [Node; NEIGHBOURHOOD_NODES] {
        let mut local = [[0.0; 7]; NEIGHBOURHOOD_NODES];
        for (node, values) in local.iter_mut().zip(x.chunks(7)) {
            node.copy_from_slice(values);
        }
        local
    }

    fn dot(a: &[Real], b: &[Real]) -> Real {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    fn axpy(x: &[Real], h: Real, d: &[Real]) -> Vec<Real> {
        x.iter().zip(d).map(|(x, d)| x + h * d).collect()
    }

    thread_local! {
        /// Whether this test thread's [`Flat::adjoint`]s run the baseline copies of the kernels'
        /// adjoints rather than the copies the CPU dispatches to.
        static BASELINE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }

    /// A transfer kernel as a map of its flattened inputs, with its adjoint.
    trait Flat {
        fn groups(&self) -> Vec<Group>;
        fn forward(&self, x: &[Real]) -> Vec<Real>;
        /// `acc` plus the adjoint of the inputs for the output adjoint `cot`, laid out like `x`.
        fn adjoint(&self, x: &[Real], cot: &[Real], acc: &[Real]) -> Vec<Real>;
    }

    struct P2g<const SPLIT: bool>;

    impl<const SPLIT: bool> Flat for P2g<SPLIT> {
        fn groups(&self) -> Vec<Group> {
            layout(&[
                ("xg", 3 * N, 1.0),
                ("v", 3 * N, 1.0),
                ("c", 9 * N, 1.0),
                ("stress", 9 * N, 1.0),
                ("mass", N, 1.0),
                ("vol0", N, 1.0),
                ("j", N, 1.0),
                ("dt", 1, DT),
                ("dx", 1, DX),
            ])
        }

        fn forward(&self, x: &[Real]) -> Vec<Real> {
            let g = self.groups();
            let s = |k: usize| &x[g[k].range.clone()];
            let (xg, v, c, stress) = (v3s(s(0)), v3s(s(1)), m3s(s(2)), m3s(s(3)));
            let p = P2gInput { xg: &xg, v: &v, c: &c, stress: &stress, mass: s(4), vol0: s(5), j: s(6) };
            let mut local = [[0.0; 7]; NEIGHBOURHOOD_NODES];
            p2g_block::<SPLIT>(ORIGIN, &ORDER, &p, &TransferParams { dt: s(7)[0], dx: s(8)[0] }, &mut local);
            local.concat()
        }

        fn adjoint(&self, x: &[Real], cot: &[Real], acc: &[Real]) -> Vec<Real> {
            let g = self.groups();
            let s = |k: usize| &x[g[k].range.clone()];
            let a = |k: usize| &acc[g[k].range.clone()];
            let (xg, v, c, stress) = (v3s(s(0)), v3s(s(1)), m3s(s(2)), m3s(s(3)));
            let p = P2gInput { xg: &xg, v: &v, c: &c, stress: &stress, mass: s(4), vol0: s(5), j: s(6) };
            let (mut xg_bar, mut v_bar, mut c_bar, mut stress_bar) = (v3s(a(0)), v3s(a(1)), m3s(a(2)), m3s(a(3)));
            let (mut mass_bar, mut vol0_bar, mut jac_bar) = (a(4).to_vec(), a(5).to_vec(), a(6).to_vec());
            let (mut dt_bar, mut dx_bar) = (a(7)[0], a(8)[0]);
            let kernel = if BASELINE.get() { p2g_block_adjoint_body::<SPLIT> } else { p2g_block_adjoint::<SPLIT> };
            kernel(
                ORIGIN,
                &ORDER,
                &p,
                &TransferParams { dt: s(7)[0], dx: s(8)[0] },
                &nodes(cot),
                &mut P2gAdjoint {
                    xg_bar: &mut xg_bar,
                    v_bar: &mut v_bar,
                    c_bar: &mut c_bar,
                    stress_bar: &mut stress_bar,
                    mass_bar: &mut mass_bar,
                    vol0_bar: &mut vol0_bar,
                    jac_bar: &mut jac_bar,
                    dt_bar: &mut dt_bar,
                    dx_bar: &mut dx_bar,
                },
            );
            flat_v3(&xg_bar)
                .chain(flat_v3(&v_bar))
                .chain(flat_m3(&c_bar))
                .chain(flat_m3(&stress_bar))
                .chain(mass_bar)
                .chain(vol0_bar)
                .chain(jac_bar)
                .chain([dt_bar, dx_bar])
                .collect()
        }
    }

    struct G2p {
        flip: Real,
        j_bar: bool,
        /// Hand the adjoint the forward's outputs v and C (taken without FLIP only).
        use_forward: bool,
    }

    impl Flat for G2p {
        fn groups(&self) -> Vec<Group> {
            layout(&[
                ("xg", 3 * N, 1.0),
                ("v", 3 * N, 1.0),
                ("j", N, 1.0),
                ("vol0", N, 1.0),
                ("grid", 7 * NEIGHBOURHOOD_NODES, 1.0),
                ("dt", 1, DT),
                ("dx", 1, DX),
            ])
        }

        /// The particle state after G2P: xg, v, C, J.
        fn forward(&self, x: &[Real]) -> Vec<Real> {
            let g = self.groups();
            let s = |k: usize| &x[g[k].range.clone()];
            let (mut xg, mut v, mut c, mut j) = (v3s(s(0)), v3s(s(1)), vec![M3::ZERO; N], s(2).to_vec());
            let tp = TransferParams { dt: s(5)[0], dx: s(6)[0] };
            let mut out = G2pOutput { xg: &mut xg, v: &mut v, c: &mut c, j: &mut j };
            g2p_block(ORIGIN, &ORDER, &nodes(s(4)), self.flip, self.j_bar.then_some(s(3)), &tp, &mut out);
            flat_v3(&xg).chain(flat_v3(&v)).chain(flat_m3(&c)).chain(j).collect()
        }

        fn adjoint(&self, x: &[Real], cot: &[Real], acc: &[Real]) -> Vec<Real> {
            let g = self.groups();
            let s = |k: usize| &x[g[k].range.clone()];
            let a = |k: usize| &acc[g[k].range.clone()];
            let (xg, v, local) = (v3s(s(0)), v3s(s(1)), nodes(s(4)));
            let (xg_new_bar, v_new_bar, c_bar) = (v3s(&cot[..3 * N]), v3s(&cot[3 * N..6 * N]), m3s(&cot[6 * N..15 * N]));
            let fwd = self.use_forward.then(|| {
                let (mut xo, mut vo, mut co, mut jo) = (xg.clone(), v.clone(), vec![M3::ZERO; N], s(2).to_vec());
                let tp = TransferParams { dt: s(5)[0], dx: s(6)[0] };
                let mut out = G2pOutput { xg: &mut xo, v: &mut vo, c: &mut co, j: &mut jo };
                g2p_block(ORIGIN, &ORDER, &local, self.flip, self.j_bar.then_some(s(3)), &tp, &mut out);
                (vo, co)
            });
            let inp = G2pAdjointIn {
                local: &local,
                xg: &xg,
                v: &v,
                j: s(2),
                forward: fwd.as_ref().map(|(v, c)| (&v[..], &c[..])),
                xg_bar: &xg_new_bar,
                v_bar: &v_new_bar,
                c_bar: &c_bar,
                jac_bar: &cot[15 * N..],
            };
            let (mut xg_bar, mut v_bar, mut jac_bar, mut vol0_bar) = (v3s(a(0)), v3s(a(1)), a(2).to_vec(), a(3).to_vec());
            let (mut local_bar, mut dt_bar, mut dx_bar) = (nodes(a(4)), a(5)[0], a(6)[0]);
            let mut out = G2pAdjointOut {
                local_bar: &mut local_bar,
                xg_bar: &mut xg_bar,
                v_bar: &mut v_bar,
                jac_bar: &mut jac_bar,
                vol0_bar: &mut vol0_bar,
                dt_bar: &mut dt_bar,
                dx_bar: &mut dx_bar,
            };
            let tp = TransferParams { dt: s(5)[0], dx: s(6)[0] };
            let kernel = if BASELINE.get() { g2p_block_adjoint_body } else { g2p_block_adjoint };
            kernel(ORIGIN, &ORDER, self.flip, self.j_bar.then_some(s(3)), &tp, &inp, &mut out);
            flat_v3(&xg_bar)
                .chain(flat_v3(&v_bar))
                .chain(jac_bar)
                .chain(vol0_bar)
                .chain(local_bar.concat())
                .chain([dt_bar, dx_bar])
                .collect()
        }
    }

    /// A position whose stencil base is `ORIGIN + cell`, at least `margin` from the faces where
    /// the base changes.
    fn position(rng: &mut Rng, cell: [i32; 3], margin: Real) -> [Real; 3] {
        std::array::from_fn(|d| (ORIGIN[d] + cell[d]) as Real + 0.5 + rng.uniform(margin, 1.0 - margin))
    }

    fn face_distance(xg: V3) -> Real {
        let t = xg - V3::splat(0.5);
        (t - t.round()).abs().min_element()
    }

    /// Margin to the faces: keeps every stencil base fixed under the Taylor test's largest step.
    const MARGIN: Real = 0.05;

    fn p2g_point(rng: &mut Rng) -> Vec<Real> {
        let shared = rng.cell();
        let cells = [shared, shared, rng.cell(), rng.cell()];
        let mut x: Vec<Real> = cells.iter().flat_map(|&c| position(rng, c, MARGIN)).collect();
        x.extend(rng.vec(3 * N, -1.0, 1.0));
        x.extend(rng.vec(9 * N, -1.0, 1.0));
        x.extend(rng.vec(9 * N, -1.0, 1.0));
        x.extend(rng.vec(N, 0.5, 1.5));
        x.extend(rng.vec(N, 0.5, 1.5));
        x.extend(rng.vec(N, 0.8, 1.2));
        x.extend([DT, DX]);
        x
    }

    /// Particles 0 and 1 share a cell before and after the move, particle 2 leaves the block (so
    /// under J-bar it keeps its own J), and every particle stays clear of the faces, before and
    /// after the move.
    fn g2p_point(rng: &mut Rng) -> Vec<Real> {
        let block_end = ORIGIN[0] + BLOCK_EDGE as i32;
        for _ in 0..1000 {
            let shared = [rng.below(BLOCK_EDGE - 1), rng.below(BLOCK_EDGE), rng.below(BLOCK_EDGE)];
            let edge = [BLOCK_EDGE as i32 - 1, rng.below(BLOCK_EDGE), rng.below(BLOCK_EDGE)];
            let cells = [shared, shared, edge, rng.cell()];
            let mut x: Vec<Real> = cells.iter().flat_map(|&c| position(rng, c, 2.0 * MARGIN)).collect();
            x[6] = (block_end - 1) as Real + 0.5 + rng.uniform(0.8, 0.9);
            x.extend(rng.vec(3 * N, -1.0, 1.0));
            x.extend(rng.vec(N, 0.8, 1.2));
            x.extend(rng.vec(N, 0.5, 1.5));
            for _ in 0..NEIGHBOURHOOD_NODES {
                x.push(rng.uniform(0.5, 1.5));
                // new and old velocity, drifting along +x by about a quarter cell per step so that
                // particle 2 leaves the block (the stencil average of the noise is small)
                for channel in 0..6 {
                    x.push(rng.uniform(-1.0, 1.0) + if channel % 3 == 0 { 3.75 } else { 0.0 });
                }
            }
            x.extend([DT, DX]);
            let moved = v3s(&G2p { flip: 0.0, j_bar: false, use_forward: false }.forward(&x)[..3 * N]);
            let base = |p: usize| base_and_fx(moved[p]).0;
            let clear = moved.iter().all(|&m| face_distance(m) >= MARGIN);
            let mixed = base(0) == base(1) && cell_of(ORIGIN, moved[0]).is_some();
            if clear && mixed && base(2)[0] == block_end {
                return x;
            }
        }
        panic!("no admissible G2P case in 1000 draws");
    }

    fn loss(k: &impl Flat, x: &[Real], cot: &[Real]) -> Real {
        dot(cot, &k.forward(x))
    }

    /// Relative mismatch between the adjoint and fourth-order central differences along one random
    /// direction in each input group.
    fn group_errors(k: &impl Flat, x: &[Real], rng: &mut Rng) -> Vec<Real> {
        let cot = rng.vec(k.forward(x).len(), -1.0, 1.0);
        let grad = k.adjoint(x, &cot, &vec![0.0; x.len()]);
        k.groups()
            .iter()
            .map(|g| {
                let mut d = vec![0.0; x.len()];
                for i in g.range.clone() {
                    d[i] = rng.direction(g.scale);
                }
                let at = |h: Real| k.forward(&axpy(x, h, &d));
                let (p1, m1, p2, m2) = (at(H), at(-H), at(2.0 * H), at(-2.0 * H));
                // difference each output before weighting, so large outputs (positions) cancel
                // exactly instead of leaving their rounding in the sum
                let fd = (0..cot.len())
                    .map(|i| cot[i] * (8.0 * (p1[i] - m1[i]) - (p2[i] - m2[i])))
                    .sum::<Real>()
                    / (12.0 * H);
                let ad = dot(&grad, &d);
                // both exactly zero for inputs the configuration ignores
                if fd == ad {
                    0.0
                } else {
                    (fd - ad).abs() / fd.abs().max(ad.abs())
                }
            })
            .collect()
    }

    fn check_central_differences(label: &str, k: &impl Flat, point: fn(&mut Rng) -> Vec<Real>, seed: u64) {
        let mut rng = Rng(seed);
        let groups = k.groups();
        let mut worst = vec![0.0 as Real; groups.len()];
        for _ in 0..CASES {
            let x = point(&mut rng);
            for (w, e) in worst.iter_mut().zip(group_errors(k, &x, &mut rng)) {
                *w = w.max(e);
            }
        }
        let report: Vec<String> = groups.iter().zip(&worst).map(|(g, e)| format!("{} {e:.1e}", g.name)).collect();
        println!("{label}: max relative error {}", report.join(", "));
        assert!(worst.iter().all(|&e| e <= TOL), "{label}: {}", report.join(", "));
    }

    /// Log-log slope of `|f(x + h d) - f(x) - h <grad, d>|` over h = 1e-2 .. 1e-4.
    fn taylor_slope(k: &impl Flat, x: &[Real], rng: &mut Rng) -> Real {
        let cot = rng.vec(k.forward(x).len(), -1.0, 1.0);
        let grad = k.adjoint(x, &cot, &vec![0.0; x.len()]);
        let mut d = vec![0.0; x.len()];
        for g in k.groups() {
            for i in g.range {
                d[i] = rng.direction(g.scale);
            }
        }
        let (f0, slope) = (loss(k, x, &cot), dot(&grad, &d));
        let points: Vec<(Real, Real)> = (0..=8)
            .map(|i| {
                let h = (10.0 as Real).powf(-2.0 - 0.25 * i as Real);
                let remainder = (loss(k, &axpy(x, h, &d), &cot) - f0 - h * slope).abs();
                (h.ln(), remainder.ln())
            })
            .collect();
        let n = points.len() as Real;
        let (mx, my) = (points.iter().map(|p| p.0).sum::<Real>() / n, points.iter().map(|p| p.1).sum::<Real>() / n);
        let sxy: Real = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let sxx: Real = points.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
        sxy / sxx
    }

    #[test]
    fn p2g_adjoint_matches_central_differences() {
        check_central_differences("p2g folded", &P2g::<false>, p2g_point, 1);
    }

    #[test]
    fn p2g_split_adjoint_matches_central_differences() {
        check_central_differences("p2g split", &P2g::<true>, p2g_point, 2);
    }

    #[test]
    fn g2p_apic_adjoint_matches_central_differences() {
        check_central_differences("g2p apic", &G2p { flip: 0.0, j_bar: false, use_forward: false }, g2p_point, 3);
        check_central_differences("g2p apic, forward outputs", &G2p { flip: 0.0, j_bar: false, use_forward: true }, g2p_point, 3);
    }

    #[test]
    fn g2p_flip_adjoint_matches_central_differences() {
        check_central_differences("g2p flip", &G2p { flip: 0.95, j_bar: false, use_forward: false }, g2p_point, 4);
    }

    #[test]
    fn g2p_apic_j_bar_adjoint_matches_central_differences() {
        check_central_differences("g2p apic j-bar", &G2p { flip: 0.0, j_bar: true, use_forward: false }, g2p_point, 5);
        check_central_differences("g2p apic j-bar, forward outputs", &G2p { flip: 0.0, j_bar: true, use_forward: true }, g2p_point, 5);
    }

    #[test]
    fn g2p_flip_j_bar_adjoint_matches_central_differences() {
        check_central_differences("g2p flip j-bar", &G2p { flip: 0.95, j_bar: true, use_forward: false }, g2p_point, 6);
    }

    #[test]
    fn p2g_taylor_remainder_is_second_order() {
        let mut rng = Rng(7);
        let x = p2g_point(&mut rng);
        let slope = taylor_slope(&P2g::<true>, &x, &mut rng);
        println!("p2g split: Taylor slope {slope:.3}");
        assert!((slope - 2.0).abs() <= 0.1, "slope {slope}");
    }

    #[test]
    fn g2p_taylor_remainder_is_second_order() {
        let mut rng = Rng(8);
        let x = g2p_point(&mut rng);
        let slope = taylor_slope(&G2p { flip: 0.95, j_bar: true, use_forward: false }, &x, &mut rng);
        println!("g2p flip j-bar: Taylor slope {slope:.3}");
        assert!((slope - 2.0).abs() <= 0.1, "slope {slope}");
    }

    /// The adjoint must put particles in the J-bar cells the forward put them in; this fails as
    /// soon as the arithmetic of g2p_block changes without g2p_particle following it.
    #[test]
    fn g2p_recomputation_is_bit_identical_to_the_forward() {
        let mut rng = Rng(10);
        let kernel = G2p { flip: 0.0, j_bar: false, use_forward: false };
        let x = g2p_point(&mut rng);
        let after = kernel.forward(&x);
        let g = kernel.groups();
        let (xg, j, local) = (v3s(&x[g[0].range.clone()]), &x[g[2].range.clone()], nodes(&x[g[4].range.clone()]));
        for p in 0..N {
            let recomputed = g2p_particle(ORIGIN, &local, &TransferParams { dt: DT, dx: DX }, xg[p]);
            assert_eq!(recomputed.xg_new.to_array().as_slice(), &after[3 * p..3 * p + 3]);
            assert_eq!(j[p] * (1.0 + DT * recomputed.tr_c), after[15 * N + p]);
        }
    }

    /// The copies the CPU dispatches to (AVX2 where it has it) give the baseline copies' bits,
    /// for every variant of both adjoints, at scattered points, output adjoints and
    /// accumulators.
    #[test]
    fn dispatched_adjoints_give_the_baseline_bits() {
        let g2p = |flip: Real, j_bar: bool, use_forward: bool| G2p { flip, j_bar, use_forward };
        type Point = fn(&mut Rng) -> Vec<Real>;
        let kernels: [(&dyn Flat, Point); 8] = [
            (&P2g::<false>, p2g_point),
            (&P2g::<true>, p2g_point),
            (&g2p(0.0, false, false), g2p_point),
            (&g2p(0.0, false, true), g2p_point),
            (&g2p(0.95, false, false), g2p_point),
            (&g2p(0.0, true, false), g2p_point),
            (&g2p(0.0, true, true), g2p_point),
            (&g2p(0.95, true, false), g2p_point),
        ];
        let mut rng = Rng(11);
        let bits = |x: &[Real]| x.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
        for (k, (kernel, point)) in kernels.iter().enumerate() {
            for _ in 0..4 {
                let x = point(&mut rng);
                let cot = rng.vec(kernel.forward(&x).len(), -1.0, 1.0);
                let acc = rng.vec(x.len(), -1.0, 1.0);
                let dispatched = kernel.adjoint(&x, &cot, &acc);
                BASELINE.set(true);
                let baseline = kernel.adjoint(&x, &cot, &acc);
                BASELINE.set(false);
                assert!(bits(&dispatched) == bits(&baseline), "kernel {k}: the dispatched copy's bits differ");
            }
        }
    }

    /// Adjoints add to what their outputs already hold: a second call doubles the first.
    #[test]
    fn adjoints_accumulate_into_their_outputs() {
        fn doubles(k: &impl Flat, x: &[Real], rng: &mut Rng) {
            let cot = rng.vec(k.forward(x).len(), -1.0, 1.0);
            let once = k.adjoint(x, &cot, &vec![0.0; x.len()]);
            let twice = k.adjoint(x, &cot, &once);
            let scale = once.iter().fold(0.0 as Real, |m, g| m.max(g.abs()));
            assert!(scale > 0.0);
            for (t, o) in twice.iter().zip(&once) {
                assert!((t - 2.0 * o).abs() <= 1e-14 * scale, "{t} vs 2 x {o}");
            }
        }
        let mut rng = Rng(9);
        let x = p2g_point(&mut rng);
        doubles(&P2g::<true>, &x, &mut rng);
        let x = g2p_point(&mut rng);
        doubles(&G2p { flip: 0.95, j_bar: true, use_forward: false }, &x, &mut rng);
    }
}
