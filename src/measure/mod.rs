//! The measurement loop (issue 6): measurements and the experiments that produced them
//! (`data.rs`), a virtual rheometer (`rheometer.rs`), and running experiments under a model to
//! compare with measurements or to synthesise them (`compare.rs`).

pub mod compare;
pub mod data;
pub mod rheometer;
