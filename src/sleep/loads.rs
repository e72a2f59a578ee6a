//! The wake test on load (`wake_by_load`, module notes of `sleep/`): the reactions of the nodes
//! sleeping units hold, averaged into each unit's load, wake the sleeping column under a load
//! that passes its margin to yield.

use super::holds::Holds;
use super::units::{states, states_mut, unit_coords, unit_in_table, unit_index, wrap_unit, UnitState, UNITS_PER_EDGE, UNIT_CELLS};
use super::Sleep;
use crate::grid::{Grid, NODES_PER_BLOCK};
use crate::kernels::material::Material;
use crate::kernels::Real;

/// Share of a traction's magnitude that reaches tau = sqrt(J2): 1/sqrt(3), exact for a
/// vertical load on a free-standing column (see the module notes).
pub(super) const LOAD_SHARE: f32 = 0.577_350_26;

impl Sleep {
    /// Take in the load of the grid update just done (its held nodes' reactions in
    /// `reactions`, step `step` of length `dt`, ending at `now`): each held node's reaction is
    /// shared among the sleeping units holding it, each unit's average load brought up to date,
    /// and units whose load passes the margin of the sleeping column under them are marked
    /// LOADED for the next update to wake (module notes).
    pub fn take_loads(&mut self, grid: &Grid, dt: f64, step: u64, now: f64, material: &dyn Material) {
        if self.sleeping_units == 0 || !self.tests_loads() {
            return;
        }
        let geom = &grid.geom;
        let slot_block = grid.slot_block.as_slice();
        let a = if self.cfg.load_time > 0.0 { (dt / self.cfg.load_time).min(1.0) as f32 } else { 1.0 };
        let step32 = step as u32;
        let touched = self.woken.as_mut_slice();
        let mut n_touched = 0usize;
        let holds = Holds { state: states(self.state.as_slice()), asleep_in_block: self.asleep_in_block.as_slice(), sleeping_units: self.sleeping_units };
        let (load, load_step) = (self.load.as_mut_slice(), self.load_step.as_mut_slice());
        let reactions = self.reactions.as_slice();
        let (down_axis, sign) = self.down.expect("checked above");
        let column_loads = self.column_loads;
        for (s, &bi) in slot_block[..grid.n_active].iter().enumerate() {
            let Some(window) = holds.block(geom, geom.block_coords(bi)) else {
                continue;
            };
            for li in 0..NODES_PER_BLOCK {
                let f = reactions[s * NODES_PER_BLOCK + li];
                if f == [0.0; 3] {
                    continue;
                }
                let mut holders = [0u32; 8];
                let mut n = 0;
                for u in window.holders(li) {
                    holders[n] = u;
                    n += 1;
                }
                if column_loads {
                    // the node's load goes to the column it lies in the middle of (unit k's
                    // stencil reach is nodes 2k..=2k+3 on each axis: its middle two), when it
                    // sleeps. Why: shared evenly, the weight of material over one column counts
                    // partly on its neighbour, and the column then finds that weight added
                    // (spuriously) when the material falls asleep and counts in its own weights
                    let node = geom.node_of(geom.block_coords(bi), li);
                    let centred = |u: u32| {
                        let c = unit_coords(geom, u);
                        (0..3).all(|a| a == down_axis || c[a] == (node[a] - 1).div_euclid(UNIT_CELLS))
                    };
                    let mut m = 0;
                    for k in 0..n {
                        if centred(holders[k]) {
                            holders[m] = holders[k];
                            m += 1;
                        }
                    }
                    if m > 0 {
                        n = m;
                    }
                }
                let share = a / n as f32;
                for &u in &holders[..n] {
                    let (l, last) = (&mut load[u as usize], &mut load_step[u as usize]);
                    if *last != step32 {
                        // first share this step: decay over the steps since the last one
                        let gap = step32.wrapping_sub(*last).min(1 << 16) as i32;
                        let keep = (1.0 - a).powi(gap);
                        *l = l.map(|x| x * keep);
                        *last = step32;
                        touched[n_touched] = u;
                        n_touched += 1;
                    }
                    for k in 0..3 {
                        l[k] += share * f[k];
                    }
                }
            }
        }
        let (state, asleep_since, margin) = (states_mut(self.state.as_mut_slice()), self.clock.as_slice(), self.margin.as_slice());
        let (base, weight) = (self.base.as_mut_slice(), self.weight.as_slice());
        let pressed = self.pressed.as_mut_slice();
        let per_area = self.per_area;
        let weight_of = |w: u32| if column_loads { weight[w as usize] } else { 0.0 };
        let loaded = self.loaded.as_mut_slice();
        let tau = self.cfg.load_time;
        let (floor, fraction) = (self.cfg.load_floor as f32, self.cfg.load_fraction_for(column_loads) as f32);
        let column = geom.nb[down_axis] * UNITS_PER_EDGE as i32;
        // the sleeping unit next to unit c along the down axis (`step` = sign: below, -sign:
        // above), if any (a column asleep all round a periodic axis ends where it began)
        let next_asleep = |c: [i32; 3], step: i32, state: &[UnitState]| {
            let mut n = c;
            n[down_axis] += step;
            let n = wrap_unit(geom, n);
            (unit_in_table(geom, n) && state[unit_index(geom, n) as usize].is_asleep()).then_some(n)
        };
        for &u in &touched[..n_touched] {
            let l = load[u as usize];
            // the average has run since the unit fell asleep, from zero: unbias it
            let slept = now - asleep_since[u as usize] as f64;
            let w8 = if tau > 0.0 { 1.0 - (-slept / tau).exp() } else { 1.0 };
            if w8 < 0.9 {
                continue;
            }
            let size = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt() / w8 as f32;
            // with column loads, a column is walked from its top only: a unit under sleeping
            // ones takes, on its own nodes, only what presses on its sides, and a walk from it
            // would set or test the units below against a part of their load
            if column_loads && next_asleep(unit_coords(geom, u), -sign, state).is_some() {
                continue;
            }
            if base[u as usize].is_nan() {
                base[u as usize] = size;
                continue;
            }
            // down the sleeping column from u: the load each unit carries is the load on u and
            // the weights of the sleeping units above it; only what was added since it fell
            // asleep counts (the rest is in its frozen stress). The deepest unit whose margin
            // that passes wakes, with the column above it.
            let mut carried = size;
            let mut c = unit_coords(geom, u);
            let (mut w, mut deepest) = (u, None);
            for depth in 1.. {
                if column_loads && base[w as usize].is_nan() {
                    // a unit whose own nodes took no load since it fell asleep (it slept under
                    // sleeping units): what it carries when a load first reaches it
                    base[w as usize] = carried;
                }
                // without column loads, the load added on u, against every unit's margin
                let added = if column_loads { carried - base[w as usize] } else { size - base[u as usize] };
                // the compression that adds, over the unit's face; with column loads its
                // particles take it when they wake
                let compression = per_area * added;
                if column_loads {
                    pressed[w as usize] = compression.max(0.0);
                }
                let t = LOAD_SHARE * compression;
                let gain = material.strength_gain((now - asleep_since[w as usize] as f64).max(0.0) as Real) as f32;
                if t > fraction * (margin[w as usize].max(0.0) + gain) + floor {
                    deepest = Some(c[down_axis]);
                }
                carried += weight_of(w);
                let Some(n) = next_asleep(c, sign, state).filter(|_| depth < column) else { break };
                c = n;
                w = unit_index(geom, n);
            }
            let Some(last) = deepest else { continue };
            let mut c = unit_coords(geom, u);
            loop {
                let w = unit_index(geom, wrap_unit(geom, c));
                if state[w as usize] == UnitState::Asleep {
                    state[w as usize] = UnitState::Loaded;
                    loaded[self.n_loaded] = w;
                    self.n_loaded += 1;
                }
                if c[down_axis] == last {
                    break;
                }
                c[down_axis] += sign;
            }
        }
    }
}
