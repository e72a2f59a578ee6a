//! Reverse-mode gradients.

pub mod schedule;
