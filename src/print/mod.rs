//! 3D concrete printing: the `[print]` scenario table, toolpaths (and their G-code import), the
//! nozzle, and the emission stage of the pipeline.
//!
//! The nozzle is a vertical tube of height `tube_height` whose outlet follows the toolpath. Grid
//! nodes inside the tube move with the nozzle and, downwards, at the extrusion speed U: the
//! concrete in a nozzle advances as a plug (yield-stress fluids slip on a lubricating layer at
//! the wall), so driving every node of the tube is closer to the physics than 000's rule of
//! adding U only to the topmost node, and it fixes the flux through the outlet at A U whatever
//! the resolution. A node's weight is the indicator of 000 eqs. 23-24 (or the hard `if`).

pub mod arc;
pub mod emitter;
pub mod gcode;
pub mod gcode_dialect;
pub mod imperfection;
pub mod laid;
pub mod newest;
pub mod nozzle;
pub mod points;
pub mod pump;
pub mod toolpath;

use crate::kernels::nozzle::Indicator;
use crate::kernels::Real;
use emitter::{EmissionPlan, Emitter};
use newest::Newest;
use nozzle::NozzleShape;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use toolpath::{Segment, Toolpath};
use crate::invalid::Invalid;

/// The `[print]` table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrintConfig {
    pub nozzle: NozzleShape,
    /// Height of the driven tube above the outlet [m]; default two cells.
    #[serde(default)]
    pub tube_height: Option<f64>,
    /// "smooth" (000 eqs. 23-24, the default) or "hard" (the plain `if`).
    #[serde(default)]
    pub indicator: IndicatorKind,
    /// Width delta of the smooth indicator's transition band, centred on the nozzle wall [m];
    /// default one cell.
    #[serde(default)]
    pub transition: Option<f64>,
    /// New particles per cell along each axis.
    #[serde(default = "default_ppc")]
    pub particles_per_cell_axis: u32,
    /// "continuous" (the default: one particle layer of thickness h = dx / ppc whenever the
    /// extruded length has grown by h, so the flux is smooth in time) or "interval" (000 sec.
    /// 2.4: a whole cell of layers every dx / U, which pulses at that frequency).
    #[serde(default)]
    pub emission: Emission,
    /// Outlet position at t = 0 [m] (for `path`).
    #[serde(default)]
    pub start: Option<[f64; 3]>,
    /// Inline toolpath.
    #[serde(default)]
    pub path: Vec<Segment>,
    /// G-code toolpath file (relative to the scenario file), instead of `path`.
    #[serde(default)]
    pub gcode: Option<PathBuf>,
    #[serde(default)]
    pub gcode_options: gcode::GcodeOptions,
    /// Point-list toolpath file (CSV `x, y, z, speed, flow` in SI units, relative to the
    /// scenario file, see `print::points`), instead of `path`: a robot's export.
    #[serde(default)]
    pub points: Option<PathBuf>,
    /// Delivered over commanded flow: every print move's extrusion speed is this times the
    /// toolpath's (a pump or a flow multiplier off by some percent); default 1.
    #[serde(default = "one")]
    pub extrusion_factor: f64,
    /// Added to the nozzle's height all along the toolpath [m] (a Z offset: the standoff the
    /// printer really holds against the one commanded); default 0.
    #[serde(default)]
    pub z_offset: f64,
    /// A horizontal offset of the nozzle growing with its height (see `print::imperfection`), to
    /// make a print buckle one chosen way; default none.
    #[serde(default)]
    pub imperfection: Option<imperfection::Imperfection>,
    /// How material enters: "extruded" through the nozzle's tube (the default), or "laid" at
    /// rest in a nominal section as the nozzle passes (`print::laid`).
    #[serde(default)]
    pub deposit: Deposit,
    /// Slab buffers the emitter may prepare ahead of the stepper.
    #[serde(default = "default_queue")]
    pub queue: usize,
}

fn default_ppc() -> u32 {
    2
}
fn one() -> f64 {
    1.0
}
fn default_queue() -> usize {
    64
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum IndicatorKind {
    #[default]
    Smooth,
    Hard,
}

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Emission {
    #[default]
    Continuous,
    Interval,
}

/// `[print] deposit`: `{ kind = "extruded" }` (the default) or `{ kind = "laid", width, height }`.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Deposit {
    #[default]
    Extruded,
    Laid(laid::LaidSection),
}

impl Deposit {
    pub fn laid(&self) -> Option<&laid::LaidSection> {
        match self {
            Deposit::Laid(s) => Some(s),
            Deposit::Extruded => None,
        }
    }
}

/// Why the print cannot be set up: a value its check refuses, a G-code file that cannot be read
/// or parsed, or a toolpath that does not chain.
#[derive(Debug, thiserror::Error)]
pub enum PrintError {
    #[error(transparent)]
    Invalid(#[from] Invalid),
    #[error("print.{key} {}: {source}", path.display())]
    Read { key: &'static str, path: PathBuf, source: std::io::Error },
    #[error("{}: {source}", path.display())]
    Gcode { path: PathBuf, source: gcode::GcodeError },
    #[error("{}: {source}", path.display())]
    Points { path: PathBuf, source: points::PointsError },
    #[error(transparent)]
    Toolpath(#[from] toolpath::ToolpathError),
}

impl PrintConfig {
    pub fn validate(&self) -> Result<(), Invalid> {
        self.nozzle.validate()?;
        if let Some(h) = self.tube_height {
            if !(h > 0.0 && h.is_finite()) {
                return Err(Invalid(format!("print.tube_height must be > 0, got {h}")));
            }
        }
        if let Some(d) = self.transition {
            if !(d > 0.0 && d.is_finite()) {
                return Err(Invalid(format!("print.transition must be > 0, got {d}")));
            }
        }
        if !(1..=4).contains(&self.particles_per_cell_axis) {
            return Err(Invalid(format!("print.particles_per_cell_axis must be 1..=4, got {}", self.particles_per_cell_axis)));
        }
        let given: Vec<&str> = [("print.path", !self.path.is_empty()), ("print.gcode", self.gcode.is_some()), ("print.points", self.points.is_some())]
            .into_iter()
            .filter_map(|(key, given)| given.then_some(key))
            .collect();
        match given[..] {
            [] => return Err(Invalid("print: no toolpath; give print.path segments, print.gcode or print.points".into())),
            ["print.path"] if self.start.is_none() => return Err(Invalid("print.start (outlet position at t = 0) is missing".into())),
            [_] => {}
            _ => return Err(Invalid(format!("print: give one toolpath, not {}", given.join(" and ")))),
        }
        if self.queue == 0 {
            return Err(Invalid("print.queue must be >= 1".into()));
        }
        if !(self.extrusion_factor.is_finite() && self.extrusion_factor > 0.0) {
            return Err(Invalid(format!("print.extrusion_factor must be finite and > 0, got {}", self.extrusion_factor)));
        }
        if !self.z_offset.is_finite() {
            return Err(Invalid(format!("print.z_offset must be finite, got {}", self.z_offset)));
        }
        if let Some(imp) = &self.imperfection {
            imp.validate()?;
        }
        if let Some(l) = self.deposit.laid() {
            l.validate()?;
            if self.emission == Emission::Interval {
                return Err(Invalid("print.emission = \"interval\" is a rule of extruded deposits; a laid deposit adds whole columns".into()));
            }
        }
        Ok(())
    }

    /// Build the toolpath (reading the G-code file relative to `base_dir`), with the
    /// imperfection (from the commanded heights), the extrusion factor and the Z offset applied.
    pub fn toolpath(&self, base_dir: &Path) -> Result<Toolpath, PrintError> {
        let read = |key, file: &PathBuf| {
            let path = base_dir.join(file);
            std::fs::read_to_string(&path).map(|text| (text, path.clone())).map_err(|source| PrintError::Read { key, path, source })
        };
        let commanded = match (&self.gcode, &self.points) {
            (Some(file), _) => {
                let (text, path) = read("gcode", file)?;
                gcode::parse_gcode_for_outlet(&text, &self.gcode_options, self.nozzle.area()).map(|(p, _)| p).map_err(|source| PrintError::Gcode { path, source })?
            }
            (None, Some(file)) => {
                let (text, path) = read("points", file)?;
                points::parse_points(&text, self.nozzle.area()).map_err(|source| PrintError::Points { path, source })?
            }
            (None, None) => Toolpath::from_segments(self.start.unwrap_or_default(), &self.path)?,
        };
        let commanded = match &self.imperfection {
            Some(imp) => imp.apply(commanded)?,
            None => commanded,
        };
        if self.extrusion_factor == 1.0 && self.z_offset == 0.0 {
            return Ok(commanded);
        }
        let delivered = commanded
            .moves()
            .iter()
            .map(|m| {
                let shift = |mut p: [f64; 3]| {
                    p[2] += self.z_offset;
                    p
                };
                toolpath::Move { from: shift(m.from), to: shift(m.to), extrusion_speed: self.extrusion_factor * m.extrusion_speed, ..m.clone() }
            })
            .collect();
        Ok(Toolpath::from_moves(delivered)?)
    }
}

/// The nozzle's drive at one time, as the grid update applies it.
#[derive(Clone, Copy, Debug)]
pub struct NozzleDrive {
    /// Outlet centre [m].
    pub outlet: [f64; 3],
    pub tube_height: f64,
    /// Velocity imposed inside the tube: nozzle velocity plus U downwards.
    pub velocity: [f64; 3],
    pub shape: NozzleShape,
    pub indicator: Indicator,
}

impl NozzleDrive {
    /// Bounding box of the nodes the drive may touch.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let [ex, ey] = self.shape.half_extent();
        let pad = match self.indicator {
            Indicator::Smooth { delta } => 0.5 * delta as f64,
            Indicator::Hard => 0.0,
        };
        let o = self.outlet;
        ([o[0] - ex - pad, o[1] - ey - pad, o[2]], [o[0] + ex + pad, o[1] + ey + pad, o[2] + self.tube_height])
    }

    /// Weight of the drive at world point `x` (0 outside the tube).
    #[inline]
    pub fn weight(&self, x: [f64; 3]) -> Real {
        if x[2] < self.outlet[2] - 1e-12 || x[2] > self.outlet[2] + self.tube_height + 1e-12 {
            return 0.0;
        }
        let (d, r) = self.shape.distance(x[0] - self.outlet[0], x[1] - self.outlet[1]);
        crate::kernels::nozzle::weight(self.indicator, d as Real, r as Real)
    }
}

/// The printing process of a running simulation.
pub struct Printer {
    pub toolpath: Arc<Toolpath>,
    pub shape: NozzleShape,
    pub tube_height: f64,
    pub indicator: Indicator,
    /// Particle spacing of emitted material.
    pub spacing: f64,
    /// Volume each emitted particle stands for.
    pub particle_volume: f64,
    pub plan: EmissionPlan,
    pub emitter: Option<Emitter>,
    /// Emission in the stepper's own thread instead of `emitter`, for gradient runs: they jump
    /// back and forth in time, which a queue filled ahead cannot follow.
    pub sync: Option<SyncEmission>,
    /// The newest slab while it enters (continuous emission).
    pub newest: Newest,
}

/// Slab by slab emission without a thread: `next` is the first slab not yet added.
pub struct SyncEmission {
    pub next: u64,
    slab: emitter::Slab,
    /// The slab `slab` holds, if filled.
    filled: Option<u64>,
}

impl SyncEmission {
    pub fn new(plan: &EmissionPlan, next: u64) -> SyncEmission {
        let slab = emitter::Slab { slab: 0, due: 0.0, velocity: [0.0; 3], moves: (None, 0), positions: Vec::with_capacity(plan.particles_per_slab()) };
        SyncEmission { next, slab, filled: None }
    }

    /// Hand every slab due at or before `t` to `add`, in order, as `Emitter::drain_due` does.
    pub fn drain_due<E>(&mut self, plan: &EmissionPlan, t: f64, mut add: impl FnMut(&emitter::Slab) -> Result<(), E>) -> Result<(), E> {
        let total = plan.slabs();
        while self.next < total {
            if self.filled != Some(self.next) {
                plan.fill(self.next, &mut self.slab);
                self.filled = Some(self.next);
            }
            if self.slab.due > t {
                break;
            }
            add(&self.slab)?;
            self.next += 1;
        }
        Ok(())
    }
}

impl Printer {
    pub fn new(cfg: &PrintConfig, dx: f64, domain: ([f64; 3], [f64; 3]), base_dir: &Path) -> Result<Printer, PrintError> {
        cfg.validate()?;
        let toolpath = Arc::new(cfg.toolpath(base_dir)?);
        let ppc = cfg.particles_per_cell_axis;
        let h = dx / ppc as f64;
        let indicator = match cfg.indicator {
            IndicatorKind::Hard => Indicator::Hard,
            IndicatorKind::Smooth => Indicator::Smooth { delta: cfg.transition.unwrap_or(dx) as Real },
        };
        let group = match cfg.emission {
            Emission::Continuous => 1,
            Emission::Interval => ppc,
        };
        let (plan, particle_volume) = if let Some(section) = cfg.deposit.laid() {
            section.check(&toolpath, cfg.nozzle.area())?;
            let lattice = section.lattice(h);
            let (per_column, volume) = (lattice.volume / cfg.nozzle.area(), lattice.particle_volume());
            let laid = Some((Arc::new(lattice), per_column));
            (EmissionPlan { toolpath: toolpath.clone(), offsets: Arc::new(Vec::new()), spacing: h, group: 1, tube_height: 0.0, domain, partial: false, laid }, volume)
        } else {
            let offsets = cfg.nozzle.lattice(h);
            if offsets.is_empty() {
                return Err(Invalid(format!("print.nozzle is smaller than one particle spacing ({h} m); refine simulation.dx")).into());
            }
            let volume = cfg.nozzle.area() * h / offsets.len() as f64;
            let tube_height = cfg.tube_height.unwrap_or(2.0 * dx);
            let partial = cfg.emission == Emission::Continuous;
            (EmissionPlan { toolpath: toolpath.clone(), offsets: Arc::new(offsets), spacing: h, group, tube_height, domain, partial, laid: None }, volume)
        };
        let newest = Newest::new(plan.particles_per_slab());
        let tube_height = plan.tube_height;
        Ok(Printer { toolpath, shape: cfg.nozzle, tube_height, indicator, spacing: h, particle_volume, plan, emitter: None, sync: None, newest })
    }

    /// Slabs handed to the stepper so far.
    pub fn emitted(&self) -> u64 {
        match (&self.sync, &self.emitter) {
            (Some(s), _) => s.next,
            (None, Some(e)) => e.emitted,
            (None, None) => 0,
        }
    }

    /// Start the emitter thread at slab `first`.
    pub fn start(&mut self, buffers: usize, first: u64) {
        self.emitter = Some(Emitter::spawn(self.plan.clone(), buffers, first));
    }

    /// The drive at time `t`, or None once the toolpath has ended.
    pub fn drive(&self, t: f64) -> Option<NozzleDrive> {
        // a laid deposit has no tube to drive
        if t >= self.toolpath.end_time() || self.plan.laid.is_some() {
            return None;
        }
        let s = self.toolpath.state_at(t);
        Some(NozzleDrive {
            outlet: s.position,
            tube_height: self.tube_height,
            velocity: [s.velocity[0], s.velocity[1], s.velocity[2] - s.extrusion_speed],
            shape: self.shape,
            indicator: self.indicator,
        })
    }
}
