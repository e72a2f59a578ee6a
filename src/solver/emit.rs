//! Emission: the printer's slabs added to the pool, and the newest slab's masses and feed.

use super::{SimError, Simulation};
use crate::grid::GridGeom;
use crate::kernels::material::Material;
use crate::kernels::{Real, V3};
use crate::memory::MemoryError;
use crate::particles::Particles;
use crate::print::emitter::Slab;
use crate::print::{NozzleDrive, Printer};

impl Simulation {
    /// Add the emitter's slabs that are due by now, and note which slab is the newest and what
    /// fraction of it has been extruded.
    pub(crate) fn emit(&mut self) -> Result<(), SimError> {
        let Some(pr) = &mut self.printer else { return Ok(()) };
        let t = self.time;
        let vol = pr.particle_volume;
        let (before, id_before) = (pr.emitted(), self.particles.next_id);
        let (geom, particles, mat) = (&self.grid.geom, &mut self.particles, &*self.material);
        let add = |slab: &Slab| add_slab(geom, particles, mat, vol, t, slab);
        if let Some(sync) = &mut pr.sync {
            sync.drain_due(&pr.plan, t, add)?;
        } else if let Some(em) = &mut pr.emitter {
            em.drain_due(t, add)?;
        }
        note_newest(pr, t, self.particles.next_id, before, id_before);
        Ok(())
    }

    /// Set the masses emission changed this step among particles `from..` (see
    /// `print/newest.rs`); after reordering.
    pub(crate) fn newest_masses(&mut self, from: usize) {
        if let Some(pr) = &mut self.printer {
            let rho = self.material.density() as f64;
            pr.newest.set_masses(&mut self.particles, rho, pr.particle_volume, from);
        }
    }

    /// After G2P: the newest slab moves with the feed in proportion to what is still in it.
    pub(crate) fn follow_feed(&mut self, dt: Real, drive: Option<&NozzleDrive>) {
        if let Some(pr) = &mut self.printer {
            let v = drive.map_or([0.0; 3], |d| d.velocity);
            let inv_dx = (1.0 / self.scenario.simulation.dx) as Real;
            pr.newest.follow_feed(&mut self.particles, dt, inv_dx, V3::new(v[0] as Real, v[1] as Real, v[2] as Real));
        }
    }
}

/// Note which slab is the newest at time `t` and what fraction of it has been extruded, after
/// emission took the slab count from `before` (the next particle id then `id_before`) to the
/// printer's `emitted()` (the next id now `next_id`). Derived from the slab counts and ids
/// alone: ids are creation order, whether or not merging has removed particles since.
pub(crate) fn note_newest(pr: &mut Printer, t: f64, next_id: u32, before: u64, id_before: u32) {
    let after = pr.emitted();
    let nw = &mut pr.newest;
    if !pr.plan.partial || after == 0 {
        (nw.set_from, nw.moving) = (u32::MAX, false);
        return;
    }
    nw.slab = after - 1;
    nw.first = next_id - pr.plan.count(after - 1) as u32;
    nw.set_from = if after > before && before > 0 { id_before - pr.plan.count(before - 1) as u32 } else { nw.first };
    (nw.fraction, nw.moving) = pr.plan.fraction(after - 1, t);
}

/// Append a slab's particles, moved ballistically from its due time to `t` (inside the tube the
/// grid moves them at exactly that velocity).
fn add_slab(geom: &GridGeom, particles: &mut Particles, mat: &dyn Material, vol: f64, t: f64, slab: &Slab) -> Result<(), MemoryError> {
    let rho = mat.density() as f64;
    let sl = particles.state_len;
    let lag = t - slab.due;
    let v = slab.velocity;
    let vel = V3::new(v[0] as Real, v[1] as Real, v[2] as Real);
    for x in &slab.positions {
        let xg = geom.to_grid([x[0] + lag * v[0], x[1] + lag * v[1], x[2] + lag * v[2]]);
        let i = particles.push(xg, vel, (rho * vol) as Real, vol as Real)?;
        mat.init_state(&mut particles.state.as_mut_slice()[i * sl..(i + 1) * sl]);
    }
    Ok(())
}
