//! The one disk writer: a background thread that writes jobs while the stepper goes on (restart
//! checkpoints, `checkpoint/writer.rs`).
//!
//! A fixed set of buffers circulates: the stepper takes a free one, fills it (a memcpy) and
//! submits it with its job; the thread writes it, gives the buffer back and reports how the
//! write went. The stepper waits only when every buffer is still being written, and nothing is
//! allocated per write.

use crossbeam::channel::{bounded, Receiver, Sender};
use std::thread::JoinHandle;

/// A background writer of jobs `J`, each with a buffer `B`, reporting `R` per job.
pub struct Writer<B, J, R> {
    jobs: Option<Sender<(B, J)>>,
    free: Receiver<B>,
    give_back: Sender<B>,
    reports: Receiver<R>,
    worker: Option<JoinHandle<()>>,
    in_flight: usize,
}

impl<B: Send + 'static, J: Send + 'static, R: Send + 'static> Writer<B, J, R> {
    /// Start the thread `name` with `buffers`; `write` writes one job from its buffer. At most
    /// `reports` reports wait unread before the thread waits for the stepper.
    pub fn spawn(name: &str, buffers: Vec<B>, reports: usize, mut write: impl FnMut(&B, &J) -> R + Send + 'static) -> std::io::Result<Self> {
        let (job_tx, job_rx) = bounded::<(B, J)>(1);
        let (free_tx, free_rx) = bounded::<B>(buffers.len());
        let (report_tx, report_rx) = bounded::<R>(reports);
        for b in buffers {
            free_tx.send(b).expect("room for every buffer");
        }
        let give_back = free_tx.clone();
        let worker = std::thread::Builder::new().name(name.into()).spawn(move || {
            for (buffer, job) in job_rx {
                let r = write(&buffer, &job);
                let _ = free_tx.send(buffer);
                if report_tx.send(r).is_err() {
                    break;
                }
            }
        })?;
        Ok(Writer { jobs: Some(job_tx), free: free_rx, give_back, reports: report_rx, worker: Some(worker), in_flight: 0 })
    }

    /// A free buffer, waiting until one is written if none is; None if the thread has stopped.
    pub fn buffer(&self) -> Option<B> {
        self.free.recv().ok()
    }

    /// Give back a buffer taken but not submitted.
    pub fn give_back(&self, buffer: B) {
        let _ = self.give_back.send(buffer);
    }

    /// Queue `buffer` to be written as `job`; false if the thread has stopped.
    pub fn submit(&mut self, buffer: B, job: J) -> bool {
        let sent = self.jobs.as_ref().is_some_and(|j| j.send((buffer, job)).is_ok());
        self.in_flight += sent as usize;
        sent
    }

    /// A report, if one is ready.
    pub fn poll(&mut self) -> Option<R> {
        let r = self.reports.try_recv().ok()?;
        self.in_flight -= 1;
        Some(r)
    }

    /// The next report, waiting for it; None if nothing is queued or the thread has stopped.
    pub fn wait(&mut self) -> Option<R> {
        if self.in_flight == 0 {
            return None;
        }
        let r = self.reports.recv().ok()?;
        self.in_flight -= 1;
        Some(r)
    }

    /// Wait until every queued job is written; their reports, oldest first.
    pub fn drain(&mut self) -> Vec<R> {
        std::iter::from_fn(|| self.wait()).collect()
    }

    /// Stop the thread once it has written what is queued; the reports not read yet.
    pub fn finish(mut self) -> Vec<R> {
        self.stop();
        self.reports.try_iter().collect()
    }
}

impl<B, J, R> Writer<B, J, R> {
    /// Close the queue and wait for the thread to write what is in it.
    fn stop(&mut self) {
        self.jobs = None;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

impl<B, J, R> Drop for Writer<B, J, R> {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::Writer;

    #[test]
    fn jobs_are_written_in_order_and_buffers_come_back() {
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = seen.clone();
        let mut w = Writer::spawn("test-writer", vec![vec![0u8; 4], vec![0u8; 4]], 4, move |b: &Vec<u8>, j: &u32| {
            log.lock().unwrap().push((b[0], *j));
            *j * 10
        })
        .unwrap();
        for j in 0..5u32 {
            let mut b = w.buffer().unwrap();
            b[0] = j as u8;
            assert!(w.submit(b, j));
        }
        let mut reports = Vec::new();
        while let Some(r) = w.poll() {
            reports.push(r);
        }
        reports.extend(w.drain());
        assert_eq!(reports, vec![0, 10, 20, 30, 40]);
        assert_eq!(*seen.lock().unwrap(), vec![(0, 0), (1, 1), (2, 2), (3, 3), (4, 4)]);
        // both buffers are free again, and a taken one can be given back
        let (a, b) = (w.buffer().unwrap(), w.buffer().unwrap());
        w.give_back(a);
        w.give_back(b);
        assert!(w.submit(w.buffer().unwrap(), 7));
        assert_eq!(w.finish(), vec![70]);
    }
}
