//! The adjoint of one MLS-MPM step: the step's phases ([`PHASES`]) run forward from its start
//! state, saving into the tape what each phase overwrites that an adjoint reads
//! ([`Phase::saves`]), then the same list backwards through each phase's adjoint (beside its
//! forward in `solver/`). Phases outer, objectives inner: every objective's adjoint of a phase
//! sees the live state as that phase left it.

use crate::observables::{Frame, Objective, Seed};
use super::print_adjoint::PrintParams;
use super::GradError;
use crate::memory::{Backing, MemoryError, MemoryPlan};
use crate::pools::Counts;
use crate::solver::{Adjoint, Simulation, Step, Tape, ToolpathBar, PHASES};
use std::time::Instant;

/// The adjoint of one MLS-MPM step for several seeds at once (a vector adjoint: several
/// objectives of one forward run, each with its own adjoint arrays); the step is recomputed once
/// and its tape shared.
pub struct StepAdjoint {
    tape: Tape,
    /// One adjoint per objective.
    pub seeds: Vec<Adjoint>,
    /// Wall seconds of the recompute, then of each phase's adjoint (by its place in `PHASES`),
    /// over all reversed steps.
    phase_s: [f64; 1 + PHASES.len()],
}

impl StepAdjoint {
    /// Bytes shared by all seeds (the tape, with a sleep tape for `sleep_units` units) into
    /// `plan`, and those of `seeds` seeds' adjoints.
    pub fn plan(plan: &mut MemoryPlan, cap: &Counts, state_len: usize, sleep_units: usize, seeds: usize) {
        Tape::plan(plan, cap, state_len, sleep_units);
        for k in 0..seeds {
            Adjoint::plan(plan, k, cap, state_len);
        }
    }

    pub fn new(sim: &Simulation, b: &Backing, seeds: usize) -> Result<StepAdjoint, GradError> {
        let tape = Tape::new(sim, b)?;
        let seeds = (0..seeds).map(|k| Adjoint::new(sim, k, b)).collect::<Result<_, MemoryError>>()?;
        Ok(StepAdjoint { tape, seeds, phase_s: [0.0; 1 + PHASES.len()] })
    }

    /// The reverse sweep's wall seconds: the recompute, then each phase's adjoint in the order
    /// they run.
    pub fn phase_seconds(&self) -> Vec<(String, f64)> {
        let adjoints = PHASES.iter().enumerate().rev().filter(|(_, p)| p.has_adjoint());
        std::iter::once(("recompute".to_string(), self.phase_s[0])).chain(adjoints.map(|(i, p)| (p.name().to_string(), self.phase_s[1 + i]))).collect()
    }

    /// Reverse the step the live state of `sim` starts, for the seeds `active` marks (the others
    /// start later in the reverse sweep: their objectives come at earlier steps, their adjoints
    /// are still zero). `objectives` (seed, objective) are evaluated on the state after the step
    /// and seed those adjoints. The live state is consumed. Returns the objectives' values, in
    /// `objectives`' order.
    pub fn reverse(
        &mut self,
        sim: &mut Simulation,
        until: f64,
        objectives: &[(usize, &Objective)],
        frame: &Frame,
        active: &[bool],
        prints: &mut [Option<PrintParams>],
    ) -> Result<Vec<f64>, GradError> {
        let mut clock = Instant::now();
        let (dt, _) = sim.choose_dt(until);
        let mut step = Step::new(sim, dt);
        for phase in PHASES {
            if let Some(what) = phase.saves() {
                self.tape.save(what, sim);
            }
            if phase.read_by_adjoints() || !objectives.is_empty() {
                sim.run_phase(phase, &mut step)?;
            }
        }
        let n = sim.particles.n;
        let mut values = Vec::with_capacity(objectives.len());
        for &(k, obj) in objectives {
            let a = &mut self.seeds[k];
            let seed = Seed {
                xg: &mut a.next.xg.as_mut_slice()[..n],
                v: &mut a.next.v.as_mut_slice()[..n],
                j: &mut a.next.j.as_mut_slice()[..n],
                mass: &mut a.mass_bar.as_mut_slice()[..n],
                vol0: &mut a.vol0_bar.as_mut_slice()[..n],
            };
            values.push(obj.evaluate(sim, frame, Some(seed))?);
        }
        lap(&mut clock, &mut self.phase_s[0]);

        for (i, phase) in PHASES.iter().enumerate().rev().filter(|(_, p)| p.has_adjoint()) {
            for ((a, pp), _) in self.seeds.iter_mut().zip(prints.iter_mut()).zip(active).filter(|(_, on)| **on) {
                let toolpath = pp.as_mut().map(|p| p as &mut dyn ToolpathBar);
                sim.phase_adjoint(*phase, &step, &mut self.tape, a, toolpath)?;
            }
            lap(&mut clock, &mut self.phase_s[1 + i]);
        }
        for (a, _) in self.seeds.iter_mut().zip(active).filter(|(_, on)| **on) {
            a.end_step(n);
        }
        // timed with the last adjoint to run
        let last = PHASES.iter().position(|p| p.has_adjoint()).unwrap_or(0);
        lap(&mut clock, &mut self.phase_s[1 + last]);
        Ok(values)
    }
}

/// Add the time since `clock` to `acc` and restart the clock.
fn lap(clock: &mut Instant, acc: &mut f64) {
    let now = Instant::now();
    *acc += (now - *clock).as_secs_f64();
    *clock = now;
}
