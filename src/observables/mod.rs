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
//! `layers.rs`, `front.rs`, `motion.rs`, `mean_z.rs`). `objective.rs` is the registry: the
//! [`Objective`] a name stands for, and which file computes it. `docs/measurement.md` shows how
//! to add one.
//!
//! They follow the observables of `observe.rs` (a particle stands for a cube of side
//! `spacing`): extents add one spacing to the spread of particle centres. An extent is a max
//! minus a min, so its gradient flows through the extreme particles only; which particle is
//! extreme, and which particles fall into a slab or band, a profile's y bin or a printed layer,
//! is held fixed (piecewise constant in the positions).

mod area;
mod extent;
mod front;
mod layers;
mod mean_z;
mod motion;
mod objective;
mod profile;
pub mod smooth_extent;
mod spread;
mod state;
#[cfg(test)]
mod tests;

pub use objective::{Objective, NAMES};
pub use state::{Frame, Seed};

/// Why an observable cannot be named or taken: a name that does not parse, or a state that does
/// not have it (no particle where it looks).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ObservableError(pub String);
