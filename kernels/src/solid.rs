//! Contact of grid nodes with solid bodies inside the domain (issue 30).
//!
//! A solid is a signed distance `phi` (negative inside the solid) and the unit normal `n`
//! pointing from the material into the solid (`-grad phi`). A node takes the solid's contact
//! condition ([`WallKind`], relative to the solid's velocity) in proportion to the smoothed
//! indicator `w(phi)`:
//!
//! ```text
//! v' = w(phi) wall(v) + (1 - w(phi)) v
//! w(phi) = 1                                   phi <= 0   (on or inside the solid)
//!          1 - t^2 (3 - 2t),  t = phi / delta   0 < phi < delta
//!          0                                   phi >= delta
//! ```
//!
//! Nodes on the surface take the whole condition, as nodes on a domain wall do; the band of
//! width `delta` outside it blends, so the node velocities, and everything downstream, are
//! differentiable in the solid's position (the polynomial of paper 000 eqs. 23-24). `delta = 0`
//! is the hard indicator `phi <= 0`.

use crate::boundary::{apply_wall, WallKind};
use crate::real::{r, Real, V3};

/// The indicator `w(phi)` and its slope `dw/dphi` for band width `delta` (0: hard).
#[inline]
pub fn indicator(phi: Real, delta: Real) -> (Real, Real) {
    if phi <= r(0.0) {
        return (r(1.0), r(0.0));
    }
    if delta <= r(0.0) || phi >= delta {
        return (r(0.0), r(0.0));
    }
    let t = phi / delta;
    (r(1.0) - t * t * (r(3.0) - r(2.0) * t), -r(6.0) * t * (r(1.0) - t) / delta)
}

/// Adjoint of [`indicator`]: dJ/dphi for dJ/dw.
#[inline]
pub fn indicator_adjoint(phi: Real, delta: Real, w_bar: Real) -> Real {
    w_bar * indicator(phi, delta).1
}

/// One node's contact with a solid: `v' = w wall(v) + (1 - w) v` (module docs).
#[inline]
pub fn contact(kind: WallKind, phi: Real, delta: Real, normal: V3, v_solid: V3, v: V3) -> V3 {
    let (w, _) = indicator(phi, delta);
    if w <= r(0.0) {
        return v;
    }
    apply_wall(kind, normal, v_solid, v) * w + v * (r(1.0) - w)
}

/// Adjoints of [`contact`]'s inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactBar {
    pub v: V3,
    pub phi: Real,
    pub normal: V3,
    pub v_solid: V3,
    /// Of the Coulomb coefficient (0 for the other kinds).
    pub mu: Real,
}

/// Adjoint of [`contact`] for the adjoint `out_bar` of its result. The branch the forward took
/// (into the solid or not, sliding or sticking) is held fixed, as in `boundary::apply_wall_adjoint`.
#[inline]
pub fn contact_adjoint(kind: WallKind, phi: Real, delta: Real, normal: V3, v_solid: V3, v: V3, out_bar: V3) -> ContactBar {
    let (w, slope) = indicator(phi, delta);
    if w <= r(0.0) {
        return ContactBar { v: out_bar, phi: r(0.0), normal: V3::ZERO, v_solid: V3::ZERO, mu: r(0.0) };
    }
    let walled = apply_wall(kind, normal, v_solid, v);
    let phi_bar = out_bar.dot(walled - v) * slope;
    let (rel_bar, normal_bar, mu_bar) = wall_adjoint(kind, normal, v - v_solid, out_bar * w);
    ContactBar { v: rel_bar + out_bar * (r(1.0) - w), phi: phi_bar, normal: normal_bar, v_solid: out_bar * w - rel_bar, mu: mu_bar }
}

/// Adjoint of `apply_wall(kind, n, 0, rel)` in `rel`, `n` and mu, for the adjoint `b` of its
/// result (the normal's adjoint is what `apply_wall_adjoint` leaves out: a curved or moving
/// solid's normal depends on its position).
fn wall_adjoint(kind: WallKind, n: V3, rel: V3, b: V3) -> (V3, V3, Real) {
    let vn = rel.dot(n);
    // out = vt keep with vt = rel - n vn: given vt_bar and the direct vn_bar, the adjoints of rel
    // and n follow from vn = rel . n
    let through = |vt_bar: V3, vn_bar: Real| {
        let vn_total = vn_bar - n.dot(vt_bar);
        (vt_bar + n * vn_total, rel * vn_total - vt_bar * vn)
    };
    match kind {
        WallKind::NoSlip => (V3::ZERO, V3::ZERO, r(0.0)),
        WallKind::FreeSlip if vn > r(0.0) => {
            let (a, nb) = through(b, r(0.0));
            (a, nb, r(0.0))
        }
        WallKind::FreeSlip => (b, V3::ZERO, r(0.0)),
        WallKind::Symmetry => {
            let (a, nb) = through(b, r(0.0));
            (a, nb, r(0.0))
        }
        WallKind::Friction { mu } => {
            if vn <= r(0.0) {
                return (b, V3::ZERO, r(0.0));
            }
            let vt = rel - n * vn;
            let len = vt.length();
            let keep = if len > r(0.0) { r(1.0) - r(mu) * vn / len } else { r(0.0) };
            if keep <= r(0.0) {
                return (V3::ZERO, V3::ZERO, r(0.0));
            }
            let keep_bar = vt.dot(b);
            let len_bar = keep_bar * r(mu) * vn / (len * len);
            let vt_bar = b * keep + vt * (len_bar / len);
            let (a, nb) = through(vt_bar, -keep_bar * r(mu) / len);
            (a, nb, -keep_bar * vn / len)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indicator_is_one_on_the_surface_and_zero_beyond_the_band() {
        assert_eq!(indicator(r(-0.3), r(0.01)), (r(1.0), r(0.0)));
        assert_eq!(indicator(r(0.0), r(0.01)).0, r(1.0));
        assert_eq!(indicator(r(0.01), r(0.01)).0, r(0.0));
        assert!((indicator(r(0.005), r(0.01)).0 - r(0.5)).abs() < r(1e-6));
        // hard: on or inside only
        assert_eq!(indicator(r(0.0), r(0.0)).0, r(1.0));
        assert_eq!(indicator(r(1e-9), r(0.0)).0, r(0.0));
    }

    #[test]
    fn contact_blends_between_the_condition_and_the_free_node() {
        let n = V3::new(0.0, 0.0, -1.0);
        let v = V3::new(1.0, 0.0, -0.5);
        assert_eq!(contact(WallKind::NoSlip, r(-0.1), r(0.01), n, V3::ZERO, v), V3::ZERO);
        assert_eq!(contact(WallKind::NoSlip, r(0.02), r(0.01), n, V3::ZERO, v), v);
        let half = contact(WallKind::NoSlip, r(0.005), r(0.01), n, V3::ZERO, v);
        assert!((half - v * r(0.5)).length() < r(1e-6));
        // a moving solid: no-slip takes its velocity
        let vs = V3::new(0.2, 0.0, 0.0);
        assert_eq!(contact(WallKind::NoSlip, r(-0.1), r(0.01), n, vs, v), vs);
    }

    /// Every kind and branch, inside the solid and in the band, against central differences of
    /// <out_bar, contact> in v, v_solid, the normal (as a free vector), phi and mu.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn contact_adjoint_matches_central_differences() {
        let n = V3::new(0.0, 0.6, -0.8);
        let vs = V3::new(0.1, -0.05, 0.02);
        let bar = V3::new(0.7, -1.3, 0.4);
        let into = V3::new(1.0, 0.4, -0.6);
        let away = V3::new(1.0, -0.4, 0.6);
        let delta = 0.01;
        let kinds = [WallKind::NoSlip, WallKind::FreeSlip, WallKind::Symmetry, WallKind::Friction { mu: 0.3 }, WallKind::Friction { mu: 5.0 }];
        let h = 1e-7;
        let mut checked_phi = false;
        for kind in kinds {
            for v in [into, away] {
                for phi in [-0.02, 0.0031, 0.0077] {
                    let ad = contact_adjoint(kind, phi, delta, n, vs, v, bar);
                    let loss = |kind: WallKind, phi: f64, n: V3, vs: V3, v: V3| contact(kind, phi, delta, n, vs, v).dot(bar);
                    let close = |a: f64, fd: f64, what: &str| {
                        assert!((a - fd).abs() <= 1e-6 * (1.0 + fd.abs()), "{kind:?} v {v:?} phi {phi}: d/d{what} {a} against {fd}")
                    };
                    for c in 0..3 {
                        let mut e = V3::ZERO;
                        e[c] = h;
                        close(ad.v[c], (loss(kind, phi, n, vs, v + e) - loss(kind, phi, n, vs, v - e)) / (2.0 * h), "v");
                        close(ad.v_solid[c], (loss(kind, phi, n, vs + e, v) - loss(kind, phi, n, vs - e, v)) / (2.0 * h), "v_solid");
                        close(ad.normal[c], (loss(kind, phi, n + e, vs, v) - loss(kind, phi, n - e, vs, v)) / (2.0 * h), "normal");
                    }
                    close(ad.phi, (loss(kind, phi + h, n, vs, v) - loss(kind, phi - h, n, vs, v)) / (2.0 * h), "phi");
                    checked_phi |= ad.phi.abs() > 1.0;
                    if let WallKind::Friction { mu } = kind {
                        let fd = (loss(WallKind::Friction { mu: mu + h }, phi, n, vs, v) - loss(WallKind::Friction { mu: mu - h }, phi, n, vs, v)) / (2.0 * h);
                        close(ad.mu, fd, "mu");
                    }
                }
            }
        }
        assert!(checked_phi, "the band's phi derivative was never exercised");
    }

    #[cfg(not(feature = "f32"))]
    #[test]
    fn indicator_adjoint_matches_central_differences() {
        let delta = 0.004;
        for k in 1..40 {
            let phi = delta * k as f64 / 40.0;
            let h = 1e-9;
            let fd = (indicator(phi + h, delta).0 - indicator(phi - h, delta).0) / (2.0 * h);
            let ad = indicator_adjoint(phi, delta, 1.0);
            assert!((ad - fd).abs() <= 1e-6 * fd.abs().max(1.0), "phi {phi}: {ad} against {fd}");
        }
    }
}
