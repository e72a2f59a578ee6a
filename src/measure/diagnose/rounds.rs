//! `strand diagnose --rounds N`: the loop a user runs by hand, run to its end. Each round
//! diagnoses the model, adds the effect the verdict chooses (fitted, with its parameters refitted
//! in every later round beside `--fit`), and diagnoses again, until nothing is significant (the
//! verdict is not "add EFFECT") or N rounds have run. The error after each round is the
//! chi^2 per observation of the model it leaves.

use crate::measure::campaign::Campaign;
use crate::measure::error::MeasureError;
use crate::measure::diagnose::{diagnose, DiagnoseOptions, Diagnosis};
use crate::measure::model::Model;
use std::fmt::Write as _;

#[derive(Clone, Debug, serde::Serialize)]
pub struct Round {
    /// 1, 2, ...
    pub round: usize,
    /// The round's base fit: chi^2 / observations.
    pub chi2_per_observation_before: f64,
    /// The effect added this round, if any.
    pub added: Option<String>,
    /// chi^2 / observations of the model the round leaves (the base's when nothing was added).
    pub chi2_per_observation_after: f64,
    pub diagnosis: Diagnosis,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Rounds {
    pub rounds: Vec<Round>,
    /// The effects added, in order.
    pub added: Vec<String>,
    pub final_chi2: f64,
    pub final_chi2_per_observation: f64,
    /// Whether the last round found nothing more to add (rather than running out of rounds).
    pub complete: bool,
    /// The parameters fitted in the final model: `--fit` and the added effects'.
    pub fit: Vec<String>,
    #[serde(skip)]
    pub model: Model,
}

/// Diagnose rounds from `model`, each adding the effect the last recommended, until none is or
/// `max_rounds` have run.
pub fn rounds(
    c: &Campaign,
    model: &Model,
    fit: &[String],
    opts: &DiagnoseOptions,
    max_rounds: usize,
) -> Result<Rounds, MeasureError> {
    let n = c.data.len().max(1) as f64;
    let (mut model, mut fit) = (model.clone(), fit.to_vec());
    let mut out = Rounds {
        rounds: vec![],
        added: vec![],
        final_chi2: f64::NAN,
        final_chi2_per_observation: f64::NAN,
        complete: false,
        fit: vec![],
        model: model.clone(),
    };
    for round in 1..=max_rounds.max(1) {
        // the model's values are known in the first round only (the discretisation estimate's)
        let campaign = if round == 1 { *c } else { Campaign { estimate: None, ..*c } };
        let d = diagnose(&campaign, &model, &fit, opts)?;
        let before = d.base_chi2;
        let chosen = d.recommended.as_ref().and_then(|e| d.candidates.iter().find(|c| c.effect == *e));
        let (added, after, next) = match (chosen, &d.recommended_model) {
            (Some(c), Some(m)) => {
                (Some(c.effect.clone()), c.fitted_chi2.unwrap_or(before), Some((m.clone(), m.effect(&c.effect)?)))
            }
            _ => (None, before, None),
        };
        out.rounds.push(Round {
            round,
            chi2_per_observation_before: before / n,
            added: added.clone(),
            chi2_per_observation_after: after / n,
            diagnosis: d.clone(),
        });
        out.final_chi2 = after;
        match next {
            Some((m, effect)) => {
                fit.extend(effect.params().iter().map(|s| format!("{}.{}", effect.name(), s.name)));
                out.added.push(added.expect("with the model"));
                model = m;
            }
            None => {
                // the base was refitted this round: its values are the final model's
                model = d.base_model.clone();
                out.complete = true;
                break;
            }
        }
    }
    out.final_chi2_per_observation = out.final_chi2 / n;
    out.fit = fit;
    out.model = model;
    Ok(out)
}

/// Each round's diagnosis, then the error after each round.
pub fn report(r: &Rounds) -> String {
    let mut s = String::new();
    for round in &r.rounds {
        let _ = writeln!(s, "=== round {} ===", round.round);
        s.push_str(&crate::measure::diagnose::report(&round.diagnosis));
        s.push('\n');
    }
    let _ = writeln!(s, "rounds (chi^2 / observations):");
    for round in &r.rounds {
        let what = match &round.added {
            Some(e) => format!("add {e}"),
            None => round.diagnosis.verdict.clone(),
        };
        let _ = writeln!(
            s,
            "  round {}: {:.4} -> {what} -> {:.4}",
            round.round, round.chi2_per_observation_before, round.chi2_per_observation_after
        );
    }
    let mut chain: Vec<String> =
        r.rounds.first().map(|x| format!("{:.3}", x.chi2_per_observation_before)).into_iter().collect();
    chain.extend(r.rounds.iter().filter(|x| x.added.is_some()).map(|x| format!("{:.3}", x.chi2_per_observation_after)));
    let _ = writeln!(
        s,
        "error: {}; effects added: {}{}",
        chain.join(" -> "),
        if r.added.is_empty() { "none".to_string() } else { r.added.join(", ") },
        if r.complete { "" } else { " (stopped at --rounds with an effect still significant)" }
    );
    s
}
