//! `profile@X:Y`: a point of a section's top outline, as the reporter's `profile.csv` draws it.

use super::objective::{Kind, Objective, Takes};
use super::state::{section_points, section_y, Seed, State};
use super::ObservableError;
use crate::kernels::Real;

/// A point of the printed cross-section's profile: the height above the base [m] of the top
/// outline of the section at x = station, at lateral position y [m]. Exactly
/// `observe::profile_z_at(cross_section(..).profile, y) - base_z` as the run's reporter builds
/// the section: the particles with |x - station| <= slab / 2 (`[observe] slab`, default one
/// cell), with `[observe] mirror_y` together with their mirror images, binned in y at the
/// print's spacing h from the lowest y; a bin's top is its highest particle + h / 2, the
/// outline runs linearly between bin centres, flat over the outer half of a run's end bins,
/// and at the base elsewhere (0 in a gap or beside the material). Its adjoint flows through
/// the particles that set the tops of the (at most two) bins around y, and through the one
/// that sets the lowest y (the bins' origin); which particles those are is held fixed.
pub(super) const PROFILE: Kind = Kind { name: "profile", takes: Takes::StationAndY, measured: true, evaluate: |s, o, seed| s.profile(o, o.station(), o.y(), seed) };

impl State<'_> {
    pub(super) fn profile(&self, what: &Objective, station: f64, y: f64, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let frame = self.frame;
        let h = frame.spacing;
        let pts = section_points(self.sim, frame, station).ok_or_else(|| ObservableError(format!("objective {}: no particle within half a slab of x = {station} m", what.name())))?;
        let py = |pt: &(usize, f64)| section_y(frame, self.world(pt.0)[1], pt.1);
        // the bins' origin: the lowest y (first on ties), and each bin's top particle
        let o = pts.iter().enumerate().fold(0, |b, (k, pt)| if py(pt) < py(&pts[b]) { k } else { b });
        let origin = py(&pts[o]);
        let mut tops: std::collections::BTreeMap<i64, (f64, usize)> = std::collections::BTreeMap::new();
        for pt in &pts {
            let top = self.world(pt.0)[2] + 0.5 * h;
            let e = tops.entry(crate::observe::bin(py(pt), origin, h)).or_insert((top, pt.0));
            if top > e.0 {
                *e = (top, pt.0);
            }
        }
        let u = (y - origin) / h;
        let k0 = u.floor();
        let t = u - k0;
        let k0 = k0 as i64;
        // (weight, particle) of the tops the point interpolates, and d value / d origin
        let (terms, d_origin): (Vec<(f64, usize)>, f64) = match (tops.get(&k0), tops.get(&(k0 + 1))) {
            (Some(&(a, ia)), Some(&(b, ib))) => (vec![(1.0 - t, ia), (t, ib)], -(b - a) / h),
            (Some(&(_, ia)), None) if t <= 0.5 => (vec![(1.0, ia)], 0.0),
            (None, Some(&(_, ib))) if t >= 0.5 => (vec![(1.0, ib)], 0.0),
            _ => (Vec::new(), 0.0),
        };
        let value = if terms.is_empty() { 0.0 } else { terms.iter().map(|&(w, i)| w * (self.world(i)[2] + 0.5 * h)).sum::<f64>() - frame.base_z };
        if let Some(s) = seed {
            for &(w, i) in &terms {
                s.xg[i].z += w as Real * self.scale;
            }
            let (io, sign) = pts[o];
            s.xg[io].y += (sign * d_origin) as Real * self.scale;
        }
        Ok(value)
    }
}
