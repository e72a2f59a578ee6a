//! Checkpointing for a run whose length is known only when it stops (a stop condition).
//!
//! Forward phase: with S slots, at most K = max(1, floor(S/2)) are kept during the run, at every
//! multiple of a spacing d that starts at 1. When a new multiple of d arrives and K are kept, d
//! doubles and every kept step that is not a multiple of the new d is freed ("thinning"). Kept
//! are then always exactly the multiples of d at or below the current step, never more than K:
//! a doubling happens at step K d, and the multiples of 2d up to K d number floor(K/2) + 1 <= K.
//!
//! Reverse phase, once the run stops after N steps: the gaps between kept steps (and from the
//! last one to N) are reversed from the top down, each by Revolve with the slots not held by
//! the kept steps below it; gap i (counting from 0) gets S - i >= S - K + 1 slots.
//!
//! Bound: every gap is at most d long, and d <= max(1, 2(N - 1)/K) because the last doubling
//! happened at a step K d_old <= N - 1. Revolve runs each step of a gap at most rho times, rho
//! the least r with C(S - K + 1 + r, r) >= max(1, floor(2(N - 1)/K)). So the total forward work,
//! the N steps of the run itself included, is at most N (1 + rho). For comparison, knowing N in
//! advance gives about r N with C(S + r, r) >= N; halving the slots for the kept steps is a
//! middle course between storing everything for short runs (N <= K costs just N) and a full
//! Revolve over the whole run for long ones. With S = 64 and N = 10^7, rho = 6 against r = 5; in
//! practice the gaps are shorter than d and the cost is close to the offline optimum (measured:
//! N = 10^6, S = 64, 4.27 N online against 4.14 N offline).

use super::revolve::Revolve;
use super::{Action, ScheduleError, Tier};
use std::collections::VecDeque;

/// Forward-phase decisions for a run of unknown length. Call [`OnlineSchedule::on_step`] each
/// time the run is about to advance from its live state (first with state 0), carry out the
/// returned actions, and call [`OnlineSchedule::finish`] when the run stops.
pub struct OnlineSchedule {
    slots: usize,
    kept_limit: usize,
    spacing: u64,
    /// Kept steps, ascending: exactly the multiples of `spacing` below `next_step`.
    kept: Vec<u64>,
    next_step: u64,
    pending: Vec<Action>,
}

impl OnlineSchedule {
    pub fn new(slots: usize) -> Result<OnlineSchedule, ScheduleError> {
        if slots == 0 {
            // Any run of two steps or more would need state 0 back.
            return Err(ScheduleError::NoSlots { n_steps: 2 });
        }
        let kept_limit = (slots / 2).max(1);
        Ok(OnlineSchedule {
            slots,
            kept_limit,
            spacing: 1,
            kept: Vec::new(),
            next_step: 0,
            pending: Vec::new(),
        })
    }

    /// The run is about to advance from the live state at step [`OnlineSchedule::steps`]: the
    /// `Free`s and the `Store` (of the live state) to carry out first.
    pub fn on_step(&mut self) -> std::vec::Drain<'_, Action> {
        let step = self.next_step;
        self.next_step += 1;
        if step.is_multiple_of(self.spacing) {
            if self.kept.len() == self.kept_limit {
                self.spacing *= 2;
                let spacing = self.spacing;
                for &old in self.kept.iter().filter(|&&k| !k.is_multiple_of(spacing)) {
                    self.pending.push(Action::Free { step: old, tier: Tier::Ram });
                }
                self.kept.retain(|&k| k.is_multiple_of(spacing));
            }
            if step.is_multiple_of(self.spacing) {
                self.pending.push(Action::Store { step, tier: Tier::Ram });
                self.kept.push(step);
            }
        }
        self.pending.drain(..)
    }

    /// Steps run so far: the N of the reversal if the run stops now.
    pub fn steps(&self) -> u64 {
        self.next_step
    }

    /// The kept steps, ascending.
    pub fn kept(&self) -> &[u64] {
        &self.kept
    }

    /// The reverse phase for a run that stopped after [`OnlineSchedule::steps`] steps.
    pub fn finish(self) -> OnlineReverse {
        OnlineReverse { slots: self.slots, end: self.next_step, kept: self.kept, gap: None, pending: VecDeque::new() }
    }
}

/// The lazy action stream reversing an online run.
pub struct OnlineReverse {
    slots: usize,
    /// Steps below `end` are not yet handed to a gap.
    end: u64,
    /// Kept steps whose gaps are still to come.
    kept: Vec<u64>,
    gap: Option<Revolve>,
    pending: VecDeque<Action>,
}

impl Iterator for OnlineReverse {
    type Item = Action;

    fn next(&mut self) -> Option<Action> {
        loop {
            if let Some(action) = self.pending.pop_front() {
                return Some(action);
            }
            if let Some(gap) = &mut self.gap {
                if gap.refill(&mut self.pending) {
                    continue;
                }
            }
            let base = self.kept.pop()?;
            // The kept steps below this gap keep their slots until their own gaps.
            let slots = self.slots - self.kept.len();
            self.gap = Some(Revolve::from_stored(base, self.end, slots));
            self.end = base;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::executor::Executor;
    use super::super::revolve::repetitions;
    use super::*;
    use proptest::prelude::*;

    /// Run `n` steps online, then reverse; returns the executor for its statistics.
    fn run_online(n: u64, slots: usize) -> Executor {
        let mut schedule = OnlineSchedule::new(slots).unwrap();
        let mut exec = Executor::new(n);
        for step in 0..n {
            assert_eq!(schedule.steps(), step);
            for action in schedule.on_step() {
                exec.apply(action);
            }
            assert!(schedule.kept().len() <= (slots / 2).max(1), "step {step}: kept {:?}", schedule.kept());
            exec.apply(Action::Advance { from: step, to: step + 1 });
        }
        for action in schedule.finish() {
            exec.apply(action);
        }
        exec.finish();
        exec
    }

    /// The bound of the module docs, computed from N and S alone.
    fn work_bound(n: u64, slots: usize) -> u64 {
        let kept = (slots / 2).max(1) as u64;
        let gap = (2 * n.saturating_sub(1) / kept).max(1);
        let rho = repetitions(gap, slots as u64 - kept + 1);
        n * (1 + rho)
    }

    #[test]
    fn online_reversal_is_valid_and_bounded() {
        for slots in [1usize, 2, 3, 4, 5, 8, 13, 64] {
            for n in [0u64, 1, 2, 3, 7, 31, 32, 33, 97, 1000, 4099] {
                if slots == 1 && n > 1000 {
                    continue; // quadratic by design
                }
                let exec = run_online(n, slots);
                let stats = exec.stats();
                assert!(stats.peak.0 <= slots, "N = {n}, S = {slots}: peak {:?}", stats.peak);
                assert!(stats.forward_steps <= work_bound(n, slots), "N = {n}, S = {slots}: {}", stats.forward_steps);
            }
        }
    }

    #[test]
    fn short_online_runs_store_everything() {
        let stats = run_online(30, 64).stats();
        assert_eq!(stats.forward_steps, 30, "no recomputation when every state is kept");
    }

    #[test]
    fn online_without_slots_is_refused() {
        assert!(OnlineSchedule::new(0).is_err());
    }

    #[test]
    fn sixty_four_slots_for_ten_million_steps_cost_at_most_seven_sweeps() {
        assert_eq!(work_bound(10_000_000, 64), 70_000_000);
    }

    proptest! {
        #[test]
        fn online_stops_anywhere(n in 0u64..5000, slots in 2usize..24) {
            let stats = run_online(n, slots).stats();
            prop_assert!(stats.peak.0 <= slots);
            prop_assert!(stats.forward_steps <= work_bound(n, slots));
        }
    }
}
