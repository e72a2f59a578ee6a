//! The restart state as one walk of the pool tables: every pool of the particles, the grid and
//! sleeping (and the particles' next id) is a [`Slot`], and its role says what a checkpoint
//! makes of it. The file's sections ([`sections`]), the staging buffer's size
//! ([`staging_bytes`]), the state hash's arrays ([`full_state`]) and restoring
//! (`state.rs`, over [`layout`]) all read the same slots; no pool is named here.
//!
//! In a file the groups come in this order ([`file_rank`]), each in declaration order: the
//! particles' stored pools and ids; under FLIP their awake velocities (`NAME_awake`); the grid's
//! stored pools (the slots of its blocks); its moving nodes (the two sections its
//! [`Role::Nodes`] names); where sleeping particles merge, the pools the ids no longer give and
//! the next id; the sleep tables, two sections each (`NAME_at`, the indices of the nonzero
//! entries, then `NAME`, those entries).

use super::format::pad;
use crate::grid::NODES_PER_BLOCK;
use crate::kernels::transfer::Node;
use crate::kernels::Real;
use crate::particles::NEXT_ID;
use crate::pools::{AnyPool, Counts, Per, Pools, Role};
use crate::solver::Simulation;
use std::borrow::Cow;
use std::mem::size_of;

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

/// Whose pool table a slot is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Owner {
    Particles,
    Grid,
    Sleep,
}

/// What a slot holds: the pool at this index of its owner's table, or the particles' next id
/// (a one-entry table, [`NEXT_ID`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Of {
    Pool(usize),
    NextId,
}

/// One entry of the simulation's pool tables, as a checkpoint sees it.
pub struct Slot {
    pub owner: Owner,
    of: Of,
    pub name: Cow<'static, str>,
    pub role: Role,
    pub per: Per,
}

/// The section of the awake part of the pool `name` ([`Role::FlipVelocity`]).
pub fn awake_section(name: &str) -> String {
    format!("{name}_awake")
}

/// The section of the indices of the nonzero entries of the sparse pool `name`.
pub fn at_section(name: &str) -> String {
    format!("{name}_at")
}

fn table<C: Pools>(c: &C, owner: Owner) -> Vec<Slot> {
    c.pools().into_iter().enumerate().map(|(i, d)| Slot { owner, of: Of::Pool(i), name: d.name, role: d.role, per: d.per }).collect()
}

/// Every pool of `sim`'s tables, each table in declaration order: the particles' (then their
/// next id, which the ids give unless particles merge), the grid's, sleeping's.
pub fn slots(sim: &Simulation) -> Vec<Slot> {
    let mut v = table(&sim.particles, Owner::Particles);
    v.push(Slot { owner: Owner::Particles, of: Of::NextId, name: NEXT_ID.into(), role: Role::FromIds, per: Per::Table(1) });
    v.extend(table(&sim.grid, Owner::Grid));
    if let Some(sl) = &sim.sleep {
        v.extend(table(sl, Owner::Sleep));
    }
    v
}

/// Where a slot's sections go in `sim`'s checkpoints (the module doc's order of groups), or
/// none where the checkpoint does not store it.
fn file_rank(s: &Slot, sim: &Simulation) -> Option<u8> {
    let flip = sim.scenario.simulation.flip > 0.0;
    match (s.owner, s.role) {
        (Owner::Particles, Role::Stored | Role::Ids) => Some(0),
        (Owner::Particles, Role::FlipVelocity) if flip => Some(1),
        (Owner::Grid, Role::Stored) => Some(2),
        (Owner::Grid, Role::Nodes { .. }) => Some(3),
        (Owner::Particles, Role::FromIds) if coarsens(sim) => Some(4),
        (Owner::Sleep, Role::Sparse) => Some(5),
        _ => None,
    }
}

/// The slots a checkpoint of `sim` stores, in file order.
pub fn layout(sim: &Simulation) -> Vec<Slot> {
    let mut v: Vec<(u8, Slot)> = slots(sim).into_iter().filter_map(|s| file_rank(&s, sim).map(|r| (r, s))).collect();
    // stable: declaration order within a group
    v.sort_by_key(|(r, _)| *r);
    v.into_iter().map(|(_, s)| s).collect()
}

/// Whether the state hash covers a slot: every state pool of the particles and of sleeping, and
/// with sleeping the grid's stored pools (the last binning, on which the next step's sleeping
/// depends); not the grid's nodes, which a step boundary leaves for the next step's P2G to
/// overwrite, nor the next id.
fn hashed(s: &Slot, sim: &Simulation) -> bool {
    s.of != Of::NextId
        && match s.owner {
            Owner::Particles | Owner::Sleep => s.role.is_state(),
            Owner::Grid => s.role == Role::Stored && sim.sleep.is_some(),
        }
}

impl Slot {
    fn pool<'a>(&self, sim: &'a Simulation) -> Option<&'a dyn AnyPool> {
        let Of::Pool(i) = self.of else { return None };
        Some(match self.owner {
            Owner::Particles => sim.particles.pools().swap_remove(i).of(&sim.particles),
            Owner::Grid => sim.grid.pools().swap_remove(i).of(&sim.grid),
            Owner::Sleep => {
                let sl = sim.sleep.as_ref().expect("a sleep slot where the simulation sleeps");
                sl.pools().swap_remove(i).of(sl)
            }
        })
    }

    /// The whole pool's bytes.
    pub fn bytes<'a>(&self, sim: &'a Simulation) -> &'a [u8] {
        self.pool(sim).map_or_else(|| bytemuck::bytes_of(&sim.particles.next_id), |p| p.bytes())
    }

    pub fn bytes_mut<'a>(&self, sim: &'a mut Simulation) -> &'a mut [u8] {
        let Of::Pool(i) = self.of else { return bytemuck::bytes_of_mut(&mut sim.particles.next_id) };
        match self.owner {
            Owner::Particles => sim.particles.pools().swap_remove(i).of_mut(&mut sim.particles).bytes_mut(),
            Owner::Grid => sim.grid.pools().swap_remove(i).of_mut(&mut sim.grid).bytes_mut(),
            Owner::Sleep => {
                let sl = sim.sleep.as_mut().expect("a sleep slot where the simulation sleeps");
                sl.pools().swap_remove(i).of_mut(sl).bytes_mut()
            }
        }
    }

    pub fn elem_bytes(&self, sim: &Simulation) -> usize {
        self.pool(sim).map_or(size_of::<u32>(), |p| p.elem_bytes())
    }

    fn reals_per_elem(&self, sim: &Simulation) -> usize {
        self.pool(sim).map_or(0, |p| p.reals_per_elem())
    }

    /// Bytes of its entries for `counts`.
    pub fn bytes_for(&self, sim: &Simulation, counts: &Counts) -> usize {
        self.per.len(counts) * self.elem_bytes(sim)
    }

    /// Its live part, for `now`.
    pub fn live<'a>(&self, sim: &'a Simulation, now: &Counts) -> &'a [u8] {
        &self.bytes(sim)[..self.bytes_for(sim, now)]
    }

    /// Its sections at `now` (the module doc).
    fn parts<'a>(&self, sim: &'a Simulation, now: &Counts) -> Vec<Part<'a>> {
        let (size, reals) = (self.elem_bytes(sim), self.reals_per_elem(sim));
        match self.role {
            Role::FlipVelocity => {
                // FLIP adds the change of the grid velocity to the particle's own; asleep it is zero
                let p = &sim.particles;
                let awake = &self.bytes(sim)[p.n_sleep * size..p.n * size];
                vec![Part { name: awake_section(&self.name), len: awake.len(), reals: (p.n - p.n_sleep) * reals, source: Source::Raw(awake) }]
            }
            Role::Nodes { moving: moving_name, velocity } => {
                let nodes: &[Node] = bytemuck::cast_slice(self.live(sim, now));
                let k = node_channels(sim);
                let occupied = nodes.iter().filter(|n| moving(n, k)).count();
                vec![
                    Part { name: moving_name.into(), len: nodes.len() / NODES_PER_BLOCK * 8, reals: 0, source: Source::Moving(nodes, k) },
                    Part { name: velocity.into(), len: occupied * k * size_of::<Real>(), reals: occupied * k, source: Source::Velocities(nodes, k) },
                ]
            }
            Role::Sparse => {
                // per unit of the whole domain, but zero away from material (and the load tables
                // away from sleeping units); counted as integers: the sleep tables are f32 or
                // integers whatever the precision
                let table = self.bytes(sim);
                let count = table.chunks_exact(size).filter(|e| nonzero(e)).count();
                vec![
                    Part { name: at_section(&self.name), len: count * 4, reals: 0, source: Source::NonZeroAt(table, size) },
                    Part { name: self.name.to_string(), len: count * size, reals: 0, source: Source::NonZero(table, size) },
                ]
            }
            _ => {
                let b = self.live(sim, now);
                vec![Part { name: self.name.to_string(), len: b.len(), reals: self.per.len(now) * reals, source: Source::Raw(b) }]
            }
        }
    }

    /// Its sections' lengths at the pools' capacity `cap`: every entry of a sparse table
    /// nonzero, and as many nodes moving as the grid's slots hold, or 27 per particle.
    fn capacity(&self, sim: &Simulation, cap: &Counts) -> Vec<usize> {
        let (n, size) = (self.per.len(cap), self.elem_bytes(sim));
        match self.role {
            Role::Nodes { .. } => {
                // a particle's stencil gives mass to 27 nodes, so no more nodes than that can move
                let moving = n.min(27 * cap.particles);
                vec![n / NODES_PER_BLOCK * 8, moving * node_channels(sim) * size_of::<Real>()]
            }
            Role::Sparse => vec![n * 4, n * size],
            _ => vec![n * size],
        }
    }
}

/// Node channels a restart needs: the velocity, and with FLIP the velocity before the update.
pub fn node_channels(sim: &Simulation) -> usize {
    if sim.scenario.simulation.flip > 0.0 {
        6
    } else {
        3
    }
}

/// How many particles and grid slots `sim` has now.
pub fn counts_now(sim: &Simulation) -> Counts {
    Counts { particles: sim.particles.n, blocks: sim.grid.n_active, particle_blocks: sim.grid.n_particle_blocks }
}

/// Whether `sim` merges sleeping particles (`[sleep] coarsen`).
pub fn coarsens(sim: &Simulation) -> bool {
    sim.sleep.as_ref().is_some_and(|s| s.cfg.coarsen)
}

/// The restart state's sections, in file order, at the middle of a step (after `begin_step`;
/// at a step boundary they describe the middle of the step just taken).
pub fn sections(sim: &Simulation) -> Vec<Part<'_>> {
    let now = counts_now(sim);
    layout(sim).iter().flat_map(|s| s.parts(sim, &now)).collect()
}

/// Bytes of the staging buffer `strand run` maps for `sim`'s checkpoints: [`sections`] at the
/// pools' capacity, each padded.
pub fn staging_bytes(sim: &Simulation) -> usize {
    let cap = Counts::capacity(sim.particles.capacity(), sim.grid.max_blocks());
    layout(sim).iter().flat_map(|s| s.capacity(sim, &cap)).map(pad).sum()
}

/// The arrays of the whole state at a step boundary, for the state hash: equal hashes,
/// bit-identical particles (whatever a checkpoint leaves out to be rebuilt). With sleeping, the
/// last step's binning and the sleep tables too: the next step's sleeping depends on them.
pub fn full_state(sim: &Simulation) -> Vec<(Cow<'static, str>, &[u8])> {
    let now = counts_now(sim);
    slots(sim)
        .into_iter()
        .filter(|s| hashed(s, sim))
        .map(|s| {
            let live = s.live(sim, &now);
            (s.name, live)
        })
        .collect()
}
