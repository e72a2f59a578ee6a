//! Workers of a campaign's evaluation that have run out of experiments, lent to the experiments
//! still running. A campaign's jobs are its experiments, handed out longest first
//! ([`par_map_experiments`](super::runner::par_map_experiments)); when one experiment costs
//! most of the campaign (a two-layer wall among single lines, its Jacobian 2 p runs of it), the
//! other workers finish early and stand idle while its runs go one after another. The runs an
//! experiment makes that do not depend on each other (a Jacobian's differences, a coarse and a
//! fine run) go through [`Spare::map`], which runs them on its own thread and on every worker
//! that falls idle meanwhile. Scheduling only: each run is the same function of its inputs on
//! whichever thread runs it, so results are bit-identical with or without spare workers.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Workers with no experiment left, as a count of free slots: a worker adds its slot when it
/// leaves ([`Spare::leave`]), a helper borrows one for each run it makes.
pub struct Spare {
    free: Mutex<usize>,
    freed: Condvar,
    /// The most helpers one experiment's runs can use: every other worker.
    helpers: usize,
}

/// How long a helper waits for a free slot before it looks again whether any run is left.
const LOOK_AGAIN: Duration = Duration::from_millis(20);

impl Spare {
    /// For `workers` workers, none free yet.
    pub fn new(workers: usize) -> Spare {
        Spare { free: Mutex::new(0), freed: Condvar::new(), helpers: workers.saturating_sub(1) }
    }

    /// A worker that has run out of experiments gives its slot to the runs still to make.
    pub fn leave(&self) {
        self.give_back();
    }

    fn give_back(&self) {
        *self.free.lock().unwrap_or_else(|e| e.into_inner()) += 1;
        self.freed.notify_one();
    }

    /// A free slot, waiting for one until `done` says nothing is left to run.
    fn borrow(&self, done: impl Fn() -> bool) -> bool {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if done() {
                return false;
            }
            if *free > 0 {
                *free -= 1;
                return true;
            }
            free = self.freed.wait_timeout(free, LOOK_AGAIN).unwrap_or_else(|e| e.into_inner()).0;
        }
    }

    /// `f(i)` for every i in 0..n, results in index order: on this thread, and on each worker
    /// that falls idle before the last one is taken.
    pub fn map<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
        let next = AtomicUsize::new(0);
        let out: Vec<Mutex<Option<T>>> = (0..n).map(|_| Mutex::new(None)).collect();
        let run = |i: usize| *out[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(f(i));
        let done = || next.load(Ordering::Relaxed) >= n;
        std::thread::scope(|s| {
            for _ in 0..self.helpers.min(n.saturating_sub(1)) {
                s.spawn(|| {
                    while self.borrow(done) {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i < n {
                            run(i);
                        }
                        self.give_back();
                    }
                });
            }
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                run(i);
            }
        });
        out.into_iter().map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()).expect("every run made")).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs are shared with a worker only once it has left: before, they stay on the caller's
    /// thread; after, both threads take them; either way every result lands at its index.
    #[test]
    fn runs_go_to_workers_that_have_left_and_results_keep_their_order() {
        let spare = Spare::new(2);
        let caller = std::thread::current().id();
        let alone = spare.map(6, |i| (i * i, std::thread::current().id()));
        assert_eq!(alone.iter().map(|r| r.0).collect::<Vec<_>>(), vec![0, 1, 4, 9, 16, 25]);
        assert!(alone.iter().all(|r| r.1 == caller), "a run went to a worker that had not left");
        spare.leave();
        let shared = spare.map(8, |i| {
            std::thread::sleep(Duration::from_millis(30));
            (i + 1, std::thread::current().id())
        });
        assert_eq!(shared.iter().map(|r| r.0).collect::<Vec<_>>(), (1..=8).collect::<Vec<_>>());
        assert!(shared.iter().any(|r| r.1 != caller), "no run went to the worker that left");
        assert_eq!(*spare.free.lock().unwrap(), 1, "the slot is given back");
    }
}
