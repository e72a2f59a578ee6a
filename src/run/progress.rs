//! A run's progress on stderr: a bar on a terminal, else a line every 10 s.

use super::{Run, RunOptions};
use std::io::IsTerminal;
use std::time::Instant;

/// A progress bar of `steps` estimated steps, on a terminal unless quiet.
pub(super) fn progress_bar(opts: &RunOptions, steps: u64) -> Option<indicatif::ProgressBar> {
    if opts.quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let b = indicatif::ProgressBar::new(steps);
    b.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} steps  {msg}  ETA {eta}").unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    Some(b)
}

impl Run<'_> {
    /// The progress bar on a terminal, else a line every 10 s.
    pub(super) fn show_progress(&mut self) {
        let sim = &self.sim;
        let (first_step, end, start) = (self.first_step, self.end, self.outputs.start);
        if let Some(b) = &self.bar {
            if sim.step.is_multiple_of(16) {
                let rate = (sim.step - first_step) as f64 / start.elapsed().as_secs_f64();
                let remaining = ((end - sim.time) / sim.last_dt.max(1e-300)).ceil() as u64;
                b.set_length(sim.step - first_step + remaining);
                b.set_position(sim.step - first_step);
                b.set_message(format!("{rate:.0} steps/s  t = {:.4} s  {} particles", sim.time, sim.particles.n));
            }
        } else if !self.opts.quiet && self.last_line.elapsed().as_secs_f64() > 10.0 {
            self.last_line = Instant::now();
            let rate = (sim.step - first_step) as f64 / start.elapsed().as_secs_f64();
            let remaining = (end - sim.time) / sim.last_dt.max(1e-300) / rate.max(1e-9);
            eprintln!(
                "step {} t = {:.4e} s dt = {:.2e} ({:?}) {:.0} steps/s ETA {:.0} s, {} particles",
                sim.step, sim.time, sim.last_dt, sim.last_limit, rate, remaining, sim.particles.n
            );
        }
    }
}
