//! Start-up: every pool sized from the scenario and the budget checked before anything is
//! mapped.

use super::binning::Scratch;
use super::walls::Walls;
use super::bodies::count_body_particles;
use super::{DtLimit, SimError, Simulation, MAX_THREADS};
use crate::grid::{Grid, GridGeom};
use crate::kernels::boundary::WallKind;
use crate::kernels::{Real, V3};
use crate::materials::build_material;
use crate::memory::{parse_size, Backing, MemoryPlan};
use crate::pools::{Counts, Pools};
use crate::particles::Particles;
use crate::invalid::Invalid;
use crate::print::Printer;
use crate::scenario::Scenario;
use crate::sleep::Sleep;
use crate::threads::ThreadTeam;
use std::sync::atomic::AtomicU64;

impl Simulation {
    /// Size every pool from the scenario, check the budget, map the pools and create the
    /// initial particles. Every command that builds a simulation comes through here, so none
    /// allocates before the memory plan's lower bound ([`super::preflight`]) is checked.
    pub fn new(scenario: &Scenario) -> Result<Self, SimError> {
        scenario.validate()?;
        // the memory plan's lower bound first: counting the particles of a scenario far over its
        // budget one by one, or building its print, would take hours or the machine's memory
        super::preflight(scenario)?;
        let material = build_material(&scenario.material)?;
        let geom = GridGeom::new(scenario.simulation.dx, scenario.domain.min, scenario.domain.max, scenario.domain.periodic);
        let state_len = material.state_names().len();

        let printer = match &scenario.print {
            Some(cfg) => {
                let d = &scenario.domain;
                Some(Printer::new(cfg, scenario.simulation.dx, (d.min, d.max), &scenario.base_dir)?)
            }
            None => None,
        };
        if let Some(p) = &printer {
            check_print_inside_domain(scenario, p)?;
        }
        let cap = particle_capacity(scenario, printer.as_ref())?;
        let max_blocks = scenario.memory.max_blocks.unwrap_or(geom.table_len()).max(8);
        let budget = parse_size(&scenario.memory.budget)?;
        // solids hook (issue 30)
        let nozzle = printer.as_ref().and_then(|p| match p.shape {
            crate::print::nozzle::NozzleShape::Circle { diameter } => Some((diameter, p.tube_height)),
            _ => None,
        });
        let mut particles = Particles::declared(state_len);
        let mut grid = Grid::declared(geom);
        let mut scratch = Scratch::declared(max_blocks, state_len);
        let mut sleep = scenario.sleep.as_ref().map(|cfg| Sleep::declared(cfg.clone(), &grid.geom, scenario.simulation.gravity).with_column_loads(material.column_loads()));
        let mut solids = crate::solid::Solids::declared(&scenario.solids, scenario.simulation.dx, nozzle)?;

        let capacity = Counts::capacity(cap, max_blocks);
        let mut memory = MemoryPlan::default();
        particles.plan_memory(&mut memory, &capacity);
        grid.plan_memory(&mut memory, &capacity);
        scratch.plan_memory(&mut memory, &capacity);
        if let Some(s) = &solids {
            s.plan_memory(&mut memory, &capacity);
        }
        if let Some(s) = &sleep {
            s.plan_memory(&mut memory, &capacity);
        }
        if let Some(p) = &printer {
            let q = scenario.print.as_ref().map_or(0, |c| c.queue);
            memory.add::<[f64; 3]>("emission.queue", (q + 1) * p.plan.particles_per_slab());
        }
        memory.check(budget)?;

        let backing = Backing { dir: scenario.memory.dir.clone() };
        if let Some(d) = &backing.dir {
            std::fs::create_dir_all(d)
                .map_err(|source| SimError::MemoryDir { dir: d.clone(), source })?;
        }
        particles.map_pools(&capacity, &backing)?;
        grid.map_pools(&capacity, &backing)?;
        scratch.map_pools(&capacity, &backing)?;
        if let Some(s) = &mut solids {
            s.map_pools(&capacity, &backing)?;
        }
        if let Some(s) = &mut sleep {
            s.map_pools(&capacity, &backing)?;
        }

        let threads = match scenario.simulation.threads {
            0 => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            t => t,
        }
        .min(MAX_THREADS);
        let accel = acceleration(scenario, material.density() as f64);
        let walls = Walls::new(&scenario.boundary, &grid.geom);

        let mut sim = Simulation {
            scenario: scenario.clone(),
            material,
            particles,
            grid,
            scratch,
            team: ThreadTeam::new(threads),
            walls,
            accel,
            time: 0.0,
            step: 0,
            vmax: 0.0,
            last_dt: 0.0,
            last_limit: DtLimit::Fixed,
            memory,
            budget,
            thread_out: std::array::from_fn(|_| AtomicU64::new(0)),
            phase_seconds: [0.0; super::PHASES.len()],
            printer,
            sleep,
            awake_particle_steps: 0,
            external_work: 0.0,
            frozen_order: false,
            solids,
        };
        if let Some(p) = &mut sim.printer {
            p.start(scenario.print.as_ref().map_or(64, |c| c.queue), 0);
        }
        for body in &scenario.bodies {
            sim.add_body(body)?;
        }
        sim.vmax = sim.particles.v.as_slice()[..sim.particles.n].iter().map(|v| v.length() as f64).fold(0.0, f64::max);
        Ok(sim)
    }
}

/// The particle pool's length: `[memory] max_particles`, or what the bodies and the whole print
/// need; an error when the print needs more than the pool holds.
fn particle_capacity(scenario: &Scenario, printer: Option<&Printer>) -> Result<usize, SimError> {
    let initial = count_body_particles(scenario);
    let emitted = printer.map_or(0, |p| p.plan.total_particles() as usize);
    let cap = scenario.memory.max_particles.unwrap_or(initial + emitted).max(1);
    if initial + emitted > cap {
        return Err(SimError::ParticlePool { initial, emitted, capacity: cap });
    }
    Ok(cap)
}

/// Gravity plus the body force per unit mass of a material of density `rho`.
fn acceleration(scenario: &Scenario, rho: f64) -> V3 {
    let s = &scenario.simulation;
    V3::new(
        (s.gravity[0] + s.body_force[0] / rho) as Real,
        (s.gravity[1] + s.body_force[1] / rho) as Real,
        (s.gravity[2] + s.body_force[2] / rho) as Real,
    )
}

/// Start-up check: the tube must stay inside the domain along the whole toolpath, with room above
/// it for the slab that is entering (continuous emission), whose lattice points outside the
/// domain would be lost. It may cross a symmetry plane as long as the nozzle axis itself stays
/// inside.
fn check_print_inside_domain(sc: &Scenario, p: &Printer) -> Result<(), SimError> {
    let (lo, hi) = p.toolpath.bounds();
    // a laid deposit reaches half its section's width from the path, the nozzle its outlet's
    let [ex, ey] = match p.plan.laid.as_ref() {
        Some((lattice, _)) => [lattice.reach(); 2],
        None => p.shape.half_extent(),
    };
    let b = &sc.boundary;
    let sides = [[b.x_min, b.x_max], [b.y_min, b.y_max], [b.z_min, b.z_max]];
    let reach = [ex, ey, 0.0];
    for a in 0..3 {
        let lo_need = if sides[a][0] == WallKind::Symmetry { lo[a] } else { lo[a] - reach[a] };
        let hi_need = if sides[a][1] == WallKind::Symmetry { hi[a] } else { hi[a] + reach[a] };
        let feed = if p.plan.partial { p.plan.slab_thickness() } else { 0.0 };
        let hi_need = if a == 2 { hi[a] + p.tube_height + feed } else { hi_need };
        if lo_need < sc.domain.min[a] - 1e-12 || hi_need > sc.domain.max[a] + 1e-12 {
            let what = if a == 2 && feed > 0.0 { "nozzle tube and the slab entering it" } else { "nozzle tube" };
            return Err(SimError::Invalid(Invalid(format!(
                "print: the {what} span [{lo_need:.4}, {hi_need:.4}] m on axis {a} along the toolpath, \
                 outside the domain [{}, {}]",
                sc.domain.min[a], sc.domain.max[a]
            ))));
        }
    }
    Ok(())
}
