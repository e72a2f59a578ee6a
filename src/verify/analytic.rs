//! Closed-form and experimental reference solutions for the verification suite.
//!
//! Everything here is plain `f64` (deliberately not the crate's `Real`), pure and
//! allocation free, so that a reference value never depends on the precision the
//! solver was built with.
//!
//! | function | problem | source |
//! | --- | --- | --- |
//! | [`newtonian_poiseuille_steady`] | steady plane Poiseuille flow | paper 000 App. B.1 |
//! | [`newtonian_poiseuille_transient`] | start-up plane Poiseuille flow (Fourier series) | Morris, Fox & Zhu (1997); Sigalotti et al. (2003), ref. \[67\] of paper 000 |
//! | [`bingham_poiseuille`] | steady Bingham plane Poiseuille flow with a plug | paper 001 eqs. (48)-(50) |
//! | [`hydrostatic_pressure`] | gauge pressure in a fluid at rest | - |
//! | [`abrams_cone_volume`], [`roussel_spread_radius`], [`roussel_profile`] | final shape of a slump-flow test | paper 001 sec. 4.1.1, eq. (51) (see the note on the profile) |
//! | [`martin_moyce_front`], [`interp_reference`] | dam-break surge front, experiment | Martin & Moyce (1952), Table 2, as transcribed in public code (see below) |
//!
//! Sign and geometry conventions: plane channel flows are along `x`, the channel
//! occupies `y in [-h/2, h/2]` with no-slip walls at `y = +-h/2`; the driving body
//! force per unit volume `f` (N/m^3) acts in `+x`. A body *acceleration* `F` (m/s^2,
//! as paper 000 B.1 quotes it, `F = 8 mm/s^2`) corresponds to `f = rho * F`.

use std::f64::consts::PI;

// ---------------------------------------------------------------------------
// Plane Poiseuille flow, Newtonian
// ---------------------------------------------------------------------------

/// Steady plane Poiseuille velocity of a Newtonian fluid.
///
/// Solves `0 = f + mu u''(y)` with `u(+-h/2) = 0`:
///
/// ```text
/// u(y) = f / (2 mu) * (h^2/4 - y^2),      u_max = u(0) = f h^2 / (8 mu).
/// ```
///
/// * `y`  - wall-normal coordinate, channel centre at `y = 0` (m)
/// * `h`  - channel height, walls at `y = +-h/2` (m)
/// * `f`  - driving body force per unit volume (N/m^3); `rho * F` for an acceleration `F`
/// * `mu` - dynamic viscosity (Pa s)
///
/// Returns 0 outside the channel (`|y| > h/2`).
pub fn newtonian_poiseuille_steady(y: f64, h: f64, f: f64, mu: f64) -> f64 {
    let half = 0.5 * h;
    if y.abs() > half {
        return 0.0;
    }
    f / (2.0 * mu) * (half * half - y * y)
}

/// Start-up plane Poiseuille flow of a Newtonian fluid from rest (Fourier series).
///
/// The fluid is at rest at `t = 0` and the body force `f` is switched on at `t = 0`;
/// `rho u_t = f + mu u_yy`, `u(+-h/2, t) = 0`, `u(y, 0) = 0`. With `eta = y + h/2`
/// (distance from the lower wall), `nu = mu / rho` and odd `k = 2n + 1`,
///
/// ```text
/// u(y, t) = f/(2 mu) eta (h - eta)
///         - sum_{n=0}^{terms-1} 4 f h^2 / (mu pi^3 k^3) sin(k pi eta / h) exp(-k^2 pi^2 nu t / h^2).
/// ```
///
/// This is the separation-of-variables series used as the reference solution for
/// SPH Poiseuille tests by J. P. Morris, P. J. Fox and Y. Zhu, "Modeling low
/// Reynolds number incompressible flows using SPH", J. Comput. Phys. 136 (1997)
/// 214-226, and by L. D. G. Sigalotti et al., J. Comput. Phys. 191 (2003) 622-638
/// (ref. \[67\] of paper 000, the analytical solution its Fig. B.1(c) compares with).
/// Those papers write it with a body acceleration `F`; here `F = f / rho`. The
/// series coefficients are the sine series of the steady parabola,
/// `eta (h - eta) = sum_k 8 h^2 / (pi^3 k^3) sin(k pi eta / h)` (odd `k`), so the
/// sum cancels the steady part exactly at `t = 0`; each mode decays with the
/// diffusion time `h^2 / (k^2 pi^2 nu)`.
///
/// * `terms` - number of (odd) modes kept. The truncation error is below
///   `4 f h^2/(mu pi^3) * sum_{k > 2 terms - 1} k^-3 ~ f h^2 / (2 mu pi^3 terms^2)` at `t = 0`
///   and decays exponentially for `t > 0`; a few tens of terms suffice once
///   `nu t / h^2 > 1e-3`.
///
/// For `t < 0` the fluid is at rest and 0 is returned; on the walls and outside the
/// channel exactly 0 is returned.
pub fn newtonian_poiseuille_transient(
    y: f64,
    t: f64,
    h: f64,
    f: f64,
    rho: f64,
    mu: f64,
    terms: usize,
) -> f64 {
    let half = 0.5 * h;
    // Walls (and outside) are exactly at rest; sin(k pi) is not exactly 0 in floating point.
    if y.abs() >= half || t < 0.0 {
        return 0.0;
    }
    let eta = y + half;
    let nu = mu / rho;
    let steady = f / (2.0 * mu) * eta * (h - eta);
    let amp = 4.0 * f * h * h / (mu * PI * PI * PI);
    let mut transient = 0.0;
    for n in 0..terms {
        let k = (2 * n + 1) as f64;
        let decay = (-k * k * PI * PI * nu * t / (h * h)).exp();
        transient += amp / (k * k * k) * (k * PI * eta / h).sin() * decay;
    }
    steady - transient
}

// ---------------------------------------------------------------------------
// Plane Poiseuille flow, Bingham
// ---------------------------------------------------------------------------

/// Steady plane Poiseuille velocity of a Bingham fluid (plug flow), paper 001 eqs. (48)-(50).
///
/// The shear stress balances the body force, `tau_xy = -f y`, so the material is
/// unyielded where `|f y| <= tau0`, i.e. inside the plug `|y| <= y0 = tau0 / f`:
///
/// ```text
/// v(y) = 1/(2 eta) [ f (h^2/4 - y^2)  - 2 tau0 (h/2 - |y|) ],   y0 < |y| <= h/2   (49)
/// v(y) = 1/(2 eta) [ f (h^2/4 - y0^2) - 2 tau0 (h/2 - y0)  ],   |y| <= y0        (50)
/// ```
///
/// (paper 001 cites Bird 2002). If `y0 >= h/2` the yield stress is never exceeded
/// and there is no flow. `tau0 = 0` gives [`newtonian_poiseuille_steady`] with `mu = eta`.
///
/// * `y`    - wall-normal coordinate, channel centre at 0 (m)
/// * `h`    - channel height (paper 001's `H`), walls at `+-h/2` (m)
/// * `f`    - body force per unit volume (N/m^3); a negative `f` drives the flow in `-x`
/// * `tau0` - yield stress (Pa), `>= 0`
/// * `eta`  - plastic viscosity (Pa s)
///
/// Returns 0 outside the channel.
pub fn bingham_poiseuille(y: f64, h: f64, f: f64, tau0: f64, eta: f64) -> f64 {
    let half = 0.5 * h;
    if y.abs() > half || f == 0.0 {
        return 0.0;
    }
    // Solve for |f| and restore the direction at the end (the problem is odd in f).
    let fa = f.abs();
    let y0 = tau0 / fa;
    if y0 >= half {
        return 0.0;
    }
    let s = y.abs().max(y0); // plug: evaluate (49) at |y| = y0, which is (50)
    let v = (fa * (half * half - s * s) - 2.0 * tau0 * (half - s)) / (2.0 * eta);
    v * f.signum()
}

// ---------------------------------------------------------------------------
// Hydrostatics
// ---------------------------------------------------------------------------

/// Hydrostatic gauge pressure at height `z` under a free surface at `z_top`.
///
/// `p(z) = rho g (z_top - z)` for `z <= z_top` (gravity `g > 0` acting in `-z`) and
/// `0` above the free surface. Atmospheric pressure is the zero.
pub fn hydrostatic_pressure(z: f64, z_top: f64, rho: f64, g: f64) -> f64 {
    rho * g * (z_top - z).max(0.0)
}

// ---------------------------------------------------------------------------
// Slump flow (Roussel)
// ---------------------------------------------------------------------------

/// Abrams cone height `H0` (m), paper 001 sec. 4.1.1.
pub const ABRAMS_H0: f64 = 0.300;
/// Abrams cone top radius `Rmin` (m), paper 001 sec. 4.1.1.
pub const ABRAMS_R_MIN: f64 = 0.050;
/// Abrams cone base radius `Rmax` (m), paper 001 sec. 4.1.1.
pub const ABRAMS_R_MAX: f64 = 0.100;

/// Volume of the Abrams cone (a conical frustum), in m^3.
///
/// `Omega = pi H0 / 3 (Rmin^2 + Rmin Rmax + Rmax^2)` with `H0 = 300 mm`,
/// `Rmin = 50 mm`, `Rmax = 100 mm` (paper 001 sec. 4.1.1; the same cone as paper 000
/// B.3): `Omega = 0.0175 pi / 10 = 5.4978e-3 m^3` (about 5.5 litres).
pub fn abrams_cone_volume() -> f64 {
    let (h, a, b) = (ABRAMS_H0, ABRAMS_R_MIN, ABRAMS_R_MAX);
    PI * h / 3.0 * (a * a + a * b + b * b)
}

/// Final slump-flow radius `R` of a Bingham material, paper 001 eq. (51)
/// (Roussel & Coussot 2005, "pancake" regime `H << R`, inertia and surface tension
/// neglected, flow stops where the wall shear stress reaches `tau0`):
///
/// ```text
/// R = ( 225 rho g Omega^2 / (128 pi^2 tau0) )^(1/5)
/// ```
///
/// * `rho` - density (kg/m^3), `g` - gravity (m/s^2), `omega` - sample volume (m^3),
///   `tau0` - yield stress (Pa).
///
/// The slump-flow *diameter* SF that experiments report is `2 R`. For the paper 001
/// benchmark (`tau0 = 50 Pa`, `rho = 2300`, `g = 9.81`, Abrams cone) `R = 0.29998 m`,
/// i.e. SF = 600 mm.
pub fn roussel_spread_radius(rho: f64, g: f64, omega: f64, tau0: f64) -> f64 {
    (225.0 * rho * g * omega * omega / (128.0 * PI * PI * tau0)).powf(0.2)
}

/// Final height profile `h(r)` of the slump-flow pancake of radius `R`.
///
/// ```text
/// h(r) = sqrt( 2 tau0 (R - r) / (rho g) ),   0 <= r <= R;   0 for r > R.
/// ```
///
/// **Note on paper 001 eq. (51):** the plain-text copy prints
/// `h(r) = 2 tau0 / (rho g) (R - r)` without the square root. That linear form is
/// dimensionally inconsistent (it has units of m^2) and does not reproduce the `R`
/// of the same equation. The stopping criterion `rho g h |dh/dr| = tau0` integrates
/// to `h^2 = 2 tau0 (R - r) / (rho g)`, and the volume of that profile,
/// `Omega = 2 pi int_0^R r h dr = (8 pi / 15) sqrt(2 tau0 / (rho g)) R^(5/2)`,
/// inverts exactly to eq. (51)'s `R`; the square-root form is therefore used here
/// (the unit tests check this volume consistency).
///
/// Argument order: `r` (m), `big_r` = `R` (m), `rho`, `g`, `tau0`. `|r|` is used so
/// a signed coordinate through the centre may be passed.
pub fn roussel_profile(r: f64, big_r: f64, rho: f64, g: f64, tau0: f64) -> f64 {
    let d = big_r - r.abs();
    if d <= 0.0 {
        return 0.0;
    }
    (2.0 * tau0 * d / (rho * g)).sqrt()
}

// ---------------------------------------------------------------------------
// Dam break: Martin & Moyce (1952) experimental surge front
// ---------------------------------------------------------------------------

/// Martin & Moyce (1952) column width `a` for [`martin_moyce_front`]: 2.25 in (m).
pub const MARTIN_MOYCE_A: f64 = 0.05715;
/// Martin & Moyce aspect parameter `n^2` (column height = `n^2 a`) for [`martin_moyce_front`].
pub const MARTIN_MOYCE_N2: f64 = 2.0;

/// Martin & Moyce (1952) surge-front positions, `(T, Z)` with
/// `T = n t sqrt(g / a) = t sqrt(2 g / a)` and `Z = z / a`.
///
/// **Experiment.** J. C. Martin and W. J. Moyce, "Part IV. An experimental study of
/// the collapse of liquid columns on a rigid horizontal plane", Phil. Trans. R. Soc.
/// Lond. A 244 (1952) 312-324, doi:10.1098/rsta.1952.0006. A 2D water column of
/// width `a` and height `n^2 a` collapses onto a dry horizontal floor; `z` is the
/// distance of the surge front (the toe) from the wall behind the column. **These
/// points are for `n^2 = 2` (column twice as high as wide), `a = 2.25 in = 0.05715 m`,
/// not for a square column.** No trustworthy tabulation of the `n^2 = 1` (square)
/// column was found (see below).
///
/// **Where the numbers come from.** The original paper is not open access and was
/// not consulted directly. The 15 points are transcribed from
/// `TormodLandet/Ocellaris`, `scripts/plot_dam_break.py` (commit 44fd559f4e36),
/// comment "Data from Martin and Moyce (1952), Table 2 and 6", whose plotting
/// code uses `n = sqrt(2)`, `a = 0.05715`, `T = t sqrt(g/a) n` and `Z = x_max / a`.
/// They are cross-checked against two independent public copies:
/// * `chaos-polymtl/lethe`, `examples/multiphysics/dam-break/dam-break-2d.py`: the
///   same first 13 points to within 0.02 (plus a `(0, 1)` initial point), used with a
///   column of width 3.5 and height 7 (`n^2 = 2`) and `T = t sqrt(2 g / a)`;
/// * `pypr/pysph`, `pysph/examples/db_exp_data.py` (`mm_data_2`, digitised from
///   Martin & Moyce's Fig. 3 for `n^2 = 2`, `a = 2.25 in`): agrees to within 0.07 in
///   `Z` over the common range (checked in the tests).
///
/// The `Z` values are the table's fixed stations (front positions 2.5, 2.75, 3.25,
/// 3.75, ... in, i.e. multiples of 0.25 in = a/9);
/// `T` is the measured arrival time. Data cover `0.41 <= T <= 3.33`. Note that some
/// numerical papers shift the simulated curve in time to absorb the finite gate
/// removal of the experiment (Lethe adds 0.175 to `T`); no shift is applied here.
///
/// **Paper 000, App. B.2** does not use this data set. It compares against
/// Lobovsky et al. (2014) \[75\] and the simulations of \[76, 77\]: "the normalized
/// time-front position curve is compared with experimental and existing simulation
/// results \[75-77\]"; "the normalized front with respect to the normalized time".
/// The text does not state the normalisation (Fig. B.2(b) is missing from the
/// text extraction), so the exact scaling the paper plots cannot be confirmed from
/// it. Its set-up, "consistent with Lobovsky's experiment", is a 1.6 m x 0.8 m x
/// 0.25 m domain with a 0.6 m x 0.6 m x 0.15 m initial fluid block
/// (8 x 60 x 60 x 15 = 432,000 particles at 0.01 m cells), `g = 9.8`, water with
/// `mu = 1e-3 Pa s`, slip walls, 0.5 s. It is therefore *not* a 0.3 m-high column:
/// if the 0.6 m x 0.6 m sides are the length and height, the column is square
/// (`n^2 = 1`), which is neither the aspect ratio of these Martin & Moyce points
/// (`n^2 = 2`) nor the `H = 0.3 m`, `L = 0.6 m` Lobovsky case; the order of the
/// block's dimensions is not stated in the text. A run compared with this
/// function must use a column of height `2a` and `T = t sqrt(2 g / a)`.
pub fn martin_moyce_front() -> &'static [(f64, f64)] {
    &MARTIN_MOYCE_FRONT
}

/// See [`martin_moyce_front`]: `(T, Z)`, `T = t sqrt(2g/a)`, `Z = z/a`, `n^2 = 2`, `a = 2.25 in`.
const MARTIN_MOYCE_FRONT: [(f64, f64); 15] = [
    (0.41, 1.11),
    (0.84, 1.22),
    (1.19, 1.44),
    (1.43, 1.67),
    (1.63, 1.89),
    (1.83, 2.11),
    (1.98, 2.33),
    (2.20, 2.56),
    (2.32, 2.78),
    (2.51, 3.00),
    (2.65, 3.22),
    (2.83, 3.44),
    (2.98, 3.67),
    (3.11, 3.89),
    (3.33, 4.11),
];

/// Martin & Moyce normalised time `T = n t sqrt(g / a)`, with `n = sqrt(n_squared)`
/// (`n_squared = 2` gives `t sqrt(2 g / a)`, the convention of [`martin_moyce_front`]).
pub fn martin_moyce_time(t: f64, a: f64, g: f64, n_squared: f64) -> f64 {
    t * (n_squared * g / a).sqrt()
}

/// Martin & Moyce surge front `Z(T)` by linear interpolation of [`martin_moyce_front`].
///
/// `t_norm` is `T = t sqrt(2 g / a)`. Returns `None` outside the measured range
/// `[0.41, 3.33]` (no extrapolation) or for NaN.
pub fn interp_reference(t_norm: f64) -> Option<f64> {
    let data = martin_moyce_front();
    let (t_first, _) = data[0];
    let (t_last, _) = data[data.len() - 1];
    if !(t_norm >= t_first && t_norm <= t_last) {
        return None;
    }
    for w in data.windows(2) {
        let ((t0, z0), (t1, z1)) = (w[0], w[1]);
        if t_norm <= t1 {
            let s = (t_norm - t0) / (t1 - t0);
            return Some(z0 + s * (z1 - z0));
        }
    }
    Some(data[data.len() - 1].1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    // Paper 000 B.1: 1 mm channel, water, F = 8 mm/s^2 (f = rho F = 8 N/m^3).
    const H: f64 = 1.0e-3;
    const RHO: f64 = 1000.0;
    const MU: f64 = 1.0e-3;
    const F: f64 = RHO * 8.0e-3;

    #[test]
    fn steady_poiseuille_centre_walls_and_ode() {
        let umax = F * H * H / (8.0 * MU);
        assert!(close(
            newtonian_poiseuille_steady(0.0, H, F, MU),
            umax,
            1e-15
        ));
        assert!(close(umax, 1.0e-3, 1e-15), "paper 000 case: u_max = 1 mm/s");
        assert_eq!(newtonian_poiseuille_steady(0.5 * H, H, F, MU), 0.0);
        assert_eq!(newtonian_poiseuille_steady(-0.5 * H, H, F, MU), 0.0);
        // mu u'' = -f by central differences (exact for a parabola up to rounding).
        let d = H * 1e-3;
        for &y in &[-0.3 * H, 0.0, 0.2 * H, 0.45 * H] {
            let upp = (newtonian_poiseuille_steady(y + d, H, F, MU)
                - 2.0 * newtonian_poiseuille_steady(y, H, F, MU)
                + newtonian_poiseuille_steady(y - d, H, F, MU))
                / (d * d);
            assert!(
                close(MU * upp, -F, 1e-6 * F),
                "y={y}: mu u''={} vs -f={}",
                MU * upp,
                -F
            );
        }
        // Mean velocity 2/3 u_max (Simpson on the parabola is exact).
        let mean = (newtonian_poiseuille_steady(-0.5 * H, H, F, MU)
            + 4.0 * newtonian_poiseuille_steady(0.0, H, F, MU)
            + newtonian_poiseuille_steady(0.5 * H, H, F, MU))
            / 6.0;
        assert!(close(mean, 2.0 / 3.0 * umax, 1e-15));
    }

    #[test]
    fn transient_poiseuille_converges_to_steady() {
        // Diffusion time h^2/nu = 1 s; at t = 20 s every mode is below exp(-197).
        for &y in &[-0.4 * H, -0.1 * H, 0.0, 0.25 * H, 0.49 * H] {
            let u = newtonian_poiseuille_transient(y, 20.0, H, F, RHO, MU, 50);
            let us = newtonian_poiseuille_steady(y, H, F, MU);
            assert!(
                close(u, us, 1e-12 * us.abs().max(1e-12)),
                "y={y}: {u} vs {us}"
            );
        }
        // At t = 1 s (paper 000's end time) the centre is within exp(-pi^2) of steady.
        let u1 = newtonian_poiseuille_transient(0.0, 1.0, H, F, RHO, MU, 50);
        let us = newtonian_poiseuille_steady(0.0, H, F, MU);
        let first_mode = 4.0 * F * H * H / (MU * PI.powi(3)) * (-PI * PI).exp();
        assert!(
            close(us - u1, first_mode, 1e-9 * us),
            "{} vs {}",
            us - u1,
            first_mode
        );
        // Monotone start-up at the centre.
        let mut prev = 0.0;
        for i in 1..=20 {
            let u = newtonian_poiseuille_transient(0.0, 0.05 * i as f64, H, F, RHO, MU, 50);
            assert!(u > prev && u < us);
            prev = u;
        }
    }

    #[test]
    fn transient_poiseuille_starts_from_rest() {
        let umax = newtonian_poiseuille_steady(0.0, H, F, MU);
        for &y in &[-0.45 * H, -0.2 * H, 0.0, 0.3 * H] {
            let u = newtonian_poiseuille_transient(y, 0.0, H, F, RHO, MU, 4000);
            assert!(u.abs() < 1e-6 * umax, "y={y}: u(t=0)={u}");
        }
        // Too few terms leave a visible residual: the test above can fail.
        let u_poor = newtonian_poiseuille_transient(0.0, 0.0, H, F, RHO, MU, 1);
        assert!(u_poor.abs() > 1e-3 * umax);
        assert_eq!(
            newtonian_poiseuille_transient(0.0, -1.0, H, F, RHO, MU, 10),
            0.0
        );
        assert_eq!(
            newtonian_poiseuille_transient(0.5 * H, 0.3, H, F, RHO, MU, 10),
            0.0
        );
    }

    #[test]
    fn transient_poiseuille_satisfies_pde() {
        // rho u_t = f + mu u_yy at interior points, by second-order central differences.
        let terms = 200;
        let dt = 1e-4;
        let dy = H * 1e-3;
        for &(y, t) in &[
            (0.0, 0.05),
            (0.2 * H, 0.1),
            (-0.35 * H, 0.3),
            (0.1 * H, 0.02),
        ] {
            let u = |yy: f64, tt: f64| newtonian_poiseuille_transient(yy, tt, H, F, RHO, MU, terms);
            let ut = (u(y, t + dt) - u(y, t - dt)) / (2.0 * dt);
            let uyy = (u(y + dy, t) - 2.0 * u(y, t) + u(y - dy, t)) / (dy * dy);
            let res = RHO * ut - (F + MU * uyy);
            assert!(res.abs() < 1e-4 * F, "y={y} t={t}: residual {res} (f={F})");
        }
    }

    // Paper 001 sec. 3.3 Bingham Poiseuille case: H = 0.5 m, F = 2000 N/m^3, eta = 30 Pa s.
    const HB: f64 = 0.5;
    const FB: f64 = 2000.0;
    const ETA: f64 = 30.0;

    #[test]
    fn bingham_wall_plug_continuity_and_slope() {
        for &tau0 in &[10.0, 50.0, 100.0, 200.0] {
            let y0 = tau0 / FB;
            assert_eq!(bingham_poiseuille(0.5 * HB, HB, FB, tau0, ETA), 0.0);
            assert!(bingham_poiseuille(-0.5 * HB, HB, FB, tau0, ETA).abs() < 1e-14);
            // Continuity at the yield surface.
            let e = 1e-9;
            let inside = bingham_poiseuille(y0 - e, HB, FB, tau0, ETA);
            let outside = bingham_poiseuille(y0 + e, HB, FB, tau0, ETA);
            assert!(
                close(inside, outside, 1e-9 * inside.abs().max(1.0)),
                "tau0={tau0}"
            );
            // Rigid plug: constant velocity, zero slope.
            let vp = bingham_poiseuille(0.0, HB, FB, tau0, ETA);
            for &y in &[-0.9 * y0, -0.3 * y0, 0.5 * y0, 0.99 * y0] {
                assert_eq!(bingham_poiseuille(y, HB, FB, tau0, ETA), vp);
            }
            // Plug velocity by hand: v = (H/2 - y0)^2 F / (2 eta).
            let hand = FB * (0.5 * HB - y0).powi(2) / (2.0 * ETA);
            assert!(close(vp, hand, 1e-12 * hand), "tau0={tau0}: {vp} vs {hand}");
            // Yielded region: stress balance tau0 + eta |dv/dy| = f |y|.
            let d = 1e-6;
            for &y in &[y0 + 0.2 * (0.5 * HB - y0), -(y0 + 0.7 * (0.5 * HB - y0))] {
                let dv = (bingham_poiseuille(y + d, HB, FB, tau0, ETA)
                    - bingham_poiseuille(y - d, HB, FB, tau0, ETA))
                    / (2.0 * d);
                let tau = tau0 + ETA * dv.abs();
                assert!(close(tau, FB * y.abs(), 1e-5 * FB * y.abs()), "tau={tau}");
            }
        }
    }

    #[test]
    fn bingham_reduces_to_newtonian_and_stops_below_yield() {
        for &y in &[-0.2, -0.05, 0.0, 0.1, 0.24] {
            let b = bingham_poiseuille(y, HB, FB, 0.0, ETA);
            let n = newtonian_poiseuille_steady(y, HB, FB, ETA);
            assert!(close(b, n, 1e-12 * n.abs().max(1e-12)), "y={y}: {b} vs {n}");
        }
        // Small tau0 is close to Newtonian (continuity in tau0).
        let b = bingham_poiseuille(0.0, HB, FB, 1e-6, ETA);
        let n = newtonian_poiseuille_steady(0.0, HB, FB, ETA);
        assert!(close(b, n, 1e-6 * n));
        // y0 = tau0 / f >= H/2: no flow.
        assert_eq!(bingham_poiseuille(0.0, HB, FB, 500.0, ETA), 0.0);
        assert_eq!(bingham_poiseuille(0.1, HB, FB, 600.0, ETA), 0.0);
        assert!(bingham_poiseuille(0.0, HB, FB, 499.0, ETA) > 0.0);
        // Odd in f.
        assert_eq!(
            bingham_poiseuille(0.1, HB, -FB, 50.0, ETA),
            -bingham_poiseuille(0.1, HB, FB, 50.0, ETA)
        );
        // A higher yield stress slows the flow everywhere.
        assert!(
            bingham_poiseuille(0.0, HB, FB, 200.0, ETA)
                < bingham_poiseuille(0.0, HB, FB, 10.0, ETA)
        );
    }

    #[test]
    fn hydrostatic() {
        assert_eq!(hydrostatic_pressure(0.3, 0.3, 1000.0, 9.81), 0.0);
        assert_eq!(hydrostatic_pressure(0.5, 0.3, 1000.0, 9.81), 0.0);
        assert!(close(
            hydrostatic_pressure(0.0, 0.6, 1000.0, 9.8),
            5880.0,
            1e-9
        ));
        assert!(close(
            hydrostatic_pressure(-1.0, 0.0, 2300.0, 9.81),
            22563.0,
            1e-9
        ));
    }

    #[test]
    fn abrams_volume_by_hand() {
        // Frustum = big cone minus the cut-off tip. The apex lies 0.3 m above the top
        // face (radius halves over 0.3 m), so the full cone has height 0.6 m.
        let big = PI * 0.1 * 0.1 * 0.6 / 3.0;
        let tip = PI * 0.05 * 0.05 * 0.3 / 3.0;
        let omega = abrams_cone_volume();
        println!(
            "Abrams cone volume = {omega:.9e} m^3 (hand: {:.9e})",
            big - tip
        );
        assert!(close(omega, big - tip, 1e-15));
        assert!(close(omega, 5.497787e-3, 1e-9));
    }

    #[test]
    fn roussel_paper_001_case() {
        let (rho, g, tau0) = (2300.0, 9.81, 50.0);
        let omega = abrams_cone_volume();
        let r = roussel_spread_radius(rho, g, omega, tau0);
        // Independent arrangement: invert the volume of the sqrt profile,
        // Omega = (8 pi/15) sqrt(2 tau0/(rho g)) R^(5/2)  =>  R = [15 Omega/(8 pi) sqrt(rho g/(2 tau0))]^(2/5).
        let r_vol = (15.0 * omega / (8.0 * PI) * (rho * g / (2.0 * tau0)).sqrt()).powf(0.4);
        // Hand computation: R^5 = 225*2300*9.81*Omega^2/(128*pi^2*50) = 2.4421e-3 m^5.
        let r_hand = 0.29998193;
        println!(
            "Roussel spread: R = {r:.8} m (volume inversion {r_vol:.8}, hand {r_hand}); SF = {:.1} mm; h(0) = {:.2} mm",
            2000.0 * r,
            1000.0 * roussel_profile(0.0, r, rho, g, tau0)
        );
        assert!(close(r, r_vol, 1e-12), "{r} vs {r_vol}");
        assert!(close(r, r_hand, 1e-7), "{r} vs {r_hand}");
    }

    #[test]
    fn roussel_profile_volume_and_stopping_criterion() {
        let (rho, g, tau0) = (2300.0, 9.81, 50.0);
        let omega = abrams_cone_volume();
        let big_r = roussel_spread_radius(rho, g, omega, tau0);
        // Volume of revolution, midpoint rule in s = sqrt(R - r) to remove the edge singularity:
        // r = R - s^2, dr = -2 s ds, Omega = int_0^sqrt(R) 2 pi r h(r) 2 s ds.
        let n = 20000;
        let smax = big_r.sqrt();
        let ds = smax / n as f64;
        let mut vol = 0.0;
        for i in 0..n {
            let s = (i as f64 + 0.5) * ds;
            let r = big_r - s * s;
            vol += 2.0 * PI * r * roussel_profile(r, big_r, rho, g, tau0) * 2.0 * s * ds;
        }
        assert!(
            close(vol, omega, 1e-6 * omega),
            "profile volume {vol} vs cone {omega}"
        );
        // rho g h |h'| = tau0 in the interior.
        let d = 1e-7;
        for &r in &[0.01, 0.1, 0.2, 0.28] {
            let hp = (roussel_profile(r + d, big_r, rho, g, tau0)
                - roussel_profile(r - d, big_r, rho, g, tau0))
                / (2.0 * d);
            let tau = rho * g * roussel_profile(r, big_r, rho, g, tau0) * hp.abs();
            assert!(close(tau, tau0, 1e-5 * tau0), "r={r}: {tau}");
        }
        assert_eq!(roussel_profile(big_r, big_r, rho, g, tau0), 0.0);
        assert_eq!(roussel_profile(1.2 * big_r, big_r, rho, g, tau0), 0.0);
        assert_eq!(
            roussel_profile(-0.1, big_r, rho, g, tau0),
            roussel_profile(0.1, big_r, rho, g, tau0)
        );
    }

    #[test]
    fn martin_moyce_data_shape() {
        let d = martin_moyce_front();
        assert_eq!(d.len(), 15);
        for w in d.windows(2) {
            assert!(w[1].0 > w[0].0 && w[1].1 > w[0].1, "not increasing: {w:?}");
        }
        // The front starts at the column's foot: Z > 1, increasing from there.
        assert!(d[0].1 > 1.0 && d[0].1 < 1.2);
        // Z stations are multiples of 0.25 in / 2.25 in: Z * 9 is (nearly) an integer.
        for &(_, z) in d {
            assert!((z * 9.0 - (z * 9.0).round()).abs() < 0.05, "Z={z}");
        }
        assert!(close(
            martin_moyce_time(1.0, MARTIN_MOYCE_A, 9.81, MARTIN_MOYCE_N2),
            (2.0 * 9.81 / 0.05715f64).sqrt(),
            1e-12
        ));
    }

    #[test]
    fn martin_moyce_interpolation() {
        let d = martin_moyce_front();
        for &(t, z) in d {
            assert!(close(interp_reference(t).unwrap(), z, 1e-12), "node T={t}");
        }
        assert_eq!(interp_reference(0.40), None);
        assert_eq!(interp_reference(3.34), None);
        assert_eq!(interp_reference(f64::NAN), None);
        let mid = interp_reference(0.5 * (1.19 + 1.43)).unwrap();
        assert!(close(mid, 0.5 * (1.44 + 1.67), 1e-12));
        let q = interp_reference(2.0).unwrap();
        assert!(close(
            q,
            2.33 + (2.0 - 1.98) / (2.20 - 1.98) * (2.56 - 2.33),
            1e-12
        ));
    }

    #[test]
    fn martin_moyce_matches_independent_digitisation() {
        // pypr/pysph pysph/examples/db_exp_data.py, mm_data_2 (n^2 = 2, a = 2.25 in),
        // digitised independently from Martin & Moyce's Fig. 3; points inside our range.
        let pysph = [
            (0.832, 1.217),
            (1.219, 1.474),
            (1.997, 2.292),
            (2.547, 2.995),
        ];
        for &(t, z) in &pysph {
            let zi = interp_reference(t).unwrap();
            println!("T={t}: table {zi:.3}, pysph digitisation {z}");
            assert!(close(zi, z, 0.08), "T={t}: {zi} vs {z}");
        }
        // chaos-polymtl/lethe dam-break-2d.py copy of the table (first 13 points, rounded).
        let lethe_t = [
            0.41, 0.84, 1.19, 1.43, 1.63, 1.82, 1.97, 2.2, 2.32, 2.5, 2.64, 2.82, 2.96,
        ];
        let lethe_z = [
            1.11, 1.23, 1.44, 1.67, 1.89, 2.11, 2.33, 2.56, 2.78, 3.0, 3.22, 3.44, 3.67,
        ];
        for (i, (&t, &z)) in lethe_t.iter().zip(lethe_z.iter()).enumerate() {
            assert!(
                close(d(i).0, t, 0.021) && close(d(i).1, z, 0.011),
                "point {i}"
            );
        }
        fn d(i: usize) -> (f64, f64) {
            martin_moyce_front()[i]
        }
    }
}
