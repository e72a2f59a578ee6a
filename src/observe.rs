//! Observables: functions of the particle state at one time.
//!
//! Everything here is a pure function of particle positions (world coordinates, metres)
//! and current particle volumes (m^3, `vol0 * J`); there is no I/O except the small CSV
//! helpers at the end. Axes: z is up, x is the printing direction, cross-sections lie in
//! the y-z plane.
//!
//! A particle stands for a cube of side `spacing`, so extents add one `spacing` (half on
//! each side) to the spread of particle centres. Particles whose position is not finite
//! are ignored everywhere, so one diverged particle does not poison a whole observable.
//! A cloud whose `spacing` is not a positive finite number is treated as empty.

use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Particles as the observables see them.
///
/// `pos` and `vol` are read pairwise; if their lengths differ, the extra entries of the
/// longer one are ignored.
pub struct Cloud<'a> {
    /// Particle positions in metres.
    pub pos: &'a [[f64; 3]],
    /// Current particle volumes in m^3 (`vol0 * J`).
    pub vol: &'a [f64],
    /// Particle spacing h = dx / particles_per_cell_axis; a particle stands for a cube of side h.
    pub spacing: f64,
}

impl Cloud<'_> {
    /// Particles with a finite position, paired with their volume; empty if `spacing` is unusable.
    fn particles(&self) -> impl Iterator<Item = ([f64; 3], f64)> + '_ {
        let usable = self.spacing.is_finite() && self.spacing > 0.0;
        let n = if usable {
            self.pos.len().min(self.vol.len())
        } else {
            0
        };
        self.pos[..n]
            .iter()
            .zip(&self.vol[..n])
            .filter(|(p, _)| p.iter().all(|v| v.is_finite()))
            .map(|(p, v)| (*p, *v))
    }

    /// Particles in the slab `|x - station| <= slab / 2`; none if `slab` is not positive.
    fn slab(&self, station: f64, slab: f64) -> impl Iterator<Item = ([f64; 3], f64)> + '_ {
        let half = if slab > 0.0 {
            slab / 2.0
        } else {
            f64::NEG_INFINITY
        };
        self.particles()
            .filter(move |(p, _)| (p[0] - station).abs() <= half)
    }
}

/// Index of the bin of width `h` that holds `v`, with bins centred on `origin + k h`.
///
/// Centring on a particle coordinate (the minimum) puts every column of an undeformed
/// lattice at a bin centre, whatever the lattice offset, so no column is split or merged.
pub(crate) fn bin(v: f64, origin: f64, h: f64) -> i64 {
    // `as` saturates, so a far outlier lands in an extreme bin instead of panicking.
    ((v - origin) / h).round() as i64
}

/// A y-z cross-section of the deposit through a slab of particles around `x = station`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CrossSection {
    /// x of the section.
    pub station: f64,
    /// Slab thickness used: particles with `|x - station| <= slab / 2`.
    pub slab: f64,
    /// Number of particles in the slab.
    pub particles: usize,
    /// Outline of the top surface as a polyline in (y, z), ordered by y (non-decreasing).
    ///
    /// The slab's particles are put in y bins of width `spacing` centred on
    /// `min y + k * spacing`. Each occupied bin contributes its top point
    /// `(bin centre, max z + spacing / 2)`. Every run of adjacent occupied bins is closed
    /// down to `base_z` with vertical edges at the particle extent: it starts with
    /// `(first centre - spacing / 2, base_z)`, `(first centre - spacing / 2, first top)` and
    /// ends with `(last centre + spacing / 2, last top)`, `(last centre + spacing / 2, base_z)`.
    /// A gap of empty bins (two filaments side by side) therefore drops to `base_z` instead
    /// of bridging across. Empty if the slab holds no particles.
    pub profile: Vec<[f64; 2]>,
    /// Particle extent in y: `max y - min y + spacing`; 0 if empty.
    pub width: f64,
    /// `max z + spacing / 2 - base_z`; 0 if empty.
    pub height: f64,
    /// Material area: particle volumes summed with a quadratic B-spline window in x (knot
    /// spacing `slab`, support `|x - station| < 1.5 slab`, unit integral over x), i.e.
    /// `sum vol N((x - station) / slab) / slab`.
    ///
    /// Consistent with the mass balance. A plain box of width `slab` would count 2 or 3 rows
    /// of particles where 2.2 are due (a +-20 % error on a printed strand, whose rows lie
    /// V h / U apart); the B-spline window integrates rows of any spacing s < slab to within
    /// sinc^3(pi slab / s), about 1e-3 at s = 0.45 slab.
    pub area: f64,
    /// Geometric area under the `profile` polyline and above `base_z`.
    pub profile_area: f64,
    /// Volume-weighted mean y of the slab's particles (plain mean if their volumes sum to
    /// zero); 0 if empty.
    pub y_center: f64,
}

impl CrossSection {
    fn empty(station: f64, slab: f64) -> Self {
        CrossSection {
            station,
            slab,
            particles: 0,
            profile: Vec::new(),
            width: 0.0,
            height: 0.0,
            area: 0.0,
            profile_area: 0.0,
            y_center: 0.0,
        }
    }

    /// One CSV line (no newline) matching [`SECTION_CSV_HEADER`].
    ///
    /// Numbers use Rust's shortest round-trip format, so reading them back is exact.
    pub fn csv_row(&self, time: f64) -> String {
        format!(
            "{},{},{},{},{},{},{},{}",
            time,
            self.station,
            self.particles,
            self.width,
            self.height,
            self.area,
            self.profile_area,
            self.y_center
        )
    }
}

/// Header line (no newline) for [`CrossSection::csv_row`].
pub const SECTION_CSV_HEADER: &str =
    "time,station,particles,width,height,area,profile_area,y_center";

/// The cross-section through the slab of particles with `|x - station| <= slab / 2`.
///
/// Heights are measured from `base_z` (the print bed). A non-positive or NaN `slab` selects
/// no particles; an empty section has all measures 0 and an empty profile.
pub fn cross_section(c: &Cloud, station: f64, slab: f64, base_z: f64) -> CrossSection {
    let h = c.spacing;
    let parts: Vec<([f64; 3], f64)> = c.slab(station, slab).collect();
    if parts.is_empty() {
        return CrossSection::empty(station, slab);
    }

    let mut y_min = f64::INFINITY;
    let mut y_max = f64::NEG_INFINITY;
    let mut z_max = f64::NEG_INFINITY;
    let (mut vol_sum, mut vy_sum, mut y_sum) = (0.0, 0.0, 0.0);
    for (p, v) in &parts {
        y_min = y_min.min(p[1]);
        y_max = y_max.max(p[1]);
        z_max = z_max.max(p[2]);
        vol_sum += v;
        vy_sum += v * p[1];
        y_sum += p[1];
    }
    let y_center = if vol_sum != 0.0 {
        vy_sum / vol_sum
    } else {
        y_sum / parts.len() as f64
    };

    // Top of each occupied y bin; the BTreeMap keeps bins ordered by y.
    let area = c
        .particles()
        .map(|(p, v)| v * quadratic_bspline((p[0] - station) / slab))
        .sum::<f64>()
        / slab;

    let mut tops: BTreeMap<i64, f64> = BTreeMap::new();
    for (p, _) in &parts {
        let top = tops.entry(bin(p[1], y_min, h)).or_insert(f64::NEG_INFINITY);
        *top = top.max(p[2] + h / 2.0);
    }
    let profile = profile_polyline(&tops, y_min, h, base_z);

    CrossSection {
        station,
        slab,
        particles: parts.len(),
        width: y_max - y_min + h,
        height: z_max + h / 2.0 - base_z,
        area,
        profile_area: area_under(&profile, base_z),
        y_center,
        profile,
    }
}

/// The quadratic B-spline of unit knot spacing centred at 0 (support |x| < 1.5, unit integral).
fn quadratic_bspline(x: f64) -> f64 {
    quadratic_bspline_and_slope(x).0
}

/// [`quadratic_bspline`] and its derivative (for the area objective's adjoint).
pub(crate) fn quadratic_bspline_and_slope(x: f64) -> (f64, f64) {
    let a = x.abs();
    if a < 0.5 {
        (0.75 - a * a, -2.0 * x)
    } else if a < 1.5 {
        (0.5 * (1.5 - a) * (1.5 - a), -(1.5 - a) * x.signum())
    } else {
        (0.0, 0.0)
    }
}

/// The closed-run polyline described on [`CrossSection::profile`].
fn profile_polyline(tops: &BTreeMap<i64, f64>, origin: f64, h: f64, base_z: f64) -> Vec<[f64; 2]> {
    let centre = |k: i64| origin + k as f64 * h;
    let mut out = Vec::with_capacity(tops.len() + 4);
    let mut prev: Option<(i64, f64)> = None;
    for (&k, &top) in tops {
        let new_run = prev.is_none_or(|(pk, _)| k != pk + 1);
        if new_run {
            if let Some((pk, ptop)) = prev {
                close_right(&mut out, centre(pk) + h / 2.0, ptop, base_z);
            }
            let left = centre(k) - h / 2.0;
            out.push([left, base_z]);
            out.push([left, top]);
        }
        out.push([centre(k), top]);
        prev = Some((k, top));
    }
    if let Some((pk, ptop)) = prev {
        close_right(&mut out, centre(pk) + h / 2.0, ptop, base_z);
    }
    out
}

fn close_right(out: &mut Vec<[f64; 2]>, right: f64, top: f64, base_z: f64) {
    out.push([right, top]);
    out.push([right, base_z]);
}

/// Trapezoidal integral of `z - base_z` along a polyline ordered by y.
fn area_under(line: &[[f64; 2]], base_z: f64) -> f64 {
    line.windows(2)
        .map(|w| (w[1][0] - w[0][0]) * ((w[0][1] - base_z) + (w[1][1] - base_z)) / 2.0)
        .sum()
}

/// The z of a profile polyline (as [`CrossSection::profile`], ordered by y) at lateral position
/// `y`: linear between its points, the highest where a vertical edge stands at `y` (so the top of
/// a run's end column counts up to its edge). None for an empty profile or a `y` outside it.
pub fn profile_z_at(profile: &[[f64; 2]], y: f64) -> Option<f64> {
    let mut best: Option<f64> = None;
    for w in profile.windows(2) {
        let ([y0, z0], [y1, z1]) = (w[0], w[1]);
        if !(y0 <= y && y <= y1) {
            continue;
        }
        let z = if y1 > y0 { z0 + (z1 - z0) * (y - y0) / (y1 - y0) } else { z0.max(z1) };
        best = Some(best.map_or(z, |b: f64| b.max(z)));
    }
    best
}

/// Height of the whole deposit: `max z + spacing / 2 - base_z`; 0 for an empty cloud.
pub fn total_height(c: &Cloud, base_z: f64) -> f64 {
    c.particles()
        .map(|(p, _)| p[2])
        .fold(None, |m: Option<f64>, z| Some(m.map_or(z, |m| m.max(z))))
        .map_or(0.0, |z| z + c.spacing / 2.0 - base_z)
}

/// Thickness of each printed layer in the slab `|x - station| <= slab / 2`.
///
/// `layer_tops[k]` is the nominal z of layer k's top (the nozzle outlet height while it was
/// printed), strictly ascending. Positions alone do not say which layer a particle came
/// from, so particles are assigned by their z against the nominal tops:
///
/// - layer 0 takes `z < layer_tops[0]`,
/// - layer k (0 < k < n - 1) takes `layer_tops[k - 1] <= z < layer_tops[k]`,
/// - the last layer takes `z >= layer_tops[n - 2]` (no upper limit, so a bulge above its
///   nominal top still counts).
///
/// The measured top of layer k is `max z + spacing / 2` over its particles, and its
/// thickness is that top minus the measured top of layer k - 1 (`base_z` for layer 0).
/// An empty layer has thickness 0 and passes the top of the layer below on to the next.
///
/// Because the boundaries are nominal, this resolves a layer only while it has settled by
/// less than about one particle spacing below its nominal top: material that sags further
/// is counted in the layer below. Returns an empty Vec if `layer_tops` is empty, not finite
/// or not strictly ascending.
pub fn layer_heights(
    c: &Cloud,
    station: f64,
    slab: f64,
    layer_tops: &[f64],
    base_z: f64,
) -> Vec<f64> {
    if !valid_layer_tops(layer_tops) {
        return Vec::new();
    }
    let n = layer_tops.len();
    let h = c.spacing;
    let mut tops: Vec<Option<f64>> = vec![None; n];
    for (p, _) in c.slab(station, slab) {
        let k = layer_of(layer_tops, p[2]);
        let top = p[2] + h / 2.0;
        tops[k] = Some(tops[k].map_or(top, |t: f64| t.max(top)));
    }
    let mut below = base_z;
    tops.iter()
        .map(|t| match t {
            Some(t) => {
                let thickness = t - below;
                below = *t;
                thickness
            }
            None => 0.0,
        })
        .collect()
}

/// Whether `layer_tops` can assign particles to layers: not empty, finite, strictly ascending.
pub(crate) fn valid_layer_tops(layer_tops: &[f64]) -> bool {
    !layer_tops.is_empty()
        && layer_tops.iter().all(|t| t.is_finite())
        && layer_tops.windows(2).all(|w| w[0] < w[1])
}

/// The layer (0-based) a particle at height `z` is assigned to, as [`layer_heights`] says:
/// the number of nominal tops at or below z, the last layer taking everything above.
pub(crate) fn layer_of(layer_tops: &[f64], z: f64) -> usize {
    layer_tops.partition_point(|&t| t <= z).min(layer_tops.len() - 1)
}

/// Width of each printed layer in the slab `|x - station| <= slab / 2`: the y extent of the
/// particles [`layer_heights`] assigns to it, `max y - min y + spacing`; 0 for an empty layer.
/// Returns an empty Vec where [`layer_heights`] does.
pub fn layer_widths(c: &Cloud, station: f64, slab: f64, layer_tops: &[f64]) -> Vec<f64> {
    if !valid_layer_tops(layer_tops) {
        return Vec::new();
    }
    let mut ext: Vec<Option<(f64, f64)>> = vec![None; layer_tops.len()];
    for (p, _) in c.slab(station, slab) {
        let e = &mut ext[layer_of(layer_tops, p[2])];
        *e = Some(e.map_or((p[1], p[1]), |(lo, hi)| (lo.min(p[1]), hi.max(p[1]))));
    }
    ext.iter()
        .map(|e| e.map_or(0.0, |(lo, hi)| hi - lo + c.spacing))
        .collect()
}

/// The spread of a slump-flow test.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Spread {
    /// Mean of `d_x` and `d_y`.
    pub mean_diameter: f64,
    /// Extent along x: `max x - min x + spacing`.
    pub d_x: f64,
    /// Extent along y: `max y - min y + spacing`.
    pub d_y: f64,
    /// Diameter of the disc with the footprint's area: `sqrt(4 A / pi)`, where A is the
    /// number of occupied x-y cells of side `spacing` times `spacing^2`.
    pub area_diameter: f64,
    /// Centre (x, y) of the extent box the two diameters are measured across.
    pub center: [f64; 2],
}

/// Spread of the particles with `z < base_z + band` (the layer touching the base plate).
///
/// Footprint cells are centred on `(min x + i spacing, min y + j spacing)`, so an
/// undeformed lattice has one particle column per cell. No particle in the band gives
/// all zeros.
pub fn slump_spread(c: &Cloud, base_z: f64, band: f64) -> Spread {
    let h = c.spacing;
    let foot: Vec<[f64; 2]> = c
        .particles()
        .filter(|(p, _)| p[2] < base_z + band)
        .map(|(p, _)| [p[0], p[1]])
        .collect();
    if foot.is_empty() {
        return Spread {
            mean_diameter: 0.0,
            d_x: 0.0,
            d_y: 0.0,
            area_diameter: 0.0,
            center: [0.0; 2],
        };
    }
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in &foot {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let cells: HashSet<(i64, i64)> = foot
        .iter()
        .map(|p| (bin(p[0], lo[0], h), bin(p[1], lo[1], h)))
        .collect();
    let area = cells.len() as f64 * h * h;
    let d_x = hi[0] - lo[0] + h;
    let d_y = hi[1] - lo[1] + h;
    Spread {
        mean_diameter: (d_x + d_y) / 2.0,
        d_x,
        d_y,
        area_diameter: (4.0 * area / std::f64::consts::PI).sqrt(),
        center: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
    }
}

/// Writes section profiles in long format: header `time,station,y,z`, then one row per
/// profile point of each `(time, section)`.
pub fn write_profile_csv(path: &Path, sections: &[(f64, &CrossSection)]) -> std::io::Result<()> {
    let mut text = String::from("time,station,y,z\n");
    for (time, s) in sections {
        for [y, z] in &s.profile {
            // Writing to a String cannot fail.
            let _ = writeln!(text, "{},{},{},{}", time, s.station, y, z);
        }
    }
    let mut f = std::fs::File::create(path)?;
    f.write_all(text.as_bytes())?;
    f.flush()
}

/// Why measured profile points cannot be read: the file, or a line of it (1-based).
#[derive(Debug, thiserror::Error)]
pub enum PointsCsvError {
    #[error("{}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{}: no header `y,z` (file has no data lines)", path.display())]
    NoHeader { path: PathBuf },
    #[error("{}:{line}: {message}", path.display())]
    Line { path: PathBuf, line: usize, message: String },
}

/// Reads measured profile points from a CSV file with header `y,z` (metres).
///
/// Blank lines and lines starting with `#` are skipped anywhere. Every other line after the
/// header must hold exactly two finite numbers. Errors name the file and the 1-based line.
pub fn read_points_csv(path: &Path) -> Result<Vec<[f64; 2]>, PointsCsvError> {
    let text = std::fs::read_to_string(path).map_err(|source| PointsCsvError::Read { path: path.to_path_buf(), source })?;
    let at = |line: usize, message: String| PointsCsvError::Line { path: path.to_path_buf(), line, message };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_start_matches('\u{feff}').trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));

    match lines.next() {
        Some((_, l)) if l.split(',').map(str::trim).eq(["y", "z"]) => {}
        Some((n, l)) => return Err(at(n, format!("expected header `y,z`, found `{l}`"))),
        None => return Err(PointsCsvError::NoHeader { path: path.to_path_buf() }),
    }

    let mut points = Vec::new();
    for (n, l) in lines {
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() != 2 {
            return Err(at(n, format!("expected 2 fields `y,z`, found {}", fields.len())));
        }
        let mut p = [0.0; 2];
        for (slot, (field, axis)) in p.iter_mut().zip(fields.iter().zip(["y", "z"])) {
            *slot = match field.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                _ => {
                    return Err(at(n, format!("{axis} `{field}` is not a finite number")))
                }
            };
        }
        points.push(p);
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const H: f64 = 0.002;
    const BASE: f64 = 0.1;

    /// Lattice of particles at cell centres `(i + 1/2) h` offset by `origin`, kept where `keep` holds.
    fn lattice(
        n: [usize; 3],
        origin: [f64; 3],
        keep: impl Fn([f64; 3]) -> bool,
    ) -> (Vec<[f64; 3]>, Vec<f64>) {
        let mut pos = Vec::new();
        for i in 0..n[0] {
            for j in 0..n[1] {
                for k in 0..n[2] {
                    let p = [
                        origin[0] + (i as f64 + 0.5) * H,
                        origin[1] + (j as f64 + 0.5) * H,
                        origin[2] + (k as f64 + 0.5) * H,
                    ];
                    if keep(p) {
                        pos.push(p);
                    }
                }
            }
        }
        let vol = vec![H * H * H; pos.len()];
        (pos, vol)
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn box_section_is_exact() {
        // 20 x 15 x 10 particles: width 30 mm, height 20 mm, offset in y so y_center is not 0.
        let (pos, vol) = lattice([20, 15, 10], [0.0, -0.01, BASE], |_| true);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        // Station on a particle plane, slab of 3 planes: boundaries at 1.5 h fall between planes.
        let s = cross_section(&c, 10.5 * H, 3.0 * H, BASE);
        assert_eq!(s.particles, 3 * 15 * 10);
        let (w, hgt) = (15.0 * H, 10.0 * H);
        assert!(close(s.width, w, 1e-12), "width {}", s.width);
        assert!(close(s.height, hgt, 1e-12), "height {}", s.height);
        assert!(close(s.area, w * hgt, 1e-12), "area {}", s.area);
        assert!(
            close(s.profile_area, w * hgt, 1e-12),
            "profile_area {}",
            s.profile_area
        );
        assert!(
            close(s.y_center, -0.01 + w / 2.0, 1e-12),
            "y_center {}",
            s.y_center
        );
        assert!(close(total_height(&c, BASE), hgt, 1e-12));
    }

    #[test]
    fn half_disc_area_within_lattice_error() {
        let r = 40.0 * H;
        let (pos, vol) = lattice([12, 80, 40], [0.0, -r, BASE], |p| {
            (p[1] * p[1] + (p[2] - BASE).powi(2)).sqrt() <= r
        });
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = cross_section(&c, 6.0 * H, 3.0 * H, BASE);
        let exact = PI * r * r / 2.0;
        assert!(
            close(s.area, exact, 0.01 * exact),
            "area {} vs {}",
            s.area,
            exact
        );
        assert!(
            close(s.profile_area, exact, 0.01 * exact),
            "profile_area {} vs {}",
            s.profile_area,
            exact
        );
        assert!(close(s.width, 2.0 * r, H), "width {}", s.width);
        assert!(close(s.height, r, H), "height {}", s.height);
        assert!(
            close(s.y_center, 0.0, 1e-9),
            "symmetric section, y_center {}",
            s.y_center
        );
    }

    #[test]
    fn empty_slab_gives_zeros_not_nan() {
        let (pos, vol) = lattice([4, 4, 4], [0.0, 0.0, BASE], |_| true);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        for s in [
            cross_section(&c, 1.0, 3.0 * H, BASE),
            cross_section(&c, 1.5 * H, 0.0, BASE),
            cross_section(&c, 1.5 * H, f64::NAN, BASE),
            cross_section(
                &Cloud {
                    pos: &pos,
                    vol: &vol,
                    spacing: 0.0,
                },
                1.5 * H,
                3.0 * H,
                BASE,
            ),
        ] {
            assert_eq!(s.particles, 0);
            assert!(s.profile.is_empty());
            for v in [s.width, s.height, s.area, s.profile_area, s.y_center] {
                assert_eq!(v, 0.0);
            }
        }
        let none = Cloud {
            pos: &[],
            vol: &[],
            spacing: H,
        };
        assert_eq!(total_height(&none, BASE), 0.0);
        let sp = slump_spread(&none, BASE, H);
        assert_eq!([sp.mean_diameter, sp.area_diameter], [0.0, 0.0]);
    }

    #[test]
    fn non_finite_particles_are_ignored() {
        let (mut pos, mut vol) = lattice([3, 5, 5], [0.0, 0.0, BASE], |_| true);
        pos.push([1.5 * H, f64::NAN, 1.0]);
        vol.push(H * H * H);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = cross_section(&c, 1.5 * H, 3.0 * H, BASE);
        assert_eq!(s.particles, 75);
        assert!(close(s.height, 5.0 * H, 1e-12));
    }

    #[test]
    fn profile_is_ordered_and_closed_with_gaps_dropping_to_base() {
        // Two filaments: y columns 0..5 (5 high) and 8..10 (3 high), gap of columns 5..8.
        let (mut pos, mut vol) = lattice([1, 5, 5], [0.0, 0.0, BASE], |_| true);
        let (p2, v2) = lattice([1, 2, 3], [0.0, 8.0 * H, BASE], |_| true);
        pos.extend(p2);
        vol.extend(v2);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = cross_section(&c, 0.5 * H, H, BASE);
        let p = &s.profile;
        assert!(
            p.windows(2).all(|w| w[0][0] <= w[1][0]),
            "profile not ordered: {p:?}"
        );
        assert_eq!(p.first().unwrap(), &[0.0, BASE]);
        assert!(close(p.last().unwrap()[0], 10.0 * H, 1e-12) && p.last().unwrap()[1] == BASE);
        // 5 + 2 centre points, 4 closure points per run.
        assert_eq!(p.len(), 5 + 2 + 8);
        // The gap is at base level between y = 5h and 8h.
        let at_base: Vec<f64> = p
            .iter()
            .filter(|q| q[1] == BASE)
            .map(|q| q[0] / H)
            .collect();
        let want = [0.0, 5.0, 8.0, 10.0];
        assert!(
            at_base.iter().zip(want).all(|(a, b)| close(*a, b, 1e-9)),
            "{at_base:?}"
        );
        assert!(
            close(s.profile_area, (5.0 * 5.0 + 2.0 * 3.0) * H * H, 1e-12),
            "{}",
            s.profile_area
        );
        assert!(close(s.width, 10.0 * H, 1e-12));
        // read back at any y: the run's tops, the base in the gap, nothing beside the section
        let at = |y: f64| profile_z_at(p, y * H);
        for (y, z) in [(0.3, 5.0), (2.5, 5.0), (4.9, 5.0), (5.0, 5.0), (6.0, 0.0), (8.0, 3.0), (9.7, 3.0)] {
            assert!(close(at(y).unwrap(), BASE + z * H, 1e-12), "y = {y} h: {:?}", at(y));
        }
        assert_eq!((at(-0.1), at(10.1), profile_z_at(&[], 0.0)), (None, None, None));
    }

    #[test]
    fn profile_z_at_is_linear_between_column_tops() {
        let profile = [[0.0, BASE], [0.0, BASE + 2.0 * H], [0.5 * H, BASE + 2.0 * H], [1.5 * H, BASE + 4.0 * H], [2.0 * H, BASE + 4.0 * H], [2.0 * H, BASE]];
        assert!(close(profile_z_at(&profile, 0.75 * H).unwrap(), BASE + 2.5 * H, 1e-12));
        assert!(close(profile_z_at(&profile, 1.25 * H).unwrap(), BASE + 3.5 * H, 1e-12));
        // on a vertical edge, the top
        assert!(close(profile_z_at(&profile, 2.0 * H).unwrap(), BASE + 4.0 * H, 1e-12));
    }

    #[test]
    fn layer_heights_of_three_stacked_layers() {
        // Layers 4, 3 and 5 particles thick, narrowing upward so each one is a distinct box.
        let mut pos = Vec::new();
        let layers = [(4usize, 10usize), (3, 8), (5, 6)];
        let mut z0 = BASE;
        let mut tops = Vec::new();
        for (nz, ny) in layers {
            let (p, _) = lattice([3, ny, nz], [0.0, 0.0, z0], |_| true);
            pos.extend(p);
            z0 += nz as f64 * H;
            tops.push(z0);
        }
        let vol = vec![H * H * H; pos.len()];
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let got = layer_heights(&c, 1.5 * H, 3.0 * H, &tops, BASE);
        assert_eq!(got.len(), 3);
        for (g, (nz, _)) in got.iter().zip(layers) {
            assert!(close(*g, nz as f64 * H, 1e-12), "{got:?}");
        }
        let widths = layer_widths(&c, 1.5 * H, 3.0 * H, &tops);
        for (w, (_, ny)) in widths.iter().zip(layers) {
            assert!(close(*w, ny as f64 * H, 1e-12), "{widths:?}");
        }
        assert!(layer_widths(&c, 1.5 * H, 3.0 * H, &[tops[1], tops[0]]).is_empty());
        // The top layer bulging above its nominal top still counts for it.
        let raised: Vec<f64> = tops.iter().map(|t| t - H).collect();
        let got = layer_heights(&c, 1.5 * H, 3.0 * H, &raised, BASE);
        assert!(close(got[2], 6.0 * H, 1e-12), "{got:?}");
        // Invalid nominal tops give nothing rather than garbage.
        assert!(layer_heights(&c, 1.5 * H, 3.0 * H, &[tops[1], tops[0]], BASE).is_empty());
        // An empty layer reports 0 and the next one is measured from the layer below it.
        let got = layer_heights(
            &c,
            1.5 * H,
            3.0 * H,
            &[tops[0], tops[0] + 0.25 * H, tops[1], tops[2]],
            BASE,
        );
        assert!(
            close(got[1], 0.0, 0.0) && close(got[2], 3.0 * H, 1e-12),
            "{got:?}"
        );
        let widths = layer_widths(&c, 1.5 * H, 3.0 * H, &[tops[0], tops[0] + 0.25 * H, tops[1], tops[2]]);
        assert_eq!(widths.len(), 4);
        assert!(close(widths[1], 0.0, 0.0) && close(widths[2], 8.0 * H, 1e-12), "{widths:?}");
    }

    #[test]
    fn slump_spread_of_lattice_disc() {
        let r = 50.0 * H;
        // Two particle layers of a disc centred at (0.3, -0.2), plus a tall column the band must exclude.
        let (mut pos, _) = lattice([100, 100, 2], [0.3 - r, -0.2 - r, BASE], |p| {
            (p[0] - 0.3).hypot(p[1] + 0.2) <= r
        });
        pos.push([0.3 + 2.0 * r, -0.2, BASE + 10.0 * H]);
        let vol = vec![H * H * H; pos.len()];
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = slump_spread(&c, BASE, 3.0 * H);
        for d in [s.d_x, s.d_y, s.mean_diameter] {
            assert!(close(d, 2.0 * r, H), "diameter {d} vs {}", 2.0 * r);
        }
        assert!(
            close(s.area_diameter, 2.0 * r, 0.01 * 2.0 * r),
            "area_diameter {}",
            s.area_diameter
        );
        assert!(
            close(s.center[0], 0.3, 1e-9) && close(s.center[1], -0.2, 1e-9),
            "{:?}",
            s.center
        );
    }

    #[test]
    fn csv_row_matches_header_and_round_trips() {
        let (pos, vol) = lattice([3, 4, 5], [0.0, 0.0, BASE], |_| true);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = cross_section(&c, 1.5 * H, 3.0 * H, BASE);
        let row = s.csv_row(0.25);
        assert_eq!(
            row.split(',').count(),
            SECTION_CSV_HEADER.split(',').count()
        );
        let v: Vec<f64> = row.split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(
            v,
            [
                0.25,
                s.station,
                60.0,
                s.width,
                s.height,
                s.area,
                s.profile_area,
                s.y_center
            ]
        );
    }

    #[test]
    fn profile_csv_round_trips_through_read_points() {
        let (pos, vol) = lattice([1, 3, 2], [0.0, 0.0, BASE], |_| true);
        let c = Cloud {
            pos: &pos,
            vol: &vol,
            spacing: H,
        };
        let s = cross_section(&c, 0.5 * H, H, BASE);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("profiles.csv");
        write_profile_csv(&path, &[(0.0, &s), (1.5, &s)]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.lines().count(), 1 + 2 * s.profile.len());
        assert!(text.starts_with("time,station,y,z\n0,"), "{text}");

        // Keep only y,z to make a measured-points file, with comments and blanks mixed in.
        let mut measured = String::from("# scanned profile\n\ny, z\n");
        for l in text.lines().skip(1).take(s.profile.len()) {
            let f: Vec<&str> = l.split(',').collect();
            measured += &format!("{},{}\n# note\n", f[2], f[3]);
        }
        let mpath = dir.path().join("measured.csv");
        std::fs::write(&mpath, measured).unwrap();
        assert_eq!(read_points_csv(&mpath).unwrap(), s.profile);
    }

    #[test]
    fn read_points_errors_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.csv");
        let cases = [
            ("y,z\n0.1,0.2\n0.1;0.2\n", ":3:"),
            ("# c\ny,z\n0.1,abc\n", ":3:"),
            ("y,z\n0.1,inf\n", ":2:"),
            ("x,z\n", ":1:"),
            ("# only a comment\n", "no header"),
        ];
        for (text, want) in cases {
            std::fs::write(&path, text).unwrap();
            let e = read_points_csv(&path).unwrap_err().to_string();
            assert!(e.contains("bad.csv") && e.contains(want), "{text:?} -> {e}");
        }
        let e = read_points_csv(&dir.path().join("missing.csv")).unwrap_err().to_string();
        assert!(e.contains("missing.csv"), "{e}");
    }
}

#[cfg(test)]
mod window_tests {
    use super::*;

    /// Rows of particles at a spacing unrelated to the slab: the B-spline window must still give
    /// the row density, where a box window of the same width is off by up to a row.
    #[test]
    fn area_window_integrates_rows_of_any_spacing() {
        let (h, slab) = (0.00125, 0.0025);
        for &s in &[0.00111, 0.00093, 0.0013, 0.0007] {
            let mut pos = Vec::new();
            for i in 0..200 {
                for j in 0..20 {
                    for k in 0..10 {
                        pos.push([i as f64 * s + 0.37 * s, j as f64 * h, k as f64 * h]);
                    }
                }
            }
            // each particle stands for s * h * h, so the exact area is 20 h * 10 h
            let vol = vec![s * h * h; pos.len()];
            let c = Cloud { pos: &pos, vol: &vol, spacing: h };
            let exact = 200.0 * h * h;
            for &st in &[0.05, 0.0507, 0.0613] {
                let a = cross_section(&c, st, slab, -0.5 * h).area;
                assert!((a / exact - 1.0).abs() < 0.01, "s = {s}, station {st}: {a} vs {exact}");
            }
        }
    }
}
