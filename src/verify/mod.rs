//! The verification suite: closed-form and experimental references.
pub mod analytic;
