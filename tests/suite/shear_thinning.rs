//! The shear-thinning effect found on data with it hidden (issue 29): flow curves synthesised
//! from a Herschel-Bulkley truth (tau0 80 Pa, k 25 Pa s^n, n 0.6, 2 % noise), diagnosed from the
//! Bingham base model: `strand diagnose` must rank shear_thinning first, recommend it, and the
//! recalibration must find n within 10 %. Rheometer campaigns: seconds.

use std::path::Path;
use crate::common::{strand, s, measure_fixtures};

#[test]
fn hidden_shear_thinning_is_ranked_first_and_recalibrated() {
    let d = measure_fixtures("shear_thinning");
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data.csv");
    let exps = d.join("experiments.toml");
    let (code, _, err) = strand(&["synth", "--model", s(&d.join("truth_hb.toml")), "--experiments", s(&exps), "--noise", "0.02", "--seed", "7", "--out", s(&data)]);
    assert_eq!(code, 0, "{err}");
    let (out, base) = (tmp.path().join("best.toml"), d.join("base.toml"));
    let args = [
        "diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps),
        "--fit", "material.yield_stress,material.viscosity", "--json", "--out", s(&out),
    ];
    let (code, json, err) = strand(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    println!("{v:#}");
    let c = &v["candidates"][0];
    assert_eq!(c["effect"], "shear_thinning", "{v:#}");
    assert_eq!(c["test"], "score", "{c:#}");
    assert_eq!(c["recommended"], true, "{v:#}");
    assert_eq!(v["verdict"], "add shear_thinning", "{v:#}");
    let ratio = c["error_ratio"].as_f64().unwrap();
    assert!(ratio <= 0.3, "recalibrated error {ratio} of the base model's: {v:#}");
    let fitted = |name: &str| c["fitted"].as_array().unwrap().iter().find(|p| p[0] == name).unwrap()[1].as_f64().unwrap();
    let n = fitted("shear_thinning.n");
    assert!((n / 0.6 - 1.0).abs() < 0.1, "n {n} against the truth's 0.6");
    // with n free, the yield stress and the consistency come back too
    assert!((fitted("material.yield_stress") / 80.0 - 1.0).abs() < 0.1, "{c:#}");
    assert!((fitted("material.viscosity") / 25.0 - 1.0).abs() < 0.1, "{c:#}");
    // the written model has the effect on, at the fitted n
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("[effects.shear_thinning]"), "{text}");
}

#[test]
fn a_bingham_truth_does_not_call_for_shear_thinning() {
    // the same campaign from the base model's own law (n = 1): the score test in n is two-sided
    // (its null is inside its bounds) and must not flag it
    let d = measure_fixtures("shear_thinning");
    let tmp = tempfile::tempdir().unwrap();
    let truth = tmp.path().join("truth.toml");
    std::fs::write(&truth, std::fs::read_to_string(d.join("truth_hb.toml")).unwrap().replace("n = 0.6", "n = 1.0")).unwrap();
    let data = tmp.path().join("data.csv");
    let exps = d.join("experiments.toml");
    let (code, _, err) = strand(&["synth", "--model", s(&truth), "--experiments", s(&exps), "--noise", "0.02", "--seed", "7", "--out", s(&data)]);
    assert_eq!(code, 0, "{err}");
    let base = d.join("base.toml");
    let args = ["diagnose", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps), "--fit", "material.yield_stress,material.viscosity", "--json"];
    let (code, json, err) = strand(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let c = v["candidates"].as_array().unwrap().iter().find(|c| c["effect"] == "shear_thinning").unwrap();
    assert!(c["p_value"].as_f64().unwrap() > 0.01 && c["recommended"] == false, "{v:#}");
    assert_eq!(v["verdict"], "explained", "{v:#}");
}

#[test]
fn the_slump_front_against_the_flow_index_agrees_with_central_differences() {
    // fixtures/measure/slump (2 cm cells), cut to 0.1 s of flow, with the EVP material made
    // Herschel-Bulkley, and at n = 1 (the effect's null, where the score test reads d/dn): the
    // solver's adjoint in material.flow_index against central differences and the Taylor test
    use strand::grad::check::{check, REL_STEPS};
    use strand::grad::{gradient, GradOptions};
    use strand::observables::Objective;
    use strand::scenario::Scenario;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/slump/slump.toml");
    let base = std::fs::read_to_string(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = GradOptions { ram_bytes: 1 << 30, disk_bytes: 0, disk_dir: dir.path().to_path_buf(), threads: None, schedule: None, until_rest: None };
    let obj: Objective = "front".parse().unwrap();
    let wrt = ["material.flow_index".to_string()];
    for n in [0.6, 1.0] {
        let text = base.replace("end_time = 0.2\n", "end_time = 0.1\n").replace("yield_stress = 60.0\n", &format!("yield_stress = 60.0\nflow_index = {n:?}\n"));
        let sc = Scenario::parse(&text).unwrap();
        let r = gradient(&sc, &obj, &wrt, &opts).unwrap();
        let c = check(&sc, &obj, &r, None, &REL_STEPS).unwrap();
        for p in &c.params {
            println!("n = {n}: d front / d {} = {:.6e}, central differences {:?}", p.param, p.adjoint, p.central);
            let best = p.central.iter().map(|x| x.2).fold(f64::INFINITY, f64::min);
            assert!(best <= 1e-6, "n = {n}: {p:?}");
        }
        println!("n = {n}: Taylor slope {:.3} {:?}", c.taylor_slope, c.taylor);
        assert!((c.taylor_slope - 2.0).abs() <= 0.2, "n = {n}: Taylor slope {:.3}: {:?}", c.taylor_slope, c.taylor);
        assert!(r.gradient[0] != 0.0, "the front moves with n");
    }
}
