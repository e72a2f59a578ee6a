//! A fixed team of worker threads that run one closure at a time, each with its thread index.
//!
//! The step loop dispatches several parallel phases per step; spawning threads (or queueing boxed
//! jobs) would allocate on every dispatch. This team is created once; `run` hands the workers a
//! borrowed closure, so a dispatch allocates nothing. Work is split statically by thread index,
//! so results never depend on timing.
//!
//! Waiting spins first and sleeps only after [`SPIN`]: a step dispatches about ten phases, each
//! tens to hundreds of microseconds on a small print or slump, and waking a sleeping thread costs
//! a futex call and a context switch on each side. With two `std::sync::Barrier`s per dispatch
//! (what this team used before), the quick print-sleep check spent as much time in the kernel as
//! in its own code (68.8 s sys against 67.8 s user, 383k futex calls in its first 20 s;
//! BENCHMARKS.md "Thread team").
//!
//! Spinning pays only while every team thread has a core of its own; otherwise the spinner takes
//! the core from the very thread it waits for. `cargo test --release --test suite -- grad::` (two tests at
//! once, each with a two-thread team, on two cores) took more than 8.5 min against 154-193 s with
//! the barriers, and with one other single-thread process on the two cores the quick slump check
//! took 131 s against 19 s. So a waiter spins only while (1) the team threads in use in this
//! process fit in the machine's cores ([`IN_USE`]) and (2) the thread that dispatches has lately
//! not waited for a core ([`check_in`]: the second rule sees other processes); otherwise it sleeps
//! at once, as with the barriers.

use std::cell::{Cell, UnsafeCell};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::Relaxed, Ordering::SeqCst};
use std::sync::{Arc, Condvar, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

type Job = dyn Fn(usize) + Sync;

/// How long a waiting thread spins before it sleeps: longer than a step's serial stretches on a
/// small problem, short enough that a thread left waiting (a serial stretch between runs) gives
/// its core back soon.
const SPIN: Duration = Duration::from_micros(100);

/// How often a dispatching thread measures how long it waited for a core.
const SAMPLE: Duration = Duration::from_millis(20);

/// Waiters may spin only while a dispatching thread waits for a core less than this fraction of
/// the time. Measured on 2 cores, per thread: 0 % spinning and 0-4 % sleeping with the team
/// alone, 23-49 % with one other busy thread (BENCHMARKS.md "Thread team").
const CALM: f64 = 0.05;

/// Team threads in use in the process: each thread that has dispatched to a team of two or more
/// counts that team's size (callers included), from its first dispatch until it exits. Counting
/// per dispatching thread rather than per live team leaves out a team that is alive but idle (its
/// workers asleep, as when a verify case keeps one simulation while it runs the next on the same
/// thread), and counts tests or jobs that run at once, each on its own thread. A thread that stops
/// dispatching stays counted until it exits, which can only make waiters sleep sooner.
static IN_USE: AtomicUsize = AtomicUsize::new(0);

/// Whether the last measurement of a dispatching thread found the cores free; see [`check_in`].
static CALM_CORES: AtomicBool = AtomicBool::new(false);

/// A dispatching thread's share of [`IN_USE`] and its last measurement of waiting for a core.
struct Caller {
    counted: Cell<usize>,
    /// When, and this thread's total wait for a core then (ns).
    sampled: Cell<Option<(Instant, u64)>>,
}

impl Drop for Caller {
    fn drop(&mut self) {
        IN_USE.fetch_sub(self.counted.get(), Relaxed);
    }
}

thread_local! {
    static CALLER: Caller = const { Caller { counted: Cell::new(0), sampled: Cell::new(None) } };
}

/// Called by `run` on the dispatching thread: count it as using a team of `n`, and every [`SAMPLE`]
/// set [`CALM_CORES`] from the share of the time since the last sample it spent runnable but
/// without a core. That share is the direct measure of oversubscription, whoever causes it;
/// sleeping waiters do not hide it (a woken thread still queues for a core), so the rule does not
/// flip back to spinning while the cores stay busy. Where it cannot be measured, never spin.
fn check_in(n: usize) {
    // `try_with`: during thread teardown the state is gone, and then nothing is counted
    let _ = CALLER.try_with(|c| {
        if c.counted.get() < n {
            IN_USE.fetch_add(n - c.counted.get(), Relaxed);
            c.counted.set(n);
        }
        let now = Instant::now();
        let last = c.sampled.get();
        if last.is_some_and(|(t, _)| now - t < SAMPLE) {
            return;
        }
        let waited = run_delay_ns();
        let calm = match (last, waited) {
            (Some((t, w0)), Some(w)) => (w.saturating_sub(w0) as f64) < CALM * (now - t).as_nanos() as f64,
            _ => false,
        };
        CALM_CORES.store(calm, Relaxed);
        c.sampled.set(Some((now, waited.unwrap_or(0))));
    });
}

/// This thread's total time runnable but waiting for a core (ns), from Linux's schedstat; `None`
/// where that cannot be read. Allocates nothing (the step loop must not).
fn run_delay_ns() -> Option<u64> {
    use std::io::Read;
    let mut buf = [0u8; 96];
    let n = std::fs::File::open("/proc/thread-self/schedstat").ok()?.read(&mut buf).ok()?;
    std::str::from_utf8(&buf[..n]).ok()?.split_ascii_whitespace().nth(1)?.parse().ok()
}

/// Whether a waiter should sleep at once rather than spin (hints read without ordering: a stale
/// value costs at most one wait's spin or one sleep).
fn oversubscribed() -> bool {
    static CORES: OnceLock<usize> = OnceLock::new();
    let cores = *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    IN_USE.load(Relaxed) > cores || !CALM_CORES.load(Relaxed)
}

/// Spin until `ready()` or [`SPIN`] has passed, not at all if [`oversubscribed`]; whether it
/// became ready.
#[inline]
fn spin_until(ready: impl Fn() -> bool) -> bool {
    if oversubscribed() {
        return ready();
    }
    let t0 = Instant::now();
    loop {
        for _ in 0..64 {
            if ready() {
                return true;
            }
            std::hint::spin_loop();
        }
        if t0.elapsed() > SPIN {
            return ready();
        }
    }
}

/// A wake-up flag a thread can sleep on after spinning: `sleeping` tells the waker whether the
/// lock and the notification (a system call) are needed.
#[derive(Default)]
struct Sleeper {
    sleeping: AtomicUsize,
    lock: Mutex<()>,
    cv: Condvar,
}

impl Sleeper {
    /// Wait until `ready()`: spin, then sleep. `ready` must become true only by a write that is
    /// followed by [`Sleeper::wake`].
    fn wait(&self, ready: impl Fn() -> bool) {
        if spin_until(&ready) {
            return;
        }
        let mut g = self.lock.lock().unwrap_or_else(|e| e.into_inner());
        // SeqCst on both sides: either the waker sees this count, or this thread sees its write
        self.sleeping.fetch_add(1, SeqCst);
        while !ready() {
            g = self.cv.wait(g).unwrap_or_else(|e| e.into_inner());
        }
        self.sleeping.fetch_sub(1, SeqCst);
    }

    /// After the write that makes the waiters ready.
    fn wake(&self) {
        if self.sleeping.load(SeqCst) > 0 {
            // the lock makes sure a sleeper counted above is in `cv.wait`, not about to enter it
            let _g = self.lock.lock().unwrap_or_else(|e| e.into_inner());
            self.cv.notify_all();
        }
    }
}

struct Shared {
    /// Bumped by `run` to start a job (and by `drop`, with `quit`, to stop the workers).
    epoch: AtomicU64,
    /// Workers still in the current job.
    running: AtomicUsize,
    /// The current job, written before `epoch` is bumped and read after it is seen.
    job: UnsafeCell<Option<&'static Job>>,
    quit: AtomicBool,
    start: Sleeper,
    done: Sleeper,
}

// SAFETY: `job` is written only by `run` while no worker reads it (every worker has finished the
// previous job, `running` == 0) and read by workers only after the epoch that publishes it.
unsafe impl Sync for Shared {}

pub struct ThreadTeam {
    n: usize,
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
}

impl ThreadTeam {
    /// A team of `n >= 1` threads: the caller plus `n - 1` workers.
    pub fn new(n: usize) -> Self {
        let n = n.max(1);
        let shared = Arc::new(Shared {
            epoch: AtomicU64::new(0),
            running: AtomicUsize::new(0),
            job: UnsafeCell::new(None),
            quit: AtomicBool::new(false),
            start: Sleeper::default(),
            done: Sleeper::default(),
        });
        let workers = (1..n)
            .map(|tid| {
                let s = shared.clone();
                std::thread::Builder::new()
                    .name(format!("strand-worker-{tid}"))
                    .spawn(move || {
                        let mut seen = 0;
                        loop {
                            s.start.wait(|| s.epoch.load(SeqCst) != seen);
                            seen = s.epoch.load(SeqCst);
                            if s.quit.load(SeqCst) {
                                return;
                            }
                            // SAFETY: published by the epoch just seen; `run` keeps it alive
                            // until `running` falls to 0 below.
                            let job = unsafe { (*s.job.get()).expect("job set before its epoch") };
                            job(tid);
                            if s.running.fetch_sub(1, SeqCst) == 1 {
                                s.done.wake();
                            }
                        }
                    })
                    .expect("cannot spawn worker thread")
            })
            .collect();
        ThreadTeam { n, shared, workers }
    }

    pub fn threads(&self) -> usize {
        self.n
    }

    /// Run `f(tid)` on every thread of the team, `tid` in `0..threads()`, and wait for all.
    pub fn run<F: Fn(usize) + Sync>(&self, f: F) {
        if self.n == 1 {
            f(0);
            return;
        }
        check_in(self.n);
        let job: &(dyn Fn(usize) + Sync + '_) = &f;
        // SAFETY: the 'static is a lie told only to the workers, who call it strictly between
        // the epoch below and their decrement of `running`; `run` does not return (and `f` stays
        // alive) until `running` is 0, and the slot is cleared before returning.
        let job: &'static Job = unsafe { std::mem::transmute::<&(dyn Fn(usize) + Sync + '_), &'static Job>(job) };
        let s = &*self.shared;
        // SAFETY: no worker is in a job (the last `run` waited for `running` == 0).
        unsafe { *s.job.get() = Some(job) };
        s.running.store(self.n - 1, SeqCst);
        s.epoch.fetch_add(1, SeqCst);
        s.start.wake();
        f(0);
        s.done.wait(|| s.running.load(SeqCst) == 0);
        // SAFETY: every worker is done with it.
        unsafe { *s.job.get() = None };
    }

    /// The half-open range of `0..n` that thread `tid` of `threads` owns (contiguous, balanced).
    pub fn share(n: usize, tid: usize, threads: usize) -> std::ops::Range<usize> {
        let lo = n * tid / threads;
        let hi = n * (tid + 1) / threads;
        lo..hi
    }

    /// Run `f(range, chunk)` on every thread, `data` cut into elements of `width` values and
    /// shared out as by [`ThreadTeam::share`]: `chunk` is the thread's elements `range`.
    pub fn for_each_share<T: Send>(&self, data: &mut [T], width: usize, f: impl Fn(std::ops::Range<usize>, &mut [T]) + Sync) {
        let n = data.len() / width.max(1);
        let threads = self.n;
        let data = SharedSlice::new(data);
        self.run(|tid| {
            let r = ThreadTeam::share(n, tid, threads);
            // SAFETY: shares are disjoint.
            let chunk = unsafe { data.slice_mut(r.start * width..r.end * width) };
            f(r, chunk);
        });
    }
}

impl Drop for ThreadTeam {
    fn drop(&mut self) {
        if self.n > 1 {
            self.shared.quit.store(true, SeqCst);
            self.shared.epoch.fetch_add(1, SeqCst);
            self.shared.start.wake();
            for w in self.workers.drain(..) {
                let _ = w.join();
            }
        }
    }
}

/// A mutable slice shared across the team where the caller guarantees disjoint writes.
#[derive(Clone, Copy)]
pub struct SharedSlice<T> {
    ptr: *mut T,
    len: usize,
}
unsafe impl<T: Send> Send for SharedSlice<T> {}
unsafe impl<T: Send> Sync for SharedSlice<T> {}

impl<T> SharedSlice<T> {
    pub fn new(s: &mut [T]) -> Self {
        SharedSlice { ptr: s.as_mut_ptr(), len: s.len() }
    }
    /// # Safety
    /// No other thread may access index `i` while the returned reference lives.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn get_mut(&self, i: usize) -> &mut T {
        debug_assert!(i < self.len);
        &mut *self.ptr.add(i)
    }
    /// # Safety
    /// No other thread may write `range` while the returned slice lives.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn slice_mut(&self, range: std::ops::Range<usize>) -> &mut [T] {
        debug_assert!(range.end <= self.len);
        std::slice::from_raw_parts_mut(self.ptr.add(range.start), range.end - range.start)
    }
    /// # Safety
    /// No thread may write the slice while it is read.
    #[inline(always)]
    pub unsafe fn as_slice(&self) -> &[T] {
        std::slice::from_raw_parts(self.ptr, self.len)
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn every_thread_runs_each_job_once() {
        let team = ThreadTeam::new(3);
        let hits = [AtomicUsize::new(0), AtomicUsize::new(0), AtomicUsize::new(0)];
        for _ in 0..100 {
            team.run(|tid| {
                hits[tid].fetch_add(1, Ordering::Relaxed);
            });
        }
        for h in &hits {
            assert_eq!(h.load(Ordering::Relaxed), 100);
        }
    }

    #[test]
    fn a_dispatching_thread_counts_its_largest_team_once() {
        std::thread::spawn(|| {
            let two = ThreadTeam::new(2);
            two.run(|_| {});
            two.run(|_| {});
            ThreadTeam::new(3).run(|_| {});
            two.run(|_| {});
            ThreadTeam::new(1).run(|_| {});
            assert_eq!(CALLER.with(|c| c.counted.get()), 3);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn shares_cover_range() {
        for n in [0, 1, 7, 100] {
            for t in 1..4 {
                let total: usize = (0..t).map(|i| ThreadTeam::share(n, i, t).len()).sum();
                assert_eq!(total, n);
            }
        }
    }
}
