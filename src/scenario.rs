//! Scenario files (TOML). Every table rejects unknown keys, and `validate` checks values, so a
//! typo or a bad number is an error that names the key before anything runs.

use crate::config::sleep::{sleep_by_default, SleepDefault};
use crate::config::{CheckpointConfig, DiskFullPolicy, ObserveConfig, PrintConfig, SleepConfig};
use crate::kernels::boundary::WallKind;
use crate::memory::parse_size;
use crate::solid::shape::{Sdf, ShapeConfig, ShapeContext};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use crate::invalid::Invalid;

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub name: String,
    pub simulation: SimulationTable,
    pub domain: Domain,
    #[serde(default)]
    pub boundary: Boundary,
    /// The material table: `kind = "<registry name>"` plus that material's parameters.
    pub material: toml::Table,
    #[serde(default, rename = "body")]
    pub bodies: Vec<Body>,
    /// Solid bodies inside the domain (`[[solid]]`, `src/solid/`; issue 30 hook).
    #[serde(default, rename = "solid")]
    pub solids: Vec<crate::solid::SolidConfig>,
    #[serde(default)]
    pub output: Output,
    pub memory: Memory,
    /// Printing: nozzle, toolpath, emission.
    #[serde(default)]
    pub print: Option<PrintConfig>,
    /// Sleeping blocks of material at rest: `None` keeps all material awake. Once the scenario
    /// is read, a written `[sleep]` is here unless it says `enabled = false`, and an unwritten
    /// one as [`sleep_by_default`] decides (`sleep_default` says what it decided).
    #[serde(default)]
    pub sleep: Option<SleepConfig>,
    /// What [`sleep_by_default`] decided for a scenario that writes no `[sleep]` (None when it
    /// writes one), for the run's log.
    #[serde(skip)]
    pub sleep_default: Option<SleepDefault>,
    /// Observables written at each output.
    #[serde(default)]
    pub observe: Option<ObserveConfig>,
    /// Restart checkpoints.
    #[serde(default)]
    pub checkpoint: CheckpointConfig,
    /// Folder that relative paths in the scenario (G-code, measurements) start from.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The TOML text the scenario was read from: a checkpoint keeps it, so a resume can name
    /// every key that changed since.
    #[serde(skip)]
    pub source: String,
}

/// The `[simulation]` table: cell size, end time, time step and the solver's numerical options
/// (the running simulation is `solver::Simulation`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationTable {
    /// Grid spacing [m].
    pub dx: f64,
    /// Simulated time to reach [s].
    pub end_time: f64,
    /// Fixed time step [s]; automatic (CFL) when absent.
    #[serde(default)]
    pub dt: Option<f64>,
    /// Courant number of the automatic step.
    #[serde(default = "default_cfl")]
    pub cfl: f64,
    /// Largest step the automatic control may take [s].
    #[serde(default)]
    pub max_dt: Option<f64>,
    /// Gravitational acceleration [m/s2].
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Extra body force per unit volume [N/m3] (e.g. a pressure gradient driving a channel).
    #[serde(default)]
    pub body_force: [f64; 3],
    /// Worker threads; 0 = all cores.
    #[serde(default)]
    pub threads: usize,
    /// FLIP share of the particle velocity update (0 = APIC, the default: the particle takes the
    /// grid velocity; alpha in (0, 1] keeps alpha (v_p + grid increment) + (1 - alpha) v_grid).
    /// FLIP makes steady wall-bounded flows independent of dt at coarse resolution, but its noise
    /// lets particles drift across streamlines; see DESIGN.md for the measurements.
    #[serde(default = "default_flip")]
    pub flip: f64,
    /// Cell-averaged volume ratio (J-bar) against volumetric locking of nearly isochoric flow.
    #[serde(default = "default_true")]
    pub j_bar: bool,
    /// Physically reorder particles by block every this many steps (between reorders they are
    /// visited through an index permutation).
    #[serde(default = "default_reorder")]
    pub reorder_interval: u64,
    /// Mass (inertia) scaling s >= 1 for quasi-static prints (docs/scenario.md "Mass
    /// scaling"): the grid update divides every force's impulse by s, as if the material's
    /// inertia were s times its mass, while weights, stresses, time and every rate stay real.
    /// The automatic step grows as sqrt(s) (wave) and s (viscous). 1 (the default) is off.
    #[serde(default = "default_mass_scaling")]
    pub mass_scaling: f64,
}

fn default_cfl() -> f64 {
    0.3
}
fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}
fn default_flip() -> f64 {
    0.0
}
fn default_reorder() -> u64 {
    16
}
fn default_mass_scaling() -> f64 {
    1.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Domain {
    /// Lower corner of the region material may occupy [m].
    pub min: [f64; 3],
    /// Upper corner [m].
    pub max: [f64; 3],
    /// Periodic axes (x, y, z): material leaving one side enters the other; no walls there.
    #[serde(default)]
    pub periodic: [bool; 3],
}

/// Wall conditions on the six faces of the domain and an optional printing platform.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Boundary {
    #[serde(default = "default_wall")]
    pub x_min: WallKind,
    #[serde(default = "default_wall")]
    pub x_max: WallKind,
    #[serde(default = "default_wall")]
    pub y_min: WallKind,
    #[serde(default = "default_wall")]
    pub y_max: WallKind,
    #[serde(default = "default_floor")]
    pub z_min: WallKind,
    #[serde(default = "default_wall")]
    pub z_max: WallKind,
    #[serde(default)]
    pub platform: Option<Platform>,
}

fn default_wall() -> WallKind {
    WallKind::FreeSlip
}
fn default_floor() -> WallKind {
    WallKind::NoSlip
}

impl Default for Boundary {
    fn default() -> Self {
        Boundary {
            x_min: default_wall(),
            x_max: default_wall(),
            y_min: default_wall(),
            y_max: default_wall(),
            z_min: default_floor(),
            z_max: default_wall(),
            platform: None,
        }
    }
}

/// A horizontal printing platform: the top face of the box `xy_min..xy_max` at height `z`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Platform {
    pub z: f64,
    pub xy_min: [f64; 2],
    pub xy_max: [f64; 2],
    #[serde(default = "default_floor")]
    pub kind: WallKind,
}

/// The most steps a run may plan: a fixed dt (or the first automatic one) that needs more to
/// reach `end_time` is refused, since such a run would not end in any useful time.
pub const MAX_STEPS: f64 = 1e9;

/// The most grid cells along one axis: the grid's block table and its memory plan are indexed
/// in machine integers, which this keeps far from overflow.
pub const MAX_CELLS_PER_AXIS: f64 = 262_144.0;

/// Initial material: a shape filled with particles on a regular lattice of
/// `particles_per_cell_axis^3` particles per cell, moving at `velocity`.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Body {
    Box {
        min: [f64; 3],
        max: [f64; 3],
        #[serde(default = "default_ppc")]
        particles_per_cell_axis: u32,
        #[serde(default)]
        velocity: [f64; 3],
    },
    /// A vertical frustum (z up) standing on `base_center`: a cylinder when the radii agree, a
    /// slump cone otherwise.
    Frustum {
        base_center: [f64; 3],
        bottom_radius: f64,
        top_radius: f64,
        height: f64,
        #[serde(default = "default_ppc")]
        particles_per_cell_axis: u32,
        #[serde(default)]
        velocity: [f64; 3],
    },
    /// The region in any of `parts`, shapes as `[[solid]]` takes them (boxes, cylinders,
    /// half-spaces, unions, intersections; `solids.md`): a funnel's fill, a mould's.
    Union {
        parts: Vec<ShapeConfig>,
        #[serde(default = "default_ppc")]
        particles_per_cell_axis: u32,
        #[serde(default)]
        velocity: [f64; 3],
    },
    /// The region in all of `parts` (a box cut by inclined half-spaces: a hopper's fill).
    Intersection {
        parts: Vec<ShapeConfig>,
        #[serde(default = "default_ppc")]
        particles_per_cell_axis: u32,
        #[serde(default)]
        velocity: [f64; 3],
    },
}

fn default_ppc() -> u32 {
    2
}

impl Body {
    pub fn particles_per_cell_axis(&self) -> u32 {
        match self {
            Body::Box { particles_per_cell_axis, .. }
            | Body::Frustum { particles_per_cell_axis, .. }
            | Body::Union { particles_per_cell_axis, .. }
            | Body::Intersection { particles_per_cell_axis, .. } => *particles_per_cell_axis,
        }
    }
    pub fn velocity(&self) -> [f64; 3] {
        match self {
            Body::Box { velocity, .. } | Body::Frustum { velocity, .. } | Body::Union { velocity, .. } | Body::Intersection { velocity, .. } => *velocity,
        }
    }
    /// The shape of a union or intersection body, as a solid's shape.
    fn region(&self) -> Option<ShapeConfig> {
        match self {
            Body::Union { parts, .. } => Some(ShapeConfig::Union { parts: parts.clone() }),
            Body::Intersection { parts, .. } => Some(ShapeConfig::Intersection { parts: parts.clone() }),
            Body::Box { .. } | Body::Frustum { .. } => None,
        }
    }
    /// The signed distance of a union or intersection body (checked by `validate`: it builds,
    /// and is bounded).
    fn distance(&self) -> Option<Box<dyn Sdf>> {
        let cx = ShapeContext { nozzle: None };
        self.region().map(|r| r.build("body", &cx).expect("a body's region is checked before it is filled"))
    }
    /// Bounding box of the shape.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match self {
            Body::Box { min, max, .. } => (*min, *max),
            Body::Frustum { base_center: c, bottom_radius, top_radius, height, .. } => {
                let r = bottom_radius.max(*top_radius);
                ([c[0] - r, c[1] - r, c[2]], [c[0] + r, c[1] + r, c[2] + height])
            }
            Body::Union { .. } | Body::Intersection { .. } => {
                let (lo, hi) = self.distance().and_then(|d| d.bounds()).expect("a body's region is checked to be bounded");
                (lo.to_array(), hi.to_array())
            }
        }
    }
    /// The test of whether a point lies inside the shape (built once: a region's distance
    /// function is assembled from its parts).
    pub fn inside(&self) -> impl Fn([f64; 3]) -> bool + '_ {
        let region = self.distance();
        move |p: [f64; 3]| match (&region, self) {
            (Some(d), _) => d.distance(glam::DVec3::from(p)) < 0.0,
            (None, Body::Box { min, max, .. }) => (0..3).all(|a| p[a] >= min[a] && p[a] < max[a]),
            (None, Body::Frustum { base_center: c, bottom_radius, top_radius, height, .. }) => {
                let h = p[2] - c[2];
                if !(0.0..*height).contains(&h) {
                    return false;
                }
                let r = bottom_radius + (top_radius - bottom_radius) * h / height;
                let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
                dx * dx + dy * dy < r * r
            }
            (None, Body::Union { .. } | Body::Intersection { .. }) => unreachable!("a region has its distance"),
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Simulated time between outputs [s].
    #[serde(default = "default_interval")]
    pub interval: f64,
    /// Write VTU particle snapshots.
    #[serde(default = "default_true")]
    pub vtu: bool,
    /// Bytes the output folder may hold (snapshots, checkpoints, CSVs), e.g. "20 GiB"; none
    /// means no limit beyond the disk itself.
    #[serde(default)]
    pub disk_budget: Option<String>,
    /// What to do when the next snapshot would not fit the disk budget.
    #[serde(default)]
    pub on_disk_full: DiskFullPolicy,
}

fn default_interval() -> f64 {
    0.1
}
fn default_true() -> bool {
    true
}

impl Default for Output {
    fn default() -> Self {
        Output { interval: default_interval(), vtu: true, disk_budget: None, on_disk_full: Default::default() }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Memory {
    /// Memory budget for every pool, e.g. "2 GiB".
    pub budget: String,
    /// Back pools with files in this directory instead of anonymous memory.
    #[serde(default)]
    pub dir: Option<PathBuf>,
    /// Particle capacity; default: the initial particle count.
    #[serde(default)]
    pub max_particles: Option<usize>,
    /// Grid block capacity; default: every block of the domain.
    #[serde(default)]
    pub max_blocks: Option<usize>,
}

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("cannot read scenario {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("scenario {path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("scenario: {0}")]
    Invalid(#[from] Invalid),
}

/// A table's deserialisation error on one line, where first (`in \`simulation\``) and what is
/// wrong last, as a text's error ends with what is wrong.
fn where_then_what(e: &toml::de::Error) -> String {
    let what = e.message().trim();
    let full = e.to_string();
    let place: Vec<&str> = full.lines().map(str::trim).filter(|l| !l.is_empty() && *l != what).collect();
    match place.is_empty() {
        true => what.to_string(),
        false => format!("{}: {what}", place.join(" ")),
    }
}

impl Scenario {
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io { path: path.into(), source })?;
        let mut sc = Scenario::parse_as_written(&text).map_err(|e| match e {
            ScenarioError::Parse { message, .. } => ScenarioError::Parse { path: path.into(), message },
            other => other,
        })?;
        sc.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        sc.resolve_defaults();
        Ok(sc)
    }

    /// A scenario from its text; files it names (a G-code toolpath) are relative to the working
    /// directory.
    pub fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        let mut sc = Scenario::parse_as_written(text)?;
        sc.resolve_defaults();
        Ok(sc)
    }

    /// A scenario from a TOML table already read and edited (the measurement loop sets a model's
    /// keys in it): the scenario `parse` gives of the table's text, read from the table itself;
    /// the text is written once, as the scenario's record (`source`), and not read back.
    pub fn from_table(doc: toml::Table) -> Result<Scenario, ScenarioError> {
        let parse_error = |message: String| ScenarioError::Parse { path: PathBuf::from("<table>"), message };
        let source = toml::to_string(&doc).map_err(|e| parse_error(e.to_string()))?;
        let mut sc: Scenario = toml::Value::Table(doc).try_into().map_err(|e: toml::de::Error| parse_error(where_then_what(&e)))?;
        sc.validate()?;
        sc.source = source;
        sc.resolve_defaults();
        Ok(sc)
    }

    fn parse_as_written(text: &str) -> Result<Scenario, ScenarioError> {
        let mut sc: Scenario =
            toml::from_str(text).map_err(|e| ScenarioError::Parse { path: PathBuf::from("<text>"), message: e.to_string() })?;
        sc.validate()?;
        sc.source = text.to_string();
        Ok(sc)
    }

    /// Defaults that depend on the rest of the scenario: sleeping itself, without `[sleep]`, as
    /// [`sleep_by_default`] rules (printed to failure: two or more layers observed at a station) (a material that does not build leaves it off: its error comes
    /// when the simulation is built), and off with `[sleep] enabled = false`; `[sleep]
    /// wake_by_load` is on for prints of two or more layers (a toolpath that does not load yet
    /// counts as two: the safe side), off otherwise (`sleep.rs`).
    fn resolve_defaults(&mut self) {
        match &self.sleep {
            None => {
                let to_failure = self.printed_layers() >= 2 && self.observe.as_ref().is_some_and(|o| !o.stations.is_empty());
                let rule = crate::materials::build_material(&self.material).ok().map(|m| sleep_by_default(self.print.is_some(), to_failure, &*m));
                if rule.as_ref().is_some_and(|r| r.on) {
                    self.sleep = Some(SleepConfig::defaults());
                }
                self.sleep_default = rule;
            }
            Some(z) if !z.enabled => self.sleep = None,
            Some(_) => {}
        }
        let layers = self.printed_layers();
        let Some(z) = &mut self.sleep else { return };
        if z.wake_by_load.is_none() {
            z.wake_by_load = Some(layers >= 2);
        }
    }

    /// Layers the toolpath prints: 0 without `[print]`, 2 (the safe side of the defaults that
    /// read it) when the toolpath does not load yet.
    fn printed_layers(&self) -> usize {
        self.print.as_ref().map_or(0, |p| p.toolpath(&self.base_dir).map_or(2, |t| t.layers().len()))
    }

    /// Value checks serde cannot express; each message names the key.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |m: String| Err(ScenarioError::Invalid(Invalid(m)));
        check_simulation(&self.simulation)?;
        check_domain(&self.domain, self.simulation.dx)?;
        check_boundary(&self.boundary)?;
        for (i, b) in self.bodies.iter().enumerate() {
            check_body(i, b, &self.domain)?;
        }
        if !(self.output.interval > 0.0) {
            return bad(format!("output.interval must be > 0, got {}", self.output.interval));
        }
        parse_size(&self.memory.budget).map_err(|e| ScenarioError::Invalid(Invalid(format!("memory.budget: {e}"))))?;
        if let Some(b) = &self.output.disk_budget {
            parse_size(b).map_err(|e| ScenarioError::Invalid(Invalid(format!("output.disk_budget: {e}"))))?;
        }
        self.checkpoint.validate()?;
        if let Some(p) = &self.print {
            p.validate()?;
        }
        // solids hook (issue 30)
        crate::solid::validate(&self.solids, self.print.is_some())?;
        if let Some(z) = &self.sleep {
            z.validate()?;
        }
        if let Some(o) = &self.observe {
            o.validate()?;
        }
        if !self.material.contains_key("kind") {
            return bad("material.kind is missing (one of: newtonian, bingham, papanastasiou_roussel, evp_bingham, drucker_prager)".into());
        }
        Ok(())
    }
}

/// `[simulation]`'s values: a positive cell, a finite end, a step the run can plan.
fn check_simulation(s: &SimulationTable) -> Result<(), Invalid> {
    if !(s.dx > 0.0 && s.dx.is_finite()) {
        return Err(Invalid(format!("simulation.dx must be a positive length, got {}", s.dx)));
    }
    if !s.end_time.is_finite() {
        return Err(Invalid(format!("simulation.end_time must be a finite time, got {}", s.end_time)));
    }
    if !(s.end_time >= 0.0) {
        return Err(Invalid(format!("simulation.end_time must be >= 0, got {}", s.end_time)));
    }
    if let Some(dt) = s.dt {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(Invalid(format!("simulation.dt must be > 0, got {dt}")));
        }
        let steps = s.end_time / dt;
        if steps > MAX_STEPS {
            return Err(Invalid(format!("simulation.dt = {dt:e} s takes {steps:.3e} steps to end_time = {} s, more than the {MAX_STEPS:e} a run may plan", s.end_time)));
        }
    }
    if let Some(m) = s.max_dt {
        if !(m > 0.0 && m.is_finite()) {
            return Err(Invalid(format!("simulation.max_dt must be > 0, got {m}")));
        }
    }
    if !(s.cfl > 0.0 && s.cfl <= 1.0) {
        return Err(Invalid(format!("simulation.cfl must be in (0, 1], got {}", s.cfl)));
    }
    if !(0.0..=1.0).contains(&s.flip) {
        return Err(Invalid(format!("simulation.flip must be in [0, 1], got {}", s.flip)));
    }
    if s.reorder_interval == 0 {
        return Err(Invalid("simulation.reorder_interval must be >= 1".into()));
    }
    // s < 1 would make the material lighter than it is, which no quasi-static argument allows
    if !(s.mass_scaling.is_finite() && s.mass_scaling >= 1.0) {
        return Err(Invalid(format!(
            "simulation.mass_scaling must be a finite factor >= 1 (1 = real inertia), got {}",
            s.mass_scaling
        )));
    }
    if s.gravity.iter().chain(s.body_force.iter()).any(|g| !g.is_finite()) {
        return Err(Invalid("simulation.gravity and simulation.body_force must be finite".into()));
    }
    Ok(())
}

/// `[domain]`: finite, at least a cell and at most what the grid indexes on every axis; a
/// periodic axis a whole number of blocks (one, or an even number).
fn check_domain(d: &Domain, dx: f64) -> Result<(), Invalid> {
    for a in 0..3 {
        if !(d.min[a].is_finite() && d.max[a].is_finite()) {
            return Err(Invalid(format!("domain.min[{a}] and domain.max[{a}] must be finite, got {} and {}", d.min[a], d.max[a])));
        }
        if !(d.max[a] > d.min[a]) {
            return Err(Invalid(format!("domain.max[{a}] ({}) must exceed domain.min[{a}] ({})", d.max[a], d.min[a])));
        }
        let cells = (d.max[a] - d.min[a]) / dx;
        if cells > MAX_CELLS_PER_AXIS {
            return Err(Invalid(format!("domain: axis {a} spans {cells:.3e} cells of dx = {dx} m, more than the {MAX_CELLS_PER_AXIS:e} the grid can index; raise simulation.dx")));
        }
        if cells < 1.0 - 1e-6 {
            return Err(Invalid(format!("domain: axis {a} spans {} m, less than one cell of simulation.dx = {dx} m", d.max[a] - d.min[a])));
        }
        if d.periodic[a] {
            let n = cells.round();
            if (cells - n).abs() > 1e-6 * n.max(1.0) || !(n as u64).is_multiple_of(4) {
                return Err(Invalid(format!("domain: periodic axis {a} must span a multiple of 4 cells (got {cells} cells of dx = {dx})")));
            }
            let blocks = n as u64 / 4;
            if blocks != 1 && !blocks.is_multiple_of(2) {
                return Err(Invalid(format!("domain: periodic axis {a} spans {blocks} blocks of 4 cells; it must be 1 or an even number")));
            }
        }
    }
    Ok(())
}

/// `[boundary]`: friction coefficients >= 0, a platform with an area.
fn check_boundary(b: &Boundary) -> Result<(), Invalid> {
    for (k, w) in [("x_min", b.x_min), ("x_max", b.x_max), ("y_min", b.y_min), ("y_max", b.y_max), ("z_min", b.z_min), ("z_max", b.z_max)] {
        if let WallKind::Friction { mu } = w {
            if !(mu >= 0.0 && mu.is_finite()) {
                return Err(Invalid(format!("boundary.{k}.friction.mu must be >= 0, got {mu}")));
            }
        }
    }
    if let Some(p) = &b.platform {
        if !(p.xy_max[0] > p.xy_min[0] && p.xy_max[1] > p.xy_min[1]) {
            return Err(Invalid("boundary.platform.xy_max must exceed xy_min".into()));
        }
    }
    Ok(())
}

/// `[[body]]` number `i`: a shape with a volume, finite, overlapping the domain (it may be cut by
/// it: symmetry planes).
fn check_body(i: usize, b: &Body, domain: &Domain) -> Result<(), Invalid> {
    let ppc = b.particles_per_cell_axis();
    if ppc == 0 || ppc > 4 {
        return Err(Invalid(format!("body[{i}].particles_per_cell_axis must be 1..=4, got {ppc}")));
    }
    if let Some(region) = b.region() {
        let key = format!("body[{i}]");
        region.validate(&key)?;
        let built = region.build(&key, &ShapeContext { nozzle: None })?;
        if built.bounds().is_none() {
            return Err(Invalid(format!("body[{i}] is unbounded (a half-space, or a union with one): intersect it with a box")));
        }
    }
    let (lo, hi) = b.bounds();
    if lo.iter().chain(hi.iter()).chain(b.velocity().iter()).any(|v| !v.is_finite()) {
        return Err(Invalid(format!("body[{i}]: its position, size and velocity must be finite")));
    }
    match b {
        Body::Box { min, max, .. } => {
            if (0..3).any(|a| !(max[a] > min[a])) {
                return Err(Invalid(format!("body[{i}]: box max must exceed min on every axis")));
            }
        }
        Body::Frustum { bottom_radius, top_radius, height, .. } => {
            if !(*bottom_radius > 0.0 && *top_radius >= 0.0 && *height > 0.0) {
                return Err(Invalid(format!("body[{i}]: frustum radii must be >= 0 (bottom > 0) and height > 0")));
            }
        }
        Body::Union { .. } | Body::Intersection { .. } => {}
    }
    for a in 0..3 {
        if hi[a] <= domain.min[a] || lo[a] >= domain.max[a] {
            return Err(Invalid(format!("body[{i}] lies entirely outside the domain on axis {a}")));
        }
    }
    Ok(())
}
