//! The scenario's tables that a component reads, each with its defaults and validation. The
//! bottom of the crate: these files import no runtime module (the `[print]`, `[observe] failure`
//! and disk-policy tables live beside the small, dependency-free types they are made of, and are
//! re-exported here), so `scenario.rs` and every component can build on them.

pub mod checkpoint;
pub mod observe;
pub mod sleep;

pub use crate::disk::DiskFullPolicy;
pub use crate::failure::FailureConfig;
pub use crate::print::PrintConfig;
pub use checkpoint::CheckpointConfig;
pub use observe::ObserveConfig;
pub use sleep::SleepConfig;
