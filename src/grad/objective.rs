//! Objectives: scalar functions of the final particle state, with their adjoints (the seed of
//! the backward pass).
//!
//! They follow the observables of `observe.rs` (a particle stands for a cube of side
//! `spacing`): extents add one spacing to the spread of particle centres. An extent is a max
//! minus a min, so its gradient flows through the extreme particles only; which particle is
//! extreme, and which particles fall into a slab or band, is held fixed (piecewise constant in
//! the positions).

use crate::kernels::{Real, V3};
use crate::solver::Simulation;

#[derive(Clone, Debug, PartialEq)]
pub enum Objective {
    /// Slump-flow spread: mean of the x and y extents of the particles within two spacings of
    /// the base (as `spread.csv`'s `mean_diameter`).
    Spread,
    /// Extent in y of the particles within half a cell of x = station [m], summed over the
    /// stations (paper 000 sec. 4.2 sums three); with `[observe] mirror_y`, of the mirrored
    /// material.
    Width { stations: Vec<f64> },
    /// Top of the particles within half a cell of x = station above the base [m], summed.
    Height { stations: Vec<f64> },
    /// Cross-section area at x = station [m2], summed: the particle volumes V0 J weighted by the
    /// quadratic B-spline of knot spacing `slab` in x, over the slab (as `sections.csv`'s `area`,
    /// consistent with the mass balance); with `[observe] mirror_y`, of the mirrored material.
    Area { stations: Vec<f64> },
    /// Top of all the material above the base [m].
    TotalHeight,
    /// Flow front: the leading edge of the material in x [m] (largest particle x plus half a
    /// spacing; the flow distance of an L-box or channel test, from the gate at its x).
    Front,
    /// Largest x velocity of any particle (the centreline speed of a channel flow).
    VxMax,
    /// Sum of m |v|^2 / 2.
    KineticEnergy,
    /// Volume-weighted mean height of the particles above the base.
    MeanZ,
}

pub const NAMES: &str = "spread, width@X[,X...], height@X[,X...], area@X[,X...], total_height, front, vx_max, kinetic_energy, mean_z";

impl std::str::FromStr for Objective {
    type Err = String;
    fn from_str(s: &str) -> Result<Objective, String> {
        let stations = |v: &str| {
            v.split(',')
                .map(|x| x.trim().parse::<f64>().map_err(|_| format!("objective '{s}': the stations after '@' must be numbers in metres")))
                .collect::<Result<Vec<f64>, String>>()
        };
        match s.split_once('@') {
            Some(("width", x)) => Ok(Objective::Width { stations: stations(x)? }),
            Some(("height", x)) => Ok(Objective::Height { stations: stations(x)? }),
            Some(("area", x)) => Ok(Objective::Area { stations: stations(x)? }),
            _ => match s {
                "spread" => Ok(Objective::Spread),
                "total_height" => Ok(Objective::TotalHeight),
                "front" => Ok(Objective::Front),
                "vx_max" => Ok(Objective::VxMax),
                "kinetic_energy" => Ok(Objective::KineticEnergy),
                "mean_z" => Ok(Objective::MeanZ),
                _ => Err(format!("unknown objective '{s}'; known: {NAMES}")),
            },
        }
    }
}

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
}

impl Frame {
    pub fn of(sim: &Simulation) -> Frame {
        let sc = &sim.scenario;
        let dx = sc.simulation.dx;
        let ppc = sc.bodies.first().map_or(2, |b| b.particles_per_cell_axis());
        let base_z = sc.boundary.platform.as_ref().map_or(sc.domain.min[2], |p| p.z);
        // printed material is laid at the print's spacing
        let ppc = sc.print.as_ref().map_or(ppc, |p| p.particles_per_cell_axis);
        let obs = sc.observe.as_ref();
        Frame { dx, spacing: dx / ppc as f64, base_z, mirror_y: obs.and_then(|o| o.mirror_y), slab: obs.and_then(|o| o.slab).unwrap_or(dx) }
    }
}

/// Index of the particle maximising `key` among those `keep` admits (the first on ties).
fn arg_max(n: usize, keep: impl Fn(usize) -> bool, key: impl Fn(usize) -> f64) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for i in (0..n).filter(|&i| keep(i)) {
        let k = key(i);
        if best.is_none_or(|(_, b)| k > b) {
            best = Some((i, k));
        }
    }
    best.map(|b| b.0)
}

impl Objective {
    /// The objective on `sim`'s current state; with `seed`, also add its adjoint there.
    pub fn evaluate(&self, sim: &Simulation, frame: &Frame, seed: Option<Seed>) -> Result<f64, String> {
        let p = &sim.particles;
        let n = p.n;
        let geom = &sim.grid.geom;
        let world = |i: usize| geom.to_world(p.xg.as_slice()[i]);
        let dx = frame.dx;
        // d(world coordinate)/d(grid coordinate)
        let scale = dx as Real;
        let value = match self {
            Objective::Spread => {
                let band = |i: usize| world(i)[2] < frame.base_z + 2.0 * frame.spacing;
                let ext = |a: usize| {
                    let hi = arg_max(n, band, |i| world(i)[a]);
                    let lo = arg_max(n, band, |i| -world(i)[a]);
                    hi.zip(lo)
                };
                let (Some((xh, xl)), Some((yh, yl))) = (ext(0), ext(1)) else {
                    return Err("objective spread: no particle lies within two spacings of the base".into());
                };
                let d = |h: usize, l: usize, a: usize| world(h)[a] - world(l)[a] + frame.spacing;
                let value = 0.5 * (d(xh, xl, 0) + d(yh, yl, 1));
                if let Some(s) = seed {
                    s.xg[xh].x += 0.5 * scale;
                    s.xg[xl].x -= 0.5 * scale;
                    s.xg[yh].y += 0.5 * scale;
                    s.xg[yl].y -= 0.5 * scale;
                }
                value
            }
            Objective::Width { stations } | Objective::Height { stations } => {
                let width = matches!(self, Objective::Width { .. });
                let mut total = 0.0;
                let mut seed = seed;
                for &station in stations {
                    let slab = |i: usize| (world(i)[0] - station).abs() <= 0.5 * dx;
                    let top = arg_max(n, slab, |i| world(i)[2]);
                    let (hi, lo) = (arg_max(n, slab, |i| world(i)[1]), arg_max(n, slab, |i| -world(i)[1]));
                    let (Some(top), Some(hi), Some(lo)) = (top, hi, lo) else {
                        return Err(format!("objective {}: no particle within half a cell of x = {station} m", self.name()));
                    };
                    total += if !width {
                        world(top)[2] + 0.5 * frame.spacing - frame.base_z
                    } else if let Some(y0) = frame.mirror_y {
                        2.0 * (world(hi)[1] - y0) + frame.spacing
                    } else {
                        world(hi)[1] - world(lo)[1] + frame.spacing
                    };
                    if let Some(s) = seed.as_mut() {
                        match (width, frame.mirror_y) {
                            (false, _) => s.xg[top].z += scale,
                            (true, Some(_)) => s.xg[hi].y += 2.0 * scale,
                            (true, None) => {
                                s.xg[hi].y += scale;
                                s.xg[lo].y -= scale;
                            }
                        }
                    }
                }
                total
            }
            Objective::Area { stations } => {
                let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
                let copies = if frame.mirror_y.is_some() { 2.0 } else { 1.0 };
                let slab = frame.slab;
                let mut total = 0.0;
                let mut seed = seed;
                for &station in stations {
                    for i in 0..n {
                        let u = (world(i)[0] - station) / slab;
                        if u.abs() >= 1.5 {
                            continue;
                        }
                        let (b, db) = crate::observe::quadratic_bspline_and_slope(u);
                        let vol = (vol0[i] * jv[i]) as f64;
                        total += copies * vol * b / slab;
                        if let Some(s) = seed.as_mut() {
                            s.xg[i].x += (copies * vol * db / (slab * slab)) as Real * scale;
                            s.j[i] += (copies * vol0[i] as f64 * b / slab) as Real;
                            s.vol0[i] += (copies * jv[i] as f64 * b / slab) as Real;
                        }
                    }
                }
                total
            }
            Objective::TotalHeight => {
                let top = arg_max(n, |_| true, |i| world(i)[2]).ok_or("objective total_height: no particles")?;
                if let Some(s) = seed {
                    s.xg[top].z += scale;
                }
                world(top)[2] + 0.5 * frame.spacing - frame.base_z
            }
            Objective::Front => {
                let lead = arg_max(n, |_| true, |i| world(i)[0]).ok_or("objective front: no particles")?;
                if let Some(s) = seed {
                    s.xg[lead].x += scale;
                }
                world(lead)[0] + 0.5 * frame.spacing
            }
            Objective::VxMax => {
                let v = p.v.as_slice();
                let i = arg_max(n, |_| true, |i| v[i].x as f64).ok_or("objective vx_max: no particles")?;
                if let Some(s) = seed {
                    s.v[i].x += 1.0;
                }
                v[i].x as f64
            }
            Objective::KineticEnergy => {
                let (v, m) = (p.v.as_slice(), p.mass.as_slice());
                let value = (0..n).map(|i| 0.5 * (m[i] * v[i].length_squared()) as f64).sum();
                if let Some(s) = seed {
                    for i in 0..n {
                        s.v[i] += v[i] * m[i];
                        s.mass[i] += 0.5 * v[i].length_squared();
                    }
                }
                value
            }
            Objective::MeanZ => {
                let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
                let w: f64 = (0..n).map(|i| (vol0[i] * jv[i]) as f64).sum();
                if w <= 0.0 {
                    return Err("objective mean_z: no particles".into());
                }
                let wz: f64 = (0..n).map(|i| (vol0[i] * jv[i]) as f64 * (world(i)[2] - frame.base_z)).sum();
                let value = wz / w;
                if let Some(s) = seed {
                    for i in 0..n {
                        let vi = (vol0[i] * jv[i]) as f64;
                        s.xg[i].z += (vi / w) as Real * scale;
                        s.j[i] += (vol0[i] as f64 * ((world(i)[2] - frame.base_z) - value) / w) as Real;
                        s.vol0[i] += (jv[i] as f64 * ((world(i)[2] - frame.base_z) - value) / w) as Real;
                    }
                }
                value
            }
        };
        Ok(value)
    }

    pub fn name(&self) -> String {
        match self {
            Objective::Spread => "spread".into(),
            Objective::Width { stations } => format!("width@{}", join(stations)),
            Objective::Height { stations } => format!("height@{}", join(stations)),
            Objective::Area { stations } => format!("area@{}", join(stations)),
            Objective::TotalHeight => "total_height".into(),
            Objective::Front => "front".into(),
            Objective::VxMax => "vx_max".into(),
            Objective::KineticEnergy => "kinetic_energy".into(),
            Objective::MeanZ => "mean_z".into(),
        }
    }
}

fn join(stations: &[f64]) -> String {
    stations.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")
}
