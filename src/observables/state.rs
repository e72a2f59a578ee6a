//! What an observable reads and where it writes its adjoint: the simulation's state and the
//! scenario's geometry ([`Frame`]), the seeds ([`Seed`]), and the selections several observables
//! share (the extreme particle, a section's points, the layer tops).

use crate::kernels::{Real, V3};
use crate::solver::Simulation;

/// Adjoints an objective seeds: of the final positions (grid coordinates), velocities, volume
/// ratios, masses and initial volumes (which emission's entering slab changes).
pub struct Seed<'a> {
    pub xg: &'a mut [V3],
    pub v: &'a mut [V3],
    pub j: &'a mut [Real],
    pub mass: &'a mut [Real],
    pub vol0: &'a mut [Real],
}

/// Geometry the objectives need from the scenario.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub dx: f64,
    pub spacing: f64,
    pub base_z: f64,
    /// `[observe] mirror_y`: the domain is half of a problem symmetric about y = mirror_y.
    pub mirror_y: Option<f64>,
    /// `[observe] slab`: knot spacing of the area's B-spline in x (default one cell).
    pub slab: f64,
    /// `[observe] y_range`, which the objectives refuse (they see every particle).
    pub y_range: Option<[f64; 2]>,
}

impl Frame {
    pub fn of(sim: &Simulation) -> Frame {
        let sc = &sim.scenario;
        let dx = sc.simulation.dx;
        let ppc = sc.bodies.first().map_or(2, |b| b.particles_per_cell_axis());
        // printed material is laid at the print's spacing
        let ppc = sc.print.as_ref().map_or(ppc, |p| p.particles_per_cell_axis);
        let obs = sc.observe.as_ref();
        // as the run's reporter: `[observe] base_z`, else the platform top, else the domain floor
        let base_z = obs.and_then(|o| o.base_z).or(sc.boundary.platform.as_ref().map(|p| p.z)).unwrap_or(sc.domain.min[2]);
        let (mirror_y, y_range) = (obs.and_then(|o| o.mirror_y), obs.and_then(|o| o.y_range));
        Frame { dx, spacing: dx / ppc as f64, base_z, mirror_y, slab: obs.and_then(|o| o.slab).unwrap_or(dx), y_range }
    }
}

/// Index of the particle maximising `key` among those `keep` admits (the first on ties).
pub(super) fn arg_max(n: usize, keep: impl Fn(usize) -> bool, key: impl Fn(usize) -> f64) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for i in (0..n).filter(|&i| keep(i)) {
        let k = key(i);
        if best.is_none_or(|(_, b)| k > b) {
            best = Some((i, k));
        }
    }
    best.map(|b| b.0)
}

/// The state an observable reads: the simulation, its frame, and d(world coordinate)/d(grid
/// coordinate) (`scale`, the cell size: seeds are of grid coordinates).
pub(super) struct State<'a> {
    pub(super) sim: &'a Simulation,
    pub(super) frame: &'a Frame,
    pub(super) scale: Real,
}

impl State<'_> {
    pub(super) fn n(&self) -> usize {
        self.sim.particles.n
    }

    pub(super) fn world(&self, i: usize) -> [f64; 3] {
        self.sim.grid.geom.to_world(self.sim.particles.xg.as_slice()[i])
    }
}

/// The particles of the cross-section slab |x - station| <= slab / 2 as the reporter's cloud
/// holds them: (index, +1) for each, and with `mirror_y` also (index, -1) for its mirror image
/// (y -> 2 y0 - y). None if the slab is empty.
pub(super) fn section_points(sim: &Simulation, frame: &Frame, station: f64) -> Option<Vec<(usize, f64)>> {
    let p = &sim.particles;
    let half = 0.5 * frame.slab;
    let inside: Vec<usize> = (0..p.n).filter(|&i| (sim.position(i)[0] - station).abs() <= half).collect();
    let mut pts: Vec<(usize, f64)> = inside.iter().map(|&i| (i, 1.0)).collect();
    if frame.mirror_y.is_some() {
        pts.extend(inside.iter().map(|&i| (i, -1.0)));
    }
    (!pts.is_empty()).then_some(pts)
}

/// The y of a section point: a particle's own (`sign` 1) or its mirror image about
/// `[observe] mirror_y` (`sign` -1), as `section_points` lists them.
pub(super) fn section_y(frame: &Frame, y: f64, sign: f64) -> f64 {
    sign * y + if sign < 0.0 { 2.0 * frame.mirror_y.unwrap_or(0.0) } else { 0.0 }
}

/// The nominal layer tops `layers.csv` assigns particles by: the z of each of the toolpath's
/// layers; None without a print or when they do not ascend.
pub(super) fn layer_tops(sim: &Simulation) -> Option<Vec<f64>> {
    let tops: Vec<f64> = sim.printer.as_ref()?.toolpath.layers().iter().map(|l| l.0).collect();
    crate::observe::valid_layer_tops(&tops).then_some(tops)
}
