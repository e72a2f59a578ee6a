//! What is said about a scenario before it runs: too many planned steps, and warnings about what
//! its author may not expect. (Its memory plan's lower bound, checked before anything is
//! allocated, is `solver::preflight`, which every simulation's setup calls.)

use crate::invalid::Invalid;
use crate::scenario::Scenario;
use crate::solver::Simulation;

/// What a scenario does that its author may not expect, said before it runs, one line each
/// (`warning: ...` or `note: ...`): a wall moved to the nearest cell face, nothing to simulate,
/// a body cut by the domain, bodies overlapping, a solid that holds no grid node, a sleeping
/// elastic wall printed to failure, what the G-code import skipped, whether a print that writes
/// no `[sleep]` sleeps and why.
pub fn scenario_warnings(sc: &Scenario, sim: &Simulation) -> Vec<String> {
    use crate::solver::for_each_lattice_point;
    let mut w = Vec::new();
    let (d, dx) = (&sc.domain, sc.simulation.dx);
    for a in 0..3 {
        let cells = (d.max[a] - d.min[a]) / dx;
        let n = cells.round();
        if !d.periodic[a] && (cells - n).abs() > 1e-6 * n.max(1.0) {
            w.push(format!(
                "domain.max[{a}] = {} is not a whole number of cells of dx = {dx} from domain.min[{a}] = {} ({cells:.4} cells): \
                 the wall is at {} ({n} cells)",
                d.max[a],
                d.min[a],
                d.min[a] + n * dx
            ));
        }
    }
    // a printed section needs the nozzle resolved by enough cells
    if let Some(r) = sc.print.as_ref().filter(|p| p.deposit.laid().is_none()).and_then(|p| p.nozzle.resolution_warning(dx, sc.simulation.j_bar)) {
        w.push(r);
    }
    // a solid outside the domain touches nothing: most often its coordinates are in mm
    for (name, lo, hi) in sim.solids.as_ref().map_or(Vec::new(), |z| z.wholly_outside(d.min, d.max)) {
        w.push(format!(
            "solid '{name}' lies wholly outside the domain (its bounds [{:.4}, {:.4}, {:.4}] to [{:.4}, {:.4}, {:.4}] against the domain's {:?} to {:?}): \
             it touches nothing; lengths are in metres (were they written in mm?)",
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z, d.min, d.max
        ));
    }
    // a solid that holds no node lets material through
    for (name, most) in sim.solids.as_ref().map_or(Vec::new(), |z| z.held_at_no_node(&sim.grid.geom)) {
        let seen = if most > 0.0 { format!("only its band's nodes take part of its condition (at most {most:.2}), so material seeps through it") } else { "the grid does not see it".to_string() };
        w.push(format!("solid '{name}' holds no grid node at dx = {dx} (none lies on or inside it): {seen}; make it at least a cell thick or move a face onto a node plane"));
    }
    // sleeping material is held still: the failure layer of a wall of a rate-independent
    // elastic-plastic solid (elastic, no viscosity) moves (docs/failure.md)
    let stability = sim.material.stability();
    let rate_independent_solid = stability.shear_modulus > 0.0 && stability.max_viscosity == 0.0;
    let printed_to_failure = sc.print.is_some() && sc.observe.as_ref().is_some_and(|o| !o.stations.is_empty());
    if sc.sleep.is_some() && printed_to_failure && rate_independent_solid {
        w.push(format!(
            "warning: [sleep] holds sleeping material still, and a sleeping {} wall printed to failure does not fail where it \
             fails awake (docs/failure.md \"Sleeping and failure\"); for its failure layer, run it without [sleep]",
            sim.material.name()
        ));
    }
    if sim.particles.n == 0 && sc.print.is_none() {
        w.push(if sc.bodies.is_empty() {
            "nothing to simulate: the scenario has no [[body]] and no [print]".to_string()
        } else {
            format!("nothing to simulate: the bodies hold no particle at dx = {dx} (each is smaller than a particle spacing, or dx exceeds the domain)")
        });
    }
    if let Some((file, p)) = sc.print.as_ref().and_then(|p| p.gcode.as_ref().map(|f| (f, p))) {
        let path = sc.base_dir.join(file);
        let notes = std::fs::read_to_string(&path).ok().and_then(|t| crate::print::gcode::parse_gcode_for_outlet(&t, &p.gcode_options, p.nozzle.area()).ok().map(|(_, n)| n));
        if let Some(n) = notes {
            if !n.is_empty() {
                w.push(format!("note: {}: {n}", path.display()));
            }
            w.extend(n.warnings.iter().map(|x| format!("{}: {x}", path.display())));
        }
    }
    for (i, b) in sc.bodies.iter().enumerate() {
        let (lo, hi) = b.bounds();
        let cut: Vec<String> = (0..3)
            .filter(|&a| lo[a] < d.min[a] - 1e-9 * dx || hi[a] > d.max[a] + 1e-9 * dx)
            .map(|a| format!("axis {a}: [{}, {}] against the domain's [{}, {}]", lo[a], hi[a], d.min[a], d.max[a]))
            .collect();
        if !cut.is_empty() {
            let mut n = 0usize;
            for_each_lattice_point(sc, b, |_| n += 1);
            w.push(format!("body[{i}] reaches outside the domain ({}): the part outside is cut off, {n} particles remain", cut.join("; ")));
        }
        for (j, other) in sc.bodies.iter().enumerate().take(i) {
            let (olo, ohi) = other.bounds();
            if (0..3).any(|a| hi[a] <= olo[a] || lo[a] >= ohi[a]) {
                continue;
            }
            let (mut n, contains) = (0usize, other.inside());
            for_each_lattice_point(sc, b, |p| n += contains(p) as usize);
            if n > 0 {
                w.push(format!("body[{i}] overlaps body[{j}]: {n} of its particles lie inside body[{j}], doubling the material there"));
            }
        }
    }
    // a print that writes no [sleep]: whether it sleeps, and why (the default's rule,
    // `config::sleep::sleep_by_default`)
    if let Some(d) = sc.sleep_default.as_ref().filter(|_| sc.print.is_some()) {
        w.push(match d.on {
            true => format!("note: sleeping is on by default: {}; [sleep] enabled = false keeps all material awake", d.why),
            false => format!("note: all material stays awake: {}; a [sleep] table lets it sleep", d.why),
        });
    }
    w.into_iter().map(|x| if x.starts_with("note: ") { x } else { format!("warning: {x}") }).collect()
}

/// The steps the run needs at its first time step, refused over `MAX_STEPS`.
pub fn planned_steps(sim: &Simulation, end: f64) -> Result<f64, Invalid> {
    let (dt, limit) = sim.choose_dt(f64::INFINITY);
    let steps = ((end - sim.time) / dt).max(0.0).ceil();
    if steps > crate::scenario::MAX_STEPS {
        return Err(Invalid(format!(
            "the first time step, {dt:.3e} s (bound by {limit:?}), takes {steps:.3e} steps to simulation.end_time = {end} s, \
             more than the {:e} a run may plan",
            crate::scenario::MAX_STEPS
        )));
    }
    Ok(steps)
}
