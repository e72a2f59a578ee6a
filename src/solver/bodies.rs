//! The scenario's initial bodies, filled with particles on a lattice.

use super::{SimError, Simulation};
use crate::kernels::{Real, V3};
use crate::scenario::{Body, Scenario};

impl Simulation {
    /// Fill a body with particles on a lattice of `ppc^3` points per cell.
    pub(super) fn add_body(&mut self, body: &Body) -> Result<(), SimError> {
        let dx = self.scenario.simulation.dx;
        let ppc = body.particles_per_cell_axis();
        let vol = (dx / ppc as f64).powi(3);
        let vel = body.velocity();
        let mut err = None;
        let sc = self.scenario.clone();
        for_each_lattice_point(&sc, body, |p| {
            if err.is_none() {
                err = self.add_particle(p, vel, vol).err();
            }
        });
        err.map_or(Ok(()), Err)
    }

    /// Add one particle at world position `x` with velocity `v` and initial volume `vol0`.
    pub fn add_particle(&mut self, x: [f64; 3], v: [f64; 3], vol0: f64) -> Result<usize, SimError> {
        let xg = self.grid.geom.to_grid(x);
        let rho = self.material.density() as f64;
        let i = self.particles.push(xg, V3::new(v[0] as Real, v[1] as Real, v[2] as Real), (rho * vol0) as Real, vol0 as Real)?;
        let s = self.particles.state_len;
        self.material.init_state(&mut self.particles.state.as_mut_slice()[i * s..(i + 1) * s]);
        Ok(i)
    }
}

/// Lattice points of a body: `ppc^3` per cell, on cells aligned with the domain's lower corner.
pub fn for_each_lattice_point(sc: &Scenario, body: &Body, mut f: impl FnMut([f64; 3])) {
    let dx = sc.simulation.dx;
    let ppc = body.particles_per_cell_axis() as usize;
    let h = dx / ppc as f64;
    let (lo, hi) = body.bounds();
    let contains = body.inside();
    let mut range = [(0i64, 0i64); 3];
    for a in 0..3 {
        let m = sc.domain.min[a];
        range[a] = (((lo[a] - m) / h - 0.5).ceil() as i64, ((hi[a] - m) / h - 0.5).floor() as i64);
    }
    for i in range[0].0..=range[0].1 {
        for jj in range[1].0..=range[1].1 {
            for k in range[2].0..=range[2].1 {
                let p = [
                    sc.domain.min[0] + (i as f64 + 0.5) * h,
                    sc.domain.min[1] + (jj as f64 + 0.5) * h,
                    sc.domain.min[2] + (k as f64 + 0.5) * h,
                ];
                let inside = (0..3).all(|a| p[a] >= sc.domain.min[a] && p[a] <= sc.domain.max[a]);
                if inside && contains(p) {
                    f(p);
                }
            }
        }
    }
}

pub fn count_body_particles(sc: &Scenario) -> usize {
    let mut n = 0;
    for b in &sc.bodies {
        for_each_lattice_point(sc, b, |_| n += 1);
    }
    n
}
