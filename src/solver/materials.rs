//! The material update, and the finiteness check that names the first bad particle; and the
//! update's adjoint.

use super::adjoint::{Adjoint, Tape, CHUNK, MAX_PARAMS, MAX_STATE};
use super::{SimError, Simulation};
use crate::kernels::material::UpdateAdjoint;
use crate::kernels::{Real, M3};
use crate::threads::{SharedSlice, ThreadTeam};
use std::sync::atomic::Ordering;

/// Particles per chunk of the material update and its finiteness check: their stresses (72
/// bytes each in f64) stay in an L1 cache of 32-48 KiB between the two.
const CHECK_CHUNK: usize = 256;

impl Simulation {
    /// Material update over contiguous particle ranges, then a finiteness check that names the
    /// first bad particle.
    pub(crate) fn update_materials(&mut self, dt: Real) -> Result<(), SimError> {
        let (first, n) = (self.particles.n_sleep, self.particles.n);
        let p = &mut self.particles;
        let sl = p.state_len;
        let c = &p.c.as_slice()[..n];
        let jv = &p.j.as_slice()[..n];
        let vv = &p.v.as_slice()[..n];
        let state = SharedSlice::new(&mut p.state.as_mut_slice()[..n * sl]);
        let stress = SharedSlice::new(&mut p.stress.as_mut_slice()[..n]);
        let mat = &*self.material;
        let threads = self.team.threads();
        let out = &self.thread_out;
        self.team.run(|tid| {
            let r = ThreadTeam::share(n - first, tid, threads);
            let r = first + r.start..first + r.end;
            // SAFETY: ranges are disjoint.
            let (st, sg) = unsafe { (state.slice_mut(r.start * sl..r.end * sl), stress.slice_mut(r.clone())) };
            // Checked chunk by chunk right after its update, while its stresses are still in
            // cache: a second pass over the whole range would read them back from memory. The
            // first bad particle, and every particle's update, are the same either way.
            let finite = |i: usize, s: &M3| jv[i] > 0.0 && jv[i].is_finite() && vv[i].is_finite() && s.is_finite();
            let mut bad = u64::MAX;
            for lo in r.clone().step_by(CHECK_CHUNK) {
                let hi = (lo + CHECK_CHUNK).min(r.end);
                let (a, b) = (lo - r.start, hi - r.start);
                mat.update_batch(&c[lo..hi], &jv[lo..hi], dt, &mut st[a * sl..b * sl], &mut sg[a..b]);
                if bad == u64::MAX {
                    bad = (lo..hi).find(|&i| !finite(i, &sg[i - r.start])).map_or(u64::MAX, |i| i as u64);
                }
            }
            out[tid].store(bad, Ordering::Relaxed);
        });
        let bad = (0..threads).map(|t| out[t].load(Ordering::Relaxed)).min().unwrap_or(u64::MAX);
        if bad != u64::MAX {
            let i = bad as usize;
            let p = &self.particles;
            let sci = scientific;
            let (field, value) = if !p.v.as_slice()[i].is_finite() {
                ("velocity", format!("[{}]", sci(&p.v.as_slice()[i].to_array())))
            } else if !(p.j.as_slice()[i] > 0.0 && p.j.as_slice()[i].is_finite()) {
                ("volume ratio J", sci(&[p.j.as_slice()[i]]))
            } else {
                ("stress", format!("[{}]", sci(&p.stress.as_slice()[i].to_cols_array())))
            };
            return Err(SimError::BlowUp { step: self.step, time: self.time, index: i, id: p.id.as_slice()[i], field, value });
        }
        Ok(())
    }
}

impl Simulation {
    /// The material update's adjoint: `a.next.stress` and `a.next.state` (the adjoints of its
    /// outputs) go to the velocity gradient and volume ratio G2P produced (`a.next.c`,
    /// `a.next.j`), the state before the step (`a.cur.state`) and the parameters. Reads the
    /// pool as the recompute left it (before the blend's adjoint gives G2P's outputs back).
    pub(crate) fn materials_adjoint(&self, tape: &mut Tape, a: &mut Adjoint, dt: Real) {
        let p = &self.particles;
        // the sleeping prefix had no update (the sleep update's adjoint passes its adjoints on)
        let (first, n, sl) = (p.n_sleep, p.n, p.state_len);
        let (c1, j1) = (&p.c.as_slice()[..n], &p.j.as_slice()[..n]);
        let state0 = tape.particles.state.as_slice();
        let mat = &*self.material;
        let np = a.material_bar.len();
        let next_stress = a.next.stress.as_slice();
        let next_state = a.next.state.as_slice();
        let next_c = SharedSlice::new(&mut a.next.c.as_mut_slice()[..n]);
        let next_j = SharedSlice::new(&mut a.next.j.as_mut_slice()[..n]);
        let cur_state = SharedSlice::new(&mut a.cur.state.as_mut_slice()[..n * sl]);
        let chunks = n.div_ceil(CHUNK);
        let partial = SharedSlice::new(&mut tape.chunks[..chunks]);
        let threads = self.team.threads();
        self.team.run(|tid| {
            for k in ThreadTeam::share(chunks, tid, threads) {
                // SAFETY: chunk k and its particles belong to this thread.
                let acc = unsafe { partial.get_mut(k) };
                *acc = [0.0; MAX_PARAMS];
                for i in (k * CHUNK).max(first)..((k + 1) * CHUNK).min(n) {
                    let mut out_bar = [0.0 as Real; MAX_STATE];
                    out_bar[..sl].copy_from_slice(&next_state[i * sl..(i + 1) * sl]);
                    let mut params = [0.0 as Real; MAX_PARAMS];
                    let mut adj = unsafe {
                        UpdateAdjoint {
                            grad_v_bar: next_c.get_mut(i),
                            j_bar: next_j.get_mut(i),
                            state_bar: cur_state.slice_mut(i * sl..(i + 1) * sl),
                            params_bar: &mut params[..np],
                        }
                    };
                    mat.update_adjoint(&c1[i], j1[i], dt, &state0[i * sl..(i + 1) * sl], &next_stress[i], &out_bar[..sl], &mut adj);
                    for (a, v) in acc.iter_mut().zip(&params[..np]) {
                        *a += *v as f64;
                    }
                }
            }
        });
        // chunk sums in chunk order: the same bits for any thread count
        for acc in &tape.chunks[..chunks] {
            for (m, v) in a.material_bar.iter_mut().zip(acc) {
                *m += v;
            }
        }
    }
}

/// Values for a message in scientific notation: plain formatting spells 1e-300 with 300 digits.
fn scientific(values: &[Real]) -> String {
    values.iter().map(|x| format!("{x:.6e}")).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    /// Issue 27 finding 9: a blow-up message shows J and the other fields in a few digits.
    #[test]
    fn blow_up_values_are_short() {
        let s = super::scientific(&[-1e-30, 1e30, -62.088_41]);
        assert!(s.starts_with("-1.000000e-30, 1.000000e30, -6.20884") && s.len() < 50, "{s}");
    }
}
