//! The model's discretisation error, estimated and counted (issue 26 item 3).
//!
//! A simulated observable depends on the cell size: case 1's strand is 54.1 mm wide at 2.5 mm
//! cells and 49.2 mm at 1 mm. Measured to a caliper's 2 %, that difference would be blamed on a
//! physical effect. The experiments file's `[resolution]` table names a finer run of every
//! simulation experiment:
//!
//! ```toml
//! [resolution]
//! fine = { "simulation.dx" = 0.002 }   # scenario keys of the finer run (dx required)
//! order = 1.0                          # order of convergence p; default DEFAULT_ORDER
//! ```
//!
//! Each experiment runs at the model's cell size h (value f_h) and at the finer one h / r
//! (f_{h/r}, the `fine` keys set after the experiment's own `set`). With f(h) = f_0 + C h^p, the
//! Richardson extrapolation is f_0 = f_{h/r} + (f_{h/r} - f_h) / (r^p - 1), and the model's
//! discretisation error at its own cell size is e = f_h - f_0 = (f_h - f_{h/r}) r^p / (r^p - 1).
//! compare, calibrate and diagnose add |e| in quadrature to the measurement's uncertainty,
//! sigma = sqrt(u^2 + e^2), so z, chi^2, the fit's weights and diagnose's tests count only what
//! the cell size cannot explain. A rheometer test is one material point, with no cells: no error.
//!
//! When: once, at the model compare, calibrate or diagnose starts from, not per iteration. The
//! error is a property of the discretised flow that moves slowly with the material parameters
//! (it is the difference of two runs of the same flow), while the finer run costs r^4 times the
//! model's (r^3 more particles, r more steps): per iteration it would dominate the loop.
//! Held fixed, the weights keep chi^2 one function of the parameters, so Levenberg-Marquardt's
//! accepted steps, the score tests and the likelihood ratios all compare like with like. After a
//! calibration has moved the parameters far, compare or diagnose from the calibrated model
//! estimates it afresh there.
//!
//! The default order, [`DEFAULT_ORDER`], is measured on case 1 (BENCHMARKS.md,
//! "Discretisation error").

use crate::measure::error::MeasureError;
use super::experiments::{Experiment, Experiments, ResolutionTable};
use crate::measure::observation::{Observable, Observation};
use super::runner::{evaluate, find, group, job_threads, par_map_experiments, ungroup, Applied, Jobs};
use crate::measure::model::Model;

/// The order of convergence p assumed when `[resolution]` gives none: case 1's width at 8, 10
/// and 25 cells per nozzle diameter converges at p = 0.78 (BENCHMARKS.md, "Discretisation
/// error"); its height and area, and the width at coarser cells, are not monotonic there. A
/// lower p counts more of a difference as error (r^p / (r^p - 1)), so the measured order rounded
/// down errs on the side of a larger error.
pub const DEFAULT_ORDER: f64 = 0.75;

/// A Richardson extrapolation from two cell sizes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Richardson {
    /// f_0, the value at zero cell size.
    pub extrapolated: f64,
    /// f_h - f_0: the coarse value's discretisation error.
    pub error: f64,
}

/// f_0 and the coarse value's error from `coarse` = f(h) and `fine` = f(h / ratio), assuming
/// f(h) = f_0 + C h^order.
pub fn richardson(coarse: f64, fine: f64, ratio: f64, order: f64) -> Richardson {
    let gain = ratio.powf(order);
    let extrapolated = fine + (fine - coarse) / (gain - 1.0);
    Richardson { extrapolated, error: coarse - extrapolated }
}

/// One observation's discretisation error.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Estimate {
    pub experiment: String,
    /// As in the data: `name`, `name@X` or `name@X:Y`.
    pub observable: String,
    /// The model's cell size and the finer run's [m].
    pub dx: f64,
    pub fine_dx: f64,
    pub order: f64,
    /// The model's value at dx, at fine_dx, and extrapolated to zero cell size.
    pub value: f64,
    pub fine: f64,
    pub extrapolated: f64,
    /// value - extrapolated.
    pub error: f64,
}

/// The order the table gives, or the default.
pub fn order(table: &ResolutionTable) -> f64 {
    table.order.unwrap_or(DEFAULT_ORDER)
}

/// Experiment `x` with the finer run's keys set after its own.
fn finer(x: &Experiment, table: &ResolutionTable) -> Experiment {
    let mut x = x.clone();
    for (k, v) in &table.fine {
        x.set.insert(k.clone(), v.clone());
    }
    x
}

/// The cell size experiment `x` runs at under `model`.
fn cell_size(model: &Model, exps: &Experiments, x: &Experiment) -> Result<f64, MeasureError> {
    let path = exps.base_dir.join(x.scenario.as_ref().expect("a simulation"));
    Ok(Applied::new(model, x)?.scenario(&path)?.simulation.dx)
}

/// Each observation's discretisation error under `model` (None for a rheometer test), from the
/// experiments' `[resolution]` table; None without one. `values`, when given, are the model's
/// values of `data` already computed (compare's), which spares the runs at the model's cell size.
pub fn estimate(
    model: &Model,
    data: &[Observation],
    exps: &Experiments,
    values: Option<&[f64]>,
    jobs: usize,
) -> Result<Option<Vec<Option<Estimate>>>, MeasureError> {
    let Some(table) = &exps.resolution else { return Ok(None) };
    let p = order(table);
    let wanted = group(data);
    let given: Option<Vec<Vec<f64>>> = values.map(|v| per_experiment(data, &wanted, v));
    let threads = job_threads(jobs, wanted.len());
    let per = par_map_experiments(&wanted, jobs, |k, spare| -> Result<Vec<Option<Estimate>>, MeasureError> {
        let (id, obs) = &wanted[k];
        let x = find(exps, id)?;
        if x.scenario.is_none() {
            return Ok(vec![None; obs.len()]);
        }
        let fine_x = finer(x, table);
        let (dx, fine_dx) = (cell_size(model, exps, x)?, cell_size(model, exps, &fine_x)?);
        if fine_dx >= dx {
            return Err(MeasureError::Resolution(format!("experiment '{id}': [resolution] fine.\"simulation.dx\" = \
                {fine_dx} is not finer than the cell size the model runs it at, {dx}")));
        }
        // the two runs side by side where the campaign has a spare worker, the longer first
        let runs: Vec<&Experiment> = if given.is_some() { vec![&fine_x] } else { vec![&fine_x, x] };
        let mut ran = spare.map(runs.len(), |i| evaluate(model, exps, runs[i], obs, threads));
        let coarse = match &given {
            Some(v) => v[k].clone(),
            None => ran.pop().expect("ran")?,
        };
        let fine = ran.pop().expect("ran").map_err(|e| MeasureError::FinerRun(Box::new(e)))?;
        obs.iter()
            .zip(coarse.iter().zip(&fine))
            .map(|(o, (&c, &f))| {
                if !(c.is_finite() && f.is_finite()) {
                    return Err(MeasureError::Resolution(format!("experiment '{id}': {o} is {c} at dx = {dx} and {f} at \
                        dx = {fine_dx}: no discretisation error can be estimated")));
                }
                let r = richardson(c, f, dx / fine_dx, p);
                Ok(Some(Estimate {
                    experiment: id.clone(),
                    observable: o.to_string(),
                    dx,
                    fine_dx,
                    order: p,
                    value: c,
                    fine: f,
                    extrapolated: r.extrapolated,
                    error: r.error,
                }))
            })
            .collect()
    })?;
    Ok(Some(ungroup(data, &wanted, &per)))
}

/// `values` (in the data's order) regrouped by experiment, in `wanted`'s order.
fn per_experiment(data: &[Observation], wanted: &[(String, Vec<Observable>)], values: &[f64]) -> Vec<Vec<f64>> {
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); wanted.len()];
    for (o, v) in data.iter().zip(values) {
        let k = wanted.iter().position(|(id, _)| *id == o.experiment).expect("grouped");
        per[k].push(*v);
    }
    per
}

/// The errors alone, one per observation (None where there is none).
pub fn errors(estimates: &[Option<Estimate>]) -> Vec<Option<f64>> {
    estimates.iter().map(|e| e.as_ref().map(|e| e.error)).collect()
}

/// The data with each discretisation error added in quadrature to its uncertainty: what
/// calibrate and diagnose fit, so that their chi^2 counts only what the cell size cannot explain.
pub fn counted(data: &[Observation], estimates: &[Option<Estimate>]) -> Vec<Observation> {
    data.iter()
        .zip(estimates)
        .map(|(o, e)| {
            let mut o = o.clone();
            if let Some(e) = e {
                o.uncertainty = o.uncertainty.hypot(e.error);
            }
            o
        })
        .collect()
}

/// The data as measured, their discretisation errors, and the start model's values of them (as
/// a fit runs them: [`counted_data`]).
pub struct Counted {
    pub data: Vec<Observation>,
    pub estimates: Vec<Option<Estimate>>,
    pub start_values: Vec<f64>,
}

/// What calibrate and diagnose fit: `data` with the discretisation errors at `model` counted
/// ([`counted`]), and what was counted; `data` unchanged without `[resolution]`. The model's own
/// runs are a fit's (fixed step, every particle awake: [`evaluate`](super::sensitivity::evaluate)), so
/// the fit from this model takes their values as its start's.
pub fn counted_data(
    model: &Model,
    data: Vec<Observation>,
    exps: &Experiments,
    jobs: usize,
) -> Result<(Vec<Observation>, Option<Counted>), MeasureError> {
    if exps.resolution.is_none() {
        return Ok((data, None));
    }
    let start_values = super::sensitivity::evaluate(model, &data, exps, (None, Jobs::new(jobs)), None)?.values;
    let estimates = estimate(model, &data, exps, Some(&start_values), jobs)?.expect("a [resolution] table");
    Ok((counted(&data, &estimates), Some(Counted { data, estimates, start_values })))
}

/// The warning calibrate and diagnose give once when print experiments run without a
/// `[resolution]` table: a printed section's cell-size error is then not counted, and a fit or
/// a diagnosis reads it as the material's (on six lines at 2.5 mm cells against 2 mm data, the
/// true material alone misses by rms z 8.2 under 2 % noise). None when there is nothing to say.
pub fn uncounted_warning(prints: &[String], exps: &Experiments) -> Option<String> {
    if prints.is_empty() || exps.resolution.is_some() {
        return None;
    }
    Some(format!(
        "warning: the print experiments ({}) run without a [resolution] table, so the cell size's discretisation error \
         is not counted: a misfit it causes is read as the material's. Count it with a finer run of every experiment \
         in the experiments file, e.g. [resolution] fine = {{ \"simulation.dx\" = <a finer cell> }} \
             (docs/discretisation.md)",
        prints.join(", ")
    ))
}

/// A command's JSON with the estimates added as `discretisation` (one entry per observation,
/// null for a rheometer test) when there are any.
pub fn with_estimates(mut v: serde_json::Value, counted: &Option<Counted>) -> Result<serde_json::Value, MeasureError> {
    if let Some(c) = counted {
        v["discretisation"] = serde_json::to_value(&c.estimates)?;
    }
    Ok(v)
}

/// The estimates beside z as text: for each observation the model's value at its cell size and at
/// the finer one, the extrapolation, the error, the measurement's uncertainty, and z without and
/// with the error counted, with `values` the model's (`what` names them: "start", "fitted").
pub fn report(data: &[Observation], estimates: &[Option<Estimate>], values: &[f64], what: &str) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let Some(first) = estimates.iter().flatten().next() else {
        return "discretisation: no simulation experiment in the data, nothing to estimate\n".into();
    };
    let _ = writeln!(
        s,
        "discretisation error (Richardson, order p = {}, cells {} m against {} m; estimated once, at the model given):",
        first.order, first.dx, first.fine_dx
    );
    let _ = writeln!(
        s,
        "{:<14} {:<22} {:>13} {:>13} {:>13} {:>13} {:>13} {:>9} {:>9}",
        "experiment", "observable", "model at dx", "finer", "extrapolated", "discretis.", "uncertainty", "z meas.", "z"
    );
    let (mut chi2_meas, mut chi2) = (0.0, 0.0);
    for ((o, e), v) in data.iter().zip(estimates).zip(values) {
        let residual = v - o.value;
        let z_meas = residual / o.uncertainty;
        let z = residual / o.uncertainty.hypot(e.as_ref().map_or(0.0, |e| e.error));
        chi2_meas += z_meas * z_meas;
        chi2 += z * z;
        let label = o.observable.to_string();
        match e {
            Some(e) => {
                let _ = writeln!(
                    s,
                    "{:<14} {:<22} {:>13.6e} {:>13.6e} {:>13.6e} {:>13.4e} {:>13.4e} {:>9.2} {:>9.2}",
                    o.experiment, label, e.value, e.fine, e.extrapolated, e.error, o.uncertainty, z_meas, z
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "{:<14} {:<22} {:>13} {:>13} {:>13} {:>13} {:>13.4e} {:>9.2} {:>9.2}",
                    o.experiment, label, "-", "-", "-", "none", o.uncertainty, z_meas, z
                );
            }
        }
    }
    let n = data.len().max(1) as f64;
    let _ = writeln!(s, "z at the {what} model: rms {:.3} against the measurement uncertainty alone, {:.3} with the \
        discretisation error counted (chi^2 {:.4e} -> \
        {:.4e})\n", (chi2_meas / n).sqrt(), (chi2 / n).sqrt(), chi2_meas, chi2);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(h) = f0 + C h^p (+ D h^q): a sequence with a known limit and order.
    fn sequence(f0: f64, c: f64, p: f64, d: f64, q: f64) -> impl Fn(f64) -> f64 {
        move |h: f64| f0 + c * h.powf(p) + d * h.powf(q)
    }

    #[test]
    fn richardson_recovers_the_limit_of_a_pure_power_law_of_the_right_order() {
        for (p, ratio) in [(1.0, 2.0), (2.0, 2.0), (1.0, 1.25), (1.5, 1.6), (0.7, 3.0)] {
            let f = sequence(49.2, 3.1, p, 0.0, 1.0);
            let h = 2.5e-3;
            let r = richardson(f(h), f(h / ratio), ratio, p);
            assert!((r.extrapolated - 49.2).abs() < 1e-9, "p {p} ratio {ratio}: {r:?}");
            assert!((r.error - 3.1 * h.powf(p)).abs() < 1e-9, "p {p} ratio {ratio}: {r:?}");
        }
        // a wrong order leaves an error in the limit, of the size the assumption makes it
        let f = sequence(1.0, 1.0, 2.0, 0.0, 1.0);
        let wrong = richardson(f(0.1), f(0.05), 2.0, 1.0);
        // (f = 1 + h^2 at h = 0.1 and 0.05 taken as first order: 2 f(h/2) - f(h) = 1 - h^2 / 2)
        assert!((wrong.extrapolated - (1.0 - 0.005)).abs() < 1e-12, "{wrong:?}");
    }

    #[test]
    fn with_a_higher_order_term_the_estimate_converges_at_the_next_order() {
        // f = f0 + C h + D h^2: the first-order estimate's limit is off by O(h^2), so halving h
        // quarters its error
        let f = sequence(10.0, 2.0, 1.0, 30.0, 2.0);
        let miss = |h: f64| (richardson(f(h), f(h / 2.0), 2.0, 1.0).extrapolated - 10.0).abs();
        let (a, b, c) = (miss(0.04), miss(0.02), miss(0.01));
        assert!(a > 0.0 && (a / b - 4.0).abs() < 1e-6 && (b / c - 4.0).abs() < 1e-6, "{a} {b} {c}");
        // and the error estimate approaches the true error at dx: 2h + 45h^2 against 2h + 30h^2,
        // off by 15h / (2 + 30h) relatively
        let off = |h: f64| richardson(f(h), f(h / 2.0), 2.0, 1.0).error / (f(h) - 10.0) - 1.0;
        for h in [0.04, 0.02, 0.01] {
            assert!((off(h) - 15.0 * h / (2.0 + 30.0 * h)).abs() < 1e-9, "{h}: {}", off(h));
        }
        assert!(off(0.01) < off(0.02) && off(0.02) < off(0.04));
    }

    #[test]
    fn errors_are_added_in_quadrature_and_rheometer_rows_keep_theirs() {
        let o = |u: f64| Observation {
            experiment: "a".into(),
            observable: Observable::parse("width@0.05").unwrap(),
            value: 0.03,
            uncertainty: u,
        };
        let e = Estimate {
            experiment: "a".into(),
            observable: "width@0.05".into(),
            dx: 2e-3,
            fine_dx: 1e-3,
            order: 1.0,
            value: 0.034,
            fine: 0.032,
            extrapolated: 0.030,
            error: 4e-4,
        };
        let data = vec![o(3e-4), o(1e-3)];
        let c = counted(&data, &[Some(e.clone()), None]);
        assert!((c[0].uncertainty - 5e-4).abs() < 1e-15, "{c:?}");
        assert_eq!(c[1].uncertainty, 1e-3);
        assert_eq!(errors(&[Some(e), None]), vec![Some(4e-4), None]);
    }
}
