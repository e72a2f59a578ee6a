//! The wall checked by simulation (`strand plan --check-wall`): a reduced wall of the planned
//! layer, simulated with the failure detector (`crate::failure`), confirms or refutes what the
//! closed form (`constraint.rs`) says of the plan's layer time.
//!
//! The claim checked is the closed form's: at layer time T, a wall of layers w x h stands to
//! the design height times the safety factor, H = design_height x safety_factor. The check stacks
//! N = ceil(H / h) layers of the print's own pass (its moves up to its last extruding one,
//! pauses dropped; each layer one h higher, printed back along the pass from where the last
//! ended, [`wall_path`]) at the planned settings, and says the wall stands when the detector
//! finds no failure up to one layer time after the last layer was laid. The factor is on the height, as the closed form's
//! constraint puts it: the wall must reach H, not the design height alone.
//!
//! What is reduced, openly:
//! - Time. Layer after layer at T (tens of seconds) is out of reach of an explicit step of a
//!   fraction of a millisecond, so the rest between layers is compressed by m = T / T_r, with
//!   T_r the nozzle's time over a layer and its climb plus [`SETTLE`]: layers start T_r
//!   apart, and the material's whole age clock runs m times faster ([`AGE_RATES`] times m,
//!   [`AGES`] over m: thixotropy's build-up, every age law of the stiffness and the strength), so
//!   each layer's yield stress and stiffness when the next comes are the full wall's. The print's
//!   fixed step, chosen for the fresh material, would not stay stable as the stiffness grows m
//!   times faster (on `fixtures/plan` it blew up at t = 23 s), so it is divided by the growth of
//!   the elastic wave speed from the fresh material to the wall's oldest (the same Courant
//!   number throughout); a wall whose stiffness kept its real rate would be a far younger,
//!   softer wall than the one planned. The deposit itself is printed at the planned speed and flow, so it
//!   builds up m times faster while it is laid (at the fixture's 2 Pa/s and m = 10, 20 Pa over a
//!   second). Sound when the wall settles within T_r (quasi-static, the detector's own premise);
//!   viscous stresses are not scaled.
//! - The wall's length: a slice of a long straight wall, the print's own pass (a plan's print is
//!   a short line along x) between two symmetry planes at its ends ([`mirror_ends`]), as the
//!   closed forms' long wall (plane strain). A wall of the pass alone, its ends free, is no such
//!   wall: each pass drags its top along x, and on `fixtures/plan` its upper half slid off along
//!   the pass and lost a layer at the station at 103 mm where the slice, at the same layer time
//!   (37 s), stood its 154 mm. The slice still stands on the rough base, which the closed form's
//!   squeeze leaves out: on `fixtures/plan` (4 mm cells) a wall of six layers stood 32 mm where
//!   the closed form has it collapse at 19 mm. A wall that stands confirms the plan no more
//!   strictly than that; one that fails refutes it.
//!
//! The wall's memory is planned before it allocates (`Simulation::new`) and refused over the
//! print's `[memory] budget`.

use super::constraint::Buildable;
use super::error::PlanError;
use super::planner::Plan;
use crate::failure::Failure;
use crate::print::toolpath::{Segment, Toolpath};
use toml::{Table, Value};

/// The rest each reduced layer has after the nozzle's moves, before the next layer [s]: longer
/// than the settling of a fresh layer on the fixtures (under a second, `crate::failure`) and
/// than the detector's window.
pub const SETTLE: f64 = 0.6;

/// The material keys of its growth with age [per s], which the reduced wall's compressed time
/// multiplies: thixotropy's build-up, and the rates of the age laws of the bulk modulus (EVP
/// Bingham) and of an early-age solid's Young's modulus, cohesion and friction angle.
pub const AGE_RATES: &[&str] = &[
    "a_thix",
    "bulk_modulus_rate",
    "bulk_modulus_late_rate",
    "youngs_modulus_rate",
    "youngs_modulus_late_rate",
    "cohesion_rate",
    "cohesion_late_rate",
    "friction_angle_rate",
    "friction_angle_late_rate",
];

/// The material keys that are ages [s], which the compressed time divides: a law at age a / m
/// with its rates m times larger has the value the real law has at age a.
pub const AGES: &[&str] = &["age_at_start", "max_age", "bulk_modulus_transition_age", "youngs_modulus_transition_age", "cohesion_transition_age", "friction_angle_transition_age"];

/// The reduced wall and what its simulation found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WallCheck {
    /// Layers stacked and their nominal height [m] (the planned layer's height at the station).
    pub layers: usize,
    pub layer_height: f64,
    /// The height the wall must stand to [m]: design height x safety factor.
    pub need: f64,
    /// The layer time checked [s] and the one simulated [s]; the material's age clock runs
    /// `compression` times faster.
    pub layer_time: f64,
    pub simulated_layer_time: f64,
    pub compression: f64,
    /// What the closed form says of the same wall.
    pub closed_form: Buildable,
    /// The detector's failure, None when the wall stood.
    pub failure: Option<Failure>,
    pub stands: bool,
    /// The run's steps and wall time [s].
    pub steps: u64,
    pub seconds: f64,
}

/// A value of `t` as a float or an integer.
fn number(v: &Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

fn point(v: &Value) -> Option<[f64; 3]> {
    let a = v.as_array()?;
    Some([number(a.first()?)?, number(a.get(1)?)?, number(a.get(2)?)?])
}

fn array(p: [f64; 3]) -> Value {
    Value::Array(p.iter().map(|&x| Value::Float(x)).collect())
}

/// A segment as the TOML of a `[print] path` (the kinds a reduced wall uses).
fn segment_value(s: &Segment) -> Value {
    let mut t = Table::new();
    let mut put = |k: &str, v: Value| {
        t.insert(k.into(), v);
    };
    put("kind", Value::String(s.kind_name().into()));
    match s {
        Segment::Print { to, speed, extrusion } => {
            put("to", array(*to));
            put("speed", Value::Float(*speed));
            put("extrusion", Value::Float(*extrusion));
        }
        Segment::Travel { to, speed } => {
            put("to", array(*to));
            put("speed", Value::Float(*speed));
        }
        Segment::Pause { duration } => put("duration", Value::Float(*duration)),
        Segment::Layer { dz, speed } => {
            put("dz", Value::Float(*dz));
            if let Some(v) = speed {
                put("speed", Value::Float(*v));
            }
        }
        Segment::Arc { .. } => unreachable!("a reduced wall's pass has no arcs (Line refuses extruding arcs; travel arcs are refused below)"),
    }
    Value::Table(t)
}

/// One pass of the print: its moves up to its last extruding one, pauses dropped, refused with
/// layer changes or arcs (a pass is one layer of straight moves).
fn pass(path: &[Segment]) -> Result<Vec<Segment>, PlanError> {
    let last = path.iter().rposition(|s| matches!(s, Segment::Print { .. })).ok_or_else(|| PlanError::Unsupported("--check-wall: the print has no extruding move".into()))?;
    let moves: Vec<Segment> = path[..=last].iter().filter(|s| !matches!(s, Segment::Pause { .. })).cloned().collect();
    if moves.iter().any(|s| matches!(s, Segment::Layer { .. } | Segment::Arc { .. })) {
        return Err(PlanError::Unsupported("--check-wall stacks one pass of straight moves; this print changes layer or moves along arcs (not yet)".into()));
    }
    Ok(moves)
}

/// `s` moved up by `dz`.
fn raised(s: &Segment, dz: f64) -> Segment {
    let up = |p: &[f64; 3]| [p[0], p[1], p[2] + dz];
    match s {
        Segment::Print { to, speed, extrusion } => Segment::Print { to: up(to), speed: *speed, extrusion: *extrusion },
        Segment::Travel { to, speed } => Segment::Travel { to: up(to), speed: *speed },
        other => other.clone(),
    }
}

/// The reduced wall's path from `start`: `layers` passes `h` apart, starting `period` apart,
/// and a last rest of `period`. After each pass the nozzle climbs h at `climb` speed and prints
/// the next layer back along the pass: a nozzle travelling back to the pass's start would pass
/// over the fresh layer, and its tube, which moves the grid's nodes inside it at its own
/// velocity, would drag that layer's top along. The time between two layers at a station a
/// distance d from the pass's middle alternates by +-2 d / v (v the pass's speed) about
/// `period`, its mean.
fn wall_path(start: [f64; 3], one: &[Segment], layers: usize, h: f64, period: f64, climb: f64) -> Result<Vec<Segment>, PlanError> {
    let back = backwards(start, one);
    let mut path: Vec<Segment> = Vec::new();
    let end_of = |path: &[Segment]| Toolpath::from_segments(start, path).map(|t| t.end_time()).map_err(|e| PlanError::Unsupported(format!("--check-wall: {e}")));
    for k in 0..layers {
        if k > 0 {
            path.push(Segment::Layer { dz: h, speed: Some(climb) });
            let wait = k as f64 * period - end_of(&path)?;
            if wait < -1e-9 * period {
                return Err(PlanError::Unsupported(format!("--check-wall: a layer's moves take longer than the simulated layer time {period} s")));
            }
            if wait > 0.0 {
                path.push(Segment::Pause { duration: wait });
            }
        }
        let pass = if k % 2 == 0 { one } else { &back };
        path.extend(pass.iter().map(|s| raised(s, k as f64 * h)));
    }
    path.push(Segment::Pause { duration: period });
    Ok(path)
}

/// The pass `one` from `start` run backwards: the same moves, last first, each ending where it
/// began (the pass's moves are straight: [`pass`] refuses the rest).
fn backwards(start: [f64; 3], one: &[Segment]) -> Vec<Segment> {
    let mut from = start;
    let mut ends = Vec::with_capacity(one.len());
    for s in one {
        ends.push(from);
        if let Segment::Print { to, .. } | Segment::Travel { to, .. } = s {
            from = *to;
        }
    }
    one.iter()
        .zip(ends)
        .rev()
        .map(|(s, to)| match s {
            Segment::Print { speed, extrusion, .. } => Segment::Print { to, speed: *speed, extrusion: *extrusion },
            Segment::Travel { speed, .. } => Segment::Travel { to, speed: *speed },
            other => other.clone(),
        })
        .collect()
}

/// The time one pass and the climb after it take, climbing at `climb` [s].
fn pass_period(start: [f64; 3], one: &[Segment], h: f64, climb: f64) -> Result<f64, PlanError> {
    let mut moves = one.to_vec();
    moves.push(Segment::Layer { dz: h, speed: Some(climb) });
    Ok(Toolpath::from_segments(start, &moves).map_err(|e| PlanError::Unsupported(format!("--check-wall: {e}")))?.end_time())
}

/// The reduced wall's scenario for `plan` at layer time `layer_time`, with its layers, layer
/// height, simulated layer time and compression.
pub fn scenario(plan: &Plan, layer_time: f64) -> Result<(Table, usize, f64, f64, f64), PlanError> {
    let wall = plan.targets.wall.as_ref().ok_or_else(|| PlanError::Targets("--check-wall: the targets have no [wall]: there is no wall to check".into()))?;
    let b = plan.best();
    let h = b.layer.values[1];
    let need = wall.design_height * wall.safety_factor;
    let layers = (need / h * (1.0 - 1e-12)).ceil().max(1.0) as usize;
    let mut t: Table = plan.line.scenario_text(&b.x)?.parse().map_err(|e| PlanError::Unsupported(format!("--check-wall: the planned scenario: {e}")))?;
    let bad = |what: &str| PlanError::Unsupported(format!("--check-wall: the planned scenario's {what}"));
    let print = t.get("print").and_then(Value::as_table).ok_or_else(|| bad("[print] table"))?;
    let start = print.get("start").and_then(point).ok_or_else(|| bad("print.start"))?;
    let path: Vec<Segment> = print.get("path").and_then(Value::as_array).ok_or_else(|| bad("print.path"))?.iter().map(|v| v.clone().try_into::<Segment>()).collect::<Result<_, _>>().map_err(|e| bad(&format!("print.path: {e}")))?;
    let one = pass(&path)?;
    mirror_ends(&mut t, start, &one, plan.line.station)?;
    let climb = b.x[0];
    let period = pass_period(start, &one, h, climb)? + SETTLE;
    let (simulated, compression) = if layer_time > period { (period, layer_time / period) } else { (layer_time, 1.0) };
    let full = wall_path(start, &one, layers, h, simulated, climb)?;
    let end = Toolpath::from_segments(start, &full).map_err(|e| PlanError::Unsupported(format!("--check-wall: {e}")))?.end_time();
    let print = t.get_mut("print").and_then(Value::as_table_mut).expect("checked above");
    print.insert("path".into(), Value::Array(full.iter().map(segment_value).collect()));
    let z_offset = print.get("z_offset").and_then(number).unwrap_or(0.0);
    // the material's age clock, m times faster
    if let Some(m) = t.get_mut("material").and_then(Value::as_table_mut) {
        for (k, v) in m.iter_mut() {
            match (AGE_RATES.contains(&k.as_str()), AGES.contains(&k.as_str()), number(v)) {
                (true, _, Some(x)) => *v = Value::Float(x * compression),
                (_, true, Some(x)) => *v = Value::Float(x / compression),
                _ => {}
            }
        }
    }
    let table = |t: &mut Table, k: &str| -> Result<(), PlanError> {
        t.entry(k.to_string()).or_insert_with(|| Value::Table(Table::new())).as_table_mut().map(|_| ()).ok_or_else(|| bad(&format!("[{k}]")))
    };
    for k in ["simulation", "domain", "observe", "output"] {
        table(&mut t, k)?;
    }
    // the stiffness grows m times faster than the print's fixed step was chosen for: the step
    // shrinks as the wave speed grows from the fresh material to the wall's oldest
    let growth = wave_speed_growth(t.get("material").and_then(Value::as_table).ok_or_else(|| bad("[material]"))?, end)?;
    let sim = t["simulation"].as_table_mut().expect("a table");
    sim.insert("end_time".into(), Value::Float(end));
    if let Some(dt) = sim.get("dt").and_then(number) {
        sim.insert("dt".into(), Value::Float(dt / growth));
    }
    let dx = sim.get("dx").and_then(number).ok_or_else(|| bad("simulation.dx"))?;
    // the domain reaches the nozzle over the last layer, and a layer more
    let domain = t["domain"].as_table_mut().expect("a table");
    let floor = domain.get("min").and_then(point).ok_or_else(|| bad("domain.min"))?[2];
    let cells = ((start[2] + z_offset + (layers + 1) as f64 * h - floor) / dx).ceil() + 4.0;
    let mut max = domain.get("max").and_then(point).ok_or_else(|| bad("domain.max"))?;
    max[2] = max[2].max(floor + cells * dx);
    domain.insert("max".into(), array(max));
    let observe = t["observe"].as_table_mut().expect("a table");
    observe.insert("stations".into(), Value::Array(vec![Value::Float(plan.line.station)]));
    let mut failure = Table::new();
    failure.insert("stop_after".into(), Value::Float(SETTLE));
    observe.insert("failure".into(), Value::Table(failure));
    let output = t["output"].as_table_mut().expect("a table");
    output.insert("interval".into(), Value::Float(0.02));
    output.insert("vtu".into(), Value::Boolean(false));
    Ok((t, layers, h, simulated, compression))
}

/// Cut the domain at the pass's ends with symmetry planes: the reduced wall becomes a slice of a
/// long wall (the module's doc). The pass must run along x at one y (the nozzle turns at the
/// planes, its axis inside the domain) and the station lie between its ends; the platform is
/// cut with the domain.
fn mirror_ends(t: &mut Table, start: [f64; 3], one: &[Segment], station: f64) -> Result<(), PlanError> {
    let mut points = vec![start];
    points.extend(one.iter().filter_map(|s| match s {
        Segment::Print { to, .. } | Segment::Travel { to, .. } => Some(*to),
        _ => None,
    }));
    if let Some(p) = points.iter().find(|p| (p[1] - start[1]).abs() > 1e-9) {
        return Err(PlanError::Unsupported(format!(
            "--check-wall reduces the wall to a slice of a long straight wall along x, its pass between two symmetry planes; this pass leaves y = {} m (a point at y = {} m)",
            start[1], p[1]
        )));
    }
    let lo = points.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let hi = points.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
    if !(hi > lo && (lo..=hi).contains(&station)) {
        return Err(PlanError::Unsupported(format!("--check-wall: the station x = {station} m lies outside the pass's ends [{lo}, {hi}] m, where the reduced wall is cut")));
    }
    let bad = |what: &str| PlanError::Unsupported(format!("--check-wall: the planned scenario's {what}"));
    let domain = t.get_mut("domain").and_then(Value::as_table_mut).ok_or_else(|| bad("[domain]"))?;
    for (key, x) in [("min", lo), ("max", hi)] {
        let mut p = domain.get(key).and_then(point).ok_or_else(|| bad(&format!("domain.{key}")))?;
        p[0] = x;
        domain.insert(key.into(), array(p));
    }
    if let Some(Value::Array(periodic)) = domain.get_mut("periodic") {
        if let Some(x) = periodic.first_mut() {
            *x = Value::Boolean(false);
        }
    }
    let boundary = t.entry("boundary").or_insert_with(|| Value::Table(Table::new())).as_table_mut().ok_or_else(|| bad("[boundary]"))?;
    for key in ["x_min", "x_max"] {
        boundary.insert(key.into(), Value::String("symmetry".into()));
    }
    if let Some(platform) = boundary.get_mut("platform").and_then(Value::as_table_mut) {
        for (key, cut) in [("xy_min", lo), ("xy_max", hi)] {
            if let Some(Value::Array(xy)) = platform.get_mut(key) {
                if let Some(x) = xy.first().and_then(number) {
                    xy[0] = Value::Float(if key == "xy_min" { x.max(cut) } else { x.min(cut) });
                }
            }
        }
    }
    Ok(())
}

/// How many times faster elastic waves run in the material of `material` (its age clock as the
/// reduced wall has it) at time `end` than at the start: its stiffest moduli over the ages
/// reached (`Material::stability_at`), c = sqrt((K + 4 G / 3) / rho).
fn wave_speed_growth(material: &Table, end: f64) -> Result<f64, PlanError> {
    let m = crate::materials::build_material(material).map_err(|e| PlanError::Unsupported(format!("--check-wall: the reduced wall's material: {e}")))?;
    let c = |t: f64| {
        let s = m.stability_at(t);
        ((s.bulk_modulus as f64 + 4.0 / 3.0 * s.shear_modulus as f64) / s.density as f64).sqrt()
    };
    Ok((c(end) / c(0.0)).max(1.0))
}

/// Simulate the reduced wall of `plan` at layer time `layer_time` (the plan's, or another to
/// probe), `threads` threads, its scenario (`wall.toml`) and outputs (`layers.csv`, the
/// sections) written to the folder `out`.
pub fn check(plan: &Plan, layer_time: f64, threads: Option<usize>, out: &std::path::Path) -> Result<WallCheck, PlanError> {
    let clock = std::time::Instant::now();
    let (t, layers, h, simulated, compression) = scenario(plan, layer_time)?;
    let goal = plan.wall.as_ref().ok_or_else(|| PlanError::Targets("--check-wall: the targets have no [wall]".into()))?;
    let need = goal.need();
    let closed_form = goal.wall.buildable(plan.best().layer.values[0], h, layer_time, 2.0 * need)?;
    let io = |e: std::io::Error| PlanError::Io(format!("{}: {e}", out.display()));
    std::fs::create_dir_all(out).map_err(io)?;
    std::fs::write(out.join("wall.toml"), toml::to_string(&t).map_err(|e| PlanError::Unsupported(format!("--check-wall: {e}")))?).map_err(io)?;
    let sc = crate::scenario::Scenario::from_table(t).map_err(|e| PlanError::Unsupported(format!("--check-wall: the reduced wall: {e}")))?;
    let opts = crate::run::RunOptions { out: out.to_path_buf(), threads, quiet: true, overwrite: true, ..Default::default() };
    let r = crate::run::run_scenario(&sc, &opts).map_err(|e| PlanError::Unsupported(format!("--check-wall: the reduced wall: {e}")))?;
    Ok(WallCheck { layers, layer_height: h, need, layer_time, simulated_layer_time: simulated, compression, closed_form, stands: r.failure.is_none(), failure: r.failure, steps: r.steps, seconds: clock.elapsed().as_secs_f64() })
}

/// The check in one line.
pub fn text(c: &WallCheck) -> String {
    let how = format!(
        "{} layers of {:.2} mm at a layer time of {:.1} s (simulated {:.2} s, the material's age clock {:.1} times faster; {} steps in {:.1} s)",
        c.layers,
        c.layer_height * 1e3,
        c.layer_time,
        c.simulated_layer_time,
        c.compression,
        c.steps,
        c.seconds
    );
    let closed = match c.closed_form.mode {
        Some(m) if c.closed_form.height < c.need => format!("the closed form: fails by {} at {:.3} m", m.name(), c.closed_form.height),
        _ => "the closed form: stands".to_string(),
    };
    match &c.failure {
        None => format!("wall check: stands to {:.3} m (design height x safety factor {:.3} m): {how}; {closed}\n", c.layers as f64 * c.layer_height, c.need),
        Some(f) => format!(
            "wall check: FAILS by {} in layer {} at t = {:.2} s, standing to {:.3} m, short of the design height x safety factor {:.3} m: {how}; {closed}\n",
            f.mode.name(),
            f.layer,
            f.time,
            (f.layer - 1) as f64 * c.layer_height,
            c.need
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pass_run_backwards_ends_where_it_began_and_alternates_in_the_wall() {
        let s = [0.0, 0.0, 0.01];
        let one = [Segment::Travel { to: [0.01, 0.0, 0.01], speed: 0.2 }, Segment::Print { to: [0.05, 0.0, 0.01], speed: 0.05, extrusion: 0.04 }];
        let back = backwards(s, &one);
        assert!(matches!(back[0], Segment::Print { to, speed, extrusion } if to == [0.01, 0.0, 0.01] && speed == 0.05 && extrusion == 0.04), "{back:?}");
        assert!(matches!(back[1], Segment::Travel { to, speed } if to == s && speed == 0.2), "{back:?}");
        // three layers 0.006 apart, 1.5 s apart: forward (its print after the 0.05 s travel),
        // backward, forward
        let path = wall_path(s, &one, 3, 0.006, 1.5, 0.05).unwrap();
        let t = Toolpath::from_segments(s, &path).unwrap();
        let starts: Vec<(f64, f64)> = t.layers().iter().map(|l| (l.0, l.1)).collect();
        assert_eq!(starts.len(), 3, "{starts:?}");
        for (k, (z, t0)) in starts.iter().enumerate() {
            assert!((z - (0.01 + 0.006 * k as f64)).abs() < 1e-12 && (t0 - (1.5 * k as f64 + if k % 2 == 0 { 0.05 } else { 0.0 })).abs() < 1e-9, "layer {k}: {starts:?}");
        }
        let last = t.moves().iter().rev().find(|m| m.kind == crate::print::toolpath::MoveKind::Print).unwrap();
        assert!((last.to[0] - 0.05).abs() < 1e-12, "the third layer runs forward again: {last:?}");
        // a layer time shorter than the moves is refused
        assert!(wall_path(s, &one, 3, 0.006, 0.5, 0.05).is_err());
    }

    #[test]
    fn the_wall_is_cut_at_its_pass_s_ends_by_symmetry_planes() {
        let text = "[domain]\nmin = [-0.02, 0.0, 0.0]\nmax = [0.08, 0.03, 0.05]\n[boundary]\ny_min = \"symmetry\"\nplatform = { z = 0.003, xy_min = [-0.02, 0.0], xy_max = [0.08, 0.03] }\n";
        let s = [0.0, 0.0, 0.01];
        let one = [Segment::Print { to: [0.04, 0.0, 0.01], speed: 0.05, extrusion: 0.04 }];
        let mut t: Table = text.parse().unwrap();
        mirror_ends(&mut t, s, &one, 0.025).unwrap();
        assert_eq!(point(&t["domain"]["min"]), Some([0.0, 0.0, 0.0]));
        assert_eq!(point(&t["domain"]["max"]), Some([0.04, 0.03, 0.05]));
        let b = &t["boundary"];
        assert!(b["x_min"].as_str() == Some("symmetry") && b["x_max"].as_str() == Some("symmetry") && b["y_min"].as_str() == Some("symmetry"), "{b:?}");
        assert_eq!(b["platform"]["xy_min"][0].as_float(), Some(0.0));
        assert_eq!(b["platform"]["xy_max"][0].as_float(), Some(0.04));
        // a station beyond the pass's ends, or a pass leaving its line, is refused by name
        let e = mirror_ends(&mut text.parse().unwrap(), s, &one, 0.05).unwrap_err().to_string();
        assert!(e.contains("the station x = 0.05 m lies outside the pass's ends"), "{e}");
        let bent = [Segment::Print { to: [0.04, 0.01, 0.01], speed: 0.05, extrusion: 0.04 }];
        let e = mirror_ends(&mut text.parse().unwrap(), s, &bent, 0.025).unwrap_err().to_string();
        assert!(e.contains("a slice of a long straight wall along x") && e.contains("y = 0.01 m"), "{e}");
    }
}
