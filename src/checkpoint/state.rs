//! What of a `Simulation` a checkpoint holds, and putting it back.
//!
//! The state that decides every later step: the live particles (every array, in pool order:
//! the order is part of the state, since sums run in it), the scalars that set the next time
//! step, the emitter's position in the print, and for sleeping the per-block tables plus the
//! last step's binning (blocks wake from the activity measured on it). Everything else (grid
//! nodes, sort scratch) is rebuilt from these by the next step.

use super::format::{checksum, state_hash, Checkpoint, Header, Section};
use crate::kernels::{Real, M3, V3};
use crate::solver::{DtLimit, Simulation};

fn bytes<T: bytemuck::Pod>(s: &[T]) -> &[u8] {
    bytemuck::cast_slice(s)
}

/// The state's arrays as byte views, in file order.
pub fn sections(sim: &Simulation) -> Vec<(&'static str, &[u8])> {
    let p = &sim.particles;
    let n = p.n;
    let mut v: Vec<(&'static str, &[u8])> = vec![
        ("particles.x", bytes(&p.xg.as_slice()[..n])),
        ("particles.v", bytes(&p.v.as_slice()[..n])),
        ("particles.C", bytes(&p.c.as_slice()[..n])),
        ("particles.stress", bytes(&p.stress.as_slice()[..n])),
        ("particles.J", bytes(&p.j.as_slice()[..n])),
        ("particles.mass", bytes(&p.mass.as_slice()[..n])),
        ("particles.vol0", bytes(&p.vol0.as_slice()[..n])),
        ("particles.id", bytes(&p.id.as_slice()[..n])),
        ("particles.state", bytes(&p.state.as_slice()[..n * p.state_len])),
    ];
    if let Some(sl) = &sim.sleep {
        let (state, rest) = sl.tables();
        v.push(("grid.slot_block", bytes(&sim.grid.slot_block.as_slice()[..sim.grid.n_active])));
        v.push(("sleep.state", bytes(state)));
        v.push(("sleep.rest", bytes(rest)));
        v.push(("sleep.activity", bytes(&sl.activity.as_slice()[..sim.grid.n_particle_blocks])));
    }
    v
}

/// Bytes of staging a checkpoint can need at the pools' full capacity: `cap` particles with
/// `state_len` state values, `max_blocks` grid slots, and with sleeping a `table_len` table.
pub fn max_staging_bytes(cap: usize, state_len: usize, max_blocks: usize, table_len: usize, sleep: bool) -> usize {
    let per_particle = 2 * std::mem::size_of::<V3>()
        + 2 * std::mem::size_of::<M3>()
        + 3 * std::mem::size_of::<Real>()
        + 4
        + state_len * std::mem::size_of::<Real>();
    let align = super::format::ALIGN;
    let mut total = cap * per_particle + 9 * align;
    if sleep {
        total += max_blocks * (4 + 2 * std::mem::size_of::<Real>()) + table_len * 5 + 4 * align;
    }
    total
}

/// Run-level progress a checkpoint carries so a resumed run continues its outputs.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Progress {
    /// ParaView collection entries so far.
    pub pvd: Vec<(f64, String)>,
    /// Observables at each output so far.
    pub observations: Vec<crate::report::Observation>,
}

/// The header of a checkpoint of `sim` (sections given with their checksums).
pub fn header(sim: &Simulation, outputs: u64, progress: &Progress, sections: Vec<Section>) -> Header {
    let p = &sim.particles;
    Header {
        strand_version: env!("CARGO_PKG_VERSION").to_string(),
        precision: crate::kernels::real::NAME.to_string(),
        scenario_name: sim.scenario.name.clone(),
        scenario_hash: checksum(sim.scenario.source.as_bytes()),
        scenario_text: sim.scenario.source.clone(),
        toolpath_hash: toolpath_hash(sim),
        step: sim.step,
        time: sim.time,
        vmax: sim.vmax,
        last_dt: sim.last_dt,
        last_limit: sim.last_limit.name().to_string(),
        particles: p.n as u64,
        asleep: p.n_sleep as u64,
        capacity: p.capacity() as u64,
        state_len: p.state_len as u32,
        active_blocks: sim.grid.n_active as u64,
        particle_blocks: sim.grid.n_particle_blocks as u64,
        sleeping_blocks: sim.sleep.as_ref().map_or(0, |s| s.sleeping_blocks as u64),
        table_len: sim.grid.geom.table_len() as u64,
        emitted_slabs: emitted_slabs(sim),
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

/// Hash of the physical state, as a checkpoint of it would record.
pub fn current_state_hash(sim: &Simulation) -> u64 {
    let secs: Vec<Section> = sections(sim)
        .into_iter()
        .map(|(name, b)| Section { name: name.into(), offset: 0, bytes: b.len() as u64, xxh3: checksum(b) })
        .collect();
    state_hash(sim.step, sim.time, &secs)
}

/// Put the checkpoint's state into `sim`, freshly built from a compatible scenario. Fails,
/// naming the mismatch, when the pools or the grid do not have the checkpoint's shape.
pub fn restore(sim: &mut Simulation, ck: &Checkpoint) -> Result<(), String> {
    let h = &ck.header;
    let precision = crate::kernels::real::NAME;
    if h.precision != precision {
        return Err(format!("the checkpoint holds {} reals, this strand is built for {precision}", h.precision));
    }
    let p = &mut sim.particles;
    if h.state_len as usize != p.state_len {
        return Err(format!(
            "the checkpoint's material keeps {} state values per particle, the scenario's keeps {}",
            h.state_len, p.state_len
        ));
    }
    if h.particles as usize > p.capacity() {
        return Err(format!(
            "the checkpoint holds {} particles, the pool has room for {} ([memory] max_particles)",
            h.particles,
            p.capacity()
        ));
    }
    if h.table_len as usize != sim.grid.geom.table_len() {
        return Err(format!(
            "the checkpoint's grid has {} blocks, the scenario's {} (domain or dx changed)",
            h.table_len,
            sim.grid.geom.table_len()
        ));
    }
    let n = h.particles as usize;
    let get = |name: &str, len: usize| -> Result<&[u8], String> {
        let b = ck.section(name).ok_or_else(|| format!("section '{name}' is missing"))?;
        if b.len() != len {
            return Err(format!("section '{name}' has {} bytes, expected {len}", b.len()));
        }
        Ok(b)
    };
    fn put<T: bytemuck::Pod>(dst: &mut [T], src: &[u8]) {
        bytemuck::cast_slice_mut::<T, u8>(dst).copy_from_slice(src);
    }
    fn size<T>(n: usize) -> usize {
        n * std::mem::size_of::<T>()
    }
    let sl = p.state_len;
    put(&mut p.xg.as_mut_slice()[..n], get("particles.x", size::<V3>(n))?);
    put(&mut p.v.as_mut_slice()[..n], get("particles.v", size::<V3>(n))?);
    put(&mut p.c.as_mut_slice()[..n], get("particles.C", size::<M3>(n))?);
    put(&mut p.stress.as_mut_slice()[..n], get("particles.stress", size::<M3>(n))?);
    put(&mut p.j.as_mut_slice()[..n], get("particles.J", size::<Real>(n))?);
    put(&mut p.mass.as_mut_slice()[..n], get("particles.mass", size::<Real>(n))?);
    put(&mut p.vol0.as_mut_slice()[..n], get("particles.vol0", size::<Real>(n))?);
    put(&mut p.id.as_mut_slice()[..n], get("particles.id", size::<u32>(n))?);
    put(&mut p.state.as_mut_slice()[..n * sl], get("particles.state", size::<Real>(n * sl))?);
    p.n = n;
    p.n_sleep = 0;

    sim.grid.reset();
    if let Some(sleep) = &mut sim.sleep {
        if ck.section("sleep.state").is_some() {
            let slots = get("grid.slot_block", size::<u32>(h.active_blocks as usize))?;
            let slots: &[u32] = bytemuck::cast_slice(slots);
            for &b in slots {
                // activating in slot order gives every block the slot it had
                sim.grid.activate(b).map_err(|e| e.to_string())?;
            }
            sim.grid.n_particle_blocks = h.particle_blocks as usize;
            let (state, rest) = sleep.tables_mut();
            put(state, get("sleep.state", state.len())?);
            put(rest, get("sleep.rest", size::<f32>(rest.len()))?);
            let npb = h.particle_blocks as usize;
            put(&mut sleep.activity.as_mut_slice()[..npb], get("sleep.activity", size::<[Real; 2]>(npb))?);
            sleep.sleeping_blocks = h.sleeping_blocks as usize;
            sim.particles.n_sleep = h.asleep as usize;
        }
    }
    sim.step = h.step;
    sim.time = h.time;
    sim.vmax = h.vmax;
    sim.last_dt = h.last_dt;
    sim.last_limit = DtLimit::from_name(&h.last_limit).ok_or_else(|| format!("unknown time-step bound '{}'", h.last_limit))?;
    if let Some(pr) = &mut sim.printer {
        let queue = sim.scenario.print.as_ref().map_or(64, |c| c.queue);
        // stop the emitter started at slab 0 before starting one where the checkpoint left off
        pr.emitter = None;
        pr.start(queue, h.emitted_slabs);
    }
    Ok(())
}
