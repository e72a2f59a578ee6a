//! Emission: the printer's slabs added to the pool, and the newest slab's masses and feed; and
//! their adjoints, which hand the toolpath's share to a [`ToolpathBar`].

use super::adjoint::{Adjoint, ToolpathBar, MAX_PARAMS};
use super::step::Step;
use super::{AdjointError, SimError, Simulation};
use crate::grid::GridGeom;
use crate::kernels::material::Material;
use crate::kernels::{Real, V3};
use crate::memory::MemoryError;
use crate::particles::Particles;
use crate::print::emitter::Slab;
use crate::print::newest::{follow_feed_adjoint, FollowFeedBar};
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

impl Simulation {
    /// The base toolpath's move at the step's time, on which the toolpath's closed forms are
    /// differentiated.
    pub(super) fn toolpath_move(&self) -> usize {
        self.printer.as_ref().map_or(0, |p| p.toolpath.state_at(self.time).interval)
    }

    /// Adjoint of the blend with the feed: `a.next`'s adjoints of the blended outputs become
    /// those of G2P's, and the pool gets G2P's outputs back for the adjoints of G2P and its
    /// clamp. The adjoints of the fraction and of the feed velocity are kept in `a` for the
    /// grid update's and the newest masses' adjoints.
    pub(crate) fn follow_feed_adjoint(&mut self, a: &mut Adjoint, dt: Real) {
        (a.feed_fraction_bar, a.feed_velocity_bar) = (0.0, [0.0; 3]);
        let Some(pr) = self.printer.as_ref().filter(|p| p.newest.moving) else { return };
        let nw = &pr.newest;
        let v = pr.drive(self.time).map_or([0.0; 3], |d| d.velocity);
        let v_feed = V3::new(v[0] as Real, v[1] as Real, v[2] as Real);
        let inv_dx = (1.0 / self.scenario.simulation.dx) as Real;
        let (mut fraction_bar, mut v_feed_bar) = (0.0, V3::ZERO);
        for (k, &i) in nw.index.iter().enumerate() {
            let i = i as usize;
            let out_bar = (a.next.xg.as_slice()[i], a.next.v.as_slice()[i], a.next.c.as_slice()[i], a.next.j.as_slice()[i]);
            let bar = FollowFeedBar {
                x0: &mut a.cur.xg.as_mut_slice()[i],
                j0: &mut a.cur.j.as_mut_slice()[i],
                v_feed: &mut v_feed_bar,
                fraction: &mut fraction_bar,
            };
            let (xb, vb, cb, jb) = follow_feed_adjoint(nw.fraction as Real, dt, inv_dx, nw.x0[k], nw.j0[k], v_feed, nw.g2p[k], out_bar, bar);
            a.next.xg.as_mut_slice()[i] = xb;
            a.next.v.as_mut_slice()[i] = vb;
            a.next.c.as_mut_slice()[i] = cb;
            a.next.j.as_mut_slice()[i] = jb;
            let p = &mut self.particles;
            (p.xg.as_mut_slice()[i], p.v.as_mut_slice()[i], p.c.as_mut_slice()[i], p.j.as_mut_slice()[i]) = nw.g2p[k];
        }
        (a.feed_fraction_bar, a.feed_velocity_bar) = (fraction_bar, [v_feed_bar.x as f64, v_feed_bar.y as f64, v_feed_bar.z as f64]);
    }

    /// Adjoint of [`Simulation::newest_masses`]: the step set the masses and initial volumes of
    /// the awake particles with ids `set_from..` (the newest slab's to its fraction f, a just
    /// completed one's to full); their adjoints gathered since are settled here — into the
    /// density's, and for the newest slab into f's — and cleared, for the earlier steps to gather
    /// those of the values before. f's adjoint, with the blend's, goes to `toolpath` as the
    /// extruded length's. The particles are found by id over the awake range, as the forward
    /// found them: a sleep update may have swapped them to other slots.
    pub(crate) fn newest_masses_adjoint(&self, a: &mut Adjoint, toolpath: Option<&mut dyn ToolpathBar>) {
        let Some(pr) = self.printer.as_ref() else { return };
        let nw = &pr.newest;
        let mut fraction_bar = 0.0;
        if nw.set_from != u32::MAX {
            let p = &self.particles;
            let rho = self.material.density() as f64;
            let vol = pr.particle_volume;
            let (mass_bar, vol0_bar) = (a.mass_bar.as_mut_slice(), a.vol0_bar.as_mut_slice());
            let (id, mass) = (p.id.as_slice(), p.mass.as_slice());
            for i in p.n_sleep..p.n {
                if id[i] < nw.set_from {
                    continue;
                }
                let (mb, vb) = (mass_bar[i] as f64, vol0_bar[i] as f64);
                a.density_bar += mb * mass[i] as f64 / rho;
                if id[i] >= nw.first {
                    fraction_bar += rho * vol * mb + vol * vb;
                }
                (mass_bar[i], vol0_bar[i]) = (0.0, 0.0);
            }
        }
        if let (Some(tb), true) = (toolpath, nw.moving) {
            tb.extruded(self.toolpath_move(), self.time, (fraction_bar + a.feed_fraction_bar) / pr.plan.slab_thickness());
        }
    }

    /// Emission's adjoint: the particles `step.n_before..n` entered in this step, so their
    /// adjoints are those of the emission, owed to the toolpath (handed to `toolpath`) and,
    /// through their initial state, the material; they did not exist before the step, so their
    /// adjoints end here.
    pub(crate) fn emission_adjoint(&self, step: &Step, a: &mut Adjoint, toolpath: Option<&mut dyn ToolpathBar>) -> Result<(), AdjointError> {
        let p = &self.particles;
        let (first, n, sl) = (step.n_before, p.n, p.state_len);
        if n <= first {
            return Ok(());
        }
        if let Some(tb) = toolpath {
            let inv_dx = 1.0 / self.scenario.simulation.dx;
            let x_bar: Vec<[f64; 3]> = a.cur.xg.as_slice()[first..n].iter().map(|b| [b.x as f64 * inv_dx, b.y as f64 * inv_dx, b.z as f64 * inv_dx]).collect();
            let v_bar: Vec<[f64; 3]> = a.cur.v.as_slice()[first..n].iter().map(|b| [b.x as f64, b.y as f64, b.z as f64]).collect();
            let plan = &self.printer.as_ref().ok_or(AdjointError::NoPrinter)?.plan;
            tb.emission(plan, step.first_slab, self.time, &x_bar, &v_bar)?;
        }
        let mut init = [0.0 as Real; MAX_PARAMS];
        let np = a.material_bar.len();
        for i in first..n {
            self.material.init_state_adjoint(&a.cur.state.as_slice()[i * sl..(i + 1) * sl], &mut init[..np]);
        }
        for (m, v) in a.material_bar.iter_mut().zip(&init[..np]) {
            *m += *v as f64;
        }
        a.cur.zero_range(first..n);
        Ok(())
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
