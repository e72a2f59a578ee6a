//! Why a scenario's solids cannot be built: a shape the scenario declares wrongly, or the memory
//! their pool would take.

use crate::invalid::Invalid;
use crate::memory::MemoryError;

#[derive(Debug, thiserror::Error)]
pub enum SolidError {
    #[error(transparent)]
    Invalid(#[from] Invalid),
    #[error(transparent)]
    Memory(#[from] MemoryError),
}
