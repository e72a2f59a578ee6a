//! `strand calibrate`: a bounded Levenberg-Marquardt fit of named model parameters to
//! measurements, minimising chi^2 = sum ((model - measured) / uncertainty)^2 with the Jacobian
//! from the adjoints (`campaign/sensitivity.rs`).
//!
//! Where the campaign runs simulations, whose Jacobian costs 2 p forward runs (or an adjoint's
//! several) against one for the values, an accepted step updates the Jacobian by Broyden's
//! rank-one secant (the update that matches the step's change of values) instead of computing
//! it again; the engine computes it again where the secant fit stalls (a step refused, or a
//! stop that the Jacobian declares) and at the end, so the fit stops, and its uncertainties come,
//! from an exact Jacobian ([`FitOptions::secant`](crate::measure::campaign::FitOptions::secant)).
//!
//! Parameters move in units of their scale (an effect's typical magnitude, a material number's
//! starting value), so the damping treats them alike. A parameter at a bound whose Gauss-Newton
//! step would cross it is held there for the step (an active set). Uncertainties are the square
//! roots of the diagonal of (J^T J)^-1 of the standardised residuals at the optimum: with the
//! data's uncertainties taken as given (not rescaled by the reduced chi^2, which is reported
//! beside).

use crate::measure::campaign::Campaign;
use crate::measure::error::MeasureError;
use crate::measure::observation::Observation;
use super::linalg::{gauss_newton_step, normal_equations, pinv_sym, secant_update, Mat};
use crate::measure::model::{Bounds, Model, Parameter};
use crate::measure::campaign::sensitivity::{Differences, Sensitivity};

#[derive(Clone, Debug, serde::Serialize)]
pub struct Fit {
    pub names: Vec<String>,
    pub start: Vec<f64>,
    pub values: Vec<f64>,
    /// One standard deviation; NaN for a parameter held at a bound, infinity for one without
    /// influence.
    pub uncertainty: Vec<f64>,
    pub at_bound: Vec<bool>,
    /// Whether any observation depends on the parameter at the optimum (its Jacobian column is
    /// not all zero): a wall friction does not reach a rheometer test.
    pub influence: Vec<bool>,
    pub chi2_start: f64,
    pub chi2: f64,
    /// chi^2 / (observations - free parameters).
    pub reduced_chi2: f64,
    /// chi^2 after each accepted iteration (the first is the start).
    pub history: Vec<f64>,
    pub converged: bool,
    pub observations: usize,
    /// The model's value of every observation at the optimum.
    pub model_values: Vec<f64>,
    /// d model value / d parameter at the optimum (a row per observation; empty when nothing
    /// was fitted): the curvature a one-step leave-one-out refit takes.
    #[serde(skip)]
    pub jacobian: Vec<Vec<f64>>,
    /// Each model value's scatter at the optimum, and each Jacobian entry's
    /// ([`Sensitivity::scatter`], [`Sensitivity::jacobian_scatter`]).
    #[serde(skip)]
    pub scatter: Vec<f64>,
    #[serde(skip)]
    pub jacobian_scatter: Vec<Vec<f64>>,
    /// The values and Jacobian the fit started from: where a fit from the same start (a
    /// likelihood ratio's, with an effect that leaves the model as it is) need not compute them.
    #[serde(skip)]
    pub at_start: Sensitivity,
    #[serde(skip)]
    pub model: Model,
}

/// A fit ends when a step lowers chi^2, or one undamped Gauss-Newton step predicts it would lower
/// it, by less than this times the reduced chi^2 (at least 1): a parameter one standard deviation
/// from the optimum raises chi^2 by 1, the reduced chi^2 scaling that deviation where the model
/// misses the data by more than their uncertainty, so such a step moves the parameters by less
/// than a tenth of their uncertainty, and further iterations (a Jacobian each) change nothing a
/// user reads. Or by less than chi^2's own scatter ([`chi2_scatter`]), where the model's values
/// are rough: a drop under it is no more a drop than a rise of that size is a rise.
pub const CHI2_NEGLIGIBLE: f64 = 0.01;

/// Where an exact Jacobian's undamped Gauss-Newton step predicts chi^2 to fall by less than this
/// times the reduced chi^2 (at least 1), the optimum the linearisation sees lies within one
/// standard deviation, and a step the model refuses there ends the fit instead of being damped
/// and tried again: a smooth model refuses no step that close to its optimum, where the
/// linearisation holds, and a model that does is not smooth at that scale (a print's section is
/// sampled by particles), where more damped steps only trade one rough value for another, a run
/// of the campaign each.
pub const CHI2_ROUGH: f64 = 1.0;

/// The damping of a fit's first step, and of the first on each exact Jacobian computed after
/// secant steps: nearly undamped.
pub const DAMPING: f64 = 1e-3;

/// The trials a step on an exact Jacobian gets, the damping raised fourfold after each refused
/// one.
pub const TRIES: usize = 12;

/// [`TRIES`] where the campaign runs simulations, each trial a run of the campaign: a print's
/// observables are sampled by particles and a profile point near a strand's edge jumps, so a
/// Jacobian from differences over 3 % of each parameter can promise a fall that no step
/// delivers; a step the model refuses three times, the last about a fifth of the Gauss-Newton
/// step ([`SIMULATION_DAMPING`]), is not found by damping further, and the fit ends there.
pub const SIMULATION_TRIES: usize = 3;

/// The least damping after a trial refused where the campaign runs simulations: a damping of
/// lambda adds lambda A_kk to the normal matrix's diagonal, so at 1 the step is about half the
/// Gauss-Newton step along each well-determined direction, and at 4 (the next refusal) a fifth.
/// With only [`SIMULATION_TRIES`] trials, each must be a clearly shorter step than the last: the
/// fourfold raise from 1e-3 alone leaves the step as long, and a step too long for the model's
/// nonlinearity is refused three times.
pub const SIMULATION_DAMPING: f64 = 1.0;

/// The damping after a refused trial: fourfold, and at least [`SIMULATION_DAMPING`] where the
/// campaign runs simulations.
fn raised(lambda: f64, simulated: bool) -> f64 {
    let fourfold = lambda * 4.0;
    if simulated { fourfold.max(SIMULATION_DAMPING) } else { fourfold }
}

/// The standard deviation of the difference of chi^2 at two points of a rough model (two
/// trials, or a step's two ends, apart by more than the scale on which the roughness is
/// correlated): each value's scatter s_i ([`Sensitivity::scatter`]) moves chi^2 by
/// 2 z_i s_i / sigma_i to first order, independently, so each chi^2 scatters by
/// 2 sqrt(sum z_i^2 s_i^2 / sigma_i^2), and a difference of two by sqrt(2) times that. 0 for a
/// smooth model (no scatter estimated).
pub fn chi2_scatter(z: &[f64], scatter: &[f64], data: &[Observation]) -> f64 {
    let sum: f64 = z.iter().zip(scatter.iter().zip(data)).map(|(z, (s, o))| (z * s / o.uncertainty).powi(2)).sum();
    2.0 * (2.0 * sum).sqrt()
}

/// How many times the drop a Jacobian's own scatter promises on average
/// ([`promised_by_scatter`]) a Gauss-Newton step must promise to be worth a trial: that promise
/// is a sum of squares, one a free parameter; for two it is exponential, above twice its mean
/// one time in seven.
pub const UNFOUNDED: f64 = 2.0;

/// The drop an undamped Gauss-Newton step promises, on average, from the scatter of its
/// Jacobian's entries alone (`jacobian_scatter`, [`Sensitivity::jacobian_scatter`]) at the
/// optimum of a smooth model: the gradient g = J^T z then scatters by
/// var g_k = sum_i (z_i dJ_ik)^2 (in standardised, scaled units), and the step's promise
/// g^T A^+ g by sum_k (A^+)_kk var g_k. A difference over 3 % of two nearly collinear parameters
/// (a yield stress and a viscosity seen through a strand's width and height) can promise tens
/// where no step gives anything; 0 for an adjoint's Jacobian.
pub fn promised_by_scatter(
    a: &Mat,
    z: &[f64],
    jacobian_scatter: &[Vec<f64>],
    data: &[Observation],
    scale: &[f64],
    cols: &[usize],
) -> f64 {
    if cols.is_empty() {
        return 0.0;
    }
    let (inv, _) = pinv_sym(a, 1e-12);
    cols.iter()
        .enumerate()
        .map(|(k, &c)| {
            let var_g: f64 = z
                .iter()
                .zip(jacobian_scatter.iter().zip(data))
                .map(|(z, (r, o))| (z * r[c] * scale[c] / o.uncertainty).powi(2))
                .sum();
            inv[k][k] * var_g
        })
        .sum()
}

/// Sum of the squared standardised residuals of `values` against `data`.
pub fn chi2(values: &[f64], data: &[Observation]) -> f64 {
    values.iter().zip(data).map(|(v, o)| ((v - o.value) / o.uncertainty).powi(2)).sum()
}

/// Fit `names` of `model` to the campaign's data.
pub fn calibrate(c: &Campaign, model: &Model, names: &[String]) -> Result<Fit, MeasureError> {
    calibrate_at(c, model, None, names)
}

/// [`calibrate`] from a model whose values of the data may be known (`values`), as the engine
/// gives them (the discretisation error's runs at the model,
/// [`counted_data`](crate::measure::campaign::resolution::counted_data)): then the start's Jacobian runs only its
/// differences.
pub fn calibrate_at(
    c: &Campaign,
    model: &Model,
    values: Option<&[f64]>,
    names: &[String],
) -> Result<Fit, MeasureError> {
    check(model, names)?;
    let at_start = c.evaluate(model, Some(names), values.map(|v| (v, &Differences::Central)))??;
    calibrate_from(c, model, names, at_start)
}

/// [`calibrate`] from a start whose values and Jacobian in `names` are known: `at_start` is
/// what the engine gives at `model` (a fit's own, or its rows for a subset of its data).
pub fn calibrate_from(
    c: &Campaign,
    model: &Model,
    names: &[String],
    at_start: Sensitivity,
) -> Result<Fit, MeasureError> {
    let (params, start) = check(model, names)?;
    let first = at_start.clone();
    let c2 = chi2(&at_start.values, c.data);
    if c.opts.log {
        c.opts.progress.log(&format!("fit of {}: chi^2 = {c2:.6e} at the start", names.join(", ")));
    }
    let now = Accepted { theta: start.clone(), model: model.clone(), at: at_start, chi2: c2 };
    let mut fit = Fitting::new(c, names, &params, now);
    let converged = fit.iterate()?;
    fit.result(Started { start, chi2: c2, at: first }, converged)
}

/// Where a fit started: the parameters, chi^2, and the values and Jacobian there.
struct Started {
    start: Vec<f64>,
    chi2: f64,
    at: Sensitivity,
}

/// A fit under way: the campaign, the parameters fitted (their keys parsed once, with their
/// bounds and scales), the step it stands at, and the state of its iteration.
struct Fitting<'c, 'a> {
    campaign: &'c Campaign<'a>,
    names: &'c [String],
    params: &'c [Parameter],
    bounds: Vec<Bounds>,
    scale: Vec<f64>,
    now: Accepted,
    /// Whether `now.at`'s Jacobian is the engine's, not a secant update: a fit stops on an
    /// exact one.
    exact: bool,
    lambda: f64,
    free: Vec<bool>,
    history: Vec<f64>,
    simulated: bool,
    secant: bool,
    clock: std::time::Instant,
}

/// What one iteration found from the step a fit stands at: the free parameters' normal
/// equations, what a step must promise to be tried, and whether the optimum is within reach.
struct Outlook {
    a: Mat,
    g: Vec<f64>,
    cols: Vec<usize>,
    /// A step that lowers chi^2 by less is no step (module doc of [`CHI2_NEGLIGIBLE`]).
    negligible: f64,
    worth_a_try: f64,
    gauss_newton: f64,
    near: bool,
}

impl<'c, 'a> Fitting<'c, 'a> {
    fn new(campaign: &'c Campaign<'a>, names: &'c [String], params: &'c [Parameter], now: Accepted) -> Fitting<'c, 'a> {
        let bounds: Vec<Bounds> = params.iter().map(|p| p.bounds).collect();
        let scale: Vec<f64> = bounds.iter().map(|b| b.scale).collect();
        let n = names.len();
        let history = vec![now.chi2];
        let (simulated, secant) = (campaign.runs_simulations(), campaign.on_secants());
        let clock = std::time::Instant::now();
        Fitting {
            campaign,
            names,
            params,
            bounds,
            scale,
            now,
            exact: true,
            lambda: DAMPING,
            free: vec![true; n],
            history,
            simulated,
            secant,
            clock,
        }
    }

    /// The engine's exact Jacobian where the fit stands.
    fn exact_at(&self) -> Result<Sensitivity, MeasureError> {
        self.campaign.evaluate(&self.now.model, Some(self.names), Some((&self.now.at.values, &Differences::Central)))?
    }

    /// Steps until the fit converges (true) or reaches the iteration limit (false).
    fn iterate(&mut self) -> Result<bool, MeasureError> {
        let opts = self.campaign.opts;
        while self.history.len() <= opts.max_iterations {
            let o = self.outlook();
            let next = if o.gauss_newton < o.worth_a_try {
                None
            } else {
                // one try on a secant Jacobian, which is then computed again, and near the
                // optimum (a promise under twice what the scatter would make is near it)
                let tries = if !self.exact || o.near {
                    1
                } else if self.simulated {
                    SIMULATION_TRIES
                } else {
                    TRIES
                };
                self.damped_step(&o, tries)?
            };
            let Some(next) = next else {
                if self.exact || opts.stop_on_secant {
                    return Ok(true);
                }
                // a new Jacobian, whose first step is undamped: the damping a secant Jacobian's
                // refused trial raised was that Jacobian's
                self.now.at = self.exact_at()?;
                (self.exact, self.lambda) = (true, DAMPING);
                continue;
            };
            let drop = self.now.chi2 - next.chi2;
            let gain = drop / self.now.chi2.max(1e-300);
            (self.now, self.exact) = (next, !self.secant);
            let c2 = self.now.chi2;
            self.history.push(c2);
            if opts.log {
                let (lambda, secant) = (self.lambda, if self.exact { "" } else { ", secant Jacobian" });
                let (step, seconds) = (self.history.len() - 1, self.clock.elapsed().as_secs_f64());
                opts.progress.log(&format!(
                    "step {step}: chi^2 = {c2:.6e} (damping {lambda:.1e}{secant}, {seconds:.1} s into the fit)"
                ));
            }
            if gain < opts.tolerance || drop < o.negligible {
                // a negligible drop from a step near the optimum is the optimum: a rough model
                // accepts steps within its scatter as often as it refuses them, each a Jacobian
                if self.exact || o.near || !opts.uncertainties {
                    return Ok(true);
                }
                self.now.at = self.exact_at()?;
                (self.exact, self.lambda) = (true, DAMPING);
            }
        }
        Ok(false)
    }

    /// The free parameters and their normal equations where the fit stands, and what a step
    /// from there must promise.
    fn outlook(&mut self) -> Outlook {
        let (data, opts) = (self.campaign.data, self.campaign.opts);
        let (s, c2, m) = (&self.now.at, self.now.chi2, data.len());
        let (z, jz) = standardised(&s.values, s.jacobian.as_ref().expect("asked"), data, &self.scale);
        self.free = free_parameters(&jz, &z, &self.now.theta, &self.bounds);
        let cols: Vec<usize> = (0..self.names.len()).filter(|&i| self.free[i]).collect();
        let birge = (c2 / m.saturating_sub(cols.len()).max(1) as f64).max(1.0);
        let scatter = chi2_scatter(&z, &s.scatter, data);
        let negligible = (CHI2_NEGLIGIBLE * birge).max(scatter);
        let (a, g) = normal_equations(&jz, &z, &cols);
        let gauss_newton = if cols.is_empty() { 0.0 } else { predicted_drop(&a, &g) };
        let jacobian_scatter = s.jacobian_scatter.as_ref().expect("asked");
        let unfounded = UNFOUNDED * promised_by_scatter(&a, &z, jacobian_scatter, data, &self.scale, &cols);
        let worth_a_try = negligible.max(unfounded);
        if opts.log && self.exact {
            let predicts = format!("  exact Jacobian: an undamped step predicts chi^2 = {:.6e}", c2 - gauss_newton);
            if scatter > 0.0 {
                let promise = unfounded / UNFOUNDED;
                let why = format!("chi^2 scatters by {scatter:.3e}, the Jacobian's scatter promises {promise:.3e}");
                opts.progress.log(&format!("{predicts} (reduced chi^2 {birge:.3}; {why})"));
            } else if self.history.len() > 1 {
                opts.progress.log(&format!("{predicts} (reduced chi^2 {birge:.3})"));
            }
        }
        // the optimum within reach of one step: the undamped step, from an exact Jacobian,
        // promises less than the reduced chi^2 or twice what is worth a try
        let near = self.exact && gauss_newton < (CHI2_ROUGH * birge).max(2.0 * worth_a_try);
        Outlook { a, g, cols, negligible, worth_a_try, gauss_newton, near }
    }

    /// The fit as it ends: uncertainties from the undamped normal matrix at the optimum, on an
    /// exact Jacobian where the options ask for them.
    fn result(mut self, started: Started, converged: bool) -> Result<Fit, MeasureError> {
        if !self.exact && self.campaign.opts.uncertainties {
            self.now.at = self.exact_at()?;
        }
        let (data, n, m) = (self.campaign.data, self.names.len(), self.campaign.data.len());
        let (s, scale, free) = (self.now.at, &self.scale, &self.free);
        let (z, jz) = standardised(&s.values, s.jacobian.as_ref().expect("asked"), data, scale);
        let cols: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
        let (a, _) = normal_equations(&jz, &z, &cols);
        let (cov, _) = pinv_sym(&a, 1e-12);
        let influence: Vec<bool> = (0..n).map(|i| jz.iter().any(|r| r[i] != 0.0)).collect();
        let mut uncertainty = vec![f64::NAN; n];
        for (k, &i) in cols.iter().enumerate() {
            // the pseudo-inverse gives 0 where the data say nothing
            uncertainty[i] = if influence[i] { cov[k][k].sqrt() * scale[i] } else { f64::INFINITY };
        }
        let at_bound: Vec<bool> = (0..n).map(|i| !free[i]).collect();
        let dof = m.saturating_sub(cols.len()).max(1);
        let c2 = self.now.chi2;
        Ok(Fit {
            names: self.names.to_vec(),
            start: started.start,
            values: self.now.theta,
            uncertainty,
            at_bound,
            influence,
            chi2_start: started.chi2,
            chi2: c2,
            reduced_chi2: c2 / dof as f64,
            history: self.history,
            converged,
            observations: m,
            model_values: s.values.clone(),
            jacobian: s.jacobian.expect("asked"),
            scatter: s.scatter,
            jacobian_scatter: s.jacobian_scatter.expect("asked"),
            at_start: started.at,
            model: self.now.model,
        })
    }

    /// A Levenberg-Marquardt step from where the fit stands on the normal equations of the free
    /// parameters (`o`), the damping raised until a step lowers chi^2 (at most `tries` tries)
    /// and lowered after it; none when no step lowers it, or when the damping has left a step
    /// whose linearised drop is under what is worth a try. On secants the accepted step's
    /// Jacobian is the secant update of the last one, otherwise the engine's. A trial the model
    /// rejects (a material that will not build), or whose Jacobian run is rejected (a side of a
    /// central difference where a printed line breaks up), is a failed step; the engine failing
    /// to run it is an error.
    fn damped_step(&mut self, o: &Outlook, tries: usize) -> Result<Option<Accepted>, MeasureError> {
        let (c, opts) = (self.campaign, self.campaign.opts);
        let (theta, bounds) = (&self.now.theta, &self.bounds);
        for _ in 0..tries {
            let lambda = self.lambda;
            let mut damped: Mat = o.a.clone();
            for (k, row) in damped.iter_mut().enumerate() {
                row[k] += lambda * o.a[k][k].max(1e-12);
            }
            let step = gauss_newton_step(&damped, &o.g, 1e-14);
            let mut trial = theta.to_vec();
            for (k, &i) in o.cols.iter().enumerate() {
                trial[i] = (theta[i] + step[k] * bounds[i].scale).clamp(bounds[i].lower, bounds[i].upper);
            }
            let moved =
                trial.iter().zip(theta).zip(bounds).map(|((a, b), bd)| ((a - b) / bd.scale).abs()).fold(0.0, f64::max);
            // the drop the linearisation predicts for the step taken (after the clamp): once the
            // damping leaves less than a negligible one, no step worth a run remains
            let taken: Vec<f64> = o.cols.iter().map(|&i| (trial[i] - theta[i]) / bounds[i].scale).collect();
            let a_taken: Vec<f64> = o.a.iter().map(|r| r.iter().zip(&taken).map(|(x, t)| x * t).sum()).collect();
            let linear_drop =
                -taken.iter().zip(o.g.iter().zip(&a_taken)).map(|(t, (gi, at))| t * (2.0 * gi + at)).sum::<f64>();
            if moved < 1e-12 || linear_drop < o.worth_a_try {
                return Ok(None);
            }
            let values: Vec<(&Parameter, f64)> = self.params.iter().zip(trial.iter().copied()).collect();
            let tm = self.now.model.edited(&[], &values);
            let tv = match self.campaign.evaluate(&tm, None, None)? {
                Ok(t) => t.values,
                Err(e) => {
                    if opts.log {
                        let why = format!("damping {lambda:.1e}, the largest move {moved:.3} scales");
                        opts.progress.log(&format!("  trial refused: the model fails there ({e}; {why})"));
                    }
                    self.lambda = raised(lambda, self.simulated);
                    continue;
                }
            };
            let tc2 = chi2(&tv, c.data);
            if tc2.is_finite() && tc2 < self.now.chi2 {
                let Some(at_trial) = self.at_trial(&tm, (&trial, tv))? else {
                    self.lambda = raised(lambda, self.simulated);
                    continue;
                };
                self.lambda = (lambda / 3.0).max(1e-9);
                return Ok(Some(Accepted { theta: trial, model: tm, at: at_trial, chi2: tc2 }));
            }
            if opts.log {
                let predicted = self.now.chi2 - linear_drop;
                let why = format!("damping {lambda:.1e}, the largest move {moved:.3} scales");
                opts.progress.log(&format!("  trial refused: chi^2 = {tc2:.6e}, {predicted:.3e} predicted ({why})"));
            }
            self.lambda = raised(lambda, self.simulated);
        }
        Ok(None)
    }

    /// The values and Jacobian at an accepted trial `tm` (parameters `trial`, values `tv`): the
    /// secant update of the last Jacobian on secants, otherwise the engine's (none where its
    /// run is rejected).
    fn at_trial(&self, tm: &Model, (trial, tv): (&[f64], Vec<f64>)) -> Result<Option<Sensitivity>, MeasureError> {
        let at = &self.now.at;
        if self.secant {
            let jacobian = secant_update(
                at.jacobian.as_ref().expect("asked"),
                (&self.now.theta, trial),
                &self.scale,
                (&at.values, &tv),
            );
            // the scatter is the model's near here, as the last exact Jacobian estimated it
            let (scatter, jacobian_scatter) = (at.scatter.clone(), at.jacobian_scatter.clone());
            return Ok(Some(Sensitivity { values: tv, jacobian: Some(jacobian), scatter, jacobian_scatter }));
        }
        Ok(self.campaign.evaluate(tm, Some(self.names), Some((&tv, &Differences::Central)))?.ok())
    }
}

/// Which parameters move: one is held at its bound when the Gauss-Newton step of the others and
/// itself would take it past the bound (the step, not its own gradient: a parameter collinear
/// with another may lower the loss only moving with it).
fn free_parameters(jz: &[Vec<f64>], z: &[f64], theta: &[f64], bounds: &[Bounds]) -> Vec<bool> {
    let mut free = vec![true; theta.len()];
    loop {
        let cols: Vec<usize> = (0..theta.len()).filter(|&i| free[i]).collect();
        if cols.is_empty() {
            return free;
        }
        let (a, g) = normal_equations(jz, z, &cols);
        let step = gauss_newton_step(&a, &g, 1e-12);
        let out: Vec<usize> = cols
            .iter()
            .zip(&step)
            .filter(|&(&i, &d)| (theta[i] <= bounds[i].lower && d < 0.0) || (theta[i] >= bounds[i].upper && d > 0.0))
            .map(|(&i, _)| i)
            .collect();
        if out.is_empty() {
            return free;
        }
        for i in out {
            free[i] = false;
        }
    }
}


/// A step a fit accepted: the parameters, the model with them, its values and Jacobian there,
/// and chi^2.
struct Accepted {
    theta: Vec<f64>,
    model: Model,
    at: Sensitivity,
    chi2: f64,
}

/// chi^2's drop one undamped Gauss-Newton step predicts, g^T A^+ g, from the normal equations
/// (A, g) of the standardised residuals.
pub fn predicted_drop(a: &Mat, g: &[f64]) -> f64 {
    let (inv, _) = pinv_sym(a, 1e-12);
    g.iter().zip(&inv).map(|(gi, row)| gi * row.iter().zip(g).map(|(a, b)| a * b).sum::<f64>()).sum()
}

/// The parameters, their keys parsed once, and their starting values, checked: something to
/// fit, each start finite.
fn check(model: &Model, names: &[String]) -> Result<(Vec<Parameter>, Vec<f64>), MeasureError> {
    if names.is_empty() {
        return Err(MeasureError::Fit("nothing to fit: name the parameters (--fit P1,P2,...)".into()));
    }
    let params = model.parameters(names)?;
    let start: Vec<f64> = params.iter().map(|p| p.value).collect();
    if let Some((n, v)) = names.iter().zip(&start).find(|(_, v)| !v.is_finite()) {
        return Err(MeasureError::Fit(format!("{n} starts at {v}, its null at infinity, where there is no gradient to \
            move it by: give it a finite start in the model")));
    }
    Ok((params, start))
}

/// Standardised residuals z = (model - measured) / uncertainty and their Jacobian in scaled
/// parameters (columns times the scales).
pub fn standardised(
    values: &[f64],
    jac: &[Vec<f64>],
    data: &[Observation],
    scale: &[f64],
) -> (Vec<f64>, Vec<Vec<f64>>) {
    let z = values.iter().zip(data).map(|(v, o)| (v - o.value) / o.uncertainty).collect();
    let jz = jac
        .iter()
        .zip(data)
        .map(|(row, o)| row.iter().zip(scale).map(|(g, s)| g * s / o.uncertainty).collect())
        .collect();
    (z, jz)
}

/// The fit as text: parameters with their uncertainties, and chi^2 before and after.
pub fn report(f: &Fit) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "{:<26} {:>14} {:>14} {:>14}", "parameter", "start", "fitted", "+/- (1 sigma)");
    for i in 0..f.names.len() {
        let u = if f.at_bound[i] {
            "at bound".to_string()
        } else if !f.influence[i] {
            "no influence".to_string()
        } else {
            format!("{:.4e}", f.uncertainty[i])
        };
        let _ = writeln!(s, "{:<26} {:>14.6e} {:>14.6e} {:>14}", f.names[i], f.start[i], f.values[i], u);
    }
    let rms = |c: f64| (c / f.observations as f64).sqrt();
    let _ = writeln!(
        s,
        "\nchi^2: {:.6e} -> {:.6e} over {} observations (rms z {:.3} -> {:.3}; reduced chi^2 {:.3})",
        f.chi2_start,
        f.chi2,
        f.observations,
        rms(f.chi2_start),
        rms(f.chi2),
        f.reduced_chi2
    );
    let _ = writeln!(
        s,
        "{} after {} accepted steps",
        if f.converged { "converged" } else { "stopped at the iteration limit" },
        f.history.len() - 1
    );
    s
}

/// chi^2 against iteration, as a PNG.
pub fn plot_convergence(f: &Fit, path: &std::path::Path) -> Result<(), crate::output::plot::PlotError> {
    let pts: Vec<[f64; 2]> = f.history.iter().enumerate().map(|(i, c)| [i as f64, c.max(1e-300).log10()]).collect();
    crate::output::plot::plot_xy(
        path,
        "calibration: log10 chi^2 against accepted step",
        "accepted step",
        "log10 chi^2",
        &[("chi^2".to_string(), pts)],
        true,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::campaign::FitOptions;
    use crate::measure::campaign::experiments::Experiments;
    use crate::measure::observation::Observable;

    const MODEL: &str =
        "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";
    const EXPS: &str = "[[experiment]]\nid = \"flow\"\nobserve = [\"stress@40\", \"stress@20\", \"stress@5\"]\n\
        [experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [40.0, 20.0, 5.0]\nhold = \
        0.5\n";

    #[test]
    fn the_secant_update_maps_the_step_onto_the_change_and_keeps_the_rest() {
        // values v(p) = (p0^2 + p1, 3 p1), at p = (2, 1) with parameter scales (10, 0.5)
        let f = |p: &[f64]| vec![p[0] * p[0] + p[1], 3.0 * p[1]];
        let (from, to, scale) = ([2.0, 1.0], [2.5, 1.2], [10.0, 0.5]);
        let jac = vec![vec![4.0, 1.0], vec![0.0, 3.0]];
        let (v0, v1) = (f(&from), f(&to));
        let new = secant_update(&jac, (&from, &to), &scale, (&v0, &v1));
        let step = [to[0] - from[0], to[1] - from[1]];
        for (row, (a, b)) in new.iter().zip(v0.iter().zip(&v1)) {
            let mapped: f64 = row.iter().zip(&step).map(|(g, d)| g * d).sum();
            assert!((mapped - (b - a)).abs() < 1e-12, "{mapped} against {}", b - a);
        }
        // a direction orthogonal to the step in the scaled parameters is mapped as before
        let ds = [step[0] / scale[0], step[1] / scale[1]];
        let ortho = [-ds[1] * scale[0], ds[0] * scale[1]];
        for (old, row) in jac.iter().zip(&new) {
            let (a, b): (f64, f64) =
                (old.iter().zip(&ortho).map(|(g, d)| g * d).sum(), row.iter().zip(&ortho).map(|(g, d)| g * d).sum());
            assert!((a - b).abs() < 1e-12, "{a} against {b}");
        }
        // the second value is linear: its row was right and stays so
        assert!((new[1][0] - 0.0).abs() < 1e-12 && (new[1][1] - 3.0).abs() < 1e-12, "{:?}", new[1]);
    }

    /// At the optimum of a linear model (z orthogonal to the Jacobian's columns) a Jacobian
    /// whose entries scatter promises, on average over the scatter, the drop
    /// [`promised_by_scatter`] says, though no step lowers chi^2.
    #[test]
    fn a_scattered_jacobian_promises_what_promised_by_scatter_says() {
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = crate::measure::compare::synth::noise_source(3);
        let m = 40;
        let truth: Vec<Vec<f64>> =
            (0..m).map(|i| vec![1.0 + 0.1 * i as f64, 1.1 + 0.1 * i as f64 + 0.02 * (i % 3) as f64]).collect();
        // residuals at the optimum: the part of a draw the columns do not explain
        let draw: Vec<f64> = (0..m).map(|_| { let n: f64 = StandardNormal.sample(&mut rng); 3.0 * n }).collect();
        let (a, g) = normal_equations(&truth, &draw, &[0, 1]);
        let step = gauss_newton_step(&a, &g, 1e-14);
        let z: Vec<f64> = draw.iter().zip(&truth).map(|(d, r)| d + r[0] * step[0] + r[1] * step[1]).collect();
        let (_, g) = normal_equations(&truth, &z, &[0, 1]);
        assert!(g.iter().all(|g| g.abs() < 1e-9), "{g:?}");
        let data: Vec<Observation> = (0..m)
            .map(|_| Observation {
                experiment: "x".into(),
                observable: Observable::parse("width").unwrap(),
                value: 0.0,
                uncertainty: 1.0,
            })
            .collect();
        let jacobian_scatter = vec![vec![0.02, 0.03]; m];
        let (mut sum, mut said, draws) = (0.0, 0.0, 4000);
        for _ in 0..draws {
            let noisy: Vec<Vec<f64>> = truth
                .iter()
                .zip(&jacobian_scatter)
                .map(|(r, s)| {
                    r.iter()
                        .zip(s)
                        .map(|(v, s)| {
                            let n: f64 = StandardNormal.sample(&mut rng);
                            v + s * n
                        })
                        .collect()
                })
                .collect();
            let (a, g) = normal_equations(&noisy, &z, &[0, 1]);
            sum += predicted_drop(&a, &g);
            said += promised_by_scatter(&a, &z, &jacobian_scatter, &data, &[1.0, 1.0], &[0, 1]);
        }
        let (mean, said) = (sum / draws as f64, said / draws as f64);
        println!("promised {mean} on average, {said} said");
        assert!(mean > 1.0, "the scatter promises {mean}");
        assert!((mean / said - 1.0).abs() < 0.15, "promised {mean} on average, {said} said");
    }

    /// The Bingham flow curve's fit of yield stress and viscosity from a start off the truth.
    fn flow_curve_fit(opts: &FitOptions) -> Fit {
        let truth = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let e: Experiments = toml::from_str(EXPS).unwrap();
        let data = crate::measure::compare::synth::synth(&truth, &e, 0.0, 1, 1).unwrap();
        let data: Vec<Observation> = data.into_iter().map(|mut o| {
            o.uncertainty = 1.0;
            o
        }).collect();
        let mut start = truth.clone();
        start.set("material.yield_stress", 300.0).unwrap();
        start.set("material.viscosity", 20.0).unwrap();
        let names = vec!["material.yield_stress".to_string(), "material.viscosity".to_string()];
        calibrate(&Campaign::new(&e, &data, opts), &start, &names).unwrap()
    }

    /// Progress changes no bit of a fit, and its JSON events are well-formed and monotone.
    #[test]
    fn a_fit_with_progress_events_is_the_fit_without() {
        use crate::measure::campaign::progress::tests::{check_monotone, Shared};
        let out = Shared::default();
        let progress = out.progress(1);
        progress.begin("fit", 1);
        let with = flow_curve_fit(&FitOptions { progress: progress.clone(), log: true, ..FitOptions::default() });
        progress.end();
        let without = flow_curve_fit(&FitOptions::default());
        let bits = |f: &Fit| {
            [&f.values, &f.uncertainty, &f.history, &f.model_values]
                .map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        assert_eq!(bits(&with), bits(&without));
        assert_eq!(with.model.to_toml(), without.model.to_toml());
        let events = out.events();
        check_monotone(&events);
        // the start's Jacobian, the trials and the end's: more than one evaluation
        assert!(events.len() > 3 && events.iter().all(|e| e.stage == "fit"), "{events:?}");
    }

    #[test]
    fn a_bingham_flow_curve_fit_recovers_yield_stress_and_viscosity() {
        let f = flow_curve_fit(&FitOptions::default());
        assert!(f.chi2 < 1e-6 * f.chi2_start, "{}", report(&f));
        assert!((f.values[0] / 630.0 - 1.0).abs() < 1e-3 && (f.values[1] / 7.5 - 1.0).abs() < 1e-2, "{}", report(&f));
        // the history only falls
        assert!(f.history.windows(2).all(|w| w[1] < w[0]), "{:?}", f.history);
        // three readings, two parameters, unit uncertainties: sigma = sqrt(diag (A^T A)^-1)
        assert!(f.uncertainty.iter().all(|u| u.is_finite() && *u > 0.0), "{:?}", f.uncertainty);
    }
}
