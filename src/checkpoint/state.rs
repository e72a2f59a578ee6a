//! What of a `Simulation` a checkpoint holds, and putting it back.
//!
//! A checkpoint is taken in the middle of a step, between the grid update and G2P
//! (`Simulation::begin_step` / `finish_step`): there the rest of the step needs only the grid's
//! node velocities and, per particle, x, J, the material state and the id (v too with FLIP);
//! C and the stress are produced again by G2P and the material update. Everything else is
//! rebuilt rather than stored (see DESIGN.md, "Checkpoints and resume", for the field table):
//!
//! - mass and vol0 from the ids (creation order): the bodies' lattice volumes, the printer's
//!   particle volume, and the newest slab's fraction from the slab count; their checksums in the
//!   header prove the rebuilt arrays equal the run's (a run merging sleeping particles,
//!   `[sleep] coarsen`, stores mass, vol0 and the next id instead: merged particles are no
//!   longer what their ids say);
//! - sleeping particles' v, C and stress from (state, J): a particle falling asleep is put
//!   at rest, which is exactly that (`sleep::put_at_rest`);
//! - the step's binning and block slots by binning the restored positions again (the saved
//!   grid's stored pools prove it gave the same slots); the per-block activity by G2P.
//!
//! Which pools are stored, under which sections, comes from `layout.rs`'s walk of the pool
//! tables; restore puts each slot back by its owner and role.

use super::format::{checksum, state_hash, Checkpoint, Header, Section};
use super::layout::{at_section, awake_section, counts_now, full_state, layout, node_channels, slots, Owner, Slot};
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::transfer::Node;
use crate::kernels::Real;
use crate::particles::NEXT_ID;
use crate::pools::{Counts, Role};
use crate::solver::{DtLimit, SimError, Simulation};
use std::mem::size_of;

pub use super::layout::{sections, staging_bytes, Part, Source};

fn bytes<T: bytemuck::Pod>(s: &[T]) -> &[u8] {
    bytemuck::cast_slice(s)
}

/// Bytes of the restart state per particle with reals of `real_bytes` bytes (4 for f32, 8 for
/// f64): every section of the checkpoint (particles, grid, sleep tables) over the particles.
pub fn restart_bytes_per_particle_with(sim: &Simulation, real_bytes: usize) -> f64 {
    let total: usize = sections(sim).iter().map(|s| s.len - s.reals * size_of::<Real>() + s.reals * real_bytes).sum();
    total as f64 / sim.particles.n.max(1) as f64
}

/// Bytes of the restart state per particle in this build's precision (see
/// [`restart_bytes_per_particle_with`]).
pub fn restart_bytes_per_particle(sim: &Simulation) -> f64 {
    restart_bytes_per_particle_with(sim, size_of::<Real>())
}

/// Hash of the whole state at a step boundary (`strand run --json`'s `state_hash`).
pub fn current_state_hash(sim: &Simulation) -> u64 {
    let secs: Vec<Section> = full_state(sim)
        .into_iter()
        .map(|(name, b)| Section { name: name.into(), offset: 0, bytes: b.len() as u64, xxh3: checksum(b) })
        .collect();
    state_hash(sim.step, sim.time, &secs)
}

/// Run-level progress a checkpoint carries so a resumed run continues its outputs.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Progress {
    /// ParaView collection entries so far.
    pub pvd: Vec<(f64, String)>,
    /// Observables at each output so far.
    pub observations: Vec<crate::report::Observation>,
    /// `Simulation::external_work` at the step's start (absent in older checkpoints: 0).
    #[serde(default)]
    pub external_work: f64,
}

/// The header of a checkpoint of `sim` in the middle of a step of length `dt` (bound by
/// `limit`), sections given with their checksums.
pub fn header(sim: &Simulation, dt: f64, limit: DtLimit, outputs: u64, progress: &Progress, sections: Vec<Section>) -> Header {
    let p = &sim.particles;
    let n = p.n;
    Header {
        strand_version: env!("CARGO_PKG_VERSION").to_string(),
        precision: crate::kernels::real::NAME.to_string(),
        scenario_name: sim.scenario.name.clone(),
        scenario_hash: checksum(sim.scenario.source.as_bytes()),
        scenario_text: sim.scenario.source.clone(),
        toolpath_hash: toolpath_hash(sim),
        step: sim.step,
        time: sim.time,
        dt,
        dt_limit: limit.name().to_string(),
        particles: n as u64,
        asleep: p.n_sleep as u64,
        capacity: p.capacity() as u64,
        state_len: p.state_len as u32,
        active_blocks: sim.grid.n_active as u64,
        particle_blocks: sim.grid.n_particle_blocks as u64,
        sleeping_units: sim.sleep.as_ref().map_or(0, |s| s.sleeping_units as u64),
        table_len: sim.grid.geom.table_len() as u64,
        emitted_slabs: emitted_slabs(sim),
        mass_xxh3: checksum(bytes(&p.mass.as_slice()[..n])),
        vol0_xxh3: checksum(bytes(&p.vol0.as_slice()[..n])),
        outputs,
        progress_json: serde_json::to_string(progress).unwrap_or_default(),
        state_hash: state_hash(sim.step, sim.time, &sections),
        written_unix: std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()),
        sections,
    }
}

fn emitted_slabs(sim: &Simulation) -> u64 {
    sim.printer.as_ref().map_or(0, |p| p.emitted())
}

/// xxh3 of the resolved toolpath, 0 when not printing.
pub fn toolpath_hash(sim: &Simulation) -> u64 {
    sim.printer.as_ref().map_or(0, |p| checksum(format!("{:?}", p.toolpath.moves()).as_bytes()))
}

/// Why a checkpoint cannot be put into a simulation.
#[derive(Debug, thiserror::Error)]
pub enum RestoreError {
    /// The checkpoint and the scenario (or this build of strand) differ: precision, material
    /// state, pool size, grid, FLIP, sleeping, merging, or the arrays rebuilt from the scenario.
    #[error("{0}")]
    Mismatch(String),
    #[error("section '{0}' is missing")]
    MissingSection(String),
    #[error("section '{name}' has {found} bytes, expected {expected}")]
    SectionSize { name: String, found: usize, expected: usize },
    /// The checkpoint's contents disagree with each other or with its header.
    #[error("{0}")]
    Inconsistent(String),
    /// Binning the restored particles failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    SleepState(#[from] crate::sleep::BadUnitState),
}

/// Refuse a checkpoint `sim` cannot take: another precision, material state, pool size, grid,
/// FLIP setting, sleeping or merging.
fn check_compatible(sim: &Simulation, ck: &Checkpoint) -> Result<(), RestoreError> {
    let h = &ck.header;
    let precision = crate::kernels::real::NAME;
    if h.precision != precision {
        return Err(RestoreError::Mismatch(format!("the checkpoint holds {} reals, this strand is built for {precision}", h.precision)));
    }
    let sl = sim.particles.state_len;
    if h.state_len as usize != sl {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint's material keeps {} state values per particle, the scenario's keeps {sl}",
            h.state_len
        )));
    }
    if h.particles as usize > sim.particles.capacity() {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint holds {} particles, the pool has room for {} ([memory] max_particles)",
            h.particles,
            sim.particles.capacity()
        )));
    }
    if h.table_len as usize != sim.grid.geom.table_len() {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint's grid has {} blocks, the scenario's {} (domain or dx changed)",
            h.table_len,
            sim.grid.geom.table_len()
        )));
    }
    let flip = sim.scenario.simulation.flip > 0.0;
    let all = slots(sim);
    let awake = all.iter().find(|s| s.role == Role::FlipVelocity).map(|s| awake_section(&s.name));
    if flip != awake.is_some_and(|a| ck.section(&a).is_some()) {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint was written {} FLIP, the scenario runs {} it (simulation.flip)",
            if flip { "without" } else { "with" },
            if flip { "with" } else { "without" }
        )));
    }
    if sleeping_differs(sim, ck) {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint and the scenario differ in sleeping ([sleep]): the checkpoint's material {}, the scenario's {} \
             (some prints sleep without [sleep], docs/printing.md \"Sleeping by default\"; [sleep] enabled = false keeps one awake)",
            if sim.sleep.is_some() { "stays awake" } else { "sleeps" },
            if sim.sleep.is_some() { "sleeps" } else { "stays awake" }
        )));
    }
    if super::layout::coarsens(sim) != ck.section(NEXT_ID).is_some() {
        return Err(RestoreError::Mismatch("the checkpoint and the scenario differ in merging sleeping particles ([sleep] coarsen)".into()));
    }
    Ok(())
}

/// Whether `sim` sleeps and `ck` lacks the first sleep table, or `sim` does not sleep and `ck`
/// holds sections `sim`'s checkpoints do not (its sleep tables).
fn sleeping_differs(sim: &Simulation, ck: &Checkpoint) -> bool {
    let file = layout(sim);
    if sim.sleep.is_some() {
        let first = file.iter().find(|s| s.owner == Owner::Sleep && s.role == Role::Sparse);
        return first.is_none_or(|s| ck.section(&at_section(&s.name)).is_none());
    }
    let expected: Vec<String> = sections(sim).into_iter().map(|p| p.name).collect();
    ck.header.sections.iter().any(|s| !expected.contains(&s.name))
}

/// Put the checkpoint's state into `sim`, freshly built from a compatible scenario, leaving it
/// in the middle of the step the checkpoint was taken in: the caller finishes that step with
/// `Simulation::finish_step` and the returned step length (and records its bound). Fails,
/// naming the mismatch, when the pools, the grid or the rebuilt arrays do not fit.
pub fn restore(sim: &mut Simulation, ck: &Checkpoint) -> Result<(f64, DtLimit), RestoreError> {
    let h = &ck.header;
    check_compatible(sim, ck)?;
    let limit = DtLimit::from_name(&h.dt_limit).ok_or_else(|| RestoreError::Inconsistent(format!("unknown time-step bound '{}'", h.dt_limit)))?;
    let n = h.particles as usize;
    let asleep = h.asleep as usize;
    if asleep > n {
        return Err(RestoreError::Inconsistent(format!("the checkpoint has {asleep} particles asleep of {n}")));
    }
    let at = Counts { particles: n, blocks: h.active_blocks as usize, particle_blocks: h.particle_blocks as usize };
    let masses = MassSource::of(sim);
    restore_particles(sim, ck, &at, asleep, &masses)?;
    sim.step = h.step;
    sim.time = h.time;
    // the external work done so far, which no section holds (the run's progress carries it)
    sim.external_work = serde_json::from_str::<Progress>(&h.progress_json).map_or(0.0, |p| p.external_work);
    restart_printer(sim, h);
    // every particle: the rebuilt masses of a sleeping slab's particles are full ones
    sim.newest_masses(0);
    check_rebuilt(sim, h)?;
    restore_sleep(sim, ck)?;
    restore_grid(sim, ck, &at)?;
    Ok((h.dt, limit))
}

/// Where a particle's mass and initial volume come from when the checkpoint does not store
/// them: the fresh simulation holds the bodies' particles, ids 0..fresh, with the masses and
/// volumes the run gave them (runs of equal values, one per body); ids from `fresh` on were
/// printed, each with the nozzle's particle.
struct MassSource {
    fresh: usize,
    /// (first particle, mass, initial volume) of each run of equal values.
    bodies: Vec<(usize, Real, Real)>,
    printed: Option<(Real, Real)>,
}

impl MassSource {
    fn of(sim: &Simulation) -> MassSource {
        let fresh = sim.particles.n;
        let mut bodies: Vec<(usize, Real, Real)> = Vec::new();
        for i in 0..fresh {
            let (m, v) = (sim.particles.mass.as_slice()[i], sim.particles.vol0.as_slice()[i]);
            if bodies.last().is_none_or(|&(_, bm, bv)| bm.to_bits() != m.to_bits() || bv.to_bits() != v.to_bits()) {
                bodies.push((i, m, v));
            }
        }
        let rho = sim.material.density() as f64;
        let printed = sim.printer.as_ref().map(|pr| ((rho * pr.particle_volume) as Real, pr.particle_volume as Real));
        MassSource { fresh, bodies, printed }
    }

    /// The mass and initial volume of the particle with id `id`.
    fn of_id(&self, id: usize) -> Result<(Real, Real), RestoreError> {
        if id < self.fresh {
            let k = self.bodies.partition_point(|b| b.0 <= id) - 1;
            return Ok((self.bodies[k].1, self.bodies[k].2));
        }
        let fresh = self.fresh;
        self.printed.ok_or_else(|| RestoreError::Inconsistent(format!("particle id {id} was not created by the scenario's bodies ({fresh} particles) and it does not print")))
    }
}

/// The particle pools: the stored ones, the awake velocities under FLIP, and the ids, masses
/// and volumes (stored when merging, with the next id, else rebuilt from the ids); the rebuilt
/// ones zero (C and the stress of awake particles come from G2P and the material update of this
/// step), the sleeping particles' at rest.
fn restore_particles(sim: &mut Simulation, ck: &Checkpoint, at: &Counts, asleep: usize, masses: &MassSource) -> Result<(), RestoreError> {
    let n = at.particles;
    for s in slots(sim).iter().filter(|s| s.owner == Owner::Particles && matches!(s.role, Role::Rebuilt | Role::FlipVelocity)) {
        let len = s.bytes_for(sim, at);
        s.bytes_mut(sim)[..len].fill(0);
    }
    let file: Vec<Slot> = layout(sim).into_iter().filter(|s| s.owner == Owner::Particles).collect();
    for s in &file {
        let size = s.elem_bytes(sim);
        let (range, name) = match s.role {
            Role::FlipVelocity => (asleep * size..n * size, awake_section(&s.name)),
            _ => (0..s.bytes_for(sim, at), s.name.to_string()),
        };
        let dst = &mut s.bytes_mut(sim)[range];
        dst.copy_from_slice(section(ck, &name, dst.len())?);
    }
    let p = &mut sim.particles;
    p.n = n;
    p.n_sleep = asleep;
    if !file.iter().any(|s| s.role == Role::FromIds) {
        // without merging, ids are 0..n in some order
        p.next_id = n as u32;
        for i in 0..n {
            let (m, v) = masses.of_id(p.id.as_slice()[i] as usize)?;
            p.mass.as_mut_slice()[i] = m;
            p.vol0.as_mut_slice()[i] = v;
        }
    }
    for i in 0..asleep {
        crate::sleep::put_at_rest(p, i, &*sim.material);
    }
    Ok(())
}

/// Start the printer's emitter where the checkpoint left off.
fn restart_printer(sim: &mut Simulation, h: &Header) {
    if let Some(pr) = &mut sim.printer {
        let queue = sim.scenario.print.as_ref().map_or(64, |c| c.queue);
        // stop the emitter started at slab 0 before starting one where the checkpoint left off
        pr.emitter = None;
        pr.start(queue, h.emitted_slabs);
        // this step's emission already happened: only the newest slab's fraction matters
        crate::solver::note_newest(pr, h.time, sim.particles.next_id, h.emitted_slabs, sim.particles.next_id);
    }
}

/// Refuse rebuilt masses or volumes that differ from the run's (their checksums in `h`).
fn check_rebuilt(sim: &Simulation, h: &Header) -> Result<(), RestoreError> {
    let n = h.particles as usize;
    for (what, arr, want) in
        [("masses", &sim.particles.mass, h.mass_xxh3), ("initial volumes", &sim.particles.vol0, h.vol0_xxh3)]
    {
        if checksum(bytes(&arr.as_slice()[..n])) != want {
            return Err(RestoreError::Mismatch(format!(
                "the particle {what} rebuilt from the scenario differ from the run's (its bodies or print changed?)"
            )));
        }
    }
    Ok(())
}

/// The sleeping tables (when the scenario sleeps), scattered back from their sparse sections,
/// and the counts rebuilt from them checked against the header.
fn restore_sleep(sim: &mut Simulation, ck: &Checkpoint) -> Result<(), RestoreError> {
    let h = &ck.header;
    let Some(sleep) = &sim.sleep else { return Ok(()) };
    let tables: Vec<Slot> = layout(sim).into_iter().filter(|s| s.owner == Owner::Sleep).collect();
    if sleep.tests_loads() && tables.iter().any(|s| ck.section(&at_section(&s.name)).is_none()) {
        // forced on a scenario that turned the load test on: its sleeping units have no
        // margins to test loads against
        return Err(RestoreError::Inconsistent("the checkpoint holds no sleep load tables (written without sleep.wake_by_load)".into()));
    }
    for s in &tables {
        let size = s.elem_bytes(sim);
        scatter(s.bytes_mut(sim), size, ck, &at_section(&s.name), &s.name)?;
    }
    let sleep = sim.sleep.as_mut().expect("sleeps");
    sleep.restored()?;
    if sleep.sleeping_units != h.sleeping_units as usize {
        return Err(RestoreError::Inconsistent(format!("the sleep table holds {} sleeping units, the header {}", sleep.sleeping_units, h.sleeping_units)));
    }
    Ok(())
}

/// Bin the restored particles, check that they give the checkpoint's grid blocks (`at`, and the
/// grid's stored pools), and put the stored node velocities back.
fn restore_grid(sim: &mut Simulation, ck: &Checkpoint, at: &Counts) -> Result<(), RestoreError> {
    sim.bin_particles()?;
    let now = counts_now(sim);
    let differ = || RestoreError::Inconsistent("binning the restored particles does not give the checkpoint's grid blocks".into());
    if now.blocks != at.blocks || now.particle_blocks != at.particle_blocks {
        return Err(differ());
    }
    for s in layout(sim).iter().filter(|s| s.owner == Owner::Grid) {
        match s.role {
            Role::Nodes { moving, velocity } => put_nodes(sim, ck, s, (moving, velocity))?,
            _ if section(ck, &s.name, s.bytes_for(sim, at))? != s.live(sim, &now) => return Err(differ()),
            _ => {}
        }
    }
    Ok(())
}

/// The grid nodes of `s` from their two sections (`moving`, `velocity`): the velocity channels
/// of the moving nodes, every other channel zero.
fn put_nodes(sim: &mut Simulation, ck: &Checkpoint, s: &Slot, (moving, velocity): (&str, &str)) -> Result<(), RestoreError> {
    let len = s.bytes_for(sim, &counts_now(sim));
    let na = len / size_of::<Node>() / NODES_PER_BLOCK;
    let occupied: Vec<u64> = section(ck, moving, na * 8)?.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes"))).collect();
    let k = node_channels(sim);
    let count: usize = occupied.iter().map(|m| m.count_ones() as usize).sum();
    let vel: &[u8] = section(ck, velocity, count * k * size_of::<Real>())?;
    let mut vel = vel.chunks_exact(size_of::<Real>()).map(bytemuck::pod_read_unaligned::<Real>);
    let nodes: &mut [Node] = bytemuck::cast_slice_mut(&mut s.bytes_mut(sim)[..len]);
    for (blk, mask) in nodes.chunks_exact_mut(NODES_PER_BLOCK).zip(&occupied) {
        for (l, node) in blk.iter_mut().enumerate() {
            *node = [0.0; 7];
            if mask >> l & 1 == 1 {
                // G2P reads only the velocity channels; the mass is not needed again
                for x in &mut node[1..=k] {
                    *x = vel.next().expect("counted");
                }
            }
        }
    }
    Ok(())
}

/// Section `name` of `ck`, which must hold `len` bytes.
fn section<'a>(ck: &'a Checkpoint, name: &str, len: usize) -> Result<&'a [u8], RestoreError> {
    let b = present(ck, name)?;
    if b.len() != len {
        return Err(RestoreError::SectionSize { name: name.into(), found: b.len(), expected: len });
    }
    Ok(b)
}

/// Section `name` of `ck`, of any length.
fn present<'a>(ck: &'a Checkpoint, name: &str) -> Result<&'a [u8], RestoreError> {
    ck.section(name).ok_or_else(|| RestoreError::MissingSection(name.into()))
}

/// Put a table saved by [`sparse`] back: zero, then its nonzero elements at their indices.
fn scatter(table: &mut [u8], size: usize, ck: &Checkpoint, name_at: &str, name: &str) -> Result<(), RestoreError> {
    let at = present(ck, name_at)?;
    let values = present(ck, name)?;
    if at.len() % 4 != 0 || values.len() != at.len() / 4 * size {
        return Err(RestoreError::Inconsistent(format!("sections '{name_at}' and '{name}' do not match ({} and {} bytes)", at.len(), values.len())));
    }
    table.fill(0);
    let bytes = table;
    for (i, v) in at.chunks_exact(4).zip(values.chunks_exact(size)) {
        let i = u32::from_le_bytes(i.try_into().expect("4 bytes")) as usize;
        let dst = bytes.get_mut(i * size..(i + 1) * size).ok_or_else(|| RestoreError::Inconsistent(format!("section '{name_at}': index {i} outside the table")))?;
        dst.copy_from_slice(v);
    }
    Ok(())
}
