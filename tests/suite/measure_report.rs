//! `strand compare --report DIR` on a small rheometer campaign synthesised from a truth with
//! thixotropy and compared with the base model, which lacks it: the folder holds a page showing
//! every plot, the plots are real images, and z is flagged as falling with rest time (the more the
//! truth's structure builds up at rest, the more the model under-predicts).

use std::path::Path;
use crate::common::{strand, s};

/// Four flow curves after rests of 0 to 600 s, at ages that do not follow the rests; one
/// experiment sets a key the others take from the model, so that key varies too.
const EXPERIMENTS: &str = r#"
[[experiment]]
id = "R0"
protocol = "flow_curve.toml"
rest_time = 0.0
age = 600.0
observe = ["stress@5", "stress@1"]

[[experiment]]
id = "R120"
protocol = "flow_curve.toml"
rest_time = 120.0
age = 2400.0
set = { "material.density" = 2200.0 }
observe = ["stress@5", "stress@1"]

[[experiment]]
id = "R300"
protocol = "flow_curve.toml"
rest_time = 300.0
age = 1200.0
observe = ["stress@5", "stress@1"]

[[experiment]]
id = "R600"
protocol = "flow_curve.toml"
rest_time = 600.0
age = 1800.0
observe = ["stress@5", "stress@1"]
"#;

/// The `src` of every `<img>` on the page.
fn image_sources(page: &str) -> Vec<String> {
    page.split("<img src=\"").skip(1).map(|rest| rest.split('"').next().unwrap_or_default().to_string()).collect()
}

#[test]
fn report_folder_shows_every_plot_and_flags_the_trend_with_rest_time() {
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/campaign");
    let tmp = tempfile::tempdir().unwrap();
    std::fs::copy(campaign.join("flow_curve.toml"), tmp.path().join("flow_curve.toml")).unwrap();
    let exps = tmp.path().join("experiments.toml");
    std::fs::write(&exps, EXPERIMENTS).unwrap();
    let data = tmp.path().join("data.csv");
    let (code, _, err) = strand(&["synth", "--model", s(&campaign.join("truth_thixotropy.toml")), "--experiments", s(&exps), "--noise", "0.01", "--seed", "7", "--out", s(&data)]);
    assert_eq!(code, 0, "{err}");
    let base = campaign.join("base.toml");
    let compare = ["compare", "--model", s(&base), "--data", s(&data), "--experiments", s(&exps)];

    let dir = tmp.path().join("report");
    let (code, json, err) = strand(&[&compare[..], &["--report", s(&dir), "--json"]].concat());
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    for field in ["rows", "by_experiment", "by_observable", "chi2"] {
        assert!(v.get(field).is_some(), "no '{field}' in {v:#}");
    }
    let trends = v["trends"].as_array().unwrap_or_else(|| panic!("no trends in {v:#}"));
    let trend = |name: &str| trends.iter().find(|t| t["covariate"] == name).unwrap_or_else(|| panic!("no trend against {name}: {v:#}"));
    let rest = trend("rest_time");
    assert!(rest["trend"] == true && rest["r"].as_f64().unwrap() <= -0.5 && rest["slope"].as_f64().unwrap() < 0.0 && rest["n"] == 8, "{rest:#}");
    assert_eq!(trend("age")["trend"], false, "the truth does not age: {v:#}");
    trend("at(stress)");
    trend("set.material.density");

    let page = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let mut pngs: Vec<String> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).filter(|n| n.ends_with(".png")).collect();
    pngs.sort();
    let expected = ["model_vs_data_stress.png", "residuals_vs_age.png", "residuals_vs_at_stress.png", "residuals_vs_rest_time.png", "residuals_vs_set.material.density.png"];
    assert_eq!(pngs, expected);
    let mut shown = image_sources(&page);
    shown.sort();
    assert_eq!(shown, pngs, "the page shows other images than the folder holds:\n{page}");
    for p in &pngs {
        let bytes = std::fs::read(dir.join(p)).unwrap();
        assert!(bytes.len() > 1000 && bytes.starts_with(b"\x89PNG"), "{p}: {} bytes", bytes.len());
    }
    for section in ["Per experiment", "Per observable", "chi^2", "largest |z|", "Trends of z"] {
        assert!(page.contains(section), "no '{section}' on the page:\n{page}");
    }
    assert!(!page.contains("http://") && !page.contains("https://"), "the page fetches something:\n{page}");
    let csv = std::fs::read_to_string(dir.join("trends.csv")).unwrap();
    assert!(csv.starts_with("covariate,n,r,slope,trend\n") && csv.lines().any(|l| l.starts_with("rest_time,8,") && l.ends_with(",true")), "{csv}");

    // the text report carries the trends too, and a rerun into the same folder is fine
    let (code, text, err) = strand(&[&compare[..], &["--report", s(&dir)]].concat());
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("chi^2") && text.contains("trends of z"), "{text}");
    assert!(text.lines().any(|l| l.trim_start().starts_with("rest_time") && l.ends_with("trend")), "{text}");

    // without --report, the JSON is what it was
    let (code, json, err) = strand(&[&compare[..], &["--json"]].concat());
    assert_eq!(code, 0, "{err}");
    assert!(serde_json::from_str::<serde_json::Value>(&json).unwrap().get("trends").is_none());

    // a file where the folder should be is an error naming it, before anything runs
    let (code, out, err) = strand(&[&compare[..], &["--report", s(&data)]].concat());
    assert_ne!(code, 0, "{out}");
    assert!(err.contains(s(&data)) && err.contains("not a directory"), "{err}");
    assert!(out.is_empty(), "{out}");
}
