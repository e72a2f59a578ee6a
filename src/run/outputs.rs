//! A run's output files: VTU snapshots and their PVD index, the CSV of global quantities and
//! the observables, under the disk budget; cut back to a checkpoint's outputs on resume.

use super::{io_err, RunError};
use crate::checkpoint::state;
use crate::disk::{self, DiskFullPolicy};
use crate::memory::{fmt_bytes, parse_size};
use crate::output::vtu::{vtu_size, write_pvd, write_vtu, VtuData, VtuField};
use crate::report::Reporter;
use crate::scenario::Scenario;
use crate::solver::Simulation;
use crate::Real;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Global quantities of the particle state, one CSV row per output.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Globals {
    pub time: f64,
    pub step: u64,
    pub dt: f64,
    pub dt_limit: String,
    pub particles: usize,
    pub kinetic_energy: f64,
    pub max_speed: f64,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    pub mean_j: f64,
    /// Particles asleep (see `sleep.rs`).
    pub asleep: usize,
    /// Wall time since the run started [s] (per-step cost over any interval is the ratio of
    /// its wall and step increments).
    pub wall_s: f64,
    /// CPU time of the process since it started, all threads [s]: the cost measure that other
    /// jobs sharing the machine do not distort.
    pub cpu_s: f64,
    /// Kinetic energy of the inertia the step integrates, s sum 1/2 m v^2 with s =
    /// `simulation.mass_scaling` [J] (`kinetic_energy` is that of the true masses).
    pub scaled_kinetic_energy: f64,
    /// Work of gravity and the body force on the true masses since t = 0 [J].
    pub external_work: f64,
    /// `scaled_kinetic_energy / external_work` (0 before any work is done).
    pub kinetic_to_external: f64,
    /// Froude-like number s v_max^2 / (g h): the scaled inertia of the fastest particle
    /// against the weight over the length h of [`froude_length`] (0 without gravity).
    pub froude: f64,
}

/// Above this `kinetic_to_external` a mass-scaled run warns (docs/scenario.md "Mass scaling").
/// A guideline borrowed from quasi-static explicit practice (kinetic energy kept to a few
/// percent, commonly quoted as 5-10 %, of the internal or external work with Abaqus/Explicit
/// mass scaling), not a bound this code has derived or measured.
pub const KINETIC_TO_EXTERNAL_WARN: f64 = 0.05;

/// When the kinetic-to-external ratio starts to be judged: a print's second layer's start (the
/// end of its only layer), else t = 0. Why: the ratio is cumulative, and during the first layer
/// the external work is still small while the material moving with the nozzle already carries
/// its kinetic energy (the tiny wall of tests/suite/print.rs at s = 1: 20 % at the first output,
/// 0.3 % from the second layer on). Past the first layer it is what the quasi-static argument
/// needs; on that wall 5 % from the second layer separated s = 9 (3 %, the same failure layer
/// and time as s = 1) from s = 25 (8.5 %, a layer early) (docs/scenario.md "Mass scaling").
pub fn judged_from(sim: &Simulation) -> f64 {
    let Some(pr) = &sim.printer else { return 0.0 };
    let layers = pr.toolpath.layers();
    match layers.as_slice() {
        [] => 0.0,
        [only] => only.2,
        [_, second, ..] => second.1,
    }
}

/// The length h of the Froude-like number: the printed layer height (the smallest rise between
/// consecutive layers of the toolpath), else the grid spacing dx. Why the layer: the settling
/// of a fresh layer onto the one below is the quasi-static motion whose inertia matters.
pub fn froude_length(sim: &Simulation) -> f64 {
    let dx = sim.scenario.simulation.dx;
    let Some(pr) = &sim.printer else { return dx };
    let layers = pr.toolpath.layers();
    let rise = layers.windows(2).map(|w| w[1].0 - w[0].0).filter(|h| *h > 1e-9).fold(f64::INFINITY, f64::min);
    if rise.is_finite() {
        rise
    } else {
        dx
    }
}

pub const GLOBALS_HEADER: &str =
    "time,step,dt,dt_limit,particles,kinetic_energy,max_speed,x_min,y_min,z_min,x_max,y_max,z_max,mean_J,asleep,wall_s,cpu_s,scaled_kinetic_energy,external_work,kinetic_to_external,froude";

impl Globals {
    pub fn of(sim: &Simulation) -> Globals {
        let p = &sim.particles;
        let n = p.n;
        let mut g = Globals {
            time: sim.time,
            step: sim.step,
            dt: sim.last_dt,
            dt_limit: format!("{:?}", sim.last_limit).to_lowercase(),
            particles: n,
            asleep: p.n_sleep,
            bbox_min: [f64::INFINITY; 3],
            bbox_max: [f64::NEG_INFINITY; 3],
            ..Default::default()
        };
        let (v, m, j) = (p.v.as_slice(), p.mass.as_slice(), p.j.as_slice());
        for i in 0..n {
            let s2 = v[i].length_squared() as f64;
            g.kinetic_energy += 0.5 * m[i] as f64 * s2;
            g.max_speed = g.max_speed.max(s2.sqrt());
            g.mean_j += j[i] as f64;
            let x = sim.position(i);
            for a in 0..3 {
                g.bbox_min[a] = g.bbox_min[a].min(x[a]);
                g.bbox_max[a] = g.bbox_max[a].max(x[a]);
            }
        }
        if n > 0 {
            g.mean_j /= n as f64;
        }
        let scale = sim.scenario.simulation.mass_scaling;
        g.scaled_kinetic_energy = scale * g.kinetic_energy;
        g.external_work = sim.external_work;
        g.kinetic_to_external = if sim.external_work > 0.0 { g.scaled_kinetic_energy / sim.external_work } else { 0.0 };
        let gravity = sim.scenario.simulation.gravity;
        let g_norm = (gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2]).sqrt();
        if g_norm > 0.0 {
            g.froude = scale * g.max_speed * g.max_speed / (g_norm * froude_length(sim));
        }
        g
    }

    pub fn csv_row(&self) -> String {
        format!(
            "{:.9e},{},{:.6e},{},{},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.12},{},{:.3},{:.2},{:.9e},{:.9e},{:.6e},{:.6e}",
            self.time,
            self.step,
            self.dt,
            self.dt_limit,
            self.particles,
            self.kinetic_energy,
            self.max_speed,
            self.bbox_min[0],
            self.bbox_min[1],
            self.bbox_min[2],
            self.bbox_max[0],
            self.bbox_max[1],
            self.bbox_max[2],
            self.mean_j,
            self.asleep,
            self.wall_s,
            self.cpu_s,
            self.scaled_kinetic_energy,
            self.external_work,
            self.kinetic_to_external,
            self.froude
        )
    }
}

/// User + system CPU time of this process [s], from /proc/self/stat (0 where unavailable).
pub fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // fields after the parenthesised command name; utime and stime are the 12th and 13th
    let Some(rest) = stat.rsplit_once(')').map(|r| r.1) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // the kernel reports in USER_HZ, 100 on every Linux architecture strand targets
    (ticks(11) + ticks(12)) / 100.0
}

fn real_data(s: &[Real]) -> VtuData<'_> {
    #[cfg(not(feature = "f32"))]
    return VtuData::F64(s);
    #[cfg(feature = "f32")]
    return VtuData::F32(s);
}

/// Write the particles of `sim` as a VTU file, after `fits(size)` agrees to its size.
pub fn write_snapshot(
    sim: &Simulation,
    path: &Path,
    staging: &mut Vec<f64>,
    fits: impl FnOnce(u64) -> Result<(), RunError>,
) -> Result<(), RunError> {
    let p = &sim.particles;
    let n = p.n;
    let sl = p.state_len;
    staging.clear();
    for i in 0..n {
        staging.extend_from_slice(&sim.position(i));
    }
    for i in 0..n {
        staging.push(sim.pressure(i));
    }
    for k in 0..sl {
        for i in 0..n {
            staging.push(p.state.as_slice()[i * sl + k] as f64);
        }
    }
    let (pos, rest) = staging.split_at(3 * n);
    let (pressure, state) = rest.split_at(n);
    let names = sim.material.state_names();
    let mut fields = vec![
        VtuField { name: "velocity", components: 3, data: real_data(bytemuck::cast_slice(&p.v.as_slice()[..n])) },
        VtuField { name: "pressure", components: 1, data: VtuData::F64(pressure) },
        VtuField { name: "J", components: 1, data: real_data(&p.j.as_slice()[..n]) },
        VtuField { name: "stress", components: 9, data: real_data(bytemuck::cast_slice(&p.stress.as_slice()[..n])) },
        VtuField { name: "id", components: 1, data: VtuData::U32(&p.id.as_slice()[..n]) },
    ];
    for (k, name) in names.iter().enumerate() {
        fields.push(VtuField { name, components: 1, data: VtuData::F64(&state[k * n..(k + 1) * n]) });
    }
    let size = vtu_size(&VtuData::F64(pos), &fields).map_err(io_err(path))?;
    fits(size)?;
    disk::fault_check(size).map_err(io_err(path))?;
    write_vtu(path, VtuData::F64(pos), &fields).map_err(io_err(path))
}

/// The run's output files and what a resumed run needs to continue them.
pub(super) struct Outputs<'a> {
    out: &'a Path,
    vtu: bool,
    csv_path: PathBuf,
    csv: std::io::BufWriter<std::fs::File>,
    pvd: Vec<(f64, String)>,
    staging: Vec<f64>,
    pub(super) reporter: Option<Reporter>,
    pub(super) start: Instant,
    /// Outputs written: the next is number `k_out + 1` (number 0 is the initial state).
    pub(super) k_out: u64,
    pub(super) disk: Option<DiskGuard>,
    /// The inertia mass scaling adds, as the outputs saw it.
    pub(super) inertia: Inertia,
}

/// The largest kinetic-to-external ratio and Froude-like number the outputs saw from
/// [`judged_from`] on (and before a failure, when the run detects one: a collapse is dynamic
/// whatever the scaling), and whether the warning was given.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Inertia {
    pub mass_scaling: f64,
    /// The time from which the peaks are kept and the warning judged ([`judged_from`]).
    pub from: f64,
    pub peak_kinetic_to_external: f64,
    pub peak_time: f64,
    pub peak_froude: f64,
    pub warned: bool,
}

/// The disk budget as the output stage applies it (policy in `disk.rs`).
pub(super) struct DiskGuard {
    pub(super) limit: u64,
    policy: DiskFullPolicy,
    /// Kept free for a checkpoint at full pool capacity and the small files.
    reserve: u64,
}

impl<'a> Outputs<'a> {
    /// The output files of a run in `out`: a resumed run's CSV and snapshots cut back to the
    /// `k_out` outputs its checkpoint had written, a fresh run's CSV begun with its header.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn open(sc: &Scenario, sim: &Simulation, out: &'a Path, csv_path: PathBuf, resumed: bool, k_out: u64, mut progress: state::Progress, staging_bytes: usize) -> Result<Self, RunError> {
        if resumed {
            keep_first_rows(&csv_path, k_out + 1).map_err(io_err(&csv_path))?;
            remove_snapshots_after(out, k_out);
        } else {
            std::fs::write(&csv_path, format!("{GLOBALS_HEADER}\n")).map_err(io_err(&csv_path))?;
        }
        let csv = std::fs::OpenOptions::new().append(true).open(&csv_path).map_err(io_err(&csv_path))?;
        let mut reporter = Reporter::new(sc, sim).map_err(RunError::Report)?;
        if let Some(r) = &mut reporter {
            r.history = std::mem::take(&mut progress.observations);
            r.detect_failure();
        }
        let disk = match &sc.output.disk_budget {
            Some(b) => Some(DiskGuard {
                limit: parse_size(b).map_err(|e| RunError::DiskBudget(format!("output.disk_budget: {e}")))?,
                policy: sc.output.on_disk_full,
                reserve: disk::SMALL_FILE_RESERVE + if sc.checkpoint.enabled { staging_bytes as u64 + (1 << 20) } else { 0 },
            }),
            None => None,
        };
        Ok(Outputs {
            out,
            vtu: sc.output.vtu,
            csv_path,
            csv: std::io::BufWriter::new(csv),
            pvd: progress.pvd,
            staging: Vec::with_capacity(sim.particles.capacity() * (4 + sim.particles.state_len)),
            reporter,
            start: Instant::now(),
            k_out,
            disk,
            inertia: Inertia { mass_scaling: sc.simulation.mass_scaling, from: judged_from(sim), ..Inertia::default() },
        })
    }
}

impl Outputs<'_> {
    pub(super) fn write(&mut self, sim: &Simulation) -> Result<(), RunError> {
        // the snapshot first: if the disk budget refuses it, nothing of this output is written,
        // so a checkpoint taken then resumes into exactly this output again
        if self.vtu {
            let name = format!("particles_{:05}.vtu", self.k_out);
            let path = self.out.join(&name);
            let mut staging = std::mem::take(&mut self.staging);
            let r = write_snapshot(sim, &path, &mut staging, |size| self.make_room(size));
            self.staging = staging;
            r?;
            self.pvd.push((sim.time, name));
            let pvd_path = self.out.join("particles.pvd");
            write_pvd(&pvd_path, &self.pvd).map_err(io_err(&pvd_path))?;
        }
        let g = Globals { wall_s: self.start.elapsed().as_secs_f64(), cpu_s: process_cpu_seconds(), ..Globals::of(sim) };
        writeln!(self.csv, "{}", g.csv_row()).map_err(io_err(&self.csv_path))?;
        self.csv.flush().map_err(io_err(&self.csv_path))?;
        if let Some(r) = &mut self.reporter {
            r.observe(sim);
            r.write(self.out).map_err(RunError::Report)?;
        }
        let extruding = sim.printer.as_ref().is_some_and(|p| p.plan.laid.is_none());
        self.watch_inertia(&g, extruding, sim.sleep.as_ref().is_some_and(|z| z.tests_loads()));
        Ok(())
    }

    /// Keep the peaks of the inertia figures and warn once, on stderr, when a mass-scaled run's
    /// kinetic energy passes [`KINETIC_TO_EXTERNAL_WARN`] of the external work, from
    /// [`judged_from`] on. Only with
    /// s > 1: at s = 1 the inertia is the material's own and there is nothing to lower. Not
    /// after a detected failure: the collapse that follows is dynamic by nature. A print that
    /// extrudes (`extruding`) is told that a laid deposit brings no momentum from the nozzle; one
    /// whose sleeping units wake by their load (`waking_by_load`), that waking can set them moving.
    fn watch_inertia(&mut self, g: &Globals, extruding: bool, waking_by_load: bool) {
        if g.time < self.inertia.from || self.reporter.as_ref().is_some_and(|r| r.failure.is_some_and(|f| f.time <= g.time)) {
            return;
        }
        let w = &mut self.inertia;
        w.peak_froude = w.peak_froude.max(g.froude);
        if g.kinetic_to_external > w.peak_kinetic_to_external {
            (w.peak_kinetic_to_external, w.peak_time) = (g.kinetic_to_external, g.time);
        }
        if w.mass_scaling > 1.0 && !w.warned && g.kinetic_to_external > KINETIC_TO_EXTERNAL_WARN {
            w.warned = true;
            eprintln!(
                "warning: at t = {:.4} s the kinetic energy of the scaled inertia is {:.1} % of the external work \
                 (more than {:.0} %): simulation.mass_scaling = {} is making the motion dynamic; lower mass_scaling{}{}",
                g.time,
                100.0 * g.kinetic_to_external,
                100.0 * KINETIC_TO_EXTERNAL_WARN,
                w.mass_scaling,
                if extruding {
                    ", or, where the layer's shape is not the question, lay the deposit (print.deposit = { kind = \"laid\", ... }): \
                     extruded material arrives with the scaled momentum flux s rho V^2 of the nozzle's motion, a laid one with none"
                } else {
                    ""
                },
                if waking_by_load {
                    ", or compare a run without [sleep]: sleeping units are held rigid and, woken by their load, take it \
                     at once (docs/failure.md \"Sleeping and failure\")"
                } else {
                    ""
                }
            );
        }
    }

    /// Room for a snapshot of `size` bytes under the disk budget, pruning old snapshots if the
    /// policy says so.
    fn make_room(&mut self, size: u64) -> Result<(), RunError> {
        let Some(d) = &self.disk else { return Ok(()) };
        loop {
            let used = disk::usage(self.out);
            if used + size + d.reserve <= d.limit {
                return Ok(());
            }
            if d.policy == DiskFullPolicy::PruneSnapshots && self.pvd.len() > 1 {
                let (_, old) = self.pvd.remove(0);
                std::fs::remove_file(self.out.join(&old)).map_err(io_err(&self.out.join(&old)))?;
                let pvd_path = self.out.join("particles.pvd");
                write_pvd(&pvd_path, &self.pvd).map_err(io_err(&pvd_path))?;
                continue;
            }
            return Err(RunError::DiskBudget(format!(
                "the next snapshot ({}) would take {} to {} of its {} budget, with {} kept free for a \
                 final checkpoint and the CSV files; raise [output] disk_budget{}",
                fmt_bytes(size),
                self.out.display(),
                fmt_bytes(used + size),
                fmt_bytes(d.limit),
                fmt_bytes(d.reserve),
                if d.policy == DiskFullPolicy::Stop { ", or set [output] on_disk_full = \"prune_snapshots\"" } else { "" }
            )));
        }
    }

    /// What a checkpoint of `sim` carries beside its pools: the outputs so far and the external
    /// work, which no pool holds.
    pub(super) fn progress(&self, sim: &Simulation) -> state::Progress {
        state::Progress {
            pvd: self.pvd.clone(),
            observations: self.reporter.as_ref().map(|r| r.history.clone()).unwrap_or_default(),
            external_work: sim.external_work,
        }
    }
}

/// Keep the header and the first `rows` data rows of a CSV file (the outputs a checkpoint
/// covers), written atomically; a missing file gets just its header.
fn keep_first_rows(path: &Path, rows: u64) -> std::io::Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => format!("{GLOBALS_HEADER}\n"),
        Err(e) => return Err(e),
    };
    let kept: String = text.lines().take(1 + rows as usize).map(|l| format!("{l}\n")).collect();
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, kept)?;
    std::fs::rename(&tmp, path)
}

/// Delete snapshots numbered after `k_out`: a killed run wrote them after its last checkpoint,
/// and the resumed run writes them again.
fn remove_snapshots_after(out: &Path, k_out: u64) {
    let Ok(rd) = std::fs::read_dir(out) else { return };
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let k = name.strip_prefix("particles_").and_then(|r| r.strip_suffix(".vtu")).and_then(|k| k.parse::<u64>().ok());
        if k.is_some_and(|k| k > k_out) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}
