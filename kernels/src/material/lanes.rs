//! 3x3 matrices of W particles, each entry one 256-bit register of [`crate::wide`] (4 particles
//! in f64, 8 in f32): the matrix algebra of `real.rs` lane by lane, for the materials' updates in
//! lanes (`drucker_prager_lanes.rs`, `evp_bingham_lanes.rs`).
//!
//! Every function performs, in each lane, the IEEE operations of its one-particle counterpart in
//! the same order, glam's included (no FMA; sums in the same order; a diagonal matrix added or
//! subtracted as glam does, zeros and all), so a lane holds the bits the one-particle code
//! computes. They are plain loops without closures, so that every register operation inlines
//! into the AVX2 caller (a closure is compiled on its own, without AVX2, and its intrinsics
//! become calls).

use crate::material::Eos;
use crate::real::{r, Real, M3};
use crate::wide::{R, W};

/// A 3x3 matrix of W lanes, `m[col][row]` as glam's columns.
pub(crate) type Lm = [[R; 3]; 3];

#[inline(always)]
pub(crate) fn zeros() -> Lm {
    [[R::splat(r(0.0)); 3]; 3]
}

#[inline(always)]
pub(crate) fn add(a: &Lm, b: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] + b[c][row];
        }
    }
    m
}

#[inline(always)]
pub(crate) fn sub(a: &Lm, b: &Lm) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] - b[c][row];
        }
    }
    m
}

#[inline(always)]
pub(crate) fn scale(a: &Lm, s: R) -> Lm {
    let mut m = zeros();
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = a[c][row] * s;
        }
    }
    m
}

#[inline(always)]
pub(crate) fn transpose(a: &Lm) -> Lm {
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
pub(crate) fn mul(a: &Lm, b: &Lm) -> Lm {
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
pub(crate) fn diagonal(x: R) -> Lm {
    let mut m = zeros();
    for (c, col) in m.iter_mut().enumerate() {
        col[c] = x;
    }
    m
}

/// `real::trace`.
#[inline(always)]
pub(crate) fn trace(a: &Lm) -> R {
    a[0][0] + a[1][1] + a[2][2]
}

/// `real::ddot`: column dots summed over the columns.
#[inline(always)]
pub(crate) fn ddot(a: &Lm, b: &Lm) -> R {
    let dx = a[0][0] * b[0][0] + a[0][1] * b[0][1] + a[0][2] * b[0][2];
    let dy = a[1][0] * b[1][0] + a[1][1] * b[1][1] + a[1][2] * b[1][2];
    let dz = a[2][0] * b[2][0] + a[2][1] * b[2][1] + a[2][2] * b[2][2];
    dx + dy + dz
}

/// `real::dev`: the matrix less the diagonal of its trace over three.
#[inline(always)]
pub(crate) fn dev(a: &Lm) -> Lm {
    sub(a, &diagonal(trace(a) / R::splat(r(3.0))))
}

/// `real::sym`.
#[inline(always)]
pub(crate) fn sym(a: &Lm) -> Lm {
    scale(&add(a, &transpose(a)), R::splat(r(0.5)))
}

/// `real::skew`.
#[inline(always)]
pub(crate) fn skew(a: &Lm) -> Lm {
    scale(&sub(a, &transpose(a)), R::splat(r(0.5)))
}

/// `real::jaumann_rotation` of the spin `w` over `dt`.
#[inline(always)]
pub(crate) fn jaumann_rotation(w: &Lm, dt: Real) -> Lm {
    let a = scale(w, R::splat(r(0.5) * dt));
    let a2 = mul(&a, &a);
    let norm2 = R::splat(r(0.5)) * ddot(&a, &a);
    let f = R::splat(r(2.0)) / (R::splat(r(1.0)) + norm2);
    add(&diagonal(R::splat(r(1.0))), &scale(&add(&a, &a2), f))
}

/// `real::sym_to_array`: `[xx, yy, zz, xy, yz, xz]`, off-diagonals averaged.
#[inline(always)]
pub(crate) fn sym_packed(m: &Lm) -> [R; 6] {
    let h = R::splat(r(0.5));
    [m[0][0], m[1][1], m[2][2], h * (m[1][0] + m[0][1]), h * (m[2][1] + m[1][2]), h * (m[2][0] + m[0][2])]
}

/// The matrices of W particles (`m.len() == W`), lane l holding `m[l]`.
#[inline(always)]
pub(crate) fn load_matrices(m: &[M3]) -> Lm {
    let mut lanes = [[r(0.0); W]; 9];
    for (l, m) in m[..W].iter().enumerate() {
        for (i, x) in m.to_cols_array().into_iter().enumerate() {
            lanes[i][l] = x;
        }
    }
    let mut out = zeros();
    for c in 0..3 {
        for row in 0..3 {
            out[c][row] = R::from_array(lanes[3 * c + row]);
        }
    }
    out
}

/// Writes lane l of `a` to `m[l]` (`m.len() == W`).
#[inline(always)]
pub(crate) fn store_matrices(a: &Lm, m: &mut [M3]) {
    let mut lanes = [[r(0.0); W]; 9];
    for c in 0..3 {
        for row in 0..3 {
            lanes[3 * c + row] = a[c][row].to_array();
        }
    }
    for (l, m) in m[..W].iter_mut().enumerate() {
        let mut cols = [r(0.0); 9];
        for (i, x) in cols.iter_mut().enumerate() {
            *x = lanes[i][l];
        }
        *m = M3::from_cols_array(&cols);
    }
}

/// `real::sym_from_slice` of the first six reals of W state rows of `stride` reals.
#[inline(always)]
pub(crate) fn load_sym(state: &[Real], stride: usize) -> Lm {
    let mut s6 = [[r(0.0); W]; 6];
    for l in 0..W {
        for i in 0..6 {
            s6[i][l] = state[l * stride + i];
        }
    }
    let s = [R::from_array(s6[0]), R::from_array(s6[1]), R::from_array(s6[2]), R::from_array(s6[3]), R::from_array(s6[4]), R::from_array(s6[5])];
    [[s[0], s[3], s[5]], [s[3], s[1], s[4]], [s[5], s[4], s[2]]]
}

/// Column `i` of W state rows of `stride` reals, one lane each.
#[inline(always)]
pub(crate) fn load_column(state: &[Real], stride: usize, i: usize) -> R {
    let mut a = [r(0.0); W];
    for (l, a) in a.iter_mut().enumerate() {
        *a = state[l * stride + i];
    }
    R::from_array(a)
}

/// `Eos::pressure(k, j[l])` of W particles (`j.len() == W`): the linear EOS in lanes, Tait's
/// exponential lane by lane through the one-particle code.
#[inline(always)]
pub(crate) fn pressure(eos: Eos, k: Real, j: &[Real]) -> R {
    let mut jl = [r(0.0); W];
    jl.copy_from_slice(&j[..W]);
    match eos {
        Eos::Linear => R::splat(k) * (R::splat(r(1.0)) / R::from_array(jl) - R::splat(r(1.0))),
        eos => {
            let mut p = [r(0.0); W];
            for l in 0..W {
                p[l] = eos.pressure(k, jl[l]);
            }
            R::from_array(p)
        }
    }
}
