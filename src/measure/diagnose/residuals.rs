//! The shape of the residuals, in words: what `strand diagnose` and `strand compare --report` say
//! the misfit looks like against each covariate (rest time, age, a covariate experiments declare,
//! a `set` key) and each observable's own `at` (rate, station, time), with the kind of cause that
//! follows from the shape where one does.
//!
//! Shapes, each an F-test on the standardised residuals z, nested least-squares fits:
//!
//! * **trend**: a slope in the covariate, over a constant;
//! * **curvature**: a quadratic term over the line (needs three values of the covariate);
//! * **step**: the groups of equal covariate value apart from each other, over the quadratic (or
//!   over a constant when the covariate takes two values, where a step is all a line can be);
//! * **together**: residuals that move together within each experiment, the experiments' means
//!   apart beyond the scatter within them, when no per-experiment covariate accounts for it.
//!
//! A covariate that is one value per experiment (rest time, age, a declared covariate) is tested
//! on the experiments' mean z, one point per experiment, so that residuals moving together within
//! an experiment do not count as many independent points; one that varies within experiments (an
//! `at`) is tested within them, each experiment with its own constant, so that a shift of a whole
//! experiment does not pass for a trend. The residual variance is estimated from the fit (F, not
//! chi^2): residuals standardised by uncertainties that are off by a factor have the same shapes.
//! A shape is reported when its p-value is below alpha / (the number of tests made), Bonferroni's
//! bound, so that pure noise flags nothing at rate alpha however many covariates there are.

use crate::measure::compare::Row;
use crate::measure::fit::linalg::{f_sf, pinv_sym};
use std::fmt::Write as _;

/// Something z may move with: its value at each row of the comparison, None where it does not
/// apply (the `at` of another observable, a key an experiment does not have).
#[derive(Clone, Debug, PartialEq)]
pub struct Covariate {
    /// `rest_time`, `age`, a covariate experiments declare (by its name), `at(OBSERVABLE)`,
    /// `at2(OBSERVABLE)` (a second coordinate) or `set.KEY`.
    pub name: String,
    /// The plot's axis title.
    pub axis: String,
    pub values: Vec<Option<f64>>,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Shape {
    /// The covariate's name (`age`, `at(stress)`, `set.KEY`); "experiment" for `together`.
    pub covariate: String,
    /// "trend", "curvature", "step" or "together".
    pub kind: String,
    /// Points the test ran on: experiments for a per-experiment covariate, readings otherwise.
    pub n: usize,
    pub f: f64,
    pub p_value: f64,
    /// The sign of the slope (trend, step over two values) or of the quadratic term (curvature)
    /// of z = (model - measured) / uncertainty; 0 for the others.
    pub sign: f64,
    /// The shape and its likely cause, in words.
    pub text: String,
}

/// Least squares of `y` on `cols`: the residual sum of squares, the rank, the coefficients.
fn fit(y: &[f64], cols: &[Vec<f64>]) -> (f64, usize, Vec<f64>) {
    let a: Vec<Vec<f64>> =
        cols.iter().map(|c| cols.iter().map(|d| c.iter().zip(d).map(|(p, q)| p * q).sum()).collect()).collect();
    let g: Vec<f64> = cols.iter().map(|c| c.iter().zip(y).map(|(p, q)| p * q).sum()).collect();
    let (inv, rank) = pinv_sym(&a, 1e-10);
    let coef: Vec<f64> = inv.iter().map(|r| r.iter().zip(&g).map(|(p, q)| p * q).sum()).collect();
    let rss = y
        .iter()
        .enumerate()
        .map(|(i, v)| (v - cols.iter().zip(&coef).map(|(c, k)| c[i] * k).sum::<f64>()).powi(2))
        .sum();
    (rss, rank, coef)
}

/// The F-test of `full` over `reduced` (`full` extends it): F, d1, d2 and the p-value; None when
/// the extra columns add nothing or no degree of freedom is left for the scatter.
fn f_test(y: &[f64], reduced: &[Vec<f64>], full: &[Vec<f64>]) -> Option<(f64, f64, Vec<f64>)> {
    let (r0, k0, _) = fit(y, reduced);
    let (r1, k1, coef) = fit(y, full);
    let (d1, d2) = (k1.checked_sub(k0)?, y.len().checked_sub(k1)?);
    if d1 == 0 || d2 < 2 {
        return None;
    }
    // an exact fit leaves no scatter: anything the extra columns explain is infinitely significant
    let f =
        if r1 > 1e-12 * r0.max(1e-300) { ((r0 - r1).max(0.0) / d1 as f64) / (r1 / d2 as f64) } else { f64::INFINITY };
    Some((f, f_sf(f, d1, d2), coef))
}

fn indicators(group: &[usize]) -> Vec<Vec<f64>> {
    let n = group.iter().copied().max().map_or(0, |m| m + 1);
    (0..n).map(|g| group.iter().map(|&k| if k == g { 1.0 } else { 0.0 }).collect()).collect()
}

/// Group indices of `keys` in order of first appearance.
fn groups_of<T: PartialEq + Clone>(keys: &[T]) -> (Vec<usize>, Vec<T>) {
    let mut seen: Vec<T> = Vec::new();
    let idx = keys
        .iter()
        .map(|k| match seen.iter().position(|s| s == k) {
            Some(i) => i,
            None => {
                seen.push(k.clone());
                seen.len() - 1
            }
        })
        .collect();
    (idx, seen)
}

/// A test made, before the threshold is known.
struct Tested {
    shape: Shape,
    per_experiment: bool,
}

/// The shapes of the residuals `rows` against `covariates`, significant at `alpha` for all the
/// tests together.
pub fn shapes(rows: &[Row], covariates: &[Covariate], alpha: f64) -> Vec<Shape> {
    let mut tested: Vec<Tested> = Vec::new();
    for c in covariates {
        tested.extend(covariate_shapes(rows, c));
    }
    let together = together(rows);
    let m = tested.len() + together.is_some() as usize;
    let level = alpha / m.max(1) as f64;
    let mut out: Vec<Shape> = tested.iter().filter(|t| t.shape.p_value < level).map(|t| t.shape.clone()).collect();
    let explained = tested.iter().any(|t| t.per_experiment && t.shape.p_value < level);
    if let Some(t) = together.filter(|t| t.p_value < level && !explained) {
        out.push(t);
    }
    out
}

fn covariate_shapes(rows: &[Row], c: &Covariate) -> Vec<Tested> {
    let (mut x, mut z, mut w, mut exp) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (r, v) in rows.iter().zip(&c.values) {
        if let Some(v) = v.filter(|v| v.is_finite()).filter(|_| r.z.is_finite()) {
            x.push(v);
            z.push(r.z);
            w.push(1.0 / r.uncertainty);
            exp.push(r.experiment.clone());
        }
    }
    let (exp, ids) = groups_of(&exp);
    let per_experiment = ids.len() >= 2 && (0..ids.len()).all(|g| {
        let mut v = x.iter().zip(&exp).filter(|(_, e)| **e == g).map(|(x, _)| *x);
        let first = v.next();
        v.all(|x| Some(x) == first)
    });
    // the points and the base model: experiments' means over a constant, or readings each over
    // its experiment's constant
    // Within experiments the shape is that of the residual model - measured, weighted by
    // 1 / uncertainty (z = residual / uncertainty regressed on each column / uncertainty): an
    // uncertainty relative to the value would otherwise bend a straight residual.
    let (x, z, w, base) = if per_experiment {
        let mean = |v: &[f64], g: usize| -> f64 {
            let s: Vec<f64> = v.iter().zip(&exp).filter(|(_, e)| **e == g).map(|(v, _)| *v).collect();
            s.iter().sum::<f64>() / s.len() as f64
        };
        let xs: Vec<f64> = (0..ids.len()).map(|g| mean(&x, g)).collect();
        let zs: Vec<f64> = (0..ids.len()).map(|g| mean(&z, g)).collect();
        let n = xs.len();
        (xs, zs, vec![1.0; n], vec![vec![1.0; n]])
    } else {
        let base = if ids.len() >= 2 { indicators(&exp) } else { vec![vec![1.0; x.len()]] };
        let base = base.into_iter().map(|c| c.iter().zip(&w).map(|(c, w)| c * w).collect()).collect();
        (x, z, w, base)
    };
    let (level_of, levels) = groups_of(&x.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
    let k = levels.len();
    if k < 2 {
        return vec![];
    }
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt().max(1e-300);
    let u: Vec<f64> = x.iter().map(|v| (v - mean) / sd).collect();
    let lin: Vec<Vec<f64>> = base.iter().cloned().chain([u.iter().zip(&w).map(|(u, w)| u * w).collect()]).collect();
    let quad: Vec<Vec<f64>> = lin.iter().cloned().chain([u.iter().zip(&w).map(|(u, w)| u * u * w).collect()]).collect();
    // the sign of the last column's coefficient: the slope, or the quadratic term
    let shape = |kind: &str, (f, p, coef): (f64, f64, Vec<f64>), signed: bool| {
        let sign = if signed { coef.last().copied().unwrap_or(0.0).signum() } else { 0.0 };
        Tested {
            shape: Shape {
                covariate: c.name.clone(),
                kind: kind.into(),
                n: x.len(),
                f,
                p_value: p,
                sign,
                text: describe(c, kind, sign, (&x, &z), (f, p)),
            },
            per_experiment,
        }
    };
    let mut out = Vec::new();
    if k == 2 {
        out.extend(f_test(&z, &base, &lin).map(|t| shape("step", t, true)));
        return out;
    }
    out.extend(f_test(&z, &base, &lin).map(|t| shape("trend", t, true)));
    out.extend(f_test(&z, &lin, &quad).map(|t| shape("curvature", t, true)));
    if k >= 4 {
        let groups: Vec<Vec<f64>> = quad
            .iter()
            .cloned()
            .chain(indicators(&level_of).into_iter().map(|c| c.iter().zip(&w).map(|(c, w)| c * w).collect()))
            .collect();
        out.extend(f_test(&z, &quad, &groups).map(|t| shape("step", t, false)));
    }
    out
}

/// Residuals moving together within each experiment: the experiments' means over one constant.
fn together(rows: &[Row]) -> Option<Shape> {
    let z: Vec<f64> = rows.iter().map(|r| r.z).filter(|z| z.is_finite()).collect();
    let ids: Vec<&str> = rows.iter().filter(|r| r.z.is_finite()).map(|r| r.experiment.as_str()).collect();
    let (exp, names) = groups_of(&ids);
    if names.len() < 2 {
        return None;
    }
    let (f, p, _) = f_test(&z, &[vec![1.0; z.len()]], &indicators(&exp))?;
    let means: Vec<String> = (0..names.len())
        .map(|g| {
            let v: Vec<f64> = z.iter().zip(&exp).filter(|(_, e)| **e == g).map(|(z, _)| *z).collect();
            format!("{} {:+.1}", names[g], v.iter().sum::<f64>() / v.len() as f64)
        })
        .collect();
    let text = format!(
        "residuals move together within each experiment (F = {f:.1}, p = {p:.1e}): a per-experiment cause the \
            covariates do not describe (a batch, the mix, the set-up); mean z: {}",
        means.join(", ")
    );
    Some(Shape { covariate: "experiment".into(), kind: "together".into(), n: z.len(), f, p_value: p, sign: 0.0, text })
}

/// What a covariate is, in words.
fn label(name: &str) -> String {
    match name {
        "rest_time" => "rest time".into(),
        "age" => "age".into(),
        "at(stress)" => "shear rate".into(),
        _ => match name.strip_prefix("at(").and_then(|s| s.strip_suffix(')')) {
            Some(o @ ("spread" | "front" | "vx_max" | "kinetic_energy" | "mean_z")) => format!("time ({o})"),
            Some(o) => format!("station x ({o})"),
            None => match name.strip_prefix("at2(").and_then(|s| s.strip_suffix(')')) {
                Some("profile") => "lateral position y (profile)".into(),
                Some(o) => format!("layer ({o})"),
                None => name.strip_prefix("set.").unwrap_or(name).to_string(),
            },
        },
    }
}

/// The likely kind of cause of a shape against a covariate, where one follows; `sign` is the
/// sign of the slope or of the quadratic term of z = (model - measured) / uncertainty.
fn cause(name: &str, kind: &str, sign: f64) -> Option<String> {
    let bends = kind == "curvature";
    let falls = sign < 0.0;
    Some(match name {
        "at(stress)" if bends => {
            if sign > 0.0 {
                "the flow curve is not linear in the rate: the data are concave in it (the model below them at mid \
                    rates), as a shear-thinning material's (Herschel-Bulkley, n < 1)".into()
            } else {
                "the flow curve is not linear in the rate: the data are convex in it (the model above them at mid \
                    rates), as a shear-thickening material's (Herschel-Bulkley, n > 1)".into()
            }
        }
        "at(stress)" => "the stress grows with the rate at another slope than the model's: the plastic viscosity is \
            off or not fitted".into(),
        "rest_time" if bends => "the build-up is not linear in the rest time (a structuration that saturates or \
            accelerates)".into(),
        "rest_time" if falls => "the data stiffen with rest more than the model does: structural build-up at rest \
            (thixotropy)".into(),
        "rest_time" => "the model stiffens with rest more than the data do: its build-up at rest is too strong".into(),
        "age" if bends => "the change with age is not linear in age (a power law or an exponential in age: one can be \
            declared in the model file)".into(),
        "age" if falls => "the data stiffen with age more than the model does: ageing (hydration) of the yield stress \
            or the viscosity".into(),
        "age" => "the model stiffens with age more than the data do: its ageing is too strong".into(),
        _ if name.starts_with("set.") => format!("the response to {} is not the model's", label(name)),
        _ => match name.strip_prefix("at(").and_then(|s| s.strip_suffix(')')) {
            Some("spread" | "front" | "vx_max" | "kinetic_energy" | "mean_z") if bends => "the flow's course in time \
                bends away from the model's: a time scale the model lacks (thixotropic breakdown, a relaxation, \
                elasticity)".into(),
            Some("spread" | "front" | "vx_max" | "kinetic_energy" | "mean_z") => "the flow runs faster or slower in \
                time than the model's (viscosity, or breakdown of structure while flowing)".into(),
            Some(_) => "the deposit changes along the path: something that changes while printing (ageing during the \
                print, the speed, the flow rate)".into(),
            None if name.starts_with("at2(profile") => "the section's shape across is not the model's: how the layer \
                spreads (yield stress, floor friction)".into(),
            None if name.starts_with("at2(") => "layers differ from the model's: the load of the layers above \
                (build-up, elasticity)".into(),
            None => format!("the data depend on {name} in a way the model does not: an effect that reads it can be \
                declared in the model file"),
        },
    })
}

/// A shape in words: of `kind` against covariate `c` (`sign` its direction), from the values
/// `x` of the covariate and the residuals `z`, with its F statistic and p-value.
fn describe(c: &Covariate, kind: &str, sign: f64, (x, z): (&[f64], &[f64]), (f, p): (f64, f64)) -> String {
    let what = label(&c.name);
    let shape = match kind {
        "trend" => format!("residuals {} with {what}", if sign > 0.0 { "rise" } else { "fall" }),
        "curvature" => format!("residuals bend with {what} ({} in it)", if sign > 0.0 { "convex" } else { "concave" }),
        _ => {
            let (g, levels) = groups_of(&x.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
            let means: Vec<String> = levels
                .iter()
                .enumerate()
                .map(|(i, bits)| {
                    let v: Vec<f64> = z.iter().zip(&g).filter(|(_, k)| **k == i).map(|(z, _)| *z).collect();
                    format!("{} at {:+.1}", f64::from_bits(*bits), v.iter().sum::<f64>() / v.len() as f64)
                })
                .collect();
            format!("residuals step between groups of {what} (mean z: {})", means.join(", "))
        }
    };
    let mut s = format!("{shape} (F = {f:.1}, p = {p:.1e})");
    if let Some(why) = cause(&c.name, kind, sign) {
        let _ = write!(s, ": {why}");
    }
    s
}

/// The shapes as text, a line each.
pub fn text(shapes: &[Shape]) -> String {
    let mut s = String::new();
    if shapes.is_empty() {
        let _ =
            writeln!(s, "\nshape of the residuals: no trend, curvature, step or per-experiment shift is significant");
        return s;
    }
    let _ = writeln!(s, "\nshape of the residuals:");
    for sh in shapes {
        let _ = writeln!(s, "  {}", sh.text);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::compare::comparison;
    use crate::measure::observation::{Observable, Observation};
    use crate::measure::compare::synth::noise_source;
    use rand_distr::{Distribution, StandardNormal};

    /// A campaign's layout: six experiments (rest time, age) of three rates each.
    const EXPERIMENTS: [(f64, f64); 6] =
        [(0.0, 600.0), (60.0, 1200.0), (300.0, 1800.0), (0.0, 2400.0), (600.0, 3000.0), (0.0, 3600.0)];
    const RATES: [f64; 3] = [20.0, 5.0, 1.0];

    /// Rows of the campaign with z = noise + `signal(experiment, rest, age, rate)`, and their
    /// covariates (rest time, age, the rate).
    fn campaign(seed: u64, signal: impl Fn(usize, f64, f64, f64) -> f64) -> (Vec<Row>, Vec<Covariate>) {
        let mut noise = noise_source(seed);
        let (mut data, mut values, mut covs) = (Vec::new(), Vec::new(), [Vec::new(), Vec::new(), Vec::new()]);
        for (e, (rest, age)) in EXPERIMENTS.iter().enumerate() {
            for rate in RATES {
                data.push(Observation {
                    experiment: format!("E{e}"),
                    observable: Observable { name: "stress".into(), at: Some(rate), at2: None },
                    value: 100.0,
                    uncertainty: 1.0,
                });
                let n: f64 = StandardNormal.sample(&mut noise);
                values.push(100.0 + n + signal(e, *rest, *age, rate));
                for (c, v) in covs.iter_mut().zip([*rest, *age, rate]) {
                    c.push(Some(v));
                }
            }
        }
        let names = ["rest_time", "age", "at(stress)"];
        let covs = covs
            .into_iter()
            .zip(names)
            .map(|(values, n)| Covariate { name: n.into(), axis: n.into(), values })
            .collect();
        (comparison(&data, &values).rows, covs)
    }

    #[test]
    fn pure_noise_flags_nothing() {
        // at alpha = 0.01 for all tests together, about 1 in 100 noise campaigns flags something
        let flagged: Vec<(u64, Vec<Shape>)> = (0..300)
            .map(|seed| (seed, campaign(seed, |_, _, _, _| 0.0)))
            .map(|(s, (r, c))| (s, shapes(&r, &c, 0.01)))
            .filter(|(_, sh)| !sh.is_empty())
            .collect();
        assert!(flagged.len() <= 9, "{} of 300 noise campaigns flagged: {:?}", flagged.len(), flagged.first());
        // and the noise scaled up 20 times (uncertainties stated too small) flags the same shapes
        // as unscaled, up to rounding (the texts quote mean z, which scales): the tests are F
        // tests, blind to the scale of z. Checked on the campaigns that flagged something and on
        // ten that may not have.
        let seeds = flagged.iter().map(|(s, _)| *s).chain(0..10);
        for seed in seeds {
            let (rows, covs) = campaign(seed, |_, _, _, _| 0.0);
            let scaled: Vec<Row> = rows.iter().map(|r| Row { z: 20.0 * r.z, ..r.clone() }).collect();
            let (a, b) = (shapes(&scaled, &covs, 0.01), shapes(&rows, &covs, 0.01));
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * y.abs();
            let same = a.len() == b.len()
                && a.iter().zip(&b).all(|(x, y)| {
                    (&x.covariate, &x.kind, x.n, x.sign) == (&y.covariate, &y.kind, y.n, y.sign)
                        && close(x.f, y.f)
                        && close(x.p_value, y.p_value)
                });
            assert!(same, "seed {seed}: scaled {a:#?}\nunscaled {b:#?}");
        }
    }

    #[test]
    fn a_trend_in_age_is_named_with_its_cause() {
        // the model under-predicts more as the material ages: ageing it lacks
        let (rows, covs) = campaign(1, |_, _, age, _| -8.0 * age / 3600.0);
        let sh = shapes(&rows, &covs, 0.01);
        let t = sh.iter().find(|s| s.covariate == "age").unwrap_or_else(|| panic!("{sh:#?}"));
        assert_eq!((t.kind.as_str(), t.sign, t.n), ("trend", -1.0, 6), "{t:#?}");
        assert!(t.text.starts_with("residuals fall with age") && t.text.contains("ageing"), "{}", t.text);
        // a trend with a per-experiment covariate is not a per-experiment cause of its own
        assert!(sh.iter().all(|s| s.kind != "together"), "{sh:#?}");
    }

    #[test]
    fn a_flow_curve_bending_away_from_the_line_is_curvature_in_the_rate() {
        // a Bingham line fitted through a concave (shear-thinning) flow curve: z convex in the
        // rate, above at both ends and below at mid rates
        let (rows, covs) = campaign(2, |_, _, _, rate| 4.0 * ((rate.ln() - 5f64.ln()).powi(2) - 1.2));
        let sh = shapes(&rows, &covs, 0.01);
        let c = sh
            .iter()
            .find(|s| s.covariate == "at(stress)" && s.kind == "curvature")
            .unwrap_or_else(|| panic!("{sh:#?}"));
        assert!(
            c.text.starts_with("residuals bend with shear rate")
                && c.text.contains("the flow curve is not linear in the rate")
                && c.text.contains("shear-thinning"),
            "{}",
            c.text
        );
        assert!(sh.iter().all(|s| s.covariate != "age" && s.covariate != "rest_time"), "{sh:#?}");
    }

    #[test]
    fn a_straight_residual_under_relative_uncertainties_does_not_bend() {
        // a Bingham model with the viscosity off, against Bingham data with 1 % uncertainties:
        // the residual is linear in the rate, z = residual / (0.01 measured) is not
        let mut data = Vec::new();
        let mut values = Vec::new();
        for (e, tau0) in [100.0, 120.0, 140.0].iter().enumerate() {
            for rate in [40.0, 20.0, 10.0, 5.0, 1.0] {
                let measured = tau0 + 20.0 * rate;
                data.push(Observation {
                    experiment: format!("E{e}"),
                    observable: Observable { name: "stress".into(), at: Some(rate), at2: None },
                    value: measured,
                    uncertainty: 0.01 * measured,
                });
                values.push(tau0 + 30.0 * rate);
            }
        }
        let rows = comparison(&data, &values).rows;
        let covs =
            [Covariate { name: "at(stress)".into(), axis: String::new(), values: rows.iter().map(|r| r.at).collect() }];
        let sh = shapes(&rows, &covs, 0.01);
        assert!(sh.iter().any(|s| s.kind == "trend") && sh.iter().all(|s| s.kind != "curvature"), "{sh:#?}");
    }

    #[test]
    fn batches_move_together_and_a_two_valued_key_is_a_step() {
        // each experiment off by its own amount, unrelated to rest or age
        let shift = [0.0, 6.0, -5.0, 5.0, -4.0, 3.0];
        let (rows, covs) = campaign(3, |e, _, _, _| shift[e]);
        let sh = shapes(&rows, &covs, 0.01);
        assert!(sh.iter().any(|s| s.kind == "together" && s.text.contains("within each experiment")), "{sh:#?}");
        // a set key with two values, the residuals apart between them
        let (rows, mut covs) = campaign(4, |e, _, _, _| if e % 2 == 0 { 8.0 } else { 0.0 });
        let key: Vec<Option<f64>> = (0..rows.len()).map(|i| Some(if (i / 3) % 2 == 0 { 0.3 } else { 0.5 })).collect();
        covs.push(Covariate { name: "set.material.water".into(), axis: String::new(), values: key });
        let sh = shapes(&rows, &covs, 0.01);
        let s = sh.iter().find(|s| s.covariate == "set.material.water").unwrap_or_else(|| panic!("{sh:#?}"));
        assert_eq!(s.kind, "step");
        assert!(
            s.text.contains("residuals step between groups of material.water") && s.text.contains("0.3 at +"),
            "{}",
            s.text
        );
        // explained by the key: not reported as a per-experiment cause
        assert!(sh.iter().all(|s| s.kind != "together"), "{sh:#?}");
    }
}
