//! A plan as text and JSON: the settings, the predicted layer and wall, the margins, and the
//! sensitivity of each target to each setting (the change of each for +1 % of the setting, and
//! the change of the setting that uses up a target's tolerance: where the process is fragile);
//! and the scenario with the settings applied.

use super::error::PlanError;
use super::targets::Setting;
use super::planner::Plan;
use std::path::Path;

/// One row of the sensitivity table: a target's change per +1 % of each free setting.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Sensitivity {
    pub target: &'static str,
    pub unit: &'static str,
    /// Per free setting: d target / d setting (SI units).
    pub derivative: Vec<f64>,
    /// Per free setting: the target's change for +1 % of the setting (in `unit`).
    pub per_percent: Vec<f64>,
    /// Per free setting: the change of the setting [%] that uses up the target's tolerance.
    pub tolerance_used_at: Vec<Option<f64>>,
}

/// The sensitivity table of the plan's point.
pub fn sensitivities(plan: &Plan) -> Vec<Sensitivity> {
    let b = plan.best();
    let l = &plan.targets.layer;
    let idx = Setting::index;
    let row = |target: &'static str, unit: &'static str, scale: f64, d: &dyn Fn(usize) -> f64, tol: Option<f64>| {
        let derivative: Vec<f64> = plan.free.iter().map(|(s, _)| d(idx(*s))).collect();
        let per_percent = plan.free.iter().zip(&derivative).map(|((s, _), g)| g * b.x[idx(*s)] * 0.01 * scale).collect();
        let tolerance_used_at = plan.free.iter().zip(&derivative).map(|((s, _), g)| tol.filter(|_| g.abs() > 0.0).map(|t| 100.0 * t / (g.abs() * b.x[idx(*s)]))).collect();
        Sensitivity { target, unit, derivative, per_percent, tolerance_used_at }
    };
    let g = &b.layer.gradient;
    let chain = |k: [f64; 3]| move |i: usize| k[0] * g[0][i] + k[1] * g[1][i] + if i == 0 { k[2] } else { 0.0 };
    let mut rows = vec![
        row("width", "mm", 1e3, &|i| g[0][i], Some(l.width_tolerance)),
        row("height", "mm", 1e3, &|i| g[1][i], Some(l.height_tolerance)),
    ];
    if plan.targets.wall.is_some() {
        rows.push(row("layer time", "s", 1.0, &chain(b.build.layer_time_gradient), None));
    }
    rows.push(row("build time", "s", 1.0, &chain(b.build.gradient), None));
    rows
}

/// The plan as text.
pub fn text(plan: &Plan) -> String {
    let b = plan.best();
    let l = &plan.targets.layer;
    let mut s = String::new();
    let runs = plan.history.len();
    s += &format!("plan: {} runs with gradients in {:.1} s\n", runs, plan.seconds);
    s += "settings:\n";
    for (k, st) in Setting::ALL.iter().enumerate() {
        let (u, f) = st.unit();
        match plan.free.iter().find(|(a, _)| a == st) {
            Some((_, [lo, hi])) => s += &format!("  {:<10} {:>9.2} {u:<5} (bounds {:.2} to {:.2})\n", st.name(), b.x[k] * f, lo * f, hi * f),
            None => s += &format!("  {:<10} {:>9.2} {u:<5} (held at the scenario's)\n", st.name(), b.x[k] * f),
        }
    }
    if let Some(w) = &plan.targets.wall {
        let bounds = plan.layer_time.map_or(String::new(), |[lo, hi]| format!(", bounds {lo} to {hi} s"));
        let why = match b.build.bound {
            super::build::Bound::Failure => "the shortest at which the wall stands",
            super::build::Bound::Nozzle => "the nozzle's time over the layer",
            super::build::Bound::LowerBound => "its lower bound",
            super::build::Bound::Simulated => "the shortest at which the simulated wall stood, --check-wall",
        };
        s += &format!("  layer time {:>9.2} s     ({why}{bounds})\n", b.build.layer_time);
        s += &format!("build: {:.0} layers of {:.2} mm to {} m in {:.0} s\n", w.design_height / b.layer.values[1], b.layer.values[1] * 1e3, w.design_height, b.build.build_time);
    } else {
        s += &format!("one layer: {:.2} s\n", b.build.layer_time);
    }
    s += "predicted layer and margins:\n";
    for (k, (name, t, tol)) in [("width", l.width, l.width_tolerance), ("height", l.height, l.height_tolerance)].into_iter().enumerate() {
        let v = b.layer.values[k];
        s += &format!("  {name:<7} {:>8.3} mm  target {:.3} +- {:.3} mm, margin {:.3} mm\n", v * 1e3, t * 1e3, tol * 1e3, (tol - (v - t).abs()) * 1e3);
    }
    if let (Some(w), Some(bd)) = (&plan.targets.wall, &b.build.buildable) {
        let mode = bd.mode.map_or("nothing fails below it".to_string(), |m| m.name().to_string());
        s += &format!(
            "predicted wall: stands to {:.3} m ({mode}), {:.2} x the design height {} m (safety factor asked {})\n",
            bd.height,
            bd.height / w.design_height,
            w.design_height,
            w.safety_factor
        );
        if let Some(g) = plan.wall.as_ref().filter(|g| g.wall.collapse_factor_scale() != 1.0) {
            s += &format!("  (the closed form's collapse factor x {:.4}, calibrated on the simulated wall)\n", g.wall.collapse_factor_scale());
        }
        if !plan.buckling_checked {
            s += "  (buckling not checked: the model's [material] has no bulk_modulus and poisson_ratio)\n";
        }
        if let Some(t) = trust(plan) {
            let scale = 100.0 * super::constraint::COLLAPSE_FACTOR_ACCURACY;
            let at = match t.layer_time {
                Some(lt) => format!("it stands to the design height x safety factor from a layer time of {lt:.1} s"),
                None => "no layer time within the bounds makes it stand to the design height x safety factor".into(),
            };
            s += &format!(
                "  trust: with the collapse factor {scale:.0} % lower (its accuracy against simulated walls) it stands to {:.3} m ({:.2} x the design height); {at}\n",
                t.height,
                t.height / w.design_height
            );
        }
    }
    s += "sensitivity: change per +1 % of each setting; in brackets the change of the setting that uses up the tolerance\n";
    s += &format!("  {:<11}", "");
    for (st, _) in &plan.free {
        s += &format!("{:>24}", st.name());
    }
    s += "\n";
    for r in sensitivities(plan) {
        s += &format!("  {:<11}", r.target);
        for (p, u) in r.per_percent.iter().zip(&r.tolerance_used_at) {
            let used = u.map_or(String::new(), |u| format!(" [{u:.1} %]"));
            s += &format!("{:>24}", format!("{p:+.4} {}{used}", r.unit));
        }
        s += "\n";
    }
    s
}

/// The wall by the closed form with Prandtl's collapse factor at the low end of its accuracy
/// (`constraint::COLLAPSE_FACTOR_ACCURACY`): how tall it stands at the plan's layer time, and the
/// shortest layer time within the bounds at which it stands to the design height x safety factor
/// even so.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Trust {
    pub factor_scale: f64,
    pub height: f64,
    pub layer_time: Option<f64>,
}

/// The plan's wall with the collapse factor at the low end of its accuracy; None without a wall.
pub fn trust(plan: &Plan) -> Option<Trust> {
    let (g, b) = (plan.wall.as_ref()?, plan.best());
    let factor_scale = 1.0 - super::constraint::COLLAPSE_FACTOR_ACCURACY;
    let low = g.wall.with_collapse_factor(factor_scale);
    let [w, h] = b.layer.values;
    let height = low.buildable(w, h, b.build.layer_time, 2.0 * g.need()).ok()?.height;
    let layer_time = low.shortest_layer_time(w, h, g.need(), g.layer_time).ok()?.ok();
    Some(Trust { factor_scale, height, layer_time })
}

/// The plan as JSON.
pub fn json(plan: &Plan) -> serde_json::Value {
    let b = plan.best();
    serde_json::json!({
        "settings": { "speed": b.x[0], "extrusion": b.x[1], "standoff": b.x[2], "layer_time": b.build.layer_time },
        "free": plan.free.iter().map(|(s, [lo, hi])| serde_json::json!({ "setting": s.name(), "lower": lo, "upper": hi })).collect::<Vec<_>>(),
        "layer": { "width": b.layer.values[0], "height": b.layer.values[1], "station": plan.line.station },
        "build": b.build,
        "sensitivity": sensitivities(plan),
        "wall_trust": trust(plan),
        "runs": plan.history.len(),
        "seconds": plan.seconds,
        "history": plan.history.iter().map(|e| serde_json::json!({ "x": e.x, "width": e.layer.values[0], "height": e.layer.values[1], "build_time": e.build.build_time, "accepted": e.accepted })).collect::<Vec<_>>(),
    })
}

/// Writes the scenario with the plan's settings applied to `out`, refusing an existing file
/// unless `overwrite`.
pub fn write_scenario(plan: &Plan, body: &str, out: &Path, overwrite: bool) -> Result<(), PlanError> {
    refuse_existing(out, overwrite)?;
    let b = plan.best();
    let head = format!(
        "# strand plan of {}: speed {} m/s, extrusion {} m/s, standoff {} m (print.z_offset), layer time {} s;\n# predicted width {} m, height {} m at x = {} m\n",
        plan.line.path.display(),
        b.x[0],
        b.x[1],
        b.x[2],
        b.build.layer_time,
        b.layer.values[0],
        b.layer.values[1],
        plan.line.station
    );
    std::fs::write(out, head + body).map_err(|e| PlanError::Io(format!("{}: {e}", out.display())))
}

/// An error when `path` exists and may not be overwritten.
pub fn refuse_existing(path: &Path, overwrite: bool) -> Result<(), PlanError> {
    if path.exists() && !overwrite {
        return Err(PlanError::Io(format!("{} exists: give --overwrite to replace it", path.display())));
    }
    Ok(())
}
