//! The registry of observables: the [`Objective`] each name stands for, its name back, and which
//! file computes it. An observable's forward value and its adjoint seed are one function of
//! [`State`](super::state::State) in the observable's own file; this file only names and
//! dispatches.

use super::state::{Frame, Seed, State};
use super::ObservableError;
use crate::kernels::Real;
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
    type Err = ObservableError;
    fn from_str(s: &str) -> Result<Objective, ObservableError> {
        let stations = |v: &str| {
            v.split(',')
                .map(|x| x.trim().parse::<f64>().map_err(|_| ObservableError(format!("objective '{s}': the stations after '@' must be numbers in metres"))))
                .collect::<Result<Vec<f64>, ObservableError>>()
        };
        match s.split_once('@') {
            Some(("width", x)) => Ok(Objective::Width { stations: stations(x)? }),
            Some(("height", x)) => Ok(Objective::Height { stations: stations(x)? }),
            Some(("level", x)) => match stations(x)?[..] {
                [station] => Ok(Objective::Level { station }),
                _ => Err(ObservableError(format!("objective '{s}': level takes one station"))),
            },
            Some((name @ ("smooth_width" | "smooth_height"), x)) => match stations(x)?[..] {
                [station] if name == "smooth_width" => Ok(Objective::SmoothWidth { station }),
                [station] => Ok(Objective::SmoothHeight { station }),
                _ => Err(ObservableError(format!("objective '{s}': {name} takes one station"))),
            },
            Some(("area", x)) => Ok(Objective::Area { stations: stations(x)? }),
            Some((name @ ("profile" | "layer_height" | "layer_width"), x)) => {
                let what = if name == "profile" { "X:Y, the station x and the lateral position y in metres" } else { "X:K, the station x in metres and the layer K (1 = the bottom one)" };
                let bad = || ObservableError(format!("objective '{s}': {name} takes {what}"));
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
                _ => Err(ObservableError(format!("unknown objective '{s}'; known: {NAMES}"))),
            },
        }
    }
}

impl Objective {
    /// The objective on `sim`'s current state; with `seed`, also add its adjoint there.
    pub fn evaluate(&self, sim: &Simulation, frame: &Frame, seed: Option<Seed>) -> Result<f64, ObservableError> {
        if let Some([lo, hi]) = frame.y_range {
            return Err(ObservableError(format!(
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

fn join(stations: &[f64]) -> String {
    stations.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")
}
