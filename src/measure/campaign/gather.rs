//! Independent evaluations submitted to a scheduler together. A diagnosis's independent fits
//! (each effect's likelihood-ratio fit, each left-out experiment's check) run side by side on
//! threads ([`Gather::side_by_side`]), and each submission holds the next evaluation of every
//! one of them still running: a batch fills the cores a scheduler has, where one model's
//! experiments at a time would leave most of them idle.
//!
//! The rule: a batch is submitted when every thread that may still submit is waiting with a
//! request and no batch is running. A thread's requests depend only on its own answers, so which
//! requests share a batch follows from the tasks, not from timing; within a batch the requests are
//! in the order of their threads' places (a task's index within each side-by-side run that
//! started it). Results do not depend on either: a job's result is the same bits wherever it
//! runs (`engine.rs`).

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex, MutexGuard};

/// Submissions shared by the evaluations of one command; clones of a scheduler share one.
#[derive(Debug, Default)]
pub struct Gather {
    state: Mutex<State>,
    changed: Condvar,
}

/// One evaluation's jobs: the command line of each, and how many of its results were collected
/// from earlier runs instead.
#[derive(Debug, Default)]
pub struct Request {
    pub lines: Vec<String>,
    pub collected: usize,
}

/// How a submission went: its batch number, the command run and how it ended (every thread in
/// it checks its own jobs' results).
#[derive(Clone, Debug)]
pub struct Submitted {
    pub number: usize,
    pub command: String,
    pub status: String,
    pub log: std::path::PathBuf,
}

#[derive(Debug)]
struct State {
    /// Threads that may still submit: the command's own, or the tasks of each side-by-side run
    /// in place of the thread that waits for them.
    live: usize,
    /// Requests for the next submission: the place of the thread that made each, its ticket.
    waiting: Vec<(Vec<usize>, u64, Request)>,
    running: bool,
    /// Each submitted ticket's outcome, until its thread takes it.
    done: BTreeMap<u64, Result<Submitted, String>>,
    next_ticket: u64,
}

impl Default for State {
    fn default() -> State {
        State { live: 1, waiting: Vec::new(), running: false, done: BTreeMap::new(), next_ticket: 0 }
    }
}

thread_local! {
    /// This thread's place: its task's index in each side-by-side run that started it, outermost
    /// first (empty for a thread no side-by-side run started).
    static PLACE: RefCell<Vec<usize>> = const { RefCell::new(Vec::new()) };
}

/// Counts a task's thread out when it ends, however it ends (a panic included), so that no batch
/// waits for it.
struct Leaving<'g>(&'g Gather);

impl Drop for Leaving<'_> {
    fn drop(&mut self) {
        self.0.lock().live -= 1;
        self.0.changed.notify_all();
    }
}

impl Gather {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `f(0) .. f(n - 1)` on threads of their own, each a thread that may submit in place of
    /// this one, which waits for them; their results in order. One task runs here.
    pub fn side_by_side<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
        if n <= 1 {
            return (0..n).map(f).collect();
        }
        let place = PLACE.with(|p| p.borrow().clone());
        self.lock().live += n - 1;
        let out = std::thread::scope(|s| {
            let tasks: Vec<_> = (0..n)
                .map(|i| {
                    let (f, mut place) = (&f, place.clone());
                    place.push(i);
                    s.spawn(move || {
                        let _leaving = Leaving(self);
                        PLACE.with(|p| *p.borrow_mut() = place);
                        f(i)
                    })
                })
                .collect();
            tasks.into_iter().map(|t| t.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).collect()
        });
        self.lock().live += 1;
        out
    }

    /// Waits until `request` can go with every other live thread's, then returns how its
    /// submission went; `run` submits the lines of all the requests gathered, with the number of
    /// results they collected, on the last thread to arrive.
    pub fn submit(
        &self,
        request: Request,
        run: impl FnOnce(&[String], usize) -> Result<Submitted, String>,
    ) -> Result<Submitted, String> {
        let place = PLACE.with(|p| p.borrow().clone());
        let mut st = self.lock();
        let ticket = st.next_ticket;
        st.next_ticket += 1;
        st.waiting.push((place, ticket, request));
        loop {
            if let Some(out) = st.done.remove(&ticket) {
                return out;
            }
            if !st.running && st.waiting.len() >= st.live {
                break;
            }
            st = self.changed.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        // this thread submits the batch
        let mut batch = std::mem::take(&mut st.waiting);
        batch.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)));
        st.running = true;
        drop(st);
        let lines: Vec<String> = batch.iter().flat_map(|(_, _, r)| r.lines.iter().cloned()).collect();
        let collected = batch.iter().map(|(_, _, r)| r.collected).sum();
        let out = run(&lines, collected);
        let mut st = self.lock();
        for (_, t, _) in &batch {
            st.done.insert(*t, out.clone());
        }
        st.running = false;
        let mine = st.done.remove(&ticket).expect("in the batch");
        drop(st);
        self.changed.notify_all();
        mine
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three tasks that submit 3, 1 and 2 times: each batch holds one request of every task still
    /// submitting, in the tasks' order, whatever the threads' timing; a task that ends early
    /// holds no batch back.
    #[test]
    fn a_batch_holds_the_next_request_of_every_task_still_running() {
        let g = Gather::default();
        let batches = Mutex::new(Vec::new());
        let counts = [3, 1, 2];
        for _ in 0..20 {
            batches.lock().unwrap().clear();
            let got = g.side_by_side(3, |i| {
                let mut numbers = Vec::new();
                for k in 0..counts[i] {
                    // some tasks are slower to make their request
                    std::thread::sleep(std::time::Duration::from_micros(((i * 7 + k * 3) % 5) as u64 * 200));
                    let req = Request { lines: vec![format!("task {i} request {k}")], collected: i };
                    let s = g
                        .submit(req, |lines, collected| {
                            let mut b = batches.lock().unwrap();
                            b.push((lines.to_vec(), collected));
                            Ok(Submitted {
                                number: b.len(),
                                command: String::new(),
                                status: String::new(),
                                log: Default::default(),
                            })
                        })
                        .unwrap();
                    numbers.push(s.number);
                }
                numbers
            });
            assert_eq!(got, vec![vec![1, 2, 3], vec![1], vec![1, 2]]);
            let b = batches.lock().unwrap();
            let lines = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
            assert_eq!(b[0], (lines(&["task 0 request 0", "task 1 request 0", "task 2 request 0"]), 3));
            assert_eq!(b[1], (lines(&["task 0 request 1", "task 2 request 1"]), 2));
            assert_eq!(b[2], (lines(&["task 0 request 2"]), 0));
            assert_eq!(b.len(), 3);
        }
        // the command's own thread is the only one live again: it submits alone at once
        let s = g.submit(Request::default(), |_, _| Err("not run".into()));
        assert_eq!(s.unwrap_err(), "not run");
    }

    /// Side-by-side runs nest: each inner task counts, and a batch waits for all of them.
    #[test]
    fn nested_tasks_are_gathered_with_their_cousins() {
        let g = Gather::default();
        let batches = Mutex::new(Vec::new());
        let got = g.side_by_side(2, |i| {
            g.side_by_side(2 + i, |j| {
                let req = Request { lines: vec![format!("{i}.{j}")], collected: 0 };
                g.submit(req, |lines, _| {
                    batches.lock().unwrap().push(lines.to_vec());
                    Ok(Submitted { number: 1, command: String::new(), status: String::new(), log: Default::default() })
                })
                .unwrap()
                .number
            })
        });
        assert_eq!(got, vec![vec![1, 1], vec![1, 1, 1]]);
        assert_eq!(*batches.lock().unwrap(), vec![vec!["0.0", "0.1", "1.0", "1.1", "1.2"]]);
        assert_eq!(g.lock().live, 1);
    }
}
