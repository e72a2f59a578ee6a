//! A measurement campaign: the experiments, the measurements they gave (with the discretisation
//! error counted where `[resolution]` asks: `resolution.rs`), the estimate that counted it, and
//! how the experiments run (the engine, jobs at a time, progress and a fit's options). One
//! [`Campaign`] value is handed to calibration (`fit/calibrate.rs`), diagnosis (`diagnose/`) and
//! its rounds (`diagnose/rounds.rs`) instead of the bundle each of them took apart.
//!
//! In: a model, experiments, data, [`FitOptions`], the discretisation estimate. Out: the engine's
//! values, and Jacobians in named parameters, of every observation under the model, the runs
//! counted into the command's progress.
//!
//! The folder holds what a campaign is and how it runs: the experiments file (`experiments.rs`),
//! planned before any run (`preflight.rs`); one experiment under a model, a simulation or a
//! virtual rheometer (`runner.rs`, `rheometer.rs`); values and gradients (`sensitivity.rs`, idle
//! workers lent to the experiments still running: `spare.rs`); where the experiments run
//! (`engine.rs`; independent evaluations submitted together: `gather.rs`) and what a saved result was computed from (`provenance.rs`); the
//! discretisation error counted beside the measurement uncertainty (`resolution.rs`); a long
//! command's progress (`progress.rs`).

pub mod engine;
pub mod experiments;
pub mod gather;
pub mod preflight;
pub mod progress;
pub mod provenance;
pub mod resolution;
pub mod rheometer;
pub mod runner;
pub mod sensitivity;
pub mod spare;

use self::engine::{Answer, Engine};
use super::error::MeasureError;
use self::experiments::Experiments;
use super::model::Model;
use super::observation::Observation;
use self::progress::Progress;
use self::resolution::Counted;
use self::runner::Jobs;
use self::sensitivity::Differences;
use std::sync::atomic::{AtomicU64, Ordering};

/// A campaign's data and experiments, and how they run; borrowed, so a part (a subset of the
/// data, other options) is a new value over the same things.
#[derive(Clone, Copy)]
pub struct Campaign<'a> {
    pub exps: &'a Experiments,
    pub data: &'a [Observation],
    pub opts: &'a FitOptions,
    /// The discretisation estimate `data` was counted with, made at the campaign's starting
    /// model: its runs are that model's values of the data, which a fit from it need not run.
    pub estimate: Option<&'a Counted>,
}

#[derive(Clone, Debug)]
pub struct FitOptions {
    pub max_iterations: usize,
    /// Stop when an accepted step lowers chi^2 by less than this fraction (or by less than
    /// [`CHI2_NEGLIGIBLE`](super::fit::calibrate::CHI2_NEGLIGIBLE)).
    pub tolerance: f64,
    pub jobs: usize,
    /// Where each evaluation's experiments run (`engine.rs`): here, `jobs` at a time, or as a
    /// scheduler's jobs.
    pub engine: Engine,
    /// A line on stderr per accepted step.
    pub log: bool,
    /// The runs of each evaluation counted into the command's progress (`progress.rs`): bars,
    /// JSON events or nothing; it changes no result.
    pub progress: Progress,
    /// Broyden's secant update of the Jacobian after an accepted step, for a campaign with a
    /// simulation (module doc); a rheometer campaign's adjoints cost less than its runs and
    /// always give the Jacobian.
    pub secant: bool,
    /// The fit stops on an exact Jacobian and reports its uncertainties from one. Off for a fit
    /// that needs only its optimum (a leave-one-out refit, which predicts the left-out
    /// experiment): a secant step's negligible drop then ends it, and no Jacobian is computed
    /// at the end, each one 2 p runs of the campaign.
    pub uncertainties: bool,
    /// A stall the secant Jacobian declares (its undamped step promises nothing worth a run)
    /// ends the fit, without the exact Jacobian that would check it: for a fit whose chi^2 only
    /// screens (a candidate diagnose fits after a recommended one, finished where it comes close
    /// to it), not for one whose optimum is reported.
    pub stop_on_secant: bool,
}

impl<'a> Campaign<'a> {
    pub fn new(exps: &'a Experiments, data: &'a [Observation], opts: &'a FitOptions) -> Campaign<'a> {
        Campaign { exps, data, opts, estimate: None }
    }

    /// The same campaign with other data (a subset of its rows) and no estimate (it was made for
    /// the whole data).
    pub fn with_data<'b>(&self, data: &'b [Observation]) -> Campaign<'b>
    where
        'a: 'b,
    {
        Campaign { data, estimate: None, ..*self }
    }

    /// The same campaign run with other options.
    pub fn with_opts<'b>(&self, opts: &'b FitOptions) -> Campaign<'b>
    where
        'a: 'b,
    {
        Campaign { opts, ..*self }
    }

    /// The starting model's values of the data, where the discretisation estimate ran them.
    pub fn start_values(&self) -> Option<&'a [f64]> {
        self.estimate.map(|c| &c.start_values[..])
    }

    /// The engine's values of every observation under `model` and, with `names`, their gradients
    /// in them ([`Engine::evaluate`]); with `at`, the values known there and the differences to
    /// take, only the Jacobian's runs. The runs are counted into the progress.
    pub fn evaluate(
        &self,
        model: &Model,
        names: Option<&[String]>,
        at: Option<(&[f64], &Differences)>,
    ) -> Result<Answer, MeasureError> {
        let n = names.map_or(0, <[String]>::len);
        let per_experiment = match at {
            None => (1 + 2 * n).max(1),
            Some((_, Differences::Central)) => 2 * n,
            Some((_, Differences::Forward(_))) => n,
        };
        let (engine, data, exps) = (&self.opts.engine, self.data, self.exps);
        self.counted(per_experiment, |jobs| engine.evaluate(jobs, model, (data, exps), (names, at)))
    }

    /// `evaluate` counted into the progress: `per_experiment` runs of each of the data's
    /// experiments expected, and counted as each experiment ends (the rest, of experiments an
    /// engine does not count as they end, when the evaluation ends).
    fn counted<T>(&self, per_experiment: usize, evaluate: impl FnOnce(Jobs) -> T) -> T {
        let (progress, total) = (&self.opts.progress, runs(self.data, per_experiment));
        progress.expect(total);
        let counted = AtomicU64::new(0);
        let done = || {
            counted.fetch_add(per_experiment as u64, Ordering::Relaxed);
            progress.advance(per_experiment as u64);
        };
        let answer = evaluate(Jobs { n: self.opts.jobs, done: &done });
        progress.advance(total.saturating_sub(counted.load(Ordering::Relaxed)));
        answer
    }

    /// Whether any of the experiments the data observe is a simulation (a rheometer test's
    /// Jacobian comes from its adjoint at less than a run's cost).
    pub fn runs_simulations(&self) -> bool {
        self::runner::group(self.data).iter().any(|(id, _)| self.exps.get(id).is_some_and(|x| x.scenario.is_some()))
    }

    /// Whether a fit steps on secant Jacobians: asked to ([`FitOptions::secant`]), where the
    /// campaign runs simulations.
    pub fn on_secants(&self) -> bool {
        self.opts.secant && self.runs_simulations()
    }
}

/// The runs of an evaluation of `data` with `per_experiment` runs of each experiment: what a
/// campaign of simulations differenced centrally costs (a rheometer test's adjoint costs less,
/// and is counted alike).
fn runs(data: &[Observation], per_experiment: usize) -> u64 {
    (self::runner::group(data).len() * per_experiment) as u64
}

/// The runs a fit of `names` to `data` is expected to take: the Jacobian at the start and at the
/// end, and three trial steps between (a fit on a rough model's secant Jacobians stops after a
/// few; more are expected as they come).
pub fn expected_runs(data: &[Observation], names: &[String]) -> u64 {
    runs(data, 1 + 2 * names.len()) + runs(data, 3) + runs(data, 2 * names.len())
}

impl Default for FitOptions {
    fn default() -> FitOptions {
        FitOptions {
            max_iterations: 30,
            tolerance: 1e-5,
            jobs: 1,
            engine: Engine::Local,
            log: false,
            progress: Progress::default(),
            secant: true,
            uncertainties: true,
            stop_on_secant: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::progress::tests::{check_monotone, Shared};
    use super::*;

    /// An evaluation's runs are counted as each experiment ends, not only when all have: with
    /// two rheometer experiments and two parameters (1 + 2 x 2 = 5 runs each), the progress
    /// shows 5 of 10 before 10 of 10, and the answer is the same bits as a silent evaluation's.
    #[test]
    fn an_evaluation_counts_each_experiment_as_it_ends() {
        let model = Model::from_table(
            &"[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\n\
              yield_stress = 630.0\n"
                .parse()
                .unwrap(),
        )
        .unwrap();
        let exps: Experiments = toml::from_str(
            "[[experiment]]\nid = \"fast\"\nobserve = [\"stress@40\"]\n[experiment.protocol]\n\
             [[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [40.0]\nhold = 0.5\n\
             [[experiment]]\nid = \"slow\"\nobserve = [\"stress@5\"]\n[experiment.protocol]\n\
             [[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [5.0]\nhold = 0.5\n",
        )
        .unwrap();
        let data = crate::measure::compare::synth::synth(&model, &exps, 0.0, 1, 1).unwrap();
        let names = vec!["material.yield_stress".to_string(), "material.viscosity".to_string()];
        let out = Shared::default();
        let progress = out.progress(1);
        progress.begin("evaluation", 0);
        let counted = FitOptions { progress: progress.clone(), ..FitOptions::default() };
        let with = Campaign::new(&exps, &data, &counted).evaluate(&model, Some(&names), None).unwrap().unwrap();
        progress.end();
        let silent = FitOptions::default();
        let without = Campaign::new(&exps, &data, &silent).evaluate(&model, Some(&names), None).unwrap().unwrap();
        assert_eq!(format!("{:?}", with), format!("{:?}", without));
        let events = out.events();
        check_monotone(&events);
        let shown: Vec<(u64, u64)> = events.iter().map(|e| (e.done, e.total)).collect();
        assert!(shown.contains(&(5, 10)) && shown.contains(&(10, 10)), "{shown:?}");
    }
}
