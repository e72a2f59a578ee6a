use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use strand::measure::preflight::{plan_experiments, Planned};
use strand::measure::{error::MeasureError, experiments::Experiments, model::Model, observation::Observation, resolution::Counted};
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
    Run(RunArgs),
    /// Show a checkpoint's header and summary (a file, or a run's output folder for all of its
    /// checkpoints), verifying every checksum.
    Inspect(InspectArgs),
    /// Check a scenario and print its memory plan without running it.
    Check(CheckArgs),
    /// Run the verification suite against closed-form and experimental references.
    Verify(VerifyArgs),
    /// Gradient of an objective of the final state with respect to scenario parameters, by the
    /// adjoint method under a checkpoint schedule within the RAM and disk caps.
    Grad(GradArgs),
    /// A virtual rheometer: MODEL's [material] as one material point in simple shear under the
    /// [rheometer] protocol (rest, shear, sweeps of rates), printing the shear stress at the end
    /// of every recorded hold.
    Rheometer(RheometerArgs),
    /// Run every experiment the measurements name under MODEL's [material] and compare: each
    /// observation (measured, model, residual, z), summaries per experiment and per observable,
    /// and where the model fails most.
    Compare(CompareArgs),
    /// Synthetic measurements: every experiment's `observe` list under MODEL, with relative
    /// Gaussian noise from a seed.
    Synth(SynthArgs),
    /// Fit named model parameters to measurements (bounded Levenberg-Marquardt, gradients from
    /// the adjoints): prints each parameter with its uncertainty and the error before and after,
    /// writes the calibrated model and a convergence plot.
    Calibrate(CalibrateArgs),
    /// Which physical effect the model lacks: fits --fit, scores every effect not in the model
    /// at its null (score test from the adjoint gradient; a likelihood-ratio test, from a fit,
    /// for an effect whose null lies at infinity: G, K or the floor's mu = infinity), fits the
    /// significant ones, checks them by leave-one-experiment-out, and gives a verdict ("add
    /// EFFECT", "explained" or "unexplained").
    Diagnose(DiagnoseArgs),
    /// Print settings from a calibrated model: the fastest build whose layer meets a width and a
    /// height at a station and whose wall stands to a design height with a safety factor (bounded
    /// gradient projection on the adjoint gradients; closed-form collapse and buckling), with the
    /// margins and sensitivities; writes the scenario with the settings applied. With --map, the
    /// printability map over two settings (CSV and PNG).
    Plan(PlanArgs),
    /// One job of calibrate's or diagnose's --engine: compute the experiment a job file names
    /// (its values, and gradients when asked) and save the result with its provenance.
    Evaluate(EvaluateArgs),
    /// Throughput of the peer benchmark scene (3D J-fluid dam break).
    Bench(BenchArgs),
}

#[derive(clap::Args)]
struct RunArgs {
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
}

#[derive(clap::Args)]
struct InspectArgs {
    path: PathBuf,
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct CheckArgs {
    scenario: PathBuf,
}

#[derive(clap::Args)]
struct VerifyArgs {
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
}

#[derive(clap::Args)]
struct GradArgs {
    scenario: PathBuf,
    /// What to differentiate: spread, width@X, height@X, area@X, profile@X:Y (the section's
    /// top at x = X, y = Y), layer_height@X:K, layer_width@X:K (layer K = 1, 2, ... at x = X),
    /// total_height, front, vx_max, kinetic_energy, mean_z. Given several times, the
    /// objectives share one forward and one reverse sweep (an adjoint for each).
    #[arg(long, required = true)]
    objective: Vec<String>,
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
}

#[derive(clap::Args)]
struct RheometerArgs {
    model: PathBuf,
    /// Protocol file ([[phase]] tables) instead of MODEL's [rheometer] table.
    #[arg(long)]
    protocol: Option<PathBuf>,
    /// Also each reading's derivative with respect to every material parameter (adjoint).
    #[arg(long)]
    sensitivity: bool,
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct CompareArgs {
    #[command(flatten)]
    inputs: MeasureInputs,
    /// Also write a report into DIR: model against data and z against each covariate
    /// (PNG), the trends of z (trends.csv, also printed) and index.html showing it all.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Run nothing: write DIR/jobs.txt, one command per experiment (GNU parallel, or the
    /// Slurm job array DIR/slurm.sh), each saving its values into DIR.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["collect", "only"])]
    plan: Option<PathBuf>,
    /// Compare from the values the planned jobs saved in DIR instead of running.
    #[arg(long, value_name = "DIR", conflicts_with = "only")]
    collect: Option<PathBuf>,
    /// Run this experiment alone (a planned job).
    #[arg(long, value_name = "ID", requires = "save")]
    only: Option<String>,
    /// Where --only saves its values (JSON).
    #[arg(long, value_name = "FILE", requires = "only")]
    save: Option<PathBuf>,
}

#[derive(clap::Args)]
struct SynthArgs {
    #[arg(long)]
    model: PathBuf,
    #[arg(long)]
    experiments: PathBuf,
    /// Relative noise (standard deviation), also written as each value's uncertainty.
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output CSV.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 1)]
    jobs: usize,
}

#[derive(clap::Args)]
struct CalibrateArgs {
    #[command(flatten)]
    inputs: MeasureInputs,
    /// Parameters to fit: material.KEY or EFFECT.PARAM, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    fit: Vec<String>,
    /// Where the calibrated model goes (default: MODEL's name with .calibrated.toml).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Convergence plot (PNG; default beside --out).
    #[arg(long)]
    plot: Option<PathBuf>,
    #[command(flatten)]
    fit_steps: FitSteps,
    #[command(flatten)]
    engine: EngineArgs,
}

/// How a fit steps.
#[derive(clap::Args)]
struct FitSteps {
    /// Accepted steps at most, per fit.
    #[arg(long, default_value_t = 30)]
    max_iterations: usize,
    /// Compute the Jacobian again after every accepted step. By default, a campaign with
    /// simulations updates it by Broyden's secant between exact Jacobians, taken at the start,
    /// where a step is refused and at the end (docs/measurement.md).
    #[arg(long)]
    jacobian_every_step: bool,
    /// No progress on stderr: neither the bars (or, with --json, the progress events) nor the
    /// line per stage and per accepted step.
    #[arg(long)]
    quiet: bool,
}

#[derive(clap::Args)]
struct DiagnoseArgs {
    #[command(flatten)]
    inputs: MeasureInputs,
    /// Base parameters refitted first (and in every candidate's fit), comma-separated.
    #[arg(long, value_delimiter = ',')]
    fit: Vec<String>,
    /// Significance level of the score and likelihood-ratio tests and of the base model's fit.
    #[arg(long, default_value_t = 0.01)]
    alpha: f64,
    /// Skip the leave-one-experiment-out check.
    #[arg(long)]
    no_loo: bool,
    /// Leave each experiment out by a full refit, instead of one Gauss-Newton step from the
    /// full fit checked against a run at it (and replaced by a refit where the check refuses
    /// it): see docs/gradient_cost.md.
    #[arg(long, conflicts_with = "no_loo")]
    loo_refits: bool,
    /// How many significant effects, best first, are fitted and checked by leave-one-out
    /// (each check refits once per experiment); the rest are reported significant.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    max_fitted: u64,
    /// Write the model with the recommended effect, fitted, here (with --rounds, the final
    /// model with every effect added).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    fit_steps: FitSteps,
    /// Run up to N rounds: diagnose, add the verdict's effect, refit, and diagnose again
    /// until nothing is significant, printing the error after each round.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    rounds: u64,
    #[command(flatten)]
    engine: EngineArgs,
}

#[derive(clap::Args)]
struct PlanArgs {
    /// The calibrated model ([material] and [effects.NAME], as `strand calibrate` writes it).
    #[arg(long)]
    model: PathBuf,
    /// The print: a scenario with an inline [print] path, or a G-code or point-list toolpath
    /// (written inline beside --out as .path.toml, and again with the settings as .gcode or .csv).
    #[arg(long)]
    print: PathBuf,
    /// The targets: [layer], [wall] and [settings] (docs/planning.md).
    #[arg(long)]
    targets: PathBuf,
    /// Where the scenario with the settings applied goes (default: PRINT's name with
    /// .planned.toml); the HTML report goes beside it (.html), and the map's files (.map.csv,
    /// .map.png).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace --out, the report and the map's files if they exist.
    #[arg(long)]
    overwrite: bool,
    /// Runs with gradients at most.
    #[arg(long, default_value_t = 12)]
    max_evaluations: usize,
    /// The printability map over two settings or groups: speed, extrusion, standoff, v/u (speed
    /// over extrusion speed), h/d (standoff over nozzle diameter), e.g. v/u,h/d; a range as
    /// v/u=0.8:1.5 (default: what the setting's bounds allow at the plan's point).
    #[arg(long, value_name = "X,Y")]
    map: Option<String>,
    /// After the plan, run a brute-force grid of NxM points over its first two free settings and
    /// compare the fastest feasible one and the cost with the plan's.
    #[arg(long, value_name = "NxM")]
    grid_check: Option<String>,
    /// After the plan, simulate a reduced wall of the planned layer at the planned layer time;
    /// when it fails, calibrate the closed form on it and simulate again at the layer time that
    /// asks, until a wall stands to the design height x safety factor: the plan takes its layer
    /// time (docs/planning.md).
    #[arg(long)]
    check_wall: bool,
    /// With --check-wall: the first round's layer time [s] instead of the plan's (to probe the
    /// margin).
    #[arg(long, value_name = "SECONDS", requires = "check_wall")]
    check_wall_at: Option<f64>,
    /// With --check-wall: simulated walls at most (each takes minutes).
    #[arg(long, value_name = "N", default_value_t = strand::plan::wall_rounds::DEFAULT_ROUNDS, requires = "check_wall")]
    wall_rounds: usize,
    /// Points along the map's axes.
    #[arg(long, default_value = "5x5", value_name = "NxM")]
    map_size: String,
    /// The map's points run at once (local engine).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    #[command(flatten)]
    engine: EngineArgs,
    /// Memory for each gradient run's backward pass.
    #[arg(long, default_value = "1 GiB")]
    ram: String,
    #[arg(long)]
    threads: Option<usize>,
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct EvaluateArgs {
    job: PathBuf,
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct BenchArgs {
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
}

const DEFAULT_SCENARIO: &str = include_str!("../fixtures/scenarios/default.toml");

/// What every measurement command reads.
#[derive(clap::Args)]
struct MeasureInputs {
    /// Model file: [material] and [effects.NAME].
    #[arg(long)]
    model: PathBuf,
    /// Measurements CSV: experiment,observable,at,value,uncertainty.
    #[arg(long)]
    data: PathBuf,
    /// Experiments file (TOML): what produced each experiment id.
    #[arg(long)]
    experiments: PathBuf,
    /// Experiments run at once (each is independent).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    #[arg(long)]
    json: bool,
}

/// Where calibrate's and diagnose's per-experiment evaluations run (docs/distributed.md).
#[derive(clap::Args)]
struct EngineArgs {
    /// local (in this process, --jobs at a time), parallel (GNU parallel), slurm (sbatch --wait
    /// --array), hq (HyperQueue), or a command template naming {jobs} (a file of job commands,
    /// one per line) or {task} (a job array's task script), with {n} and {dir}.
    #[arg(long, default_value = "local")]
    engine: String,
    /// The engine's folder (jobs, results, logs), readable and writable by every job; results
    /// already there are collected, not computed again.
    #[arg(long, value_name = "DIR")]
    engine_dir: Option<PathBuf>,
    /// Threads per job (0: all the job is given).
    #[arg(long, default_value_t = 1)]
    job_threads: usize,
}

impl EngineArgs {
    fn engine(&self) -> Result<strand::measure::engine::Engine, Failure> {
        let exe = std::env::current_exe()?;
        let threads = if self.job_threads == 0 { None } else { Some(self.job_threads) };
        Ok(strand::measure::engine::Engine::new(&self.engine, self.engine_dir.as_deref(), &exe, threads)?)
    }

    /// A fit's options on this engine, the inputs' `--jobs` experiments at a time, its progress
    /// on stderr (`measure/progress.rs`): a line per step and bars, or with `--json` progress
    /// events as JSON lines; nothing with `--quiet`.
    fn fit_options(&self, steps: &FitSteps, inputs: &MeasureInputs) -> Result<strand::measure::campaign::FitOptions, Failure> {
        use strand::measure::progress::Progress;
        let (max_iterations, secant, jobs) = (steps.max_iterations, !steps.jacobian_every_step, inputs.jobs);
        let progress = match (steps.quiet, inputs.json) {
            (true, _) => Progress::default(),
            (false, true) => Progress::json(Box::new(std::io::stderr())),
            (false, false) => Progress::bars(),
        };
        Ok(strand::measure::campaign::FitOptions { max_iterations, jobs, engine: self.engine()?, log: !steps.quiet, progress, secant, ..Default::default() })
    }
}

/// A fit's or a diagnosis's result on stdout: as JSON with the discretisation estimates, or as
/// `text` after the estimates' `table`.
fn print_result(json: bool, result: &impl serde::Serialize, disc: &Option<Counted>, table: impl Fn(&Counted) -> String, text: impl FnOnce() -> String) -> Result<(), Failure> {
    use strand::measure::resolution;
    if json {
        println!("{:#}", resolution::with_estimates(serde_json::to_value(result)?, disc)?);
    } else {
        if let Some(c) = disc {
            print!("{}", table(c));
        }
        print!("{}", text());
    }
    Ok(())
}

impl MeasureInputs {
    /// The model, the data and the experiments, with every simulation the data's experiments
    /// will run planned (memory, `[resolution]`'s finer cells) before any runs.
    fn load(&self) -> Result<(Model, Vec<Observation>, Experiments, Planned), MeasureError> {
        use strand::measure::observation::read_observations;
        let (m, d, e) = (Model::load(&self.model)?, read_observations(&self.data)?, Experiments::load(&self.experiments)?);
        let planned = plan_experiments(&m, &e, strand::measure::runner::group(&d).iter().map(|(id, _)| id.as_str()))?;
        Ok((m, d, e, planned))
    }
}

/// Whether a file can be written at `path` (the option `what` names it), checked before a long
/// computation whose result goes there. Leaves an existing file unchanged and no new one.
fn check_writable(path: &std::path::Path, what: &str) -> Result<(), Failure> {
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .map_err(|e| format!("{what} {}: cannot be written: {e}", path.display()))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// `strand run`: the run, and its JSON summary with --json.
fn run(args: RunArgs) -> Result<bool, Failure> {
    let RunArgs { scenario, out, threads, quiet, json, resume, force, overwrite } = args;
    let sc = match &scenario {
        Some(p) => Scenario::load(p)?,
        None => Scenario::parse(DEFAULT_SCENARIO)?,
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
    let r = run_scenario(&sc, &opts).map_err(|e| Failure { code: e.exit_code(), message: e.to_string() })?;
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
            "phase_seconds": strand::solver::PHASES.iter().zip(r.phase_seconds).map(|(k, v)| (k.name(), v)).collect::<std::collections::BTreeMap<_, _>>(),
            "last_observation": r.observations.last(),
            "failure": r.failure,
            "awake_particle_steps": r.awake_particle_steps,
            "external_work": r.external_work,
            "inertia": r.inertia,
        });
        println!("{summary:#}");
    }
    Ok(true)
}

/// `strand check`: the scenario checked, its memory plan and time step printed.
fn check(args: CheckArgs) -> Result<bool, Failure> {
    let CheckArgs { scenario } = args;
    let sc = Scenario::load(&scenario)?;
    // Simulation::new plans the memory before it allocates (solver::preflight)
    let mut sim = strand::solver::Simulation::new(&sc)?;
    strand::run::plan_checkpoint_staging(&mut sim)?;
    for w in strand::run::scenario_warnings(&sc, &sim) {
        eprintln!("{w}");
    }
    let (dt, lim) = sim.choose_dt(f64::INFINITY);
    let steps = strand::run::planned_steps(&sim, sc.simulation.end_time)?;
    println!("{}: {} particles\nmemory plan:\n{}\ntime step {dt:.3e} s ({lim:?}), about {steps:.0} steps to end_time", sc.name, sim.particles.n, sim.memory);
    Ok(true)
}

/// `strand grad`: gradients by the adjoint, checked against central differences with --check.
fn grad(args: GradArgs) -> Result<bool, Failure> {
    let GradArgs { scenario, objective, wrt, check, check_steps, json, ram, disk, disk_dir, threads, until_rest, schedule } = args;
    if let Some(h) = check_steps.iter().find(|h| !(h.is_finite() && **h > 0.0)) {
        return Err(format!("--check-steps: each relative step must be finite and > 0, got {h}").into());
    }
    if let Some(v) = until_rest.filter(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(format!("--until-rest: the speed must be finite and > 0 m/s (a speed the run can exceed and fall back below), got {v}").into());
    }
    let sc = Scenario::load(&scenario)?;
    let objs: Vec<strand::observables::Objective> = objective.iter().map(|o| o.parse()).collect::<Result<_, _>>()?;
    let size = |s: &str, what: &str| strand::memory::parse_size(s).map_err(|e| format!("--{what}: {e}"));
    let opts = strand::grad::GradOptions {
        ram_bytes: size(&ram, "ram")?,
        disk_bytes: size(&disk, "disk")?,
        disk_dir,
        threads,
        schedule: schedule.as_deref().map(strand::grad::schedule::Kind::parse).transpose()?,
        until_rest,
    };
    let seeds: Vec<strand::grad::driver::Seeded> = objs.into_iter().map(|objective| strand::grad::driver::Seeded { objective, step: None }).collect();
    let rs = strand::grad::driver::gradients(&sc, &seeds, &wrt, &opts)?;
    let objectives: Vec<strand::observables::Objective> = seeds.iter().map(|s| s.objective.clone()).collect();
    let chks: Vec<Option<strand::grad::check::Check>> = if check {
        strand::grad::check::check_many(&sc, &objectives, &rs, threads, &check_steps)?.into_iter().map(Some).collect()
    } else {
        vec![None; rs.len()]
    };
    if json && rs.len() == 1 {
        println!("{:#}", serde_json::json!({ "result": rs[0], "check": chks[0], "peak_rss_bytes": strand::verify::peak_rss_bytes() }));
    } else if json {
        println!("{:#}", serde_json::json!({ "results": rs, "checks": chks, "peak_rss_bytes": strand::verify::peak_rss_bytes() }));
    } else {
        for (r, c) in rs.iter().zip(&chks) {
            print!("{}", strand::grad::driver::report(r, c.as_ref()));
        }
    }
    Ok(true)
}

/// `strand compare`: the model against the measurements, or a planned or collected distributed run of it.
fn compare(args: CompareArgs) -> Result<bool, Failure> {
    let CompareArgs { inputs, report, plan, collect, only, save } = args;
    use strand::measure::{compare, plan as jobs, report as folder, resolution, runner};
    if let Some(dir) = &report {
        folder::prepare_dir(dir)?;
    }
    let (m, d, e, _) = inputs.load()?;
    if let Some(dir) = &plan {
        let exe = std::env::current_exe()?;
        let n = jobs::plan(dir, &exe, &inputs.model, &inputs.data, &inputs.experiments, &d)?;
        eprintln!("{n} jobs in {0}/jobs.txt: `parallel < {0}/jobs.txt` or `sbatch {0}/slurm.sh`, then --collect {0}", dir.display());
        return Ok(true);
    }
    if let (Some(id), Some(file)) = (&only, &save) {
        let mine = jobs::only(&d, id)?;
        let values = runner::model_values(&m, &mine, &e, 1)?;
        jobs::save(file, &m, &e, id, &mine, &values)?;
        eprintln!("{id}: {} values saved to {}", values.len(), file.display());
        return Ok(true);
    }
    let values = match &collect {
        Some(dir) => jobs::collect(dir, &m, &e, &d)?,
        None => runner::model_values(&m, &d, &e, inputs.jobs)?,
    };
    // [resolution]: the finer runs, here also after --collect (the jobs ran the model's)
    let disc = resolution::estimate(&m, &d, &e, Some(&values), inputs.jobs)?;
    let c = match &disc {
        Some(est) => compare::comparison_with_discretisation(&d, &values, &resolution::errors(est)),
        None => compare::comparison(&d, &values),
    };
    let trends = report.as_deref().map(|dir| folder::write(dir, &c, &e, &m)).transpose()?;
    if inputs.json {
        let mut v = serde_json::to_value(&c)?;
        if let Some((t, shapes)) = &trends {
            v["trends"] = serde_json::to_value(t)?;
            v["shapes"] = serde_json::to_value(shapes)?;
        }
        if let Some(est) = &disc {
            v["discretisation"] = serde_json::to_value(est)?;
        }
        println!("{v:#}");
    } else {
        if let Some(est) = &disc {
            print!("{}", resolution::report(&d, est, &values, "compared"));
        }
        print!("{}", compare::report(&c));
        if let Some((t, shapes)) = &trends {
            print!("{}", folder::trends_text(t));
            print!("{}", strand::measure::residuals::text(shapes));
        }
    }
    if let Some(dir) = &report {
        eprintln!("report written to {}", dir.join("index.html").display());
    }
    Ok(true)
}

/// `strand synth`: synthetic measurements.
fn synth(args: SynthArgs) -> Result<bool, Failure> {
    let SynthArgs { model, experiments, noise, seed, out, jobs } = args;
    use strand::measure::{experiments::Experiments, model::Model, observation::write_observations, synth::synth};
    let m = Model::load(&model)?;
    let e = Experiments::load(&experiments)?;
    plan_experiments(&m, &e, e.experiment.iter().map(|x| x.id.as_str()))?;
    let obs = synth(&m, &e, noise, seed, jobs)?;
    write_observations(&out, &obs)?;
    eprintln!("{} observations of {} experiments written to {}", obs.len(), e.experiment.len(), out.display());
    Ok(true)
}

/// The data with their discretisation errors counted (`[resolution]`), saying on stderr how long
/// the finer runs took: part of a fit's or a diagnosis's cost.
fn counted_data(m: &Model, d: Vec<Observation>, e: &Experiments, jobs: usize) -> Result<(Vec<Observation>, Option<Counted>), MeasureError> {
    let clock = std::time::Instant::now();
    let counted = strand::measure::resolution::counted_data(m, d, e, jobs)?;
    if counted.1.is_some() {
        eprintln!("discretisation errors estimated from [resolution]'s cells in {:.0} s", clock.elapsed().as_secs_f64());
    }
    Ok(counted)
}

/// `strand calibrate`: the fit, its report, the calibrated model and the convergence plot.
fn calibrate(args: CalibrateArgs) -> Result<bool, Failure> {
    let CalibrateArgs { inputs, fit, out, plot, fit_steps, engine } = args;
    use strand::measure::{calibrate, campaign::{expected_runs, Campaign}, resolution};
    let (m, d0, e, planned) = inputs.load()?;
    if let Some(w) = resolution::uncounted_warning(&planned.prints, &e) {
        eprintln!("{w}");
    }
    let out = out.unwrap_or_else(|| inputs.model.with_extension("calibrated.toml"));
    let plot = plot.unwrap_or_else(|| out.with_extension("png"));
    check_writable(&out, "--out")?;
    check_writable(&plot, "--plot")?;
    let (d, disc) = counted_data(&m, d0, &e, inputs.jobs)?;
    let opts = engine.fit_options(&fit_steps, &inputs)?;
    opts.progress.plan(1);
    opts.progress.begin("fit", expected_runs(&d, &fit));
    let c = Campaign { estimate: disc.as_ref(), ..Campaign::new(&e, &d, &opts) };
    let f = calibrate::calibrate_at(&c, &m, c.start_values(), &fit)?;
    opts.progress.end();
    opts.progress.finish();
    // the fitted values first: a file that fails to write then loses nothing
    print_result(inputs.json, &f, &disc, |c| resolution::report(&c.data, &c.estimates, &f.model_values, "fitted"), || calibrate::report(&f))?;
    std::fs::write(&out, f.model.to_toml()).map_err(|e| format!("--out {}: {e}", out.display()))?;
    calibrate::plot_convergence(&f, &plot).map_err(|e| format!("--plot {}: {e}", plot.display()))?;
    eprintln!("calibrated model written to {}, convergence plot to {}", out.display(), plot.display());
    Ok(true)
}

/// `strand diagnose`: which effect the model lacks, in one round or several.
fn diagnose(args: DiagnoseArgs) -> Result<bool, Failure> {
    let DiagnoseArgs { inputs, fit, alpha, no_loo, loo_refits, max_fitted, out, fit_steps, rounds, engine } = args;
    use strand::measure::{campaign::Campaign, diagnose, resolution};
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(format!("--alpha must be in (0, 1), got {alpha}").into());
    }
    let (m, d0, e, planned) = inputs.load()?;
    if let Some(w) = resolution::uncounted_warning(&planned.prints, &e) {
        eprintln!("{w}");
    }
    if let Some(out) = &out {
        check_writable(out, "--out")?;
    }
    let (d, disc) = counted_data(&m, d0, &e, inputs.jobs)?;
    let fit_opts = engine.fit_options(&fit_steps, &inputs)?;
    let c = Campaign { estimate: disc.as_ref(), ..Campaign::new(&e, &d, &fit_opts) };
    let opts = diagnose::DiagnoseOptions { alpha, leave_one_out: !no_loo, exact_refits: loo_refits, max_fitted: max_fitted as usize };
    if rounds > 1 {
        use strand::measure::rounds;
        let r = rounds::rounds(&c, &m, &fit, &opts, rounds as usize)?;
        fit_opts.progress.finish();
        // the report first: a file that fails to write then loses nothing
        if inputs.json {
            println!("{:#}", serde_json::to_value(&r)?);
        } else {
            print!("{}", rounds::report(&r));
        }
        if let (Some(out), false) = (&out, r.added.is_empty()) {
            std::fs::write(out, r.model.to_toml()).map_err(|e| format!("--out {}: {e}", out.display()))?;
            eprintln!("model with {} written to {}", r.added.join(", "), out.display());
        }
        return Ok(true);
    }
    let r = diagnose::diagnose(&c, &m, &fit, &opts)?;
    fit_opts.progress.finish();
    // the report first: a file that fails to write then loses nothing
    print_result(inputs.json, &r, &disc, |c| resolution::report(&c.data, &c.estimates, &c.start_values, "start"), || diagnose::report(&r))?;
    if let (Some(out), Some(best)) = (&out, &r.recommended_model) {
        std::fs::write(out, best.to_toml()).map_err(|e| format!("--out {}: {e}", out.display()))?;
        eprintln!("model with {} written to {}", r.recommended.as_deref().unwrap_or(""), out.display());
    }
    Ok(true)
}

/// `strand inspect`: false when a checkpoint fails its checks.
fn inspect(args: InspectArgs) -> Result<bool, Failure> {
    let (t, valid) = strand::checkpoint::inspect(&args.path, args.json)?;
    println!("{t}");
    Ok(valid)
}

/// `strand verify`: the suite, or with --list the case names.
fn verify(args: VerifyArgs) -> Result<bool, Failure> {
    let VerifyArgs { quick, json, case, list, threads } = args;
    if list {
        for (name, _) in strand::verify::CASES {
            println!("{name}");
        }
        for (name, _) in strand::verify::SLOW_CASES {
            println!("{name}  (slow: runs only when named with --case)");
        }
        return Ok(true);
    }
    Ok(strand::verify::run_suite(quick, json, case.as_deref(), threads)?)
}

/// `strand rheometer`: the virtual rheometer's readings.
fn rheometer(args: RheometerArgs) -> Result<bool, Failure> {
    print!("{}", strand::measure::rheometer::run_cli(&args.model, args.protocol.as_deref(), args.sensitivity, args.json)?);
    Ok(true)
}

/// `strand plan`: the settings, their report and scenario, and with --map the printability map.
fn plan(args: PlanArgs) -> Result<bool, Failure> {
    let PlanArgs { model, print, targets, out, overwrite, max_evaluations, map, grid_check, check_wall, check_wall_at, wall_rounds, map_size, jobs, engine, ram, threads, json } = args;
    use strand::plan::{self, map as pmap, report};
    let t = plan::targets::Targets::load(&targets)?;
    if check_wall && t.wall.is_none() {
        return Err(Failure { message: format!("--check-wall: {} has no [wall]: there is no wall to check", targets.display()), code: 2 });
    }
    if let Some(lt) = check_wall_at.filter(|lt| !(lt.is_finite() && *lt > 0.0)) {
        return Err(Failure { message: format!("--check-wall-at {lt}: give a layer time in seconds above 0"), code: 2 });
    }
    let out = out.unwrap_or_else(|| print.with_extension("planned.toml"));
    let (csv, png, html) = (out.with_extension("map.csv"), out.with_extension("map.png"), out.with_extension("html"));
    report::refuse_existing(&out, overwrite)?;
    report::refuse_existing(&html, overwrite)?;
    // a G-code or point-list print is planned on its moves written inline beside --out
    let file = plan::toolpath_file::inline(&print, &out.with_extension("path.toml"), overwrite)?;
    if let Some(f) = &file {
        report::refuse_existing(&f.planned_path(&out), overwrite)?;
    }
    let scenario = file.as_ref().map_or(print.clone(), |f| f.inlined.clone());
    let axes = map.as_deref().map(|s| plan::map_axes::parse(s, &map_size, &t)).transpose()?;
    if axes.is_some() {
        report::refuse_existing(&csv, overwrite)?;
        report::refuse_existing(&png, overwrite)?;
    }
    // the reduced walls' scenarios and outputs, a folder a round, kept for inspection
    let wall_dir = out.with_extension("wall");
    if check_wall {
        report::refuse_existing(&wall_dir, overwrite)?;
    }
    let engine = engine.engine()?;
    let ram_bytes = strand::memory::parse_size(&ram).map_err(|e| format!("--ram: {e}"))?;
    let grad = strand::grad::GradOptions { ram_bytes, disk_bytes: 0, disk_dir: std::env::temp_dir(), threads, schedule: None, until_rest: None };
    let mut p = plan::plan(&Model::load(&model)?, &scenario, &t, &plan::PlanOptions { grad, max_evaluations, progress: !json })?;
    let missed = p.infeasible();
    let wall = match (&missed, check_wall) {
        (None, true) => {
            let first = check_wall_at.unwrap_or(p.best().build.layer_time);
            Some(plan::wall_rounds::drive(&mut p, first, wall_rounds, threads, &wall_dir)?)
        }
        (Some(_), true) => {
            eprintln!("--check-wall: no wall simulated: no setting met the targets");
            None
        }
        _ => None,
    };
    if missed.is_none() {
        if json {
            let mut v = report::json(&p);
            if let Some(r) = &wall {
                v["wall_rounds"] = serde_json::to_value(r).map_err(|e| e.to_string())?;
            }
            println!("{v:#}");
        } else {
            print!("{}", report::text(&p));
        }
    }
    if let Some(r) = &wall {
        eprint!("{}", plan::wall_rounds::outcome(r));
    }
    let map = match axes {
        Some(specs) => {
            let d = p.line.nozzle;
            let axes = plan::map_axes::resolve(specs, &t, &p.settings(), d)?;
            let layer_time = p.wall.as_ref().map(|_| p.best().build.layer_time);
            let m = pmap::map(&p.line, &t, p.wall.as_ref(), axes, &p.settings(), layer_time, &engine, jobs)?;
            pmap::write_csv(&m, d, &csv)?;
            pmap::write_png(&m, &t, &png)?;
            eprint!("{}", pmap::text(&m, d));
            eprintln!("map written to {} and {}", csv.display(), png.display());
            Some(m)
        }
        None => None,
    };
    let extras = plan::report_html::Extras { missed: missed.as_ref(), wall: wall.as_ref(), map: map.as_ref().map(|m| (m, png.as_path())) };
    plan::report_html::write(&p, &extras, &html)?;
    eprintln!("report written to {}", html.display());
    // nothing is written of a plan whose targets are unmet or whose simulated wall fell
    if let Some(e) = missed.or_else(|| wall.as_ref().and_then(|r| r.refusal())) {
        return Err(Failure { message: e.to_string(), code: 1 });
    }
    if let Some(size) = grid_check {
        let [n, m] = plan::grid_search::size(&size)?;
        eprint!("{}", plan::grid_search::text(&p, &plan::grid_search::grid_search(&p, [n, m], &engine, jobs)?));
    }
    // a toolpath file's planned scenario reads the planned file, written first
    let body = match &file {
        Some(f) => {
            let written = f.planned_path(&out);
            f.write_planned(&p, &written, overwrite)?;
            eprintln!("{} with the settings written to {} (its moves inline: {})", print.display(), written.display(), f.inlined.display());
            f.planned_scenario(&p, &written)?
        }
        None => p.line.scenario_text(&p.settings())?,
    };
    report::write_scenario(&p, &body, &out, overwrite)?;
    eprintln!("scenario with the settings written to {}", out.display());
    Ok(true)
}

/// `strand evaluate`: one job of a distributed engine.
fn evaluate(args: EvaluateArgs) -> Result<bool, Failure> {
    eprintln!("{}", strand::measure::engine::evaluate(&args.job, &args.out)?);
    Ok(true)
}

/// `strand bench`: the peer benchmark's throughput.
fn bench(args: BenchArgs) -> Result<bool, Failure> {
    let BenchArgs { particles, grid, steps, repeats, threads, json } = args;
    strand::bench::run_bench(particles, grid, steps, repeats, threads, json)?;
    Ok(true)
}

/// A command's failure: its message, and the process exit status (2 unless the command gives
/// another).
struct Failure {
    message: String,
    code: u8,
}

impl From<String> for Failure {
    fn from(message: String) -> Self {
        Failure { message, code: 2 }
    }
}

/// The library's typed errors (and the system's, serde_json's), as a command's failure with their
/// message and exit status 2.
macro_rules! failure_from {
    ($($t:ty),* $(,)?) => {$(
        impl From<$t> for Failure {
            fn from(e: $t) -> Self {
                Failure { message: e.to_string(), code: 2 }
            }
        }
    )*};
}
failure_from!(
    strand::checkpoint::NoCheckpoints,
    strand::invalid::Invalid,
    strand::grad::GradError,
    strand::observables::ObservableError,
    strand::grad::schedule::ScheduleError,
    strand::verify::VerifyError,
    strand::bench::BenchError,
    strand::measure::error::MeasureError,
    strand::output::plot::PlotError,
    strand::plan::error::PlanError,
    strand::scenario::ScenarioError,
    strand::solver::SimError,
    serde_json::Error,
    std::io::Error,
);

/// Exit status 0 when the command succeeded, 1 when it ran but found a failure (a bad checkpoint,
/// a failed verification case), else the failure's.
fn main() -> ExitCode {
    let result = match Cli::parse().cmd {
        Cmd::Run(a) => run(a),
        Cmd::Inspect(a) => inspect(a),
        Cmd::Check(a) => check(a),
        Cmd::Verify(a) => verify(a),
        Cmd::Grad(a) => grad(a),
        Cmd::Rheometer(a) => rheometer(a),
        Cmd::Compare(a) => compare(a),
        Cmd::Synth(a) => synth(a),
        Cmd::Calibrate(a) => calibrate(a),
        Cmd::Diagnose(a) => diagnose(a),
        Cmd::Plan(a) => plan(a),
        Cmd::Evaluate(a) => evaluate(a),
        Cmd::Bench(a) => bench(a),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {}", e.message);
            ExitCode::from(e.code)
        }
    }
}
