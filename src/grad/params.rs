//! The parameters theta a gradient is taken with respect to, named by their key in the scenario
//! file (`material.yield_stress`, `simulation.body_force.x`, `body.0.velocity.z`,
//! `boundary.z_min.friction.mu`, ...), so the same name reads, perturbs (for central
//! differences) and reports a parameter.

use super::GradError;
use crate::key::Key;
use crate::kernels::boundary::WallKind;
use crate::solver::Simulation;

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Param {
    /// Index into the material's `param_names`.
    Material(usize),
    /// Through the particle masses (m = rho V0) and the body-force acceleration F / rho.
    Density,
    BodyForce(usize),
    Gravity(usize),
    /// The initial velocity of body `body` along `axis`.
    BodyVelocity { body: usize, axis: usize },
    /// Coulomb coefficient of the wall on `axis`, `side` (0 = min, 1 = max).
    WallFriction { axis: usize, side: usize },
    PlatformFriction,
    /// `print.path.<i>.speed`, `.extrusion` or `.duration`, or one of [`WHOLE_TOOLPATH`] (see
    /// `print_adjoint.rs`).
    Toolpath,
}

/// Toolpath parameters acting on every move, path or G-code: delivered over commanded flow, and
/// the nozzle's height offset.
pub const WHOLE_TOOLPATH: [&str; 2] = ["print.extrusion_factor", "print.z_offset"];

const AXES: [&str; 3] = ["x", "y", "z"];
const FACES: [[&str; 2]; 3] = [["x_min", "x_max"], ["y_min", "y_max"], ["z_min", "z_max"]];

fn axis(s: &str) -> Option<usize> {
    AXES.iter().position(|a| *a == s)
}

/// Every parameter key the scenario offers.
pub fn known(sim: &Simulation) -> Vec<String> {
    let mut k: Vec<String> = sim.material.param_names().iter().map(|n| format!("material.{n}")).collect();
    k.push("material.density".into());
    for a in AXES {
        k.push(format!("simulation.body_force.{a}"));
        k.push(format!("simulation.gravity.{a}"));
    }
    for b in 0..sim.scenario.bodies.len() {
        for a in AXES {
            k.push(format!("body.{b}.velocity.{a}"));
        }
    }
    for (a, sides) in FACES.iter().enumerate() {
        for (s, face) in sides.iter().enumerate() {
            if matches!(sim.walls.faces[a][s], WallKind::Friction { .. }) {
                k.push(format!("boundary.{face}.friction.mu"));
            }
        }
    }
    if matches!(sim.walls.platform, Some((_, _, WallKind::Friction { .. }))) {
        k.push("boundary.platform.kind.friction.mu".into());
    }
    if let Some(p) = &sim.scenario.print {
        k.extend(WHOLE_TOOLPATH.iter().map(|f| f.to_string()));
        for (i, seg) in p.path.iter().enumerate() {
            use crate::print::toolpath::Segment;
            let fields: &[&str] = match seg {
                // an arc of travel (extrusion 0) has no extrusion to vary: it would turn into a print
                Segment::Print { .. } => &["speed", "extrusion"],
                Segment::Arc { extrusion, .. } if *extrusion > 0.0 => &["speed", "extrusion"],
                Segment::Arc { .. } => &["speed"],
                Segment::Travel { .. } | Segment::Layer { .. } => &["speed"],
                Segment::Pause { .. } => &["duration"],
            };
            k.extend(fields.iter().map(|f| format!("print.path.{i}.{f}")));
        }
    }
    k
}

/// The parameter `key` names, parsed once ([`Key`]); an error listing the keys this scenario
/// offers where it names none.
pub fn parse(sim: &Simulation, key: &str) -> Result<(Key, Param), GradError> {
    let unknown = || GradError::Param(format!("unknown parameter '{key}' for this scenario; known: {}", known(sim).join(", ")));
    let k = Key::parse(key).map_err(|_| unknown())?;
    let p = resolve(sim, &k).ok_or_else(unknown)?;
    Ok((k, p))
}

/// The parameter a key names in this scenario, if any.
fn resolve(sim: &Simulation, key: &Key) -> Option<Param> {
    let parts: Vec<&str> = key.parts().collect();
    let p = match parts.as_slice() {
        ["material", "density"] => Some(Param::Density),
        ["material", name] => sim.material.param_names().iter().position(|n| n == name).map(Param::Material),
        ["simulation", "body_force", a] => axis(a).map(Param::BodyForce),
        ["simulation", "gravity", a] => axis(a).map(Param::Gravity),
        ["body", b, "velocity", a] => match (b.parse::<usize>(), axis(a)) {
            (Ok(body), Some(axis)) if body < sim.scenario.bodies.len() => Some(Param::BodyVelocity { body, axis }),
            _ => None,
        },
        ["print", "path", _, _] | ["print", "extrusion_factor" | "z_offset"] => known(sim).iter().any(|k| k == key.as_str()).then_some(Param::Toolpath),
        ["boundary", "platform", "kind", "friction", "mu"] => {
            matches!(sim.walls.platform, Some((_, _, WallKind::Friction { .. }))).then_some(Param::PlatformFriction)
        }
        ["boundary", face, "friction", "mu"] => FACES.iter().enumerate().find_map(|(a, sides)| {
            let s = sides.iter().position(|f| f == face)?;
            matches!(sim.walls.faces[a][s], WallKind::Friction { .. }).then_some(Param::WallFriction { axis: a, side: s })
        }),
        _ => None,
    };
    p
}

/// Walk `key` in a TOML document: `x`/`y`/`z` and numbers index arrays.
fn walk<'a>(doc: &'a mut toml::Value, key: &Key) -> Result<&'a mut toml::Value, GradError> {
    let mut at = doc;
    for part in key.parts() {
        at = match at {
            toml::Value::Table(t) => t.get_mut(part),
            toml::Value::Array(a) => part.parse::<usize>().ok().or_else(|| axis(part)).and_then(|i| a.get_mut(i)),
            _ => None,
        }
        .ok_or_else(|| GradError::Param(format!("the scenario has no value at '{key}' (set it explicitly to differentiate with respect to it)")))?;
    }
    Ok(at)
}

/// The value of `key` in the scenario text.
pub fn value(source: &str, key: &Key) -> Result<f64, GradError> {
    let mut doc: toml::Value = toml::from_str(source)?;
    match walk(&mut doc, key)? {
        toml::Value::Float(f) => Ok(*f),
        toml::Value::Integer(i) => Ok(*i as f64),
        other => Err(GradError::Param(format!("'{key}' is {other}, not a number"))),
    }
}

/// The scenario text with `key` set to `v`.
pub fn with_value(source: &str, key: &Key, v: f64) -> Result<String, GradError> {
    let mut doc: toml::Value = toml::from_str(source)?;
    *walk(&mut doc, key)? = toml::Value::Float(v);
    Ok(toml::to_string(&doc)?)
}
