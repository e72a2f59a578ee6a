//! Objectives: scalar functions of the final particle state, with their adjoints (the seed of
//! the backward pass).
//!
//! They follow the observables of `observe.rs` (a particle stands for a cube of side
//! `spacing`): extents add one spacing to the spread of particle centres. An extent is a max
//! minus a min, so its gradient flows through the extreme particles only; which particle is
//! extreme, and which particles fall into a slab or band, a profile's y bin or a printed layer,
//! is held fixed (piecewise constant in the positions).

use super::GradError;
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
    /// `Height` at one station where the material may not have arrived: 0 when no particle lies
    /// within half a cell of it (an L-box's height at the end of the box).
    Level { station: f64 },
    /// Cross-section area at x = station [m2], summed: the particle volumes V0 J weighted by the
    /// quadratic B-spline of knot spacing `slab` in x, over the slab (as `sections.csv`'s `area`,
    /// consistent with the mass balance); with `[observe] mirror_y`, of the mirrored material.
    Area { stations: Vec<f64> },
    /// A point of the printed cross-section's profile: the height above the base [m] of the top
    /// outline of the section at x = station, at lateral position y [m]. Exactly
    /// `observe::profile_z_at(cross_section(..).profile, y) - base_z` as the run's reporter builds
    /// the section: the particles with |x - station| <= slab / 2 (`[observe] slab`, default one
    /// cell), with `[observe] mirror_y` together with their mirror images, binned in y at the
    /// print's spacing h from the lowest y; a bin's top is its highest particle + h / 2, the
    /// outline runs linearly between bin centres, flat over the outer half of a run's end bins,
    /// and at the base elsewhere (0 in a gap or beside the material). Its adjoint flows through
    /// the particles that set the tops of the (at most two) bins around y, and through the one
    /// that sets the lowest y (the bins' origin); which particles those are is held fixed.
    Profile { station: f64, y: f64 },
    /// Thickness [m] of printed layer `layer` (1 = the bottom one) at x = station, as
    /// `observe::layer_heights` (the run's `layers.csv`) gives it: the slab's particles are
    /// assigned to layers by their z against the toolpath's layer heights (the nominal tops);
    /// a layer's top is its highest particle + h / 2, its thickness that top minus the top of
    /// the nearest non-empty layer below (the base for the first); 0 for an empty layer. The
    /// assignment and the top particles are held fixed.
    LayerHeight { station: f64, layer: usize },
    /// Width [m] of printed layer `layer` at x = station (`observe::layer_widths`): the y
    /// extent + h of the particles `LayerHeight` assigns to it; with `[observe] mirror_y`, of
    /// them together with their mirror images; 0 for an empty layer.
    LayerWidth { station: f64, layer: usize },
    /// The section's width at x = station [m] as a smooth function of every particle near it
    /// (`smooth_extent.rs`): the distance between the outermost crossings of its thickness
    /// profile over y with half a spacing; with `[observe] mirror_y`, twice the upper crossing's
    /// distance from the plane. Unlike `width` it has no jumps where particles cross a slab's
    /// edge, so fits and differences see a smooth function of the parameters.
    SmoothWidth { station: f64 },
    /// The section's height at x = station above the base [m], smooth as `SmoothWidth`: the
    /// upper crossing of its width profile over z with half a spacing.
    SmoothHeight { station: f64 },
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

pub const NAMES: &str = "spread, width@X[,X...], height@X[,X...], level@X, area@X[,X...], profile@X:Y, layer_height@X:K, layer_width@X:K, smooth_width@X, smooth_height@X, total_height, front, vx_max, kinetic_energy, mean_z";

impl std::str::FromStr for Objective {
    type Err = GradError;
    fn from_str(s: &str) -> Result<Objective, GradError> {
        let stations = |v: &str| {
            v.split(',')
                .map(|x| x.trim().parse::<f64>().map_err(|_| GradError::Objective(format!("objective '{s}': the stations after '@' must be numbers in metres"))))
                .collect::<Result<Vec<f64>, GradError>>()
        };
        match s.split_once('@') {
            Some(("width", x)) => Ok(Objective::Width { stations: stations(x)? }),
            Some(("height", x)) => Ok(Objective::Height { stations: stations(x)? }),
            Some(("level", x)) => match stations(x)?[..] {
                [station] => Ok(Objective::Level { station }),
                _ => Err(GradError::Objective(format!("objective '{s}': level takes one station"))),
            },
            Some((name @ ("smooth_width" | "smooth_height"), x)) => match stations(x)?[..] {
                [station] if name == "smooth_width" => Ok(Objective::SmoothWidth { station }),
                [station] => Ok(Objective::SmoothHeight { station }),
                _ => Err(GradError::Objective(format!("objective '{s}': {name} takes one station"))),
            },
            Some(("area", x)) => Ok(Objective::Area { stations: stations(x)? }),
            Some((name @ ("profile" | "layer_height" | "layer_width"), x)) => {
                let what = if name == "profile" { "X:Y, the station x and the lateral position y in metres" } else { "X:K, the station x in metres and the layer K (1 = the bottom one)" };
                let bad = || GradError::Objective(format!("objective '{s}': {name} takes {what}"));
                let (a, b) = x.split_once(':').ok_or_else(bad)?;
                let station = a.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(bad)?;
                if name == "profile" {
                    let y = b.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(bad)?;
                    return Ok(Objective::Profile { station, y });
                }
                let layer = b.trim().parse::<usize>().ok().filter(|&k| k >= 1).ok_or_else(bad)?;
                Ok(if name == "layer_height" { Objective::LayerHeight { station, layer } } else { Objective::LayerWidth { station, layer } })
            }
            _ => match s {
                "spread" => Ok(Objective::Spread),
                "total_height" => Ok(Objective::TotalHeight),
                "front" => Ok(Objective::Front),
                "vx_max" => Ok(Objective::VxMax),
                "kinetic_energy" => Ok(Objective::KineticEnergy),
                "mean_z" => Ok(Objective::MeanZ),
                _ => Err(GradError::Objective(format!("unknown objective '{s}'; known: {NAMES}"))),
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
    pub fn evaluate(&self, sim: &Simulation, frame: &Frame, seed: Option<Seed>) -> Result<f64, GradError> {
        if let Some([lo, hi]) = frame.y_range {
            return Err(GradError::Objective(format!(
                "objective {}: [observe] y_range = [{lo}, {hi}] limits the run's observables, not the gradient objectives, \
                 which see every particle: remove it to differentiate or fit",
                self.name()
            )));
        }
        let at = State { sim, frame, scale: frame.dx as Real };
        match self {
            Objective::Spread => at.spread(seed),
            Objective::Level { station } => at.level(*station, seed),
            Objective::Width { stations } => at.width_or_height(self, stations, true, seed),
            Objective::Height { stations } => at.width_or_height(self, stations, false, seed),
            Objective::Area { stations } => Ok(at.area(stations, seed)),
            Objective::Profile { station, y } => at.profile(self, *station, *y, seed),
            Objective::LayerHeight { station, layer } => at.layer(self, *station, *layer, true, seed),
            Objective::LayerWidth { station, layer } => at.layer(self, *station, *layer, false, seed),
            Objective::SmoothWidth { station } => at.smooth_extent(self, *station, true, seed),
            Objective::SmoothHeight { station } => at.smooth_extent(self, *station, false, seed),
            Objective::TotalHeight => at.total_height(seed),
            Objective::Front => at.front(seed),
            Objective::VxMax => at.vx_max(seed),
            Objective::KineticEnergy => Ok(at.kinetic_energy(seed)),
            Objective::MeanZ => at.mean_z(seed),
        }
    }

    pub fn name(&self) -> String {
        match self {
            Objective::Spread => "spread".into(),
            Objective::Width { stations } => format!("width@{}", join(stations)),
            Objective::Height { stations } => format!("height@{}", join(stations)),
            Objective::Level { station } => format!("level@{station}"),
            Objective::Area { stations } => format!("area@{}", join(stations)),
            Objective::Profile { station, y } => format!("profile@{station}:{y}"),
            Objective::LayerHeight { station, layer } => format!("layer_height@{station}:{layer}"),
            Objective::LayerWidth { station, layer } => format!("layer_width@{station}:{layer}"),
            Objective::SmoothWidth { station } => format!("smooth_width@{station}"),
            Objective::SmoothHeight { station } => format!("smooth_height@{station}"),
            Objective::TotalHeight => "total_height".into(),
            Objective::Front => "front".into(),
            Objective::VxMax => "vx_max".into(),
            Objective::KineticEnergy => "kinetic_energy".into(),
            Objective::MeanZ => "mean_z".into(),
        }
    }
}

/// The state an objective reads: the simulation, its frame, and d(world coordinate)/d(grid
/// coordinate) (`scale`, the cell size: seeds are of grid coordinates).
struct State<'a> {
    sim: &'a Simulation,
    frame: &'a Frame,
    scale: Real,
}

impl State<'_> {
    fn n(&self) -> usize {
        self.sim.particles.n
    }

    fn world(&self, i: usize) -> [f64; 3] {
        self.sim.grid.geom.to_world(self.sim.particles.xg.as_slice()[i])
    }

    fn spread(&self, seed: Option<Seed>) -> Result<f64, GradError> {
        let (frame, n) = (self.frame, self.n());
        let band = |i: usize| self.world(i)[2] < frame.base_z + 2.0 * frame.spacing;
        let ext = |a: usize| {
            let hi = arg_max(n, band, |i| self.world(i)[a]);
            let lo = arg_max(n, band, |i| -self.world(i)[a]);
            hi.zip(lo)
        };
        let (Some((xh, xl)), Some((yh, yl))) = (ext(0), ext(1)) else {
            return Err(GradError::Objective("objective spread: no particle lies within two spacings of the base".into()));
        };
        let d = |h: usize, l: usize, a: usize| self.world(h)[a] - self.world(l)[a] + frame.spacing;
        let value = 0.5 * (d(xh, xl, 0) + d(yh, yl, 1));
        if let Some(s) = seed {
            s.xg[xh].x += 0.5 * self.scale;
            s.xg[xl].x -= 0.5 * self.scale;
            s.xg[yh].y += 0.5 * self.scale;
            s.xg[yl].y -= 0.5 * self.scale;
        }
        Ok(value)
    }

    fn level(&self, station: f64, seed: Option<Seed>) -> Result<f64, GradError> {
        let slab = |i: usize| (self.world(i)[0] - station).abs() <= 0.5 * self.frame.dx;
        if arg_max(self.n(), slab, |_| 0.0).is_none() {
            return Ok(0.0);
        }
        let height = Objective::Height { stations: vec![station] };
        self.width_or_height(&height, &[station], false, seed)
    }

    fn width_or_height(&self, what: &Objective, stations: &[f64], width: bool, mut seed: Option<Seed>) -> Result<f64, GradError> {
        let (frame, n, scale) = (self.frame, self.n(), self.scale);
        let mut total = 0.0;
        for &station in stations {
            let slab = |i: usize| (self.world(i)[0] - station).abs() <= 0.5 * frame.dx;
            let top = arg_max(n, slab, |i| self.world(i)[2]);
            let (hi, lo) = (arg_max(n, slab, |i| self.world(i)[1]), arg_max(n, slab, |i| -self.world(i)[1]));
            let (Some(top), Some(hi), Some(lo)) = (top, hi, lo) else {
                return Err(GradError::Objective(format!("objective {}: no particle within half a cell of x = {station} m", what.name())));
            };
            total += if !width {
                self.world(top)[2] + 0.5 * frame.spacing - frame.base_z
            } else if let Some(y0) = frame.mirror_y {
                2.0 * (self.world(hi)[1] - y0) + frame.spacing
            } else {
                self.world(hi)[1] - self.world(lo)[1] + frame.spacing
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
        Ok(total)
    }

    fn area(&self, stations: &[f64], mut seed: Option<Seed>) -> f64 {
        let p = &self.sim.particles;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        let copies = if self.frame.mirror_y.is_some() { 2.0 } else { 1.0 };
        let slab = self.frame.slab;
        let mut total = 0.0;
        for &station in stations {
            for i in 0..p.n {
                let u = (self.world(i)[0] - station) / slab;
                if u.abs() >= 1.5 {
                    continue;
                }
                let (b, db) = crate::observe::quadratic_bspline_and_slope(u);
                let vol = (vol0[i] * jv[i]) as f64;
                total += copies * vol * b / slab;
                if let Some(s) = seed.as_mut() {
                    s.xg[i].x += (copies * vol * db / (slab * slab)) as Real * self.scale;
                    s.j[i] += (copies * vol0[i] as f64 * b / slab) as Real;
                    s.vol0[i] += (copies * jv[i] as f64 * b / slab) as Real;
                }
            }
        }
        total
    }

    /// [`Objective::SmoothWidth`] (`width`) or [`Objective::SmoothHeight`]: the section's
    /// samples (`smooth_extent::Sample`: the particle's y or z, and its area in the section, its
    /// volume spread in x as `area`'s), their edges, and the edges' adjoints carried back to the
    /// particles' positions, volume ratios and initial volumes.
    fn smooth_extent(&self, what: &Objective, station: f64, width: bool, seed: Option<Seed>) -> Result<f64, GradError> {
        use super::smooth_extent::{edge, edge_adjoint, Sample, Side};
        let (frame, h) = (self.frame, self.frame.spacing);
        let p = &self.sim.particles;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        // (particle, sign of d c / d its coordinate, B, dB/du) of each sample
        let mut whose: Vec<(usize, f64, f64, f64)> = Vec::new();
        let mut samples: Vec<Sample> = Vec::new();
        for i in 0..p.n {
            let x = self.world(i);
            let u = (x[0] - station) / frame.slab;
            if u.abs() >= 1.5 {
                continue;
            }
            let (b, db) = crate::observe::quadratic_bspline_and_slope(u);
            let a = (vol0[i] * jv[i]) as f64 * b / frame.slab;
            let images: &[f64] = if frame.mirror_y.is_some() { &[1.0, -1.0] } else { &[1.0] };
            for &sign in images {
                let c = if width { section_y(frame, x[1], sign) } else { x[2] };
                samples.push(Sample { c, a });
                whose.push((i, if width { sign } else { 1.0 }, b, db));
            }
        }
        let fail = |why: &str| GradError::Objective(format!("objective {}: {why} at x = {station} m", what.name()));
        let upper = edge(&samples, h, Side::Upper).ok_or_else(|| fail("no section reaches half a spacing of material"))?;
        let lower = match (width, frame.mirror_y) {
            (true, None) => Some(edge(&samples, h, Side::Lower).ok_or_else(|| fail("no section reaches half a spacing of material"))?),
            _ => None,
        };
        let value = match (width, frame.mirror_y, lower) {
            (false, _, _) => upper - frame.base_z,
            (true, Some(y0), _) => 2.0 * (upper - y0),
            (true, None, Some(lower)) => upper - lower,
            (true, None, None) => unreachable!("the lower edge is taken without a mirror"),
        };
        if let Some(s) = seed {
            let (mut d_c, mut d_a) = (vec![0.0; samples.len()], vec![0.0; samples.len()]);
            let tangent = || fail("the profile touches the level without crossing it (no derivative)");
            let upper_weight = if width && frame.mirror_y.is_some() { 2.0 } else { 1.0 };
            edge_adjoint(&samples, h, upper, upper_weight, &mut d_c, &mut d_a).ok_or_else(tangent)?;
            if let Some(lower) = lower {
                edge_adjoint(&samples, h, lower, -1.0, &mut d_c, &mut d_a).ok_or_else(tangent)?;
            }
            for (k, &(i, sign, b, db)) in whose.iter().enumerate() {
                let coordinate = (d_c[k] * sign) as Real * self.scale;
                if width {
                    s.xg[i].y += coordinate;
                } else {
                    s.xg[i].z += coordinate;
                }
                let vol = (vol0[i] * jv[i]) as f64;
                s.xg[i].x += (d_a[k] * vol * db / (frame.slab * frame.slab)) as Real * self.scale;
                s.j[i] += (d_a[k] * vol0[i] as f64 * b / frame.slab) as Real;
                s.vol0[i] += (d_a[k] * jv[i] as f64 * b / frame.slab) as Real;
            }
        }
        Ok(value)
    }

    fn profile(&self, what: &Objective, station: f64, y: f64, seed: Option<Seed>) -> Result<f64, GradError> {
        let frame = self.frame;
        let h = frame.spacing;
        let pts = section_points(self.sim, frame, station).ok_or_else(|| GradError::Objective(format!("objective {}: no particle within half a slab of x = {station} m", what.name())))?;
        let py = |pt: &(usize, f64)| section_y(frame, self.world(pt.0)[1], pt.1);
        // the bins' origin: the lowest y (first on ties), and each bin's top particle
        let o = pts.iter().enumerate().fold(0, |b, (k, pt)| if py(pt) < py(&pts[b]) { k } else { b });
        let origin = py(&pts[o]);
        let mut tops: std::collections::BTreeMap<i64, (f64, usize)> = std::collections::BTreeMap::new();
        for pt in &pts {
            let top = self.world(pt.0)[2] + 0.5 * h;
            let e = tops.entry(crate::observe::bin(py(pt), origin, h)).or_insert((top, pt.0));
            if top > e.0 {
                *e = (top, pt.0);
            }
        }
        let u = (y - origin) / h;
        let k0 = u.floor();
        let t = u - k0;
        let k0 = k0 as i64;
        // (weight, particle) of the tops the point interpolates, and d value / d origin
        let (terms, d_origin): (Vec<(f64, usize)>, f64) = match (tops.get(&k0), tops.get(&(k0 + 1))) {
            (Some(&(a, ia)), Some(&(b, ib))) => (vec![(1.0 - t, ia), (t, ib)], -(b - a) / h),
            (Some(&(_, ia)), None) if t <= 0.5 => (vec![(1.0, ia)], 0.0),
            (None, Some(&(_, ib))) if t >= 0.5 => (vec![(1.0, ib)], 0.0),
            _ => (Vec::new(), 0.0),
        };
        let value = if terms.is_empty() { 0.0 } else { terms.iter().map(|&(w, i)| w * (self.world(i)[2] + 0.5 * h)).sum::<f64>() - frame.base_z };
        if let Some(s) = seed {
            for &(w, i) in &terms {
                s.xg[i].z += w as Real * self.scale;
            }
            let (io, sign) = pts[o];
            s.xg[io].y += (sign * d_origin) as Real * self.scale;
        }
        Ok(value)
    }

    /// A printed layer's thickness (`height`) or width at a station.
    fn layer(&self, what: &Objective, station: f64, layer: usize, height: bool, seed: Option<Seed>) -> Result<f64, GradError> {
        let frame = self.frame;
        let tops = layer_tops(self.sim).ok_or_else(|| GradError::Objective(format!("objective {}: the scenario prints no layers whose heights ascend (the toolpath's layer z, as layers.csv takes them)", what.name())))?;
        if layer == 0 || layer > tops.len() {
            return Err(GradError::Objective(format!("objective {}: layer {layer} is not one of the toolpath's layers 1..={}", what.name(), tops.len())));
        }
        let pts = section_points(self.sim, frame, station).ok_or_else(|| GradError::Objective(format!("objective {}: no particle within half a slab of x = {station} m", what.name())))?;
        let k = layer - 1;
        let layer_of = |pt: &(usize, f64)| crate::observe::layer_of(&tops, self.world(pt.0)[2]);
        let mine: Vec<(usize, f64)> = pts.iter().copied().filter(|pt| layer_of(pt) == k).collect();
        if mine.is_empty() {
            return Ok(0.0);
        }
        if height {
            // each layer's top particle in the slab (the first on ties; the mirror images,
            // listed after the originals, add nothing in z), then this layer's and the
            // nearest non-empty one's below it
            let mut top: Vec<Option<usize>> = vec![None; k + 1];
            for pt in &pts {
                let l = layer_of(pt);
                if l <= k && top[l].is_none_or(|b| self.world(pt.0)[2] > self.world(b)[2]) {
                    top[l] = Some(pt.0);
                }
            }
            let it = top[k].expect("the layer has particles");
            let below = top[..k].iter().rev().find_map(|&t| t);
            let value = self.world(it)[2] + 0.5 * frame.spacing - below.map_or(frame.base_z, |ib| self.world(ib)[2] + 0.5 * frame.spacing);
            if let Some(s) = seed {
                s.xg[it].z += self.scale;
                if let Some(ib) = below {
                    s.xg[ib].z -= self.scale;
                }
            }
            Ok(value)
        } else {
            let py = |pt: &(usize, f64)| section_y(frame, self.world(pt.0)[1], pt.1);
            let hi = mine.iter().fold(mine[0], |b, pt| if py(pt) > py(&b) { *pt } else { b });
            let lo = mine.iter().fold(mine[0], |b, pt| if py(pt) < py(&b) { *pt } else { b });
            if let Some(s) = seed {
                s.xg[hi.0].y += hi.1 as Real * self.scale;
                s.xg[lo.0].y -= lo.1 as Real * self.scale;
            }
            Ok(py(&hi) - py(&lo) + frame.spacing)
        }
    }

    fn total_height(&self, seed: Option<Seed>) -> Result<f64, GradError> {
        let top = arg_max(self.n(), |_| true, |i| self.world(i)[2]).ok_or_else(|| GradError::Objective("objective total_height: no particles".into()))?;
        if let Some(s) = seed {
            s.xg[top].z += self.scale;
        }
        Ok(self.world(top)[2] + 0.5 * self.frame.spacing - self.frame.base_z)
    }

    fn front(&self, seed: Option<Seed>) -> Result<f64, GradError> {
        let lead = arg_max(self.n(), |_| true, |i| self.world(i)[0]).ok_or_else(|| GradError::Objective("objective front: no particles".into()))?;
        if let Some(s) = seed {
            s.xg[lead].x += self.scale;
        }
        Ok(self.world(lead)[0] + 0.5 * self.frame.spacing)
    }

    fn vx_max(&self, seed: Option<Seed>) -> Result<f64, GradError> {
        let v = self.sim.particles.v.as_slice();
        let i = arg_max(self.n(), |_| true, |i| v[i].x as f64).ok_or_else(|| GradError::Objective("objective vx_max: no particles".into()))?;
        if let Some(s) = seed {
            s.v[i].x += 1.0;
        }
        Ok(v[i].x as f64)
    }

    fn kinetic_energy(&self, seed: Option<Seed>) -> f64 {
        let p = &self.sim.particles;
        let (v, m) = (p.v.as_slice(), p.mass.as_slice());
        let value = (0..p.n).map(|i| 0.5 * (m[i] * v[i].length_squared()) as f64).sum();
        if let Some(s) = seed {
            for i in 0..p.n {
                s.v[i] += v[i] * m[i];
                s.mass[i] += 0.5 * v[i].length_squared();
            }
        }
        value
    }

    fn mean_z(&self, seed: Option<Seed>) -> Result<f64, GradError> {
        let p = &self.sim.particles;
        let base_z = self.frame.base_z;
        let (vol0, jv) = (p.vol0.as_slice(), p.j.as_slice());
        let w: f64 = (0..p.n).map(|i| (vol0[i] * jv[i]) as f64).sum();
        if w <= 0.0 {
            return Err(GradError::Objective("objective mean_z: no particles".into()));
        }
        let wz: f64 = (0..p.n).map(|i| (vol0[i] * jv[i]) as f64 * (self.world(i)[2] - base_z)).sum();
        let value = wz / w;
        if let Some(s) = seed {
            for i in 0..p.n {
                let vi = (vol0[i] * jv[i]) as f64;
                s.xg[i].z += (vi / w) as Real * self.scale;
                s.j[i] += (vol0[i] as f64 * ((self.world(i)[2] - base_z) - value) / w) as Real;
                s.vol0[i] += (jv[i] as f64 * ((self.world(i)[2] - base_z) - value) / w) as Real;
            }
        }
        Ok(value)
    }
}

/// The particles of the cross-section slab |x - station| <= slab / 2 as the reporter's cloud
/// holds them: (index, +1) for each, and with `mirror_y` also (index, -1) for its mirror image
/// (y -> 2 y0 - y). None if the slab is empty.
fn section_points(sim: &Simulation, frame: &Frame, station: f64) -> Option<Vec<(usize, f64)>> {
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
fn section_y(frame: &Frame, y: f64, sign: f64) -> f64 {
    sign * y + if sign < 0.0 { 2.0 * frame.mirror_y.unwrap_or(0.0) } else { 0.0 }
}

/// The nominal layer tops `layers.csv` assigns particles by: the z of each of the toolpath's
/// layers; None without a print or when they do not ascend.
fn layer_tops(sim: &Simulation) -> Option<Vec<f64>> {
    let tops: Vec<f64> = sim.printer.as_ref()?.toolpath.layers().iter().map(|l| l.0).collect();
    crate::observe::valid_layer_tops(&tops).then_some(tops)
}

fn join(stations: &[f64]) -> String {
    stations.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::{self, Cloud};
    use crate::scenario::Scenario;

    /// The two-layer print of the gradient tests, its y >= 0 half observed with the mirror image
    /// (`half`) or whole, at three stations.
    fn two_layers(half: bool) -> String {
        let text = include_str!("../../fixtures/scenarios/grad/two_layers.toml").replace("stations = [0.015]", "stations = [0.006, 0.015, 0.024]");
        if half {
            return text;
        }
        text.replace("min = [-0.02, 0.0, 0.0]", "min = [-0.02, -0.04, 0.0]").replace("y_min = \"symmetry\"\n", "").replace("mirror_y = 0.0\n", "")
    }

    fn run(text: &str) -> (Scenario, Simulation) {
        let sc = Scenario::parse(text).unwrap();
        let mut sim = Simulation::new(&sc).unwrap();
        let end = sc.simulation.end_time;
        while sim.time < end * (1.0 - 1e-12) {
            sim.step_until(end).unwrap();
        }
        (sc, sim)
    }

    /// The reporter's cloud: positions and volumes, with the mirror images under `mirror_y`.
    fn cloud_of(sim: &Simulation, mirror_y: Option<f64>) -> (Vec<[f64; 3]>, Vec<f64>) {
        let p = &sim.particles;
        let mut pos: Vec<[f64; 3]> = (0..p.n).map(|i| sim.position(i)).collect();
        let mut vol: Vec<f64> = (0..p.n).map(|i| (p.vol0.as_slice()[i] * p.j.as_slice()[i]) as f64).collect();
        if let Some(y0) = mirror_y {
            for i in 0..p.n {
                pos.push([pos[i][0], 2.0 * y0 - pos[i][1], pos[i][2]]);
                vol.push(vol[i]);
            }
        }
        (pos, vol)
    }

    fn value(sim: &Simulation, frame: &Frame, name: &str) -> f64 {
        name.parse::<Objective>().unwrap().evaluate(sim, frame, None).unwrap()
    }

    /// The smooth width and height: near the extreme-based ones, the same for the half model with
    /// its mirror image as for the whole, and their seeds those of central differences in each
    /// particle's position, volume ratio and initial volume.
    #[test]
    fn smooth_width_and_height_are_near_the_extremes_and_their_seeds_are_their_derivatives() {
        let mut whole = Vec::new();
        for half in [false, true] {
            let (_, mut sim) = run(&two_layers(half));
            let frame = Frame::of(&sim);
            let x = 0.015;
            let mut got = Vec::new();
            for (smooth, extreme) in [("smooth_width", "width"), ("smooth_height", "height")] {
                let name = format!("{smooth}@{x}");
                let (v, e) = (value(&sim, &frame, &name), value(&sim, &frame, &format!("{extreme}@{x}")));
                assert!((v - e).abs() <= 2.0 * frame.spacing, "half {half}: {name} {v} against {extreme} {e}");
                got.push(v);
                let n = sim.particles.n;
                let (mut xg, mut vel, mut j, mut mass, mut vol0) = (vec![V3::ZERO; n], vec![V3::ZERO; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                let obj: Objective = name.parse().unwrap();
                let seed = Seed { xg: &mut xg, v: &mut vel, j: &mut j, mass: &mut mass, vol0: &mut vol0 };
                obj.evaluate(&sim, &frame, Some(seed)).unwrap();
                // the particles the edges hang on most, in each coordinate, and in J and V0
                let heaviest = |g: &dyn Fn(usize) -> f64| (0..n).max_by(|&a, &b| g(a).abs().total_cmp(&g(b).abs())).unwrap();
                let mut checked = 0;
                for which in 0..5 {
                    let g = |i: usize| match which { 0 => xg[i].x, 1 => xg[i].y, 2 => xg[i].z, 3 => j[i], _ => vol0[i] } as f64;
                    let i = heaviest(&g);
                    if g(i) == 0.0 {
                        continue;
                    }
                    let eps = 1e-6;
                    let scale = if which == 4 { sim.particles.vol0.as_slice()[i] as f64 } else { 1.0 };
                    let mut at = |e: f64| {
                        let p = &mut sim.particles;
                        match which {
                            0 => p.xg.as_mut_slice()[i].x += e as Real,
                            1 => p.xg.as_mut_slice()[i].y += e as Real,
                            2 => p.xg.as_mut_slice()[i].z += e as Real,
                            3 => p.j.as_mut_slice()[i] += e as Real,
                            _ => p.vol0.as_mut_slice()[i] += e as Real,
                        }
                        value(&sim, &frame, &name)
                    };
                    let (up, down) = (at(eps * scale), at(-2.0 * eps * scale));
                    at(eps * scale);
                    let fd = (up - down) / (2.0 * eps * scale);
                    assert!((fd - g(i)).abs() <= 1e-4 * g(i).abs(), "half {half}, {name}, particle {i}, derivative {which}: seed {:e}, central differences {fd:e}", g(i));
                    checked += 1;
                }
                assert!(checked >= 4, "half {half}, {name}: {checked} derivatives seeded");
            }
            whole.push(got);
        }
        for k in 0..2 {
            assert!((whole[0][k] - whole[1][k]).abs() <= 0.05 * whole[0][k], "whole {:?} against half {:?}", whole[0], whole[1]);
        }
    }

    #[test]
    fn profile_points_and_layer_heights_and_widths_are_the_reporters_observables() {
        for half in [true, false] {
            let (sc, sim) = run(&two_layers(half));
            let frame = Frame::of(&sim);
            assert_eq!(frame.mirror_y, half.then_some(0.0));
            let mut reporter = crate::report::Reporter::new(&sc, &sim).unwrap().unwrap();
            let o = reporter.observe(&sim).clone();
            let (pos, vol) = cloud_of(&sim, frame.mirror_y);
            let cloud = Cloud { pos: &pos, vol: &vol, spacing: frame.spacing };
            let tops: Vec<f64> = sim.printer.as_ref().unwrap().toolpath.layers().iter().map(|l| l.0).collect();
            assert_eq!(tops, [0.006, 0.012]);
            let mut interpolated = 0;
            for (k, section) in o.sections.iter().enumerate() {
                let x = section.station;
                let (first, last) = (section.profile[0][0], section.profile.last().unwrap()[0]);
                // across the section and 3 mm beyond, off the bin edges (where the outline is vertical)
                for j in 0..=200 {
                    let y = first - 0.003 + (last - first + 0.006) * (j as f64 + 0.37) / 200.0;
                    let want = observe::profile_z_at(&section.profile, y).map_or(0.0, |z| z - frame.base_z);
                    let got = value(&sim, &frame, &format!("profile@{x}:{y}"));
                    assert!((got - want).abs() <= 1e-12, "half {half}, profile@{x}:{y}: {got} against the reporter's outline {want}");
                    interpolated += usize::from(got > 0.0 && section.profile.iter().all(|p| p[0] != y));
                }
                let widths = observe::layer_widths(&cloud, x, frame.slab, &tops);
                assert_eq!(o.layers[k].len(), 2);
                for layer in 1..=2 {
                    let got = value(&sim, &frame, &format!("layer_height@{x}:{layer}"));
                    assert!((got - o.layers[k][layer - 1]).abs() <= 1e-12, "half {half}, layer_height@{x}:{layer}: {got} against {:?}", o.layers[k]);
                    let got = value(&sim, &frame, &format!("layer_width@{x}:{layer}"));
                    assert!((got - widths[layer - 1]).abs() <= 1e-12, "half {half}, layer_width@{x}:{layer}: {got} against {widths:?}");
                    assert!(widths[layer - 1] > 0.0 && o.layers[k][layer - 1] > 0.0);
                }
                // the layers add up to the section's height, and the widest layer is the section's width
                assert!((o.layers[k].iter().sum::<f64>() - section.height).abs() <= 1e-12, "{:?} against {}", o.layers[k], section.height);
                assert!((widths.iter().cloned().fold(0.0, f64::max) - section.width).abs() <= 1e-12, "{widths:?} against {}", section.width);
            }
            assert!(interpolated > 100, "{interpolated} points between outline vertices");
            // no such layer, no material
            let e = "layer_height@0.015:3".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string();
            assert!(e.contains("layer 3") && e.contains("1..=2"), "{e}");
            let e = "profile@0.05:0".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string();
            assert!(e.contains("no particle"), "{e}");
        }
    }

    #[test]
    fn the_profile_drops_to_the_base_between_filaments_and_beside_them() {
        // two boxes of 2 x 5 x 4 and 2 x 2 x 2 particles (10 mm cells, 2 per cell), 15 mm apart
        let text = r#"
name = "two-boxes"
[simulation]
dx = 0.01
end_time = 0.1
[domain]
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 1e5
viscosity = 1.0
[[body]]
shape = "box"
min = [0.02, 0.02, 0.0]
max = [0.03, 0.045, 0.02]
[[body]]
shape = "box"
min = [0.02, 0.06, 0.0]
max = [0.03, 0.07, 0.01]
[memory]
budget = "16 MiB"
"#;
        let sc = Scenario::parse(text).unwrap();
        let sim = Simulation::new(&sc).unwrap();
        let frame = Frame::of(&sim);
        let (pos, vol) = cloud_of(&sim, None);
        let cloud = Cloud { pos: &pos, vol: &vol, spacing: frame.spacing };
        let section = observe::cross_section(&cloud, 0.025, frame.slab, frame.base_z);
        assert_eq!(section.profile.len(), 5 + 2 + 8, "{:?}", section.profile);
        // the level is the height where there is material, 0 where there is none
        let top = section.height;
        assert!((value(&sim, &frame, "level@0.025") - top).abs() <= 1e-12 && (value(&sim, &frame, "height@0.025") - top).abs() <= 1e-12);
        assert_eq!(value(&sim, &frame, "level@0.08"), 0.0);
        assert!("height@0.08".parse::<Objective>().unwrap().evaluate(&sim, &frame, None).unwrap_err().to_string().contains("no particle"));
        assert_eq!("level@0.025".parse::<Objective>().unwrap().name(), "level@0.025");
        assert!("level@0.02,0.03".parse::<Objective>().unwrap_err().to_string().contains("one station"));
        for j in 0..100 {
            let y = 0.01 + 0.07 * (j as f64 + 0.5) / 100.0;
            let want = observe::profile_z_at(&section.profile, y).map_or(0.0, |z| z - frame.base_z);
            let got = value(&sim, &frame, &format!("profile@0.025:{y}"));
            assert!((got - want).abs() <= 1e-12, "y = {y}: {got} against {want}");
            let expect = if (0.02..=0.045).contains(&y) {
                0.02
            } else if (0.06..=0.07).contains(&y) {
                0.01
            } else {
                0.0
            };
            assert!((got - expect).abs() <= 1e-9, "y = {y}: {got}, a box top of {expect}");
        }
    }

    #[test]
    fn names_parse_and_print_back_and_bad_ones_say_what_they_take() {
        for name in ["profile@0.075:0.01", "profile@0.075:-0.002", "layer_height@0.075:2", "layer_width@0.03:1", "smooth_width@0.04", "smooth_height@0.04"] {
            let o: Objective = name.parse().unwrap();
            assert_eq!(o.name(), name);
            assert_eq!(o.name().parse::<Objective>().unwrap(), o);
        }
        assert_eq!("profile@0.075:0.01".parse::<Objective>().unwrap(), Objective::Profile { station: 0.075, y: 0.01 });
        assert_eq!(" layer_height@0.075: 3".trim().parse::<Objective>().unwrap(), Objective::LayerHeight { station: 0.075, layer: 3 });
        for (bad, want) in [
            ("profile@0.075", "profile takes X:Y"),
            ("profile@0.075:", "profile takes X:Y"),
            ("profile@a:0.01", "profile takes X:Y"),
            ("profile@0.075:0.01:0.02", "profile takes X:Y"),
            ("profile@0.075:inf", "profile takes X:Y"),
            ("layer_height@0.075", "layer_height takes X:K"),
            ("layer_height@0.075:0", "layer K (1 = the bottom one)"),
            ("layer_height@0.075:1.5", "layer_height takes X:K"),
            ("layer_width@0.075:-1", "layer_width takes X:K"),
            ("smooth_width@0.04,0.05", "smooth_width takes one station"),
            ("smooth_height@x", "stations after '@' must be numbers"),
            ("profile", "unknown objective 'profile'"),
        ] {
            let e = bad.parse::<Objective>().unwrap_err().to_string();
            assert!(e.contains(want) && e.contains(bad), "{bad}: {e}");
        }
        for name in ["profile@X:Y", "layer_height@X:K", "layer_width@X:K"] {
            assert!(NAMES.contains(name), "{NAMES}");
        }
    }
}
