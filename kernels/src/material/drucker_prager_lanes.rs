//! The elastic step of `drucker_prager.rs`'s return map for W particles at once, each in a lane
//! of a 256-bit register (4 particles in f64, 8 in f32), for CPUs with AVX2
//! (`drucker_prager::return_map_batch` runs it).
//!
//! Why the elastic step: a printed wall is elastic almost everywhere, and that part of the scalar
//! return map is a chain of dependent operations (a division for the mean stress, the Jaumann
//! rotation's division, a square root) that one particle at a time cannot overlap. The lanes
//! compute the trial stress and test it against the cone and the cutoff; a lane whose trial is
//! elastic is written, every other lane (plastic, or not finite) is left to the one-particle
//! return map, which computes its trial afresh. Every lane performs the one-particle code's IEEE
//! operations in the same order, glam's included (no FMA; sums in the same order; a diagonal
//! matrix added as glam adds it, zeros and all), so a written lane holds the bits the one-particle
//! return map would leave.

use crate::material::lanes::{add, ddot, dev, diagonal, jaumann_rotation, load_matrices, load_sym, mul, scale, skew, store_matrices, sym, sym_packed, trace, transpose};
use crate::real::{r, Real, M3};
use crate::wide::{R, W};

/// The return map's constants that the elastic step reads, one array of W lanes each.
pub(crate) struct ElasticConsts {
    pub(crate) k: [Real; W],
    pub(crate) g: [Real; W],
    pub(crate) q_phi: [Real; W],
    pub(crate) k_phi: [Real; W],
    pub(crate) sigma_t: [Real; W],
}

/// The elastic steps of W particles: `grad_v` and `stress` of length W, `state` W rows of
/// `stride` (stress and eps_p first). Where a lane's trial stress is elastic, writes its stress
/// to its row and to `stress` as the return map would; returns the mask of those lanes (bit l
/// for lane l) and leaves the other lanes' rows and `stress` as they were.
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn elastic_steps(c: &ElasticConsts, grad_v: &[M3], dt: Real, state: &mut [Real], stride: usize, stress: &mut [M3]) -> u32 {
    let l_m = load_matrices(grad_v);
    let sigma_old = load_sym(state, stride);
    let (k, g) = (R::from_array(c.k), R::from_array(c.g));

    // drucker_prager::trial
    let d = sym(&l_m);
    let rot = jaumann_rotation(&skew(&l_m), dt);
    let rsr = mul(&mul(&rot, &sigma_old), &transpose(&rot));
    let dev_term = scale(&dev(&d), R::splat(r(2.0)) * g * R::splat(dt));
    let vol_term = diagonal(k * trace(&d) * R::splat(dt));
    let sigma_tr = add(&add(&sym(&rsr), &dev_term), &vol_term);

    // return_map's elastic test
    let sm_tr = trace(&sigma_tr) / R::splat(r(3.0));
    let s_tr = dev(&sigma_tr);
    let tau_tr = (R::splat(r(0.5)) * ddot(&s_tr, &s_tr)).sqrt();
    let f_s = tau_tr + R::from_array(c.q_phi) * sm_tr - R::from_array(c.k_phi);
    let f_t = sm_tr - R::from_array(c.sigma_t);
    let zero = R::splat(r(0.0));
    let elastic = f_t.lt_mask(zero) & f_s.le_mask(zero);

    // sym_to_array, and the matrix
    let packed = sym_packed(&sigma_tr);
    let mut rows = [[r(0.0); W]; 6];
    for (i, p) in packed.into_iter().enumerate() {
        rows[i] = p.to_array();
    }
    let mut matrices = [M3::ZERO; W];
    store_matrices(&sigma_tr, &mut matrices);
    for l in 0..W {
        if elastic & (1 << l) == 0 {
            continue;
        }
        for i in 0..6 {
            state[l * stride + i] = rows[i][l];
        }
        stress[l] = matrices[l];
    }
    elastic
}
