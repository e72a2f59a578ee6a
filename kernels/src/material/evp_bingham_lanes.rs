//! `evp_bingham.rs`'s update for W particles at once, each in a lane of a 256-bit register (4
//! particles in f64, 8 in f32), for CPUs with AVX2 (`EvpBingham::update_batch` runs it), in the
//! material's plain form: Bingham's flow rule (`flow_index` 1), no Maxwell branch, no age law.
//!
//! Why: the update is most of a printed line's material phase (a third of its step, measured on
//! the user-style line), and one particle at a time it is a chain of dependent long operations
//! (the deviator's division by three, the Jaumann rotation's division, the square roots of the
//! trial stress and of the return map's root, its divisions) that cannot overlap. In lanes both
//! branches, elastic and plastic, are computed for every lane and each lane keeps its own; every
//! lane performs the one-particle update's IEEE operations in the same order, glam's included
//! (no FMA; sums in the same order), so each lane holds the bits `EvpBingham::update` leaves.
//! The Tait EOS's exponential runs lane by lane through the one-particle code.

use crate::material::lanes::{add, ddot, dev, diagonal, jaumann_rotation, load_column, load_matrices, load_sym, mul, pressure, scale, skew, store_matrices, sub, sym, sym_packed, transpose};
use crate::material::Eos;
use crate::real::{r, Real, M3};
use crate::wide::{R, W};

/// The constants of a batch's update: shear modulus, viscosity, yield stress, alpha, the
/// build-up rate A_thix / tau0, the bulk modulus and the EOS.
pub(crate) struct Consts {
    pub(crate) g: Real,
    pub(crate) eta: Real,
    pub(crate) tau0: Real,
    pub(crate) alpha: Real,
    pub(crate) build_up_rate: Real,
    pub(crate) k: Real,
    pub(crate) eos: Eos,
}

/// The updates of W particles: `grad_v`, `j` and `stress` of length W, `state` W rows of
/// `stride` reals (`[s (6), lambda, gamma_p]` first).
///
/// # Safety
/// The CPU has AVX2.
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn updates(c: &Consts, grad_v: &[M3], j: &[Real], dt: Real, state: &mut [Real], stride: usize, stress: &mut [M3]) {
    let splat = R::splat;
    let (one, two, zero) = (splat(r(1.0)), splat(r(2.0)), splat(r(0.0)));
    let (g, eta, tau0, alpha) = (splat(c.g), splat(c.eta), splat(c.tau0), splat(c.alpha));
    let l_m = load_matrices(grad_v);
    let s_old = load_sym(state, stride);

    // trial_deviator
    let rot = jaumann_rotation(&skew(&l_m), dt);
    let rsr = mul(&mul(&rot, &s_old), &transpose(&rot));
    let s_tr = add(&dev(&sym(&rsr)), &scale(&dev(&sym(&l_m)), splat(r(2.0) * c.g * dt)));
    let lambda_tr = load_column(state, stride, 6) + splat(c.build_up_rate * dt);
    let tau_tr = (splat(r(0.5)) * ddot(&s_tr, &s_tr)).sqrt();
    let f_tr = tau_tr - (one + lambda_tr) * tau0;
    let plastic = zero.lt_mask(f_tr);

    // the return map (plastic_shear_rate), in every lane; each lane keeps its branch
    let mut s = s_tr;
    let mut lambda = lambda_tr;
    let mut gamma_p_dt = [r(0.0); W];
    if plastic != 0 {
        let dt_r = splat(dt);
        let xi = eta + dt_r * (g + alpha * (tau0 - tau_tr));
        let zeta = two * alpha * dt_r * (dt_r * g + eta);
        let root = (xi * xi + two * zeta * f_tr).sqrt();
        let gamma_p = R::select(zero.lt_mask(xi), two * f_tr / (xi + root), (root - xi) / zeta);
        let tau = tau_tr - dt_r * g * gamma_p;
        let ratio = tau / tau_tr;
        for col in 0..3 {
            for row in 0..3 {
                s[col][row] = R::select(plastic, s_tr[col][row] * ratio, s_tr[col][row]);
            }
        }
        lambda = R::select(plastic, lambda_tr / (one + dt_r * alpha * gamma_p), lambda_tr);
        gamma_p_dt = (gamma_p * dt_r).to_array();
    }

    // the state, and the stress s - p I
    let packed = sym_packed(&s);
    let mut rows = [[r(0.0); W]; 6];
    for (i, p) in packed.into_iter().enumerate() {
        rows[i] = p.to_array();
    }
    let lambda = lambda.to_array();
    for l in 0..W {
        let row = &mut state[l * stride..l * stride + 8];
        for i in 0..6 {
            row[i] = rows[i][l];
        }
        row[6] = lambda[l];
        if plastic & (1 << l) != 0 {
            row[7] += gamma_p_dt[l];
        }
    }
    let p = pressure(c.eos, c.k, j);
    store_matrices(&sub(&s, &diagonal(p)), stress);
}
