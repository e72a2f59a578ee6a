//! A fixed team of worker threads that run one closure at a time, each with its thread index.
//!
//! The step loop dispatches several parallel phases per step; spawning threads (or queueing boxed
//! jobs) would allocate on every dispatch. This team is created once; `run` hands the workers a
//! borrowed closure and waits on a barrier, so a dispatch allocates nothing. Work is split
//! statically by thread index, so results never depend on timing.

use std::sync::{Arc, Barrier, Mutex};
use std::thread::JoinHandle;

type Job = dyn Fn(usize) + Sync;

struct Shared {
    start: Barrier,
    done: Barrier,
    /// The current job, valid between the two barriers of one `run`.
    job: Mutex<Option<&'static Job>>,
    quit: std::sync::atomic::AtomicBool,
}

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
            start: Barrier::new(n),
            done: Barrier::new(n),
            job: Mutex::new(None),
            quit: std::sync::atomic::AtomicBool::new(false),
        });
        let workers = (1..n)
            .map(|tid| {
                let s = shared.clone();
                std::thread::Builder::new()
                    .name(format!("strand-worker-{tid}"))
                    .spawn(move || loop {
                        s.start.wait();
                        if s.quit.load(std::sync::atomic::Ordering::Acquire) {
                            return;
                        }
                        let job = s.job.lock().unwrap_or_else(|e| e.into_inner()).expect("job set before start");
                        job(tid);
                        s.done.wait();
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
        let job: &(dyn Fn(usize) + Sync + '_) = &f;
        // SAFETY: the 'static is a lie told only to the workers, who use the reference strictly
        // between the `start` and `done` barriers; `run` does not return (and `f` stays alive)
        // until every worker has passed `done`, and the slot is cleared before returning.
        let job: &'static Job = unsafe { std::mem::transmute::<&(dyn Fn(usize) + Sync + '_), &'static Job>(job) };
        *self.shared.job.lock().unwrap_or_else(|e| e.into_inner()) = Some(job);
        self.shared.start.wait();
        f(0);
        self.shared.done.wait();
        *self.shared.job.lock().unwrap_or_else(|e| e.into_inner()) = None;
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
            self.shared.quit.store(true, std::sync::atomic::Ordering::Release);
            self.shared.start.wait();
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
    fn shares_cover_range() {
        for n in [0, 1, 7, 100] {
            for t in 1..4 {
                let total: usize = (0..t).map(|i| ThreadTeam::share(n, i, t).len()).sum();
                assert_eq!(total, n);
            }
        }
    }
}
