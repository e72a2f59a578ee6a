use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use strand::run::{run_scenario, RunOptions};
use strand::scenario::Scenario;

/// strand — fixed-memory MLS-MPM for 3D concrete printing.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a scenario (TOML) to its end time; without SCENARIO, the embedded default.
    Run {
        scenario: Option<PathBuf>,
        /// Output directory (VTU snapshots, globals.csv, observables).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Worker threads (overrides simulation.threads).
        #[arg(long)]
        threads: Option<usize>,
        /// No progress or summary on stderr.
        #[arg(long)]
        quiet: bool,
        /// Print a JSON summary on stdout (steps, times, particles, peak memory, state hash,
        /// last observables).
        #[arg(long)]
        json: bool,
        /// Continue from the newest good checkpoint in OUT/checkpoints.
        #[arg(long)]
        resume: bool,
        /// With --resume: continue even though the scenario changed since the checkpoint.
        #[arg(long, requires = "resume")]
        force: bool,
        /// Start afresh even though OUT holds checkpoints of an unfinished run (deletes them).
        #[arg(long, conflicts_with = "resume")]
        overwrite: bool,
    },
    /// Show a checkpoint's header and summary (a file, or a run's output folder for all of its
    /// checkpoints), verifying every checksum.
    Inspect {
        path: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Check a scenario and print its memory plan without running it.
    Check { scenario: PathBuf },
    /// Run the verification suite against closed-form and experimental references.
    Verify {
        /// Reduced resolution (looser tolerances, marked in the table).
        #[arg(long)]
        quick: bool,
        #[arg(long)]
        json: bool,
        /// Only cases whose name contains this text.
        #[arg(long)]
        case: Option<String>,
        /// List the case names and exit.
        #[arg(long)]
        list: bool,
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Gradient of an objective of the final state with respect to scenario parameters, by the
    /// adjoint method under a checkpoint schedule within the RAM and disk caps.
    Grad {
        scenario: PathBuf,
        /// What to differentiate: spread, width@X, height@X, vx_max, kinetic_energy, mean_z.
        #[arg(long)]
        objective: String,
        /// Parameters, comma-separated scenario keys (material.yield_stress,
        /// simulation.body_force.x, body.0.velocity.z, boundary.z_min.friction.mu, ...).
        #[arg(long, value_delimiter = ',', required = true)]
        wrt: Vec<String>,
        /// Also central differences at several steps and the Taylor remainder test.
        #[arg(long)]
        check: bool,
        /// Relative steps of --check's central differences.
        #[arg(long, value_delimiter = ',', default_values_t = strand::grad::check::REL_STEPS)]
        check_steps: Vec<f64>,
        #[arg(long)]
        json: bool,
        /// Memory for the backward pass: adjoint arrays plus RAM checkpoints.
        #[arg(long, default_value = "1 GiB")]
        ram: String,
        /// Disk for checkpoints beyond the RAM cap.
        #[arg(long, default_value = "0")]
        disk: String,
        /// Folder of the disk checkpoints (deleted files when done).
        #[arg(long, default_value = "grad_checkpoints")]
        disk_dir: PathBuf,
        #[arg(long)]
        threads: Option<usize>,
        /// Stop the run once the largest particle speed, having exceeded SPEED m/s, falls back
        /// below it (or at the end time); the online schedule then checkpoints a run of unknown
        /// length.
        #[arg(long, value_name = "SPEED")]
        until_rest: Option<f64>,
        /// Force a schedule instead of choosing one from --ram and --disk: store-all,
        /// two-level[:SEGMENT] or revolve:RAM_SLOTS,DISK_SLOTS.
        #[arg(long)]
        schedule: Option<String>,
    },
    /// Throughput of the peer benchmark scene (3D J-fluid dam break).
    Bench {
        #[arg(long, default_value_t = 262_144)]
        particles: usize,
        #[arg(long, default_value_t = 64)]
        grid: usize,
        #[arg(long, default_value_t = 30)]
        steps: usize,
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        #[arg(long)]
        threads: Option<usize>,
        #[arg(long)]
        json: bool,
    },
}

const DEFAULT_SCENARIO: &str = include_str!("../fixtures/scenarios/default.toml");

fn main() -> ExitCode {
    let cli = Cli::parse();
    let mut exit_code = 2u8;
    let result: Result<bool, String> = match cli.cmd {
        Cmd::Run { scenario, out, threads, quiet, json, resume, force, overwrite } => (|| {
            let sc = match &scenario {
                Some(p) => Scenario::load(p).map_err(|e| e.to_string())?,
                None => Scenario::parse(DEFAULT_SCENARIO).map_err(|e| e.to_string())?,
            };
            let mut command = "strand run".to_string();
            if let Some(p) = &scenario {
                command += &format!(" {}", p.display());
            }
            command += &format!(" --out {}", out.display());
            if let Some(t) = threads {
                command += &format!(" --threads {t}");
            }
            let opts = RunOptions { out, threads, quiet, resume, force, overwrite, command };
            let r = match run_scenario(&sc, &opts) {
                Ok(r) => r,
                Err(e) => {
                    exit_code = e.exit_code();
                    return Err(e.to_string());
                }
            };
            if json {
                let summary = serde_json::json!({
                    "scenario": sc.name,
                    "steps": r.steps,
                    "time": r.time,
                    "wall_s": r.wall_s,
                    "particles": r.particles,
                    "peak_rss_bytes": strand::verify::peak_rss_bytes(),
                    "state_hash": format!("{:016x}", r.state_hash),
                    "resumed_from": r.resumed_from,
                    "last_checkpoint": r.last_checkpoint,
                    "phase_seconds": strand::solver::PHASES.iter().zip(r.phase_seconds).map(|(k, v)| (k.to_string(), v)).collect::<std::collections::BTreeMap<_, _>>(),
                    "last_observation": r.observations.last(),
                });
                println!("{summary:#}");
            }
            Ok(true)
        })(),
        Cmd::Inspect { path, json } => strand::checkpoint::inspect(&path, json).map(|(t, valid)| {
            println!("{t}");
            valid
        }),
        Cmd::Check { scenario } => (|| {
            let sc = Scenario::load(&scenario).map_err(|e| e.to_string())?;
            let sim = strand::solver::Simulation::new(&sc).map_err(|e| e.to_string())?;
            let (dt, lim) = sim.choose_dt(f64::INFINITY);
            println!("{}: {} particles\nmemory plan:\n{}\ntime step {dt:.3e} s ({lim:?})", sc.name, sim.particles.n, sim.memory);
            Ok(true)
        })(),
        Cmd::Verify { list: true, .. } => {
            for (name, _) in strand::verify::CASES {
                println!("{name}");
            }
            for (name, _) in strand::verify::SLOW_CASES {
                println!("{name}  (slow: runs only when named with --case)");
            }
            Ok(true)
        }
        Cmd::Verify { quick, json, case, threads, .. } => strand::verify::run_suite(quick, json, case.as_deref(), threads),
        Cmd::Grad { scenario, objective, wrt, check, check_steps, json, ram, disk, disk_dir, threads, until_rest, schedule } => (|| {
            let sc = Scenario::load(&scenario).map_err(|e| e.to_string())?;
            let obj: strand::grad::Objective = objective.parse()?;
            let size = |s: &str, what: &str| strand::memory::parse_size(s).map_err(|e| format!("--{what}: {e}"));
            let opts = strand::grad::GradOptions {
                ram_bytes: size(&ram, "ram")?,
                disk_bytes: size(&disk, "disk")?,
                disk_dir,
                threads,
                schedule: schedule.as_deref().map(strand::grad::schedule::Kind::parse).transpose()?,
                until_rest,
            };
            let r = strand::grad::gradient(&sc, &obj, &wrt, &opts)?;
            let chk = if check { Some(strand::grad::check::check(&sc, &obj, &r, threads, &check_steps)?) } else { None };
            if json {
                println!("{:#}", serde_json::json!({ "result": r, "check": chk, "peak_rss_bytes": strand::verify::peak_rss_bytes() }));
            } else {
                print!("{}", strand::grad::driver::report(&r, chk.as_ref()));
            }
            Ok(true)
        })(),
        Cmd::Bench { particles, grid, steps, repeats, threads, json } => {
            strand::bench::run_bench(particles, grid, steps, repeats, threads, json).map(|_| true)
        }
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(exit_code)
        }
    }
}
