//! `area`: a section's area, the particle volumes V0 J weighted in x by the quadratic B-spline of
//! knot spacing `[observe] slab` (as `sections.csv`'s `area`).

use super::objective::{Kind, Takes};
use super::state::{Seed, State};
use crate::kernels::Real;

/// Cross-section area at x = station [m2], summed: the particle volumes V0 J weighted by the
/// quadratic B-spline of knot spacing `slab` in x, over the slab (as `sections.csv`'s `area`,
/// consistent with the mass balance); with `[observe] mirror_y`, of the mirrored material.
pub(super) const AREA: Kind = Kind { name: "area", takes: Takes::Stations, measured: true, evaluate: |s, o, seed| Ok(s.area(o.stations(), seed)) };

impl State<'_> {
    pub(super) fn area(&self, stations: &[f64], mut seed: Option<Seed>) -> f64 {
        let p = &self.sim.particles;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        let copies = if self.frame.mirror_y.is_some() { 2.0 } else { 1.0 };
        let slab = self.frame.slab;
        let mut total = 0.0;
        for &station in stations {
            for i in 0..p.n {
                let u = (self.world(i)[0] - station) / slab;
                if u.abs() >= 1.5 {
                    continue;
                }
                let (b, db) = crate::observe::quadratic_bspline_and_slope(u);
                let vol = (vol0[i] * jv[i]) as f64;
                total += copies * vol * b / slab;
                if let Some(s) = seed.as_mut() {
                    s.xg[i].x += (copies * vol * db / (slab * slab)) as Real * self.scale;
                    s.j[i] += (copies * vol0[i] as f64 * b / slab) as Real;
                    s.vol0[i] += (copies * jv[i] as f64 * b / slab) as Real;
                }
            }
        }
        total
    }
}
