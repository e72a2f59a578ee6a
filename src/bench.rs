//! `strand bench`: the scene of ../shared/peer (3D J-fluid dam break, MLS-MPM, taichi's mpm3d
//! algorithm) run by strand's solver, timed the way the peer scripts time theirs.
//!
//! Peer scene: unit box, G^3 grid, rho = 1, Kirchhoff pressure E (J - 1) with E = 400, gravity
//! 9.8 along -y, separating walls 3 cells deep, a cube of P particles at 8 per cell in the corner,
//! dt = 0.0128 / G. strand's Newtonian fluid with zero viscosity and the linear EOS gives exactly
//! that stress: V0 J sigma = V0 J K (1 - 1/J) = V0 K (J - 1).

use crate::scenario::{Scenario, ScenarioError};
use crate::solver::{SimError, Simulation};
use std::time::Instant;

/// Why the peer scene cannot be built or run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("{particles} particles at 8 per cell do not fit a {grid}^3 grid")]
    TooManyParticles { particles: usize, grid: usize },
}

pub fn peer_scenario(particles: usize, grid: usize, threads: usize) -> Result<Scenario, BenchError> {
    let g = grid as f64;
    let dx = 1.0 / g;
    let text = format!(
        r#"
name = "peer-jfluid-{grid}"
[simulation]
dx = {dx}
end_time = 1.0
dt = {dt}
gravity = [0.0, -9.8, 0.0]
threads = {threads}
flip = 0.0
[domain]
min = [{lo}, {lo}, {lo}]
max = [{hi}, {hi}, {hi}]
[boundary]
x_min = "free_slip"
x_max = "free_slip"
y_min = "free_slip"
y_max = "free_slip"
z_min = "free_slip"
z_max = "free_slip"
[material]
kind = "newtonian"
density = 1.0
bulk_modulus = 400.0
viscosity = 0.0
[memory]
budget = "8 GiB"
max_particles = {particles}
"#,
        dt = 0.0128 / g,
        lo = 2.0 * dx,
        hi = 1.0 - 2.0 * dx,
    );
    Ok(Scenario::parse(&text)?)
}

/// A deterministic 64-bit generator (splitmix64) for the random particle cloud.
pub struct SplitMix(pub u64);
impl SplitMix {
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Build the peer scene: particles uniformly at random in the corner cube, sorted by cell.
pub fn peer_simulation(particles: usize, grid: usize, threads: usize) -> Result<Simulation, BenchError> {
    let sc = peer_scenario(particles, grid, threads)?;
    let mut sim = Simulation::new(&sc)?;
    let dx = 1.0 / grid as f64;
    let side = (particles as f64 / 8.0).cbrt() * dx;
    let lo = 3.0 * dx;
    if lo + side > 1.0 - 4.0 * dx {
        return Err(BenchError::TooManyParticles { particles, grid });
    }
    let mut rng = SplitMix(0);
    let mut pts: Vec<[f64; 3]> = (0..particles)
        .map(|_| [lo + rng.next_f64() * side, lo + rng.next_f64() * side, lo + rng.next_f64() * side])
        .collect();
    let key = |p: &[f64; 3]| {
        let c = |x: f64| (x * grid as f64).floor() as i64;
        (c(p[0]) * grid as i64 + c(p[1])) * grid as i64 + c(p[2])
    };
    pts.sort_by_key(key);
    let vol = dx * dx * dx / 8.0;
    for p in pts {
        sim.add_particle(p, [0.0; 3], vol)?;
    }
    Ok(sim)
}

#[derive(Debug, serde::Serialize)]
pub struct BenchResult {
    pub tool: &'static str,
    pub particles: usize,
    pub grid: usize,
    pub steps: usize,
    pub repeats: usize,
    pub dtype: &'static str,
    pub threads: usize,
    pub sec_per_step: f64,
    pub particle_steps_per_s: f64,
    pub runs_s: Vec<f64>,
    /// Share of the timed wall time per phase of the step.
    pub phases: Vec<(&'static str, f64)>,
    /// Bytes per particle a restart checkpoint of the scene holds after the timed steps, in this
    /// build's precision (`strand inspect` gives it for any checkpoint).
    pub restart_bytes_per_particle: f64,
}

pub fn run_bench(
    particles: usize,
    grid: usize,
    steps: usize,
    repeats: usize,
    threads: Option<usize>,
    json: bool,
) -> Result<BenchResult, BenchError> {
    let mut sim = peer_simulation(particles, grid, threads.unwrap_or(0))?;
    let dt = 0.0128 / grid as f64;
    for _ in 0..3 {
        sim.advance(dt)?;
    }
    sim.phase_seconds = [0.0; crate::solver::PHASES.len()];
    let mut runs = Vec::new();
    for _ in 0..repeats.max(1) {
        let t0 = Instant::now();
        for _ in 0..steps {
            sim.advance(dt)?;
        }
        runs.push(t0.elapsed().as_secs_f64());
    }
    let mut sorted = runs.clone();
    sorted.sort_by(f64::total_cmp);
    let sec_per_step = sorted[sorted.len() / 2] / steps as f64;
    let r = BenchResult {
        tool: "strand",
        particles,
        grid,
        steps,
        repeats: repeats.max(1),
        dtype: crate::kernels::real::NAME,
        threads: sim.threads(),
        sec_per_step,
        particle_steps_per_s: particles as f64 / sec_per_step,
        phases: {
            let total: f64 = sim.phase_seconds.iter().sum();
            crate::solver::PHASES.iter().zip(sim.phase_seconds).map(|(p, t)| (p.name(), t / total)).collect()
        },
        runs_s: runs,
        restart_bytes_per_particle: crate::checkpoint::state::restart_bytes_per_particle(&sim),
    };
    if json {
        println!("{}", serde_json::to_string(&r).unwrap_or_default());
    } else {
        println!(
            "strand particles={} grid={}^3 steps={} dtype={} threads={} sec_per_step={:.6} particle_steps_per_s={:.4e} restart_bytes_per_particle={:.1}",
            r.particles, r.grid, r.steps, r.dtype, r.threads, r.sec_per_step, r.particle_steps_per_s, r.restart_bytes_per_particle
        );
        let shares: Vec<String> = r.phases.iter().map(|(n, s)| format!("{n} {:.0}%", 100.0 * s)).collect();
        eprintln!("phases: {}", shares.join(", "));
    }
    Ok(r)
}
