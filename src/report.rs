//! What a run reports besides snapshots: printed-geometry and slump observables at each output
//! (CSV), and cross-section plots (PNG).

pub use crate::config::ObserveConfig;
use crate::failure::{Detector, Failure};
use crate::observe::{self, Cloud, CrossSection, SECTION_CSV_HEADER};
use crate::observe::PointsCsvError;
use crate::output::plot::{plot_cross_section, PlotError};
use crate::scenario::Scenario;
use crate::solver::{SimError, Simulation};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Why the observables cannot be taken or written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error(transparent)]
    Sim(#[from] SimError),
    /// `[observe] measured`: the measured profile points.
    #[error(transparent)]
    Measured(#[from] PointsCsvError),
    #[error("a failure needs a print of two or more layers and [observe] stations (this one has {layers} layers)")]
    NoFailureDetector { layers: usize },
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error(transparent)]
    Plot(#[from] PlotError),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |source| ReportError::Io { path: path.to_path_buf(), source }
}

/// Observables of one output time.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Observation {
    pub time: f64,
    pub sections: Vec<CrossSection>,
    /// Per-layer thickness at each station (one row per station), when printing.
    pub layers: Vec<Vec<f64>>,
    pub total_height: f64,
    pub spread: Option<observe::Spread>,
}

/// Computes the observables a scenario asks for and writes them into the output folder:
/// `sections.csv`, `profiles.csv`, `layers.csv`, `spread.csv`, and `section_x<mm>.png`.
pub struct Reporter {
    cfg: ObserveConfig,
    base_z: f64,
    slab: f64,
    spacing: f64,
    layer_tops: Vec<f64>,
    measured: Option<Vec<[f64; 2]>>,
    pos: Vec<[f64; 3]>,
    vol: Vec<f64>,
    /// Every observation so far (profiles are small: one point per particle column).
    pub history: Vec<Observation>,
    detector: Option<Detector>,
    /// The print's failure, once the history shows it.
    pub failure: Option<Failure>,
}

/// The failure of the print `sc`, as `strand run` finds it, without writing anything: the run
/// observed at every output (`[output] interval`) until the failure shows or the run ends. With
/// the number of layers printed. The measurement loop's failure observables
/// (`failure::observable`).
pub fn failure_of(sc: &Scenario) -> Result<(Option<Failure>, usize), ReportError> {
    let mut sim = Simulation::new(sc)?;
    let layers = sim.printer.as_ref().map_or(0, |p| p.toolpath.layers().len());
    let mut r = match Reporter::new(sc, &sim)? {
        Some(r) if r.detector.is_some() => r,
        _ => return Err(ReportError::NoFailureDetector { layers }),
    };
    let (end, interval) = (sc.simulation.end_time, sc.output.interval);
    r.observe(&sim);
    let mut k = 0u64;
    while r.failure.is_none() && sim.time < end * (1.0 - 1e-12) {
        k += 1;
        let next = (k as f64 * interval).min(end);
        while sim.time < next * (1.0 - 1e-12) {
            sim.step_until(next)?;
        }
        r.observe(&sim);
    }
    Ok((r.failure, layers))
}

impl Reporter {
    /// None when the scenario observes nothing.
    pub fn new(sc: &Scenario, sim: &Simulation) -> Result<Option<Reporter>, ReportError> {
        let Some(cfg) = sc.observe.clone() else { return Ok(None) };
        let dx = sc.simulation.dx;
        let base_z = cfg
            .base_z
            .or(sc.boundary.platform.as_ref().map(|p| p.z))
            .unwrap_or(sc.domain.min[2]);
        let spacing = match (&sim.printer, sc.bodies.first()) {
            (Some(p), _) => p.spacing,
            (None, Some(b)) => dx / b.particles_per_cell_axis() as f64,
            (None, None) => dx / 2.0,
        };
        let layer_tops = sim.printer.as_ref().map(|p| p.toolpath.layers().iter().map(|l| l.0).collect()).unwrap_or_default();
        let measured = match &cfg.measured {
            Some(f) => Some(observe::read_points_csv(&sc.base_dir.join(f))?),
            None => None,
        };
        let cap = sim.particles.capacity() * if cfg.mirror_y.is_some() { 2 } else { 1 };
        let detector = match &sim.printer {
            Some(p) if !cfg.stations.is_empty() => {
                Detector::new(&cfg.failure, p.toolpath.clone(), p.shape.half_extent()[0], cfg.y_range)
            }
            _ => None,
        };
        Ok(Some(Reporter {
            slab: cfg.slab.unwrap_or(dx),
            cfg,
            base_z,
            spacing,
            layer_tops,
            measured,
            pos: Vec::with_capacity(cap),
            vol: Vec::with_capacity(cap),
            history: Vec::new(),
            detector,
            failure: None,
        }))
    }

    /// Find the failure in the history (after a resume replaced it, or a new observation).
    pub fn detect_failure(&mut self) {
        if self.failure.is_none() {
            if let Some(d) = &self.detector {
                self.failure = d.detect(&self.history, |o| (o.time, &o.sections[..]));
            }
        }
    }

    /// Time at which the run should end after its failure (`[observe] failure.stop_after`).
    pub fn stop_time(&self) -> Option<f64> {
        Some(self.failure?.time + self.cfg.failure.stop_after?)
    }

    /// Observe the current state.
    pub fn observe(&mut self, sim: &Simulation) -> &Observation {
        let p = &sim.particles;
        self.pos.clear();
        self.vol.clear();
        for i in 0..p.n {
            self.pos.push(sim.position(i));
            self.vol.push(p.vol0.as_slice()[i] as f64 * p.j.as_slice()[i] as f64);
        }
        if let Some(y0) = self.cfg.mirror_y {
            for i in 0..p.n {
                let x = self.pos[i];
                self.pos.push([x[0], 2.0 * y0 - x[1], x[2]]);
                self.vol.push(self.vol[i]);
            }
        }
        if let Some([lo, hi]) = self.cfg.y_range {
            let mut kept = 0;
            for i in 0..self.pos.len() {
                if (lo..=hi).contains(&self.pos[i][1]) {
                    self.pos[kept] = self.pos[i];
                    self.vol[kept] = self.vol[i];
                    kept += 1;
                }
            }
            self.pos.truncate(kept);
            self.vol.truncate(kept);
        }
        let cloud = Cloud { pos: &self.pos, vol: &self.vol, spacing: self.spacing };
        let sections: Vec<CrossSection> =
            self.cfg.stations.iter().map(|&x| observe::cross_section(&cloud, x, self.slab, self.base_z)).collect();
        let layers = if self.layer_tops.len() > 1 {
            self.cfg
                .stations
                .iter()
                .map(|&x| observe::layer_heights(&cloud, x, self.slab, &self.layer_tops, self.base_z))
                .collect()
        } else {
            Vec::new()
        };
        let spread = self.cfg.spread.then(|| observe::slump_spread(&cloud, self.base_z, 2.0 * self.spacing));
        let total_height = observe::total_height(&cloud, self.base_z);
        self.history.push(Observation { time: sim.time, sections, layers, total_height, spread });
        self.detect_failure();
        self.history.last().expect("just pushed")
    }

    /// Rewrite the CSV files and plots from the history.
    pub fn write(&self, dir: &Path) -> Result<(), ReportError> {
        if !self.cfg.stations.is_empty() {
            let path = dir.join("sections.csv");
            let mut f = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io(&path))?);
            writeln!(f, "{SECTION_CSV_HEADER}").map_err(io(&path))?;
            for o in &self.history {
                for s in &o.sections {
                    writeln!(f, "{}", s.csv_row(o.time)).map_err(io(&path))?;
                }
            }
            f.flush().map_err(io(&path))?;
            let path = dir.join("profiles.csv");
            let all: Vec<(f64, &CrossSection)> =
                self.history.iter().flat_map(|o| o.sections.iter().map(move |s| (o.time, s))).collect();
            observe::write_profile_csv(&path, &all).map_err(io(&path))?;
            if let Some(last) = self.history.last() {
                for s in &last.sections {
                    let png = dir.join(format!("section_x{:.1}mm.png", s.station * 1e3));
                    let title = format!("cross-section at x = {:.1} mm, t = {:.3} s", s.station * 1e3, last.time);
                    let lines = vec![(format!("t = {:.3} s", last.time), s.profile.clone())];
                    plot_cross_section(&png, &title, &lines, self.measured.as_deref())?;
                }
            }
        }
        let path = dir.join("layers.csv");
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io(&path))?);
        // failure_layer (1 = the first) and failure_time on the rows from the failure time on,
        // empty before it and when the print stands
        writeln!(f, "time,station,layer,thickness,total_height,failure_layer,failure_time").map_err(io(&path))?;
        for o in &self.history {
            let failed = match self.failure {
                Some(fl) if fl.time <= o.time => format!("{},{:.9e}", fl.layer, fl.time),
                _ => ",".to_string(),
            };
            for (k, st) in self.cfg.stations.iter().enumerate() {
                for (l, th) in o.layers.get(k).map(|v| v.as_slice()).unwrap_or(&[]).iter().enumerate() {
                    writeln!(f, "{:.9e},{st},{l},{th:.9e},{:.9e},{failed}", o.time, o.total_height).map_err(io(&path))?;
                }
            }
        }
        f.flush().map_err(io(&path))?;
        if self.cfg.spread {
            let path = dir.join("spread.csv");
            let mut f = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io(&path))?);
            writeln!(f, "time,mean_diameter,d_x,d_y,area_diameter").map_err(io(&path))?;
            for o in &self.history {
                if let Some(s) = &o.spread {
                    writeln!(f, "{:.9e},{:.9e},{:.9e},{:.9e},{:.9e}", o.time, s.mean_diameter, s.d_x, s.d_y, s.area_diameter)
                        .map_err(io(&path))?;
                }
            }
            f.flush().map_err(io(&path))?;
        }
        Ok(())
    }
}
