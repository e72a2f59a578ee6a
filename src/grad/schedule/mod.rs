//! Checkpoint schedules: in which order to run, save, reload and reverse the forward steps so
//! that a reverse-mode gradient through `N` explicit steps (up to 10^7) sees the forward states
//! in reverse order while holding only a few of them.
//!
//! A schedule is a stream of [`Action`]s and knows nothing about the simulator: the gradient
//! driver executes the actions, and the schedules are tested alone against an abstract executor
//! that checks every precondition. Streams are generated lazily (O(slots) memory), so a plan for
//! 10^7 steps never holds 10^7 actions.
//!
//! # Conventions
//!
//! State `k` is the forward state before step `k`; step `k` maps state `k` to state `k + 1`.
//! The sweep starts with state 0 live. `Reverse { step: k }` is given the live state `k`: it
//! recomputes step `k` locally (the tape of one step) and maps the adjoint of state `k + 1` to
//! that of state `k`; for `k = N - 1` it also evaluates the objective on state `N`, so state `N`
//! is never needed by itself (Griewank's "youturn"). Forward work is counted as the steps run
//! by `Advance` actions; the one local recomputation inside every `Reverse` is not counted.
//! A slot holds one stored state; the live state is the simulator's own and takes no slot.
//!
//! # Strategies and their bounds (N steps)
//!
//! | kind | forward steps | peak slots |
//! |---|---|---|
//! | StoreAll | N - 1 | N - 1 (states 0..N-2; state N-1 stays live) |
//! | TwoLevel, segment `m` | L + N - ceil(N/m) < 2N, L = m (ceil(N/m) - 1) | <= ceil(N/m) + m - 2 |
//! | Revolve, s slots | t(N, s) = r N - C(s + r, r - 1), optimal | min(s, N - 1) |
//!
//! The default two-level segment m = ceil(sqrt N) gives at most 2 ceil(sqrt N) - 2 slots.
//! For Revolve, r is the repetition number, the least r with C(s + r, s) >= N: no step runs
//! more than r times, and t(N, s) is the least forward work of any schedule with s slots
//! (Griewank & Walther, "Algorithm 799: Revolve", 2000). Our own derivation, checked against a
//! brute-force dynamic programme in the tests, is in `revolve.rs`.
//!
//! The two tiers: Revolve keeps its checkpoints on a stack, and a checkpoint stays at its stack
//! position from store to free. Positions `0..disk_slots` (the bottom, sparse checkpoints such as
//! state 0, restored least often) live on disk and the rest (the dense top, restored for nearly
//! every reversed step) in RAM. So RAM never holds more than `ram_slots` states and disk never
//! more than `disk_slots`, and a disk checkpoint is read back only after everything stacked above
//! it, a whole RAM-tier sub-range, has been reversed.
//!
//! [`OnlineSchedule`] handles runs whose length is known only when they stop; its bound is in
//! `online.rs`.

#[cfg(test)]
mod executor;
mod online;
mod revolve;
mod two_level;

pub use online::{OnlineReverse, OnlineSchedule};

use crate::memory::fmt_bytes;
use std::collections::VecDeque;

/// Where a stored state lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Tier {
    Ram,
    Disk,
}

/// One instruction to the gradient driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Run the forward simulator from the live state at step `from` to step `to` (to > from).
    Advance { from: u64, to: u64 },
    /// Save the live state (the state at `step`) into a slot of `tier`.
    Store { step: u64, tier: Tier },
    /// Make the stored state at `step` live again; the slot stays stored.
    Restore { step: u64, tier: Tier },
    /// Take the adjoint of step `step` from the live state at `step`, which it consumes: the live
    /// state is undefined until the next `Restore`.
    Reverse { step: u64 },
    /// Drop the stored state at `step` from `tier`.
    Free { step: u64, tier: Tier },
}

/// Memory for checkpoints: the size of one stored state and what each tier may hold. The live
/// state is not counted here.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    pub state_bytes: u64,
    pub ram_bytes: u64,
    pub disk_bytes: u64,
}

/// The schedule strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Store every state of one forward sweep, then reverse: no recomputation.
    StoreAll,
    /// Store every `segment`-th state in a first sweep, then re-run each segment storing all of
    /// its states (paper 000 sec. 2.3).
    TwoLevel { segment: u64 },
    /// Binomial checkpointing: the fewest forward steps for the given slots.
    Revolve { ram_slots: usize, disk_slots: usize },
}

impl Kind {
    /// `store-all`, `two-level` (segment ceil(sqrt N)) or `two-level:SEGMENT`, and
    /// `revolve:RAM_SLOTS,DISK_SLOTS`. A two-level segment of 0 means ceil(sqrt N).
    pub fn parse(s: &str) -> Result<Kind, ScheduleError> {
        let bad = || ScheduleError::Unknown { name: s.to_string() };
        let num = |t: &str| t.trim().parse::<u64>().map_err(|_| bad());
        match s.split_once(':') {
            None if s == "store-all" => Ok(Kind::StoreAll),
            None if s == "two-level" => Ok(Kind::TwoLevel { segment: 0 }),
            Some(("two-level", m)) => Ok(Kind::TwoLevel { segment: num(m)? }),
            Some(("revolve", slots)) => {
                let (r, d) = slots.split_once(',').ok_or_else(bad)?;
                Ok(Kind::Revolve { ram_slots: num(r)? as usize, disk_slots: num(d)? as usize })
            }
            _ => Err(bad()),
        }
    }
}

#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum ScheduleError {
    #[error("the checkpoint budget gives a state size of 0 bytes; it must be the size of one stored forward state")]
    ZeroStateSize,
    #[error(
        "reversing {n_steps} steps needs at least one checkpoint slot of {} (the state size), but the RAM budget of {} and the disk budget of {} hold none",
        fmt_bytes(*state_bytes), fmt_bytes(*ram_bytes), fmt_bytes(*disk_bytes)
    )]
    NoRoom { n_steps: u64, state_bytes: u64, ram_bytes: u64, disk_bytes: u64 },
    #[error("reversing {n_steps} steps needs at least one checkpoint slot (for state 0), but the schedule has 0")]
    NoSlots { n_steps: u64 },
    #[error("a two-level schedule needs a segment of at least 1 step")]
    ZeroSegment,
    /// A schedule name `Kind::parse` does not know.
    #[error("schedule '{name}': expected store-all, two-level[:SEGMENT] or revolve:RAM_SLOTS,DISK_SLOTS")]
    Unknown { name: String },
}

/// A schedule for a known number of steps, with its cost worked out in advance.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    kind: Kind,
    n_steps: u64,
    forward_steps: u64,
    peak_slots: (usize, usize),
}

impl Plan {
    /// A plan of the given kind; fails if it cannot reverse `n_steps` at all.
    pub fn new(kind: Kind, n_steps: u64) -> Result<Plan, ScheduleError> {
        let (forward_steps, peak_slots) = match kind {
            Kind::StoreAll => {
                let segment = n_steps.max(1);
                (two_level::forward_steps(n_steps, segment), (two_level::peak_slots(n_steps, segment), 0))
            }
            Kind::TwoLevel { segment } => {
                if segment == 0 {
                    return Err(ScheduleError::ZeroSegment);
                }
                (two_level::forward_steps(n_steps, segment), (two_level::peak_slots(n_steps, segment), 0))
            }
            Kind::Revolve { ram_slots, disk_slots } => {
                let slots = ram_slots.saturating_add(disk_slots);
                if slots == 0 && n_steps >= 2 {
                    return Err(ScheduleError::NoSlots { n_steps });
                }
                // The stack fills from the bottom, so disk positions are taken first.
                let used = usize::try_from(n_steps.saturating_sub(1)).unwrap_or(usize::MAX).min(slots);
                let disk = used.min(disk_slots);
                (revolve::forward_steps(n_steps, slots as u64), (used - disk, disk))
            }
        };
        Ok(Plan { kind, n_steps, forward_steps, peak_slots })
    }

    pub fn store_all(n_steps: u64) -> Plan {
        Plan::new(Kind::StoreAll, n_steps).expect("store-all needs no slot budget")
    }

    /// Two-level checkpointing with the segment ceil(sqrt N), which minimises its peak slots.
    pub fn two_level(n_steps: u64) -> Plan {
        Plan::new(Kind::TwoLevel { segment: ceil_sqrt(n_steps).max(1) }, n_steps).expect("the segment is at least 1")
    }

    pub fn kind(&self) -> Kind {
        self.kind
    }

    pub fn n_steps(&self) -> u64 {
        self.n_steps
    }

    /// Steps run by all `Advance` actions together (saturating at `u64::MAX`; exact for
    /// N < 2^42).
    pub fn forward_steps(&self) -> u64 {
        self.forward_steps
    }

    /// Most states stored at once, as (RAM, disk).
    pub fn peak_slots(&self) -> (usize, usize) {
        self.peak_slots
    }

    /// The action stream, generated lazily.
    pub fn actions(&self) -> Actions {
        let generator = match self.kind {
            Kind::StoreAll => Generator::TwoLevel(two_level::TwoLevel::new(self.n_steps, self.n_steps.max(1))),
            Kind::TwoLevel { segment } => Generator::TwoLevel(two_level::TwoLevel::new(self.n_steps, segment)),
            Kind::Revolve { ram_slots, disk_slots } => Generator::Revolve(revolve::Revolve::new(
                self.n_steps,
                ram_slots.saturating_add(disk_slots),
                disk_slots,
            )),
        };
        Actions { pending: VecDeque::new(), generator }
    }
}

/// The plan for `n_steps` within `budget`: store-all when every needed state fits in RAM;
/// otherwise Revolve with as many RAM slots as fit, plus the fewest disk slots that give the
/// fewest forward steps the disk budget allows.
pub fn choose(n_steps: u64, budget: &Budget) -> Result<Plan, ScheduleError> {
    if budget.state_bytes == 0 {
        return Err(ScheduleError::ZeroStateSize);
    }
    let needed = n_steps.saturating_sub(1);
    let ram = budget.ram_bytes / budget.state_bytes;
    if needed <= ram {
        return Ok(Plan::store_all(n_steps));
    }
    // More than `needed` slots in all would never be used.
    let disk = (budget.disk_bytes / budget.state_bytes).min(needed - ram);
    if ram + disk == 0 {
        return Err(ScheduleError::NoRoom {
            n_steps,
            state_bytes: budget.state_bytes,
            ram_bytes: budget.ram_bytes,
            disk_bytes: budget.disk_bytes,
        });
    }
    // Forward work falls as slots are added, so the fewest disk slots reaching the optimum of
    // the whole disk budget are found by bisection; disk traffic is slow and is kept to those.
    let best = revolve::forward_steps(n_steps, ram + disk);
    let (mut lo, mut hi) = (0, disk);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if revolve::forward_steps(n_steps, ram + mid) == best {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    // Both counts are below `needed`, which indexes states, so they fit a usize on 64-bit
    // targets; saturating keeps 32-bit targets within their own address space.
    let as_slots = |x: u64| usize::try_from(x).unwrap_or(usize::MAX);
    Plan::new(Kind::Revolve { ram_slots: as_slots(ram), disk_slots: as_slots(lo) }, n_steps)
}

/// The lazy action stream of a [`Plan`].
pub struct Actions {
    pending: VecDeque<Action>,
    generator: Generator,
}

enum Generator {
    TwoLevel(two_level::TwoLevel),
    Revolve(revolve::Revolve),
}

impl Iterator for Actions {
    type Item = Action;

    fn next(&mut self) -> Option<Action> {
        loop {
            if let Some(action) = self.pending.pop_front() {
                return Some(action);
            }
            let more = match &mut self.generator {
                Generator::TwoLevel(g) => g.refill(&mut self.pending),
                Generator::Revolve(g) => g.refill(&mut self.pending),
            };
            if !more {
                return None;
            }
        }
    }
}

fn ceil_sqrt(n: u64) -> u64 {
    let mut r = (n as f64).sqrt() as u64;
    while r.saturating_mul(r) < n {
        r += 1;
    }
    while r > 0 && (r - 1) * (r - 1) >= n {
        r -= 1;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::executor::run;
    use super::*;

    #[test]
    fn store_all_stores_every_state_but_the_live_one() {
        for n in [0u64, 1, 2, 3, 7, 100, 10_000] {
            let plan = Plan::store_all(n);
            let stats = run(&plan.actions().collect::<Vec<_>>(), n);
            assert_eq!(stats.forward_steps, n.saturating_sub(1), "N = {n}");
            assert_eq!(stats.forward_steps, plan.forward_steps(), "N = {n}");
            assert_eq!(stats.peak, (n.saturating_sub(1) as usize, 0), "N = {n}");
            assert_eq!(stats.peak, plan.peak_slots(), "N = {n}");
        }
    }

    #[test]
    fn two_level_is_valid_and_peaks_near_two_sqrt_n() {
        for n in [0u64, 1, 2, 3, 4, 5, 17, 97, 100, 101, 1009, 10_000] {
            for segment in [ceil_sqrt(n).max(1), 1, 7] {
                let plan = Plan::new(Kind::TwoLevel { segment }, n).unwrap();
                let stats = run(&plan.actions().collect::<Vec<_>>(), n);
                assert_eq!(stats.forward_steps, plan.forward_steps(), "{plan:?}");
                assert_eq!(stats.peak, plan.peak_slots(), "{plan:?}");
                assert!(stats.max_runs_per_step <= 2, "{plan:?}: at most two sweeps");
                let bound = (n.div_ceil(segment) + segment).saturating_sub(2) as usize;
                assert!(stats.peak.0 <= bound, "{plan:?}: peak {:?} > {bound}", stats.peak);
            }
            let default = Plan::two_level(n);
            let bound = (2 * ceil_sqrt(n)).saturating_sub(2) as usize;
            assert!(default.peak_slots().0 <= bound, "N = {n}: {:?} > 2 ceil(sqrt N) - 2", default.peak_slots());
        }
    }

    #[test]
    fn revolve_is_valid_for_edge_small_prime_and_large_n() {
        for n in [0u64, 1, 2, 3, 5, 13, 61, 97, 256, 1009, 10_000] {
            for (ram, disk) in
                [(1, 0), (2, 0), (3, 0), (0, 1), (0, 3), (1, 1), (2, 3), (5, 2), (16, 0), (64, 0), (4, 60)]
            {
                if n >= 2_000 && ram + disk < 3 {
                    continue; // quadratic work; small N covers these slot counts
                }
                let plan = Plan::new(Kind::Revolve { ram_slots: ram, disk_slots: disk }, n).unwrap();
                let stats = run(&plan.actions().collect::<Vec<_>>(), n);
                assert_eq!(stats.forward_steps, plan.forward_steps(), "{plan:?}");
                assert_eq!(stats.peak, plan.peak_slots(), "{plan:?}");
                assert!(stats.peak.0 <= ram && stats.peak.1 <= disk, "{plan:?}: peak {:?}", stats.peak);
            }
        }
    }

    #[test]
    fn revolve_without_slots_is_refused_only_when_slots_are_needed() {
        for n in [0, 1] {
            assert!(Plan::new(Kind::Revolve { ram_slots: 0, disk_slots: 0 }, n).is_ok());
        }
        assert_eq!(
            Plan::new(Kind::Revolve { ram_slots: 0, disk_slots: 0 }, 2),
            Err(ScheduleError::NoSlots { n_steps: 2 })
        );
        assert_eq!(Plan::new(Kind::TwoLevel { segment: 0 }, 5), Err(ScheduleError::ZeroSegment));
    }

    const MIB: u64 = 1 << 20;

    #[test]
    fn choose_stores_all_when_it_fits() {
        let budget = Budget { state_bytes: MIB, ram_bytes: 99 * MIB, disk_bytes: 0 };
        assert_eq!(choose(100, &budget).unwrap().kind(), Kind::StoreAll);
        // Steps 0 and 1 need no slot at all.
        let nothing = Budget { state_bytes: MIB, ram_bytes: 0, disk_bytes: 0 };
        assert_eq!(choose(1, &nothing).unwrap().kind(), Kind::StoreAll);
        assert_eq!(choose(0, &nothing).unwrap().kind(), Kind::StoreAll);
    }

    #[test]
    fn choose_uses_revolve_under_a_tight_ram_cap() {
        let budget = Budget { state_bytes: MIB, ram_bytes: 98 * MIB + 5, disk_bytes: 0 };
        let plan = choose(100, &budget).unwrap();
        assert_eq!(plan.kind(), Kind::Revolve { ram_slots: 98, disk_slots: 0 });
        assert_eq!(plan.forward_steps(), 100, "one step runs twice");
        let tight = Budget { state_bytes: MIB, ram_bytes: 10 * MIB, disk_bytes: 0 };
        let plan = choose(1_000_000, &tight).unwrap();
        assert_eq!(plan.kind(), Kind::Revolve { ram_slots: 10, disk_slots: 0 });
        assert!(plan.peak_slots().0 <= 10);
    }

    #[test]
    fn choose_adds_disk_slots_only_where_ram_runs_out() {
        // No RAM slot at all: everything on disk.
        let budget = Budget { state_bytes: MIB, ram_bytes: MIB - 1, disk_bytes: 5 * MIB };
        let plan = choose(1000, &budget).unwrap();
        assert_eq!(plan.kind(), Kind::Revolve { ram_slots: 0, disk_slots: 5 });
        // Ample disk: enough disk slots to store every state, not more.
        let budget = Budget { state_bytes: MIB, ram_bytes: 3 * MIB, disk_bytes: 10_000 * MIB };
        let plan = choose(1000, &budget).unwrap();
        assert_eq!(plan.kind(), Kind::Revolve { ram_slots: 3, disk_slots: 996 });
        assert_eq!(plan.forward_steps(), 999);
        // The fewest disk slots that reach the optimum: one fewer would cost forward work.
        let budget = Budget { state_bytes: MIB, ram_bytes: 64 * MIB, disk_bytes: 1000 * MIB };
        let plan = choose(100, &budget).unwrap();
        let Kind::Revolve { ram_slots: 64, disk_slots } = plan.kind() else { panic!("{plan:?}") };
        let fewer = Plan::new(Kind::Revolve { ram_slots: 64, disk_slots: disk_slots - 1 }, 100).unwrap();
        assert!(fewer.forward_steps() > plan.forward_steps(), "{plan:?} uses a needless disk slot");
        assert_eq!(plan.forward_steps(), 99);
    }

    #[test]
    fn choose_names_the_numbers_when_nothing_fits() {
        let budget = Budget { state_bytes: 3 * MIB, ram_bytes: 2 * MIB, disk_bytes: MIB };
        let err = choose(500, &budget).unwrap_err();
        assert_eq!(
            err,
            ScheduleError::NoRoom { n_steps: 500, state_bytes: 3 * MIB, ram_bytes: 2 * MIB, disk_bytes: MIB }
        );
        let text = err.to_string();
        for needle in ["500 steps", "3.00 MiB", "2.00 MiB", "1.00 MiB"] {
            assert!(text.contains(needle), "'{text}' lacks '{needle}'");
        }
        let zero = Budget { state_bytes: 0, ram_bytes: MIB, disk_bytes: MIB };
        assert_eq!(choose(5, &zero), Err(ScheduleError::ZeroStateSize));
    }

    #[test]
    fn ceil_sqrt_is_exact() {
        for n in 0..10_000u64 {
            let r = ceil_sqrt(n);
            assert!(r * r >= n && (r == 0 || (r - 1) * (r - 1) < n), "n = {n}: {r}");
        }
        assert_eq!(ceil_sqrt(10_000_000), 3163);
    }
}
