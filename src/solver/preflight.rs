//! The memory plan's lower bound, checked before a simulation allocates or counts anything: the
//! grid and the fewest particles the bodies can hold, against `[memory] budget`.

use crate::invalid::Invalid;
use crate::memory::{fmt_bytes, parse_size};
use crate::scenario::Scenario;

/// Before anything is allocated or counted: refuse a scenario whose memory plan is over its
/// budget even with the fewest particles its bodies can hold (a lower bound from each body's
/// lattice, cheap at any resolution), so every command answers at once where counting the
/// particles one by one would take hours, or allocating them the machine's memory.
/// [`Simulation::new`](super::Simulation::new) calls it first, so no command that builds a
/// simulation (run, check, grad, compare, synth, calibrate, diagnose, evaluate, verify) misses it.
pub fn preflight(sc: &Scenario) -> Result<(), Invalid> {
    use crate::memory::MemoryPlan;
    use crate::pools::Pools;
    let budget = parse_size(&sc.memory.budget).map_err(|e| Invalid(format!("memory.budget: {e}")))?;
    let state_len = crate::materials::build_material(&sc.material)?.state_names().len();
    // a fold from +0.0: an empty f64 sum is -0.0, which printed as "-0.0000e0 particles"
    let fewest = sc.bodies.iter().map(|b| fewest_particles(sc, b)).fold(0.0, |n, b| n + b);
    let geom = crate::grid::GridGeom::new(sc.simulation.dx, sc.domain.min, sc.domain.max, sc.domain.periodic);
    let capacity = crate::pools::Counts::capacity(fewest.min(1e15) as usize, sc.memory.max_blocks.unwrap_or(geom.table_len()).max(8));
    let mut plan = MemoryPlan::default();
    crate::particles::Particles::declared(state_len).plan_memory(&mut plan, &capacity);
    crate::grid::Grid::declared(geom).plan_memory(&mut plan, &capacity);
    if plan.total() > budget {
        let what = if fewest >= 1.0 { format!("the grid and the at least {} particles of the bodies", count(fewest)) } else { "the grid alone (before any particle)".to_string() };
        return Err(Invalid(format!(
            "memory plan: {what} at dx = {} m need at least {}, over the budget of {} \
             (raise [memory] budget, or lower resolution / max_blocks):\n{plan}",
            sc.simulation.dx,
            fmt_bytes(plan.total()),
            fmt_bytes(budget)
        )));
    }
    Ok(())
}

/// A particle count for a message: whole below a million, else in scientific notation.
fn count(n: f64) -> String {
    if n < 1e6 {
        format!("{n:.0}")
    } else {
        format!("{n:.3e}")
    }
}

/// The fewest particles `body` holds: its lattice over the largest box inside it and the
/// domain (a union's or intersection's: its lattice counted).
fn fewest_particles(sc: &Scenario, body: &crate::scenario::Body) -> f64 {
    use crate::scenario::Body;
    let h = sc.simulation.dx / body.particles_per_cell_axis() as f64;
    let (lo, hi) = match body {
        Body::Box { min, max, .. } => (*min, *max),
        Body::Frustum { base_center: c, bottom_radius, top_radius, height, .. } => {
            let r = bottom_radius.min(*top_radius) / std::f64::consts::SQRT_2;
            ([c[0] - r, c[1] - r, c[2]], [c[0] + r, c[1] + r, c[2] + height])
        }
        Body::Union { .. } | Body::Intersection { .. } => {
            let mut n = 0usize;
            super::bodies::for_each_lattice_point(sc, body, |_| n += 1);
            return n as f64;
        }
    };
    let d = &sc.domain;
    (0..3).map(|a| ((hi[a].min(d.max[a]) - lo[a].max(d.min[a])) / h - 1.0).floor().max(0.0)).product()
}
