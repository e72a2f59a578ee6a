//! G-code import into a toolpath.
