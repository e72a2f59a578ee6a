//! A viscoelastic Maxwell branch (paper 004 sec. 2, eqs. 2.8-2.9; sec. 4.2, eqs. 4.5-4.9): a
//! spring G_M in series with a dashpot eta_M, whose deviatoric stress s_M is added to another
//! material's stress (in parallel with it: both see the same velocity gradient). Objective form,
//! with the Jaumann rate the EVP material's stress already uses:
//!
//! ```text
//! ds_M/dt - W s_M + s_M W = 2 G_M D' - s_M / t_M,     t_M = eta_M / G_M
//! ```
//!
//! (004 writes the relaxation time as lambda = mu / G in eq. 2.9, meaning eta / G; its large-strain
//! eq. 5.39-5.40 uses the upper-convected rate, here the Jaumann one, so a rigid spin leaves the
//! invariants of s_M unchanged exactly.)
//!
//! One step, for a velocity gradient held constant over it (004's recursive update, eq. 4.9c,
//! exact in time for constant D' instead of its midpoint factor exp(-dt / 2 t_M) dt):
//!
//! ```text
//! s_M' = e dev(sym(R s_M R^T)) + 2 G_M t_M (1 - e) D',     e = exp(-dt / t_M)
//! ```
//!
//! with R the Hughes-Winget rotation of the step ([`crate::real::jaumann_rotation`]). Below the
//! Weissenberg number t_M |grad v| << 1 this is the linear Maxwell model: a step strain relaxes
//! as exp(-t / t_M), and a constant shear rate gamma_dot builds s_xy = G_M t_M gamma_dot
//! (1 - exp(-t / t_M)), a steady stress eta_M gamma_dot with eta_M = G_M t_M. The update is
//! unconditionally stable in dt / t_M; its increment per step is at most 2 G_M dt D', that of a
//! spring G_M, which is why the time step counts G_M with the elastic shear modulus.
//!
//! These are free functions of the step's rotation R and D' = dev(sym(L)), so the material the
//! branch is added to computes both once for its own update and for the branch's.

use crate::real::{ddot, dev, r, sym, Real, M3};

/// exp(-dt / t_M) and 1 - exp(-dt / t_M), the latter without cancellation for dt << t_M.
#[inline]
fn decay(time: Real, dt: Real) -> (Real, Real) {
    let x = dt / time;
    ((-x).exp(), -(-x).exp_m1())
}

/// The branch's deviatoric stress after one step: `s_old` (before the step) rotated by `rot`,
/// relaxed by exp(-dt / t_M), plus the stress 2 G_M t_M (1 - exp(-dt / t_M)) D' that the
/// deviatoric rate of deformation `d_dev` builds over the step.
#[inline]
pub fn update(rot: &M3, d_dev: &M3, modulus: Real, time: Real, dt: Real, s_old: &M3) -> M3 {
    let (e, a) = decay(time, dt);
    // dev(sym()) drops the round-off trace and asymmetry of the rotation, as in the EVP trial
    // stress
    dev(&sym(&(*rot * *s_old * rot.transpose()))) * e + *d_dev * (r(2.0) * modulus * time * a)
}

/// Adjoints of what [`update`] read, for the adjoint `s_new_bar` of the stress it returned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Adjoint {
    pub rot_bar: M3,
    pub d_dev_bar: M3,
    pub s_old_bar: M3,
    pub modulus_bar: Real,
    pub time_bar: Real,
}

/// Vector-Jacobian product of [`update`] (dt held fixed).
#[inline]
pub fn update_adjoint(rot: &M3, d_dev: &M3, modulus: Real, time: Real, dt: Real, s_old: &M3, s_new_bar: &M3) -> Adjoint {
    let (e, a) = decay(time, dt);
    let x = dt / time;
    let rotated = dev(&sym(&(*rot * *s_old * rot.transpose())));
    let gain = r(2.0) * modulus * time * a;
    // s_new = rotated e + d_dev gain
    let e_bar = ddot(s_new_bar, &rotated);
    let gain_bar = ddot(s_new_bar, d_dev);
    // dev and sym are self-adjoint projections
    let proj_bar = dev(&sym(&(*s_new_bar * e)));
    // d e / d t_M = e x / t_M; d (t_M a) / d t_M = a - e x
    Adjoint {
        rot_bar: (proj_bar + proj_bar.transpose()) * *rot * *s_old,
        d_dev_bar: *s_new_bar * gain,
        s_old_bar: rot.transpose() * proj_bar * *rot,
        modulus_bar: gain_bar * r(2.0) * time * a,
        time_bar: gain_bar * r(2.0) * modulus * (a - e * x) + e_bar * e * x / time,
    }
}

/// Relaxation at rest over `duration` (no rotation, D' = 0), in place on the six packed entries
/// `[xx, yy, zz, xy, yz, xz]`: what `duration / dt` steps of [`update`] at rest do, up to
/// round-off.
#[inline]
pub fn relax(s: &mut [Real], time: Real, duration: Real) {
    let e = (-duration / time).exp();
    s.iter_mut().for_each(|v| *v *= e);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::test_util::simple_shear;
    use crate::real::{jaumann_rotation, skew, sym_to_array, V3};

    const EPS: Real = if cfg!(feature = "f32") { 1e-5 } else { 1e-12 };

    /// The branch stepped `n` times at a constant L from `s`, as a material would step it.
    fn run(l: &M3, modulus: Real, time: Real, dt: Real, n: usize, s: M3) -> M3 {
        let (rot, d) = (jaumann_rotation(&skew(l), dt), dev(&sym(l)));
        (0..n).fold(s, |s, _| update(&rot, &d, modulus, time, dt, &s))
    }

    fn max_abs(m: &M3) -> Real {
        m.to_cols_array().iter().fold(0.0, |a: Real, &x| a.max(x.abs()))
    }

    #[test]
    fn a_step_strain_relaxes_as_exp_minus_t_over_t_m() {
        let (g_m, t_m, dt) = (500.0 as Real, 0.2 as Real, 1e-3 as Real);
        // the step: a fast shear for 10 dt << t_M, gamma = 0.02
        let rate = 2.0 as Real;
        let s0 = run(&simple_shear(rate), g_m, t_m, dt, 10, M3::ZERO);
        // the Maxwell stress of the step, G_M t_M rate (1 - exp(-10 dt / t_M)), to O(Wi^2)
        let step = g_m * t_m * rate * (1.0 - (-10.0 * dt / t_m).exp());
        assert!((s0.y_axis.x / step - 1.0).abs() < 1e-3, "{} vs {step}", s0.y_axis.x);
        for n in [1usize, 100, 400, 1000] {
            let s = run(&M3::ZERO, g_m, t_m, dt, n, s0);
            let want = s0 * (-(n as Real) * dt / t_m).exp();
            assert!(max_abs(&(s - want)) <= 100.0 * EPS * max_abs(&s0), "n = {n}: {s:?} vs {want:?}");
            // what a sleeping particle gets in one call
            let mut packed = sym_to_array(&s0);
            relax(&mut packed, t_m, n as Real * dt);
            let got = sym_to_array(&s);
            for k in 0..6 {
                assert!((packed[k] - got[k]).abs() <= 100.0 * EPS * max_abs(&s0), "n = {n}, entry {k}: {packed:?} vs {got:?}");
            }
        }
    }

    #[test]
    fn a_constant_spin_free_rate_builds_the_closed_form_stress_exactly() {
        // planar extension: L symmetric, no rotation, so the update is exact in time
        let l = M3::from_diagonal(V3::new(1.5, -1.5, 0.0));
        let (g_m, t_m, dt) = (800.0 as Real, 0.05 as Real, 1e-3 as Real);
        for n in [1usize, 10, 50, 200, 1000] {
            let s = run(&l, g_m, t_m, dt, n, M3::ZERO);
            let t = n as Real * dt;
            let want = l * (2.0 * g_m * t_m * (1.0 - (-t / t_m).exp()));
            assert!(max_abs(&(s - want)) <= 1e3 * EPS * max_abs(&want), "t = {t}: {s:?} vs {want:?}");
        }
    }

    #[test]
    fn simple_shear_builds_eta_m_gamma_dot_and_the_corotational_steady_state() {
        let (g_m, t_m, dt) = (300.0 as Real, 0.5 as Real, 1e-4 as Real);
        // Weissenberg number t_M gamma_dot = 0.01: the linear Maxwell model, s_xy = G_M t_M
        // gamma_dot (1 - exp(-t / t_M)), up to relative O(Wi^2) = 1e-4
        let rate = 0.02 as Real;
        for n in [1000usize, 5000, 30000] {
            let s = run(&simple_shear(rate), g_m, t_m, dt, n, M3::ZERO);
            let want = g_m * t_m * rate * (1.0 - (-(n as Real) * dt / t_m).exp());
            assert!((s.y_axis.x / want - 1.0).abs() < 3e-4, "t = {}: {} vs {want}", n as Real * dt, s.y_axis.x);
        }
        // Wi = 0.5: the Jaumann (corotational) Maxwell model's steady state, s_xy = eta_M
        // gamma_dot / (1 + Wi^2) and s_xx = -s_yy = Wi s_xy (which the spin must get right)
        let rate = 1.0 as Real;
        let wi = t_m * rate;
        let s = run(&simple_shear(rate), g_m, t_m, dt, 100_000, M3::ZERO);
        let xy = g_m * t_m * rate / (1.0 + wi * wi);
        assert!((s.y_axis.x / xy - 1.0).abs() < 1e-3, "{} vs {xy}", s.y_axis.x);
        assert!((s.x_axis.x / (wi * xy) - 1.0).abs() < 1e-3, "{} vs {}", s.x_axis.x, wi * xy);
        assert!((s.y_axis.y / (wi * xy) + 1.0).abs() < 1e-3, "{}", s.y_axis.y);
        assert!(s.z_axis.z.abs() < 1e-9 * xy || cfg!(feature = "f32"));
    }

    #[test]
    fn zero_modulus_keeps_a_zero_stress_zero() {
        let l = M3::from_cols(V3::new(0.3, -2.0, 0.5), V3::new(3.0, -0.4, 1.2), V3::new(-0.7, 0.9, 0.2)) * 40.0;
        let s = run(&l, 0.0, 1.0, 1e-3, 100, M3::ZERO);
        assert!(s.to_cols_array().iter().all(|&x| x == 0.0), "{s:?}");
    }

    /// The branch from L, as a material calls it, against central differences and the Taylor
    /// test: inputs `[L (9), s_old (6), G_M, t_M]`, output s_M' (9).
    #[cfg(not(feature = "f32"))]
    struct Branch {
        dt: f64,
    }

    #[cfg(not(feature = "f32"))]
    impl crate::adjoint_check::Flat for Branch {
        fn forward(&self, x: &[f64]) -> Vec<f64> {
            let l = M3::from_cols_array(&std::array::from_fn(|i| x[i]));
            let s = crate::real::sym_from_slice(&x[9..15]);
            let rot = jaumann_rotation(&skew(&l), self.dt);
            update(&rot, &dev(&sym(&l)), x[15], x[16], self.dt, &s).to_cols_array().to_vec()
        }
        fn adjoint(&self, x: &[f64], cot: &[f64]) -> Vec<f64> {
            let l = M3::from_cols_array(&std::array::from_fn(|i| x[i]));
            let s = crate::real::sym_from_slice(&x[9..15]);
            let w = skew(&l);
            let rot = jaumann_rotation(&w, self.dt);
            let bar = M3::from_cols_array(&std::array::from_fn(|i| cot[i]));
            let a = update_adjoint(&rot, &dev(&sym(&l)), x[15], x[16], self.dt, &s, &bar);
            let l_bar = dev(&sym(&a.d_dev_bar)) + skew(&crate::real::jaumann_rotation_adjoint(&w, self.dt, &a.rot_bar));
            let mut s_bar = [0.0; 6];
            crate::real::sym_from_slice_adjoint(&a.s_old_bar, &mut s_bar);
            let mut g = l_bar.to_cols_array().to_vec();
            g.extend_from_slice(&s_bar);
            g.extend_from_slice(&[a.modulus_bar, a.time_bar]);
            g
        }
        fn groups(&self) -> Vec<(String, std::ops::Range<usize>)> {
            vec![("grad_v".into(), 0..9), ("s_old".into(), 9..15), ("maxwell_modulus".into(), 15..16), ("maxwell_time".into(), 16..17)]
        }
    }

    /// dt / t_M small (the usual case), 1, and 5 (the branch nearly a viscosity; much larger and
    /// exp(-dt / t_M) drops what s_old adds below the round-off of the differences).
    #[cfg(not(feature = "f32"))]
    #[test]
    fn adjoint_matches_central_differences_and_the_taylor_test() {
        use crate::adjoint_check::{group_errors, taylor_slope, Rng};
        let l = [0.3, -2.0, 0.5, 3.0, -0.4, 1.2, -0.7, 0.9, 0.2];
        let s = [100.0, -40.0, -60.0, 80.0, -30.0, 20.0];
        for (k, (t_m, dt)) in [(1.0, 1e-3), (0.01, 1e-2), (2e-3, 1e-2)].into_iter().enumerate() {
            let mut x: Vec<f64> = l.iter().map(|v| 20.0 * v).collect();
            x.extend_from_slice(&s);
            x.extend_from_slice(&[400.0, t_m]);
            let mut scale = vec![1.0; 9];
            scale.extend(s.iter().map(|v: &f64| v.abs()));
            scale.extend_from_slice(&[400.0, t_m]);
            let mut rng = Rng(91 + k as u64);
            let br = Branch { dt };
            let errs = group_errors(&br, &x, &scale, &mut rng);
            let worst = errs.iter().map(|e| e.1).fold(0.0, f64::max);
            let slope = taylor_slope(&br, &x, &scale, &mut rng).expect("the branch is nonlinear in t_M and L");
            println!("t_M = {t_M} s, dt = {dt} s: errors {errs:?}, Taylor slope {slope:.3}", t_M = t_m);
            assert!(worst < 1e-7, "{errs:?}");
            assert!(slope > 1.9, "Taylor remainder slope {slope}");
        }
    }
}
