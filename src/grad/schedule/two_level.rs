//! Two-level segment checkpointing (paper 000 sec. 2.3), and store-all as its one-segment case.
//!
//! A first sweep stores the start of every segment of `segment` steps. Then, from the last
//! segment to the first, the segment start is restored and the segment re-run storing each of its
//! states but the last (which stays live), and the segment is reversed, freeing as it goes. Every
//! step runs at most twice; with m = ceil(N / segment) segments, the stored states peak at the m
//! segment starts plus the inner states of one segment. The last segment's start is stored only
//! if the segment has a second step, because the first sweep ends with that start live.

use super::{Action, Tier};
use std::collections::VecDeque;

fn segments(n: u64, segment: u64) -> u64 {
    n.div_ceil(segment)
}

/// First sweep to the last segment start, then each segment but its last step.
pub(super) fn forward_steps(n: u64, segment: u64) -> u64 {
    if n == 0 {
        return 0;
    }
    let m = segments(n, segment);
    (m - 1) * segment + n - m
}

pub(super) fn peak_slots(n: u64, segment: u64) -> usize {
    if n == 0 {
        return 0;
    }
    let m = segments(n, segment);
    let last_len = n - (m - 1) * segment;
    let last_start_stored = u64::from(last_len >= 2);
    // While the last segment is reversed every start is stored; while the one below it is,
    // the last start is gone but that segment is full length.
    let during_last = (m - 1) + last_start_stored + last_len.saturating_sub(2);
    let during_full = if m >= 2 { (m - 1) + segment.saturating_sub(2) } else { 0 };
    usize::try_from(during_last.max(during_full)).unwrap_or(usize::MAX)
}

enum Phase {
    /// The first sweep; the live state is the segment start `at`.
    Sweep {
        at: u64,
    },
    /// The segment at `start` must be reloaded before it is re-run.
    Enter {
        start: u64,
    },
    /// Re-running the segment at `start`; the live state is `at` and `start + 1..at` are stored.
    Fill {
        start: u64,
        at: u64,
    },
    /// Reversing the segment at `start`; steps `start..=next` remain, all stored.
    Drain {
        start: u64,
        next: u64,
    },
    Done,
}

pub(super) struct TwoLevel {
    n: u64,
    segment: u64,
    last_start: u64,
    phase: Phase,
}

impl TwoLevel {
    pub(super) fn new(n: u64, segment: u64) -> TwoLevel {
        let phase = if n == 0 { Phase::Done } else { Phase::Sweep { at: 0 } };
        let last_start = if n == 0 { 0 } else { (segments(n, segment) - 1) * segment };
        TwoLevel { n, segment, last_start, phase }
    }

    fn segment_end(&self, start: u64) -> u64 {
        (start + self.segment).min(self.n)
    }

    fn next_segment(start: u64, segment: u64) -> Phase {
        if start == 0 {
            Phase::Done
        } else {
            Phase::Enter { start: start - segment }
        }
    }

    /// Push the next few actions; false once the stream has ended.
    pub(super) fn refill(&mut self, out: &mut VecDeque<Action>) -> bool {
        let ram = Tier::Ram;
        self.phase = match self.phase {
            Phase::Done => return false,
            Phase::Sweep { at } if at < self.last_start => {
                out.push_back(Action::Store { step: at, tier: ram });
                out.push_back(Action::Advance { from: at, to: at + self.segment });
                Phase::Sweep { at: at + self.segment }
            }
            Phase::Sweep { at } => {
                if self.n - at >= 2 {
                    out.push_back(Action::Store { step: at, tier: ram });
                }
                Phase::Fill { start: at, at }
            }
            Phase::Enter { start } => {
                out.push_back(Action::Restore { step: start, tier: ram });
                Phase::Fill { start, at: start }
            }
            Phase::Fill { start, at } => {
                let last = self.segment_end(start) - 1;
                if at < last {
                    out.push_back(Action::Advance { from: at, to: at + 1 });
                    if at + 1 < last {
                        out.push_back(Action::Store { step: at + 1, tier: ram });
                    }
                    Phase::Fill { start, at: at + 1 }
                } else if at == start {
                    // A one-step segment: its start is stored unless the first sweep ended there.
                    if start != self.last_start {
                        out.push_back(Action::Free { step: start, tier: ram });
                    }
                    out.push_back(Action::Reverse { step: start });
                    Self::next_segment(start, self.segment)
                } else {
                    out.push_back(Action::Reverse { step: at });
                    Phase::Drain { start, next: at - 1 }
                }
            }
            Phase::Drain { start, next } => {
                out.push_back(Action::Restore { step: next, tier: ram });
                out.push_back(Action::Free { step: next, tier: ram });
                out.push_back(Action::Reverse { step: next });
                if next == start {
                    Self::next_segment(start, self.segment)
                } else {
                    Phase::Drain { start, next: next - 1 }
                }
            }
        };
        true
    }
}
