//! The newest slab of a continuous emission, while it is still entering the tube.
//!
//! A fraction f = (L + H) / s - q of slab q has been extruded (see `emitter.rs`). Its particles
//! carry that fraction of their mass and volume, and move with the feed in proportion to the rest:
//! after G2P their position, velocity, velocity gradient and volume ratio become
//!
//! ```text
//! x = (1 - f) (x0 + dt v_feed) + f x_g2p      v = (1 - f) v_feed + f v_g2p
//! C = f C_g2p                                  J = (1 - f) J0 + f J_g2p
//! ```
//!
//! with v_feed the velocity the nozzle imposes in its tube. Both make the simulation continuous
//! in the extrusion speed, whose changes move the time each slab begins to enter: a slab entering
//! at the end of one step has f = 0 in it, carries no mass and moves exactly with the feed, which
//! is where a slab entering at the start of the next step is placed. Without the blend, a
//! particle's first step would follow the grid near the nozzle's wall (whose nodes outside the
//! tube move freely), and entering one step earlier or later would leave a different trace for
//! the rest of the run: central differences in U would see those jumps, the adjoint could not.

use crate::kernels::{Real, M3, V3};
use crate::particles::Particles;

/// The slab's state in the current step, and scratch sized for one slab at start-up.
pub struct Newest {
    pub slab: u64,
    /// Id of the slab's first particle (ids are creation order).
    pub first: u32,
    /// First id whose mass this step's emission set: `first`, or the previous newest slab's first
    /// particle when it was completed in this step.
    pub set_from: u32,
    /// Fraction of the slab extruded, and whether it moves with the extruded length (strictly
    /// between 0 and 1); when it does not, the blend is the identity.
    pub fraction: f64,
    pub moving: bool,
    /// Pool indices of the slab's particles, found after the step's reordering.
    pub index: Vec<u32>,
    /// Position and volume ratio before G2P, and G2P's own output (x, v, C, J), for the blend and
    /// its adjoint.
    pub x0: Vec<V3>,
    pub j0: Vec<Real>,
    pub g2p: Vec<(V3, V3, M3, Real)>,
}

impl Newest {
    pub fn new(per_slab: usize) -> Newest {
        Newest {
            slab: 0,
            first: u32::MAX,
            set_from: u32::MAX,
            fraction: 1.0,
            moving: false,
            index: Vec::with_capacity(per_slab),
            x0: Vec::with_capacity(per_slab),
            j0: Vec::with_capacity(per_slab),
            g2p: Vec::with_capacity(per_slab),
        }
    }

    /// Set the masses and volumes of particles `set_from..` among `p`'s particles `from..` (the
    /// slab's to its fraction, a just completed one's to full), and find the slab's particles
    /// there. A scan with one compare per particle: once particles are reordered, ids are not
    /// indices. Stepping passes `from = n_sleep`: the fraction changes only while the nozzle
    /// extrudes, and an extruding tube keeps its units awake, so a sleeping particle's mass is
    /// already its slab's (and scanning the sleeping prefix every step would cost what has been
    /// printed, not what moves).
    pub fn set_masses(&mut self, p: &mut Particles, rho: f64, vol: f64, from: usize) {
        self.index.clear();
        self.x0.clear();
        self.j0.clear();
        if self.set_from == u32::MAX {
            return;
        }
        let n = p.n;
        let (id, mass, vol0) = (p.id.as_slice(), p.mass.as_mut_slice(), p.vol0.as_mut_slice());
        for i in from..n {
            if id[i] >= self.set_from {
                let f = if id[i] >= self.first { self.fraction } else { 1.0 };
                mass[i] = (rho * vol * f) as Real;
                vol0[i] = (vol * f) as Real;
                if id[i] >= self.first {
                    debug_assert!(self.index.len() < self.index.capacity(), "a slab holds more particles than planned");
                    self.index.push(i as u32);
                }
            }
        }
        for &i in &self.index {
            self.x0.push(p.xg.as_slice()[i as usize]);
            self.j0.push(p.j.as_slice()[i as usize]);
        }
    }

    /// After G2P: blend the slab's particles with the feed moving at `v_feed` [m/s].
    pub fn follow_feed(&mut self, p: &mut Particles, dt: Real, inv_dx: Real, v_feed: V3) {
        self.g2p.clear();
        if !self.moving {
            return;
        }
        let f = self.fraction as Real;
        let g = 1.0 - f;
        for (k, &i) in self.index.iter().enumerate() {
            let i = i as usize;
            let (x, v, c, j) = (p.xg.as_slice()[i], p.v.as_slice()[i], p.c.as_slice()[i], p.j.as_slice()[i]);
            self.g2p.push((x, v, c, j));
            p.xg.as_mut_slice()[i] = (self.x0[k] + v_feed * (dt * inv_dx)) * g + x * f;
            p.v.as_mut_slice()[i] = v_feed * g + v * f;
            p.c.as_mut_slice()[i] = c * f;
            p.j.as_mut_slice()[i] = self.j0[k] * g + j * f;
        }
    }
}

/// Adjoint of [`Newest::follow_feed`] for particle `k` of the slab: takes the adjoints of the
/// blended outputs, returns those of G2P's outputs, and adds to those of the position and volume
/// ratio before the step, of v_feed and of f.
pub struct FollowFeedBar<'a> {
    pub x0: &'a mut V3,
    pub j0: &'a mut Real,
    pub v_feed: &'a mut V3,
    pub fraction: &'a mut f64,
}

#[allow(clippy::too_many_arguments)]
#[inline]
pub fn follow_feed_adjoint(
    f: Real,
    dt: Real,
    inv_dx: Real,
    x0: V3,
    j0: Real,
    v_feed: V3,
    g2p: (V3, V3, M3, Real),
    out_bar: (V3, V3, M3, Real),
    bar: FollowFeedBar,
) -> (V3, V3, M3, Real) {
    let (x, v, c, j) = g2p;
    let (xb, vb, cb, jb) = out_bar;
    let g = 1.0 - f;
    let move_scale = dt * inv_dx;
    let x_kin = x0 + v_feed * move_scale;
    let mut fb = xb.dot(x - x_kin) + vb.dot(v - v_feed) + (j - j0) * jb;
    for a in 0..3 {
        fb += cb.col(a).dot(c.col(a));
    }
    *bar.fraction += fb as f64;
    *bar.x0 += xb * g;
    *bar.j0 += jb * g;
    *bar.v_feed += xb * (g * move_scale) + vb * g;
    (xb * f, vb * f, cb * f, jb * f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follow_feed_adjoint_matches_central_differences() {
        // J(inputs) = <w, blend(inputs)>; every input's adjoint against central differences (the
        // blend is linear in each input alone, so the differences are exact up to rounding)
        let mut seed = 0x9e3779b97f4a7c15u64;
        let mut u = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Real
        };
        let mut v3 = || V3::new(u(), u(), u());
        let (x0, v_feed, x, v) = (v3(), v3(), v3(), v3());
        let (wx, wv) = (v3(), v3());
        let c = M3::from_cols(v3(), v3(), v3());
        let wc = M3::from_cols(v3(), v3(), v3());
        let (j0, j, wj): (Real, Real, Real) = (0.97, 1.02, 0.6);
        let (dt, inv_dx) = (0.01 as Real, 20.0 as Real);
        let blend = |f: Real, x0: V3, j0: Real, v_feed: V3, x: V3, v: V3, c: M3, j: Real| -> f64 {
            let g = 1.0 - f;
            let xo = (x0 + v_feed * (dt * inv_dx)) * g + x * f;
            let vo = v_feed * g + v * f;
            let co = c * f;
            let jo = j0 * g + j * f;
            let mut s = (wx.dot(xo) + wv.dot(vo) + wj * jo) as f64;
            for a in 0..3 {
                s += wc.col(a).dot(co.col(a)) as f64;
            }
            s
        };
        let f = 0.37 as Real;
        let (mut x0b, mut j0b, mut vfb, mut fb) = (V3::ZERO, 0.0 as Real, V3::ZERO, 0.0);
        let (xb, vb, cb, jb) = follow_feed_adjoint(
            f,
            dt,
            inv_dx,
            x0,
            j0,
            v_feed,
            (x, v, c, j),
            (wx, wv, wc, wj),
            FollowFeedBar { x0: &mut x0b, j0: &mut j0b, v_feed: &mut vfb, fraction: &mut fb },
        );
        let h = 1e-2 as Real;
        let cd = |plus: f64, minus: f64| (plus - minus) / (2.0 * h as f64);
        let tol = 1e3 * Real::EPSILON as f64;
        let close = |a: f64, b: f64, what: &str| assert!((a - b).abs() <= tol * (1.0 + b.abs()), "{what}: adjoint {a}, central difference {b}");
        close(fb, cd(blend(f + h, x0, j0, v_feed, x, v, c, j), blend(f - h, x0, j0, v_feed, x, v, c, j)), "f");
        close(j0b as f64, cd(blend(f, x0, j0 + h, v_feed, x, v, c, j), blend(f, x0, j0 - h, v_feed, x, v, c, j)), "J0");
        close(jb as f64, cd(blend(f, x0, j0, v_feed, x, v, c, j + h), blend(f, x0, j0, v_feed, x, v, c, j - h)), "J");
        for a in 0..3 {
            let e = [V3::X, V3::Y, V3::Z][a] * h;
            close(x0b[a] as f64, cd(blend(f, x0 + e, j0, v_feed, x, v, c, j), blend(f, x0 - e, j0, v_feed, x, v, c, j)), "x0");
            close(vfb[a] as f64, cd(blend(f, x0, j0, v_feed + e, x, v, c, j), blend(f, x0, j0, v_feed - e, x, v, c, j)), "v_feed");
            close(xb[a] as f64, cd(blend(f, x0, j0, v_feed, x + e, v, c, j), blend(f, x0, j0, v_feed, x - e, v, c, j)), "x");
            close(vb[a] as f64, cd(blend(f, x0, j0, v_feed, x, v + e, c, j), blend(f, x0, j0, v_feed, x, v - e, c, j)), "v");
            for r in 0..3 {
                let mut dc = M3::ZERO;
                dc.col_mut(a)[r] = h;
                close(cb.col(a)[r] as f64, cd(blend(f, x0, j0, v_feed, x, v, c + dc, j), blend(f, x0, j0, v_feed, x, v, c - dc, j)), "C");
            }
        }
    }
}
