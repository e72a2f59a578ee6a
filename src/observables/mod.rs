//! Observables: scalar functions of the particle state at one time, each with its adjoint (the
//! seed of the backward pass).
//!
//! In: a [`Simulation`](crate::solver::Simulation) at the time observed, its [`Frame`] (the
//! scenario's geometry), and optionally a [`Seed`] to add the adjoint to. Out: the value, in SI
//! units. Both the forward runs of the measurement loop (`measure/`) and the gradients (`grad/`)
//! take their observables from here; the run's reporter (`observe.rs`) writes the same sections
//! to CSV, and [`tests`] holds each observable to the reporter's figure.
//!
//! Each observable is one file: its forward value and its seed side by side, as a kernel is
//! beside its adjoint (`spread.rs`, `extent.rs`, `area.rs`, `smooth_extent.rs`, `profile.rs`,
//! `layers.rs`, `front.rs`, `motion.rs`, `mean_z.rs`), each declaring its [`Kind`]: name,
//! coordinates, whether experiments may name it, and the function. The `registry!` below lists
//! the files; `objective.rs` parses a name into an [`Objective`] and dispatches to its kind.
//! `docs/measurement.md` shows how to add one.
//!
//! They follow the observables of `observe.rs` (a particle stands for a cube of side
//! `spacing`): extents add one spacing to the spread of particle centres. An extent is a max
//! minus a min, so its gradient flows through the extreme particles only; which particle is
//! extreme, and which particles fall into a slab or band, a profile's y bin or a printed layer,
//! is held fixed (piecewise constant in the positions).

mod objective;
mod state;
#[cfg(test)]
mod tests;

/// The registry: each observable's file and the [`Kind`]s it declares, one line per file. The
/// files' modules and [`KINDS`], every observable in this order, are made from it.
macro_rules! registry {
    ($($file:ident: $($kind:ident),+;)*) => {
        $(mod $file;)*
        /// Every observable: what `strand grad` and an experiments file can name.
        pub const KINDS: &[&Kind] = &[$($(&$file::$kind,)+)*];
    };
}

registry! {
    spread: SPREAD;
    extent: WIDTH, HEIGHT, LEVEL, TOTAL_HEIGHT;
    area: AREA;
    profile: PROFILE;
    layers: LAYER_HEIGHT, LAYER_WIDTH;
    smooth_extent: SMOOTH_WIDTH, SMOOTH_HEIGHT;
    front: FRONT;
    motion: VX_MAX, KINETIC_ENERGY;
    mean_z: MEAN_Z;
}

pub use objective::{kind, names, At, Kind, Objective, Takes};
pub use front::FRONT;
pub use state::{Frame, Seed};

/// Why an observable cannot be named or taken: a name that does not parse, or a state that does
/// not have it (no particle where it looks).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ObservableError(pub String);
