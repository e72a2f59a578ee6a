//! Toolpaths: timed nozzle moves with piecewise-constant parameters.
