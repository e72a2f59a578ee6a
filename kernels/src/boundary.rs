//! Velocity conditions imposed on grid nodes at walls (paper 000 sec. 2.4, paper 002 eq. 35).
//!
//! A wall is described by its outward unit normal `n` (pointing out of the fluid, into the wall).
//! Conditions act on the node velocity after the momentum update:
//! * `NoSlip`   — the node moves with the wall: v = v_wall.
//! * `FreeSlip` — the normal component into the wall is removed; material may leave the wall.
//! * `Symmetry` — a mirror plane of a symmetric problem: the normal component is removed both
//!   ways, so material neither crosses the plane nor pulls away from it.
//! * `Friction` — Coulomb friction: the normal component into the wall is removed and the
//!   tangential speed reduced by mu times the removed normal speed, never reversing it.

use crate::real::{r, Real, V3};
use serde::Deserialize;

#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum WallKind {
    NoSlip,
    FreeSlip,
    Symmetry,
    Friction { mu: f64 },
}

/// Apply a wall condition to a node velocity `v` (relative to a wall moving with `v_wall`).
#[inline]
pub fn apply_wall(kind: WallKind, normal: V3, v_wall: V3, v: V3) -> V3 {
    let rel = v - v_wall;
    let out = match kind {
        WallKind::NoSlip => V3::ZERO,
        WallKind::FreeSlip => {
            let vn = rel.dot(normal);
            if vn > r(0.0) {
                rel - normal * vn
            } else {
                rel
            }
        }
        WallKind::Symmetry => rel - normal * rel.dot(normal),
        WallKind::Friction { mu } => {
            let vn = rel.dot(normal);
            if vn > r(0.0) {
                let vt = rel - normal * vn;
                let vt_len = vt.length();
                let keep = if vt_len > r(0.0) { (r(1.0) - r(mu) * vn / vt_len).max(r(0.0)) } else { r(0.0) };
                vt * keep
            } else {
                rel
            }
        }
    };
    out + v_wall
}

/// Adjoint of [`apply_wall`] for the adjoint `out_bar` of the result: the adjoints of `v` and of
/// the friction coefficient mu (0 for the other kinds). The wall velocity is held fixed, and so
/// is the branch the forward took (moving into the wall or not, sliding or sticking).
#[inline]
pub fn apply_wall_adjoint(kind: WallKind, normal: V3, v_wall: V3, v: V3, out_bar: V3) -> (V3, Real) {
    let rel = v - v_wall;
    let tangential = |b: V3| b - normal * normal.dot(b);
    match kind {
        WallKind::NoSlip => (V3::ZERO, r(0.0)),
        WallKind::FreeSlip if rel.dot(normal) > r(0.0) => (tangential(out_bar), r(0.0)),
        WallKind::FreeSlip => (out_bar, r(0.0)),
        WallKind::Symmetry => (tangential(out_bar), r(0.0)),
        WallKind::Friction { mu } => {
            let vn = rel.dot(normal);
            if vn <= r(0.0) {
                return (out_bar, r(0.0));
            }
            let vt = rel - normal * vn;
            let len = vt.length();
            let keep = if len > r(0.0) { r(1.0) - r(mu) * vn / len } else { r(0.0) };
            if keep <= r(0.0) {
                return (V3::ZERO, r(0.0));
            }
            // out = vt keep, keep = 1 - mu vn / |vt|
            let keep_bar = vt.dot(out_bar);
            let len_bar = keep_bar * r(mu) * vn / (len * len);
            let vt_bar = out_bar * keep + vt * (len_bar / len);
            let vn_bar = -keep_bar * r(mu) / len;
            (tangential(vt_bar) + normal * vn_bar, -keep_bar * vn / len)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions() {
        let n = V3::new(0.0, 0.0, -1.0); // floor: outward normal points down
        let v = V3::new(1.0, 0.0, -0.5);
        assert_eq!(apply_wall(WallKind::NoSlip, n, V3::ZERO, v), V3::ZERO);
        assert_eq!(apply_wall(WallKind::FreeSlip, n, V3::ZERO, v), V3::new(1.0, 0.0, 0.0));
        // leaving the wall is untouched
        let up = V3::new(1.0, 0.0, 0.5);
        assert_eq!(apply_wall(WallKind::FreeSlip, n, V3::ZERO, up), up);
        assert_eq!(apply_wall(WallKind::Friction { mu: 0.4 }, n, V3::ZERO, up), up);
        // a symmetry plane stops motion away from it too
        assert_eq!(apply_wall(WallKind::Symmetry, n, V3::ZERO, up), V3::new(1.0, 0.0, 0.0));
        assert_eq!(apply_wall(WallKind::Symmetry, n, V3::ZERO, v), V3::new(1.0, 0.0, 0.0));
        // Coulomb: tangential 1.0 reduced by 0.4 * 0.5
        let f = apply_wall(WallKind::Friction { mu: 0.4 }, n, V3::ZERO, v);
        assert!((f - V3::new(0.8, 0.0, 0.0)).length() < 1e-6);
        // large friction sticks, never reverses
        let f = apply_wall(WallKind::Friction { mu: 10.0 }, n, V3::ZERO, v);
        assert_eq!(f, V3::ZERO);
    }

    /// Every kind and branch against central differences of <out_bar, apply_wall>: moving into
    /// the wall and away from it, sliding and sticking under friction, and moving straight into
    /// it (no tangential velocity, the `vt_len > 0` guard). The points sit away from the kinks
    /// (rel . n = 0, keep = 0) by far more than the step.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_on_every_branch() {
        let n = V3::new(0.0, 0.6, -0.8);
        let vw = V3::new(0.1, -0.05, 0.02);
        let bar = V3::new(0.7, -1.3, 0.4);
        let into = V3::new(1.0, 0.4, -0.6); // rel . n = 0.72 > 0: into the wall
        let away = V3::new(1.0, -0.4, 0.6);
        // an axis normal and a still wall, so the tangential part is exactly zero
        let floor = V3::new(0.0, 0.0, -1.0);
        let straight_in = V3::new(0.0, 0.0, -0.5);
        let cases = [
            (WallKind::NoSlip, n, vw, into),
            (WallKind::FreeSlip, n, vw, into),
            (WallKind::FreeSlip, n, vw, away),
            (WallKind::Symmetry, n, vw, into),
            (WallKind::Symmetry, n, vw, away),
            (WallKind::Friction { mu: 0.3 }, n, vw, into),
            (WallKind::Friction { mu: 0.3 }, n, vw, away),
            (WallKind::Friction { mu: 5.0 }, n, vw, into),
            (WallKind::Friction { mu: 0.3 }, floor, V3::ZERO, straight_in),
        ];
        let h = 1e-6;
        for (kind, n, vw, v) in cases {
            let (v_bar, mu_bar) = apply_wall_adjoint(kind, n, vw, v, bar);
            let loss = |kind: WallKind, v: V3| apply_wall(kind, n, vw, v).dot(bar);
            for a in 0..3 {
                let mut e = V3::ZERO;
                e[a] = h;
                let fd = (loss(kind, v + e) - loss(kind, v - e)) / (2.0 * h);
                assert!((fd - v_bar[a]).abs() <= 1e-8 * (1.0 + fd.abs()), "{kind:?} {v:?}: d/dv[{a}] {} against {fd}", v_bar[a]);
            }
            let fd_mu = match kind {
                WallKind::Friction { mu } => {
                    (loss(WallKind::Friction { mu: mu + h }, v) - loss(WallKind::Friction { mu: mu - h }, v)) / (2.0 * h)
                }
                _ => 0.0,
            };
            assert!((fd_mu - mu_bar).abs() <= 1e-8 * (1.0 + fd_mu.abs()), "{kind:?} {v:?}: d/dmu {mu_bar} against {fd_mu}");
        }
        // sliding friction really has a mu derivative, so the check above is not vacuous
        assert!(apply_wall_adjoint(WallKind::Friction { mu: 0.3 }, n, vw, into, bar).1.abs() > 0.1);
    }
}
