//! `vx_max` and `kinetic_energy`: the material's motion.

use super::objective::{Kind, Takes};
use super::state::{arg_max, Seed, State};
use super::ObservableError;

/// Largest x velocity of any particle (the centreline speed of a channel flow).
pub(super) const VX_MAX: Kind = Kind { name: "vx_max", takes: Takes::Nothing, measured: true, evaluate: |s, _, seed| s.vx_max(seed) };

/// Sum of m |v|^2 / 2.
pub(super) const KINETIC_ENERGY: Kind = Kind { name: "kinetic_energy", takes: Takes::Nothing, measured: true, evaluate: |s, _, seed| Ok(s.kinetic_energy(seed)) };

impl State<'_> {
    pub(super) fn vx_max(&self, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let v = self.sim.particles.v.as_slice();
        let i = arg_max(self.n(), |_| true, |i| v[i].x as f64).ok_or_else(|| ObservableError("objective vx_max: no particles".into()))?;
        if let Some(s) = seed {
            s.v[i].x += 1.0;
        }
        Ok(v[i].x as f64)
    }

    pub(super) fn kinetic_energy(&self, seed: Option<Seed>) -> f64 {
        let p = &self.sim.particles;
        let (v, m) = (p.v.as_slice(), p.mass.as_slice());
        let value = (0..p.n).map(|i| 0.5 * (m[i] * v[i].length_squared()) as f64).sum();
        if let Some(s) = seed {
            for i in 0..p.n {
                s.v[i] += v[i] * m[i];
                s.mass[i] += 0.5 * v[i].length_squared();
            }
        }
        value
    }
}
