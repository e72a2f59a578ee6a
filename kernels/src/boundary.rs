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

use crate::real::{r, V3};
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
}
