//! Solid bodies inside the domain (`[[solid]]`): formwork, rebars, an L-box's gate, a slump
//! cone's mould, the nozzle's body.
//!
//! Each solid is a signed distance function ([`shape::Sdf`], one file per shape), a contact kind
//! (no-slip, free-slip or Coulomb friction, `kernels::boundary::WallKind`), a motion (static,
//! carried by the nozzle's outlet, or at a constant velocity) and, for a gate, the time it opens
//! (is removed). The grid update applies every solid to the nodes of the blocks it reaches, after
//! the domain walls, through the smoothed indicator of `kernels/src/solid.rs`; the momentum each
//! solid removes is summed per block slot and reduced in slot order into the force the material
//! exerts on it.
//!
//! Start-up builds everything (the shapes, a reaction pool of `max_blocks` slots per solid in the
//! memory plan); the step allocates nothing. A scenario without solids builds nothing, maps no
//! pool and runs exactly as before.

pub mod cuboid;
pub mod cylinder;
pub mod error;
pub mod frustum;
pub mod half_space;
pub mod nozzle_body;
pub mod revolved;
pub mod shape;
pub mod union;

use crate::grid::GridGeom;
use crate::kernels::boundary::WallKind;
use crate::kernels::solid::{contact, contact_adjoint, indicator};
use crate::kernels::{Real, V3};
use crate::memory::{Backing, Pool};
use crate::pools::{Counts, Per, PoolDecl, Pools, Role};
use crate::print::toolpath::Toolpath;
use glam::DVec3;
use serde::Deserialize;
use shape::{Sdf, ShapeConfig, ShapeContext};
use crate::invalid::Invalid;

/// The most solids a scenario may declare (a block's solids are a bit mask); more bodies fit
/// as parts of a union.
pub const MAX_SOLIDS: usize = 32;

/// How a solid moves.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    #[default]
    Static,
    /// Carried by the nozzle: the shape's coordinates are relative to the outlet centre, and it
    /// moves at the nozzle's velocity (without the extrusion speed).
    Nozzle,
    /// Translated at this constant velocity [m/s] from where it is declared at t = 0 (a slump
    /// cone lifted off its concrete): `motion = { velocity = [0.0, 0.0, 0.15] }`.
    Velocity([f64; 3]),
}

/// One `[[solid]]` table: `shape = "..."` with that shape's keys, and the keys below.
///
/// ```toml
/// [[solid]]
/// shape = "cylinder"          # box, cylinder, frustum, half_space, union, intersection, difference, nozzle
/// from = [0.2, 0.0, 0.05]
/// to = [0.2, 0.2, 0.05]
/// radius = 0.006
/// contact = { friction = { mu = 0.5 } }   # "no_slip" (default), "free_slip"
/// ```
#[derive(Clone, Debug, Deserialize)]
#[serde(try_from = "toml::Table")]
pub struct SolidConfig {
    pub shape: ShapeConfig,
    /// Label in messages and outputs (default `solid[i]`).
    pub name: Option<String>,
    /// Contact condition; default no-slip, free-slip for the nozzle body.
    pub contact: WallKind,
    pub motion: Motion,
    /// The time the solid is removed (a gate opening) [s]; never when absent.
    pub open_at: Option<f64>,
    /// Width of the indicator's band outside the surface [m]; default one cell, 0 for the hard
    /// indicator (the node on or inside the solid only).
    pub transition: Option<f64>,
}

/// The keys every solid takes besides its shape's.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Common {
    name: Option<String>,
    contact: Option<WallKind>,
    motion: Option<Motion>,
    open_at: Option<f64>,
    transition: Option<f64>,
}

const COMMON_KEYS: [&str; 5] = ["name", "contact", "motion", "open_at", "transition"];

impl TryFrom<toml::Table> for SolidConfig {
    type Error = Invalid;
    fn try_from(mut t: toml::Table) -> Result<Self, Invalid> {
        let mut common = toml::Table::new();
        for k in COMMON_KEYS {
            if let Some(v) = t.remove(k) {
                common.insert(k.to_string(), v);
            }
        }
        let c: Common = common.clone().try_into().map_err(|e: toml::de::Error| Invalid(format!("solid: {}: {}", failing_key(&common), e.message())))?;
        if !t.contains_key("shape") {
            return Err(Invalid("solid: `shape` is missing (one of: box, cylinder, frustum, half_space, union, intersection, difference, nozzle)".into()));
        }
        let shape: ShapeConfig = t.try_into().map_err(|e: toml::de::Error| Invalid(format!("solid: {}", e.message())))?;
        let nozzle = matches!(shape, ShapeConfig::Nozzle { .. });
        Ok(SolidConfig {
            contact: c.contact.unwrap_or(if nozzle { WallKind::FreeSlip } else { WallKind::NoSlip }),
            motion: c.motion.unwrap_or(if nozzle { Motion::Nozzle } else { Motion::Static }),
            shape,
            name: c.name,
            open_at: c.open_at,
            transition: c.transition,
        })
    }
}

/// The key path of `common` that does not deserialise, tried one key at a time: `motion.velocity`
/// for `motion = { velocity = [0.0, 0.15] }`, where serde's message names only the shape it
/// expected.
fn failing_key(common: &toml::Table) -> String {
    for (k, v) in common {
        let alone: toml::Table = std::iter::once((k.clone(), v.clone())).collect();
        if alone.try_into::<Common>().is_err() {
            // a one-key table (motion = { velocity = ... }) is named down to that key
            return match v.as_table().filter(|t| t.len() == 1).and_then(|t| t.keys().next()) {
                Some(inner) => format!("{k}.{inner}"),
                None => k.clone(),
            };
        }
    }
    COMMON_KEYS.join(", ")
}

/// Check the `[[solid]]` tables, naming the key (`solid[i].radius`, ...). `nozzle` is the
/// print's (inner diameter, tube height) when it prints through a circular nozzle, and
/// `printing` whether there is a `[print]` table at all.
pub fn validate(solids: &[SolidConfig], printing: bool) -> Result<(), Invalid> {
    if solids.len() > MAX_SOLIDS {
        return Err(Invalid(format!("solid: {} solids, more than the {MAX_SOLIDS} a scenario may declare; join some in a shape = \"union\"", solids.len())));
    }
    for (i, s) in solids.iter().enumerate() {
        let key = format!("solid[{i}]");
        s.shape.validate(&key)?;
        if s.contact == WallKind::Symmetry {
            return Err(Invalid(format!("{key}.contact: a solid takes no_slip, free_slip or friction, not symmetry")));
        }
        if let WallKind::Friction { mu } = s.contact {
            if !(mu >= 0.0 && mu.is_finite()) {
                return Err(Invalid(format!("{key}.contact.friction.mu must be >= 0, got {mu}")));
            }
        }
        if let Some(t) = s.open_at {
            if !t.is_finite() {
                return Err(Invalid(format!("{key}.open_at must be a finite time, got {t}")));
            }
            // the solid is present while t < open_at: before 0 it would never exist
            if t < 0.0 {
                return Err(Invalid(format!("{key}.open_at must be a time >= 0 s (the solid is removed then; 0 removes it at the start), got {t}: a negative time removes it before the run begins")));
            }
        }
        if let Some(d) = s.transition {
            if !(d >= 0.0 && d.is_finite()) {
                return Err(Invalid(format!("{key}.transition must be >= 0, got {d}")));
            }
        }
        if let Motion::Velocity(v) = s.motion {
            if !v.iter().all(|x| x.is_finite()) {
                return Err(Invalid(format!("{key}.motion.velocity must be finite, got {v:?}")));
            }
        }
        if matches!(s.shape, ShapeConfig::Nozzle { .. }) && s.motion != Motion::Nozzle {
            return Err(Invalid(format!("{key}: shape = \"nozzle\" moves with the nozzle; motion must be \"nozzle\"")));
        }
        if s.motion == Motion::Nozzle && !printing {
            return Err(Invalid(format!("{key}.motion = \"nozzle\" needs a [print] table")));
        }
    }
    Ok(())
}

/// A solid ready for the step.
#[derive(Debug)]
pub struct Solid {
    pub name: String,
    sdf: Box<dyn Sdf>,
    contact: WallKind,
    motion: Motion,
    open_at: Option<f64>,
    /// Band width [m].
    delta: f64,
    /// The shape's bounds padded by the band, in its own frame (None: unbounded).
    reach: Option<(DVec3, DVec3)>,
    /// Distances within this of 0 are on the surface [m]: a node on a face that lies on a node
    /// plane is computed a rounding error off it, and the hard indicator must not flip on that.
    on_surface: f64,
}

impl Solid {
    /// The signed distance at `q` in the shape's frame, 0 within `on_surface` of the surface.
    #[inline]
    fn distance(&self, q: DVec3) -> f64 {
        self.snapped(self.sdf.distance(q))
    }

    #[inline]
    fn snapped(&self, phi: f64) -> f64 {
        if phi.abs() <= self.on_surface {
            0.0
        } else {
            phi
        }
    }

    /// The largest weight this solid's band gives a node of `geom` through shape `sdf` (the
    /// solid's own or a part of it); 1 for an unbounded shape or one wholly outside the domain,
    /// which has nothing to hold.
    fn most_weight(&self, sdf: &dyn Sdf, geom: &GridGeom) -> f64 {
        let Some((lo, hi)) = padded(sdf, self.delta) else { return 1.0 };
        let tol = self.on_surface / geom.dx;
        let mut range = [(0i32, 0i32); 3];
        for a in 0..3 {
            let (lo, hi) = ((lo[a] - geom.origin[a]) / geom.dx, (hi[a] - geom.origin[a]) / geom.dx);
            if hi < geom.lo[a] - tol || lo > geom.hi[a] + tol {
                return 1.0;
            }
            range[a] = ((lo - tol).ceil().max(0.0) as i32, (hi + tol).floor().min(geom.cells[a] as f64) as i32);
        }
        let mut most = 0.0f64;
        for i in range[0].0..=range[0].1 {
            for j in range[1].0..=range[1].1 {
                for k in range[2].0..=range[2].1 {
                    let phi = self.snapped(sdf.distance(DVec3::from(geom.node_position([i, j, k]))));
                    most = most.max(indicator(phi as Real, self.delta as Real).0 as f64);
                    if most >= 1.0 {
                        return most;
                    }
                }
            }
        }
        most
    }
}

/// A shape's bounds padded by a band of width `delta` (None: unbounded): all its band reaches.
fn padded(sdf: &dyn Sdf, delta: f64) -> Option<(DVec3, DVec3)> {
    sdf.bounds().map(|(lo, hi)| (lo - DVec3::splat(delta), hi + DVec3::splat(delta)))
}

/// Where a solid is at one time.
#[derive(Clone, Copy, Debug, Default)]
pub struct Placement {
    /// Translation from the shape's frame to the world.
    pub offset: DVec3,
    pub velocity: DVec3,
    pub present: bool,
}

/// Every solid of a scenario, and the forces on them.
pub struct Solids {
    pub list: Vec<Solid>,
    /// Momentum each solid removed in each block slot during the last grid update:
    /// `[slot * n + solid]`.
    reactions: Pool<[f64; 3]>,
    /// Force the material exerted on each solid in the last step [N].
    force: Vec<[f64; 3]>,
}

impl Pools for Solids {
    fn pools(&self) -> Vec<PoolDecl<Self>> {
        vec![PoolDecl::new("solid.reactions", Per::Block(self.list.len()), Role::Scratch, |s| &s.reactions, |s| &mut s.reactions)]
    }
}

impl Solids {
    /// Build the solids of a scenario (None when it has none), their pool declared but not mapped
    /// ([`Pools::map_pools`] maps it). `nozzle` is the printer's (inner diameter, tube height)
    /// for a circular nozzle.
    pub fn declared(cfgs: &[SolidConfig], dx: f64, nozzle: Option<(f64, f64)>) -> Result<Option<Solids>, Invalid> {
        if cfgs.is_empty() {
            return Ok(None);
        }
        let cx = ShapeContext { nozzle };
        let mut list = Vec::with_capacity(cfgs.len());
        for (i, c) in cfgs.iter().enumerate() {
            let key = format!("solid[{i}]");
            let sdf = c.shape.build(&key, &cx)?;
            // the band lets a node's weight vary smoothly while the solid moves over the grid; a
            // static solid's weights are constants of the node, where a band would only widen it
            let delta = c.transition.unwrap_or(if c.motion == Motion::Static { 0.0 } else { dx });
            let reach = padded(&*sdf, delta);
            let on_surface = 1e-6 * dx;
            list.push(Solid { name: c.name.clone().unwrap_or(key), sdf, contact: c.contact, motion: c.motion, open_at: c.open_at, delta, reach, on_surface });
        }
        Ok(Some(Solids { force: vec![[0.0; 3]; list.len()], list, reactions: Pool::default() }))
    }

    /// The static solids that lie wholly outside the box `lo`..`hi` (the domain), with their
    /// bounds: they touch nothing, most often a shape written in mm where strand reads m.
    pub fn wholly_outside(&self, lo: [f64; 3], hi: [f64; 3]) -> Vec<(String, DVec3, DVec3)> {
        self.list
            .iter()
            .filter(|s| s.motion == Motion::Static)
            .filter_map(|s| s.sdf.bounds().map(|(a, b)| (s.name.clone(), a, b)))
            .filter(|(_, a, b)| (0..3).any(|k| b[k] < lo[k] || a[k] > hi[k]))
            .collect()
    }

    /// [`Solids::declared`] with `max_blocks` grid slots, mapped.
    pub fn new(cfgs: &[SolidConfig], dx: f64, nozzle: Option<(f64, f64)>, max_blocks: usize, backing: &Backing) -> Result<Option<Solids>, error::SolidError> {
        let mut solids = Solids::declared(cfgs, dx, nozzle)?;
        if let Some(s) = &mut solids {
            s.map_pools(&Counts::capacity(0, max_blocks), backing)?;
        }
        Ok(solids)
    }

    /// The solids' placements at time `t` (`toolpath`: the print's, for solids carried by the
    /// nozzle; from its end on the nozzle rests at its last position).
    pub fn at(&self, t: f64, toolpath: Option<&Toolpath>) -> SolidsAt<'_> {
        SolidsAt { list: &self.list, place: placements(&self.list, t, toolpath) }
    }

    /// The placements at time `t` and the reaction pool, apart, for the grid update.
    pub fn for_grid_update(&mut self, t: f64, toolpath: Option<&Toolpath>) -> (SolidsAt<'_>, &mut [[f64; 3]]) {
        let Solids { list, reactions, .. } = self;
        (SolidsAt { list, place: placements(list, t, toolpath) }, reactions.as_mut_slice())
    }

    /// Sum the reactions of slots `0..n_active` in slot order into each solid's force, for a step
    /// of length `dt`.
    pub fn total_forces(&mut self, n_active: usize, dt: f64) {
        let n = self.list.len();
        let r = self.reactions.as_slice();
        for (k, f) in self.force.iter_mut().enumerate() {
            let mut sum = [0.0; 3];
            for s in 0..n_active {
                for c in 0..3 {
                    sum[c] += r[s * n + k][c];
                }
            }
            *f = sum.map(|x| x / dt);
        }
    }

    /// Force the material exerted on solid `k` during the last step [N] (momentum it removed
    /// from the grid over dt).
    pub fn force(&self, k: usize) -> [f64; 3] {
        self.force[k]
    }

    pub fn len(&self) -> usize {
        self.list.len()
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The static solids, or parts of a union, no node of grid `geom` lies in (on or inside the
    /// surface), each named (`rebars`, `rebars.parts[1]`) with the largest weight a node of its
    /// band takes (0: the grid does not see it). Such a body, thinner than a cell and off the
    /// node planes, holds nothing fully: material seeps through it in proportion to `1 - w`.
    pub fn held_at_no_node(&self, geom: &GridGeom) -> Vec<(String, f64)> {
        let mut thin = Vec::new();
        for s in self.list.iter().filter(|s| s.motion == Motion::Static) {
            let parts = s.sdf.union_parts();
            let bodies: Vec<(String, &dyn Sdf)> = if parts.is_empty() {
                vec![(s.name.clone(), &*s.sdf)]
            } else {
                parts.iter().enumerate().map(|(i, p)| (format!("{}.parts[{i}]", s.name), &**p)).collect()
            };
            for (name, sdf) in bodies {
                let most = s.most_weight(sdf, geom);
                if most < 1.0 {
                    thin.push((name, most));
                }
            }
        }
        thin
    }
}

fn placements(list: &[Solid], t: f64, toolpath: Option<&Toolpath>) -> [Placement; MAX_SOLIDS] {
    let mut place = [Placement::default(); MAX_SOLIDS];
    let nozzle = toolpath.map(|tp| tp.state_at(t));
    for (p, s) in place.iter_mut().zip(list) {
        p.present = s.open_at.is_none_or(|o| t < o);
        match (s.motion, &nozzle) {
            (Motion::Nozzle, Some(n)) => {
                p.offset = DVec3::from(n.position);
                p.velocity = DVec3::from(n.velocity);
            }
            (Motion::Velocity(v), _) => {
                p.velocity = DVec3::from(v);
                p.offset = p.velocity * t;
            }
            _ => {}
        }
    }
    place
}

/// The solids at one time: what the grid update and its adjoint read.
pub struct SolidsAt<'a> {
    list: &'a [Solid],
    place: [Placement; MAX_SOLIDS],
}

/// Adjoints the grid update's adjoint takes from the solids at one node.
#[derive(Clone, Copy, Debug, Default)]
pub struct SolidsBar {
    /// Of the nozzle's outlet position, through the solids it carries.
    pub outlet: [f64; 3],
    /// Of the nozzle's velocity, through the solids it carries.
    pub nozzle_velocity: [f64; 3],
}

impl SolidsAt<'_> {
    pub fn len(&self) -> usize {
        self.list.len()
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The solids (as bits) present now whose band reaches a node of block `b`.
    pub fn block_mask(&self, geom: &GridGeom, b: [i32; 3]) -> u32 {
        let mut mask = 0;
        for (k, (s, p)) in self.list.iter().zip(&self.place).enumerate() {
            let reaches = match s.reach {
                None => true,
                Some((lo, hi)) => geom.block_overlaps(b, ((lo + p.offset).to_array(), (hi + p.offset).to_array())),
            };
            if p.present && reaches {
                mask |= 1 << k;
            }
        }
        mask
    }

    /// The signed distance, the normal into the solid and the solid's velocity at world point
    /// `x` for solid `k`, or None beyond its band.
    #[inline]
    fn near(&self, k: usize, x: DVec3) -> Option<(Real, V3, V3)> {
        let (s, p) = (&self.list[k], &self.place[k]);
        let q = x - p.offset;
        let phi = s.distance(q);
        if phi >= s.delta && s.delta > 0.0 || phi > 0.0 && s.delta == 0.0 {
            return None;
        }
        let n = -s.sdf.gradient(q);
        Some((phi as Real, V3::new(n.x as Real, n.y as Real, n.z as Real), V3::new(p.velocity.x as Real, p.velocity.y as Real, p.velocity.z as Real)))
    }

    /// Apply the solids of `mask` to node velocity `v` of mass `m` at world position `x`, in
    /// declaration order; the momentum each removes is added to `reactions[k]`.
    #[inline]
    pub fn apply(&self, mask: u32, x: [f64; 3], m: Real, mut v: V3, reactions: &mut [[f64; 3]]) -> V3 {
        let x = DVec3::from(x);
        let mut bits = mask;
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let Some((phi, n, vs)) = self.near(k, x) else { continue };
            let out = contact(self.list[k].contact, phi, self.list[k].delta as Real, n, vs, v);
            let dp = (v - out) * m;
            for c in 0..3 {
                reactions[k][c] += dp[c] as f64;
            }
            v = out;
        }
        v
    }

    /// Adjoint of [`SolidsAt::apply`] at a node: for the velocity `v` before the solids and the
    /// adjoint `v_bar` of the result, the adjoint of `v`; the adjoints of the nozzle's position
    /// and velocity through the solids it carries go to `bar`. The vertical component of the
    /// carried solids' velocity has no adjoint here (it is the nozzle's vertical speed without
    /// the extrusion speed, which the drive's adjoint does not separate).
    pub fn apply_adjoint(&self, mask: u32, x: [f64; 3], v: V3, v_bar: V3, bar: &mut SolidsBar) -> V3 {
        let x = DVec3::from(x);
        // inputs of each application, recomputed forward
        let mut inputs = [(0usize, V3::ZERO); MAX_SOLIDS];
        let mut count = 0;
        let mut at = v;
        let mut bits = mask;
        while bits != 0 {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let Some((phi, n, vs)) = self.near(k, x) else { continue };
            inputs[count] = (k, at);
            count += 1;
            at = contact(self.list[k].contact, phi, self.list[k].delta as Real, n, vs, at);
        }
        let mut b = v_bar;
        for &(k, vin) in inputs[..count].iter().rev() {
            let (phi, n, vs) = self.near(k, x).expect("the forward applied it");
            let s = &self.list[k];
            let cb = contact_adjoint(s.contact, phi, s.delta as Real, n, vs, vin, b);
            b = cb.v;
            if s.motion == Motion::Nozzle {
                // phi(x - o) and n = -grad phi(x - o): d/do = -grad phi phi_bar + H n_bar
                let q = x - self.place[k].offset;
                let g = s.sdf.gradient(q);
                let nb = DVec3::new(cb.normal.x as f64, cb.normal.y as f64, cb.normal.z as f64);
                let o_bar = -g * cb.phi as f64 + s.sdf.hessian_times(q, nb);
                for c in 0..2 {
                    bar.nozzle_velocity[c] += cb.v_solid[c] as f64;
                }
                for c in 0..3 {
                    bar.outlet[c] += o_bar[c];
                }
            }
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The adjoint of the solids at a node, through the nozzle body's position and velocity
    /// (its distance, and its normal through the Hessian), against central differences; at
    /// nodes under the flat end, beside the outer wall, in the bore and near the edges, moving
    /// into the body and away from it.
    #[test]
    fn the_nozzle_body_adjoint_matches_central_differences() {
        let cfg: SolidConfig = toml::from_str::<toml::Table>("shape = \"nozzle\"\nouter_diameter = 0.03\ncontact = { friction = { mu = 0.4 } }")
            .unwrap()
            .try_into()
            .unwrap();
        let (dx, backing) = (0.005, Backing { dir: None });
        let solids = Solids::new(&[cfg], dx, Some((0.012, 0.01)), 1, &backing).unwrap().unwrap();
        let outlet = DVec3::new(0.1, 0.05, 0.02);
        let vel = DVec3::new(0.08, -0.02, 0.0);
        let at = |o: DVec3, vs: DVec3| {
            let mut place = [Placement::default(); MAX_SOLIDS];
            place[0] = Placement { offset: o, velocity: vs, present: true };
            SolidsAt { list: &solids.list, place }
        };
        let h = 1e-7;
        let mut exercised = 0;
        for (dxyz, v) in [
            ([0.009, 0.002, -0.003], [0.1, 0.0, 0.2]),
            ([0.018, 0.004, 0.004], [-0.3, 0.1, 0.05]),
            ([0.0035, 0.001, 0.004], [0.0, 0.3, -0.1]),
            ([0.0165, 0.0045, -0.002], [-0.2, -0.1, 0.1]),
            ([0.004, -0.003, -0.002], [0.1, 0.1, 0.3]),
            ([0.012, 0.0, -0.001], [0.05, 0.0, -0.2]),
        ] {
            let x = (outlet + DVec3::from(dxyz)).to_array();
            let v = V3::new(v[0], v[1], v[2]);
            let v_bar = V3::new(0.7, -0.4, 1.1);
            let mut bar = SolidsBar::default();
            let b = at(outlet, vel).apply_adjoint(1, x, v, v_bar, &mut bar);
            let loss = |o: DVec3, vs: DVec3, v: V3| at(o, vs).apply(1, x, 1.0, v, &mut [[0.0; 3]]).dot(v_bar);
            for c in 0..3 {
                let mut e = DVec3::ZERO;
                e[c] = h;
                let fd_o = (loss(outlet + e, vel, v) - loss(outlet - e, vel, v)) / (2.0 * h);
                assert!((fd_o - bar.outlet[c]).abs() < 1e-5 * (1.0 + fd_o.abs()), "at {dxyz:?}: d/d outlet[{c}] {} against {fd_o}", bar.outlet[c]);
                let mut ev = V3::ZERO;
                ev[c] = h;
                let fd_v = (loss(outlet, vel, v + ev) - loss(outlet, vel, v - ev)) / (2.0 * h);
                assert!((fd_v - b[c]).abs() < 1e-6 * (1.0 + fd_v.abs()), "at {dxyz:?}: d/dv[{c}] {} against {fd_v}", b[c]);
                if c < 2 {
                    let fd_s = (loss(outlet, vel + e, v) - loss(outlet, vel - e, v)) / (2.0 * h);
                    assert!((fd_s - bar.nozzle_velocity[c]).abs() < 1e-6 * (1.0 + fd_s.abs()), "at {dxyz:?}: d/d velocity[{c}]");
                }
                exercised += (bar.outlet[c].abs() > 1.0) as usize;
            }
        }
        assert!(exercised > 3, "the position derivative was hardly exercised");
    }
}
