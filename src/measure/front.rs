//! Observables read from the flow front's history over a run rather than from one time: when
//! the front reaches a station and when it stops (an L-box's `t_end` and `t_final`, paper 001
//! Sec. 4.2).
//!
//! The front is `front`'s: the largest particle x plus half a spacing (`observables/front.rs`), so
//! these observables are for flows along +x (an L-box, a channel). It is recorded after every
//! step of the run, to its end:
//!
//! - `arrival@X`: the first time [s] the front reaches x = X [m], interpolated linearly between
//!   the two steps around it. A run whose front never reaches X gives its end time (it arrives,
//!   if at all, after the run), as `failure_time` does for a print that stands.
//! - `stop_time@D`: the time [s] flow stops: the first time after which the front stays within
//!   D [m] of where it ends, to the end of the run (D > 0, the resolution of the observer: a
//!   front that creeps less than D counts as stopped). A front still moving by more than D at
//!   the end gives a time close to the end: run long enough for the flow to stop.
//!
//! Neither has an adjoint (a first crossing and a last departure are not smooth in the
//! positions): `strand compare` and `synth` evaluate them, and calibrate and diagnose take their
//! Jacobian columns by central differences (`sensitivity::has_adjoint`), as they do the failure
//! observables'; `strand grad` refuses them (`observables::observable_plan`).

use super::error::MeasureError;
use super::observation::Observable;
use crate::observables::{At, Frame, Objective, FRONT};
use crate::solver::Simulation;

/// The observables of this file.
pub const OBSERVABLES: &[&str] = &["arrival", "stop_time"];

/// Whether `o` is written as one of [`OBSERVABLES`] takes it: one coordinate, positive for
/// `stop_time`'s tolerance.
pub fn check_observable(o: &Observable) -> Result<(), MeasureError> {
    let what = match o.name.as_str() {
        "arrival" => "the station the front reaches: arrival@X (metres)",
        "stop_time" => "the distance the front may still move once stopped: stop_time@D (metres, > 0)",
        other => {
            return Err(MeasureError::Observable(format!(
                "'{other}' is not a front-history observable ({})",
                OBSERVABLES.join(", ")
            )))
        }
    };
    match (o.at, o.at2) {
        (Some(_), Some(_)) => Err(MeasureError::Observable(format!("'{o}': {} takes one coordinate, {what}", o.name))),
        (None, _) => Err(MeasureError::Observable(format!("'{}' needs {what}", o.name))),
        (Some(d), None) if o.name == "stop_time" && d <= 0.0 => {
            Err(MeasureError::Observable(format!("'{o}': the distance must be > 0 metres, got {d}")))
        }
        (Some(_), None) => Ok(()),
    }
}

/// The front after each step of a run: (time, front x) pairs, from the start.
#[derive(Clone, Debug, Default)]
pub struct FrontTrace {
    samples: Vec<(f64, f64)>,
}

impl FrontTrace {
    /// A trace holding `sim`'s front now.
    pub fn start(sim: &Simulation) -> Result<FrontTrace, MeasureError> {
        let mut t = FrontTrace::default();
        t.record(sim)?;
        Ok(t)
    }

    /// Add `sim`'s front at its current time.
    pub fn record(&mut self, sim: &Simulation) -> Result<(), MeasureError> {
        let x = Objective::new(&FRONT, At::Nothing).evaluate(sim, &Frame::of(sim), None)?;
        self.push(sim.time, x);
        Ok(())
    }

    /// Add a sample (times must not decrease).
    pub fn push(&mut self, time: f64, front: f64) {
        debug_assert!(self.samples.last().is_none_or(|&(t, _)| time >= t));
        self.samples.push((time, front));
    }

    /// The value of observable `o` (one of [`OBSERVABLES`], checked) for this trace.
    pub fn value(&self, o: &Observable) -> Result<f64, MeasureError> {
        check_observable(o)?;
        let at = o.at.expect("checked");
        match o.name.as_str() {
            "arrival" => self.arrival(at),
            _ => self.stop_time(at),
        }
    }

    /// The first time the front reaches `x`; the last sample's time if it never does.
    pub fn arrival(&self, x: f64) -> Result<f64, MeasureError> {
        let s = self.nonempty()?;
        let Some(k) = s.iter().position(|&(_, f)| f >= x) else {
            return Ok(s[s.len() - 1].0);
        };
        if k == 0 {
            return Ok(s[0].0);
        }
        let ((t0, f0), (t1, f1)) = (s[k - 1], s[k]);
        Ok(t0 + (t1 - t0) * (x - f0) / (f1 - f0))
    }

    /// The first time after which the front stays within `tol` of its last sample.
    pub fn stop_time(&self, tol: f64) -> Result<f64, MeasureError> {
        let s = self.nonempty()?;
        let end = s[s.len() - 1].1;
        Ok(match s.iter().rposition(|&(_, f)| (f - end).abs() > tol) {
            Some(k) => s[k + 1].0,
            None => s[0].0,
        })
    }

    fn nonempty(&self) -> Result<&[(f64, f64)], MeasureError> {
        if self.samples.is_empty() {
            return Err(MeasureError::History("the front was never recorded".into()));
        }
        Ok(&self.samples)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(points: &[(f64, f64)]) -> FrontTrace {
        let mut t = FrontTrace::default();
        for &(a, b) in points {
            t.push(a, b);
        }
        t
    }

    #[test]
    fn arrival_interpolates_the_first_crossing_and_is_the_end_when_never_reached() {
        // the front passes 0.5 between 1 s (0.4) and 2 s (0.6), recedes, passes again later
        let t = trace(&[(0.0, 0.1), (1.0, 0.4), (2.0, 0.6), (3.0, 0.45), (4.0, 0.7)]);
        assert!((t.arrival(0.5).unwrap() - 1.5).abs() < 1e-12);
        assert_eq!(t.arrival(0.05).unwrap(), 0.0);
        assert_eq!(t.arrival(0.7).unwrap(), 4.0);
        assert_eq!(t.arrival(0.8).unwrap(), 4.0);
    }

    #[test]
    fn stop_time_is_the_last_departure_beyond_the_tolerance() {
        let t = trace(&[(0.0, 0.1), (1.0, 0.5), (2.0, 0.58), (3.0, 0.595), (4.0, 0.6), (5.0, 0.6)]);
        // within 10 mm of 0.6 from 2 s on; within 1 mm from 4 s; within 1 m from the start
        assert_eq!(t.stop_time(0.01).unwrap(), 3.0);
        assert_eq!(t.stop_time(0.021).unwrap(), 2.0);
        assert_eq!(t.stop_time(1e-3).unwrap(), 4.0);
        assert_eq!(t.stop_time(1.0).unwrap(), 0.0);
        // a front still moving at the end stops at the end
        assert_eq!(trace(&[(0.0, 0.0), (1.0, 0.1), (2.0, 0.2)]).stop_time(0.01).unwrap(), 2.0);
        assert!(FrontTrace::default().stop_time(0.01).unwrap_err().to_string().contains("never recorded"));
    }

    #[test]
    fn each_takes_one_coordinate_and_the_error_says_which() {
        let ob = |s: &str| Observable::parse(s).unwrap();
        assert!(check_observable(&ob("arrival@0.7")).is_ok());
        assert!(check_observable(&ob("stop_time@0.005")).is_ok());
        for (bad, want) in [
            ("arrival", "arrival@X"),
            ("arrival@0.7:1", "one coordinate"),
            ("stop_time", "stop_time@D"),
            ("stop_time@0", "> 0 metres"),
            ("stop_time@-0.01", "> 0 metres"),
            ("front@1", "not a front-history"),
        ] {
            let e = check_observable(&ob(bad)).unwrap_err().to_string();
            assert!(e.contains(want), "{bad}: {e}");
        }
        let t = trace(&[(0.0, 0.1), (1.0, 0.3)]);
        assert!((t.value(&ob("arrival@0.2")).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(t.value(&ob("stop_time@0.01")).unwrap(), 1.0);
    }
}
