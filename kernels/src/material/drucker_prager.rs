//! Non-associated Drucker-Prager elastoplasticity with tension cutoff and a hypoelastic Jaumann
//! trial stress (paper 002 sec. 2.3 eq. 21 and App. A eqs. 37-55; the FLAC formulation).
//!
//! With tension positive, sigma_m = tr(sigma)/3, s = dev(sigma), tau = sqrt(s:s / 2):
//!
//! ```text
//! q_phi = 6 sin(phi) / (sqrt3 (3 + m sin phi)),  k_phi = 6 c cos(phi) / (sqrt3 (3 + m sin phi)),
//! q_psi = 6 sin(psi) / (sqrt3 (3 + m sin psi))                  (A, params; 002 has m = 1)
//! f_s = tau + q_phi sigma_m - k_phi       shear yield, plastic potential tau + q_psi sigma_m (41)
//! f_t = sigma_m - sigma_t                 tension cutoff, associated                        (42)
//! h   = tau - tau_P - alpha_P (sigma_m - sigma_t),  tau_P = k_phi - q_phi sigma_t,
//!       alpha_P = sqrt(1 + q_phi^2) - q_phi                                          (43, 44)
//! ```
//!
//! `cone_match` says which vertices of the Mohr-Coulomb hexagon the cone passes through (its
//! potential's cone the same for psi): `extension` (m = 1, the default and 002's), the triaxial-
//! extension vertices: at yield q / p = sqrt3 q_phi = 6 sin(phi) / (3 + sin(phi)) for c = 0, with
//! q = sqrt(3 J2) and p = -sigma_m; inside Mohr-Coulomb but at those vertices, and short of it
//! most at the compression vertices: there its q at a given p is (3 - sin phi) / (3 + sin phi)
//! of Mohr-Coulomb's, and its unconfined compressive strength 6 c cos(phi) / (3 - sin(phi)) is
//! 3 (1 - sin phi) / (3 - sin phi) of Mohr-Coulomb's 2 c cos(phi) / (1 - sin(phi)) (2.12 c against
//! 2.86 c at 20 deg). `compression` (m = -1), the triaxial-compression vertices: q / p = 6 sin(phi)
//! / (3 - sin(phi)), Mohr-Coulomb's strength wherever two principal stresses are equal and the
//! third the most compressive (unconfined and triaxial compression: a wall or a column under its
//! own weight), and outside Mohr-Coulomb elsewhere (its q up to (3 + sin phi) / (3 - sin phi) of
//! Mohr-Coulomb's at the extension vertices). The apex c cot(phi) is the same for both.
//! `tension_cutoff` sigma_t defaults to the cone apex c cot(phi) (no cutoff when phi = 0) and may
//! not exceed it.
//!
//! One step:
//! 1. trial sigma_tr = R sigma R^T + dt (K tr(D) I + 2 G D'), with R the Hughes-Winget rotation
//!    of the Jaumann rate ([`jaumann_rotation`]; first-order equal to eq. 38's
//!    sigma + dw sigma - sigma dw, but an exact rotation, so a rigid spin leaves the invariants
//!    unchanged).
//! 2. Zones (eqs. 45-47): f_t < 0 and f_s <= 0 elastic; shear return if f_t < 0 and f_s > 0, or
//!    f_t >= 0 and h > 0; tension return otherwise.
//! 3. Shear return (48-52): dl = f_s / (G + K q_phi q_psi), sigma_m -= K q_psi dl,
//!    tau = k_phi - q_phi sigma_m, s scaled radially.
//!    Tension return (53-55): sigma_m = sigma_t, s unchanged.
//! 4. Corner (not in 002): the single line h = 0 splits the two returns only approximately, so a
//!    shear return can land beyond the cutoff (always, when psi = 0 and the trial had
//!    sigma_m > sigma_t) and a tension return can keep tau > tau_P. Either result violates the other
//!    surface; the stress then goes to the corner (sigma_t, tau_P) where both hold.
//!
//! The equivalent plastic strain increment is sqrt(2/3 de_p:de_p) of the plastic strain
//! de_p = C^-1 : (sigma_tr - sigma), which is eq. 51 for the shear return, eq. 54 for the tension
//! return, and also covers the corner.
//!
//! The pressure is part of the stress state, not an EOS of J: dilatancy changes the mean stress
//! plastically, so the solver's `j` is not used and there is no `eos` key (it is rejected as
//! unknown).
//!
//! Per-particle state (7 reals): `[sigma_xx, sigma_yy, sigma_zz, sigma_xy, sigma_yz, sigma_xz,
//! eps_p]` — the full Cauchy stress [Pa] and the accumulated equivalent plastic strain [-]
//! (von Mises measure, sum of eqs. 51/54).

use serde::Deserialize;

use crate::material::eos::{resolve_shear_modulus, shear_modulus_of, shear_modulus_of_partials};
use crate::material::{non_negative, positive, Material, MaterialError, StabilityInfo, UpdateAdjoint};
use crate::real::{
    ddot, dev, jaumann_rotation, jaumann_rotation_adjoint, r, skew, sym, sym_from_slice, sym_from_slice_adjoint, sym_to_array,
    sym_to_array_adjoint, trace, Real, M3, V3,
};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DruckerPrager {
    /// Reference density rho0 [kg/m3].
    pub density: f64,
    /// Elastic bulk modulus K [Pa].
    pub bulk_modulus: f64,
    /// Elastic shear modulus G [Pa]; give this or `poisson_ratio`.
    #[serde(default)]
    pub shear_modulus: Option<f64>,
    /// Poisson's ratio nu [-], G = 3 K (1 - 2 nu) / (2 (1 + nu)); give this or `shear_modulus`.
    #[serde(default)]
    pub poisson_ratio: Option<f64>,
    /// Internal friction angle phi [deg].
    pub friction_angle_deg: f64,
    /// Dilatancy angle psi [deg], 0 <= psi <= phi.
    #[serde(default)]
    pub dilatancy_angle_deg: f64,
    /// Cohesion c [Pa].
    #[serde(default)]
    pub cohesion: f64,
    /// Tensile strength sigma_t of the mean stress [Pa]; defaults to the cone apex c cot(phi).
    #[serde(default)]
    pub tension_cutoff: Option<f64>,
    /// The Mohr-Coulomb vertices the cone passes through (module notes).
    #[serde(default)]
    pub cone_match: ConeMatch,
}

/// Which vertices of the Mohr-Coulomb hexagon the Drucker-Prager cone passes through (module
/// notes): `extension` (the default) or `compression`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConeMatch {
    #[default]
    Extension,
    Compression,
}

impl ConeMatch {
    /// m of the module notes: the sign of sin(phi) in the cone's denominator 3 + m sin(phi).
    fn m(self) -> f64 {
        match self {
            ConeMatch::Extension => 1.0,
            ConeMatch::Compression => -1.0,
        }
    }
}

/// Constants of the return map, derived once per batch (once per run of particles of one age for
/// a material whose parameters change with the particle's age, `early_age.rs`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Consts {
    pub(crate) k: Real,
    pub(crate) g: Real,
    pub(crate) q_phi: Real,
    pub(crate) k_phi: Real,
    pub(crate) q_psi: Real,
    pub(crate) sigma_t: Real,
    pub(crate) tau_p: Real,
    pub(crate) alpha_p: Real,
}

fn cone_slope(angle_deg: f64, matched: ConeMatch) -> f64 {
    let s = angle_deg.to_radians().sin();
    6.0 * s / (3f64.sqrt() * (3.0 + matched.m() * s))
}

/// Mean stress of the cone apex, k_phi / q_phi = c cot(phi); infinite for phi = 0.
pub(crate) fn apex(cohesion: f64, friction_angle_deg: f64) -> f64 {
    let phi = friction_angle_deg.to_radians();
    if phi > 0.0 {
        cohesion * phi.cos() / phi.sin()
    } else {
        f64::INFINITY
    }
}

/// What the return map's [`Consts`] are made of, in the scenario's f64: the elastic moduli, the
/// Mohr-Coulomb angles and cohesion, and the tension cutoff (`None`: the apex c cot(phi)). The
/// constants and their adjoint are built from it, so a material whose moduli or strength vary
/// (with age, `early_age.rs`) reuses this return map on constants of its own.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cone {
    pub(crate) k: f64,
    pub(crate) g: f64,
    pub(crate) phi_deg: f64,
    pub(crate) psi_deg: f64,
    pub(crate) cohesion: f64,
    pub(crate) cutoff: Option<f64>,
    pub(crate) matched: ConeMatch,
}

/// What a cone's constants take from its two angles: their trigonometry, the costly part of
/// [`Cone::consts`]. A material whose moduli and cohesion vary from particle to particle but
/// whose angles do not (an early-age solid with a constant friction angle) builds it once per
/// batch; the constants come out the same bits either way.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Angles {
    sin_phi: f64,
    cos_phi: f64,
    /// 3 + m sin(phi), k_phi's denominator over sqrt3 (module notes).
    den_phi: f64,
    /// phi > 0 in radians: a cone with an apex.
    has_apex: bool,
    q_phi: f64,
    q_psi: f64,
    alpha_p: f64,
}

impl Angles {
    pub(crate) fn of(phi_deg: f64, psi_deg: f64, matched: ConeMatch) -> Angles {
        let phi = phi_deg.to_radians();
        let q_phi = cone_slope(phi_deg, matched);
        Angles {
            sin_phi: phi.sin(),
            cos_phi: phi.cos(),
            den_phi: 3.0 + matched.m() * phi.sin(),
            has_apex: phi > 0.0,
            q_phi,
            q_psi: cone_slope(psi_deg, matched),
            alpha_p: (1.0 + q_phi * q_phi).sqrt() - q_phi,
        }
    }

    /// [`apex`] for these angles.
    pub(crate) fn apex(&self, cohesion: f64) -> f64 {
        if self.has_apex {
            cohesion * self.cos_phi / self.sin_phi
        } else {
            f64::INFINITY
        }
    }
}

impl Cone {
    pub(crate) fn consts(&self) -> Consts {
        self.consts_with(&Angles::of(self.phi_deg, self.psi_deg, self.matched))
    }

    /// [`Cone::consts`] with the trigonometry of its angles given (`angles` must be those of
    /// `phi_deg`, `psi_deg` and `matched`).
    pub(crate) fn consts_with(&self, angles: &Angles) -> Consts {
        let q_phi = angles.q_phi;
        let k_phi = 6.0 * self.cohesion * angles.cos_phi / (3f64.sqrt() * angles.den_phi);
        let sigma_t = self.cutoff.unwrap_or_else(|| angles.apex(self.cohesion));
        // q_phi = 0 has an infinite default cutoff; the corner shear stress is then just k_phi.
        // The floor absorbs the slack validate() allows above the apex.
        let tau_p = if q_phi > 0.0 {
            (k_phi - q_phi * sigma_t).max(0.0)
        } else {
            k_phi
        };
        Consts {
            k: r(self.k),
            g: r(self.g),
            q_phi: r(q_phi),
            k_phi: r(k_phi),
            q_psi: r(angles.q_psi),
            sigma_t: r(sigma_t),
            tau_p: r(tau_p),
            alpha_p: r(angles.alpha_p),
        }
    }

    /// Chain the adjoints of the constants `[K, G, q_phi, k_phi, q_psi, sigma_t, tau_P]` to the
    /// inputs: returns the adjoints of `[k, g, phi_deg, psi_deg, cohesion, cutoff]` (that of
    /// `cutoff` 0 when it is `None`, the apex's going to cohesion and phi).
    pub(crate) fn adjoint(&self, bar: [Real; 7]) -> [f64; 6] {
        // a real conversion in the f32 build
        #[allow(clippy::unnecessary_cast)]
        let [k_bar, g_bar, q_phi_bar, mut k_phi_bar, q_psi_bar, mut sigma_t_bar, tau_p_bar] = bar.map(|b| b as f64);
        let mut q_phi_bar = q_phi_bar;
        let to_rad = std::f64::consts::PI / 180.0;
        let phi = self.phi_deg.to_radians();
        let (sp, cp) = (phi.sin(), phi.cos());
        let m = self.matched.m();
        let den = 3.0 + m * sp;
        let q_phi = cone_slope(self.phi_deg, self.matched);
        let k_phi = 6.0 * self.cohesion * cp / (3f64.sqrt() * den);
        let sigma_t = self.cutoff.unwrap_or_else(|| apex(self.cohesion, self.phi_deg));
        // tau_P = max(k_phi - q_phi sigma_t, 0), or k_phi without friction
        if q_phi > 0.0 {
            if k_phi - q_phi * sigma_t > 0.0 {
                k_phi_bar += tau_p_bar;
                q_phi_bar -= tau_p_bar * sigma_t;
                sigma_t_bar -= tau_p_bar * q_phi;
            }
        } else {
            k_phi_bar += tau_p_bar;
        }
        // d cone_slope / d angle_deg, with s = sin(angle): 18 / (sqrt3 (3 + m s)^2) cos(angle) pi/180
        let slope_rate = |deg: f64| {
            let a = deg.to_radians();
            18.0 / (3f64.sqrt() * (3.0 + m * a.sin()).powi(2)) * a.cos() * to_rad
        };
        let mut phi_bar = q_phi_bar * slope_rate(self.phi_deg);
        let mut c_bar = k_phi_bar * 6.0 * cp / (3f64.sqrt() * den);
        phi_bar += k_phi_bar * 6.0 * self.cohesion / 3f64.sqrt() * (-sp * den - m * cp * cp) / (den * den) * to_rad;
        let psi_bar = q_psi_bar * slope_rate(self.psi_deg);
        let mut cut_bar = 0.0;
        if self.cutoff.is_some() {
            cut_bar = sigma_t_bar;
        } else if sp > 0.0 {
            // apex = c cot(phi)
            c_bar += sigma_t_bar * cp / sp;
            phi_bar -= sigma_t_bar * self.cohesion / (sp * sp) * to_rad;
        }
        [k_bar, g_bar, phi_bar, psi_bar, c_bar, cut_bar]
    }
}

impl DruckerPrager {
    pub fn validate(&self) -> Result<(), MaterialError> {
        positive("material.density", self.density)?;
        positive("material.bulk_modulus", self.bulk_modulus)?;
        resolve_shear_modulus(
            "material",
            self.bulk_modulus,
            self.shear_modulus,
            self.poisson_ratio,
        )?;
        let phi = self.friction_angle_deg;
        if !(phi.is_finite() && (0.0..90.0).contains(&phi)) {
            return Err(MaterialError::out_of_range("material.friction_angle_deg", "in [0, 90)", phi));
        }
        let psi = self.dilatancy_angle_deg;
        if !(psi.is_finite() && psi >= 0.0 && psi <= phi) {
            return Err(MaterialError::out_of_range(
                "material.dilatancy_angle_deg",
                format!("in [0, friction_angle_deg = {phi}]"),
                psi,
            ));
        }
        non_negative("material.cohesion", self.cohesion)?;
        if phi == 0.0 && self.cohesion == 0.0 {
            return Err(MaterialError::NoShearStrength);
        }
        if let Some(t) = self.tension_cutoff {
            let apex = self.apex();
            // The relative slack admits a cutoff written as c cot(phi) computed another way.
            if !(t.is_finite() && t >= 0.0 && t <= apex * (1.0 + 1e-12)) {
                return Err(MaterialError::out_of_range(
                    "material.tension_cutoff",
                    format!("in [0, c cot(phi) = {apex}] (the cone apex)"),
                    t,
                ));
            }
        }
        Ok(())
    }

    /// Elastic shear modulus G [Pa].
    #[inline]
    pub fn shear_modulus(&self) -> f64 {
        shear_modulus_of(self.bulk_modulus, self.shear_modulus, self.poisson_ratio)
    }

    /// Mean stress of the cone apex, k_phi / q_phi = c cot(phi); infinite for phi = 0.
    fn apex(&self) -> f64 {
        apex(self.cohesion, self.friction_angle_deg)
    }

    fn cone(&self) -> Cone {
        Cone {
            k: self.bulk_modulus,
            g: self.shear_modulus(),
            phi_deg: self.friction_angle_deg,
            psi_deg: self.dilatancy_angle_deg,
            cohesion: self.cohesion,
            cutoff: self.tension_cutoff,
            matched: self.cone_match,
        }
    }

    fn consts(&self) -> Consts {
        self.cone().consts()
    }

    /// Chain the adjoints of the constants `[K, G, q_phi, k_phi, q_psi, sigma_t, tau_P]` to the
    /// parameters in `param_names` order.
    fn consts_adjoint(&self, bar: [Real; 7], params_bar: &mut [Real]) {
        let [k_bar, g_bar, phi_bar, psi_bar, c_bar, cut_bar] = self.cone().adjoint(bar);
        let (k_total, second) = match (self.shear_modulus, self.poisson_ratio) {
            (None, Some(nu)) => {
                let (dg_dk, dg_dnu) = shear_modulus_of_partials(self.bulk_modulus, nu);
                (k_bar + g_bar * dg_dk, g_bar * dg_dnu)
            }
            _ => (k_bar, g_bar),
        };
        for (i, v) in [k_total, second, phi_bar, psi_bar, c_bar, cut_bar].into_iter().enumerate().take(params_bar.len()) {
            params_bar[i] += v as Real;
        }
    }
}

/// The hypoelastic trial stress of step 1, and the rotation it used.
#[inline]
pub(crate) fn trial(c: &Consts, grad_v: &M3, dt: Real, sigma_old: &M3) -> (M3, M3) {
    let d = sym(grad_v);
    let rot = jaumann_rotation(&skew(grad_v), dt);
    // sym() keeps the round-off asymmetry of the product out of the returned stress.
    let sigma_tr = sym(&(rot * *sigma_old * rot.transpose()))
        + dev(&d) * (r(2.0) * c.g * dt)
        + M3::from_diagonal(V3::splat(c.k * trace(&d) * dt));
    (sigma_tr, rot)
}

/// How far tau may rise at the stress held in `state` (its first 6 reals) before the cone or
/// the cutoff is reached, at this mean stress: min(-f_s, sigma_t - sigma_m) [Pa] (negative
/// outside). Why at this mean stress: a load that presses on the material raises tau by at
/// most its share and the cone's strength with its pressure, so the margin is a lower bound
/// for it; a load that pulls moves sigma_m towards the cutoff by no more than tau rises (a
/// uniaxial traction adds t / 3 to sigma_m and t / sqrt3 to tau), hence the cutoff's margin.
pub(crate) fn yield_margin(c: &Consts, state: &[Real]) -> Real {
    let sigma = sym_from_slice(&state[..6]);
    let sm = trace(&sigma) / r(3.0);
    let s = dev(&sigma);
    let tau = (r(0.5) * ddot(&s, &s)).sqrt();
    (c.k_phi - c.q_phi * sm - tau).min(c.sigma_t - sm)
}

/// One step of the return map on a state whose first 7 reals are the stress (6) and eps_p,
/// updated in place; returns the new stress.
#[inline]
pub(crate) fn return_map(c: &Consts, grad_v: &M3, dt: Real, state: &mut [Real]) -> M3 {
    let (sigma_tr, _) = trial(c, grad_v, dt, &sym_from_slice(&state[..6]));

    let sm_tr = trace(&sigma_tr) / r(3.0);
    let s_tr = dev(&sigma_tr);
    let tau_tr = (r(0.5) * ddot(&s_tr, &s_tr)).sqrt();
    let f_s = tau_tr + c.q_phi * sm_tr - c.k_phi;
    let f_t = sm_tr - c.sigma_t;

    let shear_return = || {
        let dl = f_s / (c.g + c.k * c.q_phi * c.q_psi);
        let sm = sm_tr - c.k * c.q_psi * dl;
        (sm, c.k_phi - c.q_phi * sm)
    };
    let (sm, tau) = if f_t < r(0.0) {
        if f_s <= r(0.0) {
            state[..6].copy_from_slice(&sym_to_array(&sigma_tr));
            return sigma_tr;
        }
        shear_return()
    } else if tau_tr - c.tau_p - c.alpha_p * f_t > r(0.0) {
        let (sm, tau) = shear_return();
        if sm > c.sigma_t {
            (c.sigma_t, c.tau_p)
        } else {
            (sm, tau)
        }
    } else {
        (c.sigma_t, tau_tr.min(c.tau_p))
    };

    // tau < tau_tr on every plastic branch, so tau_tr > 0 whenever the ratio is needed.
    let s = if tau < tau_tr {
        s_tr * (tau / tau_tr)
    } else {
        s_tr
    };
    let sigma = s + M3::from_diagonal(V3::splat(sm));

    let dtau = tau_tr - tau;
    let dsm = sm_tr - sm;
    let deps = (r(2.0 / 3.0)
        * (dtau * dtau / (r(2.0) * c.g * c.g) + dsm * dsm / (r(3.0) * c.k * c.k)))
        .sqrt();
    state[..6].copy_from_slice(&sym_to_array(&sigma));
    state[6] += deps;
    sigma
}

/// [`return_map`] for every particle of a batch: particle p's velocity gradient `grad_v[p]`, its
/// state `state[p * stride..]` (stress and eps_p first, updated in place), its new stress written
/// to `stress[p]`; `consts_of(its state)` gives its constants, called in particle order before
/// its step. Where the CPU has AVX2, W particles at a time take their elastic steps in lanes
/// (`drucker_prager_lanes.rs`, the same bits).
pub(crate) fn return_map_batch(grad_v: &[M3], dt: Real, state: &mut [Real], stride: usize, stress: &mut [M3], mut consts_of: impl FnMut(&[Real]) -> Consts) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::has_avx2() {
        use crate::material::drucker_prager_lanes::{elastic_steps, ElasticConsts};
        use crate::wide::W;
        done = grad_v.len() / W * W;
        for g in (0..done).step_by(W) {
            // plain loops: array::from_fn's closures were measured not to inline here
            let mut c = [consts_of(&state[g * stride..(g + 1) * stride]); W];
            for l in 1..W {
                c[l] = consts_of(&state[(g + l) * stride..(g + l + 1) * stride]);
            }
            let mut lanes = ElasticConsts { k: [r(0.0); W], g: [r(0.0); W], q_phi: [r(0.0); W], k_phi: [r(0.0); W], sigma_t: [r(0.0); W] };
            for (l, c) in c.iter().enumerate() {
                (lanes.k[l], lanes.g[l], lanes.q_phi[l], lanes.k_phi[l], lanes.sigma_t[l]) = (c.k, c.g, c.q_phi, c.k_phi, c.sigma_t);
            }
            let rows = &mut state[g * stride..(g + W) * stride];
            // SAFETY: the CPU has AVX2
            let elastic = unsafe { elastic_steps(&lanes, &grad_v[g..g + W], dt, rows, stride, &mut stress[g..g + W]) };
            for l in (0..W).filter(|l| elastic & (1 << l) == 0) {
                stress[g + l] = return_map(&c[l], &grad_v[g + l], dt, &mut rows[l * stride..(l + 1) * stride]);
            }
        }
    }
    for p in done..grad_v.len() {
        let st = &mut state[p * stride..(p + 1) * stride];
        let c = consts_of(st);
        stress[p] = return_map(&c, &grad_v[p], dt, st);
    }
}

/// Adjoint of [`return_map`] with the constants held: accumulates the adjoints of L and of the
/// state before the step (its first 7 reals) into `out` and returns the adjoints of the constants
/// `[K, G, q_phi, k_phi, q_psi, sigma_t, tau_P]` (for [`Cone::adjoint`]). The zone (elastic,
/// shear, tension, corner) and the `min`/`max` of the return are the branch held fixed;
/// `alpha_P` only selects the zone.
#[allow(clippy::too_many_arguments)]
pub(crate) fn return_map_adjoint(c: &Consts, grad_v: &M3, dt: Real, state_in: &[Real], stress_bar: &M3, state_out_bar: &[Real], out: &mut UpdateAdjoint) -> [Real; 7] {
    // forward, as in `return_map`
    let d = sym(grad_v);
    let w = skew(grad_v);
    let sigma_old = sym_from_slice(&state_in[..6]);
    let (sigma_tr, rot) = trial(c, grad_v, dt, &sigma_old);
    let sm_tr = trace(&sigma_tr) / r(3.0);
    let s_tr = dev(&sigma_tr);
    let tau_tr = (r(0.5) * ddot(&s_tr, &s_tr)).sqrt();
    let f_s = tau_tr + c.q_phi * sm_tr - c.k_phi;
    let f_t = sm_tr - c.sigma_t;
    let den = c.g + c.k * c.q_phi * c.q_psi;
    let dl = f_s / den;
    let sm_shear = sm_tr - c.k * c.q_psi * dl;
    #[derive(PartialEq)]
    enum Zone {
        Elastic,
        Shear,
        Corner,
        Tension,
    }
    let zone = if f_t < r(0.0) {
        if f_s <= r(0.0) {
            Zone::Elastic
        } else {
            Zone::Shear
        }
    } else if tau_tr - c.tau_p - c.alpha_p * f_t > r(0.0) {
        if sm_shear > c.sigma_t {
            Zone::Corner
        } else {
            Zone::Shear
        }
    } else {
        Zone::Tension
    };
    let (sm, tau) = match zone {
        Zone::Elastic => (sm_tr, tau_tr),
        Zone::Shear => (sm_shear, c.k_phi - c.q_phi * sm_shear),
        Zone::Corner => (c.sigma_t, c.tau_p),
        Zone::Tension => (c.sigma_t, tau_tr.min(c.tau_p)),
    };

    // adjoints of the constants
    let (mut k_bar, mut g_bar, mut q_phi_bar, mut k_phi_bar, mut q_psi_bar, mut sigma_t_bar, mut tau_p_bar) =
        (r(0.0), r(0.0), r(0.0), r(0.0), r(0.0), r(0.0), r(0.0));
    let sigma_bar = *stress_bar + sym_to_array_adjoint(&state_out_bar[..6]);
    out.state_bar[6] += state_out_bar[6];
    let mut sigma_tr_bar = sigma_bar;
    if zone != Zone::Elastic {
        let mut sm_bar = trace(&sigma_bar);
        let mut tau_bar = r(0.0);
        let mut tau_tr_bar = r(0.0);
        let mut sm_tr_bar = r(0.0);
        let mut s_tr_bar = sigma_bar;
        if tau < tau_tr {
            s_tr_bar = sigma_bar * (tau / tau_tr);
            let ratio_bar = ddot(&sigma_bar, &s_tr);
            tau_bar += ratio_bar / tau_tr;
            tau_tr_bar -= ratio_bar * tau / (tau_tr * tau_tr);
        }
        // eps_p += sqrt(2/3 (dtau^2 / (2 G^2) + dsm^2 / (3 K^2)))
        let (dtau, dsm) = (tau_tr - tau, sm_tr - sm);
        let e = r(2.0 / 3.0) * (dtau * dtau / (r(2.0) * c.g * c.g) + dsm * dsm / (r(3.0) * c.k * c.k));
        if e > r(0.0) {
            let e_bar = state_out_bar[6] / (r(2.0) * e.sqrt());
            let dtau_bar = e_bar * r(2.0 / 3.0) * dtau / (c.g * c.g);
            let dsm_bar = e_bar * r(2.0 / 3.0) * r(2.0) * dsm / (r(3.0) * c.k * c.k);
            g_bar -= e_bar * r(2.0 / 3.0) * dtau * dtau / (c.g * c.g * c.g);
            k_bar -= e_bar * r(2.0 / 3.0) * r(2.0) * dsm * dsm / (r(3.0) * c.k * c.k * c.k);
            tau_tr_bar += dtau_bar;
            tau_bar -= dtau_bar;
            sm_tr_bar += dsm_bar;
            sm_bar -= dsm_bar;
        }
        match zone {
            Zone::Shear => {
                // tau = k_phi - q_phi sm; sm = sm_tr - K q_psi dl; dl = f_s / den
                k_phi_bar += tau_bar;
                q_phi_bar -= tau_bar * sm;
                sm_bar -= tau_bar * c.q_phi;
                sm_tr_bar += sm_bar;
                k_bar -= sm_bar * c.q_psi * dl;
                q_psi_bar -= sm_bar * c.k * dl;
                let dl_bar = -sm_bar * c.k * c.q_psi;
                let f_s_bar = dl_bar / den;
                let den_bar = -dl_bar * dl / den;
                g_bar += den_bar;
                k_bar += den_bar * c.q_phi * c.q_psi;
                q_phi_bar += den_bar * c.k * c.q_psi;
                q_psi_bar += den_bar * c.k * c.q_phi;
                tau_tr_bar += f_s_bar;
                q_phi_bar += f_s_bar * sm_tr;
                sm_tr_bar += f_s_bar * c.q_phi;
                k_phi_bar -= f_s_bar;
            }
            Zone::Corner => {
                sigma_t_bar += sm_bar;
                tau_p_bar += tau_bar;
            }
            Zone::Tension => {
                sigma_t_bar += sm_bar;
                if tau_tr <= c.tau_p {
                    tau_tr_bar += tau_bar;
                } else {
                    tau_p_bar += tau_bar;
                }
            }
            Zone::Elastic => unreachable!(),
        }
        // tau_tr = sqrt(s_tr : s_tr / 2), s_tr = dev(sigma_tr), sm_tr = tr(sigma_tr) / 3
        if tau_tr > r(0.0) {
            s_tr_bar += s_tr * (r(0.5) * tau_tr_bar / tau_tr);
        }
        sigma_tr_bar = dev(&s_tr_bar) + M3::from_diagonal(V3::splat(sm_tr_bar / r(3.0)));
    }
    // sigma_tr = sym(R sigma R^T) + 2 G dt dev(d) + K dt tr(d) I
    let a_bar = sym(&sigma_tr_bar);
    let d_bar = dev(&sigma_tr_bar) * (r(2.0) * c.g * dt) + M3::from_diagonal(V3::splat(c.k * dt * trace(&sigma_tr_bar)));
    g_bar += r(2.0) * dt * ddot(&sigma_tr_bar, &dev(&d));
    k_bar += dt * trace(&d) * trace(&sigma_tr_bar);
    let rot_bar = a_bar * rot * sigma_old * r(2.0);
    *out.grad_v_bar += sym(&d_bar) + skew(&jaumann_rotation_adjoint(&w, dt, &rot_bar));
    sym_from_slice_adjoint(&(rot.transpose() * a_bar * rot), &mut out.state_bar[..6]);
    [k_bar, g_bar, q_phi_bar, k_phi_bar, q_psi_bar, sigma_t_bar, tau_p_bar]
}

impl Material for DruckerPrager {
    fn name(&self) -> &'static str {
        "drucker_prager"
    }

    fn state_names(&self) -> &'static [&'static str] {
        &[
            "sigma_xx", "sigma_yy", "sigma_zz", "sigma_xy", "sigma_yz", "sigma_xz", "eps_p",
        ]
    }

    fn init_state(&self, state: &mut [Real]) {
        state[..7].fill(r(0.0));
    }

    #[inline]
    fn update(&self, grad_v: &M3, _j: Real, dt: Real, state: &mut [Real]) -> M3 {
        return_map(&self.consts(), grad_v, dt, state)
    }

    /// Same as the default, with the trigonometry of the constants done once per batch and the
    /// elastic steps in lanes (`drucker_prager_lanes.rs`).
    fn update_batch(&self, grad_v: &[M3], _j: &[Real], dt: Real, state: &mut [Real], stress: &mut [M3]) {
        let c = self.consts();
        return_map_batch(grad_v, dt, state, 7, stress, |_| c);
    }

    fn param_names(&self) -> &'static [&'static str] {
        const G_CUT: [&str; 6] = ["bulk_modulus", "shear_modulus", "friction_angle_deg", "dilatancy_angle_deg", "cohesion", "tension_cutoff"];
        const NU_CUT: [&str; 6] = ["bulk_modulus", "poisson_ratio", "friction_angle_deg", "dilatancy_angle_deg", "cohesion", "tension_cutoff"];
        let names: &'static [&'static str; 6] = if self.shear_modulus.is_some() { &G_CUT } else { &NU_CUT };
        if self.tension_cutoff.is_some() {
            names
        } else {
            &names[..5]
        }
    }

    /// [`return_map_adjoint`] on this material's constants, chained to its parameters.
    fn update_adjoint(&self, grad_v: &M3, _j: Real, dt: Real, state_in: &[Real], stress_bar: &M3, state_out_bar: &[Real], out: &mut UpdateAdjoint) {
        let bar = return_map_adjoint(&self.consts(), grad_v, dt, state_in, stress_bar, state_out_bar, out);
        self.consts_adjoint(bar, out.params_bar);
    }


    fn stress_at_rest(&self, state: &[Real], _j: Real) -> M3 {
        // the full Cauchy stress is the state (the pressure is not an EOS of J)
        sym_from_slice(&state[..6])
    }

    fn stability(&self) -> StabilityInfo {
        StabilityInfo {
            density: r(self.density),
            bulk_modulus: r(self.bulk_modulus),
            shear_modulus: r(self.shear_modulus()),
            max_viscosity: r(0.0),
            thickening: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::{tau_of};
    use proptest::prelude::*;

    const EPS: Real = if cfg!(feature = "f32") { 1e-5 } else { 1e-10 };
    /// Relative tolerance of plastic increments, which are differences of nearly equal stresses.
    const INC: Real = if cfg!(feature = "f32") { 1e-3 } else { 1e-6 };

    fn sand() -> DruckerPrager {
        DruckerPrager {
            density: 2650.0,
            bulk_modulus: 1.0e7,
            shear_modulus: Some(5.0e6),
            poisson_ratio: None,
            friction_angle_deg: 30.0,
            dilatancy_angle_deg: 0.0,
            cohesion: 0.0,
            tension_cutoff: None,
            cone_match: ConeMatch::Extension,
        }
    }

    fn mean(s: &M3) -> Real {
        trace(s) / 3.0
    }

    fn iso(p: Real) -> M3 {
        M3::from_diagonal(V3::splat(p))
    }

    fn start(m: &DruckerPrager, sigma: M3) -> [Real; 7] {
        let mut st = [0.0; 7];
        m.init_state(&mut st);
        st[..6].copy_from_slice(&sym_to_array(&sigma));
        st
    }

    fn sin_deg(x: f64) -> Real {
        x.to_radians().sin() as Real
    }

    /// Runs `n` steps of constant L and returns the final stress and the eps_p of the last step.
    fn drive(m: &DruckerPrager, st: &mut [Real; 7], l: M3, dt: Real, n: usize) -> (M3, Real) {
        let mut sigma = M3::ZERO;
        let mut last = 0.0;
        for _ in 0..n {
            let before = st[6];
            sigma = m.update(&l, 1.0, dt, st);
            last = st[6] - before;
        }
        (sigma, last)
    }

    /// Triaxial compression (two principal stresses equal, the third the most compressive) ends
    /// on the cone at q / p = 6 sin(phi) / (3 + m sin(phi)): the extension-matched cone's ratio
    /// below Mohr-Coulomb's, the compression-matched cone's Mohr-Coulomb's own.
    #[test]
    fn isochoric_triaxial_compression_ends_on_the_cone_of_its_match() {
        for (matched, m_sign) in [(ConeMatch::Extension, 1.0), (ConeMatch::Compression, -1.0)] {
            let m = DruckerPrager { cone_match: matched, ..sand() };
            let p0 = 1.0e5 as Real;
            let mut st = start(&m, iso(-p0));
            let (e, dt) = (1.0 as Real, 1e-5 as Real);
            // Axial (z) shortening at constant volume: the mean stress stays -p0 while q grows.
            let l = M3::from_diagonal(V3::new(0.5 * e, 0.5 * e, -e));
            let (sigma, deps) = drive(&m, &mut st, l, dt, 3000);
            let p = -mean(&sigma);
            let q = 3f64.sqrt() as Real * tau_of(&sigma);
            let s = sin_deg(30.0);
            let ratio = 6.0 * s / (3.0 + m_sign * s);
            assert!((p - p0).abs() < EPS * p0, "{matched:?}: p = {p}");
            assert!((q / p - ratio).abs() < EPS, "{matched:?}: q/p = {}, expected {ratio}", q / p);
            // Triaxial compression: the axial stress is the most compressive, laterals equal.
            assert!(sigma.z_axis.z < sigma.x_axis.x && (sigma.x_axis.x - sigma.y_axis.y).abs() < EPS * p0);
            // Mohr-Coulomb (c = 0): (s1 - s3) / 2 + (s1 + s3) / 2 sin(phi) is 0 on its surface
            let mc = (sigma.x_axis.x - sigma.z_axis.z) / 2.0 + (sigma.x_axis.x + sigma.z_axis.z) / 2.0 * s;
            assert_eq!(mc.abs() < EPS * p0, matched == ConeMatch::Compression, "{matched:?}: Mohr-Coulomb residual {mc}");
            // Perfect plasticity at steady state: the whole strain increment is plastic,
            // eps_eq = sqrt(2/3 D:D) dt = e dt.
            assert!((deps - e * dt).abs() < INC * e * dt, "deps = {deps}");
        }
    }

    /// Unconfined compression: at Mohr-Coulomb's strength f = 2 c cos(phi) / (1 - sin(phi)) the
    /// compression-matched cone is reached (a margin of 0); the extension-matched one is reached
    /// at 3 (1 - sin phi) / (3 - sin phi) of f, and at f the stress is outside it (module notes).
    #[test]
    fn unconfined_compressive_strength_of_each_match() {
        for (phi, c) in [(20.0f64, 2.0e3f64), (35.0, 5.0e2)] {
            let (sp, cp) = (phi.to_radians().sin(), phi.to_radians().cos());
            let f = 2.0 * c * cp / (1.0 - sp);
            let state = [0.0, 0.0, -f as Real, 0.0, 0.0, 0.0, 0.0];
            let tol = if cfg!(feature = "f32") { 1e-5 } else { 1e-9 } * f as Real;
            for matched in [ConeMatch::Compression, ConeMatch::Extension] {
                let m = DruckerPrager { friction_angle_deg: phi, cohesion: c, cone_match: matched, ..sand() };
                let margin = yield_margin(&m.consts(), &state);
                if matched == ConeMatch::Compression {
                    assert!(margin.abs() < tol, "phi {phi}: margin {margin} at Mohr-Coulomb's strength");
                } else {
                    let f_ext = f * 3.0 * (1.0 - sp) / (3.0 - sp);
                    let state_ext = [0.0, 0.0, -f_ext as Real, 0.0, 0.0, 0.0, 0.0];
                    assert!(margin < -0.1 * f as Real / 3f64.sqrt() as Real, "phi {phi}: margin {margin}");
                    let margin_ext = yield_margin(&m.consts(), &state_ext);
                    assert!(margin_ext.abs() < tol, "phi {phi}: margin {margin_ext} at 3 (1 - s) / (3 - s) of it");
                }
            }
        }
    }

    #[test]
    fn triaxial_extension_yield_satisfies_mohr_coulomb() {
        for (phi, c) in [(30.0, 0.0), (35.0, 2.0e4), (20.0, 5.0e3)] {
            let m = DruckerPrager {
                friction_angle_deg: phi,
                cohesion: c,
                ..sand()
            };
            let p0 = 1.0e5 as Real;
            let mut st = start(&m, iso(-p0));
            let l = M3::from_diagonal(V3::new(-0.5, -0.5, 1.0));
            let (sigma, _) = drive(&m, &mut st, l, 1e-5, 3000);
            assert!(st[6] > 0.0);
            // Principal stresses: axial the largest (least compressive), laterals the smallest.
            let (s1, s3) = (sigma.z_axis.z, sigma.x_axis.x);
            let (sphi, cphi) = (sin_deg(phi), (phi as Real).to_radians().cos());
            let mc = (s1 - s3) / 2.0 + (s1 + s3) / 2.0 * sphi - c as Real * cphi;
            assert!(
                mc.abs() < EPS * p0,
                "phi={phi}, c={c}: Mohr-Coulomb residual {mc}"
            );
        }
    }

    #[test]
    fn isotropic_tension_is_capped_at_the_apex_or_the_cutoff() {
        for (cutoff, expect) in [(None, 1000.0 * 3f64.sqrt()), (Some(500.0), 500.0)] {
            let m = DruckerPrager {
                cohesion: 1000.0,
                tension_cutoff: cutoff,
                ..sand()
            };
            let mut st = start(&m, M3::ZERO);
            let (e, dt) = (1.0 as Real, 1e-6 as Real);
            let (sigma, deps) = drive(&m, &mut st, iso(e), dt, 500);
            assert!(
                (mean(&sigma) - expect as Real).abs() < EPS * 1e3,
                "{sigma:?}"
            );
            assert!(tau_of(&sigma) < EPS * 1e3);
            // Eq. 54: all of the volumetric rate 3e is plastic, eps_eq = sqrt2/3 * 3e dt.
            assert!((deps - 2f64.sqrt() as Real * e * dt).abs() < INC * e * dt);
        }
    }

    #[test]
    fn cohesionless_sand_carries_no_tension() {
        let m = sand();
        let mut st = start(&m, M3::ZERO);
        let (sigma, _) = drive(
            &m,
            &mut st,
            M3::from_diagonal(V3::new(1.0, 0.0, 0.0)),
            1e-5,
            200,
        );
        assert!(mean(&sigma) <= 0.0 && tau_of(&sigma) <= EPS, "{sigma:?}");
    }

    #[test]
    fn shear_return_follows_the_non_associated_flow_rule() {
        // One step from a state on the cone with a spin-free L, so the trial stress is known:
        // the correction (d sigma_m, d tau) must be K q_psi : G, and the result on the cone.
        let (phi, psi) = (35.0, 10.0);
        let m = DruckerPrager {
            friction_angle_deg: phi,
            dilatancy_angle_deg: psi,
            cohesion: 1e4,
            ..sand()
        };
        let sigma0 = M3::from_cols(
            V3::new(-8e4, 1e4, 0.0),
            V3::new(1e4, -1.2e5, 5e3),
            V3::new(0.0, 5e3, -1e5),
        );
        let l = M3::from_cols(
            V3::new(1.0, 2.0, 0.0),
            V3::new(2.0, -3.0, 1.0),
            V3::new(0.0, 1.0, 0.5),
        );
        let dt = 5e-3 as Real;
        let mut st = start(&m, sigma0);
        let sigma = m.update(&l, 1.0, dt, &mut st);
        let (k, g) = (1.0e7 as Real, 5.0e6 as Real);
        let trial = sigma0 + dev(&l) * (2.0 * g * dt) + iso(k * trace(&l) * dt);
        let q = |a: f64| 6.0 * sin_deg(a) / (3f64.sqrt() as Real * (3.0 + sin_deg(a)));
        let kphi = 6.0 * 1e4 * (phi as Real).to_radians().cos()
            / (3f64.sqrt() as Real * (3.0 + sin_deg(phi)));
        let (dsm, dtau) = (mean(&trial) - mean(&sigma), tau_of(&trial) - tau_of(&sigma));
        assert!(
            dtau > 0.0 && dsm > 0.0,
            "must be a plastic step: {dsm} {dtau}"
        );
        assert!((dsm / dtau - k * q(psi) / g).abs() < INC, "{}", dsm / dtau);
        let fs = tau_of(&sigma) + q(phi) * mean(&sigma) - kphi;
        assert!(fs.abs() < EPS * 1e5, "f_s = {fs}");
        // Eq. 51 with dl = dtau / G.
        let eq51 = dtau / g * (1.0 / 3.0 + 2.0 / 9.0 * q(psi) * q(psi)).sqrt();
        assert!((st[6] - eq51).abs() < INC * eq51);
    }

    #[test]
    fn rigid_rotation_keeps_the_invariants_and_stays_elastic() {
        let m = DruckerPrager {
            cohesion: 1e4,
            ..sand()
        };
        let sigma0 = M3::from_cols(
            V3::new(-8e4, 1e4, 0.0),
            V3::new(1e4, -1.2e5, 5e3),
            V3::new(0.0, 5e3, -1e5),
        );
        let mut st = start(&m, sigma0);
        // W x = a x x with a = (3, 1, 2).
        let w = M3::from_cols(
            V3::new(0.0, 2.0, -1.0),
            V3::new(-2.0, 0.0, 3.0),
            V3::new(1.0, -3.0, 0.0),
        );
        let (sigma, _) = drive(&m, &mut st, w, 1e-3, 1000);
        assert!((mean(&sigma) - mean(&sigma0)).abs() < EPS * 1e5);
        assert!((tau_of(&sigma) - tau_of(&sigma0)).abs() < EPS * 1e5);
        assert!(
            ((sigma.determinant() - sigma0.determinant()) / sigma0.determinant()).abs()
                < 100.0 * EPS
        );
        assert_eq!(st[6], 0.0);
        // Co-rotation with the material over t = 1: sigma = Q sigma0 Q^T, Q = exp(W) (Rodrigues).
        let a = V3::new(3.0, 1.0, 2.0);
        let (angle, k) = (a.length(), w * (1.0 / a.length()));
        let q = M3::IDENTITY + k * angle.sin() + k * k * (1.0 - angle.cos());
        let err = (sigma - q * sigma0 * q.transpose())
            .to_cols_array()
            .iter()
            .fold(0.0 as Real, |e, &x| e.max(x.abs()));
        assert!(err < 1e-4 * 1.2e5, "co-rotation error {err}");
    }

    #[test]
    fn batch_update_matches_single_updates() {
        let m = DruckerPrager {
            cohesion: 2e3,
            dilatancy_angle_deg: 5.0,
            ..sand()
        };
        // 11 particles: whole groups of lanes and a tail, in f64 and f32; within a group, lanes
        // that stay elastic beside lanes that yield in shear or in tension, spin, and a -0
        let k = |i: usize| (i as Real * 0.37).sin();
        let ls: Vec<M3> = (0..11)
            .map(|i| match i % 4 {
                0 => M3::from_diagonal(V3::new(1.0, 0.0, -2.0)) * k(i),
                1 => M3::from_diagonal(V3::splat(3.0)),
                2 => M3::from_cols_array(&std::array::from_fn(|j| 1e-3 * k(i + 3 * j))),
                _ => M3::from_cols(V3::new(-0.0, 0.4, 0.0), V3::new(-0.4, 1e-4 * k(i), 0.0), V3::ZERO),
            })
            .collect();
        let n = ls.len();
        let mut a = vec![0.0; 7 * n];
        let mut b = a.clone();
        let mut out = vec![M3::ZERO; n];
        for _ in 0..100 {
            m.update_batch(&ls, &vec![1.0; n], 1e-4, &mut a, &mut out);
            for p in 0..n {
                let s = m.update(&ls[p], 1.0, 1e-4, &mut b[p * 7..(p + 1) * 7]);
                assert_eq!(s.to_cols_array().map(|x| x.to_bits()), out[p].to_cols_array().map(|x| x.to_bits()), "particle {p}");
            }
        }
        assert_eq!(a.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), b.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        assert!(a.chunks(7).any(|st| st[6] > 0.0) && a.chunks(7).any(|st| st[6] == 0.0), "some particles yield, some stay elastic");
    }

    proptest! {
        #[test]
        fn every_step_ends_admissible(
            ls in proptest::collection::vec(proptest::array::uniform9(-1.0f64..1.0), 1..40),
            cohesion in prop_oneof![Just(0.0), 0.0f64..5e4],
            psi_frac in 0.0f64..1.0,
            cutoff_frac in prop_oneof![Just(None), (0.0f64..1.0).prop_map(Some)],
        ) {
            let mut m = DruckerPrager { cohesion, dilatancy_angle_deg: 30.0 * psi_frac, ..sand() };
            m.tension_cutoff = cutoff_frac.map(|f| f * m.apex());
            prop_assert!(m.validate().is_ok());
            let c = m.consts();
            let mut st = start(&m, iso(-5e4));
            for l in &ls {
                let l = M3::from_cols_array(&l.map(|x| x as Real));
                let sigma = m.update(&l, 1.0, 2e-3, &mut st);
                let (sm, tau) = (mean(&sigma), tau_of(&sigma));
                let scale = 1e5 + tau.abs() + sm.abs();
                prop_assert!(tau + c.q_phi * sm - c.k_phi <= EPS * scale, "f_s > 0: sm {} tau {}", sm, tau);
                prop_assert!(sm - c.sigma_t <= EPS * scale, "f_t > 0: sm {}", sm);
                prop_assert!(tau >= 0.0 && st[6] >= 0.0);
            }
        }
    }

    #[test]
    fn validation_and_unknown_eos_key() {
        assert!(sand().validate().is_ok());
        let bad = DruckerPrager {
            dilatancy_angle_deg: 40.0,
            ..sand()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("material.dilatancy_angle_deg"));
        let bad = DruckerPrager {
            friction_angle_deg: 0.0,
            ..sand()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("no shear strength"));
        let bad = DruckerPrager {
            cohesion: 1e3,
            tension_cutoff: Some(2e3),
            ..sand()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("material.tension_cutoff"));
        let bad = DruckerPrager {
            friction_angle_deg: 90.0,
            ..sand()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("material.friction_angle_deg"));
        // phi = 0 with cohesion: von Mises with no tension limit.
        let vm = DruckerPrager {
            friction_angle_deg: 0.0,
            cohesion: 1e3,
            ..sand()
        };
        assert!(vm.validate().is_ok());
        let mut st = start(&vm, M3::ZERO);
        let (sigma, _) = drive(&vm, &mut st, iso(1.0), 1e-5, 10);
        assert!((mean(&sigma) - 3.0e7 * 1e-4).abs() < EPS * 3e3, "{sigma:?}");

        use serde::de::value::{Error, MapDeserializer};
        let with_eos = DruckerPrager::deserialize(MapDeserializer::<_, Error>::new(
            [
                ("density", 2650.0),
                ("bulk_modulus", 1e7),
                ("friction_angle_deg", 30.0),
                ("eos", 0.0),
            ]
            .into_iter(),
        ));
        assert!(with_eos.unwrap_err().to_string().contains("eos"));
    }

    /// Where a step ended, read off its result: `"elastic"` (no plastic strain), `"shear"`
    /// (plastic, off the cutoff), `"tension"` (on the cutoff below tau_P) or `"corner point"`
    /// (sigma_t, tau_P), where the corner and a tension return with tau capped both end, with the
    /// same derivatives.
    #[cfg(not(feature = "f32"))]
    fn zone_of(m: &DruckerPrager, l: &M3, dt: Real, state: &[Real; 7]) -> &'static str {
        let mut st = *state;
        let sigma = m.update(l, 1.0, dt, &mut st);
        let c = m.consts();
        // The returns set sigma_m and tau exactly; reading them back off the stress adds rounding.
        let near = |a: Real, b: Real| (a - b).abs() <= 1e-9 * (1e4 + b.abs());
        if st[6] == state[6] {
            "elastic"
        } else if !near(mean(&sigma), c.sigma_t) {
            "shear"
        } else if near(tau_of(&sigma), c.tau_p) {
            "corner point"
        } else {
            "tension"
        }
    }

    /// Every zone of the return map: elastic, shear return from inside the tension cutoff and
    /// from beyond it, the corner, tension with tau kept and with tau capped at tau_P, and with
    /// the default cutoff (the apex c cot(phi), whose adjoint reaches cohesion and friction) the
    /// apex return and the corner at the apex; with G or nu. Each case is checked at three points
    /// drawn around its base point (L, stress direction and size); the points sit well inside
    /// their zone (asserted), so the differences never straddle a zone boundary.
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_in_every_zone() {
        use crate::adjoint_check::Rng;
        use crate::material::test_util::check_update_adjoint;
        fn make(poisson: bool, cut: bool, cone_match: ConeMatch) -> impl Fn(&[f64]) -> DruckerPrager {
            move |p: &[f64]| DruckerPrager {
                density: 2000.0,
                bulk_modulus: p[0],
                shear_modulus: (!poisson).then_some(p[1]),
                poisson_ratio: poisson.then_some(p[1]),
                friction_angle_deg: p[2],
                dilatancy_angle_deg: p[3],
                cohesion: p[4],
                tension_cutoff: cut.then(|| p[5]),
                cone_match,
            }
        }
        // A stress of mean sm and tau = size along the deviator of `u`.
        let stress = |sm: f64, size: f64, u: &[f64]| -> [f64; 7] {
            let t = (u[0] + u[1] + u[2]) / 3.0;
            let d = [u[0] - t, u[1] - t, u[2] - t];
            let norm = (0.5 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + u[3] * u[3] + u[4] * u[4] + u[5] * u[5]).sqrt();
            let k = size / norm;
            [sm + k * d[0], sm + k * d[1], sm + k * d[2], k * u[3], k * u[4], k * u[5], 0.01]
        };
        let u0 = [0.8, -0.5, -0.3, 0.35, -0.2, 0.25];
        // non-symmetric: spin as well as stretching
        let l0 = [0.3, -0.8, 0.5, 1.0, -0.4, 0.6, -0.7, 0.9, 0.2];
        let (g, nu) = (vec![1e7, 5e6], vec![1e7, 0.2857]); // the same G
        let with = |elastic: &[f64], rest: &[f64]| [elastic, rest].concat();
        // (label, zone, poisson, cut, params, mean stress, tau)
        let cases = [
            ("elastic", "elastic", false, false, with(&g, &[30.0, 10.0, 1e4]), -1e4, 1e3),
            ("shear", "shear", false, false, with(&g, &[30.0, 10.0, 1e4]), -1e4, 3e4),
            ("shear, nu", "shear", true, false, with(&nu, &[30.0, 10.0, 1e4]), -1e4, 3e4),
            ("shear beyond the cutoff", "shear", false, true, with(&g, &[30.0, 10.0, 1e4, 1e4]), 1.2e4, 2e4),
            ("corner", "corner point", false, true, with(&g, &[30.0, 0.0, 1e4, 1e4]), 2e4, 2e4),
            ("tension", "tension", true, true, with(&nu, &[30.0, 10.0, 1e4, 1e4]), 2e4, 1e3),
            ("tension, tau capped", "corner point", false, true, with(&g, &[30.0, 10.0, 1e4, 1e4]), 2e4, 5e3),
            ("apex", "corner point", false, false, with(&g, &[30.0, 10.0, 1e4]), 3e4, 1e3),
            ("apex, nu", "corner point", true, false, with(&nu, &[30.0, 10.0, 1e4]), 3e4, 1e3),
            ("corner at the apex", "corner point", false, false, with(&g, &[30.0, 0.0, 1e4]), 2.5e4, 2e4),
            ("shear, compression-matched", "shear", true, false, with(&nu, &[30.0, 10.0, 1e4]), -1e4, 3e4),
            ("apex, compression-matched", "corner point", false, false, with(&g, &[30.0, 10.0, 1e4]), 3e4, 1e3),
        ];
        for (k, (label, zone, poisson, cut, params, sm, tau)) in cases.into_iter().enumerate() {
            let cone_match = if label.ends_with("compression-matched") { ConeMatch::Compression } else { ConeMatch::Extension };
            let mut rng = Rng(7 + k as u64);
            // psi = 0 is the edge of its range, and nothing on the cutoff depends on it
            let scale: Vec<f64> = params.iter().enumerate().map(|(i, v)| if i == 3 && *v == 0.0 { 0.0 } else { v.abs().max(1.0) * 0.01 }).collect();
            for i in 0..3 {
                let l: Vec<f64> = l0.iter().map(|x| x + rng.uniform(-0.2, 0.2)).collect();
                let mut l = M3::from_cols_array(&l.try_into().unwrap());
                if zone == "corner point" {
                    // On the corner point K reaches the result only through eps_p's tiny
                    // volumetric part, below the rounding K tr(D) dt leaves in the stress; with a
                    // trace-free L that term is exactly 0 and the K differences see eps_p alone.
                    l -= M3::from_diagonal(V3::splat(trace(&l) / 3.0));
                }
                let u: Vec<f64> = u0.iter().map(|x| x + rng.uniform(-0.1, 0.1)).collect();
                let state = stress(sm * rng.uniform(0.95, 1.05), tau * rng.uniform(0.95, 1.05), &u);
                let label = format!("{label} #{i}");
                assert_eq!(zone_of(&make(poisson, cut, cone_match)(&params), &l, 1e-4, &state), zone, "{label}");
                let state_scale: Vec<f64> = state.iter().map(|v| v.abs().max(1.0) * 0.01).collect();
                check_update_adjoint(&label, make(poisson, cut, cone_match), &params, l, 1.0, 1e-4, &state, 0.1, &state_scale, &scale, 1e-6, 50 + 10 * k as u64 + i);
            }
        }
    }
}
