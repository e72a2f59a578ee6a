//! What an observable is: a [`Kind`] (listed in the registry, `mod.rs`'s [`KINDS`]), and an
//! [`Objective`], one of them with its coordinates. An observable's name, coordinates, docs,
//! forward value and adjoint seed are its [`Kind`], declared in the observable's own file beside
//! the function of [`State`] that computes it; this file only parses names and dispatches.

use super::state::{Frame, Seed, State};
use super::ObservableError;
use super::KINDS;
use crate::kernels::Real;
use crate::solver::Simulation;

/// The coordinates an observable takes after `@` in its name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Takes {
    /// None: the whole material (`spread`). An experiment may take it during the run, `name@T`.
    Nothing,
    /// Stations x [m], summed: `width@X[,X...]` (an experiment takes one).
    Stations,
    /// One station x [m]: `level@X`.
    Station,
    /// A station x and a lateral position y [m]: `profile@X:Y`.
    StationAndY,
    /// A station x [m] and a printed layer K, 1 = the bottom one: `layer_height@X:K`.
    StationAndLayer,
}

impl Takes {
    /// How a name of this kind is written after the observable's own (`@X[,X...]`).
    pub fn pattern(self) -> &'static str {
        match self {
            Takes::Nothing => "",
            Takes::Stations => "@X[,X...]",
            Takes::Station => "@X",
            Takes::StationAndY => "@X:Y",
            Takes::StationAndLayer => "@X:K",
        }
    }

    /// What the first coordinate is, as a report's axis names it.
    pub fn at_meaning(self) -> &'static str {
        match self {
            Takes::Nothing => "time [s]",
            _ => "station x [m]",
        }
    }

    /// What the second coordinate (after `:`) is, as a report's axis names it.
    pub fn at2_meaning(self) -> &'static str {
        match self {
            Takes::StationAndY => "lateral position y [m]",
            Takes::StationAndLayer => "layer (1 = the bottom one)",
            _ => "second coordinate",
        }
    }
}

/// One observable: what it is called, what it takes, whether measurement campaigns may observe
/// it, and the function giving its value and (with a seed) its adjoint.
pub struct Kind {
    pub name: &'static str,
    pub takes: Takes,
    /// Whether an experiments file may name it (`total_height` is for `strand grad` only).
    pub measured: bool,
    pub(super) evaluate: fn(&State, &Objective, Option<Seed>) -> Result<f64, ObservableError>,
}

impl std::fmt::Debug for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.debug_struct("Kind").field("name", &self.name).field("takes", &self.takes).field("measured", &self.measured).finish()
    }
}

/// An observable's coordinates, as its [`Takes`] says.
#[derive(Clone, Debug, PartialEq)]
pub enum At {
    Nothing,
    Stations(Vec<f64>),
    Point { station: f64, y: f64 },
    Layer { station: f64, layer: usize },
}

/// An observable with its coordinates: what `strand grad` differentiates and an experiment
/// observes.
#[derive(Clone, Debug)]
pub struct Objective {
    pub kind: &'static Kind,
    pub at: At,
}

impl PartialEq for Objective {
    fn eq(&self, other: &Objective) -> bool {
        self.kind.name == other.kind.name && self.at == other.at
    }
}

/// The observable named `name` (no coordinates), if the registry has it.
pub fn kind(name: &str) -> Option<&'static Kind> {
    KINDS.iter().copied().find(|k| k.name == name)
}

/// Every observable with the coordinates it takes, as `strand grad` accepts them.
pub fn names() -> String {
    KINDS.iter().map(|k| format!("{}{}", k.name, k.takes.pattern())).collect::<Vec<_>>().join(", ")
}

impl std::str::FromStr for Objective {
    type Err = ObservableError;
    fn from_str(s: &str) -> Result<Objective, ObservableError> {
        let unknown = || ObservableError(format!("unknown objective '{s}'; known: {}", names()));
        let (name, x) = match s.split_once('@') {
            Some((name, x)) => (name, Some(x)),
            None => (s, None),
        };
        let kind = kind(name).filter(|k| (k.takes == Takes::Nothing) == x.is_none()).ok_or_else(unknown)?;
        let Some(x) = x else {
            return Ok(Objective { kind, at: At::Nothing });
        };
        let stations = || {
            x.split(',')
                .map(|v| v.trim().parse::<f64>().map_err(|_| ObservableError(format!("objective '{s}': the stations after '@' must be numbers in metres"))))
                .collect::<Result<Vec<f64>, ObservableError>>()
        };
        let at = match kind.takes {
            Takes::Nothing => unreachable!("a name with '@' is of an observable that takes coordinates"),
            Takes::Stations => At::Stations(stations()?),
            Takes::Station => match stations()?[..] {
                [station] => At::Stations(vec![station]),
                _ => return Err(ObservableError(format!("objective '{s}': {name} takes one station"))),
            },
            Takes::StationAndY | Takes::StationAndLayer => {
                let y = kind.takes == Takes::StationAndY;
                let what = if y { "X:Y, the station x and the lateral position y in metres" } else { "X:K, the station x in metres and the layer K (1 = the bottom one)" };
                let bad = || ObservableError(format!("objective '{s}': {name} takes {what}"));
                let (a, b) = x.split_once(':').ok_or_else(bad)?;
                let station = a.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(bad)?;
                if y {
                    let y = b.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(bad)?;
                    At::Point { station, y }
                } else {
                    At::Layer { station, layer: b.trim().parse::<usize>().ok().filter(|&k| k >= 1).ok_or_else(bad)? }
                }
            }
        };
        Ok(Objective { kind, at })
    }
}

impl Objective {
    /// The observable `kind` at `at`.
    pub fn new(kind: &'static Kind, at: At) -> Objective {
        Objective { kind, at }
    }

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
        (self.kind.evaluate)(&at, self, seed)
    }

    /// The stations the objective is taken at (one for all but the summed extents); none for the
    /// whole material's.
    pub fn stations(&self) -> &[f64] {
        match &self.at {
            At::Nothing => &[],
            At::Stations(s) => s,
            At::Point { station, .. } | At::Layer { station, .. } => std::slice::from_ref(station),
        }
    }

    /// Its first station (0 for the whole material's).
    pub fn station(&self) -> f64 {
        self.stations().first().copied().unwrap_or(0.0)
    }

    /// Its lateral position y [m] (`profile`'s; NaN for others).
    pub fn y(&self) -> f64 {
        match self.at {
            At::Point { y, .. } => y,
            _ => f64::NAN,
        }
    }

    /// Its printed layer, 1 = the bottom one (`layer_height`'s and `layer_width`'s; 0, no layer,
    /// for others).
    pub fn layer(&self) -> usize {
        match self.at {
            At::Layer { layer, .. } => layer,
            _ => 0,
        }
    }

    /// `name`, `name@X[,X...]`, `name@X:Y` or `name@X:K`, as it parses back.
    pub fn name(&self) -> String {
        let n = self.kind.name;
        match &self.at {
            At::Nothing => n.into(),
            At::Stations(stations) => format!("{n}@{}", stations.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(",")),
            At::Point { station, y } => format!("{n}@{station}:{y}"),
            At::Layer { station, layer } => format!("{n}@{station}:{layer}"),
        }
    }
}
