//! Grid boundary conditions.
