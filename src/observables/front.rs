//! `front`: the leading edge of the material in x, its largest particle x plus half a spacing.

use super::objective::{Kind, Takes};
use super::state::{arg_max, Seed, State};
use super::ObservableError;

/// Flow front: the leading edge of the material in x [m] (largest particle x plus half a
/// spacing; the flow distance of an L-box or channel test, from the gate at its x).
pub const FRONT: Kind = Kind { name: "front", takes: Takes::Nothing, measured: true, evaluate: |s, _, seed| s.front(seed) };

impl State<'_> {
    pub(super) fn front(&self, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let lead = arg_max(self.n(), |_| true, |i| self.world(i)[0]).ok_or_else(|| ObservableError("objective front: no particles".into()))?;
        if let Some(s) = seed {
            s.xg[lead].x += self.scale;
        }
        Ok(self.world(lead)[0] + 0.5 * self.frame.spacing)
    }
}
