//! Pools declared once. Every component that owns pools (the particles, the grid, the binning's
//! scratch, sleeping, merging, the solids) lists them in one table, [`Pools::pools`]: each pool's
//! name, what its entries are of (which sets its length) and its role in a checkpoint. The
//! memory plan, the mapping, a checkpoint's sections, its staging size and its restore, the
//! state hash and the gradient schedule's stored states are all read from those tables, so a
//! new pool is one line beside its field (DESIGN.md, "Checkpoints and resume").

use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, MemoryPlan, Pool};
use bytemuck::Pod;
use std::any::TypeId;
use std::borrow::Cow;

/// What a pool is to a checkpoint (`checkpoint/state.rs` reads it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Not state: scratch, or what other pools give again (a lookup, a count of them).
    Scratch,
    /// State a checkpoint stores as it is (its live part). A step changes it.
    Stored,
    /// State a checkpoint stores as the indices and values of its nonzero entries (a table that
    /// is mostly zero).
    Sparse,
    /// State a restore rebuilds from what is stored (C and the stress by this step's G2P and
    /// material update, a sleeping particle's velocity at rest). A step changes it.
    Rebuilt,
    /// The particles' velocity: rebuilt as [`Role::Rebuilt`] is, except under FLIP, which adds
    /// the grid's change of velocity to the awake particles' own, so a checkpoint stores the
    /// awake particles' part. A step changes it.
    FlipVelocity,
    /// The particle ids: stored, and left alone by a step that neither reorders nor merges
    /// particles (a gradient run's stored states leave them out).
    Ids,
    /// Rebuilt from the ids (creation order) and the scenario, and left alone by a step as the
    /// ids are; stored when sleeping particles merge, which makes particles that their ids no
    /// longer describe.
    FromIds,
    /// The grid nodes in the middle of a step: a checkpoint stores which nodes move and their
    /// velocity channels, as the two sections named here.
    Nodes { moving: &'static str, velocity: &'static str },
}

impl Role {
    /// Whether the pool is state (the state hash covers it): all but scratch.
    pub fn is_state(self) -> bool {
        self != Role::Scratch
    }

    /// Whether a step changes it in a run that neither reorders nor merges particles: what a
    /// gradient run's stored states hold.
    pub fn changes_in_step(self) -> bool {
        matches!(self, Role::Stored | Role::Rebuilt | Role::FlipVelocity)
    }
}

/// What a pool's entries are of: this sets its length at capacity and the part of it that holds
/// state now.
#[derive(Clone, Copy, Debug)]
pub enum Per {
    /// `k` entries per particle.
    Particle(usize),
    /// `k` entries per grid slot (the active blocks).
    Block(usize),
    /// `k` entries per grid slot holding particles in the last binning.
    ParticleBlock(usize),
    /// A table of this length (per block of the domain, per sleep unit, ...), all of it live.
    Table(usize),
}

/// How many particles and grid slots there are room for (sizing the pools) or there are now
/// (their live parts).
#[derive(Clone, Copy, Debug)]
pub struct Counts {
    pub particles: usize,
    pub blocks: usize,
    pub particle_blocks: usize,
}

impl Counts {
    /// Room for `particles` particles and `blocks` grid slots.
    pub fn capacity(particles: usize, blocks: usize) -> Counts {
        Counts { particles, blocks, particle_blocks: blocks }
    }

    /// `particles` particles and no grid slots (for the particles' own pools).
    pub fn particles(particles: usize) -> Counts {
        Counts { particles, blocks: 0, particle_blocks: 0 }
    }
}

impl Per {
    /// Entries for `c`.
    pub fn len(self, c: &Counts) -> usize {
        match self {
            Per::Particle(k) => c.particles * k,
            Per::Block(k) => c.blocks * k,
            Per::ParticleBlock(k) => c.particle_blocks * k,
            Per::Table(len) => len,
        }
    }
}

/// A pool of any element type, seen as bytes.
pub trait AnyPool {
    fn bytes(&self) -> &[u8];
    fn bytes_mut(&mut self) -> &mut [u8];
    fn elem_bytes(&self) -> usize;
    /// How many of this build's reals an element holds (a `Real`, `V3` or `M3`; 0 for any other
    /// type, whatever its width).
    fn reals_per_elem(&self) -> usize;
    /// Map it, `len` zeroed elements.
    fn map(&mut self, name: &str, len: usize, backing: &Backing) -> Result<(), MemoryError>;
}

impl<T: Pod> AnyPool for Pool<T> {
    fn bytes(&self) -> &[u8] {
        bytemuck::cast_slice(self.as_slice())
    }
    fn bytes_mut(&mut self) -> &mut [u8] {
        bytemuck::cast_slice_mut(self.as_mut_slice())
    }
    fn elem_bytes(&self) -> usize {
        size_of::<T>()
    }
    fn reals_per_elem(&self) -> usize {
        let t = TypeId::of::<T>();
        [(TypeId::of::<Real>(), 1), (TypeId::of::<V3>(), 3), (TypeId::of::<M3>(), 9)].iter().find(|(id, _)| *id == t).map_or(0, |&(_, k)| k)
    }
    fn map(&mut self, name: &str, len: usize, backing: &Backing) -> Result<(), MemoryError> {
        *self = Pool::new(name, len, backing)?;
        Ok(())
    }
}

/// One pool of a component `C`: its name, what its entries are of, its role, and the field that
/// holds it.
pub struct PoolDecl<C> {
    pub name: Cow<'static, str>,
    pub per: Per,
    pub role: Role,
    pool: fn(&C) -> &dyn AnyPool,
    pool_mut: fn(&mut C) -> &mut dyn AnyPool,
}

impl<C> PoolDecl<C> {
    pub fn new(name: impl Into<Cow<'static, str>>, per: Per, role: Role, pool: fn(&C) -> &dyn AnyPool, pool_mut: fn(&mut C) -> &mut dyn AnyPool) -> Self {
        PoolDecl { name: name.into(), per, role, pool, pool_mut }
    }

    /// The pool in `c`.
    pub fn of<'a>(&self, c: &'a C) -> &'a dyn AnyPool {
        (self.pool)(c)
    }

    pub fn of_mut<'a>(&self, c: &'a mut C) -> &'a mut dyn AnyPool {
        (self.pool_mut)(c)
    }

    /// Bytes of its entries for `counts` (its live part, or all of it at capacity).
    pub fn bytes_for(&self, c: &C, counts: &Counts) -> usize {
        self.per.len(counts) * self.of(c).elem_bytes()
    }

    /// Its live part in `c`, for `now`.
    pub fn live<'a>(&self, c: &'a C, now: &Counts) -> &'a [u8] {
        &self.of(c).bytes()[..self.bytes_for(c, now)]
    }

    pub fn live_mut<'a>(&self, c: &'a mut C, now: &Counts) -> &'a mut [u8] {
        let n = self.bytes_for(c, now);
        &mut self.of_mut(c).bytes_mut()[..n]
    }
}

/// A component that owns pools.
pub trait Pools: Sized {
    /// Every pool, in declaration order (the order of the memory plan and of the state hash).
    fn pools(&self) -> Vec<PoolDecl<Self>>;

    /// Add every pool, sized for `cap`, to `plan`.
    fn plan_memory(&self, plan: &mut MemoryPlan, cap: &Counts) {
        plan_pools(self, plan, cap);
    }

    /// Map every pool, zeroed, sized for `cap`.
    fn map_pools(&mut self, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
        map_pools(self, cap, backing)
    }
}

/// [`Pools::plan_memory`]'s default: each pool of `c` at its length for `cap`.
pub fn plan_pools<C: Pools>(c: &C, plan: &mut MemoryPlan, cap: &Counts) {
    for d in c.pools() {
        plan.add_bytes(&d.name, d.bytes_for(c, cap));
    }
}

/// [`Pools::map_pools`]'s default: map each pool of `c` at its length for `cap`.
pub fn map_pools<C: Pools>(c: &mut C, cap: &Counts, backing: &Backing) -> Result<(), MemoryError> {
    for d in c.pools() {
        d.of_mut(c).map(&d.name, d.per.len(cap), backing)?;
    }
    Ok(())
}

/// The pools of `c` whose role passes `keep`, in declaration order.
pub fn with_role<C: Pools>(c: &C, keep: impl Fn(Role) -> bool) -> Vec<PoolDecl<C>> {
    c.pools().into_iter().filter(|d| keep(d.role)).collect()
}

/// The live parts of the pools of `c` whose role passes `keep`, with their names, in declaration
/// order.
pub fn live<'a, C: Pools>(c: &'a C, now: &Counts, keep: impl Fn(Role) -> bool) -> Vec<(Cow<'static, str>, &'a [u8])> {
    with_role(c, keep)
        .into_iter()
        .map(|d| {
            let bytes = d.live(c, now);
            (d.name, bytes)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::Particles;

    #[test]
    fn a_table_sizes_the_plan_and_the_pools_and_its_live_parts_follow_the_counts() {
        let p = Particles::declared(2);
        let mut plan = MemoryPlan::default();
        p.plan_memory(&mut plan, &Counts::particles(10));
        let names: Vec<&str> = plan.pools.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["particles.x", "particles.v", "particles.C", "particles.stress", "particles.J", "particles.mass", "particles.vol0", "particles.id", "particles.state"]);
        assert_eq!(plan.pools[8].1 as usize, 10 * 2 * size_of::<Real>());
        // declared, nothing is mapped
        assert!(p.xg.as_slice().is_empty() && p.state.as_slice().is_empty());

        let mut p = Particles::new(10, 2, &Backing::default()).unwrap();
        assert_eq!((p.capacity(), p.state.len()), (10, 20));
        p.n = 3;
        let now = Counts::particles(p.n);
        let live = live(&p, &now, Role::is_state);
        assert_eq!(live.len(), 9);
        assert_eq!(live[0].1.len(), 3 * size_of::<V3>());
        assert_eq!(live[8].1.len(), 3 * 2 * size_of::<Real>());
        // what a gradient run stores: the arrays a step changes, in declaration order
        let stepped: Vec<_> = with_role(&p, Role::changes_in_step).into_iter().map(|d| d.name).collect();
        assert_eq!(stepped, ["particles.x", "particles.v", "particles.C", "particles.stress", "particles.J", "particles.state"]);
        let d = &with_role(&p, |r| r == Role::Stored)[0];
        d.live_mut(&mut p, &now).fill(1);
        assert!(p.xg.as_slice()[..3].iter().all(|x| x.x != 0.0) && p.xg.as_slice()[3] == V3::ZERO);
    }
}
