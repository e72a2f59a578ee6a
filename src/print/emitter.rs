//! The emission stage of the pipeline: a thread that lays out each new slab of particles ahead of
//! time and hands it to the stepper through a bounded lock-free queue.
//!
//! Material enters the nozzle through the top of its tube at the extrusion speed U; the tube
//! starts full. Slabs are `group` particle layers thick (s = group h). Two rules:
//!
//! - **continuous** (group 1): slab q is added as soon as it starts entering, when the pushed
//!   length L(t) + H passes q s, and until it is wholly in its particles carry the fraction
//!   f = (L + H) / s - q of their mass and volume (the stepper sets it every step). The mass in the
//!   simulation is then rho A (L(t) + H) at every step, a continuous function of the toolpath's
//!   parameters: an extrusion-speed gradient sees the mass it adds, which a slab arriving whole
//!   at a step boundary hides (the mass would be a staircase in U with zero derivative).
//! - **interval** (000 sec. 2.4): slab q is added whole once L + H covers (q + 1) s.
//!
//! The emitter gives each slab the time it is added (`due`) and its positions at that time; the
//! stepper adds it at the first step starting at or after, advancing the positions
//! ballistically by the lag (inside the tube the grid moves material at exactly that velocity).
//! Every particle stands for `particle_volume`, chosen so the mass flux is rho A U exactly,
//! whatever the lattice's fit to the outlet.
//!
//! Slab buffers are allocated once and circulate between a `full` and a `free` queue, so the
//! steady state allocates nothing; the contents depend only on the toolpath, never on timing.

use super::laid::LaidLattice;
use super::toolpath::Toolpath;
use crossbeam::channel::{bounded, Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;

/// What the emitter needs to lay out slabs.
#[derive(Clone)]
pub struct EmissionPlan {
    pub toolpath: Arc<Toolpath>,
    /// Horizontal lattice offsets inside the outlet.
    pub offsets: Arc<Vec<[f64; 2]>>,
    /// Particle spacing h.
    pub spacing: f64,
    /// Layers per slab: 1 (continuous) or particles per cell axis (one cell, 000 sec. 2.4).
    pub group: u32,
    /// Tube height H above the outlet.
    pub tube_height: f64,
    /// Material region of the domain: points outside are not emitted, so a domain cut at a
    /// symmetry plane through the nozzle axis receives exactly its half of the flux.
    pub domain: ([f64; 3], [f64; 3]),
    /// Slabs enter with the fraction of their mass extruded so far (continuous emission).
    pub partial: bool,
    /// A laid deposit instead (`print::laid`): its column lattice and the pushed length each
    /// column holds; a slab is then one column.
    pub laid: Option<(Arc<LaidLattice>, f64)>,
}

impl EmissionPlan {
    /// Slab thickness s.
    pub fn slab_thickness(&self) -> f64 {
        self.group as f64 * self.spacing
    }

    /// Number of slabs the whole toolpath emits.
    pub fn slabs(&self) -> u64 {
        if let Some((_, per_column)) = &self.laid {
            return (self.toolpath.total_extruded_length() / per_column + 1e-9).floor() as u64;
        }
        let pushed = (self.toolpath.total_extruded_length() + self.tube_height) / self.slab_thickness();
        if self.partial {
            // every slab that has started entering, the last one possibly in part
            (pushed - 1e-9).ceil().max(0.0) as u64
        } else {
            (pushed + 1e-9).floor() as u64
        }
    }

    /// Fraction of slab `q`'s mass inside the tube at time `t` (1 without partial slabs), and
    /// whether it is strictly between 0 and 1, where it moves with the extruded length.
    pub fn fraction(&self, q: u64, t: f64) -> (f64, bool) {
        if !self.partial {
            return (1.0, false);
        }
        let f = (self.toolpath.extruded_length(t) + self.tube_height) / self.slab_thickness() - q as f64;
        (f.clamp(0.0, 1.0), f > 0.0 && f < 1.0)
    }

    pub fn particles_per_slab(&self) -> usize {
        if let Some((lattice, _)) = &self.laid {
            return lattice.particles();
        }
        self.offsets.len() * self.group as usize
    }

    /// Upper bound of the particles the whole toolpath emits (every lattice point inside).
    pub fn total_particles(&self) -> u64 {
        self.slabs() * self.particles_per_slab() as u64
    }

    /// Lay out slab `q` into `b`.
    pub fn fill(&self, q: u64, b: &mut Slab) {
        b.positions.clear();
        let (due, moves, velocity) = self.layout(q, None, |x| b.positions.push(x));
        (b.slab, b.due, b.moves, b.velocity) = (q, due, moves, velocity);
    }

    /// As [`EmissionPlan::fill`], with the moves that set the slab's due time and state held to
    /// `branch` (another plan's `Slab::moves` for the same slab): the branch a derivative with
    /// respect to the toolpath's parameters differentiates.
    pub fn fill_on(&self, q: u64, b: &mut Slab, branch: (Option<usize>, usize)) {
        b.positions.clear();
        let (due, moves, velocity) = self.layout(q, Some(branch), |x| b.positions.push(x));
        (b.slab, b.due, b.moves, b.velocity) = (q, due, moves, velocity);
    }

    /// Number of particles slab `q` adds (its lattice points inside the domain).
    pub fn count(&self, q: u64) -> usize {
        let mut k = 0;
        self.layout(q, None, |_| k += 1);
        k
    }

    /// Whether `x` lies in the material region of the domain (points outside are not emitted).
    fn inside(&self, x: &[f64; 3]) -> bool {
        (0..3).all(|a| x[a] >= self.domain.0[a] && x[a] <= self.domain.1[a])
    }

    /// Slab `q`'s positions at its due time, each handed to `put`; returns the due time, the
    /// moves that set it (see `Slab::moves`) and the particles' velocity.
    fn layout(&self, q: u64, branch: Option<(Option<usize>, usize)>, mut put: impl FnMut([f64; 3])) -> (f64, (Option<usize>, usize), [f64; 3]) {
        if let Some((lattice, per_column)) = &self.laid {
            let due = lattice.layout(&self.toolpath, q, *per_column, |x| if self.inside(&x) { put(x) });
            let need = (q + 1) as f64 * per_column;
            let extruding = self.toolpath.move_extruding(need).flatten();
            return (due, (extruding, self.toolpath.state_at(due).interval), [0.0; 3]);
        }
        let h = self.spacing;
        let slab = self.slab_thickness();
        // a partial slab is added one slab thickness earlier, still above the tube
        let lead = if self.partial { slab } else { 0.0 };
        let need = (q + 1) as f64 * slab - self.tube_height - lead;
        let tp = &self.toolpath;
        let (extruding, due) = match branch {
            Some((Some(k), _)) => (Some(k), tp.time_at_extruded_on(k, need)),
            Some((None, _)) => (None, 0.0),
            None if need <= 0.0 => (None, 0.0),
            None => (tp.move_extruding(need).flatten(), tp.time_at_extruded_length(need).unwrap_or(f64::INFINITY)),
        };
        let at = match branch {
            Some((_, k)) => k,
            None => tp.state_at(due).interval,
        };
        let st = tp.state_on(at, due);
        // the tube is pre-filled at t = 0: those slabs already sit deeper
        let excess = (tp.extruded_on(at, due) + self.tube_height + lead - (q + 1) as f64 * slab).max(0.0);
        let z_top = st.position[2] + self.tube_height + lead;
        for m in 0..self.group {
            let z = z_top - 0.5 * h - excess - m as f64 * h;
            for o in self.offsets.iter() {
                let x = [st.position[0] + o[0], st.position[1] + o[1], z];
                if self.inside(&x) {
                    put(x);
                }
            }
        }
        (due, (extruding, at), [st.velocity[0], st.velocity[1], st.velocity[2] - st.extrusion_speed])
    }
}

/// One slab of new particles.
pub struct Slab {
    pub slab: u64,
    /// Time at which the slab is added [s]: when it starts entering the tube (continuous) or
    /// is wholly inside it (interval).
    pub due: f64,
    /// Velocity of every particle of the slab at `due`.
    pub velocity: [f64; 3],
    /// The move whose extrusion sets `due` (None when the slab starts in the pre-filled tube)
    /// and the move in effect at `due`.
    pub moves: (Option<usize>, usize),
    /// World positions at `due`.
    pub positions: Vec<[f64; 3]>,
}

pub struct Emitter {
    full: Receiver<Box<Slab>>,
    free: Sender<Box<Slab>>,
    pending: Option<Box<Slab>>,
    worker: Option<JoinHandle<()>>,
    /// Slabs handed to the stepper so far.
    pub emitted: u64,
}

impl Emitter {
    /// Start the emitter thread with `buffers` slab buffers in flight, emitting slabs
    /// `first..plan.slabs()` (a resumed run starts past 0).
    pub fn spawn(plan: EmissionPlan, buffers: usize, first: u64) -> Emitter {
        let buffers = buffers.max(2);
        let (full_tx, full_rx) = bounded::<Box<Slab>>(buffers);
        let (free_tx, free_rx) = bounded::<Box<Slab>>(buffers);
        let per = plan.particles_per_slab();
        for _ in 0..buffers {
            let b = Box::new(Slab { slab: 0, due: 0.0, velocity: [0.0; 3], moves: (None, 0), positions: Vec::with_capacity(per) });
            free_tx.send(b).expect("free queue has room for every buffer");
        }
        let total = plan.slabs();
        let worker = std::thread::Builder::new()
            .name("strand-emitter".into())
            .spawn(move || {
                for q in first..total {
                    // the stepper dropped its end: the run is over
                    let Ok(mut b) = free_rx.recv() else { return };
                    plan.fill(q, &mut b);
                    if full_tx.send(b).is_err() {
                        return;
                    }
                }
            })
            .expect("cannot spawn the emitter thread");
        Emitter { full: full_rx, free: free_tx, pending: None, worker: Some(worker), emitted: first }
    }

    /// Hand every slab due at or before `t` to `add`, in order. Blocks only when the emitter
    /// has fallen behind the stepper.
    pub fn drain_due<E>(&mut self, t: f64, mut add: impl FnMut(&Slab) -> Result<(), E>) -> Result<(), E> {
        loop {
            if self.pending.is_none() {
                match self.full.recv() {
                    Ok(b) => self.pending = Some(b),
                    Err(_) => return Ok(()), // every slab emitted
                }
            }
            let b = self.pending.as_ref().expect("just filled");
            if b.due > t {
                return Ok(());
            }
            add(b)?;
            self.emitted += 1;
            let b = self.pending.take().expect("just checked");
            // the emitter may have finished and dropped its end: the buffer is then not needed
            let _ = self.free.send(b);
        }
    }
}

impl Drop for Emitter {
    fn drop(&mut self) {
        // Dropping the queues ends the worker's loop; wait for it so no thread outlives the run.
        let (_, dead_rx) = bounded::<Box<Slab>>(0);
        self.full = dead_rx;
        let (dead_tx, _) = bounded::<Box<Slab>>(0);
        self.free = dead_tx;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}
