//! The floating-point type of the whole simulator: f64 by default, f32 with the `f32` feature.

#[cfg(not(feature = "f32"))]
mod imp {
    pub type Real = f64;
    pub type V3 = glam::DVec3;
    /// Accumulator vector of G2P's gather (glam has no SIMD f64 vector of 3).
    pub type V3A = glam::DVec3;
    pub type M3 = glam::DMat3;
    pub const NAME: &str = "f64";
}
#[cfg(feature = "f32")]
mod imp {
    pub type Real = f32;
    pub type V3 = glam::Vec3;
    /// Accumulator vector of G2P's gather: one SIMD register, the same IEEE
    /// operations lane by lane as `V3`, so results are bit-identical.
    pub type V3A = glam::Vec3A;
    pub type M3 = glam::Mat3;
    pub const NAME: &str = "f32";
}
pub use imp::*;

/// Convert an f64 literal or parameter into the working precision.
#[inline(always)]
pub fn r(x: f64) -> Real {
    x as Real
}

/// Symmetric part of a matrix.
#[inline]
pub fn sym(a: &M3) -> M3 {
    (*a + a.transpose()) * r(0.5)
}

/// Skew-symmetric part of a matrix.
#[inline]
pub fn skew(a: &M3) -> M3 {
    (*a - a.transpose()) * r(0.5)
}

/// Deviatoric part of a matrix.
#[inline]
pub fn dev(a: &M3) -> M3 {
    let tr = a.x_axis.x + a.y_axis.y + a.z_axis.z;
    *a - M3::from_diagonal(V3::splat(tr / r(3.0)))
}

#[inline]
pub fn trace(a: &M3) -> Real {
    a.x_axis.x + a.y_axis.y + a.z_axis.z
}

/// Double contraction A : B.
#[inline]
pub fn ddot(a: &M3, b: &M3) -> Real {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// Symmetric matrix packed as `[xx, yy, zz, xy, yz, xz]`, the order every stress-like particle
/// state uses. Off-diagonals are averaged so a slightly asymmetric input packs its symmetric part.
#[inline]
pub fn sym_to_array(m: &M3) -> [Real; 6] {
    let h = r(0.5);
    [
        m.x_axis.x,
        m.y_axis.y,
        m.z_axis.z,
        h * (m.y_axis.x + m.x_axis.y),
        h * (m.z_axis.y + m.y_axis.z),
        h * (m.z_axis.x + m.x_axis.z),
    ]
}

/// Adjoint of [`sym_to_array`]: the matrix adjoint for the adjoint `b` of the six entries (an
/// off-diagonal entry's adjoint splits half-half over its two places).
#[inline]
pub fn sym_to_array_adjoint(b: &[Real]) -> M3 {
    let h = r(0.5);
    M3::from_cols(
        V3::new(b[0], h * b[3], h * b[5]),
        V3::new(h * b[3], b[1], h * b[4]),
        V3::new(h * b[5], h * b[4], b[2]),
    )
}

/// Adjoint of [`sym_from_slice`]: adds the adjoint of the six entries for the matrix adjoint
/// `m` (an off-diagonal entry collects both of its places).
#[inline]
pub fn sym_from_slice_adjoint(m: &M3, b: &mut [Real]) {
    b[0] += m.x_axis.x;
    b[1] += m.y_axis.y;
    b[2] += m.z_axis.z;
    b[3] += m.x_axis.y + m.y_axis.x;
    b[4] += m.y_axis.z + m.z_axis.y;
    b[5] += m.x_axis.z + m.z_axis.x;
}

/// Inverse of [`sym_to_array`]; reads the first six entries of `v`.
#[inline]
pub fn sym_from_slice(v: &[Real]) -> M3 {
    M3::from_cols(
        V3::new(v[0], v[3], v[5]),
        V3::new(v[3], v[1], v[4]),
        V3::new(v[5], v[4], v[2]),
    )
}

/// Rotation increment of the Hughes-Winget integration of the Jaumann rate over a step:
/// R = (I - W dt/2)^-1 (I + W dt/2), evaluated in closed form as the Cayley transform
/// R = I + 2 (A + A^2) / (1 + |a|^2) with A = W dt/2 and a its axial vector.
///
/// `R s R^T` equals the explicit update `s + dt (W s - s W)` to first order in dt, but is an exact
/// rotation, so a rigid spin leaves the stress invariants unchanged to round-off however many steps
/// are taken (the explicit form inflates |s| by (1 + |W dt|^2) every step).
#[inline]
pub fn jaumann_rotation(w: &M3, dt: Real) -> M3 {
    let a = *w * (r(0.5) * dt);
    let a2 = a * a;
    // For skew A, A:A = 2 |a|^2.
    let norm2 = r(0.5) * ddot(&a, &a);
    M3::IDENTITY + (a + a2) * (r(2.0) / (r(1.0) + norm2))
}

/// Adjoint of [`jaumann_rotation`] with respect to `w` (dt held fixed), for the adjoint `r_bar`
/// of the rotation.
#[inline]
pub fn jaumann_rotation_adjoint(w: &M3, dt: Real, r_bar: &M3) -> M3 {
    let a = *w * (r(0.5) * dt);
    let a2 = a * a;
    let norm2 = r(0.5) * ddot(&a, &a);
    let c = r(2.0) / (r(1.0) + norm2);
    let sum_bar = *r_bar * c;
    let c_bar = ddot(r_bar, &(a + a2));
    let norm2_bar = -c_bar * r(2.0) / ((r(1.0) + norm2) * (r(1.0) + norm2));
    // d(a a) = da a + a da
    let a_bar = sum_bar + sum_bar * a.transpose() + a.transpose() * sum_bar + a * norm2_bar;
    a_bar * (r(0.5) * dt)
}

/// The adjoints above against central differences of <bar, f(x)> along each input entry.
#[cfg(all(test, not(feature = "f32")))]
mod tests {
    use super::*;

    const H: Real = 1e-6;

    fn m(v: [Real; 9]) -> M3 {
        M3::from_cols_array(&v)
    }

    #[test]
    fn rotation_adjoint_matches_central_differences() {
        let w = skew(&m([0.3, -2.0, 0.5, 3.0, -0.4, 1.2, -0.7, 0.9, 0.2])) * 40.0;
        let dt = 1e-2;
        let bar = m([0.7, -1.1, 0.4, 0.2, 0.9, -0.5, -0.3, 0.6, 1.3]);
        let w_bar = jaumann_rotation_adjoint(&w, dt, &bar);
        for k in 0..9 {
            let mut e = [0.0; 9];
            e[k] = H;
            let f = |s: Real| ddot(&bar, &jaumann_rotation(&(w + m(e) * s), dt));
            let fd = (f(1.0) - f(-1.0)) / (2.0 * H);
            let ad = w_bar.to_cols_array()[k];
            assert!((fd - ad).abs() <= 1e-8 * (1.0 + fd.abs()), "entry {k}: adjoint {ad}, central difference {fd}");
        }
    }

    #[test]
    fn packing_adjoints_are_the_transposes_of_the_packings() {
        // <b, sym_to_array(M)> = <sym_to_array_adjoint(b), M> and likewise for sym_from_slice,
        // for every unit input: both maps are linear, so this is the whole derivative
        let b = [0.7, -1.1, 0.4, 0.2, 0.9, -0.5];
        let dot6 = |a: [Real; 6]| a.iter().zip(&b).map(|(x, y)| x * y).sum::<Real>();
        let adj = sym_to_array_adjoint(&b);
        for k in 0..9 {
            let mut e = [0.0; 9];
            e[k] = 1.0;
            assert_eq!(dot6(sym_to_array(&m(e))), ddot(&adj, &m(e)), "entry {k}");
        }
        let mbar = m([0.7, -1.1, 0.4, 0.2, 0.9, -0.5, -0.3, 0.6, 1.3]);
        let mut back = [0.0; 6];
        sym_from_slice_adjoint(&mbar, &mut back);
        for k in 0..6 {
            let mut e = [0.0; 6];
            e[k] = 1.0;
            assert_eq!(ddot(&mbar, &sym_from_slice(&e)), back[k], "entry {k}");
        }
    }
}
