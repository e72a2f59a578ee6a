//! `strand grad --check`: the adjoint gradient against central differences at several step
//! sizes, and the Taylor remainder test, each from full forward runs of perturbed scenarios.

use super::driver::{forward_value, GradResult};
use super::objective::Objective;
use super::GradError;
use super::params::with_value;
use crate::scenario::Scenario;

/// Default relative step sizes of the central differences (times |theta|, or absolute when
/// theta = 0).
pub const REL_STEPS: [f64; 3] = [1e-2, 1e-3, 1e-4];

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
        text = with_value(&text, k, *v)?;
    }
    let mut p = Scenario::parse(&text)?;
    p.base_dir = sc.base_dir.clone();
    Ok(p)
}

/// Central differences at the relative steps `rel_steps` for every parameter, then the Taylor test.
pub fn check(sc: &Scenario, objective: &Objective, r: &GradResult, threads: Option<usize>, rel_steps: &[f64]) -> Result<Check, GradError> {
    let value_at = |values: &[f64]| forward_value(&perturbed(sc, &r.params, values)?, objective, threads, r.steps);
    let t0 = std::time::Instant::now();
    let mut params = Vec::new();
    for (k, key) in r.params.iter().enumerate() {
        let mut central = Vec::new();
        for &rel in rel_steps {
            let h = step_of(r.values[k], rel);
            let mut plus = r.values.clone();
            plus[k] += h;
            let mut minus = r.values.clone();
            minus[k] -= h;
            let fd = (value_at(&plus)? - value_at(&minus)?) / (2.0 * h);
            let rel_err = if fd == r.gradient[k] { 0.0 } else { (fd - r.gradient[k]).abs() / fd.abs().max(r.gradient[k].abs()) };
            central.push((h, fd, rel_err));
        }
        params.push(ParamCheck { param: key.clone(), adjoint: r.gradient[k], central });
    }
    let central_s = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let d: Vec<f64> = r.values.iter().map(|&v| if v != 0.0 { v } else { 1.0 }).collect();
    let slope_dir: f64 = r.gradient.iter().zip(&d).map(|(g, d)| g * d).sum();
    let j0 = value_at(&r.values)?;
    let mut taylor = Vec::new();
    for i in 0..5 {
        let h = 1e-3 / 2f64.powi(i);
        let at: Vec<f64> = r.values.iter().zip(&d).map(|(v, d)| v + h * d).collect();
        taylor.push((h, (value_at(&at)? - j0 - h * slope_dir).abs()));
    }
    Ok(Check {
        params,
        taylor_slope: log_slope(&taylor),
        taylor,
        central_s,
        taylor_s: t1.elapsed().as_secs_f64(),
        central_runs: 2 * rel_steps.len() * r.params.len(),
    })
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
