//! The adjoint of one MLS-MPM step: recompute the step from its start state (keeping the two
//! things the forward overwrites in place and the adjoint needs: the particle state before the
//! step and the grid as P2G left it), then run the step's phases backwards:
//!
//! ```text
//! materials ─▶ wall clamp of positions ─▶ G2P ─▶ grid update (ghosts, walls) ─▶ P2G
//! ```
//!
//! `next` holds the adjoint of the state after the step and `cur` receives that of the state
//! before it; they swap roles every step. Masses and initial volumes change only when emission
//! sets them (a partial slab's fraction), so their adjoints accumulate over the steps in one
//! array each, and are settled and cleared at the step that set them.

use super::fields::Fields;
use super::grid_adjoint::{grid_update_adjoint, GridParamsBar};
use super::objective::{Frame, Objective, Seed};
use super::print_adjoint::PrintParams;
use crate::print::newest::{follow_feed_adjoint, FollowFeedBar};
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::material::UpdateAdjoint;
use crate::kernels::transfer::{Node, P2gInput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};
use crate::kernels::transfer_adjoint::{g2p_block_adjoint, p2g_block_adjoint, G2pAdjointIn, G2pAdjointOut, P2gAdjoint};
use crate::kernels::{Real, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use crate::solver::{balanced, flush_local, gather_local, Simulation};
use crate::threads::SharedSlice;
use std::time::Instant;

/// Most internal state reals any material keeps per particle.
const MAX_STATE: usize = 16;
/// Most parameters a material may offer.
const MAX_PARAMS: usize = 16;
/// Particles per partial sum of the material parameters' adjoints: fixed, so the sums do not
/// depend on the thread count.
const CHUNK: usize = 256;

/// Phases of a reversed step, as `StepAdjoint::phase_s` times them.
pub const PHASES: [&str; 6] = ["recompute", "materials", "g2p", "grid_update", "p2g", "emission"];

/// The adjoint of one MLS-MPM step for several seeds at once (a vector adjoint: several
/// objectives of one forward run, each with its own adjoint arrays); the step is recomputed once
/// and its tape shared.
pub struct StepAdjoint {
    /// The particle state at the start of the step being reversed.
    tape: Fields,
    /// Grid nodes after P2G, before the grid update.
    grid_tape: Pool<Node>,
    chunk_params: Vec<[f64; MAX_PARAMS]>,
    /// One adjoint per objective.
    pub seeds: Vec<Adjoint>,
    /// Wall seconds spent in each of `PHASES`, over all reversed steps.
    pub phase_s: [f64; PHASES.len()],
}

/// The adjoint arrays of one objective.
pub struct Adjoint {
    pub cur: Fields,
    pub next: Fields,
    pub mass_bar: Pool<Real>,
    pub vol0_bar: Pool<Real>,
    grid_bar: Pool<Node>,
    /// Adjoints of the material's parameters, in `param_names` order.
    pub material_bar: Vec<f64>,
    /// Density's adjoint through the masses emission set, settled step by step (the masses that
    /// never change are settled once at the end, from `mass_bar`).
    pub density_bar: f64,
    pub grid_params_bar: GridParamsBar,
}

/// A pool name for seed `k` (seed 0 keeps the plain names; mapped pools need distinct names).
fn named(name: &str, k: usize) -> String {
    if k == 0 {
        name.to_string()
    } else {
        format!("{name}.{k}")
    }
}

impl StepAdjoint {
    /// Bytes shared by all seeds (the tape) into `plan`, and those of `seeds` seeds' adjoints.
    pub fn plan(plan: &mut MemoryPlan, n: usize, state_len: usize, grid_nodes: usize, seeds: usize) {
        Fields::plan(plan, "grad.tape", n, state_len);
        plan.add::<Node>("grad.grid_tape", grid_nodes);
        for k in 0..seeds {
            Fields::plan(plan, &named("grad.adjoint_a", k), n, state_len);
            Fields::plan(plan, &named("grad.adjoint_b", k), n, state_len);
            plan.add::<Real>(&named("grad.mass_bar", k), n);
            plan.add::<Real>(&named("grad.vol0_bar", k), n);
            plan.add::<Node>(&named("grad.grid_bar", k), grid_nodes);
        }
    }

    pub fn new(sim: &Simulation, b: &Backing, seeds: usize) -> Result<StepAdjoint, String> {
        let n = sim.particles.capacity();
        if sim.material.param_names().len() > MAX_PARAMS || sim.particles.state_len > MAX_STATE {
            return Err(format!("material {}: the gradient driver takes at most {MAX_PARAMS} parameters and {MAX_STATE} state values", sim.material.name()));
        }
        Self::pools(sim, n, b, seeds).map_err(|e| e.to_string())
    }

    fn pools(sim: &Simulation, n: usize, b: &Backing, seeds: usize) -> Result<StepAdjoint, MemoryError> {
        let sl = sim.particles.state_len;
        let nodes = sim.grid.nodes.len();
        let adjoint = |k: usize| -> Result<Adjoint, MemoryError> {
            Ok(Adjoint {
                cur: Fields::new(&named("grad.adjoint_a", k), n, sl, b)?,
                next: Fields::new(&named("grad.adjoint_b", k), n, sl, b)?,
                mass_bar: Pool::new(&named("grad.mass_bar", k), n, b)?,
                vol0_bar: Pool::new(&named("grad.vol0_bar", k), n, b)?,
                grid_bar: Pool::new(&named("grad.grid_bar", k), nodes, b)?,
                material_bar: vec![0.0; sim.material.param_names().len()],
                density_bar: 0.0,
                grid_params_bar: GridParamsBar::default(),
            })
        };
        Ok(StepAdjoint {
            tape: Fields::new("grad.tape", n, sl, b)?,
            grid_tape: Pool::new("grad.grid_tape", nodes, b)?,
            chunk_params: vec![[0.0; MAX_PARAMS]; n.div_ceil(CHUNK)],
            seeds: (0..seeds).map(adjoint).collect::<Result<_, _>>()?,
            phase_s: [0.0; PHASES.len()],
        })
    }

    /// Reverse the step the live state of `sim` starts, for the seeds `active` marks (the others
    /// start later in the reverse sweep: their objectives come at earlier steps, their adjoints
    /// are still zero). `objectives` (seed, objective) are evaluated on the state after the step
    /// and seed those adjoints. The live state is consumed. Returns the objectives' values, in
    /// `objectives`' order.
    pub fn reverse(
        &mut self,
        sim: &mut Simulation,
        until: f64,
        objectives: &[(usize, &Objective)],
        frame: &Frame,
        active: &[bool],
        prints: &mut [Option<PrintParams>],
    ) -> Result<Vec<f64>, String> {
        let mut clock = Instant::now();
        let (dt, _) = sim.choose_dt(until);
        let dtr = dt as Real;
        let t = sim.time;

        // recompute the step, keeping what it overwrites
        let (n_before, first_slab) = (sim.particles.n, sim.printer.as_ref().map_or(0, |p| p.emitted()));
        sim.emit().map_err(|e| e.to_string())?;
        sim.newest_masses(0); // (gradients run without sleeping)
        let n = sim.particles.n;
        let drive = sim.printer.as_ref().and_then(|p| p.drive(t));
        self.tape.copy_from(sim);
        sim.bin_particles().map_err(|e| e.to_string())?;
        sim.clear_grid();
        sim.p2g(dtr);
        let used = sim.grid.n_active * NODES_PER_BLOCK;
        self.grid_tape.as_mut_slice()[..used].copy_from_slice(&sim.grid.nodes.as_slice()[..used]);
        sim.grid_update(dtr, drive.as_ref());
        sim.g2p(dtr);
        sim.follow_feed(dtr, drive.as_ref());
        let mut values = Vec::with_capacity(objectives.len());
        if !objectives.is_empty() {
            sim.update_materials(dtr).map_err(|e| e.to_string())?;
        }
        for &(k, obj) in objectives {
            let a = &mut self.seeds[k];
            let seed = Seed {
                xg: &mut a.next.xg.as_mut_slice()[..n],
                v: &mut a.next.v.as_mut_slice()[..n],
                j: &mut a.next.j.as_mut_slice()[..n],
                mass: &mut a.mass_bar.as_mut_slice()[..n],
                vol0: &mut a.vol0_bar.as_mut_slice()[..n],
            };
            values.push(obj.evaluate(sim, frame, Some(seed))?);
        }
        lap(&mut clock, &mut self.phase_s[0]);

        // every seed's materials adjoint reads the blended pool before the first follow-feed
        // adjoint hands the pool G2P's outputs back
        for (a, _) in self.seeds.iter_mut().zip(active).filter(|(_, on)| **on) {
            a.materials_adjoint(&self.tape, &mut self.chunk_params, sim, dtr);
        }
        lap(&mut clock, &mut self.phase_s[1]);
        let tp = TransferParams { dx: sim.scenario.simulation.dx as Real, dt: dtr };
        for ((a, pp), _) in self.seeds.iter_mut().zip(prints.iter_mut()).zip(active).filter(|(_, on)| **on) {
            let (feed_fraction_bar, v_feed_bar) = a.follow_feed_adjoint(sim, dtr);
            a.clamp_adjoint(sim);
            lap(&mut clock, &mut self.phase_s[1]);
            a.grid_bar.as_mut_slice()[..used].fill([0.0; 7]);
            a.g2p_adjoint(&self.tape, sim, &tp);
            lap(&mut clock, &mut self.phase_s[2]);
            let g = &mut a.grid_params_bar;
            grid_update_adjoint(sim, drive.as_ref(), &self.grid_tape.as_slice()[..used], &mut a.grid_bar.as_mut_slice()[..used], dtr, g);
            let (outlet_bar, velocity_bar) = (std::mem::take(&mut g.drive_outlet), std::mem::take(&mut g.drive_velocity));
            lap(&mut clock, &mut self.phase_s[3]);
            a.p2g_adjoint(&self.tape, sim, &tp);
            lap(&mut clock, &mut self.phase_s[4]);
            let mass_fraction_bar = a.settle_set_masses(sim);
            if let Some(pp) = pp.as_mut() {
                let k = sim.printer.as_ref().map_or(0, |p| p.toolpath.state_at(t).interval);
                if drive.is_some() {
                    let v = [velocity_bar[0] + v_feed_bar[0], velocity_bar[1] + v_feed_bar[1], velocity_bar[2] + v_feed_bar[2]];
                    pp.drive(k, t, outlet_bar, v);
                }
                if let Some(pr) = sim.printer.as_ref().filter(|p| p.newest.moving) {
                    pp.extruded(k, t, (mass_fraction_bar + feed_fraction_bar) / pr.plan.slab_thickness());
                }
                if n > n_before {
                    a.emission_adjoint(sim, pp, n_before, first_slab, t)?;
                }
            }
            std::mem::swap(&mut a.cur, &mut a.next);
            // particles beyond n were never touched by this step's adjoint
            a.cur.zero_range(0..n, sim.particles.state_len);
            lap(&mut clock, &mut self.phase_s[5]);
        }
        Ok(values)
    }
}

/// Add the time since `clock` to `acc` and restart the clock.
fn lap(clock: &mut Instant, acc: &mut f64) {
    let now = Instant::now();
    *acc += (now - *clock).as_secs_f64();
    *clock = now;
}

fn block_origin(sim: &Simulation, s: usize) -> [i32; 3] {
    let b = sim.grid.geom.block_coords(sim.grid.slot_block.as_slice()[s]);
    [b[0] * BLOCK_EDGE as i32, b[1] * BLOCK_EDGE as i32, b[2] * BLOCK_EDGE as i32]
}

impl Adjoint {
    /// Adjoint of the newest slab's blend with the feed (`print/newest.rs`): `next`'s adjoints
    /// of the blended outputs become those of G2P's, and the pool gets G2P's outputs back for
    /// the clamp's and G2P's adjoints. Returns the adjoints of the fraction and of the feed velocity.
    fn follow_feed_adjoint(&mut self, sim: &mut Simulation, dt: Real) -> (f64, [f64; 3]) {
        let Some(pr) = sim.printer.as_ref().filter(|p| p.newest.moving) else { return (0.0, [0.0; 3]) };
        let nw = &pr.newest;
        let t = sim.time;
        let v = pr.drive(t).map_or([0.0; 3], |d| d.velocity);
        let v_feed = V3::new(v[0] as Real, v[1] as Real, v[2] as Real);
        let inv_dx = (1.0 / sim.scenario.simulation.dx) as Real;
        let (mut fraction_bar, mut v_feed_bar) = (0.0, V3::ZERO);
        for (k, &i) in nw.index.iter().enumerate() {
            let i = i as usize;
            let out_bar = (self.next.xg.as_slice()[i], self.next.v.as_slice()[i], self.next.c.as_slice()[i], self.next.j.as_slice()[i]);
            let bar = FollowFeedBar {
                x0: &mut self.cur.xg.as_mut_slice()[i],
                j0: &mut self.cur.j.as_mut_slice()[i],
                v_feed: &mut v_feed_bar,
                fraction: &mut fraction_bar,
            };
            let (xb, vb, cb, jb) = follow_feed_adjoint(nw.fraction as Real, dt, inv_dx, nw.x0[k], nw.j0[k], v_feed, nw.g2p[k], out_bar, bar);
            self.next.xg.as_mut_slice()[i] = xb;
            self.next.v.as_mut_slice()[i] = vb;
            self.next.c.as_mut_slice()[i] = cb;
            self.next.j.as_mut_slice()[i] = jb;
            let p = &mut sim.particles;
            (p.xg.as_mut_slice()[i], p.v.as_mut_slice()[i], p.c.as_mut_slice()[i], p.j.as_mut_slice()[i]) = nw.g2p[k];
        }
        (fraction_bar, [v_feed_bar.x as f64, v_feed_bar.y as f64, v_feed_bar.z as f64])
    }

    /// The step's emission set the masses and initial volumes of particles `set_from..` (the
    /// newest slab's to its fraction f, a just completed one's to full): their adjoints gathered
    /// since are settled here — into the density's, and for the newest slab into f's — and
    /// cleared, for the earlier steps to gather those of the values before. Returns f's adjoint.
    fn settle_set_masses(&mut self, sim: &Simulation) -> f64 {
        let Some(pr) = sim.printer.as_ref() else { return 0.0 };
        let nw = &pr.newest;
        if nw.set_from == u32::MAX {
            return 0.0;
        }
        let p = &sim.particles;
        let rho = sim.material.density() as f64;
        let vol = pr.particle_volume;
        let (mass_bar, vol0_bar) = (self.mass_bar.as_mut_slice(), self.vol0_bar.as_mut_slice());
        let mut fraction_bar = 0.0;
        // emitted particles are never reordered in a gradient run: index = id
        for i in nw.set_from as usize..p.n {
            debug_assert_eq!(p.id.as_slice()[i] as usize, i);
            let (mb, vb) = (mass_bar[i] as f64, vol0_bar[i] as f64);
            self.density_bar += mb * p.mass.as_slice()[i] as f64 / rho;
            if i >= nw.first as usize {
                fraction_bar += rho * vol * mb + vol * vb;
            }
            (mass_bar[i], vol0_bar[i]) = (0.0, 0.0);
        }
        fraction_bar
    }

    /// Particles `first..n` entered in this step: their adjoints are those of the emission, owed
    /// to the toolpath and (through their initial state) the material; they did not exist before
    /// the step, so their adjoints end here.
    fn emission_adjoint(&mut self, sim: &Simulation, pp: &mut PrintParams, first: usize, first_slab: u64, t: f64) -> Result<(), String> {
        let p = &sim.particles;
        let (n, sl) = (p.n, p.state_len);
        let inv_dx = 1.0 / sim.scenario.simulation.dx;
        let x_bar: Vec<[f64; 3]> = self.cur.xg.as_slice()[first..n].iter().map(|b| [b.x as f64 * inv_dx, b.y as f64 * inv_dx, b.z as f64 * inv_dx]).collect();
        let v_bar: Vec<[f64; 3]> = self.cur.v.as_slice()[first..n].iter().map(|b| [b.x as f64, b.y as f64, b.z as f64]).collect();
        let plan = &sim.printer.as_ref().ok_or("emission without a printer")?.plan;
        pp.emission(plan, first_slab, t, &x_bar, &v_bar)?;
        let mut init = [0.0 as Real; MAX_PARAMS];
        let np = self.material_bar.len();
        for i in first..n {
            sim.material.init_state_adjoint(&self.cur.state.as_slice()[i * sl..(i + 1) * sl], &mut init[..np]);
        }
        for (m, v) in self.material_bar.iter_mut().zip(&init[..np]) {
            *m += *v as f64;
        }
        self.cur.zero_range(first..n, sl);
        Ok(())
    }

    /// Materials: `next.stress` and `next.state` (the adjoints of their outputs) go to the
    /// velocity gradient and volume ratio G2P produced (`next.c`, `next.j`), the state before the
    /// step (`cur.state`) and the parameters.
    fn materials_adjoint(&mut self, tape: &Fields, chunk_params: &mut [[f64; MAX_PARAMS]], sim: &Simulation, dt: Real) {
        let p = &sim.particles;
        let (n, sl) = (p.n, p.state_len);
        let (c1, j1) = (&p.c.as_slice()[..n], &p.j.as_slice()[..n]);
        let state0 = tape.state.as_slice();
        let mat = &*sim.material;
        let np = self.material_bar.len();
        let next_stress = self.next.stress.as_slice();
        let next_state = self.next.state.as_slice();
        let next_c = SharedSlice::new(&mut self.next.c.as_mut_slice()[..n]);
        let next_j = SharedSlice::new(&mut self.next.j.as_mut_slice()[..n]);
        let cur_state = SharedSlice::new(&mut self.cur.state.as_mut_slice()[..n * sl]);
        let chunks = n.div_ceil(CHUNK);
        let partial = SharedSlice::new(&mut chunk_params[..chunks]);
        let threads = sim.team.threads();
        sim.team.run(|tid| {
            for k in crate::threads::ThreadTeam::share(chunks, tid, threads) {
                // SAFETY: chunk k and its particles belong to this thread.
                let acc = unsafe { partial.get_mut(k) };
                *acc = [0.0; MAX_PARAMS];
                for i in k * CHUNK..((k + 1) * CHUNK).min(n) {
                    let mut out_bar = [0.0 as Real; MAX_STATE];
                    out_bar[..sl].copy_from_slice(&next_state[i * sl..(i + 1) * sl]);
                    let mut params = [0.0 as Real; MAX_PARAMS];
                    let mut adj = unsafe {
                        UpdateAdjoint {
                            grad_v_bar: next_c.get_mut(i),
                            j_bar: next_j.get_mut(i),
                            state_bar: cur_state.slice_mut(i * sl..(i + 1) * sl),
                            params_bar: &mut params[..np],
                        }
                    };
                    mat.update_adjoint(&c1[i], j1[i], dt, &state0[i * sl..(i + 1) * sl], &next_stress[i], &out_bar[..sl], &mut adj);
                    for (a, v) in acc.iter_mut().zip(&params[..np]) {
                        *a += *v as f64;
                    }
                }
            }
        });
        // chunk sums in chunk order: the same bits for any thread count
        for acc in &chunk_params[..chunks] {
            for (m, a) in self.material_bar.iter_mut().zip(acc) {
                *m += a;
            }
        }
    }

    /// G2P's caller projects positions that left the domain back onto its walls (and the
    /// platform): the clamped coordinates no longer depend on anything.
    fn clamp_adjoint(&mut self, sim: &Simulation) {
        let geom = &sim.grid.geom;
        let x1 = sim.particles.xg.as_slice();
        let bar = self.next.xg.as_mut_slice();
        let platform = sim.walls.platform;
        for i in 0..sim.particles.n {
            for a in 0..3 {
                if !geom.periodic[a] && (x1[i][a] == geom.lo[a] as Real || x1[i][a] == geom.hi[a] as Real) {
                    bar[i][a] = 0.0;
                }
            }
            if let Some((z, xy, _)) = platform {
                let x = x1[i];
                if x.z == z && x.x >= xy[0] && x.x <= xy[2] && x.y >= xy[1] && x.y <= xy[3] {
                    bar[i].z = 0.0;
                }
            }
        }
    }

    /// G2P's adjoint scatters into the grid adjoint as P2G scatters into the grid: by colour,
    /// so threads never add to the same node and every node sums in the same order.
    fn g2p_adjoint(&mut self, tape: &Fields, sim: &Simulation, tp: &TransferParams) {
        let n = sim.particles.n;
        let sc = &sim.scratch;
        let starts = sc.slot_start.as_slice();
        let order = sc.order.as_slice();
        let nbr = sc.nbr.as_slice();
        let nodes = sim.grid.nodes.as_slice();
        let flip = sim.scenario.simulation.flip as Real;
        let vol0 = &sim.particles.vol0.as_slice()[..n];
        let j_bar_avg = sim.scenario.simulation.j_bar.then_some(vol0);
        let grid_bar = SharedSlice::new(self.grid_bar.as_mut_slice());
        let (x0, v0, j0) = (&tape.xg.as_slice()[..n], &tape.v.as_slice()[..n], &tape.j.as_slice()[..n]);
        // the recomputed G2P's v and C are still in the pool (the blend with the feed undone)
        let forward = (flip == 0.0).then(|| (&sim.particles.v.as_slice()[..n], &sim.particles.c.as_slice()[..n]));
        let next = (&self.next.xg.as_slice()[..n], &self.next.v.as_slice()[..n], &self.next.c.as_slice()[..n], &self.next.j.as_slice()[..n]);
        let cur_xg = SharedSlice::new(&mut self.cur.xg.as_mut_slice()[..n]);
        let cur_v = SharedSlice::new(&mut self.cur.v.as_mut_slice()[..n]);
        let cur_j = SharedSlice::new(&mut self.cur.j.as_mut_slice()[..n]);
        let vol0_bar = SharedSlice::new(&mut self.vol0_bar.as_mut_slice()[..n]);
        let threads = sim.team.threads();
        for c in 0..8 {
            let (c0, c1) = (sc.colour_start[c], sc.colour_start[c + 1]);
            if c0 == c1 {
                continue;
            }
            let blocks = &sc.colour_blocks.as_slice()[c0..c1];
            let cum = &sc.colour_cum.as_slice()[c0..c1];
            let last = *blocks.last().unwrap() as usize;
            let total = cum[cum.len() - 1] + (starts[last + 1] - starts[last]);
            sim.team.run(|tid| {
                let (lo, hi) = balanced(cum, total, tid, threads);
                let mut local = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                let mut local_bar = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
                let (mut dt_bar, mut dx_bar) = (0.0, 0.0);
                for &s in &blocks[lo..hi] {
                    let s = s as usize;
                    gather_local(&mut local, &nbr[s], nodes);
                    local_bar.iter_mut().for_each(|l| *l = [0.0; 7]);
                    let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                    let inp = G2pAdjointIn { local: &local, xg: x0, v: v0, j: j0, forward, xg_bar: next.0, v_bar: next.1, c_bar: next.2, jac_bar: next.3 };
                    // SAFETY: a particle belongs to one block and a block to one thread; within a
                    // colour, block neighbourhoods are disjoint.
                    let mut out = unsafe {
                        G2pAdjointOut {
                            local_bar: &mut local_bar,
                            xg_bar: cur_xg.slice_mut(0..n),
                            v_bar: cur_v.slice_mut(0..n),
                            jac_bar: cur_j.slice_mut(0..n),
                            vol0_bar: vol0_bar.slice_mut(0..n),
                            dt_bar: &mut dt_bar,
                            dx_bar: &mut dx_bar,
                        }
                    };
                    g2p_block_adjoint(block_origin(sim, s), ord, flip, j_bar_avg, tp, &inp, &mut out);
                    unsafe { flush_local(&local_bar, &nbr[s], &grid_bar) };
                }
            });
        }
    }

    /// P2G's adjoint gathers from the grid adjoint as G2P gathers from the grid: particle
    /// blocks split across threads by particle count.
    fn p2g_adjoint(&mut self, tape: &Fields, sim: &Simulation, tp: &TransferParams) {
        let n = sim.particles.n;
        let sc = &sim.scratch;
        let npb = sim.grid.n_particle_blocks;
        let starts = &sc.slot_start.as_slice()[..npb + 1];
        let order = sc.order.as_slice();
        let nbr = sc.nbr.as_slice();
        let p = &sim.particles;
        let input = P2gInput {
            xg: &tape.xg.as_slice()[..n],
            v: &tape.v.as_slice()[..n],
            c: &tape.c.as_slice()[..n],
            stress: &tape.stress.as_slice()[..n],
            mass: &p.mass.as_slice()[..n],
            vol0: &p.vol0.as_slice()[..n],
            j: &tape.j.as_slice()[..n],
        };
        let split = sim.scenario.simulation.flip > 0.0;
        let grid_bar = self.grid_bar.as_slice();
        let cur = (
            SharedSlice::new(&mut self.cur.xg.as_mut_slice()[..n]),
            SharedSlice::new(&mut self.cur.v.as_mut_slice()[..n]),
            SharedSlice::new(&mut self.cur.c.as_mut_slice()[..n]),
            SharedSlice::new(&mut self.cur.stress.as_mut_slice()[..n]),
            SharedSlice::new(&mut self.cur.j.as_mut_slice()[..n]),
        );
        let mass_bar = SharedSlice::new(&mut self.mass_bar.as_mut_slice()[..n]);
        let vol0_bar = SharedSlice::new(&mut self.vol0_bar.as_mut_slice()[..n]);
        let threads = sim.team.threads();
        sim.team.run(|tid| {
            let (lo, hi) = balanced(&starts[..npb], starts[npb], tid, threads);
            let mut local_bar = [[0.0 as Real; 7]; NEIGHBOURHOOD_NODES];
            let (mut dt_bar, mut dx_bar) = (0.0, 0.0);
            for s in lo..hi {
                gather_local(&mut local_bar, &nbr[s], grid_bar);
                let ord = &order[starts[s] as usize..starts[s + 1] as usize];
                // SAFETY: every particle belongs to one block and every block to one thread.
                let mut out = unsafe {
                    P2gAdjoint {
                        xg_bar: cur.0.slice_mut(0..n),
                        v_bar: cur.1.slice_mut(0..n),
                        c_bar: cur.2.slice_mut(0..n),
                        stress_bar: cur.3.slice_mut(0..n),
                        mass_bar: mass_bar.slice_mut(0..n),
                        vol0_bar: vol0_bar.slice_mut(0..n),
                        jac_bar: cur.4.slice_mut(0..n),
                        dt_bar: &mut dt_bar,
                        dx_bar: &mut dx_bar,
                    }
                };
                let origin = block_origin(sim, s);
                if split {
                    p2g_block_adjoint::<true>(origin, ord, &input, tp, &local_bar, &mut out);
                } else {
                    p2g_block_adjoint::<false>(origin, ord, &input, tp, &local_bar, &mut out);
                }
            }
        });
    }
}
