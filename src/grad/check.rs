//! `strand grad --check`: the adjoint gradient against central differences at several step
//! sizes, and the Taylor remainder test, each from full forward runs of perturbed scenarios.

use super::driver::{forward_values_after, GradResult};
use crate::observables::Objective;
use super::GradError;
use super::params::with_value;
use crate::key::Key;
use crate::scenario::Scenario;

/// Default relative step sizes of the central differences (times |theta|, or absolute when
/// theta = 0).
pub const REL_STEPS: [f64; 3] = [1e-2, 1e-3, 1e-4];

/// Default steps h of the Taylor test (relative to every parameter at once).
pub const TAYLOR_STEPS: [f64; 5] = [1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5];

#[derive(Clone, Debug, serde::Serialize)]
pub struct ParamCheck {
    pub param: String,
    pub adjoint: f64,
    /// (step h, central difference, relative difference to the adjoint)
    pub central: Vec<(f64, f64, f64)>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Check {
    pub params: Vec<ParamCheck>,
    /// (h, |J(theta + h d) - J(theta) - h <dJ, d>|) along d = theta (a relative perturbation of
    /// every parameter at once; d = 1 for a parameter at 0).
    pub taylor: Vec<(f64, f64)>,
    /// Least-squares slope of log remainder against log h: 2 when the gradient is right.
    pub taylor_slope: f64,
    /// Wall seconds of the central differences' forward runs, and of the Taylor test's.
    pub central_s: f64,
    pub taylor_s: f64,
    pub central_runs: usize,
}

fn step_of(theta: f64, rel: f64) -> f64 {
    if theta != 0.0 {
        rel * theta.abs()
    } else {
        rel
    }
}

fn perturbed(sc: &Scenario, keys: &[String], values: &[f64]) -> Result<Scenario, GradError> {
    let mut text = sc.source.clone();
    for (k, v) in keys.iter().zip(values) {
        text = with_value(&text, &Key::parse(k).map_err(GradError::Param)?, *v)?;
    }
    let mut p = Scenario::parse(&text)?;
    p.base_dir = sc.base_dir.clone();
    Ok(p)
}

/// Central differences at the relative steps `rel_steps` for every parameter, then the Taylor test.
pub fn check(sc: &Scenario, objective: &Objective, r: &GradResult, threads: Option<usize>, rel_steps: &[f64]) -> Result<Check, GradError> {
    Ok(check_many(sc, std::slice::from_ref(objective), std::slice::from_ref(r), threads, rel_steps)?.remove(0))
}

/// [`check`] of several objectives of one gradient run (`results[k]` of `objectives[k]`, with
/// the same parameters at the same values): each perturbed forward run serves every objective,
/// each taken after its own result's steps, so the check costs what one objective's does.
pub fn check_many(sc: &Scenario, objectives: &[Objective], results: &[GradResult], threads: Option<usize>, rel_steps: &[f64]) -> Result<Vec<Check>, GradError> {
    check_many_with(sc, objectives, results, threads, rel_steps, &TAYLOR_STEPS)
}

/// [`check_many`] with the Taylor test at `taylor_steps` (a run whose discrete choices, such as
/// which units sleep, move under larger steps needs smaller ones).
pub fn check_many_with(
    sc: &Scenario,
    objectives: &[Objective],
    results: &[GradResult],
    threads: Option<usize>,
    rel_steps: &[f64],
    taylor_steps: &[f64],
) -> Result<Vec<Check>, GradError> {
    let Some(r) = results.first() else { return Ok(Vec::new()) };
    if objectives.len() != results.len() || results.iter().any(|o| o.params != r.params || o.values != r.values) {
        return Err(GradError::Objective("check: the results checked together must be of one run's parameters, one per objective".into()));
    }
    let steps: Vec<u64> = results.iter().map(|o| o.steps).collect();
    let values_at = |values: &[f64]| forward_values_after(&perturbed(sc, &r.params, values)?, objectives, &steps, threads);
    let t0 = std::time::Instant::now();
    // central[k][j]: parameter k's differences for objective j
    let mut central = vec![vec![Vec::new(); results.len()]; r.params.len()];
    for (k, per_objective) in central.iter_mut().enumerate() {
        for &rel in rel_steps {
            let h = step_of(r.values[k], rel);
            let mut plus = r.values.clone();
            plus[k] += h;
            let mut minus = r.values.clone();
            minus[k] -= h;
            let (up, down) = (values_at(&plus)?, values_at(&minus)?);
            for (j, o) in results.iter().enumerate() {
                let fd = (up[j] - down[j]) / (2.0 * h);
                let rel_err = if fd == o.gradient[k] { 0.0 } else { (fd - o.gradient[k]).abs() / fd.abs().max(o.gradient[k].abs()) };
                per_objective[j].push((h, fd, rel_err));
            }
        }
    }
    let central_s = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let d: Vec<f64> = r.values.iter().map(|&v| if v != 0.0 { v } else { 1.0 }).collect();
    let j0 = values_at(&r.values)?;
    let mut taylor = vec![Vec::new(); results.len()];
    for &h in taylor_steps {
        let at: Vec<f64> = r.values.iter().zip(&d).map(|(v, d)| v + h * d).collect();
        let jh = values_at(&at)?;
        for (j, o) in results.iter().enumerate() {
            let slope_dir: f64 = o.gradient.iter().zip(&d).map(|(g, d)| g * d).sum();
            taylor[j].push((h, (jh[j] - j0[j] - h * slope_dir).abs()));
        }
    }
    let taylor_s = t1.elapsed().as_secs_f64();
    Ok(results
        .iter()
        .zip(taylor)
        .enumerate()
        .map(|(j, (o, taylor))| Check {
            params: r.params.iter().enumerate().map(|(k, key)| ParamCheck { param: key.clone(), adjoint: o.gradient[k], central: central[k][j].clone() }).collect(),
            taylor_slope: log_slope(&taylor),
            taylor,
            central_s,
            taylor_s,
            central_runs: 2 * rel_steps.len() * r.params.len(),
        })
        .collect())
}

/// Least-squares slope of log y against log x.
pub fn log_slope(points: &[(f64, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> = points.iter().map(|&(x, y)| (x.ln(), y.max(f64::MIN_POSITIVE).ln())).collect();
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    sxy / sxx
}
