//! The plan as one self-contained HTML page (`OUT.html` beside the planned scenario): the plan's
//! report as `report.rs` gives it (or why no setting met the targets), how far the wall's closed
//! form can be trusted, the simulated walls when `--check-wall` ran, and with `--map` the
//! printability map: its contour plots, embedded in the page (`output::html`), and a table of its
//! points, those meeting the targets shaded. Nothing is fetched from elsewhere and no file
//! beside it is needed, so the page can be moved, mailed or archived alone.

use super::error::PlanError;
use super::map::Map;
use super::planner::Plan;
use super::targets::Targets;
use super::wall_rounds::Rounds;
use crate::output::html::{embedded_png, escape, table};
use std::fmt::Write as _;
use std::path::Path;

/// What the page shows besides the plan.
pub struct Extras<'a> {
    /// Why no setting met the targets (the plan's report is then the best point's).
    pub missed: Option<&'a PlanError>,
    /// The walls simulated with `--check-wall`, round after round.
    pub wall: Option<&'a Rounds>,
    /// The map and its PNG.
    pub map: Option<(&'a Map, &'a Path)>,
}

const HEAD: &str = concat!(
    "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>strand plan</title>\n<style>\n",
    "body { font-family: sans-serif; margin: 2em auto; max-width: 1320px; padding: 0 1em; }\n",
    "table { border-collapse: collapse; margin: 0.5em 0 1.5em; }\nth, td { border: 1px solid #bbb; padding: 0.2em 0.6em; text-align: right; }\n",
    "th { background: #eee; }\ntr.feasible { background: #dfd; }\npre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; }\n",
    ".missed { color: #a00; }\nimg { max-width: 100%; }\nfigure { margin: 1em 0; }\n</style>\n</head>\n<body>\n<h1>Print settings planned by strand</h1>\n",
);

/// Writes the page to `path`.
pub fn write(plan: &Plan, extras: &Extras, path: &Path) -> Result<(), PlanError> {
    let mut s = String::from(HEAD);
    let _ = writeln!(s, "<p>Print <code>{}</code>, layer observed at x = {} m.</p>", escape(&plan.line.path.display().to_string()), plan.line.station);
    if let Some(e) = extras.missed {
        let _ = writeln!(s, "<p class=\"missed\">{}</p>\n<h2>The closest setting found</h2>", escape(&e.to_string()));
    } else {
        s.push_str("<h2>The plan</h2>\n");
    }
    let _ = writeln!(s, "<pre>{}</pre>", escape(&super::report::text(plan)));
    if plan.wall.is_some() {
        let _ = writeln!(s, "<h2>The wall's closed form</h2>\n<p>{}</p>", escape(super::constraint::TRUST));
    }
    if let Some(c) = extras.wall {
        let _ = writeln!(s, "<h2>The wall simulated</h2>\n<pre>{}</pre>", escape(&super::wall_rounds::text(c)));
    }
    if let Some((m, png)) = extras.map {
        s.push_str(&map_section(m, &plan.targets, plan.line.nozzle, png)?);
    }
    s.push_str("</body>\n</html>\n");
    std::fs::write(path, s).map_err(|e| PlanError::Io(format!("{}: {e}", path.display())))
}

/// The map's section: what it spans and holds, its plots (the PNG `png`, embedded) and its
/// points, with the groups V/U and H/D for a nozzle `diameter` [m].
pub fn map_section(m: &Map, targets: &Targets, diameter: f64, png: &Path) -> Result<String, PlanError> {
    let mut s = String::new();
    let s = &mut s;
    let [a, b] = m.axes;
    let l = &targets.layer;
    let feasible = m.points.iter().filter(|p| p.feasible).count();
    let wall = targets.wall.as_ref().map_or(String::new(), |w| format!("; a wall standing to {} m x {}", w.design_height, w.safety_factor));
    let _ = writeln!(
        s,
        "<h2>Printability map</h2>\n<p>{} against {}, {} x {} points, the other settings at the plan's point. Targets: width {:.2} &plusmn; {:.2} mm, height {:.2} &plusmn; {:.2} mm at the station{}. {feasible} of {} points meet them. In the plots the iso-lines are labelled with their values, each target's edges are bold, the region that meets every target (the fields bilinear between the points) is shaded green, and the plan's point is the red cross.</p>",
        escape(&a.quantity.label(&m.marked)),
        escape(&b.quantity.label(&m.marked)),
        a.n,
        b.n,
        l.width * 1e3,
        l.width_tolerance * 1e3,
        l.height * 1e3,
        l.height_tolerance * 1e3,
        escape(&wall),
        m.points.len()
    );
    s.push_str(&embedded_png(png, "contour plots of the layer's width and height and the wall's buildable height").map_err(|e| PlanError::Io(format!("{}: {e}", png.display())))?);
    let d = diameter;
    let rows = m.points.iter().map(|p| {
        let bh = p.buildable.map_or("-".to_string(), |b| format!("{:.3}", b.height));
        let meets = match (p.feasible, &p.error) {
            (_, Some(e)) => format!("no ({e})"),
            (true, None) => "yes".into(),
            (false, None) => "no".into(),
        };
        let plan_mark = if p.x == m.marked { " (the plan)" } else { "" };
        let cells = [p.x[0] * 1e3, p.x[1] * 1e3, p.x[2] * 1e3].into_iter().map(|v| format!("{v:.2}")).chain([format!("{:.3}", p.x[0] / p.x[1]), format!("{:.3}", p.x[2] / d), format!("{:.3}", p.width * 1e3), format!("{:.3}", p.height * 1e3), bh, meets + plan_mark]);
        (p.feasible, cells.collect())
    });
    table(s, &["speed [mm/s]", "extrusion [mm/s]", "standoff [mm]", "V/U", "H/D", "width [mm]", "height [mm]", "buildable [m]", "meets the targets"], "feasible", rows);
    let _ = writeln!(s, "<p>The plan's point: speed {:.2} mm/s, extrusion {:.2} mm/s, standoff {:.2} mm (V/U {:.3}, H/D {:.3}, D = {:.1} mm).</p>", m.marked[0] * 1e3, m.marked[1] * 1e3, m.marked[2] * 1e3, m.marked[0] / m.marked[1], m.marked[2] / d, d * 1e3);
    Ok(std::mem::take(s))
}
