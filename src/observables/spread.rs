//! `spread`: the slump-flow spread, the mean of the x and y extents of the particles within two
//! spacings of the base (as `spread.csv`'s `mean_diameter`).

use super::objective::{Kind, Takes};
use super::state::{arg_max, Seed, State};
use super::ObservableError;

/// Slump-flow spread: mean of the x and y extents of the particles within two spacings of
/// the base (as `spread.csv`'s `mean_diameter`).
pub(super) const SPREAD: Kind = Kind { name: "spread", takes: Takes::Nothing, measured: true, evaluate: |s, _, seed| s.spread(seed) };

impl State<'_> {
    pub(super) fn spread(&self, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let (frame, n) = (self.frame, self.n());
        let band = |i: usize| self.world(i)[2] < frame.base_z + 2.0 * frame.spacing;
        let ext = |a: usize| {
            let hi = arg_max(n, band, |i| self.world(i)[a]);
            let lo = arg_max(n, band, |i| -self.world(i)[a]);
            hi.zip(lo)
        };
        let (Some((xh, xl)), Some((yh, yl))) = (ext(0), ext(1)) else {
            return Err(ObservableError("objective spread: no particle lies within two spacings of the base".into()));
        };
        let d = |h: usize, l: usize, a: usize| self.world(h)[a] - self.world(l)[a] + frame.spacing;
        let value = 0.5 * (d(xh, xl, 0) + d(yh, yl, 1));
        if let Some(s) = seed {
            s.xg[xh].x += 0.5 * self.scale;
            s.xg[xl].x -= 0.5 * self.scale;
            s.xg[yh].y += 0.5 * self.scale;
            s.xg[yl].y -= 0.5 * self.scale;
        }
        Ok(value)
    }
}
