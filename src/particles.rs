//! The particle pool: structure of arrays with a fixed capacity, every array in its own mapped
//! pool. Positions are stored in grid coordinates (x - origin) / dx, which keeps f32 builds
//! accurate far from the origin and saves the kernels a multiply.

use crate::kernels::{Real, M3, V3};
use crate::memory::{Backing, MemoryError, Pool};
use crate::pools::{Counts, Per, PoolDecl, Pools, Role};
use crate::threads::ThreadTeam;

#[derive(Default)]
pub struct Particles {
    /// Live particles: indices `0..n`.
    pub n: usize,
    /// Particles `0..n_sleep` are asleep (see `sleep.rs`); the step works on `n_sleep..n`.
    pub n_sleep: usize,
    /// Id of the next particle created: ids are creation order, and stay unique when sleeping
    /// material is coarsened (`coarsen.rs`), which removes particles.
    pub next_id: u32,
    /// Internal state reals per particle (the material's `state_names().len()`).
    pub state_len: usize,
    /// Grid-coordinate position.
    pub xg: Pool<V3>,
    /// Velocity [m/s].
    pub v: Pool<V3>,
    /// Affine velocity / velocity gradient (APIC C, MLS-MPM L) [1/s].
    pub c: Pool<M3>,
    /// Cauchy stress [Pa], produced by the material for the next P2G.
    pub stress: Pool<M3>,
    /// Volume ratio V / V0.
    pub j: Pool<Real>,
    /// Mass [kg].
    pub mass: Pool<Real>,
    /// Initial volume [m3].
    pub vol0: Pool<Real>,
    /// Stable identity (creation order), kept through reordering.
    pub id: Pool<u32>,
    /// Material internal state, `state_len` reals per particle.
    pub state: Pool<Real>,
}

/// The positions' pool (`strand inspect` reads a checkpoint's bounding box from its section).
pub const POSITIONS: &str = "particles.x";

/// The section of a checkpoint that holds [`Particles::next_id`] where it cannot be rebuilt
/// (merging sleeping particles, which stores the [`Role::FromIds`] pools, the ids' part).
pub const NEXT_ID: &str = "particles.next_id";

impl Pools for Particles {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        use Role::*;
        let sl = self.state_len;
        vec![
            PoolDecl::new(POSITIONS, Per::Particle(1), Stored, |p| &p.xg, |p| &mut p.xg),
            PoolDecl::new("particles.v", Per::Particle(1), FlipVelocity, |p| &p.v, |p| &mut p.v),
            PoolDecl::new("particles.C", Per::Particle(1), Rebuilt, |p| &p.c, |p| &mut p.c),
            PoolDecl::new("particles.stress", Per::Particle(1), Rebuilt, |p| &p.stress, |p| &mut p.stress),
            PoolDecl::new("particles.J", Per::Particle(1), Stored, |p| &p.j, |p| &mut p.j),
            PoolDecl::new("particles.mass", Per::Particle(1), FromIds, |p| &p.mass, |p| &mut p.mass),
            PoolDecl::new("particles.vol0", Per::Particle(1), FromIds, |p| &p.vol0, |p| &mut p.vol0),
            PoolDecl::new("particles.id", Per::Particle(1), Ids, |p| &p.id, |p| &mut p.id),
            PoolDecl::new("particles.state", Per::Particle(sl), Stored, |p| &p.state, |p| &mut p.state),
        ]
    }
}

impl Particles {
    /// The pools for particles with `state_len` state values, declared but not mapped
    /// ([`Pools::map_pools`] maps them).
    pub fn declared(state_len: usize) -> Self {
        Particles { state_len, ..Default::default() }
    }

    /// Room for `cap` particles, mapped.
    pub fn new(cap: usize, state_len: usize, backing: &Backing) -> Result<Self, MemoryError> {
        let mut p = Particles::declared(state_len);
        p.map_pools(&Counts::capacity(cap, 0), backing)?;
        Ok(p)
    }

    pub fn capacity(&self) -> usize {
        self.xg.len()
    }

    /// Append one particle at rest-state; fails (naming the pool) when the pool is full.
    pub fn push(&mut self, xg: V3, v: V3, mass: Real, vol0: Real) -> Result<usize, MemoryError> {
        let i = self.n;
        if i >= self.capacity() {
            return Err(MemoryError::PoolFull {
                pool: "particles",
                needed: i + 1,
                capacity: self.capacity(),
                hint: "[memory] max_particles",
            });
        }
        self.xg.as_mut_slice()[i] = xg;
        self.v.as_mut_slice()[i] = v;
        self.c.as_mut_slice()[i] = M3::ZERO;
        self.stress.as_mut_slice()[i] = M3::ZERO;
        self.j.as_mut_slice()[i] = 1.0;
        self.mass.as_mut_slice()[i] = mass;
        self.vol0.as_mut_slice()[i] = vol0;
        self.id.as_mut_slice()[i] = self.next_id;
        self.next_id += 1;
        self.n += 1;
        Ok(i)
    }

    /// Reorder the awake particles `n_sleep..n` so that index `n_sleep + k` holds old particle
    /// `order[k]` (absolute indices); `scratch` must hold at least
    /// `n * max(size_of::<M3>(), state_len * size_of::<Real>())` bytes.
    /// The copies are shared out over `team` (they are most of a reordering step's time).
    pub fn permute(&mut self, order: &[u32], scratch: &mut [u8], team: &ThreadTeam) {
        let r = self.n_sleep..self.n;
        let order = &order[..r.len()];
        let s = self.state_len;
        permute_pod(&mut self.xg.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.v.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.c.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.stress.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.j.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.mass.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.vol0.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        permute_pod(&mut self.id.as_mut_slice()[..r.end], r.start, order, scratch, 1, team);
        if s > 0 {
            permute_pod(&mut self.state.as_mut_slice()[..r.end * s], r.start, order, scratch, s, team);
        }
    }

    /// Exchange particles `a` and `b` (every field).
    pub fn swap(&mut self, a: usize, b: usize) {
        if a == b {
            return;
        }
        self.xg.as_mut_slice().swap(a, b);
        self.v.as_mut_slice().swap(a, b);
        self.c.as_mut_slice().swap(a, b);
        self.stress.as_mut_slice().swap(a, b);
        self.j.as_mut_slice().swap(a, b);
        self.mass.as_mut_slice().swap(a, b);
        self.vol0.as_mut_slice().swap(a, b);
        self.id.as_mut_slice().swap(a, b);
        let s = self.state_len;
        let st = self.state.as_mut_slice();
        for k in 0..s {
            st.swap(a * s + k, b * s + k);
        }
    }

    /// Bytes of scratch `permute` needs per particle.
    pub fn permute_scratch_per_particle(state_len: usize) -> usize {
        std::mem::size_of::<M3>().max(state_len * std::mem::size_of::<Real>())
    }
}

/// `data[start + k] = old data[order[k]]` for every k, where an element is `width`
/// consecutive values of `data`.
fn permute_pod<T: bytemuck::Pod + Send + Sync>(data: &mut [T], start: usize, order: &[u32], scratch: &mut [u8], width: usize, team: &ThreadTeam) {
    let n = order.len();
    let w = width;
    let tmp = bytemuck::cast_slice_mut::<u8, T>(&mut scratch[..n * w * std::mem::size_of::<T>()]);
    let src: &[T] = data;
    team.for_each_share(tmp, w, |ks, out| {
        for (k, &o) in order[ks].iter().enumerate() {
            let o = o as usize;
            out[k * w..(k + 1) * w].copy_from_slice(&src[o * w..(o + 1) * w]);
        }
    });
    let tmp: &[T] = tmp;
    team.for_each_share(&mut data[start * w..(start + n) * w], w, |ks, out| out.copy_from_slice(&tmp[ks.start * w..ks.end * w]));
}
