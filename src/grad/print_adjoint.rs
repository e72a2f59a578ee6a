//! Toolpath parameters: the speed, extrusion speed or pause duration of one toolpath segment
//! (`print.path.<i>.speed`, `.extrusion`, `.duration`), each constant over its interval (paper 000
//! sec. 4.2), and the two acting on the whole toolpath, path or G-code: the extrusion factor
//! (delivered over commanded flow, `print.extrusion_factor`) and the nozzle's Z offset
//! (`print.z_offset`). They reach the simulation two ways, both chained here:
//!
//! - the nozzle drive of every step: its outlet position (through the smoothed indicator) and the
//!   velocity it imposes inside the tube;
//! - emission: the positions (moved from the slab's due time to the step) and velocity of every
//!   emitted particle, and the extruded length that sets the newest slab's mass fraction.
//!
//! Both are closed-form, piecewise-linear functions of time whose breakpoints move with the
//! parameters (a faster segment ends sooner and shifts everything after it). Their derivatives
//! with respect to a parameter are taken by central differences of these closed forms alone —
//! two toolpaths per parameter, built once — which is exact up to rounding (relative 1e-9 at
//! the step used) away from the breakpoints; the simulation itself stays differentiated by its
//! adjoint. Discrete events are held fixed: which step a slab enters in, and which lattice
//! points of the outlet lie inside the domain.

use super::GradError;
use crate::print::emitter::{EmissionPlan, Slab};
use crate::print::toolpath::Segment;
use crate::print::PrintConfig;
use crate::scenario::Scenario;
use crate::solver::{AdjointError, ToolpathBar};
use std::sync::Arc;

/// Relative step of the central differences of the toolpath.
const REL_STEP: f64 = 1e-6;

struct Item {
    h: f64,
    plus: EmissionPlan,
    minus: EmissionPlan,
    bar: f64,
}

pub struct PrintParams {
    items: Vec<Item>,
    slabs: [Slab; 3],
}

/// The `[print]` table with the toolpath parameter `key` set to `v`: a segment's value
/// (`print.path.<i>.<field>`), or one acting on the whole toolpath (`print.extrusion_factor`,
/// `print.z_offset`).
fn set(cfg: &PrintConfig, key: &str, v: f64) -> Result<PrintConfig, GradError> {
    let mut cfg = cfg.clone();
    match key {
        "print.extrusion_factor" => cfg.extrusion_factor = v,
        "print.z_offset" => cfg.z_offset = v,
        _ => {
            let (index, field) = parse_key(key).ok_or_else(|| GradError::Param(format!("'{key}' is not print.path.<i>.<speed|extrusion|duration>, print.extrusion_factor or print.z_offset")))?;
            if cfg.gcode.is_some() || cfg.points.is_some() {
                return Err(GradError::Param(format!("'{key}': segment parameters are taken on print.path segments, not on G-code or a point list")));
            }
            let seg = cfg.path.get_mut(index).ok_or_else(|| GradError::Param(format!("print.path has no segment {index}")))?;
            match (seg, field) {
                (Segment::Print { speed, .. } | Segment::Travel { speed, .. } | Segment::Arc { speed, .. }, "speed") => *speed = v,
                (Segment::Layer { speed, .. }, "speed") => *speed = Some(v),
                (Segment::Print { extrusion, .. } | Segment::Arc { extrusion, .. }, "extrusion") => *extrusion = v,
                (Segment::Pause { duration }, "duration") => *duration = v,
                (seg, _) => return Err(GradError::Param(format!("print.path.{index} is a {} segment without a differentiable '{field}'", seg.kind_name()))),
            }
        }
    }
    Ok(cfg)
}

/// Parse `print.path.<i>.<field>`.
pub fn parse_key(key: &str) -> Option<(usize, &str)> {
    let rest = key.strip_prefix("print.path.")?;
    let (i, field) = rest.split_once('.')?;
    Some((i.parse().ok()?, field))
}

fn slab(per: usize) -> Slab {
    Slab { slab: 0, due: 0.0, velocity: [0.0; 3], moves: (None, 0), positions: Vec::with_capacity(per) }
}

impl PrintParams {
    /// The toolpath parameters among `keys` (others are skipped); `values` are their values.
    pub fn new(sc: &Scenario, base: &EmissionPlan, keys: &[(String, f64)]) -> Result<PrintParams, GradError> {
        let cfg = sc.print.as_ref().ok_or_else(|| GradError::Param("toolpath parameters need a [print] table".into()))?;
        let mut items = Vec::new();
        for (key, value) in keys {
            if base.laid.is_some() {
                return Err(GradError::Param(format!("{key}: a laid deposit (print.deposit) adds whole columns, a staircase in the toolpath's parameters; differentiate an extruded one")));
            }
            let h = REL_STEP * value.abs().max(1e-3);
            let plan = |v: f64| -> Result<EmissionPlan, GradError> {
                let tp = set(cfg, key, v)?.toolpath(&sc.base_dir)?;
                Ok(EmissionPlan { toolpath: Arc::new(tp), ..base.clone() })
            };
            items.push(Item { h, plus: plan(value + h)?, minus: plan(value - h)?, bar: 0.0 });
        }
        let per = base.particles_per_slab();
        Ok(PrintParams { items, slabs: [slab(per), slab(per), slab(per)] })
    }

    /// dJ/dtheta of each toolpath parameter so far, in the order given to `new`.
    pub fn gradient(&self) -> Vec<f64> {
        self.items.iter().map(|i| i.bar).collect()
    }

    /// Chain the adjoints of step time `t`'s drive (outlet position and imposed velocity) of
    /// the base toolpath's move `k`.
    pub fn drive(&mut self, k: usize, t: f64, outlet_bar: [f64; 3], velocity_bar: [f64; 3]) {
        for it in &mut self.items {
            let (p, m) = (it.plus.toolpath.state_on(k, t), it.minus.toolpath.state_on(k, t));
            let vel = |s: &crate::print::toolpath::NozzleState| [s.velocity[0], s.velocity[1], s.velocity[2] - s.extrusion_speed];
            let (vp, vm) = (vel(&p), vel(&m));
            for c in 0..3 {
                it.bar += outlet_bar[c] * (p.position[c] - m.position[c]) / (2.0 * it.h);
                it.bar += velocity_bar[c] * (vp[c] - vm[c]) / (2.0 * it.h);
            }
        }
    }

    /// Chain the adjoint of the extruded length at step time `t` (move `k` of the base toolpath
    /// held), which sets the newest slab's mass fraction.
    pub fn extruded(&mut self, k: usize, t: f64, length_bar: f64) {
        for it in &mut self.items {
            let d = it.plus.toolpath.extruded_on(k, t) - it.minus.toolpath.extruded_on(k, t);
            it.bar += length_bar * d / (2.0 * it.h);
        }
    }

    /// Chain the adjoints of the particles slabs `first..` added at step time `t`: `x_bar` of
    /// their world positions, `v_bar` of their velocities, in the order they were added.
    pub fn emission(&mut self, base: &EmissionPlan, first: u64, t: f64, x_bar: &[[f64; 3]], v_bar: &[[f64; 3]]) -> Result<(), AdjointError> {
        let [s0, sp, sm] = &mut self.slabs;
        let (mut q, mut at) = (first, 0);
        while at < x_bar.len() {
            base.fill(q, s0);
            let k = s0.positions.len();
            for it in &mut self.items {
                it.plus.fill_on(q, sp, s0.moves);
                it.minus.fill_on(q, sm, s0.moves);
                if sp.positions.len() != k || sm.positions.len() != k {
                    return Err(AdjointError::SlabCount { slab: q });
                }
                let (lp, lm) = (t - sp.due, t - sm.due);
                for i in 0..k {
                    for c in 0..3 {
                        let xp = sp.positions[i][c] + lp * sp.velocity[c];
                        let xm = sm.positions[i][c] + lm * sm.velocity[c];
                        it.bar += x_bar[at + i][c] * (xp - xm) / (2.0 * it.h);
                        it.bar += v_bar[at + i][c] * (sp.velocity[c] - sm.velocity[c]) / (2.0 * it.h);
                    }
                }
            }
            at += k;
            q += 1;
        }
        Ok(())
    }
}

impl ToolpathBar for PrintParams {
    fn drive(&mut self, k: usize, t: f64, outlet_bar: [f64; 3], velocity_bar: [f64; 3]) {
        PrintParams::drive(self, k, t, outlet_bar, velocity_bar)
    }
    fn extruded(&mut self, k: usize, t: f64, length_bar: f64) {
        PrintParams::extruded(self, k, t, length_bar)
    }
    fn emission(&mut self, plan: &EmissionPlan, first_slab: u64, t: f64, x_bar: &[[f64; 3]], v_bar: &[[f64; 3]]) -> Result<(), AdjointError> {
        PrintParams::emission(self, plan, first_slab, t, x_bar, v_bar)
    }
}
