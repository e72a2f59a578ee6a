//! Binomial checkpointing (Revolve), generated lazily from a stack of stored steps.
//!
//! Let t(n, s) be the least forward work to reverse n steps whose first state is live and held
//! in one of s slots. One step needs nothing (t(1, s) = 0); with one slot every reversed step
//! re-runs from the base (t(n, 1) = n(n - 1)/2); otherwise the best schedule advances k steps,
//! stores there, reverses the upper n - k steps with the other s - 1 slots and then the lower k
//! with all s again:
//!
//!   t(n, s) = min over 1 <= k < n of  k + t(n - k, s - 1) + t(k, s).
//!
//! Closed form: with r the least integer with beta(s, r) = C(s + r, s) >= n,
//! t(n, s) = r n - beta(s + 1, r - 1). Both f(k) = k + t(k, s) and g(m) = t(m, s - 1) are
//! convex and piecewise linear: f rises by v + 1 over beta(s - 1, v) unit steps (v = 0, 1, ...)
//! and g by v over beta(s - 2, v), so the split is the cheapest n unit steps drawn from both.
//! Those are all with a rise below r (beta(s, r - 2) from f, beta(s - 1, r - 1) from g, together
//! beta(s, r - 1)) plus R = n - beta(s, r - 1) of the rise-r ones, where f offers
//! beta(s - 1, r - 1) and g offers beta(s - 2, r). Every such draw is optimal; we give f as many
//! as it offers:
//!
//!   k = beta(s, r - 2) + min(R, beta(s - 1, r - 1)),  1 <= k <= n - 1.
//!
//! The generator is iterative: the stack holds the stored steps, its top is the base of the range
//! being reversed, and the free slots are `slots - stack.len()`. The upper range of a split runs
//! with one slot fewer because its base sits on top of the stack; once it is done that base is
//! freed and the lower range sees the same stack, hence the same slots, as before the split. So
//! each decision depends only on (top, end, stack height) and the stream follows the recurrence
//! exactly, in O(slots) memory.

use super::{Action, Tier};
use std::collections::VecDeque;

/// C(s + r, r), saturating; exact whenever the true value times min(s, r) is below 2^128.
pub(super) fn beta(s: u64, r: u64) -> u128 {
    let j = s.min(r) as u128;
    let m = s as u128 + r as u128;
    let mut b: u128 = 1;
    for i in 1..=j {
        // b * (m - j + i) = C(m - j + i, i) * i, so the division is exact.
        match b.checked_mul(m - j + i) {
            Some(p) => b = p / i,
            None => return u128::MAX,
        }
    }
    b
}

/// The repetition number: the least r with beta(slots, r) >= n (n >= 1, slots >= 1).
pub(super) fn repetitions(n: u64, slots: u64) -> u64 {
    if slots == 1 {
        return n.saturating_sub(1);
    }
    let (mut r, mut b) = (0u64, 1u128);
    while b < n as u128 {
        r += 1;
        // beta(s, r) = beta(s, r - 1) (s + r) / r; once past n it no longer matters exactly.
        b = b.saturating_mul(slots as u128 + r as u128) / r as u128;
    }
    r
}

/// t(n, slots), saturating at `u64::MAX` (and `u64::MAX` when there are no slots but n >= 2).
pub(super) fn forward_steps(n: u64, slots: u64) -> u64 {
    if n <= 1 {
        return 0;
    }
    if slots == 0 {
        return u64::MAX;
    }
    // Beyond n - 1 slots every state is stored anyway; clamping keeps slots + 1 in range.
    let slots = slots.min(n);
    let r = repetitions(n, slots);
    let subtract = if r == 0 { 0 } else { beta(slots + 1, r - 1) };
    let t = (r as u128 * n as u128).saturating_sub(subtract);
    u64::try_from(t).unwrap_or(u64::MAX)
}

/// Where to store next when reversing `n >= 2` steps with `slots >= 2` (the base included).
fn split(n: u64, slots: u64) -> u64 {
    // As in `forward_steps`: more than n - 1 slots change nothing.
    let slots = slots.min(n);
    let r = repetitions(n, slots);
    // r >= 1 since beta(s, 0) = 1 < n; all binomials below are at most n, hence exact.
    let below = if r >= 2 { beta(slots, r - 2) } else { 0 };
    let rest = n as u128 - beta(slots, r - 1);
    (below + rest.min(beta(slots - 1, r - 1))) as u64
}

/// The action generator for reversing steps `start..end`.
pub(super) struct Revolve {
    start: u64,
    /// Steps `start..end` are still to be reversed.
    end: u64,
    /// Stored steps, ascending; position i is on disk when i < `disk_slots`.
    stack: Vec<u64>,
    slots: usize,
    disk_slots: usize,
    /// The step of the live state, if it is defined.
    live: Option<u64>,
}

impl Revolve {
    /// Reverse steps `0..n_steps` starting from the live state 0.
    pub(super) fn new(n_steps: u64, slots: usize, disk_slots: usize) -> Revolve {
        Revolve { start: 0, end: n_steps, stack: Vec::new(), slots, disk_slots, live: Some(0) }
    }

    /// Reverse steps `start..end` whose base state is already stored in RAM (and freed here).
    pub(super) fn from_stored(start: u64, end: u64, slots: usize) -> Revolve {
        Revolve { start, end, stack: vec![start], slots, disk_slots: 0, live: None }
    }

    fn tier(&self, position: usize) -> Tier {
        if position < self.disk_slots {
            Tier::Disk
        } else {
            Tier::Ram
        }
    }

    fn reverse_live(&mut self, step: u64, out: &mut VecDeque<Action>) {
        out.push_back(Action::Reverse { step });
        self.end = step;
        self.live = None;
    }

    /// Push the next few actions; false once the stream has ended.
    pub(super) fn refill(&mut self, out: &mut VecDeque<Action>) -> bool {
        if self.end <= self.start {
            return false;
        }
        let Some(&top) = self.stack.last() else {
            // Before anything is stored, the live state is the start.
            if self.end - self.start == 1 {
                self.reverse_live(self.start, out);
            } else {
                out.push_back(Action::Store { step: self.start, tier: self.tier(0) });
                self.stack.push(self.start);
            }
            return true;
        };
        let tier = self.tier(self.stack.len() - 1);
        if self.live != Some(top) {
            out.push_back(Action::Restore { step: top, tier });
            self.live = Some(top);
        }
        let n = self.end - top;
        if n == 1 {
            self.stack.pop();
            out.push_back(Action::Free { step: top, tier });
            self.reverse_live(top, out);
            return true;
        }
        let free = self.slots - self.stack.len();
        let k = if free == 0 { n - 1 } else { split(n, free as u64 + 1) };
        out.push_back(Action::Advance { from: top, to: top + k });
        self.live = Some(top + k);
        if n - k == 1 {
            self.reverse_live(top + k, out);
        } else {
            out.push_back(Action::Store { step: top + k, tier: self.tier(self.stack.len()) });
            self.stack.push(top + k);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::super::executor::{run, Stats};
    use super::super::{Kind, Plan};
    use super::*;
    use proptest::prelude::*;

    /// The recurrence of the module docs by brute force, independent of the closed form.
    fn optimum_table(max_n: usize, max_slots: usize) -> Vec<Vec<u64>> {
        const NONE: u64 = u64::MAX;
        // t[s][n]; with no slot only a single step can be reversed.
        let mut t = vec![vec![NONE; max_n + 1]; max_slots + 1];
        for row in t.iter_mut() {
            row[0] = 0;
            row[1] = 0;
        }
        for s in 1..=max_slots {
            for n in 2..=max_n {
                t[s][n] = (1..n)
                    .filter(|&k| t[s - 1][n - k] != NONE)
                    .map(|k| k as u64 + t[s - 1][n - k] + t[s][k])
                    .min()
                    .unwrap_or(NONE);
            }
        }
        t
    }

    fn run_revolve(n: u64, ram: usize, disk: usize) -> (Plan, Stats) {
        let plan = Plan::new(Kind::Revolve { ram_slots: ram, disk_slots: disk }, n).unwrap();
        let stats = run(&plan.actions().collect::<Vec<_>>(), n);
        (plan, stats)
    }

    #[test]
    fn revolve_forward_work_is_the_brute_force_optimum() {
        let t = optimum_table(60, 6);
        for s in 1..=6 {
            for n in 0..=60u64 {
                let (plan, stats) = run_revolve(n, s, 0);
                assert_eq!(stats.forward_steps, t[s][n as usize], "N = {n}, s = {s}");
                assert_eq!(plan.forward_steps(), t[s][n as usize], "closed form, N = {n}, s = {s}");
                // Splitting the slots across tiers changes where states live, not the work.
                let (_, split_tiers) = run_revolve(n, s / 2, s - s / 2);
                assert_eq!(split_tiers.forward_steps, t[s][n as usize], "N = {n}, s = {s} over two tiers");
            }
        }
    }

    #[test]
    fn closed_form_matches_the_recurrence_beyond_the_brute_force_range() {
        let t = optimum_table(400, 12);
        for s in 1..=12 {
            for n in 0..=400u64 {
                assert_eq!(forward_steps(n, s as u64), t[s][n as usize], "N = {n}, s = {s}");
            }
        }
    }

    #[test]
    fn no_step_runs_more_than_the_repetition_number() {
        for (n, s) in [(1000u64, 3usize), (10_000, 8), (4_096, 2)] {
            let (_, stats) = run_revolve(n, s, 0);
            let r = repetitions(n, s as u64);
            assert!(stats.max_runs_per_step <= r, "N = {n}, s = {s}: {} > r = {r}", stats.max_runs_per_step);
        }
    }

    #[test]
    fn binomials_are_exact_and_saturate() {
        assert_eq!(beta(3, 2), 10);
        assert_eq!(beta(0, 7), 1);
        assert_eq!(beta(64, 5), 11_238_513);
        assert_eq!(beta(1000, 1000), u128::MAX);
        assert_eq!(repetitions(10_000_000, 64), 5);
        assert_eq!(repetitions(1, 5), 0);
        assert_eq!(forward_steps(5, 0), u64::MAX);
        assert_eq!(forward_steps(5, u64::MAX), 4);
        assert_eq!(split(5, u64::MAX), 1);
    }

    /// The stream is lazy: 10^7 steps with 64 slots (about 5 10^7 actions, a third of a second
    /// in release) are counted action by action without being held, and the forward work is
    /// the closed form.
    #[test]
    fn ten_million_steps_stream_lazily() {
        let (n, slots) = (10_000_000u64, 64);
        let plan = Plan::new(Kind::Revolve { ram_slots: slots, disk_slots: 0 }, n).unwrap();
        let (mut actions, mut advanced, mut next_reverse) = (0u64, 0u64, n);
        for action in plan.actions() {
            actions += 1;
            match action {
                Action::Advance { from, to } => advanced += to - from,
                Action::Reverse { step } => {
                    assert_eq!(step + 1, next_reverse, "reversed out of order");
                    next_reverse = step;
                }
                _ => {}
            }
        }
        assert_eq!(next_reverse, 0);
        assert_eq!(advanced, plan.forward_steps());
        assert!(actions < 6 * n, "{actions} actions for {n} steps");
    }

    proptest! {
        #[test]
        fn revolve_is_valid_for_random_sizes(n in 0u64..3000, ram in 0usize..12, disk in 0usize..6) {
            prop_assume!(ram + disk >= 3 || n <= 300);
            prop_assume!(ram + disk >= 1 || n <= 1);
            let (plan, stats) = run_revolve(n, ram, disk);
            prop_assert_eq!(stats.forward_steps, plan.forward_steps());
            prop_assert_eq!(stats.peak, plan.peak_slots());
            prop_assert!(stats.peak.0 <= ram && stats.peak.1 <= disk);
        }
    }
}
