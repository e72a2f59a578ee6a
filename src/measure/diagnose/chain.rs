//! Jacobian columns without a run. An experiment's values depend on the model only through its
//! keys ([`Model::keys`] at the experiment's covariates, less the keys the experiment sets
//! itself), so where a parameter moves those keys as a combination of the ways the fitted
//! parameters move them, its column is that combination of their columns: the chain rule
//! through the keys, whose derivatives are the effects' own adjoints ([`Model::keys_adjoint`]).
//! An ageing rate moves an experiment's yield stress by its age, so its column is the yield
//! stress's times the age, without the runs its differences would take; an effect that adds a
//! key of its own (a thixotropic build-up rate, a flow index) or moves a print key is not
//! spanned, and its column is computed.

use crate::measure::error::MeasureError;
use crate::measure::effects::Keys;
use crate::measure::campaign::experiments::Experiments;
use crate::measure::fit::linalg::{gauss_newton_step, normal_equations};
use crate::measure::model::Model;
use crate::measure::observation::Observation;
use crate::measure::campaign::runner::{find, group};

/// The columns of `extra` (one value per observation of `data`) at `model`, given `jacobian`
/// (a row per observation) in `fitted` and its entries' scatter: `Some` for each parameter whose
/// key moves lie, in every experiment, in the span of the fitted parameters' (to round-off), with
/// each entry's scatter (the fitted entries' combined, as independent), `None` for the others.
pub fn chained(
    model: &Model,
    data: &[Observation],
    exps: &Experiments,
    fitted: &[String],
    (jacobian, jacobian_scatter): (&[Vec<f64>], &[Vec<f64>]),
    extra: &[String],
) -> Result<Vec<Option<Chained>>, MeasureError> {
    let all = model.parameters(&fitted.iter().chain(extra).cloned().collect::<Vec<_>>())?;
    let fcols: Vec<usize> = (0..fitted.len()).collect();
    let mut columns: Vec<Option<Chained>> =
        vec![Some(Chained { column: vec![0.0; data.len()], scatter: vec![0.0; data.len()] }); extra.len()];
    for (id, _) in group(data) {
        let x = find(exps, &id)?;
        let cov = x.covariates();
        // d key / d parameter, a row per key the experiment takes from the model
        let tangents: Vec<Vec<f64>> = model
            .keys(&cov)?
            .into_keys()
            .filter(|k| !x.set.contains_key(k))
            .map(|k| model.keys_adjoint(&cov, Keys::from([(k, 1.0)]), &all))
            .collect::<Result<_, _>>()?;
        let rows: Vec<usize> = (0..data.len()).filter(|&i| data[i].experiment == id).collect();
        for (q, column) in columns.iter_mut().enumerate() {
            let Some(col) = column else { continue };
            let t: Vec<f64> = tangents.iter().map(|r| r[fitted.len() + q]).collect();
            let Some(c) = combination(&tangents, &fcols, &t) else {
                *column = None;
                continue;
            };
            for &i in &rows {
                col.column[i] = jacobian[i].iter().zip(&c).map(|(a, b)| a * b).sum();
                col.scatter[i] = jacobian_scatter[i].iter().zip(&c).map(|(a, b)| (a * b).powi(2)).sum::<f64>().sqrt();
            }
        }
    }
    Ok(columns)
}

/// A column the chain rule gives, and its entries' scatter.
#[derive(Clone, Debug)]
pub struct Chained {
    pub column: Vec<f64>,
    pub scatter: Vec<f64>,
}

/// The coefficients c with `t` = sum_j c_j (column `cols[j]` of `tangents`), when `t` lies in
/// their span to round-off (least squares, then the residual checked).
fn combination(tangents: &[Vec<f64>], cols: &[usize], t: &[f64]) -> Option<Vec<f64>> {
    let size = t.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if size == 0.0 {
        return Some(vec![0.0; cols.len()]);
    }
    if cols.is_empty() {
        return None;
    }
    let (a, g) = normal_equations(tangents, t, cols);
    let c: Vec<f64> = gauss_newton_step(&a, &g, 1e-12).iter().map(|v| -v).collect();
    let miss = tangents
        .iter()
        .zip(t)
        .map(|(r, ti)| (ti - cols.iter().zip(&c).map(|(&k, ck)| r[k] * ck).sum::<f64>()).abs())
        .fold(0.0, f64::max);
    (miss <= 1e-9 * size).then_some(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\npoisson_ratio = \
        0.3\nviscosity = 30.0\nyield_stress = 80.0\n[effects.ageing]\n[effects.thixotropy]\n";
    const EXPS: &str = "[[experiment]]\nid = \"young\"\nrest_time = 60.0\nage = 60.0\nobserve = [\"stress@20\", \
        \"stress@5\"]\n[experiment.protocol]\n[[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0]\n\
        hold = 0.5\n\n[[experiment]]\nid = \"old\"\nage = 600.0\nobserve = [\"stress@20\"]\n[experiment.protocol]\n\
        [[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0]\nhold = 0.5\n";

    /// The chained columns equal the adjoint's Jacobian (a rheometer's, exact) for an effect the
    /// fitted parameters span (an ageing rate: the yield stress's column times each
    /// experiment's age), and an effect with a key of its own is left to be computed.
    #[test]
    fn an_ageing_rates_column_is_the_yield_stresss_times_the_age() {
        let model = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let exps: Experiments = toml::from_str(EXPS).unwrap();
        exps.validate().unwrap();
        let data = crate::measure::compare::synth::synth(&model, &exps, 0.0, 1, 1).unwrap();
        let fitted = vec!["material.yield_stress".to_string(), "material.viscosity".to_string()];
        let extra: Vec<String> = ["ageing.rate", "thixotropy.a_thix"].iter().map(|s| s.to_string()).collect();
        let all: Vec<String> = fitted.iter().chain(&extra).cloned().collect();
        let one_job = crate::measure::campaign::runner::Jobs::new(1);
        let exact = crate::measure::campaign::sensitivity::evaluate(&model, &data, &exps, (Some(&all), one_job), None)
            .unwrap()
            .jacobian
            .unwrap();
        let fit_rows: Vec<Vec<f64>> = exact.iter().map(|r| r[..2].to_vec()).collect();
        let no_scatter = vec![vec![0.0; 2]; fit_rows.len()];
        let cols = chained(&model, &data, &exps, &fitted, (&fit_rows, &no_scatter), &extra).unwrap();
        let rate = &cols[0].as_ref().expect("an ageing rate is spanned by the yield stress").column;
        assert!(rate.iter().any(|v| *v != 0.0), "{rate:?}");
        for (i, r) in exact.iter().enumerate() {
            assert!(
                (rate[i] - r[2]).abs() <= 1e-9 * r[2].abs().max(1e-300),
                "row {i}: {} against the adjoint's {}",
                rate[i],
                r[2]
            );
        }
        assert!(cols[1].is_none(), "thixotropy's build-up adds keys of its own: {:?}", cols[1]);
    }
}
