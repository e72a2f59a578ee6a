//! The sleep update's adjoint. Which units sleep and wake is discrete and held fixed (as a
//! stencil base is); what the update does to the particles is not:
//!
//! - a sleeping particle is left out of the step, so its state after the step is its state
//!   before: its adjoint passes through unchanged, and nothing of the step adds to it (no
//!   transfer, material update or parameter sees it);
//! - a particle falling asleep is put at rest: its velocity, velocity gradient and stress are
//!   overwritten (the stress by the stress at rest, read by nothing until it wakes and gets it
//!   again), so their adjoints end there;
//! - a particle waking gets its unit's rest (`rest_for_at`) and the stress at rest of the state
//!   that leaves: [`Material::wake_adjoint`] takes those back;
//! - the update moves particles in and out of the sleeping prefix by swaps, so the adjoints move
//!   back to where each particle was before it (found by id: a gradient run's ids are 0..n).

use super::{Adjoint, AdjointError, Simulation, Tape};
use crate::kernels::{Real, M3, V3};
use crate::solver::adjoint::MAX_PARAMS;

impl Simulation {
    /// The sleep update's adjoint on `a.cur` (the adjoint of the state the update left, the
    /// later phases' adjoints done), into the adjoint of the state before it; `moved`: the update
    /// moved particles (the recompute's `Step`). `tape` holds the order and clocks before it.
    pub(crate) fn sleep_adjoint(&self, moved: bool, tape: &mut Tape, a: &mut Adjoint) -> Result<(), AdjointError> {
        if self.sleep.is_none() {
            return Ok(());
        }
        let p = &self.particles;
        let (n, ns) = (p.n, p.n_sleep);
        // the sleeping particles' step is the identity
        a.cur.copy_range(&a.next, 0..ns);
        if !moved {
            return Ok(());
        }
        let (ns0, id) = (tape.n_sleep_before, p.id.as_slice());
        let slot_before = tape.slot_before.as_mut_slice();
        for (i, &k) in tape.ids_before.as_slice()[..n].iter().enumerate() {
            slot_before[k as usize] = i as u32;
        }
        let geom = &self.grid.geom;
        // the state the update left (x, J and the woken particles' state as they woke)
        let start = &tape.particles;
        let np = a.material_bar.len();
        let mut params = [0.0 as Real; MAX_PARAMS];
        let sl = p.state_len;
        for i in 0..n {
            let before = slot_before[id[i] as usize] as usize;
            if i < ns && before >= ns0 {
                // fell asleep: put at rest
                a.cur.v.as_mut_slice()[i] = V3::ZERO;
                a.cur.c.as_mut_slice()[i] = M3::ZERO;
                a.cur.stress.as_mut_slice()[i] = M3::ZERO;
            } else if i >= ns && before < ns0 {
                // woke: its unit's clock held the time it fell asleep
                let u = crate::sleep::unit_of_particle(geom, start.xg.as_slice()[i]);
                // as the update took it
                let rest = (self.time - tape.clocks_before.as_slice()[u as usize] as f64).max(0.0) as f32 as Real;
                let stress_bar = std::mem::replace(&mut a.cur.stress.as_mut_slice()[i], M3::ZERO);
                let state = &start.state.as_slice()[i * sl..(i + 1) * sl];
                let (j, j_bar) = (start.j.as_slice()[i], &mut a.cur.j.as_mut_slice()[i]);
                let state_bar = &mut a.cur.state.as_mut_slice()[i * sl..(i + 1) * sl];
                if !self.material.wake_adjoint(state, rest, j, &stress_bar, state_bar, j_bar, &mut params[..np]) {
                    return Err(AdjointError::Wake { material: self.material.name().to_string(), step: self.step });
                }
            }
        }
        for (m, v) in a.material_bar.iter_mut().zip(&params[..np]) {
            *m += *v as f64;
        }
        // back to the slots before the update: into `next` (consumed), then the two swap
        let to = |i: usize| slot_before[id[i] as usize] as usize;
        a.next.scatter_from(&a.cur, n, to);
        std::mem::swap(&mut a.cur, &mut a.next);
        // the masses' and initial volumes' adjoints through the other set's J (cleared after)
        let scratch = a.next.j.as_mut_slice();
        for bar in [&mut a.mass_bar, &mut a.vol0_bar] {
            let bar = &mut bar.as_mut_slice()[..n];
            for (i, b) in bar.iter().enumerate() {
                scratch[to(i)] = *b;
            }
            bar.copy_from_slice(&scratch[..n]);
        }
        Ok(())
    }
}
