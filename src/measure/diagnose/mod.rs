//! `strand diagnose`: which physical effect the model lacks.
//!
//! 1. The base model's `fit` parameters are calibrated.
//! 2. Every effect not in the model is switched on at its null, where the model is unchanged,
//!    and the gradient of the loss L = chi^2 / 2 in its parameters is taken there by the
//!    adjoints: a score (Lagrange-multiplier) test. With z the standardised residuals, J_f and
//!    J_e their Jacobians in the fitted and the effect's parameters, and R = (I - P_f) J_e the
//!    effect's columns with what the fitted parameters already explain projected out, the score
//!    is S = z^T R (R^T R)^+ R^T z, chi^2-distributed with rank(R) degrees of freedom when the
//!    effect is absent. A material effect's parameters start at their lower bound, so only those
//!    whose projected gradient points into the allowed side count, and with one such parameter
//!    the p-value is half chi^2(1)'s tail (S is 0 half the time under the null); a process
//!    effect's null (an extrusion factor of 1, a standoff offset of 0) lies inside its bounds, so
//!    its parameters count whichever way the gradient points, with the full tail.
//!    An effect whose null lies at infinity, where no finite parameter puts it and the loss has
//!    no gradient (elasticity, compressibility: G or K = infinity, where the explicit step goes
//!    to 0; wall friction: mu = infinity, a floor that sticks), is fitted with the base
//!    parameters from [`Effect::lr_start`] (for a modulus the finite value the base model runs
//!    in the null's place, where the model is the base model; for friction a typical mu) and
//!    tested by the likelihood ratio LR = max(0, chi^2_base - chi^2_fitted) instead, with the
//!    same chi^2(dof) tail, halved for one parameter (the null is the boundary of the parameter
//!    space, 1/G >= 0).
//! 3. Effects are ranked by statistic, S or LR: both measure the drop in chi^2 the effect
//!    brings (S is its Gauss-Newton estimate at the null, LR the drop itself), so they share
//!    one scale, where p-values would underflow to 0 and tie for every strong effect. Those
//!    significant at `alpha` (the top `max_fitted`) are fitted with the base parameters (the
//!    likelihood ratio's fit is that fit), and each whose fit lowers chi^2 by 1 % or more is
//!    checked by leave-one-experiment-out: refitted without each experiment in turn (one
//!    Gauss-Newton step from the full fit, checked by the left-out experiment's run and replaced
//!    by a full refit where the check refuses it, or with `exact_refits` always a full refit;
//!    [`leave_one_out`]), it must predict the left-out
//!    experiments better than the base model refitted the same way, or it only overfits and is
//!    not recommended. A candidate whose fitted chi^2 + 2 k (Akaike's criterion, k parameters
//!    fitted) is no less than a recommended one's is not checked: leave-one-out's choice
//!    follows that criterion asymptotically (Stone 1977), so it would not be chosen. So a
//!    candidate fitted after a recommended one is fitted to the optimum its secant Jacobian sees,
//!    and finished on an exact Jacobian there ([`finish`]: its uncertainties, leave-one-out's
//!    steps) only where it comes close to that criterion ([`SCREENED_MARGIN`]).
//! 4. When no effect is recommended and the base model does not fit (chi^2 beyond its `alpha`
//!    quantile) the verdict is "unexplained", with the pattern of the residuals.
//!
//! Under a scheduler the likelihood-ratio fits, and the leave-one-out checks of the base model
//! and of a candidate, are independent and run side by side, their evaluations submitted
//! together ([`Engine::side_by_side`](super::campaign::engine::Engine::side_by_side)); the
//! results are the same bits.
//!
//! In: a campaign, a model and the parameters to refit. Out: a [`Diagnosis`] (candidates ranked,
//! a verdict, the recommended model), or with `--rounds` the loop run to its end (`rounds.rs`).
//! Beside it: Jacobian columns the keys give without a run (`chain.rs`) and the residuals'
//! shapes in words (`residuals.rs`).

pub mod chain;
pub mod residuals;
pub mod rounds;

use super::fit::calibrate::{calibrate_at, calibrate_from, chi2, chi2_scatter, predicted_drop, standardised, Fit};
use super::campaign::{expected_runs, Campaign, FitOptions};
use super::error::{io_error, toml_error, MeasureError};
use super::observation::Observation;
use super::effects::{Covariates, Effect};
use super::fit::linalg::{chi2_sf, gauss_newton_step, normal_equations, pinv_sym};
use super::model::Model;
use super::campaign::sensitivity::{Differences, Sensitivity};

#[derive(Clone, Debug)]
pub struct DiagnoseOptions {
    /// Significance level of the score and likelihood-ratio tests and of the base model's
    /// goodness of fit.
    pub alpha: f64,
    /// How many significant effects are fitted.
    pub max_fitted: usize,
    pub leave_one_out: bool,
    /// Leave-one-out by a full refit without each experiment, instead of one checked
    /// Gauss-Newton step from the full fit (see [`leave_one_out`]).
    pub exact_refits: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> DiagnoseOptions {
        DiagnoseOptions { alpha: 0.01, max_fitted: 3, leave_one_out: true, exact_refits: false }
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    pub effect: String,
    pub about: String,
    /// 1 = the largest statistic.
    pub rank: usize,
    /// "score", or "likelihood-ratio" for an effect whose null lies at infinity.
    pub test: String,
    /// The test's statistic: the score S, or LR = chi^2_base - chi^2_fitted.
    pub score: f64,
    pub dof: usize,
    pub p_value: f64,
    /// The fitted model with this effect: chi^2 and its parameters.
    pub fitted_chi2: Option<f64>,
    /// rms z with the effect over rms z of the base fit.
    pub error_ratio: Option<f64>,
    pub fitted: Vec<(String, f64)>,
    /// Sum of the left-out experiments' chi^2: base model, and with the effect.
    pub loo_chi2_base: Option<f64>,
    pub loo_chi2: Option<f64>,
    pub verdict: String,
    pub recommended: bool,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Diagnosis {
    pub fit: Vec<String>,
    pub observations: usize,
    pub base_chi2: f64,
    pub base_rms_z: f64,
    /// P(chi^2 > base_chi2) with observations - fitted parameters degrees of freedom.
    pub base_p_value: f64,
    pub base_values: Vec<(String, f64)>,
    pub candidates: Vec<Candidate>,
    pub recommended: Option<String>,
    /// "add EFFECT", "unexplained" or "explained".
    pub verdict: String,
    /// Where the residuals of an unexplained misfit lie (largest residuals, worst observables),
    /// then the base fit's residual shapes in words.
    pub pattern: Vec<String>,
    /// The base fit's residual shapes (trend, curvature, step, together) against each covariate.
    pub shapes: Vec<self::residuals::Shape>,
    /// Wall-clock seconds of each stage.
    pub timing: Timing,
    #[serde(skip)]
    pub recommended_model: Option<Model>,
    /// The base model refitted (`fit`).
    #[serde(skip)]
    pub base_model: Model,
}

/// A likelihood-ratio effect is fitted only where one Gauss-Newton step from its start predicts
/// chi^2_base - chi^2 of at least this: one observation's noise, a fifth of the 1 % test's
/// threshold (5.4 for one parameter), so a fit the linearisation underestimates fivefold is still
/// made. The others are reported from their start, unfitted: on a print campaign each fit is
/// several minutes of CPU.
pub const LR_WORTH_FITTING: f64 = 1.0;

/// A candidate fitted after a recommended one stops where its secant Jacobian sees the optimum
/// ([`FitOptions::stop_on_secant`]), and an exact Jacobian there may still find more: on the six
/// prints of `make bench-print-diagnose`, extrusion_factor's fit stopped so at chi^2 1,004, where
/// the exact Jacobian's undamped step promised 761 (a fall of 24 %, which that Jacobian's own
/// scatter called noise). So one whose chi^2 + 2 k is under this many times the recommended
/// one's is finished on an exact Jacobian ([`finish`]) before the two are compared; one beyond
/// it is beaten.
pub const SCREENED_MARGIN: f64 = 2.0;

/// chi^2's drop one undamped Gauss-Newton step from `f`'s end predicts: g^T (J^T J)^+ g, with J
/// and the residuals standardised.
fn gauss_newton_drop(f: &Fit, data: &[Observation]) -> Result<f64, MeasureError> {
    let scale: Vec<f64> = f.model.parameters(&f.names)?.iter().map(|p| p.bounds.scale).collect();
    let (z, jz) = standardised(&f.model_values, &f.jacobian, data, &scale);
    let (a, g) = normal_equations(&jz, &z, &(0..f.names.len()).collect::<Vec<_>>());
    Ok(predicted_drop(&a, &g))
}

/// Where a diagnosis spends its time, in wall-clock seconds: the base fit, the score tests (one
/// Jacobian in every absent effect's parameters), the likelihood-ratio fits, the candidates' fits
/// and leave-one-out.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timing {
    pub base_fit: f64,
    pub score_tests: f64,
    pub likelihood_ratio_fits: f64,
    pub candidate_fits: f64,
    pub leave_one_out: f64,
}

fn rms(chi2: f64, n: usize) -> f64 {
    (chi2 / n.max(1) as f64).sqrt()
}

/// The test an effect gets: the score at its null, or, for a null at infinity, the likelihood
/// ratio of its fit.
pub fn test_of(e: &dyn Effect) -> &'static str {
    if e.null_at_infinity() {
        "likelihood-ratio"
    } else {
        "score"
    }
}

/// The p-value of a statistic with `dof` degrees of freedom: with one parameter held at its
/// bound under the null, the statistic is 0 half the time and chi^2(1) otherwise
/// (chi-bar-squared); for more, chi^2(dof) is the conservative bound.
fn p_value(stat: f64, dof: usize) -> f64 {
    match dof {
        0 => 1.0,
        1 => 0.5 * chi2_sf(stat, 1),
        _ => chi2_sf(stat, dof),
    }
}

/// The base parameters refitted with every candidate, then the effect's own.
fn fit_names(fit: &[String], e: &dyn Effect) -> Vec<String> {
    let mut names = fit.to_vec();
    names.extend(e.params().iter().map(|s| format!("{}.{}", e.name(), s.name)));
    names
}

impl Candidate {
    /// The candidate's fit: its chi^2, its error against the base model's (`base_chi2` over `m`
    /// observations), and the fitted values.
    fn record(&mut self, f: &Fit, base_chi2: f64, m: usize) {
        self.fitted_chi2 = Some(f.chi2);
        self.error_ratio = Some(rms(f.chi2, m) / rms(base_chi2, m).max(1e-300));
        self.fitted = f.names.iter().cloned().zip(f.values.iter().copied()).collect();
    }
}

fn candidate(e: &dyn Effect, score: f64, dof: usize, p_value: f64, verdict: String) -> Candidate {
    Candidate {
        effect: e.name().into(),
        about: e.about().into(),
        rank: 0,
        test: test_of(e).into(),
        score,
        dof,
        p_value,
        fitted_chi2: None,
        error_ratio: None,
        fitted: vec![],
        loo_chi2_base: None,
        loo_chi2: None,
        verdict,
        recommended: false,
    }
}

/// A diagnosis's question: the campaign, the parameters refitted with every candidate, and the
/// options of the tests.
#[derive(Clone, Copy)]
struct Diagnosing<'c, 'a> {
    c: &'c Campaign<'a>,
    fit: &'c [String],
    opts: &'c DiagnoseOptions,
}

/// Which effect `model` lacks, to explain the campaign's data once `fit` is refitted (module
/// doc); the model's values of the data are known where the campaign's discretisation estimate
/// ran them.
pub fn diagnose(
    c: &Campaign,
    model: &Model,
    fit: &[String],
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, MeasureError> {
    let d = Diagnosing { c, fit, opts };
    let data = c.data;
    let m = data.len();
    let mut clock = Clock::new(c.opts);
    let progress = &c.opts.progress;
    // the base fit, the score tests and the likelihood-ratio fits; each candidate's stages are
    // planned once the tests have ranked them
    progress.plan(3);
    clock.say("the base model".into());
    progress.begin("base fit", if fit.is_empty() { 0 } else { expected_runs(data, fit) });
    let base = base_fit(c, model, fit)?;
    let base_p_value = chi2_sf(base.chi2, m.saturating_sub(fit.len()).max(1));
    clock.timing.base_fit = clock.lap();
    progress.end();
    progress.begin("score tests", 0);
    let mut scored = score_tests(d, &base, &clock)?;
    clock.timing.score_tests = clock.lap();
    progress.end();
    progress.begin(
        "likelihood-ratio fits",
        scored.unreachable.iter().map(|e| expected_runs(data, &fit_names(fit, *e))).sum(),
    );
    let (lr, mut prefit) = likelihood_ratio_tests(d, &base, model, &scored.unreachable, &clock)?;
    clock.timing.likelihood_ratio_fits = clock.lap();
    progress.end();
    let mut cands = std::mem::take(&mut scored.candidates);
    cands.extend(lr);
    cands.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.effect.cmp(&b.effect)));
    cands.append(&mut scored.inapplicable);
    let models = fit_and_check(d, &mut cands, &base, (&mut prefit, &scored), &mut clock)?;

    // Effects equal at first order at the null (linear and exponential ageing) tie on the score;
    // the fit tells them apart. The statistic ranks, score and likelihood ratio alike (module
    // doc).
    let key = |c: &Candidate| (c.score * 1e6).round() / 1e6;
    let mut order: Vec<usize> = (0..cands.len()).collect();
    order.sort_by(|&a, &b| {
        let (ca, cb) = (&cands[a], &cands[b]);
        key(cb)
            .total_cmp(&key(ca))
            .then(ca.fitted_chi2.unwrap_or(f64::INFINITY).total_cmp(&cb.fitted_chi2.unwrap_or(f64::INFINITY)))
            .then(a.cmp(&b))
    });
    let mut cands: Vec<Candidate> = order.iter().map(|&i| cands[i].clone()).collect();
    let models: Vec<Option<Model>> = order.iter().map(|&i| models[i].clone()).collect();
    for (i, c) in cands.iter_mut().enumerate() {
        c.rank = i + 1;
    }
    let best = choose(&mut cands);
    let recommended = best.map(|i| cands[i].effect.clone());
    let recommended_model = best.and_then(|i| models[i].clone());
    let shapes = residual_shapes(c, &base, opts.alpha)?;
    let (verdict, mut pattern) = match (&recommended, base_p_value < opts.alpha) {
        (Some(e), _) => (format!("add {e}"), vec![]),
        (None, true) => ("unexplained".to_string(), largest_residuals(&base, data)),
        (None, false) => ("explained".to_string(), vec![]),
    };
    pattern.extend(shapes.iter().map(|s| s.text.clone()));
    Ok(Diagnosis {
        fit: fit.to_vec(),
        observations: m,
        base_chi2: base.chi2,
        base_rms_z: rms(base.chi2, m),
        base_p_value,
        base_values: base.names.iter().cloned().zip(base.values.iter().copied()).collect(),
        timing: clock.timing,
        candidates: cands,
        recommended,
        verdict,
        pattern,
        shapes,
        recommended_model,
        base_model: base.model.clone(),
    })
}

/// A diagnosis's stages timed, and said on stderr as they begin when `log` is on.
struct Clock {
    log: bool,
    progress: super::campaign::progress::Progress,
    began: std::time::Instant,
    since: std::time::Instant,
    timing: Timing,
}

impl Clock {
    fn new(opts: &FitOptions) -> Clock {
        let now = std::time::Instant::now();
        Clock { log: opts.log, progress: opts.progress.clone(), began: now, since: now, timing: Timing::default() }
    }

    /// Seconds since the last lap.
    fn lap(&mut self) -> f64 {
        let t = self.since.elapsed().as_secs_f64();
        self.since = std::time::Instant::now();
        t
    }

    fn say(&self, what: String) {
        if self.log {
            self.progress.log(&format!("diagnose ({:.0} s): {what}", self.began.elapsed().as_secs_f64()));
        }
    }
}

/// The base model fitted in `fit` (or taken as it is when `fit` is empty), from its values
/// where the campaign's discretisation estimate ran them.
fn base_fit(c: &Campaign, model: &Model, fit: &[String]) -> Result<Fit, MeasureError> {
    if !fit.is_empty() {
        return calibrate_at(c, model, c.start_values(), fit);
    }
    let (data, m) = (c.data, c.data.len());
    let v = match c.start_values() {
        Some(v) => v.to_vec(),
        None => c.evaluate(model, None, None)??.values,
    };
    let c2 = chi2(&v, data);
    Ok(Fit {
        names: vec![],
        start: vec![],
        values: vec![],
        uncertainty: vec![],
        at_bound: vec![],
        influence: vec![],
        chi2_start: c2,
        chi2: c2,
        reduced_chi2: c2 / m as f64,
        history: vec![c2],
        converged: true,
        observations: m,
        model_values: v.clone(),
        jacobian: vec![],
        scatter: vec![0.0; m],
        jacobian_scatter: vec![vec![]; m],
        at_start: Sensitivity {
            values: v,
            jacobian: Some(vec![]),
            scatter: vec![0.0; m],
            jacobian_scatter: Some(vec![vec![]; m]),
        },
        model: model.clone(),
    })
}

/// Values and Jacobian, in the base fit's parameters then `extra`, at `with`: the base fit's model
/// (or the model it started from, `from_start`) with effects added. Where `with` gives that
/// point's values (every added effect at its null, or a modulus at the stand-in the base model
/// runs in its place), the fitted parameters' columns are the base fit's own there, `extra`'s
/// follow from them where the keys allow ([`chained`](self::chain::chained)), and only the
/// rest are computed, from those values, by one-sided differences (the scatter is the base
/// fit's there: [`Differences::Forward`]); elsewhere every column is, from `with`'s values.
/// `with`'s values are that point's without a run where every added effect is at a start that
/// `runs_as_model` ([`Effect::start_runs_as_model`]); otherwise they are run, and compared.
fn beside_base(
    c: &Campaign,
    base: &Fit,
    (from_start, runs_as_model): (bool, bool),
    with: &Model,
    extra: &[String],
) -> Result<Sensitivity, MeasureError> {
    let (data, exps) = (c.data, c.exps);
    let names: Vec<String> = base.names.iter().chain(extra).cloned().collect();
    let (known, known_jacobian, known_scatter, known_jacobian_scatter) = match from_start {
        true => (
            &base.at_start.values,
            base.at_start.jacobian.as_ref().expect("asked"),
            &base.at_start.scatter,
            base.at_start.jacobian_scatter.as_ref().expect("asked"),
        ),
        false => (&base.model_values, &base.jacobian, &base.scatter, &base.jacobian_scatter),
    };
    let values = if runs_as_model { known.clone() } else { c.evaluate(with, None, None)??.values };
    if values != *known || base.names.is_empty() || extra.is_empty() {
        return c.evaluate(with, Some(&names), Some((&values, &Differences::Central)))?;
    }
    // an effect's columns the fitted parameters' give through the keys take no run
    let chained = self::chain::chained(with, data, exps, &base.names, (known_jacobian, known_jacobian_scatter), extra)?;
    let run: Vec<String> = extra.iter().zip(&chained).filter(|(_, c)| c.is_none()).map(|(n, _)| n.clone()).collect();
    let (computed, computed_scatter, scatter) = if run.is_empty() {
        (vec![vec![]; data.len()], vec![vec![]; data.len()], known_scatter.clone())
    } else {
        // one-sided: at the base fit's values, whose scatter its central differences estimated
        let s = c.evaluate(with, Some(&run), Some((&values, &Differences::Forward(known_scatter.clone()))))??;
        (s.jacobian.expect("asked"), s.jacobian_scatter.expect("asked"), known_scatter.clone())
    };
    // the known columns, then each extra parameter's, chained or computed
    let rows =
        |known: &[Vec<f64>], computed: Vec<Vec<f64>>, pick: fn(&self::chain::Chained) -> &Vec<f64>| -> Vec<Vec<f64>> {
            computed
                .into_iter()
                .enumerate()
                .map(|(i, computed)| {
                    let mut next = computed.into_iter();
                    let added: Vec<f64> = chained
                        .iter()
                        .map(|c| c.as_ref().map_or_else(|| next.next().expect("a computed column"), |c| pick(c)[i]))
                        .collect();
                    known[i].iter().copied().chain(added).collect()
                })
                .collect()
        };
    let jacobian = rows(known_jacobian, computed, |c| &c.column);
    let jacobian_scatter = rows(known_jacobian_scatter, computed_scatter, |c| &c.scatter);
    Ok(Sensitivity { values, jacobian: Some(jacobian), scatter, jacobian_scatter: Some(jacobian_scatter) })
}

/// What the score tests leave: a candidate for each effect tested by its score, the effects
/// whose null lies at infinity (for the likelihood ratio) and those that cannot act here, and the
/// Jacobian at the nulls in the fitted parameters and every score-tested effect's (a candidate's
/// fit starts from its columns).
struct ScoreTests {
    candidates: Vec<Candidate>,
    unreachable: Vec<&'static dyn Effect>,
    inapplicable: Vec<Candidate>,
    at_nulls: Sensitivity,
    /// Each score-tested effect's columns in `at_nulls`' Jacobian.
    columns: Vec<(&'static str, Vec<usize>)>,
}

/// Every absent effect that can act on these experiments at its null, differentiated at once,
/// and scored.
fn score_tests(d: Diagnosing, base: &Fit, clock: &Clock) -> Result<ScoreTests, MeasureError> {
    let (data, fit, opts) = (d.c.data, d.fit, d.opts);
    let mut absent: Vec<&'static dyn Effect> = Vec::new();
    let mut unreachable: Vec<&'static dyn Effect> = Vec::new();
    let mut inapplicable: Vec<Candidate> = Vec::new();
    let available = super::effects::declared::available(&base.model.declared);
    for e in available.into_iter().filter(|e| !base.model.has(e.name())) {
        match applicable(d.c, e, &base.model) {
            Ok(()) if !e.null_at_infinity() => absent.push(e),
            Ok(()) => unreachable.push(e),
            Err(why) => inapplicable.push(candidate(e, 0.0, 0, 1.0, format!("not applicable: {why}"))),
        }
    }
    let aug = base.model.edited(&absent, &[]);
    let mut names: Vec<String> = fit.to_vec();
    let mut cols_of: Vec<Vec<usize>> = Vec::new();
    for e in &absent {
        cols_of.push((names.len()..names.len() + e.params().len()).collect());
        names.extend(e.params().iter().map(|s| format!("{}.{}", e.name(), s.name)));
    }
    clock
        .say(format!("score tests at the nulls of {}", absent.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")));
    let at_nulls =
        beside_base(d.c, base, (false, absent.iter().all(|e| e.start_runs_as_model())), &aug, &names[fit.len()..])?;
    let scale: Vec<f64> = aug.parameters(&names)?.iter().map(|p| p.bounds.scale).collect();
    let (z, jz) = standardised(&at_nulls.values, at_nulls.jacobian.as_ref().expect("asked"), data, &scale);
    let fcols: Vec<usize> = (0..fit.len()).collect();
    let (ff, _) = normal_equations(&jz, &z, &fcols);
    let (ff_inv, _) = pinv_sym(&ff, 1e-12);
    // (I - P_f) applied to a column of J or to z
    let project = |v: &[f64]| -> Vec<f64> {
        if fcols.is_empty() {
            return v.to_vec();
        }
        let jt_v: Vec<f64> = fcols.iter().map(|&c| jz.iter().zip(v).map(|(r, x)| r[c] * x).sum()).collect();
        let coef: Vec<f64> = ff_inv.iter().map(|r| r.iter().zip(&jt_v).map(|(a, b)| a * b).sum()).collect();
        v.iter()
            .enumerate()
            .map(|(i, x)| x - fcols.iter().zip(&coef).map(|(&c, k)| jz[i][c] * k).sum::<f64>())
            .collect()
    };
    let zp = project(&z);

    let mut cands: Vec<Candidate> = Vec::new();
    for (e, cols) in absent.iter().zip(&cols_of) {
        let column = |c: usize| -> Vec<f64> { jz.iter().map(|r| r[c]).collect() };
        let influence = cols.iter().any(|&c| jz.iter().any(|r| r[c] != 0.0));
        // one-sided at a bound: a parameter whose null is its lower bound counts when raising it
        // from its null lowers the loss once the fitted parameters follow (the projected
        // gradient), one whose null is its upper bound when lowering it does; a null inside the
        // bounds (a flow index n = 1, a process effect's factor or offset) counts either way, if
        // its column reaches the data (the Maxwell time's null lies inside too, but its column is
        // 0 at the branch's null)
        let into_bounds = |i: usize, c: usize| {
            let (s, slope) = (e.params()[i], project(&column(c)).iter().zip(&zp).map(|(a, b)| a * b).sum::<f64>());
            if s.null <= s.lower { slope < 0.0 } else if s.null >= s.upper { slope > 0.0 } else { slope != 0.0 }
        };
        let kept_params: Vec<(usize, usize)> =
            cols.iter().copied().enumerate().filter(|&(i, c)| into_bounds(i, c)).collect();
        let kept: Vec<usize> = kept_params.iter().map(|&(_, c)| c).collect();
        let at_bound = kept_params
            .iter()
            .all(|&(i, _)| e.params()[i].null <= e.params()[i].lower || e.params()[i].null >= e.params()[i].upper);
        let r: Vec<Vec<f64>> = kept.iter().map(|&c| project(&column(c))).collect();
        let info: Vec<Vec<f64>> =
            r.iter().map(|a| r.iter().map(|b| a.iter().zip(b).map(|(x, y)| x * y).sum()).collect()).collect();
        let g: Vec<f64> = r.iter().map(|a| a.iter().zip(&zp).map(|(x, y)| x * y).sum()).collect();
        // columns the fitted parameters already explain have ~0 left after projection
        let raw: f64 = kept.iter().map(|&c| column(c).iter().map(|x| x * x).sum::<f64>()).fold(0.0, f64::max);
        let (inv, rank) = if kept.is_empty() { (vec![], 0) } else { pinv_sym(&info, 1e-10) };
        let left = info.iter().enumerate().map(|(i, row)| row[i]).fold(0.0, f64::max);
        let (score, dof) = if rank == 0 || left <= 1e-10 * raw {
            (0.0, 0)
        } else {
            (
                g.iter().enumerate().map(|(i, gi)| gi * inv[i].iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()).sum(),
                rank,
            )
        };
        // a null inside the bounds is a two-sided test: the full chi^2 tail, without the
        // bound's halving
        let p_value = match (dof, at_bound) {
            (0, _) => 1.0,
            (_, true) => p_value(score, dof),
            (_, false) => chi2_sf(score, dof),
        };
        let verdict = score_verdict(influence, (dof, kept.is_empty()), p_value, opts.alpha);
        cands.push(candidate(*e, score, dof, p_value, verdict));
    }
    let columns = absent.iter().map(|e| e.name()).zip(cols_of).collect();
    Ok(ScoreTests { candidates: cands, unreachable, inapplicable, at_nulls, columns })
}

/// A score test's verdict on a candidate; empty when it is significant at `alpha`, to be fitted.
fn score_verdict(influence: bool, (dof, none_kept): (usize, bool), p_value: f64, alpha: f64) -> String {
    if !influence {
        "no influence on these experiments".to_string()
    } else if dof == 0 && !none_kept {
        "indistinguishable from the fitted parameters here".to_string()
    } else if dof == 0 {
        "not significant: raising it from its null raises the error".to_string()
    } else if p_value >= alpha {
        format!("not significant (p = {p_value:.3})")
    } else {
        String::new()
    }
}

/// The likelihood ratio of each effect whose null lies at infinity: the effect fitted from its
/// start (a modulus: the stand-in for the null of the model it starts from, where that model is
/// the base model), with the fitted parameters from the base fit's values (so a modulus's chi^2
/// starts at chi^2_base and the fit only lowers it), and, when that finds no significant drop and the base fit moved,
/// from the model's own: the base fit may have gone where the effect has no gradient (a yield
/// stress fitted so low that every reading is past yield, where G drops out); the better of the two
/// fits counts. Returns the candidates and the fits a candidate's fit can take over.
fn likelihood_ratio_tests(
    d: Diagnosing,
    base: &Fit,
    model: &Model,
    unreachable: &[&'static dyn Effect],
    clock: &Clock,
) -> Result<(Vec<Candidate>, std::collections::BTreeMap<String, Fit>), MeasureError> {
    // the effects' fits are independent: a scheduler runs their evaluations together
    let tested =
        d.c.opts.engine.side_by_side(unreachable.len(), |k| likelihood_ratio(d, base, model, unreachable[k], clock));
    let mut cands = Vec::new();
    let mut prefit: std::collections::BTreeMap<String, Fit> = Default::default();
    for (e, t) in unreachable.iter().zip(tested) {
        let (c, f) = t?;
        if let Some(f) = f {
            prefit.insert(e.name().to_string(), f);
        }
        cands.push(c);
    }
    Ok((cands, prefit))
}

/// One effect's likelihood ratio ([`likelihood_ratio_tests`]): its candidate, and its fit where
/// one was made.
fn likelihood_ratio(
    d: Diagnosing,
    base: &Fit,
    model: &Model,
    e: &'static dyn Effect,
    clock: &Clock,
) -> Result<(Candidate, Option<Fit>), MeasureError> {
    let (data, fit, opts) = (d.c.data, d.fit, d.opts);
    let labelled = FitOptions { progress: d.c.opts.progress.labelled(e.name()), ..d.c.opts.clone() };
    let c = &d.c.with_opts(&labelled);
    let m = data.len();
    let fnames = fit_names(fit, e);
    let mut best: Option<Fit> = None;
    let mut screened: Option<f64> = None;
    // the model's own values are the base fit's when the fit stayed at its start
    let moved = base.values != base.start;
    for from in if fit.is_empty() || !moved { vec![&base.model] } else { vec![&base.model, model] } {
        if best.as_ref().is_some_and(|b| p_value(base.chi2 - b.chi2, e.params().len()) < opts.alpha) {
            break;
        }
        // a modulus's stand-in is the G or K of the model it starts from, which runs as that
        // model does
        let start = e.lr_start(&from.keys(&Covariates::default())?)?;
        let on = from.edited(&[e], &[]);
        let params = on.parameters(&fnames[fit.len()..])?;
        let with = on.edited(&[], &params.iter().zip(start).collect::<Vec<_>>());
        // the start's Jacobian, and the fit only where the effect reaches the data there and
        // one Gauss-Newton step from it predicts a drop worth fitting for: without influence
        // (G where every reading is past yield) the fit would only refit the fitted
        // parameters; from the model's values, where they are elsewhere, it may have
        clock.say(format!(
            "{}: its likelihood ratio, from {}",
            e.name(),
            if std::ptr::eq(from, model) { "the model's values" } else { "the base fit's values" }
        ));
        let start_values = beside_base(
            c,
            base,
            (std::ptr::eq(from, model), e.start_runs_as_model()),
            &with,
            &fnames[fit.len()..],
        )?;
        let no_steps = FitOptions { max_iterations: 0, log: false, ..c.opts.clone() };
        let at_start = calibrate_from(&c.with_opts(&no_steps), &with, &fnames, start_values.clone())?;
        let predicted = base.chi2 - at_start.chi2 + gauss_newton_drop(&at_start, data)?;
        let informed = at_start.influence[fit.len()..].iter().any(|&i| i);
        let (f, unfitted) = match !informed || predicted < LR_WORTH_FITTING {
            true => (at_start, Some(predicted)),
            false => (calibrate_from(c, &with, &fnames, start_values)?, None),
        };
        if best.as_ref().is_none_or(|b| f.chi2 < b.chi2) {
            best = Some(f);
            screened = unfitted;
        }
    }
    let f = best.expect("one start at least");
    // a drop within round-off is a fit that found nothing to move (no influence)
    let lr = if base.chi2 - f.chi2 > 1e-9 * base.chi2 { base.chi2 - f.chi2 } else { 0.0 };
    let dof = if lr > 0.0 { e.params().len() } else { 0 };
    let p = p_value(lr, dof);
    let reach = f.influence[fit.len()..].iter().any(|&i| i);
    let verdict = if dof == 0 && !reach {
        "no influence on these experiments".to_string()
    } else if let Some(lr) = screened.filter(|_| p >= opts.alpha) {
        format!("not significant: a Gauss-Newton step from its start predicts LR = {lr:.3}, under \
            {LR_WORTH_FITTING}; not fitted")
    } else if dof == 0 {
        "not significant: fitted, it does not lower the error".to_string()
    } else if p >= opts.alpha {
        format!("not significant (p = {p:.3})")
    } else {
        String::new()
    };
    let mut c = candidate(e, lr, dof, p, verdict);
    // a screened effect's start is no fit: nothing to report as fitted or to refit from
    if screened.is_some() {
        return Ok((c, None));
    }
    c.record(&f, base.chi2, m);
    Ok((c, Some(f)))
}

/// Fit the significant candidates, best first, up to `max_fitted` (a likelihood-ratio effect's
/// fit is already in `prefit`), and check each by leave-one-experiment-out; their verdicts set.
/// Returns each candidate's fitted model.
fn fit_and_check(
    d: Diagnosing,
    cands: &mut [Candidate],
    base: &Fit,
    (prefit, scored): (&mut std::collections::BTreeMap<String, Fit>, &ScoreTests),
    clock: &mut Clock,
) -> Result<Vec<Option<Model>>, MeasureError> {
    let (data, fit, opts) = (d.c.data, d.fit, d.opts);
    let m = data.len();
    let ids: Vec<String> = super::campaign::runner::group(data).into_iter().map(|(id, _)| id).collect();
    let mut base_loo: Option<f64> = None;
    // the recommended candidate with the least chi^2 + 2 k so far (set only by leave-one-out)
    let mut leader: Option<(String, f64)> = None;
    let mut models: Vec<Option<Model>> = vec![None; cands.len()];
    let mut fitted = 0;
    let progress = &d.c.opts.progress;
    // each candidate fitted: its fit, then its leave-one-out
    progress.plan(2 * cands.iter().filter(|c| c.verdict.is_empty()).count().min(opts.max_fitted));
    for (ci, c) in cands.iter_mut().enumerate() {
        if !c.verdict.is_empty() {
            continue;
        }
        if fitted == opts.max_fitted {
            let done =
                if prefit.contains_key(&c.effect) { "fitted, not checked by leave-one-out" } else { "not fitted" };
            c.verdict = format!("significant (p = {:.2e}), {done}: beyond the top {}", c.p_value, opts.max_fitted);
            continue;
        }
        fitted += 1;
        let effect = base.model.effect(&c.effect)?;
        let runs = if prefit.contains_key(&c.effect) { 0 } else { expected_runs(data, &fit_names(fit, effect)) };
        announce_fit(d, &c.effect, runs, clock);
        // after a recommended candidate, a fit made here needs its optimum first: only one that
        // comes close to the leader's Akaike criterion is finished on an exact Jacobian (below);
        // the others' would be 2 p runs of the campaign that nothing reads (a likelihood-ratio
        // fit, made before, is finished already)
        let lazy = leader.is_some() && !prefit.contains_key(&c.effect);
        let f = match prefit.remove(&c.effect) {
            Some(f) => f,
            None => fit_candidate(d, base, effect, scored, lazy)?,
        };
        let aic = |f: &Fit| f.chi2 + 2.0 * f.names.len() as f64;
        let f = match &leader {
            Some((name, best)) if lazy && f.chi2 < 0.99 * base.chi2 && aic(&f) < SCREENED_MARGIN * best => {
                clock.say(format!(
                    "{}: within {SCREENED_MARGIN} times {name}'s Akaike criterion; finished on an exact Jacobian",
                    c.effect
                ));
                finish(d.c, f)?
            }
            _ => f,
        };
        clock.timing.candidate_fits += clock.lap();
        progress.end();
        // one run of each experiment left out, and the base model's the first time
        progress
            .begin(&format!("{}: leave-one-out", c.effect), if base_loo.is_none() { 2 } else { 1 } * ids.len() as u64);
        c.record(&f, base.chi2, m);
        // a fit that moves the error by less than 1 % has not found anything, and is not
        // recommended whatever leaving experiments out would say
        let better = f.chi2 < 0.99 * base.chi2;
        // Akaike's criterion, which leave-one-out's choice follows asymptotically (Stone 1977):
        // a candidate that does not beat a recommended one's would not be chosen, and its
        // leave-one-out (a refit per experiment where the one-step check refuses) is not run
        let aic = aic(&f);
        let beaten = leader.as_ref().filter(|(_, best)| aic >= *best);
        if !better {
            c.verdict = "does not lower the error when fitted".to_string();
        } else if let Some((name, best)) = beaten {
            c.verdict = format!(
                "lowers the error (x {:.3}) but not chosen: chi^2 + 2 k {aic:.4e} against {name}'s {best:.4e} \
                    (Akaike), not checked by leave-one-out",
                c.error_ratio.unwrap_or(1.0)
            );
        } else if opts.leave_one_out && ids.len() >= 2 {
            // the base model's checks (the first time) and this candidate's are independent
            let checked: Vec<(&Fit, &str)> =
                if base_loo.is_none() { vec![(base, "the base model"), (&f, &c.effect)] } else { vec![(&f, &c.effect)] };
            let mut loos = d
                .c
                .opts
                .engine
                .side_by_side(checked.len(), |k| {
                    let labelled = FitOptions { progress: d.c.opts.progress.labelled(checked[k].1), ..d.c.opts.clone() };
                    leave_one_out(&d.c.with_opts(&labelled), checked[k].0, &ids, opts)
                })
                .into_iter();
            if base_loo.is_none() {
                base_loo = Some(loos.next().expect("checked")?);
            }
            let loo = loos.next().expect("checked")?;
            clock.timing.leave_one_out += clock.lap();
            c.loo_chi2_base = base_loo;
            c.loo_chi2 = Some(loo);
            c.recommended = loo < 0.9 * base_loo.expect("set");
            if c.recommended {
                leader = Some((c.effect.clone(), aic));
            }
            c.verdict = loo_verdict(c, loo / base_loo.expect("set").max(1e-300));
        } else {
            c.recommended = true;
            c.verdict = format!(
                "recommended: error x {:.3} (not checked by leave-one-out: {})",
                c.error_ratio.unwrap_or(1.0),
                if opts.leave_one_out { "one experiment only" } else { "switched off" }
            );
        }
        models[ci] = Some(f.model);
        progress.end();
    }
    Ok(models)
}

/// Says that `effect` is being fitted (then checked by leave-one-out, when the options ask) and
/// starts its progress bar of `runs` runs.
fn announce_fit(d: Diagnosing, effect: &str, runs: u64, clock: &mut Clock) {
    let _ = clock.lap();
    let then = if d.opts.leave_one_out { ", then checked by leaving each experiment out" } else { "" };
    clock.say(format!("{effect}: fitted{then}"));
    d.c.opts.progress.begin(&format!("{effect}: fit"), runs);
}

/// A fitted candidate's verdict after leave-one-out, its left-out error `ratio` times the base model's.
fn loo_verdict(c: &Candidate, ratio: f64) -> String {
    if c.recommended {
        format!("recommended: error x {:.3}, left-out error x {ratio:.3}", c.error_ratio.unwrap_or(1.0))
    } else {
        "overfits: it lowers the error but does not predict left-out experiments better".to_string()
    }
}

/// A fit made for its optimum only ([`FitOptions::uncertainties`] off, perhaps
/// [`stop_on_secant`](FitOptions::stop_on_secant) on: a candidate screened after a recommended
/// one), finished as the campaign's options ask: where its Jacobian at the end may be a secant
/// update, the engine's exact one there, and the fit taken on from it until that Jacobian's stop
/// holds (at once, where the secant fit had stopped at the optimum), so that its uncertainties,
/// and a leave-one-out step on its curvature, come from an exact Jacobian as a fit made with
/// uncertainties does. The fit keeps its start and history.
pub fn finish(c: &Campaign, f: Fit) -> Result<Fit, MeasureError> {
    if !(c.opts.uncertainties && !c.opts.stop_on_secant && c.on_secants()) {
        return Ok(f);
    }
    let exact = c.evaluate(&f.model, Some(&f.names), Some((&f.model_values, &Differences::Central)))??;
    let mut finished = calibrate_from(c, &f.model, &f.names, exact)?;
    finished.history = f.history.iter().chain(&finished.history[1..]).copied().collect();
    (finished.start, finished.chi2_start, finished.at_start) = (f.start, f.chi2_start, f.at_start);
    Ok(finished)
}

/// A candidate's fit with the base parameters, its effect from its null; `lazy`: for its optimum
/// only, on secant Jacobians ([`FitOptions::stop_on_secant`]).
fn fit_candidate(
    d: Diagnosing,
    base: &Fit,
    effect: &'static dyn Effect,
    scored: &ScoreTests,
    lazy: bool,
) -> Result<Fit, MeasureError> {
    let fit_opts =
        FitOptions { uncertainties: d.c.opts.uncertainties && !lazy, stop_on_secant: lazy, ..d.c.opts.clone() };
    let (c, fnames, with) = (d.c.with_opts(&fit_opts), fit_names(d.fit, effect), base.model.edited(&[effect], &[]));
    if scored.at_nulls.values != base.model_values {
        return calibrate_at(&c, &with, None, &fnames);
    }
    // from the score tests' Jacobian, taken where every absent effect is at its null, as this
    // one is here: the same runs, unless an effect at its null moved a value
    let own = &scored.columns.iter().find(|(e, _)| *e == effect.name()).expect("a score-tested effect").1;
    let cols: Vec<usize> = (0..d.fit.len()).chain(own.iter().copied()).collect();
    let pick = |m: &Option<Vec<Vec<f64>>>| {
        Some(m.as_ref().expect("asked").iter().map(|r| cols.iter().map(|&k| r[k]).collect()).collect())
    };
    let (jacobian, jacobian_scatter) = (pick(&scored.at_nulls.jacobian), pick(&scored.at_nulls.jacobian_scatter));
    calibrate_from(&c, &with, &fnames, Sensitivity { jacobian, jacobian_scatter, ..scored.at_nulls.clone() })
}

/// The shapes of the base fit's residuals against every covariate (`residuals.rs`).
fn residual_shapes(campaign: &Campaign, base: &Fit, alpha: f64) -> Result<Vec<self::residuals::Shape>, MeasureError> {
    let c = super::compare::comparison(campaign.data, &base.model_values);
    let covs = super::compare::report::covariates(&c.rows, campaign.exps, &base.model)?;
    Ok(self::residuals::shapes(&c.rows, &covs, alpha))
}

/// The verdict among the recommended candidates: the score ranks them, the fit decides. The one
/// that predicts left-out experiments best (lowest left-out chi^2; the lowest fitted chi^2 when
/// leave-one-out was not run) is chosen, and each other recommended one's verdict says why it was
/// not.
fn choose(cands: &mut [Candidate]) -> Option<usize> {
    let recommended: Vec<usize> = (0..cands.len()).filter(|&i| cands[i].recommended).collect();
    // leave-one-out is run for all or none of them; compare like with like
    let all_loo = recommended.iter().all(|&i| cands[i].loo_chi2.is_some());
    let key = |c: &Candidate| {
        if all_loo {
            c.loo_chi2.unwrap_or(f64::INFINITY)
        } else {
            c.fitted_chi2.unwrap_or(f64::INFINITY)
        }
    };
    let best =
        recommended.iter().copied().min_by(|&a, &b| key(&cands[a]).total_cmp(&key(&cands[b])).then(a.cmp(&b)))?;
    let (name, value) = (cands[best].effect.clone(), key(&cands[best]));
    let what = if all_loo { "left-out chi^2" } else { "fitted chi^2" };
    for &i in recommended.iter().filter(|&&i| i != best) {
        let c = &mut cands[i];
        c.verdict = format!("{}; not chosen: {what} {:.4e} against {name}'s {value:.4e}", c.verdict, key(c));
    }
    Some(best)
}

/// Whether `effect` can act on `model`'s keys and on every simulation experiment the data name,
/// each run with `model`'s `[material]`.
fn applicable(c: &Campaign, effect: &'static dyn Effect, model: &Model) -> Result<(), MeasureError> {
    let (data, exps) = (c.data, c.exps);
    model
        .edited(&[effect], &[])
        .keys(&Covariates::default())
        .map_err(|m| MeasureError::Effect(format!("in this model, {m}")))?;
    for (id, _) in super::campaign::runner::group(data) {
        if let Some(s) = exps.get(&id).and_then(|x| x.scenario.as_ref()) {
            let path = exps.base_dir.join(s);
            let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
            let mut doc: toml::Table = text.parse().map_err(toml_error(&path))?;
            doc.insert("material".into(), toml::Value::Table(model.material.clone()));
            effect.check_scenario(&doc).map_err(|m| MeasureError::Effect(format!("it {m} (experiment '{id}')")))?;
        }
    }
    Ok(())
}

/// Sum over experiments of the chi^2 of each one predicted by the fit `f` refitted without it.
///
/// By default the refit is one Gauss-Newton step from the full fit, on its own Jacobian with the
/// left-out experiment's rows taken out (bounds held as the fit held them, the step clamped to
/// them). The left-out experiment alone is run at the stepped parameters, which keeps the model's
/// nonlinearity in its chi^2, and that run checks the step as a trust region checks one: the step
/// stands when the left-out experiment's chi^2 moves from the full fit's by what the linearisation
/// that made the step predicts (within [`STEP_TRUST`] of the predicted move, or by less than
/// [`STEP_NEGLIGIBLE`] or the model's own scatter either way). A step the check refuses (leaving
/// one experiment out moves the fit far: an experiment that alone pins a parameter, correlated
/// parameters of a nonlinear effect), whose linearisation then fails for the experiment that moved
/// it, is replaced by a full refit started from the full fit. The check costs one run of each
/// experiment in all, against a calibration each for refits. With `exact_refits` every experiment
/// is left out of a full refit.
fn leave_one_out(c: &Campaign, f: &Fit, ids: &[String], opts: &DiagnoseOptions) -> Result<f64, MeasureError> {
    // each experiment's check is independent: a scheduler runs them together
    let each = c.opts.engine.side_by_side(ids.len(), |k| {
        let labelled = FitOptions { progress: c.opts.progress.labelled(&format!("without '{}'", ids[k])), ..c.opts.clone() };
        left_out(&c.with_opts(&labelled), f, &ids[k], opts)
    });
    each.into_iter().try_fold(0.0, |total, chi2| Ok(total + chi2?))
}

/// The chi^2 of experiment `id` predicted by the fit `f` refitted without it ([`leave_one_out`]).
fn left_out(c: &Campaign, f: &Fit, id: &str, opts: &DiagnoseOptions) -> Result<f64, MeasureError> {
    let data = c.data;
    let (kept, left): (Vec<usize>, Vec<usize>) = (0..data.len()).partition(|&i| data[i].experiment != id);
    let test = rows_of(data, &left);
    let predict = |model: &Model| -> Result<f64, MeasureError> {
        Ok(chi2(&c.with_data(&test).evaluate(model, None, None)??.values, &test))
    };
    if f.names.is_empty() {
        predict(&f.model)
    } else if opts.exact_refits {
        predict(&refit(c, f, &kept)?)
    } else {
        let step = one_step_without(f, data, (&kept, &left))?;
        let left_out = predict(&step.model)?;
        if step.trusted(left_out) {
            Ok(left_out)
        } else {
            predict(&refit(c, f, &kept)?)
        }
    }
}

/// `f` refitted to the observations `kept` of its data, from its own values and Jacobian there;
/// only the optimum counts ([`FitOptions::uncertainties`] off).
fn refit(c: &Campaign, f: &Fit, kept: &[usize]) -> Result<Model, MeasureError> {
    let (opts, rows) = (FitOptions { uncertainties: false, ..c.opts.clone() }, rows_of(c.data, kept));
    Ok(calibrate_from(&c.with_data(&rows).with_opts(&opts), &f.model, &f.names, at_end(f, kept))?.model)
}

/// The values and Jacobian at the end of fit `f`, for the observations `rows` (indices into its
/// data): where a fit of a subset of the data starts from `f`.
fn at_end(f: &Fit, rows: &[usize]) -> Sensitivity {
    Sensitivity {
        values: rows.iter().map(|&i| f.model_values[i]).collect(),
        jacobian: Some(rows.iter().map(|&i| f.jacobian[i].clone()).collect()),
        scatter: rows.iter().map(|&i| f.scatter[i]).collect(),
        jacobian_scatter: Some(rows.iter().map(|&i| f.jacobian_scatter[i].clone()).collect()),
    }
}

/// The observations `rows` (indices into `data`), in their order.
fn rows_of(data: &[Observation], rows: &[usize]) -> Vec<Observation> {
    rows.iter().map(|&i| data[i].clone()).collect()
}

/// A step stands when the left-out experiment's chi^2 moves by its predicted move within this
/// fraction of it: the trust-region ratio within 1 -/+ 0.25.
const STEP_TRUST: f64 = 0.25;
/// A change of chi^2 smaller than this, or than the left-out experiment's chi^2 scatter where the
/// model is rough, is no change: a step that moves the left-out experiment's chi^2 by less,
/// actual or predicted, stands.
const STEP_NEGLIGIBLE: f64 = 0.1;

/// One Gauss-Newton step without an experiment, and the left-out experiment's chi^2 at the full
/// fit and as the step's linearisation predicts it.
struct Step {
    model: Model,
    chi2_left_out: f64,
    chi2_predicted: f64,
    /// The scatter of a difference of two of the left-out experiment's chi^2 where the model is
    /// rough ([`chi2_scatter`]): a move within it is no move.
    chi2_scatter: f64,
}

impl Step {
    /// Whether the step stands, given the left-out experiment's chi^2 run at it.
    fn trusted(&self, chi2_actual: f64) -> bool {
        let predicted = self.chi2_predicted - self.chi2_left_out;
        let actual = chi2_actual - self.chi2_left_out;
        (actual - predicted).abs() <= STEP_TRUST * predicted.abs() + STEP_NEGLIGIBLE.max(self.chi2_scatter)
    }
}

/// The fit `f` moved by one Gauss-Newton step on the chi^2 of the observations `kept` (indices
/// into `data`), from `f`'s own values and Jacobian, with the left-out experiment's observations
/// `left`.
fn one_step_without(f: &Fit, data: &[Observation], (kept, left): (&[usize], &[usize])) -> Result<Step, MeasureError> {
    let params = f.model.parameters(&f.names)?;
    let bounds: Vec<_> = params.iter().map(|p| p.bounds).collect();
    let scale: Vec<f64> = bounds.iter().map(|b| b.scale).collect();
    let (z, jz) = standardised(&f.model_values, &f.jacobian, data, &scale);
    let pick = |rows: &[usize]| {
        (rows.iter().map(|&i| z[i]).collect::<Vec<f64>>(), rows.iter().map(|&i| jz[i].clone()).collect::<Vec<_>>())
    };
    let (z_kept, jz_kept) = pick(kept);
    let cols: Vec<usize> = (0..f.names.len()).filter(|&i| !f.at_bound[i]).collect();
    let (a, g) = normal_equations(&jz_kept, &z_kept, &cols);
    let step = gauss_newton_step(&a, &g, 1e-12);
    // the step taken in scaled parameters, after the clamp to the bounds
    let mut taken = vec![0.0; f.names.len()];
    let mut stepped = Vec::with_capacity(cols.len());
    for (k, &i) in cols.iter().enumerate() {
        let value = (f.values[i] + step[k] * scale[i]).clamp(bounds[i].lower, bounds[i].upper);
        taken[i] = (value - f.values[i]) / scale[i];
        stepped.push((&params[i], value));
    }
    let model = f.model.edited(&[], &stepped);
    let (z_left, jz_left) = pick(left);
    let linear: f64 = z_left
        .iter()
        .zip(&jz_left)
        .map(|(zi, row)| (zi + row.iter().zip(&taken).map(|(j, t)| j * t).sum::<f64>()).powi(2))
        .sum();
    let scatter: Vec<f64> = left.iter().map(|&i| f.scatter[i]).collect();
    let chi2_scatter = chi2_scatter(&z_left, &scatter, &rows_of(data, left));
    Ok(Step { model, chi2_left_out: z_left.iter().map(|zi| zi * zi).sum(), chi2_predicted: linear, chi2_scatter })
}

/// Where an unexplained misfit lies: the largest residuals and the observables worst fitted
/// (its shapes are [`Diagnosis::shapes`]).
fn largest_residuals(base: &Fit, data: &[Observation]) -> Vec<String> {
    let c = super::compare::comparison(data, &base.model_values);
    let mut out = Vec::new();
    let mut worst: Vec<&super::compare::Row> = c.rows.iter().collect();
    worst.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    for r in worst.iter().take(3) {
        out.push(format!(
            "largest residual: {} {}: z = {:.2} ({}-predicted by {:.2} %)",
            r.experiment,
            r.label(),
            r.z,
            if r.residual > 0.0 { "over" } else { "under" },
            100.0 * (r.residual / r.measured).abs()
        ));
    }
    for s in &c.by_observable {
        out.push(format!("observable {}: rms z = {:.2} over {}", s.name, s.rms_z, s.n));
    }
    out
}

/// The diagnosis as text.
pub fn report(d: &Diagnosis) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "base model: chi^2 = {:.4e} over {} observations (rms z {:.3}, p = {:.3e}), fitted: {}",
        d.base_chi2,
        d.observations,
        d.base_rms_z,
        d.base_p_value,
        if d.fit.is_empty() { "nothing".into() } else { d.fit.join(", ") }
    );
    for (n, v) in &d.base_values {
        let _ = writeln!(s, "  {n} = {v:.6e}");
    }
    let _ = writeln!(
        s,
        "\n{:<4} {:<17} {:<5} {:>12} {:>4} {:>10} {:>12} {:>12}  verdict",
        "rank", "effect", "test", "statistic", "dof", "p", "error ratio", "left-out"
    );
    for c in &d.candidates {
        let er = c.error_ratio.map_or("-".into(), |v| format!("{v:.3}"));
        let loo = match (c.loo_chi2, c.loo_chi2_base) {
            (Some(a), Some(b)) => format!("{:.3}", a / b.max(1e-300)),
            _ => "-".into(),
        };
        let test = if c.test == "score" { "score" } else { "LR" };
        let _ = writeln!(
            s,
            "{:<4} {:<17} {:<5} {:>12.4e} {:>4} {:>10.3e} {:>12} {:>12}  {}",
            c.rank, c.effect, test, c.score, c.dof, c.p_value, er, loo, c.verdict
        );
        if !c.fitted.is_empty() {
            let fitted: Vec<String> = c.fitted.iter().map(|(n, v)| format!("{n} = {v:.4e}")).collect();
            let _ = writeln!(s, "     fitted: {}", fitted.join(", "));
        }
    }
    if d.candidates.iter().any(|c| c.test != "score") {
        let _ =
            writeln!(s, "(LR: likelihood ratio chi^2_base - chi^2_fitted, for an effect whose null lies at infinity)");
    }
    let _ = writeln!(
        s,
        "\nverdict: {}",
        match d.verdict.as_str() {
            "unexplained" =>
                "unexplained: the base model does not fit and no effect in the library explains the residuals"
                    .to_string(),
            "explained" => "explained: the base model fits within the uncertainties; no effect is needed".to_string(),
            v => v.to_string(),
        }
    );
    for p in &d.pattern {
        let _ = writeln!(s, "  {p}");
    }
    let t = &d.timing;
    let _ = writeln!(s, "\ntime: base fit {:.1} s, score tests {:.1} s, likelihood-ratio fits {:.1} s, candidates' \
        fits {:.1} s, leave-one-out {:.1} \
        s", t.base_fit, t.score_tests, t.likelihood_ratio_fits, t.candidate_fits, t.leave_one_out);
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::effects;
    use super::super::campaign::experiments::Experiments;

    #[test]
    fn an_effect_whose_null_the_solver_cannot_run_gets_the_likelihood_ratio_and_the_others_the_score() {
        for e in effects::REGISTRY {
            let want = if ["elasticity", "compressibility", "wall_friction"].contains(&e.name()) {
                "likelihood-ratio"
            } else {
                "score"
            };
            assert_eq!(test_of(*e), want, "{}", e.name());
            // a likelihood-ratio fit starts where the solver runs; a score test at the null
            let start = e
                .lr_start(
                    &[("material.shear_modulus".to_string(), 4e5), ("material.bulk_modulus".to_string(), 1e6)]
                        .into_iter()
                        .collect(),
                )
                .unwrap();
            assert!(start.iter().all(|v| v.is_finite()), "{}: {start:?}", e.name());
        }
        // the halved tail for one parameter at its bound, the full one for more, none without
        assert!((p_value(3.841458820694124, 1) - 0.025).abs() < 1e-9);
        assert!((p_value(5.991464547107979, 2) - 0.05).abs() < 1e-9);
        assert_eq!(p_value(10.0, 0), 1.0);
    }

    /// A diagnosis of the rheometer campaign with hidden thixotropy gives the same result with
    /// progress events as without, and the events are well-formed and monotone over every stage.
    #[test]
    fn a_diagnosis_with_progress_events_is_the_diagnosis_without() {
        use super::super::campaign::progress::tests::{check_monotone, Shared};
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/campaign");
        let (truth, start) =
            (Model::load(&dir.join("truth_thixotropy.toml")).unwrap(), Model::load(&dir.join("base.toml")).unwrap());
        let exps = Experiments::load(&dir.join("experiments.toml")).unwrap();
        let data = super::super::compare::synth::synth(&truth, &exps, 0.01, 7, 1).unwrap();
        let fit = vec!["material.yield_stress".to_string(), "material.viscosity".to_string()];
        let out = Shared::default();
        let with = FitOptions { progress: out.progress(0), ..FitOptions::default() };
        let a = diagnose(&Campaign::new(&exps, &data, &with), &start, &fit, &DiagnoseOptions::default()).unwrap();
        let b =
            diagnose(&Campaign::new(&exps, &data, &FitOptions::default()), &start, &fit, &DiagnoseOptions::default())
                .unwrap();
        let json = |d: &Diagnosis| {
            let mut v = serde_json::to_value(d).unwrap();
            v.as_object_mut().unwrap().remove("timing");
            v.to_string()
        };
        assert_eq!(json(&a), json(&b));
        let events = out.events();
        check_monotone(&events);
        for stage in
            ["base fit", "score tests", "likelihood-ratio fits", "thixotropy: fit", "thixotropy: leave-one-out"]
        {
            assert!(events.iter().any(|e| e.stage == stage), "{stage}: {events:?}");
        }
    }
}
