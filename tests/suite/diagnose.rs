//! The measurement loop on data with a hidden effect (issue 6): measurements synthesised from a
//! truth with an effect the base model lacks; `strand diagnose` must rank that effect first,
//! recommend it, and the recalibrated error must fall to 30 % of the base model's or less. A
//! truth without effects flags nothing; a truth whose cause is outside the effect library is
//! reported "unexplained". Rheometer campaigns run in milliseconds; the floor-friction and
//! compressibility cases run slump simulations with their adjoints (a few minutes each on 2
//! cores).

use crate::common::{strand, s, measure_fixtures};

/// Synthesised and diagnosed with the same experiments.
const EXPS: [&str; 2] = ["experiments.toml"; 2];

/// Synthesise data from `truth` (with `truth_exps`), then diagnose `base` against it with `exps`
/// (and `extra` arguments).
fn diagnose(dir: &str, truth: &str, [truth_exps, exps]: [&str; 2], noise: &str, jobs: &str, extra: &[&str]) -> serde_json::Value {
    let d = measure_fixtures(dir);
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join(truth)), "--experiments", s(&d.join(truth_exps)), "--noise", noise, "--seed", "7", "--out", s(&data), "--jobs", jobs]);
    assert_eq!(code, 0, "{err}");
    let out = tmp.path().join("best.toml");
    let (base, exps) = (d.join("base.toml"), d.join(exps));
    let args = [
        "diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps),
        "--fit", "material.yield_stress,material.viscosity", "--json", "--jobs", jobs, "--out", s(&out),
    ];
    let (code, json, err) = strand(&[&args[..], extra].concat());
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    println!("{truth}: {v:#}");
    if v["recommended"].is_string() {
        // the recommended model is written, with the effect on
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(text.contains(&format!("[effects.{}]", v["recommended"].as_str().unwrap())), "{text}");
    }
    v
}

fn assert_found(v: &serde_json::Value, effect: &str) {
    let c = v["candidates"].as_array().unwrap();
    // every effect of the library that is not in the model is a candidate, with the test it
    // got, its statistic, the error when fitted (null when not) and a verdict
    assert_eq!(c.len(), strand::measure::effects::REGISTRY.len(), "{v:#}");
    for x in c {
        assert!(x["score"].is_number() && x.get("fitted_chi2").is_some() && x["verdict"].is_string(), "{x:#}");
        let test = if ["elasticity", "compressibility", "wall_friction"].iter().any(|e| x["effect"] == *e) { "likelihood-ratio" } else { "score" };
        assert_eq!(x["test"], test, "{x:#}");
    }
    assert_eq!(c[0]["effect"], effect, "{v:#}");
    assert_eq!(v["verdict"], format!("add {effect}"), "{v:#}");
    assert_eq!(c[0]["recommended"], true, "{v:#}");
    let ratio = c[0]["error_ratio"].as_f64().unwrap();
    assert!(ratio <= 0.3, "recalibrated error {ratio} of the base model's: {v:#}");
}

#[test]
fn hidden_thixotropy_is_ranked_first_and_recalibrated() {
    let v = diagnose("campaign", "truth_thixotropy.toml", EXPS, "0.01", "1", &[]);
    assert_found(&v, "thixotropy");
    let fitted = v["candidates"][0]["fitted"].as_array().unwrap();
    let a = fitted.iter().find(|p| p[0] == "thixotropy.a_thix").unwrap()[1].as_f64().unwrap();
    assert!((a / 0.5 - 1.0).abs() < 0.1, "A_thix {a} against the truth's 0.5");
}

#[test]
fn hidden_ageing_is_ranked_first_and_recalibrated() {
    let v = diagnose("campaign", "truth_ageing.toml", EXPS, "0.01", "1", &[]);
    assert_found(&v, "ageing");
    // the exponential form is the same effect to first order: it scores the same, fits worse
    let c = v["candidates"].as_array().unwrap();
    assert_eq!(c[1]["effect"], "ageing_exp", "{v:#}");
    assert!(c[1]["fitted_chi2"].as_f64().unwrap() > c[0]["fitted_chi2"].as_f64().unwrap());
}

#[test]
fn hidden_elasticity_is_found_by_the_likelihood_ratio_and_recalibrated() {
    // start-up readings below yield: the base model's G (4e5 Pa, its stand-in for rigid) is
    // twenty times the truth's, and no gradient can be taken at G = infinity
    let v = diagnose("elastic", "truth_elasticity.toml", EXPS, "0.01", "1", &[]);
    assert_found(&v, "elasticity");
    let c = &v["candidates"][0];
    // the statistic is the drop in chi^2 the fit brought
    let drop = v["base_chi2"].as_f64().unwrap() - c["fitted_chi2"].as_f64().unwrap();
    assert!((c["score"].as_f64().unwrap() / drop - 1.0).abs() < 1e-9, "{c:#}");
    let g = c["fitted"].as_array().unwrap().iter().find(|p| p[0] == "elasticity.shear_modulus").unwrap()[1].as_f64().unwrap();
    assert!((g / 2e4 - 1.0).abs() < 0.05, "G {g} against the truth's 2e4");
}

#[test]
fn a_truth_without_effects_flags_nothing() {
    let v = diagnose("campaign", "truth_null.toml", EXPS, "0.01", "1", &[]);
    assert_eq!(v["verdict"], "explained", "{v:#}");
    assert!(v["recommended"].is_null());
    assert!(v["candidates"].as_array().unwrap().iter().all(|c| c["recommended"] == false && c["p_value"].as_f64().unwrap() > 0.01), "{v:#}");
}

#[test]
fn a_cause_outside_the_library_is_unexplained() {
    // batch-to-batch water content: every experiment's yield stress and viscosity scaled by its
    // own factor, unrelated to rest or age
    let v = diagnose("campaign", "truth_null.toml", ["experiments_batches.toml", "experiments.toml"], "0.01", "1", &[]);
    assert_eq!(v["verdict"], "unexplained", "{v:#}");
    assert!(v["base_p_value"].as_f64().unwrap() < 1e-6, "{v:#}");
    let pattern: Vec<&str> = v["pattern"].as_array().unwrap().iter().map(|p| p.as_str().unwrap()).collect();
    assert!(pattern.iter().any(|p| p.contains("within each experiment")), "{pattern:?}");
}

#[test]
fn one_step_leave_one_out_agrees_with_exact_refits_on_the_rheometer_campaign() {
    // Leave-one-out by one checked Gauss-Newton step from the full fit (the default) against
    // full refits (--loo-refits): the same verdicts and recommendations, the base model's
    // left-out error the same to BASE_LOO_TOLERANCE, and the candidates' close to the refits'.
    for truth in ["truth_thixotropy.toml", "truth_ageing.toml"] {
        let step = diagnose("campaign", truth, EXPS, "0.01", "1", &[]);
        let exact = diagnose("campaign", truth, EXPS, "0.01", "1", &["--loo-refits"]);
        assert_eq!(step["verdict"], exact["verdict"], "{truth}");
        let (a, b) = (step["candidates"].as_array().unwrap(), exact["candidates"].as_array().unwrap());
        let mut checked = 0;
        for (x, y) in a.iter().zip(b) {
            assert_eq!((&x["effect"], &x["recommended"], &x["verdict"].as_str().unwrap()[..10]), (&y["effect"], &y["recommended"], &y["verdict"].as_str().unwrap()[..10]), "{truth}");
            for (key, tolerance) in [("loo_chi2", LOO_TOLERANCE), ("loo_chi2_base", BASE_LOO_TOLERANCE)] {
                let (Some(u), Some(v)) = (x[key].as_f64(), y[key].as_f64()) else { continue };
                println!("{truth} {} {key}: one step {u:.6e}, refits {v:.6e} ({:+.2} %)", x["effect"], 100.0 * (u / v - 1.0));
                assert!((u / v - 1.0).abs() <= tolerance, "{truth} {} {key}: one step {u}, refits {v}", x["effect"]);
                checked += 1;
            }
        }
        assert!(checked >= 2, "{truth}: {checked}");
    }
}

/// Relative difference allowed between a candidate's one-step and refitted left-out chi^2.
const LOO_TOLERANCE: f64 = 0.3;
/// The same for the base model, which misses these data (reduced chi^2 in the hundreds): its
/// refits end within a tenth of a standard deviation scaled by the reduced chi^2
/// (`calibrate::CHI2_NEGLIGIBLE`), a few units of chi^2 from it (measured at 7fdb04f: the one
/// step's 0.09 % and 0.08 % above the refits' on the thixotropy and ageing truths).
const BASE_LOO_TOLERANCE: f64 = 5e-3;

#[test]
fn hidden_floor_friction_is_found_from_slump_flow() {
    // against the base model's no-slip floor, mu = infinity, where no gradient can be taken; the
    // runner-up effects are fitted without their leave-one-out refits, which would triple the
    // test's minutes
    let v = diagnose("slump", "truth_friction.toml", EXPS, "0.003", "2", &["--max-fitted", "1"]);
    assert_found(&v, "wall_friction");
    let c = &v["candidates"][0];
    let drop = v["base_chi2"].as_f64().unwrap() - c["fitted_chi2"].as_f64().unwrap();
    assert!((c["score"].as_f64().unwrap() / drop - 1.0).abs() < 1e-9, "{c:#}");
}

#[test]
fn hidden_compressibility_is_found_from_the_slumps_height() {
    // K five times below the base model's, with G held: the centre of mass sinks as the
    // material compresses, which neither the yield stress nor the viscosity can do
    let exps = ["experiments_volume.toml"; 2];
    let v = diagnose("slump", "truth_compressibility.toml", exps, "0.003", "2", &["--max-fitted", "1"]);
    assert_found(&v, "compressibility");
    let k = v["candidates"][0]["fitted"].as_array().unwrap().iter().find(|p| p[0] == "compressibility.bulk_modulus").unwrap()[1].as_f64().unwrap();
    // six readings, three parameters: K trades a little against the yield stress
    assert!((k / 2e5 - 1.0).abs() < 0.3, "K {k} against the truth's 2e5");
}

#[test]
fn calibrate_writes_the_fitted_model_and_its_convergence_plot() {
    let d = measure_fixtures("campaign");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join("truth_thixotropy.toml")), "--experiments", s(&d.join("experiments.toml")), "--noise", "0.01", "--seed", "3", "--out", s(&data)]);
    assert_eq!(code, 0, "{err}");
    // the base model with thixotropy switched on at its null, every parameter fitted
    let model = tmp.path().join("m.toml");
    std::fs::write(&model, std::fs::read_to_string(d.join("base.toml")).unwrap() + "[effects.thixotropy]\n").unwrap();
    let out = tmp.path().join("fitted.toml");
    let exps = d.join("experiments.toml");
    let args = ["calibrate", "--model", s(&model), "--data", s(&data), "--experiments", s(&exps), "--out", s(&out), "--json", "--fit"];
    let (code, json, err) = strand(&[&args[..], &["material.yield_stress,material.viscosity,thixotropy.a_thix,thixotropy.alpha"]].concat());
    assert_eq!(code, 0, "{err}");
    let f: serde_json::Value = serde_json::from_str(&json).unwrap();
    let (before, after) = (f["chi2_start"].as_f64().unwrap(), f["chi2"].as_f64().unwrap());
    // 18 readings with 1 % noise: chi^2 near its degrees of freedom once fitted
    assert!(after < 40.0 && before > 100.0 * after, "{f:#}");
    assert!(f["uncertainty"].as_array().unwrap().iter().all(|u| u.as_f64().is_some_and(|u| u > 0.0)), "{f:#}");
    let fitted = std::fs::read_to_string(&out).unwrap();
    assert!(fitted.contains("[effects.thixotropy]") && fitted.contains("a_thix"), "{fitted}");
    assert!(std::fs::metadata(out.with_extension("png")).unwrap().len() > 1000);
    // the fitted model compares as well as the fit said
    let (code, json, err) = strand(&["compare", "--model", s(&out), "--data", s(&data), "--experiments", s(&exps), "--json"]);
    assert_eq!(code, 0, "{err}");
    let c: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!((c["chi2"].as_f64().unwrap() / after - 1.0).abs() < 1e-6, "{c:#}");

    // bad names are named
    let (code, _, err) = strand(&[&args[..], &["material.yield_stres"]].concat());
    assert_ne!(code, 0);
    assert!(err.contains("unknown parameter 'material.yield_stres'"), "{err}");
    let (code, _, err) = strand(&[&args[..], &["ageing.rate"]].concat());
    assert_ne!(code, 0);
    assert!(err.contains("effect 'ageing' is not in the model"), "{err}");
}

/// Synthesise the campaign's data from `truth` (1 % noise), then run `strand diagnose` on `base`
/// with `extra` arguments; its JSON and the model it wrote.
fn diagnose_campaign(truth: &str, base: &str, extra: &[&str]) -> (serde_json::Value, String, tempfile::TempDir) {
    let d = measure_fixtures("campaign");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let exps = d.join("experiments.toml");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join(truth)), "--experiments", s(&exps), "--noise", "0.01", "--seed", "7", "--out", s(&data)]);
    assert_eq!(code, 0, "{err}");
    let (out, base) = (tmp.path().join("best.toml"), d.join(base));
    let args = ["diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps), "--fit", "material.yield_stress,material.viscosity", "--json", "--out", s(&out)];
    let (code, json, err) = strand(&[&args[..], extra].concat());
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    println!("{truth}: {v:#}");
    (v, std::fs::read_to_string(&out).unwrap_or_default(), tmp)
}

#[test]
fn an_effect_declared_in_the_model_file_lowers_the_error_to_the_noise() {
    // the yield stress grows as the square root of age, an effect the library does not have;
    // the base model declares the power law as a candidate (a and b free, b = 1 at its null)
    let (v, written, tmp) = diagnose_campaign("truth_yield_growth.toml", "base_yield_growth.toml", &[]);
    assert_eq!(v["verdict"], "add yield_growth", "{v:#}");
    let c = v["candidates"].as_array().unwrap();
    // beside the library's
    assert_eq!(c.len(), strand::measure::effects::REGISTRY.len() + 1, "{v:#}");
    let chosen = c.iter().find(|x| x["effect"] == "yield_growth").unwrap();
    let n = v["observations"].as_f64().unwrap();
    let after = chosen["fitted_chi2"].as_f64().unwrap() / n;
    assert!(v["base_chi2"].as_f64().unwrap() / n > 10.0 && after <= 1.5, "chi^2/n {after} with the declared effect: {v:#}");
    // linear ageing, equal to it at first order at the null, also lowers the error: the fit
    // decides, and its verdict says why it was not chosen (by leave-one-out, or by Akaike's
    // criterion when the declared effect was checked first)
    let ageing = c.iter().find(|x| x["effect"] == "ageing").unwrap();
    assert!(ageing["verdict"].as_str().unwrap().contains("not chosen"), "{ageing:#}");
    let akaike = |x: &serde_json::Value| x["fitted_chi2"].as_f64().unwrap() + 2.0 * x["fitted"].as_array().unwrap().len() as f64;
    match ageing["loo_chi2"].as_f64() {
        Some(loo) => assert!(loo > chosen["loo_chi2"].as_f64().unwrap(), "{ageing:#}"),
        None => assert!(akaike(ageing) >= akaike(chosen), "{ageing:#}"),
    }
    // the written model has it declared and on, and compares as the fit said
    assert!(written.contains("[effects.yield_growth]") && written.contains("age^b") && !written.contains("candidate"), "{written}");
    let model = tmp.path().join("best.toml");
    let d = measure_fixtures("campaign");
    let (code, json, err) = strand(&["compare", "--model", s(&model), "--data", s(&tmp.path().join("data.csv")), "--experiments", s(&d.join("experiments.toml")), "--json"]);
    assert_eq!(code, 0, "{err}");
    let cmp: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!((cmp["chi2"].as_f64().unwrap() / (after * n) - 1.0).abs() < 1e-6, "{cmp:#}");
    // a typing error in the declaration names the symbol, the expression and its line
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, std::fs::read_to_string(d.join("base_yield_growth.toml")).unwrap().replace("age^b", "agee^b")).unwrap();
    let (code, _, err) = strand(&["compare", "--model", s(&bad), "--data", s(&tmp.path().join("data.csv")), "--experiments", s(&d.join("experiments.toml"))]);
    assert_ne!(code, 0);
    assert!(err.contains("unknown symbol 'agee'") && err.contains("'yield_stress * (1 + a * agee^b)'") && err.contains("(line 12)"), "{err}");
}

#[test]
fn two_hidden_effects_are_resolved_by_rounds() {
    // thixotropy and ageing of the viscosity: one round finds one, the next the other
    let (v, written, _tmp) = diagnose_campaign("truth_two_effects.toml", "base.toml", &["--rounds", "4"]);
    let added: Vec<&str> = v["added"].as_array().unwrap().iter().map(|e| e.as_str().unwrap()).collect();
    let mut sorted = added.clone();
    sorted.sort();
    assert_eq!(sorted, ["thixotropy", "viscosity_ageing"], "{v:#}");
    assert_eq!(v["complete"], true, "{v:#}");
    let fin = v["final_chi2_per_observation"].as_f64().unwrap();
    assert!(fin <= 1.5, "final chi^2/n {fin}: {v:#}");
    // the error falls round by round, and the last round finds nothing more
    let rounds = v["rounds"].as_array().unwrap();
    assert_eq!(rounds.len(), 3, "{v:#}");
    for r in &rounds[..2] {
        assert!(r["chi2_per_observation_after"].as_f64().unwrap() < 0.5 * r["chi2_per_observation_before"].as_f64().unwrap(), "{r:#}");
    }
    assert_ne!(rounds[2]["diagnosis"]["verdict"].as_str().unwrap().split(' ').next(), Some("add"), "{v:#}");
    assert!(written.contains("[effects.thixotropy]") && written.contains("[effects.viscosity_ageing]"), "{written}");
}

/// Structuration from failure heights: the layer and time at which a wall printed at three build
/// rates fails (fixtures/measure/failure: 10 mm cells, a layer every 0.65, 1.0 and 1.6 s),
/// synthesised at 5 mm cells (finer than the model's, as measured walls would be) from a truth
/// with a structural build-up at rest (A_thix = 40 Pa/s: failure layers 5, 6, 7 there; 5, 6, 8 at
/// 10 mm) and diagnosed from a base model without it. Structuration gains A_thix T of strength
/// under each layer, so the failure comes later the slower the print; a yield stress or a Coulomb
/// floor moves it at every rate alike (docs/failure.md), so the campaign itself tells them apart.
/// The failure observables have no adjoint: their Jacobian columns are central differences of
/// forward runs (measure/sensitivity.rs). One candidate is fitted, without leave-one-out, and
/// every fit stops after 3 iterations (4 found the same error ratio, with a candidate fit of
/// 89 s where 3 take 49 s). Measured at 6bafe18 beside builds and other runs: 387 s wall (base fit
/// 47 s, score tests 124 s, likelihood-ratio fits 134 s, the candidate's fit 49 s); thixotropy
/// first, error x 0.068; a Coulomb floor fitted does not lower it (x 1.02).
#[test]
fn hidden_structuration_is_found_from_failure_heights() {
    let d = measure_fixtures("failure");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let exps = d.join("experiments.toml");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join("truth_thixotropy.toml")), "--experiments", s(&d.join("experiments_fine.toml")), "--noise", "0.01", "--seed", "7", "--out", s(&data), "--jobs", "2"]);
    assert_eq!(code, 0, "{err}");
    let base = d.join("base.toml");
    let args = [
        "diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps),
        "--fit", "material.yield_stress", "--json", "--jobs", "2", "--max-fitted", "1", "--no-loo", "--max-iterations", "3",
    ];
    let (code, json, err) = strand(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    println!("{v:#}");
    let c = &v["candidates"][0];
    assert_eq!(c["effect"], "thixotropy", "{v:#}");
    assert_eq!(v["verdict"], "add thixotropy", "{v:#}");
    let ratio = c["error_ratio"].as_f64().unwrap();
    assert!(ratio <= 0.3, "recalibrated error {ratio} of the base model's: {v:#}");
}

/// A failure layer is a staircase in a parameter: a difference over a step that crosses no stair
/// is 0. At the null of a structuration rate (A_thix = 0, its scale 0.5 Pa/s) no failure layer of
/// the failure campaign's mid-rate wall moves, so the step widens until the layer has moved by
/// two stairs: the column is then positive (a mortar that structures at rest stands longer) and
/// near the staircase's mean slope (measured: 2 layers over 32 Pa/s, 0.0625; layer 6 at 40 Pa/s,
/// 0.05 a layer per Pa/s).
#[test]
fn a_failure_layers_column_resolves_its_staircase() {
    use strand::measure::{experiments::Experiments, model::Model, observation::Observable, sensitivity};
    let d = measure_fixtures("failure");
    let exps = Experiments::load(&d.join("experiments.toml")).unwrap();
    let text = std::fs::read_to_string(d.join("truth_thixotropy.toml")).unwrap().replace("a_thix = 40.0", "a_thix = 0.0");
    let model = Model::from_table(&text.parse().unwrap()).unwrap();
    let wanted = [Observable::parse("failure_layer").unwrap(), Observable::parse("failure_time").unwrap()];
    let names = ["thixotropy.a_thix".to_string()];
    let got = sensitivity::one(&model, &exps, "mid", &wanted, (Some(&names), Some(1)), None).unwrap();
    let (layer, dlayer) = (got[0].value, got[0].gradient.as_ref().unwrap()[0]);
    let dtime = got[1].gradient.as_ref().unwrap()[0];
    assert_eq!(layer, 4.0, "{got:?}");
    assert!(dlayer > 0.025 && dlayer < 0.2, "d failure_layer / d A_thix = {dlayer} (mean slope about 0.05): {got:?}");
    assert!(dtime > 0.0, "{got:?}");
}

/// A fit made for the optimum its secant Jacobian sees (`uncertainties` off, `stop_on_secant`
/// on: after a recommended candidate, diagnose fits the others so) and then finished stops on
/// the engine's exact Jacobian at its end, as a fit made with uncertainties does: the small
/// slumps (simulations, so secant steps), fitted from the base model away from their truth.
#[test]
fn a_fit_finished_on_an_exact_jacobian_ends_where_a_full_fit_does() {
    use strand::measure::calibrate::calibrate;
    use strand::measure::diagnose::finish;
    use strand::measure::campaign::{Campaign, FitOptions};
    use strand::measure::sensitivity::{evaluate, Differences};
    use strand::measure::{experiments::Experiments, model::Model, synth::synth};
    let d = measure_fixtures("slump");
    let exps = Experiments::load(&d.join("experiments.toml")).unwrap();
    // slump.toml's own material
    let truth = "[material]\nkind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1.0e6\npoisson_ratio = 0.3\nviscosity = 20.0\nyield_stress = 60.0\n";
    let truth = Model::from_table(&truth.parse().unwrap()).unwrap();
    let data = synth(&truth, &exps, 0.003, 7, 2).unwrap();
    let start = Model::load(&d.join("base.toml")).unwrap();
    let names = ["material.yield_stress".to_string(), "material.viscosity".to_string()];
    let opts = FitOptions { jobs: 2, ..FitOptions::default() };
    let c = Campaign::new(&exps, &data, &opts);
    let full = calibrate(&c, &start, &names).unwrap();
    let lazy_opts = FitOptions { uncertainties: false, stop_on_secant: true, ..opts.clone() };
    let lazy = calibrate(&c.with_opts(&lazy_opts), &start, &names).unwrap();
    let finished = finish(&c, lazy.clone()).unwrap();
    println!("full: {:?} +/- {:?}, chi^2 {} ({:?})", full.values, full.uncertainty, full.chi2, full.history);
    println!("lazy: {:?}, chi^2 {} ({:?})", lazy.values, lazy.chi2, lazy.history);
    println!("finished: {:?} +/- {:?}, chi^2 {} ({:?})", finished.values, finished.uncertainty, finished.chi2, finished.history);
    // the lazy fit ends on a secant Jacobian, the finished one on the engine's at its values, to
    // the bit
    let exact_at = |f: &strand::measure::calibrate::Fit| evaluate(&f.model, &data, &exps, (Some(&names), strand::measure::runner::Jobs::new(2)), Some((&f.model_values, &Differences::Central))).unwrap().jacobian.unwrap();
    assert_ne!(lazy.jacobian, exact_at(&lazy), "the lazy fit ended on an exact Jacobian: nothing to finish");
    assert_eq!(finished.jacobian, exact_at(&finished));
    // it keeps the lazy fit's start and history, and goes on only downhill
    assert_eq!((finished.start.clone(), finished.chi2_start), (lazy.start.clone(), lazy.chi2_start));
    assert_eq!(finished.history[..lazy.history.len()], lazy.history[..]);
    assert!(finished.chi2 <= lazy.chi2, "{} against {}", finished.chi2, lazy.chi2);
    // and it ends where the full fit ends, within its uncertainties, which are the full fit's
    for (i, name) in names.iter().enumerate() {
        let (u, v) = (finished.uncertainty[i], full.uncertainty[i]);
        assert!(u.is_finite() && u > 0.0 && (u / v - 1.0).abs() < 0.2, "{name}: {u} against {v}");
        assert!((finished.values[i] - full.values[i]).abs() < 2.0 * v, "{name}: {} against {} +/- {v}", finished.values[i], full.values[i]);
    }
}
