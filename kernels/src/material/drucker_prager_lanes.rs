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

use crate::real::{r, Real, M3, V3};
use crate::wide::{R, W};

/// The return map's constants that the elastic step reads, one array of W lanes each.
pub(crate) struct ElasticConsts {
    pub(crate) k: [Real; W],
    pub(crate) g: [Real; W],
    pub(crate) q_phi: [Real; W],
    pub(crate) k_phi: [Real; W],
    pub(crate) sigma_t: [Real; W],
}

/// A 3x3 matrix of W lanes, `m[col][row]` as glam's columns. The helpers below are written as
/// plain loops without closures, so that every register operation inlines into the AVX2 caller
/// (a closure is compiled on its own, without AVX2, and its intrinsics become calls).
type Lm = [[R; 3]; 3];

#[inline(always)]
fn zeros() -> Lm {
    [[R::splat(r(0.0)); 3]; 3]
}

#[inline(always)]
fn add(a: &Lm, b: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] + b[c][row];
        }
    }
    m
}

#[inline(always)]
fn sub(a: &Lm, b: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] - b[c][row];
        }
    }
    m
}

#[inline(always)]
fn scale(a: &Lm, s: R) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] * s;
        }
    }
    m
}

#[inline(always)]
fn transpose(a: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[row][c];
        }
    }
    m
}

/// glam's product: column c of `a b` is ((a_x b_xc + a_y b_yc) + a_z b_zc).
#[inline(always)]
fn mul(a: &Lm, b: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[0][row] * b[c][0] + a[1][row] * b[c][1] + a[2][row] * b[c][2];
        }
    }
    m
}

/// `M3::from_diagonal(V3::splat(x))`.
#[inline(always)]
fn diagonal(x: R) -> Lm {
    let mut m = zeros();
    for (c, col) in m.iter_mut().enumerate() {
        col[c] = x;
    }
    m
}

/// `a.x_axis.x + a.y_axis.y + a.z_axis.z`.
#[inline(always)]
fn trace(a: &Lm) -> R {
    a[0][0] + a[1][1] + a[2][2]
}

/// Column dots summed over the columns, as `real::ddot`.
#[inline(always)]
fn ddot(a: &Lm, b: &Lm) -> R {
    let dx = a[0][0] * b[0][0] + a[0][1] * b[0][1] + a[0][2] * b[0][2];
    let dy = a[1][0] * b[1][0] + a[1][1] * b[1][1] + a[1][2] * b[1][2];
    let dz = a[2][0] * b[2][0] + a[2][1] * b[2][1] + a[2][2] * b[2][2];
    dx + dy + dz
}

/// `real::dev`: the matrix less the diagonal of its trace over three.
#[inline(always)]
fn dev(a: &Lm) -> Lm {
    sub(a, &diagonal(trace(a) / R::splat(r(3.0))))
}

/// `real::sym`.
#[inline(always)]
fn sym(a: &Lm) -> Lm {
    scale(&add(a, &transpose(a)), R::splat(r(0.5)))
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
    let mut lanes = [[r(0.0); W]; 9];
    for (l, m) in grad_v.iter().enumerate() {
        for (i, x) in m.to_cols_array().into_iter().enumerate() {
            lanes[i][l] = x;
        }
    }
    let mut l_m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            l_m[c][row] = R::from_array(lanes[3 * c + row]);
        }
    }
    // sym_from_slice: [xx, yy, zz, xy, yz, xz]
    let mut s6 = [[r(0.0); W]; 6];
    for l in 0..W {
        for i in 0..6 {
            s6[i][l] = state[l * stride + i];
        }
    }
    let s6 = [R::from_array(s6[0]), R::from_array(s6[1]), R::from_array(s6[2]), R::from_array(s6[3]), R::from_array(s6[4]), R::from_array(s6[5])];
    let sigma_old: Lm = [[s6[0], s6[3], s6[5]], [s6[3], s6[1], s6[4]], [s6[5], s6[4], s6[2]]];
    let (k, g) = (R::from_array(c.k), R::from_array(c.g));

    // drucker_prager::trial
    let d = sym(&l_m);
    let w = scale(&sub(&l_m, &transpose(&l_m)), R::splat(r(0.5)));
    // real::jaumann_rotation
    let a = scale(&w, R::splat(r(0.5) * dt));
    let a2 = mul(&a, &a);
    let norm2 = R::splat(r(0.5)) * ddot(&a, &a);
    let f = R::splat(r(2.0)) / (R::splat(r(1.0)) + norm2);
    let rot = add(&diagonal(R::splat(r(1.0))), &scale(&add(&a, &a2), f));
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
    let h = R::splat(r(0.5));
    let st = &sigma_tr;
    let packed = [st[0][0], st[1][1], st[2][2], h * (st[1][0] + st[0][1]), h * (st[2][1] + st[1][2]), h * (st[2][0] + st[0][2])];
    let mut out = [[r(0.0); W]; 15];
    for (i, p) in packed.into_iter().enumerate() {
        out[i] = p.to_array();
    }
    for c in 0..3 {
        for row in 0..3 {
            out[6 + 3 * c + row] = st[c][row].to_array();
        }
    }
    for l in 0..W {
        if elastic & (1 << l) == 0 {
            continue;
        }
        for i in 0..6 {
            state[l * stride + i] = out[i][l];
        }
        let col = |c: usize| V3::new(out[6 + 3 * c][l], out[7 + 3 * c][l], out[8 + 3 * c][l]);
        stress[l] = M3::from_cols(col(0), col(1), col(2));
    }
    elastic
}
