//! A print's cost per layer, in the run's log: once the nozzle starts the next layer (and at the
//! run's end), a line with the steps the layer took, their mean dt, the mean awake and sleeping
//! particles and grid blocks over those steps, the sleeping units woken (by load, by material,
//! by the nozzle) and the process's CPU seconds. Enters: the toolpath's layers, then the
//! simulation after each step; leaves: the lines. Why: the cost of a long print should stay near
//! that of its top layers (sleeping, `src/sleep/`), and these lines show where it does not.
//! Counting is a few additions a step; the line is written between steps.

use super::outputs::process_cpu_seconds;
use crate::solver::Simulation;

/// The sums since the current layer began.
pub(super) struct LayerCost {
    /// Start time of each layer of the toolpath, in order.
    starts: Vec<f64>,
    /// The layer in progress (0-based; the first also before it starts).
    layer: usize,
    step0: u64,
    time0: f64,
    cpu0: f64,
    awake0: u64,
    asleep_steps: u64,
    block_steps: u64,
    woken0: [u64; 3],
}

impl LayerCost {
    /// Counting for a print whose layers start at `starts` (none: nothing is counted).
    pub(super) fn new(starts: Vec<f64>, sim: &Simulation) -> Self {
        // a resumed run counts from the layer it stands in
        let layer = starts.iter().take_while(|&&t| t <= sim.time).count().saturating_sub(1);
        let mut c = LayerCost { starts, layer, step0: 0, time0: 0.0, cpu0: 0.0, awake0: 0, asleep_steps: 0, block_steps: 0, woken0: [0; 3] };
        c.restart(sim);
        c
    }

    fn restart(&mut self, sim: &Simulation) {
        (self.step0, self.time0, self.awake0) = (sim.step, sim.time, sim.awake_particle_steps);
        self.cpu0 = process_cpu_seconds();
        (self.asleep_steps, self.block_steps) = (0, 0);
        self.woken0 = sim.sleep.as_ref().map_or([0; 3], |s| s.woken_by);
    }

    /// Count the step just taken; returns the line of the layer it finished, if it did.
    pub(super) fn after_step(&mut self, sim: &Simulation) -> Option<String> {
        if self.starts.is_empty() {
            return None;
        }
        self.asleep_steps += sim.particles.n_sleep as u64;
        self.block_steps += sim.grid.n_active as u64;
        let next = self.starts.get(self.layer + 1)?;
        (sim.time >= *next).then(|| self.finish_layer(sim))
    }

    /// The line of the layer in progress, and the next layer's counting begins.
    pub(super) fn finish_layer(&mut self, sim: &Simulation) -> String {
        let steps = (sim.step - self.step0).max(1) as f64;
        let woken = sim.sleep.as_ref().map_or([0; 3], |s| s.woken_by);
        let line = format!(
            "layer {}: t = {:.2}-{:.2} s, {} steps (mean dt {:.3e} s), awake {:.0}, asleep {:.0} particles and {:.0} grid blocks a step, \
             units woken by load {}, by material {}, by the nozzle {}; {:.1} CPU s",
            self.layer + 1,
            self.time0,
            sim.time,
            sim.step - self.step0,
            (sim.time - self.time0) / steps,
            (sim.awake_particle_steps - self.awake0) as f64 / steps,
            self.asleep_steps as f64 / steps,
            self.block_steps as f64 / steps,
            woken[0] - self.woken0[0],
            woken[1] - self.woken0[1],
            woken[2] - self.woken0[2],
            process_cpu_seconds() - self.cpu0,
        );
        self.layer += 1;
        self.restart(sim);
        line
    }

    /// Whether a layer is in progress (a print, its first layer started).
    pub(super) fn counting(&self) -> bool {
        !self.starts.is_empty() && self.layer < self.starts.len()
    }
}
