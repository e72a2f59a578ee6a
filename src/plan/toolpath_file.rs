//! A plan of a print given as a toolpath file (`[print] gcode` or `points`).
//!
//! The plan's keys act on an inline path (`line.rs`), so the file's commanded toolpath is first
//! written out as one ([`inline`]: every move a `print`, `travel` or `pause` segment, the
//! scenario otherwise as it is). After the plan, the file is written again with the planned
//! settings ([`FilePrint::write_planned`]): every extruding move at the planned speed (F) and
//! extrusion speed (E per move), the nozzle's heights moved by the planned standoff (Z), and,
//! with a wall, a dwell (G4) before each layer so that a layer starts no sooner than one layer
//! time after the one below. It is written fresh from the toolpath (G90, M83, G1 and G4 under
//! the scenario's `gcode_options`), so the commands the reader skips (temperatures, labels) are
//! not carried, and arcs come out as the chords strand prints.

use super::error::PlanError;
use super::line::{Line, Point};
use super::planner::Plan;
use super::report::refuse_existing;
use crate::print::gcode::GcodeOptions;
use crate::print::toolpath::{Move, MoveKind, Toolpath};
use crate::print::PrintConfig;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What the print's file is.
#[derive(Clone, Debug)]
pub enum Source {
    Gcode(GcodeOptions),
    Points,
}

/// A print read from a toolpath file, and its inline scenario.
#[derive(Clone, Debug)]
pub struct FilePrint {
    pub source: Source,
    /// The scenario's `print.z_offset` (the printer's own offset, kept in the planned file).
    z_offset: f64,
    /// The scenario's `print.gcode_options` table, as written (the planned scenario reads the
    /// planned G-code under them).
    options: Option<toml::Value>,
    /// The outlet's area [m2] (E of filament, a point list's flow).
    outlet_area: f64,
    /// The scenario with the toolpath inline, which the plan sets.
    pub inlined: PathBuf,
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> PlanError + '_ {
    move |e| PlanError::Io(format!("{}: {e}", path.display()))
}

/// The commanded toolpath of `cfg` (no imperfection, no extrusion factor) with its heights moved
/// by `z_offset`.
fn commanded(cfg: &PrintConfig, base_dir: &Path, z_offset: f64) -> Result<Toolpath, PlanError> {
    let cfg = PrintConfig { imperfection: None, extrusion_factor: 1.0, z_offset, ..cfg.clone() };
    cfg.toolpath(base_dir).map_err(|e| PlanError::Unsupported(e.to_string()))
}

/// The print of `scenario` read from its toolpath file and written as an inline path to
/// `inlined` (refused if it exists without `overwrite`); None when the print is inline already.
pub fn inline(scenario: &Path, inlined: &Path, overwrite: bool) -> Result<Option<FilePrint>, PlanError> {
    let text = std::fs::read_to_string(scenario).map_err(io(scenario))?;
    let mut doc: toml::Table = text.parse().map_err(|e| PlanError::Unsupported(format!("{}: {e}", scenario.display())))?;
    let Some(table) = doc.get("print") else { return Ok(None) };
    let cfg: PrintConfig = table.clone().try_into().map_err(|e| PlanError::Unsupported(format!("{}: [print]: {e}", scenario.display())))?;
    let source = match (&cfg.gcode, &cfg.points) {
        (Some(_), _) => Source::Gcode(cfg.gcode_options.clone()),
        (None, Some(_)) => Source::Points,
        (None, None) => return Ok(None),
    };
    if let Source::Gcode(GcodeOptions { flow_unit: Some(_), .. }) = source {
        return Err(PlanError::Unsupported(format!("{}: a plan sets E per move; a pump-mode G-code (gcode_options.flow_unit) is not planned yet", scenario.display())));
    }
    let base_dir = scenario.parent().map(Path::to_path_buf).unwrap_or_default();
    let tp = commanded(&cfg, &base_dir, 0.0)?;
    let path: Vec<toml::Value> = tp.moves().iter().filter_map(segment).collect();
    let print = doc.get_mut("print").and_then(toml::Value::as_table_mut).expect("[print] is a table");
    let options = print.get("gcode_options").cloned();
    for k in ["gcode", "gcode_options", "points"] {
        print.remove(k);
    }
    print.insert("start".into(), point(tp.moves()[0].from));
    print.insert("path".into(), toml::Value::Array(path));
    refuse_existing(inlined, overwrite)?;
    let head = format!("# {} with its toolpath file's moves written inline, for strand plan\n", scenario.display());
    let body = toml::to_string(&doc).map_err(|e| PlanError::Io(e.to_string()))?;
    std::fs::write(inlined, head + &body).map_err(io(inlined))?;
    Ok(Some(FilePrint { source, z_offset: cfg.z_offset, options, outlet_area: cfg.nozzle.area(), inlined: inlined.to_path_buf() }))
}

fn point(p: [f64; 3]) -> toml::Value {
    toml::Value::Array(p.iter().map(|&v| toml::Value::Float(v)).collect())
}

/// A move as an inline segment; None for a move that takes no time.
fn segment(m: &Move) -> Option<toml::Value> {
    let mut t = toml::Table::new();
    let speed = m.length() / m.duration();
    match m.kind {
        _ if m.duration() <= 0.0 => return None,
        MoveKind::Print => {
            t.insert("kind".into(), "print".into());
            t.insert("to".into(), point(m.to));
            t.insert("speed".into(), speed.into());
            t.insert("extrusion".into(), m.extrusion_speed.into());
        }
        MoveKind::Travel if m.length() > 0.0 => {
            t.insert("kind".into(), "travel".into());
            t.insert("to".into(), point(m.to));
            t.insert("speed".into(), speed.into());
        }
        MoveKind::Travel | MoveKind::Pause => {
            t.insert("kind".into(), "pause".into());
            t.insert("duration".into(), m.duration().into());
        }
    }
    Some(toml::Value::Table(t))
}

/// The dwell [s] before each layer after the first so that layers start `layer_time` apart, as
/// (index of the layer's first extruding move, dwell); layers already that far apart get none.
pub fn dwells(tp: &Toolpath, layer_time: f64) -> Vec<(usize, f64)> {
    let starts: Vec<f64> = tp.layers().iter().map(|l| l.1).collect();
    starts
        .windows(2)
        .filter_map(|w| {
            let k = tp.moves().iter().position(|m| m.kind == MoveKind::Print && m.t0 == w[1])?;
            let dwell = layer_time - (w[1] - w[0]);
            (dwell > 0.0).then_some((k, dwell))
        })
        .collect()
}

impl FilePrint {
    /// Where the planned file goes, beside the planned scenario `out`.
    pub fn planned_path(&self, out: &Path) -> PathBuf {
        out.with_extension(match self.source {
            Source::Gcode(_) => "gcode",
            Source::Points => "csv",
        })
    }

    /// The commanded toolpath at the settings `x` of `line` (the printer's own z_offset taken
    /// back out of the heights), and with a `layer_time` the dwells before its layers.
    pub fn planned(&self, line: &Line, x: &Point, layer_time: Option<f64>) -> Result<(Toolpath, Vec<(usize, f64)>), PlanError> {
        let sc = line.scenario(x)?;
        let cfg = sc.print.as_ref().expect("a plan's print");
        let tp = commanded(cfg, &sc.base_dir, cfg.z_offset - self.z_offset)?;
        let dwells = layer_time.map_or_else(Vec::new, |t| dwells(&tp, t));
        Ok((tp, dwells))
    }

    /// The file at the settings `x` of `line` and `layer_time`, written to `out` (refused if it
    /// exists without `overwrite`).
    pub fn write(&self, line: &Line, x: &Point, layer_time: Option<f64>, out: &Path, overwrite: bool) -> Result<(), PlanError> {
        refuse_existing(out, overwrite)?;
        let (tp, dwells) = self.planned(line, x, layer_time)?;
        let lt = layer_time.map_or(String::new(), |t| format!(", layer time {t} s"));
        let head = format!("strand plan: speed {} m/s, extrusion {} m/s, standoff {} m{lt}", x[0], x[1], x[2]);
        let text = match &self.source {
            Source::Gcode(o) => gcode(&tp, &dwells, o, self.outlet_area, &head),
            Source::Points => points(&tp, &dwells, self.outlet_area, &head)?,
        };
        std::fs::write(out, text).map_err(io(out))
    }

    /// The planned scenario at `plan`'s settings, its print read from the planned file `file`
    /// (beside the scenario, so named by its file name): the inline path and start give way to
    /// the file and the scenario's own `gcode_options`, the printer's `z_offset` is restored (the
    /// file's heights carry the standoff), and the end time grows by the file's layer dwells.
    pub fn planned_scenario(&self, plan: &Plan, file: &Path) -> Result<String, PlanError> {
        let x = plan.settings();
        let layer_time = plan.wall.as_ref().map(|_| plan.best().build.layer_time);
        let (_, dwells) = self.planned(&plan.line, &x, layer_time)?;
        let bad = |what: &str| PlanError::Unsupported(format!("the planned scenario of {}: {what}", self.inlined.display()));
        let mut doc: toml::Table = plan.line.scenario_text(&x)?.parse().map_err(|e| bad(&format!("{e}")))?;
        let name = file.file_name().ok_or_else(|| bad("the planned file has no name"))?.to_string_lossy().into_owned();
        let print = doc.get_mut("print").and_then(toml::Value::as_table_mut).ok_or_else(|| bad("no [print]"))?;
        for k in ["path", "start"] {
            print.remove(k);
        }
        match self.source {
            Source::Gcode(_) => {
                print.insert("gcode".into(), name.into());
                if let Some(o) = &self.options {
                    print.insert("gcode_options".into(), o.clone());
                }
            }
            Source::Points => {
                print.insert("points".into(), name.into());
            }
        }
        print.insert("z_offset".into(), self.z_offset.into());
        let sim = doc.get_mut("simulation").and_then(toml::Value::as_table_mut).ok_or_else(|| bad("no [simulation]"))?;
        let end = sim.get("end_time").and_then(toml::Value::as_float).ok_or_else(|| bad("no simulation.end_time"))?;
        sim.insert("end_time".into(), (end + dwells.iter().map(|d| d.1).sum::<f64>()).into());
        toml::to_string(&doc).map_err(|e| PlanError::Io(e.to_string()))
    }

    /// The file with the plan's settings applied (the layer time's dwells with a wall).
    pub fn write_planned(&self, plan: &Plan, out: &Path, overwrite: bool) -> Result<(), PlanError> {
        let layer_time = plan.wall.as_ref().map(|_| plan.best().build.layer_time);
        self.write(&plan.line, &plan.settings(), layer_time, out, overwrite)
    }
}

/// `tp` as G-code under `o`: absolute positions, relative E, every move with its F; `dwells`
/// as G4 before their moves.
pub fn gcode(tp: &Toolpath, dwells: &[(usize, f64)], o: &GcodeOptions, outlet_area: f64, head: &str) -> String {
    // as the G-code reader counts E
    let Ok(eu) = o.metres_per_e(|| Ok::<_, std::convert::Infallible>(outlet_area));
    let unit = o.unit;
    let at = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|i| (p[i] - o.origin[i]) / unit) };
    let mut s = format!("; {head}\nG90\nM83\n");
    let mut here: [f64; 3] = std::array::from_fn(|i| o.origin[i] + unit * o.start[i]);
    for (k, m) in tp.moves().iter().enumerate() {
        if let Some((_, d)) = dwells.iter().find(|(i, _)| *i == k) {
            let _ = writeln!(s, "G4 S{d}");
        }
        if m.kind == MoveKind::Pause {
            let _ = writeln!(s, "G4 S{}", m.duration());
            continue;
        }
        let feed = m.length() / m.duration() / unit * 60.0;
        if m.from != here {
            // the standoff moved the whole path, its first point with it
            let [x, y, z] = at(m.from);
            let _ = writeln!(s, "G1 X{x} Y{y} Z{z} F{feed}");
        }
        let [x, y, z] = at(m.to);
        let _ = match m.kind {
            MoveKind::Print => writeln!(s, "G1 X{x} Y{y} Z{z} {}{} F{feed}", o.extruder_axis, m.extrusion_speed * m.duration() / eu),
            _ => writeln!(s, "G1 X{x} Y{y} Z{z} F{feed}"),
        };
        here = m.to;
    }
    s
}

/// `tp` as a point list (`print::points`): a point list has no pauses, so a toolpath with one
/// (or a dwell) is refused.
fn points(tp: &Toolpath, dwells: &[(usize, f64)], outlet_area: f64, head: &str) -> Result<String, PlanError> {
    if !dwells.is_empty() || tp.moves().iter().any(|m| m.kind == MoveKind::Pause) {
        return Err(PlanError::Unsupported("a point list cannot hold the plan's pauses or layer dwells: give the print as G-code or inline".into()));
    }
    let mut s = format!("# {head}\nx, y, z, speed, flow\n");
    let first = &tp.moves()[0];
    let [x, y, z] = first.from;
    let _ = writeln!(s, "{x}, {y}, {z}, {}, 0", first.length() / first.duration());
    for m in tp.moves() {
        let [x, y, z] = m.to;
        let _ = writeln!(s, "{x}, {y}, {z}, {}, {}", m.length() / m.duration(), m.extrusion_speed * outlet_area);
    }
    Ok(s)
}
