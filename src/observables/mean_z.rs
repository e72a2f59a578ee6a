//! `mean_z`: the volume-weighted mean height of the particles above the base.

use super::objective::{Kind, Takes};
use super::state::{Seed, State};
use super::ObservableError;
use crate::kernels::Real;

/// Volume-weighted mean height of the particles above the base.
pub(super) const MEAN_Z: Kind = Kind { name: "mean_z", takes: Takes::Nothing, measured: true, evaluate: |s, _, seed| s.mean_z(seed) };

impl State<'_> {
    pub(super) fn mean_z(&self, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let p = &self.sim.particles;
        let base_z = self.frame.base_z;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        let w: f64 = (0..p.n).map(|i| (vol0[i] * jv[i]) as f64).sum();
        if w <= 0.0 {
            return Err(ObservableError("objective mean_z: no particles".into()));
        }
        let wz: f64 = (0..p.n).map(|i| (vol0[i] * jv[i]) as f64 * (self.world(i)[2] - base_z)).sum();
        let value = wz / w;
        if let Some(s) = seed {
            for i in 0..p.n {
                let vi = (vol0[i] * jv[i]) as f64;
                s.xg[i].z += (vi / w) as Real * self.scale;
                s.j[i] += (vol0[i] as f64 * ((self.world(i)[2] - base_z) - value) / w) as Real;
                s.vol0[i] += (jv[i] as f64 * ((self.world(i)[2] - base_z) - value) / w) as Real;
            }
        }
        Ok(value)
    }
}
