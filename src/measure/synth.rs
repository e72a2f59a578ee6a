//! Measurements synthesised from a model (`strand synth`): every experiment's `observe` list run
//! under the model, each value with seeded noise, so a seed gives the same data anywhere.

use super::experiments::Experiments;
use super::model::Model;
use super::observation::{Observable, Observation};
use super::runner::evaluate_all;

/// Measurements of every experiment's `observe` list under `model`, each value times
/// (1 + noise N(0, 1)) from a seeded generator, with uncertainty noise |value| (at least 1e-6 of
/// it, so z-scores stay finite without noise).
pub fn synth(model: &Model, exps: &Experiments, noise: f64, seed: u64, jobs: usize) -> Result<Vec<Observation>, String> {
    if !(noise.is_finite() && noise >= 0.0) {
        return Err(format!("--noise must be >= 0, got {noise}"));
    }
    let wanted: Vec<(String, Vec<Observable>)> = exps
        .experiment
        .iter()
        .map(|x| Ok((x.id.clone(), x.observe.iter().map(|o| Observable::parse(o)).collect::<Result<Vec<_>, _>>()?)))
        .collect::<Result<_, String>>()?;
    if wanted.iter().all(|(_, o)| o.is_empty()) {
        return Err("no experiment lists anything to observe (observe = [...])".into());
    }
    let values = evaluate_all(model, exps, &wanted, jobs)?;
    let mut rng = Normal::new(seed);
    let mut out = Vec::new();
    for ((id, obs), vals) in wanted.iter().zip(values) {
        for (o, v) in obs.iter().zip(vals) {
            let value = v * (1.0 + noise * rng.sample());
            out.push(Observation { experiment: id.clone(), observable: o.clone(), value, uncertainty: noise.max(1e-6) * v.abs().max(1e-300) });
        }
    }
    Ok(out)
}

/// Standard normal samples: splitmix64 and Box-Muller, so a seed gives the same data anywhere.
struct Normal {
    state: u64,
    spare: Option<f64>,
}

impl Normal {
    fn new(seed: u64) -> Normal {
        Normal { state: seed, spare: None }
    }

    fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn sample(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u, v) = (self.uniform(), self.uniform());
        let r = (-2.0 * u.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * v;
        self.spare = Some(r * a.sin());
        r * a.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::super::runner::fixture::setup;
    use super::*;

    #[test]
    fn noise_is_seeded_and_jobs_do_not_change_results() {
        let (m, e) = setup();
        let a = synth(&m, &e, 0.05, 7, 1).unwrap();
        assert_eq!(a, synth(&m, &e, 0.05, 7, 3).unwrap());
        assert_ne!(a, synth(&m, &e, 0.05, 8, 1).unwrap());
        let rel: Vec<f64> = a.iter().zip(synth(&m, &e, 0.0, 7, 1).unwrap()).map(|(n, c)| n.value / c.value - 1.0).collect();
        assert!(rel.iter().all(|r| r.abs() < 0.25) && rel.iter().any(|r| r.abs() > 1e-4), "{rel:?}");
    }

}
