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
//!   `grid.slot_block` proves it gave the same slots); the per-block activity by G2P.

use super::format::{checksum, pad, state_hash, Checkpoint, Header, Section};
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::transfer::Node;
use crate::kernels::{Real, M3, V3};
use crate::pools::{live, with_role, Counts, Pools, Role};
use crate::solver::{DtLimit, SimError, Simulation};
use std::borrow::Cow;
use std::mem::size_of;

fn bytes<T: bytemuck::Pod>(s: &[T]) -> &[u8] {
    bytemuck::cast_slice(s)
}

/// Where a section's bytes come from.
pub enum Source<'a> {
    /// A pool's bytes as they are in memory.
    Raw(&'a [u8]),
    /// The active blocks' nodes as one u64 per block, bit `l` set when node `l` has a nonzero
    /// channel `1..=k`: nodes without mass are zero after the grid update, and so are the
    /// nodes held still next to sleeping blocks.
    Moving(&'a [Node], usize),
    /// Channels `1..=k` (velocity, and with FLIP the velocity before the update) of every
    /// moving node, in slot then node order.
    Velocities(&'a [Node], usize),
    /// A table of `size`-byte elements, mostly zero: the u32 indices of its nonzero elements.
    NonZeroAt(&'a [u8], usize),
    /// The nonzero elements themselves, in index order.
    NonZero(&'a [u8], usize),
}

/// One section of the restart state.
pub struct Part<'a> {
    pub name: String,
    pub len: usize,
    /// How many of its values are reals (the rest are integers, whatever the precision).
    pub reals: usize,
    pub source: Source<'a>,
}

impl Part<'_> {
    fn raw<'a, T: bytemuck::Pod>(name: &str, s: &'a [T], reals_each: usize) -> Part<'a> {
        Part { name: name.into(), len: std::mem::size_of_val(s), reals: s.len() * reals_each, source: Source::Raw(bytes(s)) }
    }

    /// Write the section into `dst` (`len` bytes).
    pub fn fill(&self, dst: &mut [u8]) {
        match self.source {
            Source::Raw(b) => dst.copy_from_slice(b),
            Source::Moving(nodes, k) => {
                for (blk, out) in nodes.chunks_exact(NODES_PER_BLOCK).zip(dst.chunks_exact_mut(8)) {
                    let mask = blk.iter().enumerate().fold(0u64, |m, (l, n)| if moving(n, k) { m | 1 << l } else { m });
                    out.copy_from_slice(&mask.to_le_bytes());
                }
            }
            Source::Velocities(nodes, k) => {
                let mut out = dst.chunks_exact_mut(size_of::<Real>());
                for n in nodes.iter().filter(|n| moving(n, k)) {
                    for x in &n[1..=k] {
                        out.next().expect("sized by count").copy_from_slice(bytemuck::bytes_of(x));
                    }
                }
            }
            Source::NonZeroAt(table, size) => {
                let mut out = dst.chunks_exact_mut(4);
                for (i, _) in table.chunks_exact(size).enumerate().filter(|(_, e)| nonzero(e)) {
                    out.next().expect("sized by count").copy_from_slice(&(i as u32).to_le_bytes());
                }
            }
            Source::NonZero(table, size) => {
                let mut out = dst.chunks_exact_mut(size);
                for e in table.chunks_exact(size).filter(|e| nonzero(e)) {
                    out.next().expect("sized by count").copy_from_slice(e);
                }
            }
        }
    }
}

/// Whether a node has a velocity channel whose bits are not all zero (+0.0 is the only value
/// a restore may leave out).
fn moving(n: &Node, k: usize) -> bool {
    n[1..=k].iter().any(|x| x.to_bits() != 0)
}

fn nonzero(e: &[u8]) -> bool {
    e.iter().any(|&b| b != 0)
}

/// The live parts of `c`'s pools whose role passes `keep`, one section each, in declaration
/// order.
fn stored<'a, C: Pools>(c: &'a C, now: &Counts, keep: impl Fn(Role) -> bool) -> Vec<Part<'a>> {
    let part = |d: &crate::pools::PoolDecl<C>| {
        let b = d.live(c, now);
        Part { name: d.name.to_string(), len: b.len(), reals: d.per.len(now) * d.of(c).reals_per_elem(), source: Source::Raw(b) }
    };
    with_role(c, keep).iter().map(part).collect()
}

/// The two sections of each of `c`'s sparse tables (all their values are counted as integers:
/// the sleep tables are f32 or integers whatever the precision): the indices of its nonzero
/// elements (section `NAME_at`), then those.
fn sparse<C: Pools>(c: &C) -> Vec<Part<'_>> {
    let mut v = Vec::new();
    for d in with_role(c, |r| r == Role::Sparse) {
        let (table, size) = (d.of(c).bytes(), d.of(c).elem_bytes());
        let count = table.chunks_exact(size).filter(|e| nonzero(e)).count();
        v.push(Part { name: format!("{}_at", d.name), len: count * 4, reals: 0, source: Source::NonZeroAt(table, size) });
        v.push(Part { name: d.name.to_string(), len: count * size, reals: 0, source: Source::NonZero(table, size) });
    }
    v
}

/// Node channels a restart needs: the velocity, and with FLIP the velocity before the update.
fn node_channels(sim: &Simulation) -> usize {
    if sim.scenario.simulation.flip > 0.0 {
        6
    } else {
        3
    }
}

/// How many particles and grid slots `sim` has now.
fn counts_now(sim: &Simulation) -> Counts {
    Counts { particles: sim.particles.n, blocks: sim.grid.n_active, particle_blocks: sim.grid.n_particle_blocks }
}

/// What a checkpoint stores of the particles always: [`Role::Stored`] and the ids.
fn always_stored(r: Role) -> bool {
    matches!(r, Role::Stored | Role::Ids)
}

/// The restart state's sections, in file order, at the middle of a step (after
/// `begin_step`; at a step boundary they describe the middle of the step just taken): the
/// particles' stored pools (and FLIP's velocities), the grid's and its moving nodes, what
/// merging adds, and the sleep tables.
pub fn sections(sim: &Simulation) -> Vec<Part<'_>> {
    let now = counts_now(sim);
    let p = &sim.particles;
    let mut v = stored(p, &now, always_stored);
    if sim.scenario.simulation.flip > 0.0 {
        // FLIP adds the change of the grid velocity to the particle's own; asleep it is zero
        v.push(Part::raw("particles.v_awake", &p.v.as_slice()[p.n_sleep..p.n], 3));
    }
    v.extend(stored(&sim.grid, &now, |r| r == Role::Stored));
    let nodes = &sim.grid.nodes.as_slice()[..now.blocks * NODES_PER_BLOCK];
    let k = node_channels(sim);
    let occupied = nodes.iter().filter(|n| moving(n, k)).count();
    v.push(Part { name: "grid.moving".into(), len: now.blocks * 8, reals: 0, source: Source::Moving(nodes, k) });
    v.push(Part {
        name: "grid.velocity".into(),
        len: occupied * k * size_of::<Real>(),
        reals: occupied * k,
        source: Source::Velocities(nodes, k),
    });
    if coarsens(sim) {
        // merged particles carry what their ids no longer tell (module notes)
        v.extend(stored(p, &now, |r| r == Role::FromIds));
        v.push(Part::raw("particles.next_id", std::slice::from_ref(&p.next_id), 0));
    }
    if let Some(sl) = &sim.sleep {
        // per unit of the whole domain, but zero away from material (and the load tables
        // away from sleeping units)
        v.extend(sparse(sl));
    }
    v
}

/// Whether `sim` merges sleeping particles (`[sleep] coarsen`).
fn coarsens(sim: &Simulation) -> bool {
    sim.sleep.as_ref().is_some_and(|s| s.cfg.coarsen)
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

/// Bytes of the staging buffer `strand run` maps for `sim`'s checkpoints: [`sections`] at the
/// pools' capacity (every entry of a sparse table nonzero, and as many nodes moving as the
/// grid's slots hold, or 27 per particle), each padded.
pub fn staging_bytes(sim: &Simulation) -> usize {
    let p = &sim.particles;
    let cap = Counts::capacity(p.capacity(), sim.grid.max_blocks());
    let mut lens: Vec<usize> = with_role(p, always_stored).iter().map(|d| d.bytes_for(p, &cap)).collect();
    if sim.scenario.simulation.flip > 0.0 {
        lens.push(cap.particles * size_of::<V3>());
    }
    lens.extend(with_role(&sim.grid, |r| r == Role::Stored).iter().map(|d| d.bytes_for(&sim.grid, &cap)));
    // a particle's stencil gives mass to 27 nodes, so no more nodes than that can move
    let nodes = (cap.blocks * NODES_PER_BLOCK).min(27 * cap.particles);
    lens.extend([cap.blocks * 8, nodes * node_channels(sim) * size_of::<Real>()]);
    if coarsens(sim) {
        lens.extend(with_role(p, |r| r == Role::FromIds).iter().map(|d| d.bytes_for(p, &cap)));
        lens.push(4);
    }
    if let Some(sl) = &sim.sleep {
        for d in with_role(sl, |r| r == Role::Sparse) {
            let n = d.per.len(&cap);
            lens.extend([n * 4, n * d.of(sl).elem_bytes()]);
        }
    }
    lens.into_iter().map(pad).sum()
}

/// The arrays of the whole state at a step boundary, for the state hash: equal hashes,
/// bit-identical particles (whatever a checkpoint leaves out to be rebuilt). With sleeping, the
/// last step's binning and the sleep tables too: the next step's sleeping depends on them.
fn full_state(sim: &Simulation) -> Vec<(Cow<'static, str>, &[u8])> {
    let now = counts_now(sim);
    let mut v = live(&sim.particles, &now, Role::is_state);
    if let Some(sl) = &sim.sleep {
        v.extend(live(&sim.grid, &now, |r| r == Role::Stored));
        v.extend(live(sl, &now, Role::is_state));
    }
    v
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
    if flip != ck.section("particles.v_awake").is_some() {
        return Err(RestoreError::Mismatch(format!(
            "the checkpoint was written {} FLIP, the scenario runs {} it (simulation.flip)",
            if flip { "without" } else { "with" },
            if flip { "with" } else { "without" }
        )));
    }
    if sim.sleep.is_some() != ck.section("sleep.state_at").is_some() {
        return Err(RestoreError::Mismatch("the checkpoint and the scenario differ in sleeping ([sleep])".into()));
    }
    if coarsens(sim) != ck.section("particles.next_id").is_some() {
        return Err(RestoreError::Mismatch("the checkpoint and the scenario differ in merging sleeping particles ([sleep] coarsen)".into()));
    }
    Ok(())
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

/// The particle pools: the stored arrays, the awake velocities under FLIP, and the ids, masses
/// and volumes (stored when merging, else rebuilt from the ids); C and the stress at rest.
fn restore_particles(sim: &mut Simulation, ck: &Checkpoint, at: &Counts, asleep: usize, masses: &MassSource) -> Result<(), RestoreError> {
    let put = |dst: &mut [u8], name: &str| -> Result<(), RestoreError> {
        dst.copy_from_slice(section(ck, name, dst.len())?);
        Ok(())
    };
    let n = at.particles;
    let flip = sim.scenario.simulation.flip > 0.0;
    let p = &mut sim.particles;
    for d in with_role(p, always_stored) {
        put(d.live_mut(p, at), &d.name)?;
    }
    p.v.as_mut_slice()[..n].fill(V3::ZERO);
    if flip {
        put(bytemuck::cast_slice_mut(&mut p.v.as_mut_slice()[asleep..n]), "particles.v_awake")?;
    }
    p.n = n;
    p.n_sleep = asleep;
    if let Some(b) = ck.section("particles.next_id") {
        for d in with_role(p, |r| r == Role::FromIds) {
            put(d.live_mut(p, at), &d.name)?;
        }
        p.next_id = u32::from_le_bytes(b.try_into().map_err(|_| RestoreError::Inconsistent("section 'particles.next_id' is not 4 bytes".to_string()))?);
    } else {
        // without merging, ids are 0..n in some order
        p.next_id = n as u32;
        for i in 0..n {
            let (m, v) = masses.of_id(p.id.as_slice()[i] as usize)?;
            p.mass.as_mut_slice()[i] = m;
            p.vol0.as_mut_slice()[i] = v;
        }
    }
    // C and the stress of awake particles come from G2P and the material update of this step;
    // sleeping ones hold the rest state sleeping gave them
    p.c.as_mut_slice()[..n].fill(M3::ZERO);
    p.stress.as_mut_slice()[..n].fill(M3::ZERO);
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

/// The sleeping tables (when the scenario sleeps), scattered back from their sparse sections, and the counts rebuilt
/// from them checked against the header.
fn restore_sleep(sim: &mut Simulation, ck: &Checkpoint) -> Result<(), RestoreError> {
    let h = &ck.header;
    let Some(sleep) = &mut sim.sleep else { return Ok(()) };
    let loads = sleep.tests_loads();
    if loads && ck.section("sleep.load_at").is_none() {
        // forced on a scenario that turned the load test on: its sleeping units have no
        // margins to test loads against
        return Err(RestoreError::Inconsistent("the checkpoint holds no sleep load tables (written without sleep.wake_by_load)".into()));
    }
    for d in with_role(sleep, |r| r == Role::Sparse) {
        let pool = d.of_mut(sleep);
        let size = pool.elem_bytes();
        scatter(pool.bytes_mut(), size, ck, &format!("{}_at", d.name), &d.name)?;
    }
    sleep.restored()?;
    if sleep.sleeping_units != h.sleeping_units as usize {
        return Err(RestoreError::Inconsistent(format!("the sleep table holds {} sleeping units, the header {}", sleep.sleeping_units, h.sleeping_units)));
    }
    Ok(())
}

/// Bin the restored particles, check that they give the checkpoint's grid blocks (`at`), and
/// put the stored node velocities back.
fn restore_grid(sim: &mut Simulation, ck: &Checkpoint, at: &Counts) -> Result<(), RestoreError> {
    let get = |name: &str, len: usize| section(ck, name, len);
    sim.bin_particles()?;
    let (now, grid) = (counts_now(sim), &sim.grid);
    let differ = "binning the restored particles does not give the checkpoint's grid blocks";
    if now.blocks != at.blocks || now.particle_blocks != at.particle_blocks {
        return Err(RestoreError::Inconsistent(differ.into()));
    }
    for d in with_role(grid, |r| r == Role::Stored) {
        if get(&d.name, d.bytes_for(grid, at))? != d.live(grid, &now) {
            return Err(RestoreError::Inconsistent(differ.into()));
        }
    }
    let na = now.blocks;
    let occupied: Vec<u64> = get("grid.moving", na * 8)?
        .chunks_exact(8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    let k = node_channels(sim);
    let count: usize = occupied.iter().map(|m| m.count_ones() as usize).sum();
    let vel: &[u8] = get("grid.velocity", count * k * size_of::<Real>())?;
    let mut vel = vel.chunks_exact(size_of::<Real>()).map(bytemuck::pod_read_unaligned::<Real>);
    let nodes = &mut sim.grid.nodes.as_mut_slice()[..na * NODES_PER_BLOCK];
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
