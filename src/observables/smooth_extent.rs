//! The smooth extent of a section: where a kernel-smoothed thickness profile crosses a level.
//!
//! A section's width and height as extremes of particle positions in a slab (`width`, `height`)
//! jump whenever a particle enters or leaves the slab, so a fit's chi^2 scatters between nearby
//! parameter values and a Gauss-Newton step's promise is not kept. Here every particle near the
//! station weighs in smoothly instead: its volume V = V0 J, spread in x by the quadratic B-spline
//! of knot spacing `slab` (as the `area` objective), gives it an area a = V B((x - X) / slab) /
//! slab in the section; spread again along the measured axis by the B-spline of knot spacing h
//! (the print's particle spacing), the areas give a profile
//!
//!   p(c) = sum_i a_i B((c - c_i) / h) / h      [m]
//!
//! (along y, the section's thickness over y; along z, its width at height z). The extent's edge
//! is the outermost crossing of p with the level h / 2: at least half a spacing of material
//! stands there. On a lattice of spacing h a solid section of thickness h crosses it at the last
//! particle + h / 2, where the extreme-based observables put the edge; a thicker one a little
//! further out (at most 1.5 h - sqrt(h / H) h beyond the last particle, for thickness H), so the
//! smooth extent converges to the extreme one as h -> 0.
//!
//! The edge r solves p(r) = h / 2, so its derivatives follow from the implicit function theorem:
//! dr/dc_i = a_i B'((r - c_i) / h) / h^2 / p'(r) and dr/da_i = -B((r - c_i) / h) / h / p'(r),
//! smooth in every particle's position and volume as long as the crossing is not tangent.

use super::objective::{Kind, Objective, Takes};
use super::state::{section_y, Seed, State};
use super::ObservableError;
use crate::kernels::Real;
use crate::observe::quadratic_bspline_and_slope;

/// One particle's (or mirror image's) place on the measured axis and its area in the section.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub c: f64,
    pub a: f64,
}

/// Which edge of the profile: the last crossing going up the axis, or the first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Side {
    Upper,
    Lower,
}

/// The profile's value and slope at `c`.
fn profile(samples: &[Sample], h: f64, c: f64) -> (f64, f64) {
    samples.iter().fold((0.0, 0.0), |(p, dp), s| {
        let (b, db) = quadratic_bspline_and_slope((c - s.c) / h);
        (p + s.a * b / h, dp + s.a * db / (h * h))
    })
}

/// The level the edge is taken at: half a spacing of material.
pub fn level(h: f64) -> f64 {
    0.5 * h
}

/// The outermost crossing of the profile with [`level`] on `side`, to the last bit bisection
/// reaches; None when the profile nowhere reaches the level (no material, or too little).
/// Scans in steps of h / 8 (the profile's bumps are at least a spacing wide) from outside the
/// support inward, then bisects the bracketing step.
pub fn edge(samples: &[Sample], h: f64, side: Side) -> Option<f64> {
    let (lo, hi) = samples.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s.c), hi.max(s.c)));
    if !lo.is_finite() {
        return None;
    }
    let t = level(h);
    let (start, end, dir) = match side {
        Side::Upper => (hi + 1.5 * h, lo - 1.5 * h, -1.0),
        Side::Lower => (lo - 1.5 * h, hi + 1.5 * h, 1.0),
    };
    let step = h / 8.0;
    let steps = ((end - start).abs() / step).ceil() as usize;
    let mut outside = start;
    for k in 1..=steps {
        let inside = start + dir * step * k as f64;
        if profile(samples, h, inside).0 >= t {
            let (mut a, mut b) = (outside, inside);
            for _ in 0..64 {
                let m = 0.5 * (a + b);
                if m == a || m == b {
                    break;
                }
                if profile(samples, h, m).0 >= t {
                    b = m;
                } else {
                    a = m;
                }
            }
            return Some(b);
        }
        outside = inside;
    }
    None
}

/// d edge / d c_i and d edge / d a_i at the edge `r` (implicit differentiation of p(r) = level),
/// added times `scale` to `d_c` and `d_a`. None where the crossing is tangent (p'(r) = 0).
pub fn edge_adjoint(samples: &[Sample], h: f64, r: f64, scale: f64, d_c: &mut [f64], d_a: &mut [f64]) -> Option<()> {
    let slope = profile(samples, h, r).1;
    if slope == 0.0 || !slope.is_finite() {
        return None;
    }
    for (k, s) in samples.iter().enumerate() {
        let (b, db) = quadratic_bspline_and_slope((r - s.c) / h);
        d_c[k] += scale * s.a * db / (h * h) / slope;
        d_a[k] -= scale * b / h / slope;
    }
    Some(())
}

/// The section's width at x = station [m] as a smooth function of every particle near it
/// (this file): the distance between the outermost crossings of its thickness
/// profile over y with half a spacing; with `[observe] mirror_y`, twice the upper crossing's
/// distance from the plane. Unlike `width` it has no jumps where particles cross a slab's
/// edge, so fits and differences see a smooth function of the parameters.
pub(super) const SMOOTH_WIDTH: Kind = Kind { name: "smooth_width", takes: Takes::Station, measured: true, evaluate: |s, o, seed| s.smooth_extent(o, o.station(), true, seed) };

/// The section's height at x = station above the base [m], smooth as `smooth_width`: the
/// upper crossing of its width profile over z with half a spacing.
pub(super) const SMOOTH_HEIGHT: Kind = Kind { name: "smooth_height", takes: Takes::Station, measured: true, evaluate: |s, o, seed| s.smooth_extent(o, o.station(), false, seed) };

impl State<'_> {
    /// [`SMOOTH_WIDTH`] (`width`) or [`SMOOTH_HEIGHT`]: the section's
    /// samples (`smooth_extent::Sample`: the particle's y or z, and its area in the section, its
    /// volume spread in x as `area`'s), their edges, and the edges' adjoints carried back to the
    /// particles' positions, volume ratios and initial volumes.
    pub(super) fn smooth_extent(&self, what: &Objective, station: f64, width: bool, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let (frame, h) = (self.frame, self.frame.spacing);
        let p = &self.sim.particles;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        // (particle, sign of d c / d its coordinate, B, dB/du) of each sample
        let mut whose: Vec<(usize, f64, f64, f64)> = Vec::new();
        let mut samples: Vec<Sample> = Vec::new();
        for i in 0..p.n {
            let x = self.world(i);
            let u = (x[0] - station) / frame.slab;
            if u.abs() >= 1.5 {
                continue;
            }
            let (b, db) = crate::observe::quadratic_bspline_and_slope(u);
            let a = (vol0[i] * jv[i]) as f64 * b / frame.slab;
            let images: &[f64] = if frame.mirror_y.is_some() { &[1.0, -1.0] } else { &[1.0] };
            for &sign in images {
                let c = if width { section_y(frame, x[1], sign) } else { x[2] };
                samples.push(Sample { c, a });
                whose.push((i, if width { sign } else { 1.0 }, b, db));
            }
        }
        let fail = |why: &str| ObservableError(format!("objective {}: {why} at x = {station} m", what.name()));
        let upper = edge(&samples, h, Side::Upper).ok_or_else(|| fail("no section reaches half a spacing of material"))?;
        let lower = match (width, frame.mirror_y) {
            (true, None) => Some(edge(&samples, h, Side::Lower).ok_or_else(|| fail("no section reaches half a spacing of material"))?),
            _ => None,
        };
        let value = match (width, frame.mirror_y, lower) {
            (false, _, _) => upper - frame.base_z,
            (true, Some(y0), _) => 2.0 * (upper - y0),
            (true, None, Some(lower)) => upper - lower,
            (true, None, None) => unreachable!("the lower edge is taken without a mirror"),
        };
        if let Some(s) = seed {
            let (mut d_c, mut d_a) = (vec![0.0; samples.len()], vec![0.0; samples.len()]);
            let tangent = || fail("the profile touches the level without crossing it (no derivative)");
            let upper_weight = if width && frame.mirror_y.is_some() { 2.0 } else { 1.0 };
            edge_adjoint(&samples, h, upper, upper_weight, &mut d_c, &mut d_a).ok_or_else(tangent)?;
            if let Some(lower) = lower {
                edge_adjoint(&samples, h, lower, -1.0, &mut d_c, &mut d_a).ok_or_else(tangent)?;
            }
            for (k, &(i, sign, b, db)) in whose.iter().enumerate() {
                let coordinate = (d_c[k] * sign) as Real * self.scale;
                if width {
                    s.xg[i].y += coordinate;
                } else {
                    s.xg[i].z += coordinate;
                }
                let vol = (vol0[i] * jv[i]) as f64;
                s.xg[i].x += (d_a[k] * vol * db / (frame.slab * frame.slab)) as Real * self.scale;
                s.j[i] += (d_a[k] * vol0[i] as f64 * b / frame.slab) as Real;
                s.vol0[i] += (d_a[k] * jv[i] as f64 * b / frame.slab) as Real;
            }
        }
        Ok(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A solid block on a lattice of spacing h: `ny` columns from y = 0, `nz` rows thick, each
    /// particle of area h^2 in the section.
    fn block(ny: usize, nz: usize, h: f64) -> Vec<Sample> {
        (0..ny).flat_map(|j| (0..nz).map(move |_| Sample { c: j as f64 * h, a: h * h })).collect()
    }

    #[test]
    fn a_block_one_spacing_thick_has_the_extreme_based_edges() {
        let h = 0.002;
        let s = block(10, 1, h);
        let up = edge(&s, h, Side::Upper).unwrap();
        let low = edge(&s, h, Side::Lower).unwrap();
        assert!((up - (9.0 * h + 0.5 * h)).abs() < 1e-12, "{up}");
        assert!((low + 0.5 * h).abs() < 1e-12, "{low}");
    }

    #[test]
    fn a_thicker_block_reaches_out_by_the_closed_form() {
        // thickness H = nz h: the tail (1.5 - s)^2 / 2 of the partition of unity meets h / (2 H)
        let (h, nz) = (0.002, 9);
        let up = edge(&block(10, nz, h), h, Side::Upper).unwrap();
        let s = 1.5 - (1.0 / nz as f64).sqrt();
        assert!((up - (9.0 + s) * h).abs() < 1e-12, "{up} against {}", (9.0 + s) * h);
    }

    #[test]
    fn too_little_material_has_no_edge() {
        let h = 0.002;
        assert!(edge(&[Sample { c: 0.0, a: 0.1 * h * h }], h, Side::Upper).is_none());
        assert!(edge(&[], h, Side::Lower).is_none());
    }

    #[test]
    fn the_adjoint_matches_central_differences() {
        // an irregular cloud: positions and areas off the lattice
        let h = 0.002;
        let s: Vec<Sample> = (0..40).map(|k| {
            let f = k as f64;
            Sample { c: (f * 0.37).sin() * 0.01 + 0.0003 * f, a: h * h * (0.6 + 0.5 * (f * 1.3).cos().abs()) }
        }).collect();
        for side in [Side::Upper, Side::Lower] {
            let r = edge(&s, h, side).unwrap();
            let (mut dc, mut da) = (vec![0.0; s.len()], vec![0.0; s.len()]);
            edge_adjoint(&s, h, r, 1.0, &mut dc, &mut da).unwrap();
            let mut touched = 0;
            for k in 0..s.len() {
                for (which, g) in [(0, dc[k]), (1, da[k])] {
                    let eps = if which == 0 { 1e-7 } else { 1e-7 * s[k].a / h };
                    let moved = |e: f64| {
                        let mut t = s.clone();
                        if which == 0 { t[k].c += e } else { t[k].a += e }
                        edge(&t, h, side).unwrap()
                    };
                    let fd = (moved(eps) - moved(-eps)) / (2.0 * eps);
                    let tol = 1e-5 * g.abs().max(1e-3);
                    assert!((fd - g).abs() <= tol, "{side:?} sample {k} ({which}): adjoint {g:e}, central differences {fd:e}");
                    touched += (g != 0.0) as usize;
                }
            }
            assert!(touched >= 4, "{side:?}: the edge depends on {touched} numbers only");
        }
    }
}
