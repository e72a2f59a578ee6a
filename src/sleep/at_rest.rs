//! A particle put at rest as it falls asleep or merges: what a sleeping particle holds besides its
//! state and J is rebuilt from them, not stored (see the module notes of `sleep`).

use crate::kernels::material::Material;
use crate::kernels::{M3, V3};
use crate::particles::Particles;

/// Put particle `i` at rest: zero velocity and velocity gradient, and the stress its material
/// has at rest with its state and J (see the module notes: what a sleeping particle holds
/// besides its state and J is rebuilt, not stored).
pub fn put_at_rest(p: &mut Particles, i: usize, material: &dyn Material) {
    let sl = p.state_len;
    p.v.as_mut_slice()[i] = V3::ZERO;
    p.c.as_mut_slice()[i] = M3::ZERO;
    let state = &p.state.as_slice()[i * sl..(i + 1) * sl];
    p.stress.as_mut_slice()[i] = material.stress_at_rest(state, p.j.as_slice()[i]);
}
