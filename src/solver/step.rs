//! One step: the time step control and the order of the phases.

use super::{DtLimit, SimError, Simulation};
use crate::kernels::Real;

struct PhaseClock(std::time::Instant);
impl PhaseClock {
    fn start() -> Self {
        PhaseClock(std::time::Instant::now())
    }
    fn lap(&mut self, acc: &mut f64) {
        let now = std::time::Instant::now();
        *acc += (now - self.0).as_secs_f64();
        self.0 = now;
    }
}

impl Simulation {
    /// The time step for the next step and the bound that set it.
    pub fn choose_dt(&self, until: f64) -> (f64, DtLimit) {
        let s = &self.scenario.simulation;
        let (mut dt, mut limit) = match s.dt {
            Some(dt) => (dt, DtLimit::Fixed),
            None => {
                let st = self.material.stability();
                let rho = st.density as f64;
                let c = ((st.bulk_modulus as f64 + 4.0 / 3.0 * st.shear_modulus as f64) / rho).sqrt();
                let dt_wave = s.cfl * s.dx / (c + self.vmax);
                // a shear-thickening material's viscosity grows with the rate: bound the rate
                // by the particle speeds (see `max_shear_rate`)
                let mu = st.viscosity_up_to(max_shear_rate(self.vmax, s.dx));
                let dt_visc = if mu > 0.0 {
                    s.cfl * rho * s.dx * s.dx / (2.0 * mu)
                } else {
                    f64::INFINITY
                };
                let mut best = if dt_visc < dt_wave { (dt_visc, DtLimit::Viscous) } else { (dt_wave, DtLimit::Wave) };
                if let Some(m) = s.max_dt {
                    if m < best.0 {
                        best = (m, DtLimit::MaxDt);
                    }
                }
                best
            }
        };
        let left = until - self.time;
        if left <= dt * (1.0 + 1e-9) {
            dt = left;
            limit = DtLimit::Schedule;
        }
        (dt, limit)
    }

    /// Advance by one step, not going past time `until`.
    pub fn step_until(&mut self, until: f64) -> Result<(), SimError> {
        let (dt, limit) = self.choose_dt(until);
        self.advance(dt)?;
        self.last_dt = dt;
        self.last_limit = limit;
        Ok(())
    }

    /// One MLS-MPM step of length `dt`.
    pub fn advance(&mut self, dt: f64) -> Result<(), SimError> {
        self.begin_step(dt)?;
        self.finish_step(dt)
    }

    /// The first half of a step: emission, sleeping, binning, P2G and the grid update. Between
    /// the halves the rest of the step needs only the grid's node velocities, and per particle
    /// x, J, the material state and id (v too with FLIP): C and stress are rebuilt by G2P and
    /// the material update. That is where restart checkpoints are taken
    /// (`checkpoint/state.rs`).
    pub fn begin_step(&mut self, dt: f64) -> Result<(), SimError> {
        let mut clock = PhaseClock::start();
        self.emit()?;
        let drive = self.printer.as_ref().and_then(|p| p.drive(self.time));
        let mut moved = false;
        if let Some(sl) = &mut self.sleep {
            if self.step > 0 {
                let check = self.step.is_multiple_of(sl.cfg.check_interval);
                let mat = &*self.material;
                // A still nozzle (a pause) holds its tube's nodes at rest, as sleeping material's held
                // nodes are: material resting under or in it may sleep through the dwell.
                let moving_tube = drive.filter(|d| d.velocity != [0.0; 3]).map(|d| d.bounds());
                moved = sl.update(&self.grid, &mut self.particles, mat, self.last_dt, self.time, self.step, check, moving_tube);
            }
        }
        self.awake_particle_steps += (self.particles.n - self.particles.n_sleep) as u64;
        self.bin_particles()?;
        if !self.frozen_order && (moved || self.step.is_multiple_of(self.scenario.simulation.reorder_interval)) {
            self.reorder_particles();
        }
        self.newest_masses(self.particles.n_sleep);
        clock.lap(&mut self.phase_seconds[0]);
        self.clear_grid();
        clock.lap(&mut self.phase_seconds[1]);
        self.p2g(dt as Real);
        clock.lap(&mut self.phase_seconds[2]);
        self.grid_update(dt as Real, drive.as_ref());
        if let Some(sl) = &mut self.sleep {
            sl.take_loads(&self.grid, dt, self.step, self.time + dt, &*self.material);
        }
        clock.lap(&mut self.phase_seconds[3]);
        Ok(())
    }

    /// The second half of a step begun by [`Simulation::begin_step`] with the same `dt` (or put
    /// back by a checkpoint restore): G2P, the newest slab's blend, the material update.
    pub fn finish_step(&mut self, dt: f64) -> Result<(), SimError> {
        let mut clock = PhaseClock::start();
        let drive = self.printer.as_ref().and_then(|p| p.drive(self.time));
        self.g2p(dt as Real);
        self.follow_feed(dt as Real, drive.as_ref());
        clock.lap(&mut self.phase_seconds[4]);
        self.update_materials(dt as Real)?;
        clock.lap(&mut self.phase_seconds[5]);
        self.step += 1;
        self.time += dt;
        Ok(())
    }
}

/// An upper bound on the shear rate gamma_dot = sqrt(2 D':D') MLS-MPM can give a particle when
/// no grid node moves faster than `speed`: with quadratic B-splines, C = (4 / dx^2) sum_i w_i v_i
/// (x_i - x_p)^T, sum_i w_i = 1 and sum_i w_i |x_i - x_p|^2 = 3 dx^2 / 4, so by Cauchy-Schwarz
/// |C|_F <= 2 sqrt(3) speed / dx, and gamma_dot <= sqrt(2) |D|_F <= sqrt(2) |C|_F. The step
/// control passes the particles' largest speed, as the wave bound does.
pub fn max_shear_rate(speed: f64, dx: f64) -> f64 {
    2.0 * 6f64.sqrt() * speed / dx
}
