//! An abstract executor for the tests: it carries out a stream on a model of the live state and
//! the slots, panics on the first action whose precondition fails, and measures the cost.

use super::{Action, Tier};
use std::collections::HashMap;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Stats {
    pub forward_steps: u64,
    /// Most states stored at once, as (RAM, disk).
    pub peak: (usize, usize),
    /// How often the most re-run step was advanced over.
    pub max_runs_per_step: u64,
}

pub(super) struct Executor {
    n: u64,
    live: Option<u64>,
    stored: HashMap<u64, Tier>,
    in_tier: (usize, usize),
    stats: Stats,
    runs: Vec<u64>,
    /// The step the next `Reverse` must take: they come as N - 1, N - 2, ..., 0.
    next_reverse: u64,
    actions: u64,
}

impl Executor {
    pub(super) fn new(n: u64) -> Executor {
        Executor {
            n,
            live: Some(0),
            stored: HashMap::new(),
            in_tier: (0, 0),
            stats: Stats { forward_steps: 0, peak: (0, 0), max_runs_per_step: 0 },
            runs: vec![0; n as usize],
            next_reverse: n,
            actions: 0,
        }
    }

    fn count(&mut self, tier: Tier) -> &mut usize {
        match tier {
            Tier::Ram => &mut self.in_tier.0,
            Tier::Disk => &mut self.in_tier.1,
        }
    }

    pub(super) fn apply(&mut self, action: Action) {
        let at = format!("action {} ({action:?}), live {:?}", self.actions, self.live);
        self.actions += 1;
        match action {
            Action::Advance { from, to } => {
                assert_eq!(self.live, Some(from), "{at}: advance from a state that is not live");
                assert!(to > from && to <= self.n, "{at}: bad advance range for N = {}", self.n);
                self.stats.forward_steps += to - from;
                for runs in &mut self.runs[from as usize..to as usize] {
                    *runs += 1;
                    self.stats.max_runs_per_step = self.stats.max_runs_per_step.max(*runs);
                }
                self.live = Some(to);
            }
            Action::Store { step, tier } => {
                assert_eq!(self.live, Some(step), "{at}: store of a state that is not live");
                assert!(self.stored.insert(step, tier).is_none(), "{at}: state already stored");
                *self.count(tier) += 1;
                let (ram, disk) = self.in_tier;
                self.stats.peak = (self.stats.peak.0.max(ram), self.stats.peak.1.max(disk));
            }
            Action::Restore { step, tier } => {
                assert_eq!(self.stored.get(&step), Some(&tier), "{at}: restore of a state not stored there");
                self.live = Some(step);
            }
            Action::Reverse { step } => {
                assert_eq!(self.live, Some(step), "{at}: reverse without its live state");
                assert_eq!(step + 1, self.next_reverse, "{at}: reversed out of order");
                self.next_reverse = step;
                self.live = None;
            }
            Action::Free { step, tier } => {
                assert_eq!(self.stored.remove(&step), Some(tier), "{at}: free of a state not stored there");
                *self.count(tier) -= 1;
            }
        }
    }

    /// Every step reversed and every slot freed.
    pub(super) fn finish(&self) {
        assert_eq!(self.next_reverse, 0, "steps below {} never reversed", self.next_reverse);
        assert!(self.stored.is_empty(), "still stored at the end: {:?}", self.stored);
    }

    pub(super) fn stats(&self) -> Stats {
        self.stats
    }
}

/// Execute a whole offline stream for `n` steps, checking it, and return its cost.
pub(super) fn run(actions: &[Action], n: u64) -> Stats {
    let mut exec = Executor::new(n);
    for &action in actions {
        exec.apply(action);
    }
    exec.finish();
    exec.stats()
}

mod tests {
    use super::*;

    fn panics(actions: &[Action], n: u64) -> bool {
        let actions = actions.to_vec();
        std::panic::catch_unwind(move || run(&actions, n)).is_err()
    }

    #[test]
    fn executor_rejects_each_broken_precondition() {
        use Action::*;
        let ram = Tier::Ram;
        let good = [
            Store { step: 0, tier: ram },
            Advance { from: 0, to: 1 },
            Reverse { step: 1 },
            Restore { step: 0, tier: ram },
            Free { step: 0, tier: ram },
            Reverse { step: 0 },
        ];
        assert!(!panics(&good, 2));
        let broken: [&[Action]; 9] = [
            &[Advance { from: 1, to: 2 }],                                          // not live
            &[Store { step: 0, tier: ram }, Store { step: 0, tier: ram }],          // duplicate
            &[Store { step: 1, tier: ram }],                                        // not live
            &[Restore { step: 0, tier: ram }],                                      // not stored
            &[Reverse { step: 0 }],                                                 // out of order
            &[Free { step: 0, tier: ram }],                                         // not stored
            &[Store { step: 0, tier: ram }, Restore { step: 0, tier: Tier::Disk }], // wrong tier
            &good[..3],                                                             // step 0 never reversed
            // The live state was consumed by the first reverse.
            &[Store { step: 0, tier: ram }, Advance { from: 0, to: 1 }, Reverse { step: 1 }, Reverse { step: 0 }],
        ];
        for actions in broken {
            assert!(panics(actions, 2), "accepted {actions:?}");
        }
    }
}
