//! The comparison as a folder to read (`strand compare --report DIR`): the model against the
//! data for each observable, the z-scores against every covariate that varies across the data,
//! and the trend of z with each, gathered in a self-contained `index.html`.
//!
//! A model that lacks an effect leaves residuals that move with what drives the effect (rest time
//! for thixotropy, age for ageing, a speed for a rate effect), so a strong correlation of z with a
//! covariate points at what to add before `strand diagnose` is run.

use crate::measure::error::{io_error, MeasureError};
use crate::measure::compare::{Comparison, Row};
use crate::measure::campaign::experiments::Experiments;
use crate::measure::model::Model;
use crate::measure::diagnose::residuals::{Covariate, Shape};
use crate::measure::campaign::runner::{find, Applied};
use crate::measure::observables::RHEOMETER_OBSERVABLES;
use crate::output::html::{escape, table};
use crate::output::plot::{plot_measured_model, plot_xy, MeasuredPoint};
use std::collections::{BTreeSet, HashMap, HashSet};
use std::fmt::Write as _;
use std::path::Path;

/// |r| from which a correlation of z with a covariate is flagged as a trend.
pub const TREND_R: f64 = 0.5;

/// How many of the largest |z| the page lists.
const WORST: usize = 10;

/// Pearson correlation and least-squares slope of z against one covariate.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Trend {
    pub covariate: String,
    /// Rows where the covariate has a value and z is finite.
    pub n: usize,
    pub r: f64,
    /// dz / d(covariate).
    pub slope: f64,
    /// |r| >= [`TREND_R`].
    pub trend: bool,
}

/// The covariates of the comparison's rows: each experiment's `rest_time` and `age`, the `at` of
/// each observable, and every key an experiment `set`s. An experiment without such a key takes the
/// value the model gives it, if any (a `material.*` key); a key only the scenario file holds has no
/// value there, as the report does not read scenarios.
pub fn covariates(rows: &[Row], exps: &Experiments, model: &Model) -> Result<Vec<Covariate>, MeasureError> {
    let mut keys: HashMap<&str, crate::measure::effects::Keys> = HashMap::new();
    let mut set_names = BTreeSet::new();
    for r in rows {
        if !keys.contains_key(r.experiment.as_str()) {
            let x = find(exps, &r.experiment)?;
            set_names.extend(x.set.keys().cloned());
            keys.insert(&r.experiment, Applied::new(model, x)?.keys);
        }
    }
    type Of<'a> = &'a dyn Fn(&crate::measure::campaign::experiments::Experiment) -> f64;
    let per_experiment = |f: Of| -> Result<Vec<Option<f64>>, MeasureError> {
        rows.iter().map(|r| find(exps, &r.experiment).map(|x| Some(f(x)))).collect()
    };
    let mut out = vec![
        Covariate { name: "rest_time".into(), axis: "rest time [s]".into(), values: per_experiment(&|x| x.rest_time)? },
        Covariate { name: "age".into(), axis: "age [s]".into(), values: per_experiment(&|x| x.age)? },
    ];
    // the covariates experiments declare, by name; None where one does not
    let declared: BTreeSet<&String> =
        rows.iter().filter_map(|r| find(exps, &r.experiment).ok()).flat_map(|x| x.covariates.keys()).collect();
    for name in declared {
        let values = rows
            .iter()
            .map(|r| find(exps, &r.experiment).map(|x| x.covariates.get(name).copied()))
            .collect::<Result<_, _>>()?;
        out.push(Covariate { name: name.clone(), axis: name.clone(), values });
    }
    for observable in observables(rows) {
        let values = rows.iter().map(|r| if r.observable == observable { r.at } else { None }).collect();
        out.push(Covariate {
            name: format!("at({observable})"),
            axis: format!("{observable}: {}", at_meaning(observable)),
            values,
        });
        if rows.iter().any(|r| r.observable == observable && r.at2.is_some()) {
            let values = rows.iter().map(|r| if r.observable == observable { r.at2 } else { None }).collect();
            out.push(Covariate {
                name: format!("at2({observable})"),
                axis: format!("{observable}: {}", at2_meaning(observable)),
                values,
            });
        }
    }
    for key in set_names {
        let values = rows.iter().map(|r| keys[r.experiment.as_str()].get(&key).copied()).collect();
        out.push(Covariate { name: format!("set.{key}"), axis: key, values });
    }
    Ok(out)
}

/// What `at` is for an observable: a rheometer's shear rate, or what its kind takes
/// (`crate::observables`).
fn at_meaning(observable: &str) -> &'static str {
    if RHEOMETER_OBSERVABLES.contains(&observable) {
        return "shear rate [1/s]";
    }
    crate::observables::kind(observable).map_or("at", |k| k.takes.at_meaning())
}

/// What the second coordinate (after `:`) is for an observable.
fn at2_meaning(observable: &str) -> &'static str {
    crate::observables::kind(observable).map_or("second coordinate", |k| k.takes.at2_meaning())
}

/// Observable names in order of first appearance.
fn observables(rows: &[Row]) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for r in rows {
        if !out.contains(&r.observable.as_str()) {
            out.push(&r.observable);
        }
    }
    out
}

/// The trend of z against each covariate, over the rows where it has a value; a covariate that
/// takes a single value there (or none) has no row, since nothing can move with it.
pub fn trends(rows: &[Row], covariates: &[Covariate]) -> Vec<Trend> {
    covariates
        .iter()
        .filter_map(|c| {
            let (x, z): (Vec<f64>, Vec<f64>) = rows
                .iter()
                .zip(&c.values)
                .filter_map(|(r, v)| v.map(|v| (v, r.z)))
                .filter(|(x, z)| x.is_finite() && z.is_finite())
                .unzip();
            // Compared exactly: a mean of equal values can round, and a constant would then seem to vary.
            if !x.iter().any(|v| *v != x[0]) {
                return None;
            }
            let n = x.len() as f64;
            let (mx, mz) = (x.iter().sum::<f64>() / n, z.iter().sum::<f64>() / n);
            let (mut sxx, mut szz, mut sxz) = (0.0, 0.0, 0.0);
            for (x, z) in x.iter().zip(&z) {
                sxx += (x - mx) * (x - mx);
                szz += (z - mz) * (z - mz);
                sxz += (x - mx) * (z - mz);
            }
            // Constant z moves with nothing: no correlation rather than 0/0.
            let r = if szz > 0.0 { (sxz / (sxx * szz).sqrt()).clamp(-1.0, 1.0) } else { 0.0 };
            Some(Trend { covariate: c.name.clone(), n: x.len(), r, slope: sxz / sxx, trend: r.abs() >= TREND_R })
        })
        .collect()
}

/// The trends as text, for `strand compare`'s report.
pub fn trends_text(trends: &[Trend]) -> String {
    let mut s = String::new();
    if trends.is_empty() {
        let _ = writeln!(s, "\nno covariate varies across the data, so z has no trends to show");
        return s;
    }
    let _ = writeln!(s, "\ntrends of z with the covariates (|r| >= {TREND_R} flagged):");
    let _ = writeln!(s, "  {:<28} {:>5} {:>7} {:>12}", "covariate", "n", "r", "slope");
    for t in trends {
        let flag = if t.trend { "  trend" } else { "" };
        let _ = writeln!(s, "  {:<28} {:>5} {:>7.3} {:>12.4e}{flag}", t.covariate, t.n, t.r, t.slope);
    }
    s
}

/// Make `dir` a folder to write into: create it, or name a path that is there and is not one.
/// Checked before the experiments run, so a bad path fails at once.
pub fn prepare_dir(dir: &Path) -> Result<(), MeasureError> {
    if dir.exists() && !dir.is_dir() {
        return Err(MeasureError::ReportNotAFolder { dir: dir.to_path_buf() });
    }
    std::fs::create_dir_all(dir).map_err(|source| MeasureError::ReportFolder { dir: dir.to_path_buf(), source })
}

/// Significance of the residual shapes the report names (`diagnose/residuals.rs`), for all its tests
/// together.
pub const SHAPES_ALPHA: f64 = 0.01;

/// Write the report into `dir` (plots, `trends.csv`, `index.html`); the trends and the residual
/// shapes it found.
pub fn write(
    dir: &Path,
    c: &Comparison,
    exps: &Experiments,
    model: &Model,
) -> Result<(Vec<Trend>, Vec<Shape>), MeasureError> {
    prepare_dir(dir)?;
    let covs = covariates(&c.rows, exps, model)?;
    let trends = trends(&c.rows, &covs);
    let shapes = crate::measure::diagnose::residuals::shapes(&c.rows, &covs, SHAPES_ALPHA);
    let mut names = HashSet::new();
    let mut fits = Vec::new();
    for observable in observables(&c.rows) {
        let file = unique_name(&mut names, &format!("model_vs_data_{}", file_stem(observable)));
        plot_model_vs_data(&dir.join(&file), &c.rows, observable)?;
        fits.push(Figure { file, caption: format!("{observable}: measured (+- uncertainty) and model") });
    }
    let mut residuals = Vec::new();
    for t in &trends {
        let cov = covs.iter().find(|c| c.name == t.covariate).expect("every trend is of a covariate");
        let file = unique_name(&mut names, &format!("residuals_vs_{}", file_stem(&cov.name)));
        plot_residuals(&dir.join(&file), &c.rows, cov)?;
        residuals.push(Figure { file, caption: format!("z against {} (r = {:.2})", cov.name, t.r) });
    }
    write_trends_csv(&dir.join("trends.csv"), &trends)?;
    let index = dir.join("index.html");
    std::fs::write(&index, html(c, &trends, &shapes, &fits, &residuals, model)).map_err(io_error(&index))?;
    Ok((trends, shapes))
}

/// A plot the page shows.
struct Figure {
    file: String,
    caption: String,
}

/// `name` as a file-name part: runs of anything but letters, digits, `.`, `-` and `_` become one `_`.
fn file_stem(name: &str) -> String {
    let mut s = String::new();
    for ch in name.chars() {
        if ch.is_ascii_alphanumeric() || matches!(ch, '.' | '-' | '_') {
            s.push(ch);
        } else if !s.ends_with('_') {
            s.push('_');
        }
    }
    s.trim_matches('_').to_string()
}

/// `stem.png`, numbered when an earlier plot took the name, so that no plot overwrites another.
fn unique_name(taken: &mut HashSet<String>, stem: &str) -> String {
    let mut name = format!("{stem}.png");
    let mut k = 2;
    while !taken.insert(name.clone()) {
        name = format!("{stem}_{k}.png");
        k += 1;
    }
    name
}

/// One observable's measurements and model values, a group per experiment: against `at` when
/// every row has one, else against the experiment's place in the data, so that no row drops out.
/// An observable with a second coordinate on every row (a profile's y, a layer) is plotted
/// against that, a group per experiment and station.
fn plot_model_vs_data(path: &Path, rows: &[Row], observable: &str) -> Result<(), MeasureError> {
    let rows: Vec<&Row> = rows.iter().filter(|r| r.observable == observable).collect();
    let by_at2 = rows.iter().all(|r| r.at.is_some() && r.at2.is_some());
    let by_at = rows.iter().all(|r| r.at.is_some());
    let mut groups: Vec<(String, Vec<MeasuredPoint>)> = Vec::new();
    for r in rows {
        let id =
            if by_at2 { format!("{} x = {}", r.experiment, r.at.unwrap_or(f64::NAN)) } else { r.experiment.clone() };
        let k = match groups.iter().position(|(g, _)| *g == id) {
            Some(k) => k,
            None => {
                groups.push((id, Vec::new()));
                groups.len() - 1
            }
        };
        let x = if by_at2 {
            r.at2.unwrap_or(f64::NAN)
        } else if by_at {
            r.at.unwrap_or(f64::NAN)
        } else {
            (k + 1) as f64
        };
        groups[k].1.push(MeasuredPoint { x, measured: r.measured, uncertainty: r.uncertainty, model: r.model });
    }
    let x_desc = if by_at2 {
        at2_meaning(observable).to_string()
    } else if by_at {
        at_meaning(observable).to_string()
    } else {
        "experiment (1 = first in the data)".to_string()
    };
    let title = format!("{observable}: measured (filled, +- uncertainty) and model (hollow)");
    Ok(plot_measured_model(path, &title, &x_desc, observable, &groups)?)
}

/// z against one covariate, a series per observable.
fn plot_residuals(path: &Path, rows: &[Row], cov: &Covariate) -> Result<(), MeasureError> {
    let series: Vec<(String, Vec<[f64; 2]>)> = observables(rows)
        .into_iter()
        .map(|o| {
            (
                o.to_string(),
                rows.iter()
                    .zip(&cov.values)
                    .filter(|(r, _)| r.observable == o)
                    .filter_map(|(r, v)| v.map(|v| [v, r.z]))
                    .collect::<Vec<_>>(),
            )
        })
        .filter(|(_, pts)| !pts.is_empty())
        .collect();
    Ok(plot_xy(
        path,
        &format!("z = (model - measured) / uncertainty against {}", cov.name),
        &cov.axis,
        "z",
        &series,
        false,
    )?)
}

fn write_trends_csv(path: &Path, trends: &[Trend]) -> Result<(), MeasureError> {
    let err = |e: csv::Error| MeasureError::from(e).within(path.display());
    let mut w = csv::Writer::from_path(path).map_err(err)?;
    w.write_record(["covariate", "n", "r", "slope", "trend"]).map_err(err)?;
    for t in trends {
        w.write_record([
            t.covariate.clone(),
            t.n.to_string(),
            format!("{:e}", t.r),
            format!("{:e}", t.slope),
            t.trend.to_string(),
        ])
        .map_err(err)?;
    }
    w.flush().map_err(io_error(path))
}

fn figures(s: &mut String, figs: &[Figure]) {
    for f in figs {
        let _ = writeln!(
            s,
            "<figure><img src=\"{0}\" alt=\"{1}\"><figcaption>{1}</figcaption></figure>",
            escape(&f.file),
            escape(&f.caption)
        );
    }
}

/// The page's head, its style sheet and its title.
const HTML_HEAD: &str = concat!(
    "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>strand compare: model \
        against measurements</title>\n<style>\n",
    "body { font-family: sans-serif; margin: 2em auto; max-width: 960px; padding: 0 1em; }\n",
    "table { border-collapse: collapse; margin: 0.5em 0 1.5em; }\nth, td { border: 1px solid #bbb; padding: \
        0.2em 0.6em; text-align: right; }\n",
    "th { background: #eee; }\ntd:first-child, th:first-child { text-align: left; }\ntr.flag { background: \
        #fdd; }\n",
    "img { max-width: 100%; }\nfigure { margin: 1em 0; }\n</style>\n</head>\n<body>\n<h1>Model against \
        measurements</h1>\n",
);

/// The page: summaries, the worst observations, the trends and every plot, with nothing fetched
/// from elsewhere so the folder can be mailed or archived as it is.
fn html(
    c: &Comparison,
    trends: &[Trend],
    shapes: &[Shape],
    fits: &[Figure],
    residuals: &[Figure],
    model: &Model,
) -> String {
    let mut s = String::new();
    let experiments = c.by_experiment.len();
    s.push_str(HTML_HEAD);
    let _ = writeln!(
        s,
        "<p>Model <code>{}</code>: {} observations of {experiments} experiments, chi^2 = {:.6e}. z = (model - \
            measured) / uncertainty.</p>",
        escape(&model.path.display().to_string()),
        c.rows.len(),
        c.chi2
    );
    let summary_header = ["name", "n", "rms z", "mean |relative error| [%]"];
    let summary = |list: &[crate::measure::compare::Summary]| -> Vec<(bool, Vec<String>)> {
        list.iter()
            .map(|m| {
                (
                    false,
                    vec![
                        m.name.clone(),
                        m.n.to_string(),
                        format!("{:.3}", m.rms_z),
                        format!("{:.2}", 100.0 * m.mean_rel_error),
                    ],
                )
            })
            .collect()
    };
    s.push_str("<h2>Per experiment</h2>\n");
    table(&mut s, &summary_header, "flag", summary(&c.by_experiment));
    s.push_str("<h2>Per observable</h2>\n");
    table(&mut s, &summary_header, "flag", summary(&c.by_observable));

    let mut worst: Vec<&Row> = c.rows.iter().collect();
    worst.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    let _ = writeln!(s, "<h2>Where the model fails most ({} largest |z|)</h2>", worst.len().min(WORST));
    let worst_rows = worst.iter().take(WORST).map(|r| {
        (
            false,
            vec![
                r.experiment.clone(),
                r.observable.clone(),
                r.at_cell(),
                format!("{:.6e}", r.measured),
                format!("{:.6e}", r.model),
                format!("{:.4e}", r.residual),
                format!("{:.2}", r.z),
            ],
        )
    });
    table(&mut s, &["experiment", "observable", "at", "measured", "model", "residual", "z"], "flag", worst_rows);

    let _ = writeln!(s, "<h2>Trends of z with the covariates</h2>\n<p>Pearson r and least-squares slope of z against \
        each covariate that varies across the data; |r| &gt;= {TREND_R} is flagged as a trend.</p>");
    if trends.is_empty() {
        s.push_str("<p>No covariate varies across the data.</p>\n");
    } else {
        let rows = trends.iter().map(|t| {
            (
                t.trend,
                vec![
                    t.covariate.clone(),
                    t.n.to_string(),
                    format!("{:.3}", t.r),
                    format!("{:.4e}", t.slope),
                    if t.trend { "trend".into() } else { String::new() },
                ],
            )
        });
        table(&mut s, &["covariate", "n", "r", "slope", ""], "flag", rows);
    }
    let _ = writeln!(s, "<h2>Shape of the residuals</h2>\n<p>Trend, curvature, step between groups, or residuals \
        moving together within an experiment, each an F-test significant at {SHAPES_ALPHA} for all the tests \
        together.</p>");
    if shapes.is_empty() {
        s.push_str("<p>No trend, curvature, step or per-experiment shift is significant.</p>\n");
    } else {
        s.push_str("<ul>\n");
        for sh in shapes {
            let _ = writeln!(s, "<li>{}</li>", escape(&sh.text));
        }
        s.push_str("</ul>\n");
    }
    s.push_str("<h2>Model against data</h2>\n");
    figures(&mut s, fits);
    s.push_str("<h2>Residuals against the covariates</h2>\n");
    if residuals.is_empty() {
        s.push_str("<p>No covariate varies across the data.</p>\n");
    }
    figures(&mut s, residuals);
    s.push_str("</body>\n</html>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::compare::comparison;
    use crate::measure::observation::{Observable, Observation};

    /// Rows whose z equals `z`, one per experiment `e0`, `e1`, ...
    fn rows(z: &[f64]) -> Vec<Row> {
        let data: Vec<Observation> = (0..z.len())
            .map(|k| Observation {
                experiment: format!("e{k}"),
                observable: Observable { name: "stress".into(), at: Some(1.0), at2: None },
                value: 100.0,
                uncertainty: 1.0,
            })
            .collect();
        let values: Vec<f64> = z.iter().map(|z| 100.0 + z).collect();
        comparison(&data, &values).rows
    }

    fn covariate(name: &str, values: &[Option<f64>]) -> Covariate {
        Covariate { name: name.into(), axis: name.into(), values: values.to_vec() }
    }

    #[test]
    fn z_linear_in_a_covariate_is_a_trend_and_a_constant_has_no_row() {
        let x = [0.0, 1.0, 2.5, 4.0, 7.0];
        let covs =
            [covariate("x", &x.map(Some)), covariate("constant", &[Some(3.0); 5]), covariate("absent", &[None; 5])];
        let t = trends(&rows(&x.map(|x| 2.0 * x)), &covs);
        assert_eq!(t.len(), 1, "{t:?}");
        assert_eq!((t[0].covariate.as_str(), t[0].n, t[0].trend), ("x", 5, true));
        assert!((t[0].r - 1.0).abs() < 1e-12 && (t[0].slope - 2.0).abs() < 1e-12, "{t:?}");
    }

    #[test]
    fn trends_use_only_rows_with_a_value_and_weak_ones_are_not_flagged() {
        // z falls with x where x is known; the unknown rows would spoil the line if counted
        let t = trends(
            &rows(&[3.0, 1.0, -1.0, 50.0, -50.0]),
            &[covariate("x", &[Some(0.0), Some(1.0), Some(2.0), None, None])],
        );
        assert_eq!(t[0].n, 3);
        assert!((t[0].r + 1.0).abs() < 1e-12 && (t[0].slope + 2.0).abs() < 1e-12 && t[0].trend, "{t:?}");
        // z alternating with x: r = -2 / sqrt(20) = -0.45, not flagged
        let x4 = [Some(0.0), Some(1.0), Some(2.0), Some(3.0)];
        let t = trends(&rows(&[1.0, -1.0, 1.0, -1.0]), &[covariate("x", &x4)]);
        assert!(
            (t[0].r + 2.0 / 20f64.sqrt()).abs() < 1e-12 && (t[0].slope + 0.4).abs() < 1e-12 && !t[0].trend,
            "{t:?}"
        );
        // constant z moves with nothing
        let t = trends(&rows(&[2.0; 4]), &[covariate("x", &x4)]);
        assert_eq!((t[0].r, t[0].slope, t[0].trend), (0.0, 0.0, false));
    }

    const EXPERIMENTS: &str = r#"
[[experiment]]
id = "a"
rest_time = 0.0
age = 600.0
protocol = { phase = [{ kind = "sweep", rates = [5.0, 1.0], hold = 0.5 }] }
set = { "material.viscosity" = 10.0, "material.density" = 2000.0 }

[[experiment]]
id = "b"
rest_time = 300.0
age = 600.0
protocol = { phase = [{ kind = "sweep", rates = [5.0, 1.0], hold = 0.5 }] }
set = { "material.density" = 2000.0 }
"#;

    const MODEL: &str = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = \
        0.3\nviscosity = 20.0\nyield_stress = 100.0\n";

    fn setup() -> (Model, Experiments, Comparison) {
        let model = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let exps: Experiments = toml::from_str(EXPERIMENTS).unwrap();
        exps.validate().unwrap();
        let obs = |e: &str, at: f64, value: f64| Observation {
            experiment: e.into(),
            observable: Observable { name: "stress".into(), at: Some(at), at2: None },
            value,
            uncertainty: 2.0,
        };
        let data = [obs("a", 5.0, 150.0), obs("a", 1.0, 118.0), obs("b", 5.0, 260.0), obs("b", 1.0, 200.0)];
        let c = comparison(&data, &[145.0, 120.0, 200.0, 120.0]);
        (model, exps, c)
    }

    #[test]
    fn covariates_come_from_experiments_observables_and_set_keys() {
        let (model, exps, c) = setup();
        let covs = covariates(&c.rows, &exps, &model).unwrap();
        let names: Vec<&str> = covs.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["rest_time", "age", "at(stress)", "set.material.density", "set.material.viscosity"]);
        assert_eq!(covs[0].values, [Some(0.0), Some(0.0), Some(300.0), Some(300.0)]);
        assert_eq!(covs[2].values, [Some(5.0), Some(1.0), Some(5.0), Some(1.0)]);
        // b does not set the viscosity: it runs with the model's
        assert_eq!(covs[4].values, [Some(10.0), Some(10.0), Some(20.0), Some(20.0)]);
        // age and the density are the same everywhere
        let t: Vec<String> = trends(&c.rows, &covs).into_iter().map(|t| t.covariate).collect();
        assert_eq!(t, ["rest_time", "at(stress)", "set.material.viscosity"]);
    }

    #[test]
    fn a_second_coordinate_is_a_covariate_and_the_plot_axis() {
        let (model, exps, _) = setup();
        let obs = |e: &str, s: &str, value: f64| Observation {
            experiment: e.into(),
            observable: Observable::parse(s).unwrap(),
            value,
            uncertainty: 1e-4,
        };
        let data = [
            obs("a", "profile@0.075:-0.01", 0.010),
            obs("a", "profile@0.075:0.0", 0.012),
            obs("b", "profile@0.075:0.01", 0.011),
            obs("b", "height@0.075", 0.012),
        ];
        let c = comparison(&data, &[0.0101, 0.0125, 0.0118, 0.0121]);
        let covs = covariates(&c.rows, &exps, &model).unwrap();
        let names: Vec<&str> = covs.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "rest_time",
                "age",
                "at(profile)",
                "at2(profile)",
                "at(height)",
                "set.material.density",
                "set.material.viscosity"
            ]
        );
        assert_eq!(covs[3].values, [Some(-0.01), Some(0.0), Some(0.01), None]);
        assert_eq!(covs[3].axis, "profile: lateral position y [m]");
        // z grows with y: a trend the page shows, with both coordinates in its table
        let t = trends(&c.rows, &covs);
        assert!(t.iter().any(|t| t.covariate == "at2(profile)" && t.trend), "{t:?}");
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), &c, &exps, &model).unwrap();
        let page = std::fs::read_to_string(dir.path().join("index.html")).unwrap();
        assert!(page.contains("<td>0.075:0.01</td>") && page.contains("residuals_vs_at2_profile.png"), "{page}");
    }

    #[test]
    fn the_folder_has_a_page_showing_every_plot_with_text_escaped() {
        let (model, exps, mut c) = setup();
        for r in &mut c.rows[..2] {
            r.experiment = "a<&>\"".into();
        }
        let mut exps = exps;
        exps.experiment[0].id = "a<&>\"".into();
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("report");
        let (t, _) = write(&out, &c, &exps, &model).unwrap();
        assert_eq!(t.len(), 3);
        let page = std::fs::read_to_string(out.join("index.html")).unwrap();
        assert!(page.contains("a&lt;&amp;&gt;&quot;") && !page.contains("a<&>"), "{page}");
        let pngs: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .filter(|n| n.ends_with(".png"))
            .collect();
        assert_eq!(pngs.len(), 4, "{pngs:?}");
        for p in &pngs {
            assert!(page.contains(&format!("<img src=\"{p}\"")), "{p} not in the page");
        }
        assert!(
            out.join("residuals_vs_set.material.viscosity.png").exists()
                && out.join("residuals_vs_at_stress.png").exists()
        );
        let csv = std::fs::read_to_string(out.join("trends.csv")).unwrap();
        assert!(csv.starts_with("covariate,n,r,slope,trend\n") && csv.lines().count() == 4, "{csv}");
        // a file where the folder should be is named
        let e = write(&out.join("index.html"), &c, &exps, &model).unwrap_err().to_string();
        assert!(e.contains("index.html") && e.contains("not a directory"), "{e}");
    }

    #[test]
    fn file_names_are_plain_and_unique() {
        assert_eq!(file_stem("at(stress)"), "at_stress");
        assert_eq!(file_stem("set.print.path.0.speed"), "set.print.path.0.speed");
        let mut taken = HashSet::new();
        assert_eq!(unique_name(&mut taken, "a_b"), "a_b.png");
        assert_eq!(unique_name(&mut taken, "a_b"), "a_b_2.png");
    }
}
