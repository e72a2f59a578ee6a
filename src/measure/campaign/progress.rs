//! The progress of a long measurement (`strand calibrate`, `strand diagnose`): stages (the base
//! fit, the score tests, the likelihood-ratio fits, each candidate's fit and leave-one-out), each
//! counted in experiment runs, with the time left estimated per stage and overall.
//!
//! What enters: the stages a command plans ([`Progress::plan`]), begins and ends, and the runs
//! its evaluations expect and finish ([`Progress::expect`], [`Progress::advance`]). What leaves:
//! on a terminal, two bars on stderr (indicatif; hidden where stderr is not a terminal, where a
//! plain line at most every [`LINE_EVERY`] seconds stands in); with `--json`, one JSON object per
//! event on stderr ([`Event`]); nothing for a silent handle (`--quiet`, and the library's
//! default). A handle is passed down inside [`FitOptions`](crate::measure::campaign::FitOptions); it
//! only counts and prints, so results are the same bits with it or without it.

use std::io::{IsTerminal, Write};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Seconds between the plain lines that stand in for the bars where stderr is not a terminal.
pub const LINE_EVERY: f64 = 30.0;

/// A handle on a measurement's progress; clones share it. The default is silent.
#[derive(Clone, Default)]
pub struct Progress {
    meter: Option<Arc<Mutex<Meter>>>,
    /// What this handle's log lines begin with: the task they come from, where tasks run side by
    /// side ([`Progress::labelled`]).
    label: Option<Arc<str>>,
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.meter.is_some() { "Progress" } else { "Progress (silent)" })
    }
}

/// One progress event, a JSON line with `--json`: the stage, its runs done and expected (done <=
/// total; a stage's last event has done = total), its seconds so far and left (null before the
/// first run), and the same overall, over the stages planned.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Event {
    pub stage: String,
    pub done: u64,
    pub total: u64,
    pub elapsed_s: f64,
    pub eta_s: Option<f64>,
    pub stages_done: usize,
    pub stages: usize,
    pub overall_elapsed_s: f64,
    pub overall_eta_s: Option<f64>,
}

enum Sink {
    Bars { multi: indicatif::MultiProgress, overall: indicatif::ProgressBar, stage: indicatif::ProgressBar },
    Lines { last: Instant },
    Json(Box<dyn Write + Send>),
}

struct Meter {
    sink: Sink,
    /// What the last event showed: the stage, its runs done and expected, the stages done and
    /// planned; an update that changes none of them shows nothing.
    shown: (String, u64, u64, usize, usize),
    began: Instant,
    stages: usize,
    stages_done: usize,
    stage: Stage,
}

struct Stage {
    name: String,
    done: u64,
    total: u64,
    began: Instant,
}

/// Seconds left at a constant rate: `elapsed` for the fraction `done` of 1; none before any.
fn left(elapsed: f64, done: f64) -> Option<f64> {
    (done > 0.0).then(|| elapsed * (1.0 - done).max(0.0) / done)
}

impl Progress {
    /// Bars on stderr, or plain lines where it is not a terminal.
    pub fn bars() -> Progress {
        let sink = if std::io::stderr().is_terminal() {
            let multi = indicatif::MultiProgress::with_draw_target(indicatif::ProgressDrawTarget::stderr());
            let style = |t: &str| {
                indicatif::ProgressStyle::with_template(t).unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            };
            let overall = multi.add(indicatif::ProgressBar::new(1).with_style(style("{prefix:>28} [{bar:30}] {msg}")));
            let stage = multi.add(
                indicatif::ProgressBar::new(0)
                    .with_style(style("{prefix:>28} [{bar:30}] {pos}/{len} runs  {elapsed}  {msg}")),
            );
            for b in [&overall, &stage] {
                b.enable_steady_tick(Duration::from_secs(1));
            }
            overall.set_prefix("overall");
            Sink::Bars { multi, overall, stage }
        } else {
            // the first line after as long as between lines: a short command prints none
            Sink::Lines { last: Instant::now() }
        };
        Progress::with(sink)
    }

    /// Each event a JSON line ([`Event`]) on `out`.
    pub fn json(out: Box<dyn Write + Send>) -> Progress {
        Progress::with(Sink::Json(out))
    }

    fn with(sink: Sink) -> Progress {
        let now = Instant::now();
        let stage = Stage { name: String::new(), done: 0, total: 0, began: now };
        let shown = (String::new(), 0, 0, 0, 0);
        Progress {
            meter: Some(Arc::new(Mutex::new(Meter { sink, shown, began: now, stages: 0, stages_done: 0, stage }))),
            label: None,
        }
    }

    fn update(&self, f: impl FnOnce(&mut Meter)) {
        if let Some(m) = &self.meter {
            let mut m = m.lock().unwrap_or_else(|e| e.into_inner());
            f(&mut m);
            let now = (m.stage.name.clone(), m.stage.done, m.stage.total, m.stages_done, m.stages);
            if now != m.shown {
                m.shown = now;
                m.show();
            }
        }
    }

    /// `stages` more stages to come.
    pub fn plan(&self, stages: usize) {
        self.update(|m| m.stages += stages);
    }

    /// The next stage begins, expecting `runs` runs (more may be expected as it goes).
    pub fn begin(&self, stage: &str, runs: u64) {
        self.update(|m| {
            m.stage = Stage { name: stage.to_string(), done: 0, total: runs, began: Instant::now() };
            m.stages = m.stages.max(m.stages_done + 1);
        });
    }

    /// An evaluation of `runs` runs is about to start: the stage expects at least them.
    pub fn expect(&self, runs: u64) {
        self.update(|m| m.stage.total = m.stage.total.max(m.stage.done + runs));
    }

    /// `runs` runs done.
    pub fn advance(&self, runs: u64) {
        self.update(|m| {
            m.stage.done += runs;
            m.stage.total = m.stage.total.max(m.stage.done);
        });
    }

    /// The stage ends: what it did is its total.
    pub fn end(&self) {
        self.update(|m| {
            m.stage.total = m.stage.done;
            m.stages_done += 1;
        });
    }

    /// The same progress, whose log lines begin with `label` (after this handle's own): the lines
    /// of tasks that run side by side, such as a diagnosis's fits, tell which task they are from.
    pub fn labelled(&self, label: &str) -> Progress {
        let label = match &self.label {
            Some(l) => format!("{l}: {label}"),
            None => label.to_string(),
        };
        Progress { meter: self.meter.clone(), label: Some(label.into()) }
    }

    /// A line of the command's log on stderr, above the bars where they are drawn.
    pub fn log(&self, line: &str) {
        let labelled;
        let line = match &self.label {
            Some(l) => {
                labelled = format!("{l}: {line}");
                &labelled
            }
            None => line,
        };
        match &self.meter {
            Some(m) => match &m.lock().unwrap_or_else(|e| e.into_inner()).sink {
                Sink::Bars { multi, .. } => multi.suspend(|| eprintln!("{line}")),
                _ => eprintln!("{line}"),
            },
            None => eprintln!("{line}"),
        }
    }

    /// The bars cleared, where they are drawn.
    pub fn finish(&self) {
        if let Some(m) = &self.meter {
            if let Sink::Bars { overall, stage, .. } = &m.lock().unwrap_or_else(|e| e.into_inner()).sink {
                overall.finish_and_clear();
                stage.finish_and_clear();
            }
        }
    }
}

impl Meter {
    fn event(&self) -> Event {
        let s = &self.stage;
        let elapsed = s.began.elapsed().as_secs_f64();
        let fraction = if s.total == 0 { 0.0 } else { s.done as f64 / s.total as f64 };
        let overall =
            (self.stages_done as f64 + if s.done < s.total { fraction } else { 0.0 }) / self.stages.max(1) as f64;
        let overall_elapsed = self.began.elapsed().as_secs_f64();
        Event {
            stage: s.name.clone(),
            done: s.done,
            total: s.total,
            elapsed_s: elapsed,
            eta_s: left(elapsed, fraction),
            stages_done: self.stages_done,
            stages: self.stages,
            overall_elapsed_s: overall_elapsed,
            overall_eta_s: left(overall_elapsed, overall),
        }
    }

    fn show(&mut self) {
        let e = self.event();
        let eta = |s: Option<f64>| {
            s.map_or("ETA -".to_string(), |s| format!("ETA {}", indicatif::HumanDuration(Duration::from_secs_f64(s))))
        };
        match &mut self.sink {
            Sink::Bars { overall, stage, .. } => {
                overall.set_length(e.stages.max(1) as u64 * 1000);
                let at = e.stages_done as u64 * 1000
                    + if e.total > 0 && e.done < e.total { 1000 * e.done / e.total } else { 0 };
                overall.set_position(at.max(overall.position()));
                overall.set_message(format!(
                    "stage {} of {}  {}",
                    (e.stages_done + 1).min(e.stages),
                    e.stages,
                    eta(e.overall_eta_s)
                ));
                stage.set_prefix(e.stage.clone());
                stage.set_length(e.total);
                stage.set_position(e.done);
                stage.set_message(eta(e.eta_s));
            }
            Sink::Lines { last } => {
                if last.elapsed().as_secs_f64() >= LINE_EVERY && !e.stage.is_empty() {
                    *last = Instant::now();
                    eprintln!(
                        "progress: {} {}/{} runs, {}; stage {} of {}, {} in all",
                        e.stage,
                        e.done,
                        e.total,
                        eta(e.eta_s),
                        (e.stages_done + 1).min(e.stages),
                        e.stages,
                        eta(e.overall_eta_s)
                    );
                }
            }
            Sink::Json(out) => {
                if !e.stage.is_empty() {
                    let _ =
                        serde_json::to_writer(&mut *out, &e).map_err(std::io::Error::from).and_then(|_| writeln!(out));
                }
            }
        }
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;

    /// A writer the test reads back.
    #[derive(Clone, Default)]
    pub struct Shared(pub Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().write(b)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Shared {
        /// A handle whose JSON events this writer keeps, with `stages` planned.
        pub fn progress(&self, stages: usize) -> Progress {
            let p = Progress::json(Box::new(self.clone()));
            p.plan(stages);
            p
        }

        pub fn events(&self) -> Vec<Event> {
            let text = String::from_utf8(self.0.lock().unwrap().clone()).unwrap();
            text.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}"))).collect()
        }
    }

    /// Events are well-formed and monotone: within a stage done <= total and done never falls,
    /// each stage ends at its total, and the stages done never fall and end at the stages planned.
    pub fn check_monotone(events: &[Event]) {
        assert!(!events.is_empty());
        for w in events.windows(2) {
            assert!(w[1].stages_done >= w[0].stages_done, "{w:?}");
            if w[1].stages_done > w[0].stages_done {
                // the stage's end
                assert_eq!((&w[1].stage, w[1].done), (&w[0].stage, w[1].total), "a stage ends at its total: {w:?}");
            } else if w[1].stage != w[0].stage {
                // the next stage's beginning, after the last one's end
                assert_eq!(w[0].done, w[0].total, "{w:?}");
            } else {
                assert!(w[1].done >= w[0].done, "{w:?}");
            }
        }
        for e in events {
            assert!(e.done <= e.total && e.stages_done <= e.stages, "{e:?}");
            assert!(e.elapsed_s >= 0.0 && e.eta_s.is_none_or(|s| s >= 0.0 && s.is_finite()), "{e:?}");
        }
        let last = events.last().unwrap();
        assert_eq!((last.done, last.stages_done), (last.total, last.stages), "{last:?}");
    }

    #[test]
    fn a_stage_that_expects_more_grows_and_ends_at_what_it_did() {
        let out = Shared::default();
        let p = out.progress(2);
        p.begin("first", 4);
        p.expect(3);
        p.advance(3);
        p.expect(3);
        p.advance(3);
        p.end();
        p.begin("second", 10);
        p.advance(1);
        p.end();
        let events = out.events();
        check_monotone(&events);
        assert_eq!(events.iter().filter(|e| e.stage == "first").map(|e| e.total).max(), Some(6));
        assert_eq!(events.last().map(|e| (e.done, e.total)), Some((1, 1)));
    }
}
