//! `width`, `height`, `level` and `total_height`: a section's or the whole material's extent,
//! from its extreme particles plus half a spacing on each side (as `sections.csv`'s).

use super::objective::{At, Kind, Objective, Takes};
use super::state::{arg_max, Seed, State};
use super::ObservableError;

/// Extent in y of the particles within half a cell of x = station [m], summed over the
/// stations (paper 000 sec. 4.2 sums three); with `[observe] mirror_y`, of the mirrored
/// material.
pub(super) const WIDTH: Kind = Kind { name: "width", takes: Takes::Stations, measured: true, evaluate: |s, o, seed| s.width_or_height(o, o.stations(), true, seed) };

/// Top of the particles within half a cell of x = station above the base [m], summed.
pub(super) const HEIGHT: Kind = Kind { name: "height", takes: Takes::Stations, measured: true, evaluate: |s, o, seed| s.width_or_height(o, o.stations(), false, seed) };

/// `height` at one station where the material may not have arrived: 0 when no particle lies
/// within half a cell of it (an L-box's height at the end of the box).
pub(super) const LEVEL: Kind = Kind { name: "level", takes: Takes::Station, measured: true, evaluate: |s, o, seed| s.level(o.station(), seed) };

/// Top of all the material above the base [m].
pub(super) const TOTAL_HEIGHT: Kind = Kind { name: "total_height", takes: Takes::Nothing, measured: false, evaluate: |s, _, seed| s.total_height(seed) };

impl State<'_> {
    pub(super) fn level(&self, station: f64, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let slab = |i: usize| (self.world(i)[0] - station).abs() <= 0.5 * self.frame.dx;
        if arg_max(self.n(), slab, |_| 0.0).is_none() {
            return Ok(0.0);
        }
        let height = Objective::new(&HEIGHT, At::Stations(vec![station]));
        self.width_or_height(&height, &[station], false, seed)
    }

    pub(super) fn width_or_height(&self, what: &Objective, stations: &[f64], width: bool, mut seed: Option<Seed>) -> Result<f64, ObservableError> {
        let (frame, n, scale) = (self.frame, self.n(), self.scale);
        let mut total = 0.0;
        for &station in stations {
            let slab = |i: usize| (self.world(i)[0] - station).abs() <= 0.5 * frame.dx;
            let top = arg_max(n, slab, |i| self.world(i)[2]);
            let (hi, lo) = (arg_max(n, slab, |i| self.world(i)[1]), arg_max(n, slab, |i| -self.world(i)[1]));
            let (Some(top), Some(hi), Some(lo)) = (top, hi, lo) else {
                return Err(ObservableError(format!("objective {}: no particle within half a cell of x = {station} m", what.name())));
            };
            total += if !width {
                self.world(top)[2] + 0.5 * frame.spacing - frame.base_z
            } else if let Some(y0) = frame.mirror_y {
                2.0 * (self.world(hi)[1] - y0) + frame.spacing
            } else {
                self.world(hi)[1] - self.world(lo)[1] + frame.spacing
            };
            if let Some(s) = seed.as_mut() {
                match (width, frame.mirror_y) {
                    (false, _) => s.xg[top].z += scale,
                    (true, Some(_)) => s.xg[hi].y += 2.0 * scale,
                    (true, None) => {
                        s.xg[hi].y += scale;
                        s.xg[lo].y -= scale;
                    }
                }
            }
        }
        Ok(total)
    }

    pub(super) fn total_height(&self, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let top = arg_max(self.n(), |_| true, |i| self.world(i)[2]).ok_or_else(|| ObservableError("objective total_height: no particles".into()))?;
        if let Some(s) = seed {
            s.xg[top].z += self.scale;
        }
        Ok(self.world(top)[2] + 0.5 * self.frame.spacing - self.frame.base_z)
    }
}
