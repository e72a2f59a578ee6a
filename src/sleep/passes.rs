//! The passes of each step's sleep update: the wake pass (every step), the sleep pass (every
//! `check_interval` steps), and moving the particles of the units that changed in or out of the
//! sleeping prefix of the pool.

use super::units::{neighbours, on_side, particle_unit, states_mut, unit_in_table, unit_index, unit_of_point, wrap_unit, UnitState, EMPTY_UNIT, UNITS};
use super::at_rest::put_at_rest;
use super::{Sleep, SleepConfig};
use crate::grid::{Grid, EMPTY};
use crate::kernels::material::Material;
use crate::kernels::Real;
use crate::particles::Particles;

#[inline]
fn wake(b: u32, state: &mut [UnitState], woken: &mut [u32], n_woken: &mut usize) {
    if state[b as usize].is_asleep() {
        state[b as usize] = UnitState::Woken;
        woken[*n_woken] = b;
        *n_woken += 1;
    }
}

/// The speeds and strain rate of [`SleepConfig`] in the solver's precision.
pub(super) struct Limits {
    rest_speed: Real,
    rest_rate: Real,
    wake_speed: Real,
    /// `arrive_speed` (infinite: material above wakes by its load alone).
    arrive_speed: Real,
}

impl Limits {
    pub(super) fn of(cfg: &SleepConfig) -> Self {
        Limits {
            rest_speed: cfg.speed as Real,
            rest_rate: cfg.strain_rate as Real,
            wake_speed: cfg.wake_speed as Real,
            arrive_speed: cfg.arrive_speed as Real,
        }
    }
}

/// One step of an awake unit's clock (see [`Sleep`]) under its material's (max speed,
/// max strain rate): the new clock, and whether the unit wakes its sleeping neighbours.
///
/// A unit that has just woken waits out `wake_grace` first (negative clock) and wakes nobody
/// meanwhile. Why: a sleeping unit is held still, so the weight of the layers printed onto it
/// while it slept rests on its held nodes, not on its stress. When it wakes, that load reaches
/// its material at once and sends an elastic pulse through it (the weight of a 12.5 mm layer
/// on K = 1 MPa concrete moves it at about 4 mm/s, above `wake_speed`); without the grace the
/// pulse woke the next unit, whose own load woke the next, down the whole stack.
#[inline]
pub(super) fn tick(clock: f32, [v, rate]: [Real; 2], dt: f32, lim: &Limits) -> (f32, bool) {
    if clock < 0.0 {
        return ((clock + dt).min(0.0), false);
    }
    let at_rest = v < lim.rest_speed && rate < lim.rest_rate;
    (if at_rest { clock + dt } else { 0.0 }, v > lim.wake_speed)
}

impl Sleep {
    /// Update rest times from the last step's activity (grid still binned as in that step, of
    /// length `dt`, ending at time `now`), wake and put units to sleep, and move particles
    /// accordingly. Units reaching into `keep_awake` (the nozzle tube: its material must follow
    /// the nozzle even while it rests) neither sleep nor stay asleep. Returns whether particles
    /// moved.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        grid: &Grid,
        particles: &mut Particles,
        material: &dyn Material,
        dt: f64,
        now: f64,
        step: u64,
        check_sleep: bool,
        keep_awake: Option<([f64; 3], [f64; 3])>,
    ) -> bool {
        let woke = self.wake_pass(grid, dt, keep_awake);
        let slept = if check_sleep { self.sleep_pass(grid, now, step, woke) } else { 0 };
        self.sleeping_units = self.sleeping_units + slept - woke;
        if woke > 0 {
            self.wake_particles(grid, particles, material, now, woke);
        }
        if slept > 0 {
            self.put_particles_to_sleep(grid, particles, material, (woke, slept), step);
        }
        woke > 0 || slept > 0
    }

    /// Tick the awake units' clocks and wake the sleeping units that the last step's material
    /// (or the loads marked by the last step, or the nozzle tube) reaches. Returns how many woke;
    /// they are `woken[..n]`, in state `Woken`.
    fn wake_pass(&mut self, grid: &Grid, dt: f64, keep_awake: Option<([f64; 3], [f64; 3])>) -> usize {
        let geom = &grid.geom;
        let npb = grid.n_particle_blocks;
        let slot_block = grid.slot_block.as_slice();
        let activity = &self.activity.as_slice()[..npb];
        let limits = Limits::of(&self.cfg);
        let state = states_mut(self.state.as_mut_slice());
        let clock = self.clock.as_mut_slice();
        let woken = self.woken.as_mut_slice();
        let mut n_woken = 0usize;
        // below: what a unit's speed may not wake when loads are tested; without, the speed
        // rule looks at all 26 neighbours
        let below = self.down;
        for &u in &self.loaded.as_slice()[..self.n_loaded] {
            wake(u, state, woken, &mut n_woken);
        }
        self.n_loaded = 0;
        self.woken_by[0] += n_woken as u64;
        let by_load = n_woken;
        for s in 0..npb {
            for (k, &[v, rate]) in activity[s].iter().enumerate() {
                let u = slot_block[s] * UNITS as u32 + k as u32;
                if [v, rate] == EMPTY_UNIT {
                    // no material: keep the clock at zero so that empty space never sleeps
                    if state[u as usize] == UnitState::Awake {
                        clock[u as usize] = 0.0;
                    }
                    continue;
                }
                // awake material inside a sleeping unit, or fast material next to one, wakes it
                let wakes_neighbours = if state[u as usize] == UnitState::Awake {
                    let (r, loud) = tick(clock[u as usize], [v, rate], dt as f32, &limits);
                    clock[u as usize] = r;
                    loud
                } else {
                    wake(u, state, woken, &mut n_woken);
                    v > limits.wake_speed
                };
                if wakes_neighbours {
                    // material arriving fast enough wakes the units under it too
                    let skip = if v > limits.arrive_speed { None } else { below };
                    for (off, nb) in neighbours(geom, u) {
                        if !on_side(skip, off) {
                            wake(nb, state, woken, &mut n_woken);
                        }
                    }
                }
            }
        }
        self.woken_by[1] += (n_woken - by_load) as u64;
        let by_material = n_woken;
        if let Some(bx) = keep_awake {
            // units whose stencil reach (one unit further) touches the tube
            let lo = unit_of_point(geom, bx.0, -1);
            let hi = unit_of_point(geom, bx.1, 0);
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        let u = wrap_unit(geom, [i, j, k]);
                        if unit_in_table(geom, u) {
                            let idx = unit_index(geom, u);
                            if state[idx as usize] == UnitState::Awake {
                                clock[idx as usize] = clock[idx as usize].min(0.0);
                            } else {
                                wake(idx, state, woken, &mut n_woken);
                            }
                        }
                    }
                }
            }
        }
        self.woken_by[2] += (n_woken - by_material) as u64;
        n_woken
    }

    /// Put to sleep the awake units at rest for `rest_time` whose neighbours are calm, at time
    /// `now` of step `step`. Returns how many fell asleep; they are `woken[woke..woke + n]`.
    fn sleep_pass(&mut self, grid: &Grid, now: f64, step: u64, woke: usize) -> usize {
        let geom = &grid.geom;
        let npb = grid.n_particle_blocks;
        let slot_block = grid.slot_block.as_slice();
        let table = grid.table.as_slice();
        let activity = &self.activity.as_slice()[..npb];
        let limits = Limits::of(&self.cfg);
        let loads = self.tests_loads();
        // above: what a unit falling asleep may lie under while it moves, when loads are tested
        let above = self.down.map(|(a, sign)| (a, -sign));
        let state = states_mut(self.state.as_mut_slice());
        let clock = self.clock.as_mut_slice();
        let woken = self.woken.as_mut_slice();
        let per_block = self.asleep_in_block.as_mut_slice();
        let rest_time = self.cfg.rest_time as f32;
        let mut slept = 0usize;
        for s in 0..npb {
            for k in 0..UNITS {
                let u = slot_block[s] * UNITS as u32 + k as u32;
                if clock[u as usize] < rest_time || state[u as usize] != UnitState::Awake || activity[s][k] == EMPTY_UNIT {
                    continue;
                }
                // material above may move up to `arrive_speed` (loads tested), the rest up to
                // `wake_speed`
                let calm = neighbours(geom, u).all(|(off, nb)| {
                    let limit = if on_side(above, off) { limits.arrive_speed } else { limits.wake_speed };
                    let t = table[nb as usize / UNITS];
                    t == EMPTY || (t as usize) >= npb || activity[t as usize][nb as usize % UNITS][0] <= limit
                });
                if calm {
                    state[u as usize] = UnitState::Asleep;
                    clock[u as usize] = now as f32;
                    per_block[u as usize / UNITS] += 1;
                    woken[woke + slept] = u;
                    slept += 1;
                    if loads {
                        self.margin.as_mut_slice()[u as usize] = 0.0;
                        self.base.as_mut_slice()[u as usize] = f32::NAN;
                        if self.column_loads {
                            self.weight.as_mut_slice()[u as usize] = 0.0;
                            self.pressed.as_mut_slice()[u as usize] = 0.0;
                        }
                        self.load.as_mut_slice()[u as usize] = [0.0; 3];
                        self.load_step.as_mut_slice()[u as usize] = step as u32;
                    }
                }
            }
        }
        slept
    }

    /// The particles of the `woke` units just woken leave the sleeping prefix, given the rest
    /// their unit owes them (its time asleep until `now`); the units become awake and wait out
    /// `wake_grace`.
    fn wake_particles(&mut self, grid: &Grid, particles: &mut Particles, material: &dyn Material, now: f64, woke: usize) {
        let geom = &grid.geom;
        // the down axis, when woken particles take the load their column added while they slept
        let pressed_axis = self.down.filter(|_| self.column_loads && self.tests_loads()).map(|(a, _)| a);
        let state = states_mut(self.state.as_mut_slice());
        let clock = self.clock.as_mut_slice();
        let woken = self.woken.as_slice();
        let per_block = self.asleep_in_block.as_mut_slice();
        let grace = self.cfg.wake_grace as f32;
        // the rest each woken unit owes its particles, then they leave the sleeping prefix
        for &u in &woken[..woke] {
            clock[u as usize] = (now - clock[u as usize] as f64).max(0.0) as f32;
            per_block[u as usize / UNITS] -= 1;
        }
        let sl = particles.state_len;
        let mut i = 0;
        while i < particles.n_sleep {
            let u = unit_index(geom, particle_unit(particles.xg.as_slice()[i]));
            if state[u as usize].is_asleep() {
                i += 1;
            } else {
                let j = particles.j.as_slice()[i];
                let st = &mut particles.state.as_mut_slice()[i * sl..(i + 1) * sl];
                material.rest_for_at(st, clock[u as usize] as Real, j);
                if let Some(axis) = pressed_axis {
                    material.take_column_load(st, axis, self.pressed.as_slice()[u as usize] as Real);
                }
                particles.stress.as_mut_slice()[i] = material.stress_at_rest(st, particles.j.as_slice()[i]);
                particles.n_sleep -= 1;
                particles.swap(i, particles.n_sleep);
            }
        }
        for &u in &woken[..woke] {
            state[u as usize] = UnitState::Awake;
            clock[u as usize] = -grace;
        }
        if self.tests_loads() {
            let (load, load_step) = (self.load.as_mut_slice(), self.load_step.as_mut_slice());
            let (margin, base) = (self.margin.as_mut_slice(), self.base.as_mut_slice());
            for &u in &woken[..woke] {
                // zero, so that checkpoints store only sleeping units' entries
                (load[u as usize], load_step[u as usize], margin[u as usize], base[u as usize]) = ([0.0; 3], 0, 0.0, 0.0);
            }
            if self.column_loads {
                let (weight, pressed) = (self.weight.as_mut_slice(), self.pressed.as_mut_slice());
                for &u in &woken[..woke] {
                    (weight[u as usize], pressed[u as usize]) = (0.0, 0.0);
                }
            }
        }
    }

    /// The awake particles of sleeping units move into the sleeping prefix, put at rest: those of
    /// the `slept` units just fallen asleep at `step` (`woken[woke..woke + slept]`), and any that
    /// came into a unit asleep since earlier (a laid column emitted into it). With the load test,
    /// each unit just fallen asleep takes the mean margin to yield of its particles; a unit
    /// asleep since earlier keeps its margin and its load, and with column loads takes a joining
    /// particle's weight. With `coarsen`, their interior merges.
    fn put_particles_to_sleep(&mut self, grid: &Grid, particles: &mut Particles, material: &dyn Material, (woke, slept): (usize, usize), step: u64) {
        let geom = &grid.geom;
        let loads = self.tests_loads();
        let state = states_mut(self.state.as_mut_slice());
        let from = particles.n_sleep;
        let margin = self.margin.as_mut_slice();
        let sl = particles.state_len;
        for i in particles.n_sleep..particles.n {
            let u = unit_index(geom, particle_unit(particles.xg.as_slice()[i]));
            if state[u as usize] == UnitState::Asleep {
                particles.swap(i, particles.n_sleep);
                let k = particles.n_sleep;
                put_at_rest(particles, k, material);
                if loads {
                    // a unit just fallen asleep: the sleep pass set its load step to this one (the
                    // load test sets it only at later steps). Its particles' margins are summed
                    // and counted here, divided below; a unit asleep since earlier keeps its margin
                    if self.load_step.as_slice()[u as usize] == step as u32 {
                        margin[u as usize] += material.yield_margin(&particles.state.as_slice()[k * sl..(k + 1) * sl]) as f32;
                        self.count.as_mut_slice()[u as usize] += 1;
                    }
                    if self.column_loads {
                        self.weight.as_mut_slice()[u as usize] += particles.mass.as_slice()[k] as f32 * self.g;
                    }
                }
                particles.n_sleep += 1;
            }
        }
        if loads {
            // the mean margin of each unit's particles
            let count = self.count.as_mut_slice();
            for &u in &self.woken.as_slice()[woke..woke + slept] {
                margin[u as usize] /= count[u as usize].max(1) as f32;
                count[u as usize] = 0;
            }
        }
        if let Some(c) = &mut self.coarsen {
            c.merge_interior(geom, particles, from, material);
        }
    }
}
