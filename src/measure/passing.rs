//! How much of the material has passed below a plane over a run: a funnel's or a hopper's
//! discharge (paper 001 Sec. 4.3, the V-funnel's flow time and Fig. 25's percentage passed
//! through the gate).
//!
//! - `passed@Z:F`: the first time [s] at which the fraction F (0 < F <= 1) of the material's mass
//!   lies below z = Z [m], interpolated linearly between the two steps around it. A run in which
//!   less passes gives its end time (the discharge ends, if at all, after the run), as `arrival`
//!   does for a front that never arrives.
//!
//! The fraction below the plane is recorded after every step of the run, to its end. No adjoint
//! (a first crossing is not smooth in the positions): calibrate and diagnose difference it, as
//! they do the front's history (`front.rs`).

use super::error::MeasureError;
use super::observation::Observable;
use crate::solver::Simulation;

/// The observables of this file.
pub const OBSERVABLES: &[&str] = &["passed"];

/// Whether `o` is written as `passed@Z:F`, F in (0, 1].
pub fn check_observable(o: &Observable) -> Result<(), MeasureError> {
    let what = "the plane and the fraction of the mass below it: passed@Z:F (metres, 0 < F <= 1)";
    if o.name != "passed" {
        return Err(MeasureError::Observable(format!(
            "'{}' is not a passing observable ({})",
            o.name,
            OBSERVABLES.join(", ")
        )));
    }
    match (o.at, o.at2) {
        (Some(_), Some(f)) if !(f > 0.0 && f <= 1.0) => {
            Err(MeasureError::Observable(format!("'{o}': the fraction must lie in (0, 1], got {f}")))
        }
        (Some(_), Some(_)) => Ok(()),
        _ => Err(MeasureError::Observable(format!("'{o}' needs {what}"))),
    }
}

/// The fraction of the mass below each plane after each step of a run, from the start.
#[derive(Clone, Debug, Default)]
pub struct PassingTrace {
    planes: Vec<f64>,
    /// (time, the fraction below each plane, in `planes`' order)
    samples: Vec<(f64, Vec<f64>)>,
}

impl PassingTrace {
    /// A trace of the planes z = `planes`, holding `sim`'s state now.
    pub fn start(sim: &Simulation, planes: Vec<f64>) -> Result<PassingTrace, MeasureError> {
        let mut t = PassingTrace { planes, samples: Vec::new() };
        t.record(sim)?;
        Ok(t)
    }

    /// Add the fractions below the planes at `sim`'s current time.
    pub fn record(&mut self, sim: &Simulation) -> Result<(), MeasureError> {
        let p = &sim.particles;
        let mass = p.mass.as_slice();
        let total: f64 = (0..p.n).map(|i| mass[i] as f64).sum();
        if total <= 0.0 {
            return Err(MeasureError::History("passed: no material in the run".into()));
        }
        let below = self
            .planes
            .iter()
            .map(|&z| (0..p.n).filter(|&i| sim.position(i)[2] < z).map(|i| mass[i] as f64).sum::<f64>() / total)
            .collect();
        self.push(sim.time, below);
        Ok(())
    }

    /// Add a sample (times must not decrease; one fraction per plane).
    pub fn push(&mut self, time: f64, below: Vec<f64>) {
        debug_assert!(self.samples.last().is_none_or(|(t, _)| time >= *t) && below.len() == self.planes.len());
        self.samples.push((time, below));
    }

    /// The value of `passed@Z:F` (checked; Z one of the trace's planes).
    pub fn value(&self, o: &Observable) -> Result<f64, MeasureError> {
        check_observable(o)?;
        let (z, f) = (o.at.expect("checked"), o.at2.expect("checked"));
        let Some(k) = self.planes.iter().position(|&p| p == z) else {
            return Err(MeasureError::History(format!("'{o}': the plane z = {z} was not recorded")));
        };
        let s = &self.samples;
        let Some(last) = s.last() else {
            return Err(MeasureError::History("passed: nothing was recorded".into()));
        };
        Ok(match s.iter().position(|(_, b)| b[k] >= f) {
            None => last.0,
            Some(0) => s[0].0,
            Some(i) => {
                let ((t0, b0), (t1, b1)) = ((s[i - 1].0, s[i - 1].1[k]), (s[i].0, s[i].1[k]));
                t0 + (t1 - t0) * (f - b0) / (b1 - b0)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ob(s: &str) -> Observable {
        Observable::parse(s).unwrap()
    }

    #[test]
    fn passed_interpolates_the_first_crossing_and_is_the_end_when_never_reached() {
        let mut t = PassingTrace { planes: vec![0.2, 0.5], samples: Vec::new() };
        for (time, a, b) in [(0.0, 0.0, 0.1), (1.0, 0.4, 0.6), (2.0, 0.8, 0.9), (3.0, 0.9, 1.0)] {
            t.push(time, vec![a, b]);
        }
        assert!((t.value(&ob("passed@0.2:0.6")).unwrap() - 1.5).abs() < 1e-12);
        assert_eq!(t.value(&ob("passed@0.2:0.95")).unwrap(), 3.0, "never reached: the end");
        assert_eq!(t.value(&ob("passed@0.5:0.05")).unwrap(), 0.0, "already at the start");
        assert_eq!(t.value(&ob("passed@0.5:1")).unwrap(), 3.0);
        assert!(t.value(&ob("passed@0.3:0.5")).unwrap_err().to_string().contains("z = 0.3 was not recorded"));
    }

    #[test]
    fn a_malformed_passed_names_what_it_needs() {
        assert!(check_observable(&ob("passed@0.2:0.99")).is_ok());
        for (bad, want) in [
            ("passed", "passed@Z:F"),
            ("passed@0.2", "passed@Z:F"),
            ("passed@0.2:0", "(0, 1]"),
            ("passed@0.2:1.5", "(0, 1]"),
            ("front@1", "not a passing"),
        ] {
            let e = check_observable(&ob(bad)).unwrap_err().to_string();
            assert!(e.contains(want), "{bad}: {e}");
        }
    }
}
