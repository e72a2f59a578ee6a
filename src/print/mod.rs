//! 3D concrete printing: toolpaths (and their G-code import), the nozzle, emission.
pub mod gcode;
pub mod toolpath;
