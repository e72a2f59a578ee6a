//! `strand run`: drive a simulation to its end time, writing VTU snapshots, a CSV of global
//! quantities and progress.

use crate::memory::fmt_bytes;
use crate::output::vtu::{write_pvd, write_vtu, VtuData, VtuField};
use crate::report::Reporter;
use crate::scenario::Scenario;
use crate::solver::{SimError, Simulation};
use crate::Real;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{source}\n  the state after the failing step is in {} (outputs before it are kept)", snapshot.display())]
    Failed { source: SimError, snapshot: PathBuf },
    #[error("output {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{0}")]
    Report(String),
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Io { path: path.to_path_buf(), source }
}

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
}

pub const GLOBALS_HEADER: &str =
    "time,step,dt,dt_limit,particles,kinetic_energy,max_speed,x_min,y_min,z_min,x_max,y_max,z_max,mean_J,asleep,wall_s,cpu_s";

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
        g
    }

    pub fn csv_row(&self) -> String {
        format!(
            "{:.9e},{},{:.6e},{},{},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.12},{},{:.3},{:.2}",
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
            self.cpu_s
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

/// Write the particles of `sim` as a VTU file.
pub fn write_snapshot(sim: &Simulation, path: &Path, staging: &mut Vec<f64>) -> std::io::Result<()> {
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
    write_vtu(path, VtuData::F64(pos), &fields)
}

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out: PathBuf,
    /// Override the scenario's thread count.
    pub threads: Option<usize>,
    pub quiet: bool,
}

pub struct RunSummary {
    pub steps: u64,
    pub time: f64,
    pub wall_s: f64,
    pub particles: usize,
    /// Observables at each output, when the scenario asks for them.
    pub observations: Vec<crate::report::Observation>,
    /// Wall seconds spent in each phase of the step (see `solver::PHASES`).
    pub phase_seconds: [f64; 6],
}

/// Run a scenario to its end, writing outputs into `opts.out`.
pub fn run_scenario(scenario: &Scenario, opts: &RunOptions) -> Result<RunSummary, RunError> {
    let mut sc = scenario.clone();
    if let Some(t) = opts.threads {
        sc.simulation.threads = t;
    }
    std::fs::create_dir_all(&opts.out).map_err(io_err(&opts.out))?;
    let mut sim = Simulation::new(&sc)?;
    let say = |m: String| {
        if !opts.quiet {
            eprintln!("{m}");
        }
    };
    say(format!(
        "strand: '{}' — {} particles, {} threads, {} precision\nmemory plan (budget {}):\n{}",
        sc.name,
        sim.particles.n,
        sim.threads(),
        crate::kernels::real::NAME,
        fmt_bytes(sim.budget),
        sim.memory
    ));
    let (dt0, lim0) = sim.choose_dt(f64::INFINITY);
    say(format!("time step: {dt0:.3e} s, bound by {lim0:?}"));

    let csv_path = opts.out.join("globals.csv");
    let mut csv = std::io::BufWriter::new(std::fs::File::create(&csv_path).map_err(io_err(&csv_path))?);
    writeln!(csv, "{GLOBALS_HEADER}").map_err(io_err(&csv_path))?;
    let mut pvd: Vec<(f64, String)> = Vec::new();
    let mut staging = Vec::with_capacity(sim.particles.capacity() * (4 + sim.particles.state_len));
    let mut reporter = Reporter::new(&sc, &sim).map_err(RunError::Report)?;

    let end = sc.simulation.end_time;
    let interval = sc.output.interval;
    let mut k_out = 0u64;
    let start = Instant::now();
    let est_steps = (end / dt0).ceil().max(1.0) as u64;
    let bar = if !opts.quiet && std::io::stderr().is_terminal() {
        let b = indicatif::ProgressBar::new(est_steps);
        b.set_style(
            indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} steps  {msg}  ETA {eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Some(b)
    } else {
        None
    };
    let mut last_line = Instant::now();
    let mut write_output = |sim: &Simulation, k: u64| -> Result<(), RunError> {
        let g = Globals { wall_s: start.elapsed().as_secs_f64(), cpu_s: process_cpu_seconds(), ..Globals::of(sim) };
        writeln!(csv, "{}", g.csv_row()).map_err(io_err(&csv_path))?;
        csv.flush().map_err(io_err(&csv_path))?;
        if let Some(r) = &mut reporter {
            r.observe(sim);
            r.write(&opts.out).map_err(RunError::Report)?;
        }
        if sc.output.vtu {
            let name = format!("particles_{k:05}.vtu");
            let path = opts.out.join(&name);
            write_snapshot(sim, &path, &mut staging).map_err(io_err(&path))?;
            pvd.push((sim.time, name));
            let pvd_path = opts.out.join("particles.pvd");
            write_pvd(&pvd_path, &pvd).map_err(io_err(&pvd_path))?;
        }
        Ok(())
    };
    write_output(&sim, k_out)?;
    while sim.time < end * (1.0 - 1e-12) {
        let next_out = ((k_out + 1) as f64 * interval).min(end);
        while sim.time < next_out * (1.0 - 1e-12) {
            if let Err(source) = sim.step_until(next_out) {
                // keep what the failing step produced, for diagnosis in ParaView
                let snapshot = opts.out.join("failed_state.vtu");
                return Err(match write_snapshot(&sim, &snapshot, &mut Vec::new()) {
                    Ok(()) => RunError::Failed { source, snapshot },
                    Err(_) => RunError::Sim(source),
                });
            }
            if let Some(b) = &bar {
                if sim.step % 16 == 0 {
                    let rate = sim.step as f64 / start.elapsed().as_secs_f64();
                    let remaining = ((end - sim.time) / sim.last_dt.max(1e-300)).ceil() as u64;
                    b.set_length(sim.step + remaining);
                    b.set_position(sim.step);
                    b.set_message(format!("{rate:.0} steps/s  t = {:.4} s  {} particles", sim.time, sim.particles.n));
                }
            } else if !opts.quiet && last_line.elapsed().as_secs_f64() > 10.0 {
                last_line = Instant::now();
                let rate = sim.step as f64 / start.elapsed().as_secs_f64();
                let remaining = (end - sim.time) / sim.last_dt.max(1e-300) / rate.max(1e-9);
                eprintln!(
                    "step {} t = {:.4e} s dt = {:.2e} ({:?}) {:.0} steps/s ETA {:.0} s, {} particles",
                    sim.step, sim.time, sim.last_dt, sim.last_limit, rate, remaining, sim.particles.n
                );
            }
        }
        k_out += 1;
        write_output(&sim, k_out)?;
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let wall = start.elapsed().as_secs_f64();
    say(format!(
        "done: {} steps to t = {:.4} s in {:.1} s ({:.0} steps/s), {} particles{}, peak memory {}; output in {}",
        sim.step,
        sim.time,
        wall,
        sim.step as f64 / wall,
        sim.particles.n,
        if sim.particles.n_sleep > 0 { format!(" ({} asleep)", sim.particles.n_sleep) } else { String::new() },
        crate::verify::peak_rss_bytes().map_or("unknown".into(), fmt_bytes),
        opts.out.display()
    ));
    Ok(RunSummary {
        steps: sim.step,
        time: sim.time,
        wall_s: wall,
        particles: sim.particles.n,
        observations: reporter.map(|r| r.history).unwrap_or_default(),
        phase_seconds: sim.phase_seconds,
    })
}
