//! A value its check refuses: a scenario key out of range, an unknown name, a missing table.
//! The message names the key, the rule and the value found. The bottom of the crate: it imports
//! nothing, so every config table can return it.

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Invalid(pub String);
