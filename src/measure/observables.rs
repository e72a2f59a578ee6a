//! The observables: what a simulation and a rheometer test can observe, and where or when each
//! is taken.
//!
//! `at` is the station x [m] of a printed-geometry observable (`width`, `height`, `smooth_width`, `smooth_height`,
//! `level`, `area`), the time [s] of one observed during
//! a run (`spread`, `front`: a slump spread or a flow distance against time; empty for the end), or the shear rate
//! [1/s] of a rheometer reading.
//! Three printed-geometry observables take a second coordinate after a colon, `X:Y` in the `at`
//! column as in `name@X:Y`: `profile` the lateral position y [m] of a point of the section's top
//! outline (`profile@0.075:0.01`), `layer_height` and `layer_width` the layer, 1 = the bottom one
//! (`layer_height@0.075:2`). `failure_layer` and `failure_time` take no `at`: the layer and time
//! at which a print fails (`failure.rs`). `arrival@X` and `stop_time@D` are read from the flow
//! front's history: the time it reaches x = X, and the time it stops (`front.rs`). `passed@Z:F`
//! is read from the history of the mass below z = Z: the time the fraction F of it has passed
//! (`passing.rs`).

use super::error::MeasureError;
use super::front;
use super::passing;
use super::observation::Observable;
use super::campaign::rheometer::Reading;
use crate::observables::{At, Objective, Takes, KINDS};
use std::sync::LazyLock;

/// Observables a simulation experiment can produce: those of the registry (`src/observables/`)
/// an experiment may name, and those read from a run's history (failure, front, passing).
pub static SIMULATION_OBSERVABLES: LazyLock<Vec<&'static str>> = LazyLock::new(|| {
    let registry = KINDS.iter().filter(|k| k.measured).map(|k| k.name);
    registry
        .chain(crate::failure::OBSERVABLES.iter().chain(front::OBSERVABLES).chain(passing::OBSERVABLES).copied())
        .collect()
});
/// Observables a rheometer experiment can produce.
pub const RHEOMETER_OBSERVABLES: &[&str] = &["stress"];

/// Whether `o` is written with the coordinates its observable takes, on a simulation
/// (`simulation`) or a rheometer test. The time of one taken during the run is checked when it
/// runs, against the run's end.
pub fn check_coordinates(o: &Observable, simulation: bool) -> Result<(), MeasureError> {
    if crate::failure::OBSERVABLES.contains(&o.name.as_str()) {
        crate::failure::check_observable(&o.name, o.at).map_err(MeasureError::from)
    } else if front::OBSERVABLES.contains(&o.name.as_str()) {
        front::check_observable(o)
    } else if passing::OBSERVABLES.contains(&o.name.as_str()) {
        passing::check_observable(o)
    } else if simulation {
        observable_plan(o, f64::INFINITY).map(|_| ())
    } else {
        reading_rate(o).map(|_| ())
    }
}

/// When (time) and what (objective) a simulation observable is: those of the whole material
/// (spread, front, vx_max, kinetic_energy, mean_z) may be taken during the run, `@T`; a section's
/// (width, height, area, profile, layers), whose `@` is a station, at its end `end`.
pub fn observable_plan(o: &Observable, end: f64) -> Result<(f64, Objective), MeasureError> {
    let name = o.name.as_str();
    let kind = crate::observables::kind(name).filter(|k| k.measured);
    let second = match kind.map(|k| k.takes) {
        Some(Takes::StationAndY) => Some(format!("a station and a lateral position: {name}@X:Y (metres)")),
        Some(Takes::StationAndLayer) => Some(format!("a station and a layer: {name}@X:K (K = 1 the bottom layer)")),
        _ => None,
    };
    if o.at2.is_some() && second.is_none() && SIMULATION_OBSERVABLES.contains(&name) {
        return Err(MeasureError::Observable(format!("'{o}': {name} takes one coordinate after '@', not two")));
    }
    let Some(kind) = kind else {
        return Err(MeasureError::Observable(match name {
            name if front::OBSERVABLES.contains(&name) => format!("'{o}' is read from the front's history over the \
                run, not at one time: it has no adjoint"),
            name if passing::OBSERVABLES.contains(&name) => format!("'{o}' is read from the history of the mass below \
                a plane over the run, not at one time: it has no adjoint"),
            other => format!("a simulation cannot observe '{other}'"),
        }));
    };
    let station = || o.at.ok_or_else(|| MeasureError::Observable(format!("'{name}' needs a station: {name}@X")));
    let both = || match (o.at, o.at2) {
        (Some(x), Some(y)) => Ok((x, y)),
        _ => Err(MeasureError::Observable(format!("'{o}' needs {}", second.as_deref().unwrap_or("two coordinates")))),
    };
    let (t, at) = match kind.takes {
        Takes::Nothing => (o.at.unwrap_or(end), At::Nothing),
        Takes::Stations | Takes::Station => (end, At::Stations(vec![station()?])),
        Takes::StationAndY => {
            let (station, y) = both()?;
            (end, At::Point { station, y })
        }
        Takes::StationAndLayer => {
            let (station, k) = both()?;
            if !(k >= 1.0 && k.fract() == 0.0 && k <= u32::MAX as f64) {
                return Err(MeasureError::Observable(format!(
                    "'{o}': the layer must be a whole number from 1 (the bottom layer), got {k}"
                )));
            }
            (end, At::Layer { station, layer: k as usize })
        }
    };
    if !(0.0..=end).contains(&t) {
        return Err(MeasureError::Observable(format!("'{o}': time {t} s is outside the run [0, {end}] s")));
    }
    Ok((t, Objective::new(kind, at)))
}

/// Which reading a rheometer observable is: the last one at its shear rate.
pub fn reading_index(o: &Observable, readings: &[Reading]) -> Result<usize, MeasureError> {
    let rate = reading_rate(o)?;
    readings.iter().rposition(|r| (r.rate - rate).abs() <= 1e-9 * rate.abs().max(1.0)).ok_or_else(|| {
        MeasureError::Observable(format!(
            "'{o}': the protocol records no reading at rate {rate} (it records {:?})",
            readings.iter().map(|r| r.rate).collect::<Vec<_>>()
        ))
    })
}

/// The shear rate of a rheometer observable, `stress@RATE`.
pub fn reading_rate(o: &Observable) -> Result<f64, MeasureError> {
    if !RHEOMETER_OBSERVABLES.contains(&o.name.as_str()) {
        return Err(MeasureError::Observable(format!(
            "a rheometer test cannot observe '{}'; it can observe {}",
            o.name,
            RHEOMETER_OBSERVABLES.join(", ")
        )));
    }
    match (o.at, o.at2) {
        (Some(rate), None) => Ok(rate),
        (Some(_), Some(_)) => {
            Err(MeasureError::Observable(format!("'{o}': stress takes one coordinate, the shear rate: stress@RATE")))
        }
        (None, _) => Err(MeasureError::Observable("'stress' needs the shear rate: stress@RATE".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 27 finding 4: a rheometer reading is the stress; any other name is refused, as for
    /// simulations, instead of being computed as the stress.
    #[test]
    fn a_rheometer_observes_only_the_stress() {
        for name in ["banana@1", "strain@1", "spread@1", "spread"] {
            let e = reading_rate(&Observable::parse(name).unwrap()).unwrap_err().to_string();
            assert!(e.contains("rheometer test cannot observe") && e.contains("stress"), "{name}: {e}");
        }
        assert_eq!(reading_rate(&Observable::parse("stress@2.5").unwrap()).unwrap(), 2.5);
    }

    #[test]
    fn printed_geometry_observables_are_their_objectives_at_the_end() {
        let plan = |s: &str| observable_plan(&Observable::parse(s).unwrap(), 2.0);
        let objective = |name: &str, at: At| Objective::new(crate::observables::kind(name).unwrap(), at);
        assert_eq!(
            plan("profile@0.075:0.01").unwrap(),
            (2.0, objective("profile", At::Point { station: 0.075, y: 0.01 }))
        );
        assert_eq!(
            plan("layer_height@0.075:2").unwrap(),
            (2.0, objective("layer_height", At::Layer { station: 0.075, layer: 2 }))
        );
        assert_eq!(
            plan("layer_width@0.075:1").unwrap(),
            (2.0, objective("layer_width", At::Layer { station: 0.075, layer: 1 }))
        );
        assert_eq!(plan("smooth_width@0.075").unwrap(), (2.0, objective("smooth_width", At::Stations(vec![0.075]))));
        assert_eq!(plan("smooth_height@0.075").unwrap(), (2.0, objective("smooth_height", At::Stations(vec![0.075]))));
        // each objective's name is the observable's own
        for s in [
            "profile@0.075:0.01",
            "layer_height@0.075:2",
            "layer_width@0.075:1",
            "height@0.075",
            "smooth_width@0.075",
            "smooth_height@0.075",
        ] {
            assert_eq!(plan(s).unwrap().1.name(), s);
        }
        let e = plan("layer_height@0.075:-2").unwrap_err().to_string();
        assert!(e.contains("'layer_height@0.075:-2'") && e.contains("whole number from 1"), "{e}");
        let e = plan("profile").unwrap_err().to_string();
        assert!(e.contains("profile@X:Y"), "{e}");
        // the whole material's observables at a time during the run, or at its end
        for name in ["spread", "front", "vx_max", "kinetic_energy", "mean_z"] {
            assert_eq!(plan(&format!("{name}@0.5")).unwrap().0, 0.5, "{name}");
            assert_eq!(plan(name).unwrap().0, 2.0, "{name}");
        }
        assert!(plan("mean_z@3").unwrap_err().to_string().contains("outside the run"));
        let e = plan("front@1:2").unwrap_err().to_string();
        assert!(e.contains("front takes one coordinate"), "{e}");
        let e = reading_rate(&Observable::parse("stress@1:2").unwrap()).unwrap_err().to_string();
        assert!(e.contains("stress@RATE"), "{e}");
    }

}
