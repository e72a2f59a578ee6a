//! Test harness shared by the kernels' adjoints: a vector-Jacobian product checked against
//! fourth-order central differences, input group by input group, and the Taylor remainder test.
//!
//! Only compiled for tests, and only meaningful in f64 (central differences in f32 resolve
//! about three digits).

// `v as Real` and `as f64` are no-ops in the default f64 build and real conversions under
// `--features f32`; both builds compile this file.
#![allow(clippy::unnecessary_cast)]

use crate::material::{Material, UpdateAdjoint};
use crate::real::{Real, M3, V3};

/// A tiny deterministic generator (xorshift*), so failures reproduce from the seed.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn vec(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n).map(|_| self.uniform(lo, hi)).collect()
    }
}

/// A differentiable map from a flat input vector to a flat output vector, with its VJP, and the
/// named input groups (ranges) the check perturbs one at a time.
pub trait Flat {
    fn forward(&self, x: &[f64]) -> Vec<f64>;
    /// Adjoint of the inputs for the output cotangent `cot`.
    fn adjoint(&self, x: &[f64], cot: &[f64]) -> Vec<f64>;
    fn groups(&self) -> Vec<(String, std::ops::Range<usize>)>;
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn axpy(x: &[f64], h: f64, d: &[f64]) -> Vec<f64> {
    x.iter().zip(d).map(|(a, b)| a + h * b).collect()
}

/// Relative mismatch, per input group, between the adjoint and fourth-order central differences
/// of `<cot, f(x + h d)>` along a random direction `d` in that group, scaled by `scale[i]` per
/// input (so a bulk modulus of 1e6 and a strain rate of 1 are both perturbed by a relative `h`).
pub fn group_errors(k: &impl Flat, x: &[f64], scale: &[f64], rng: &mut Rng) -> Vec<(String, f64)> {
    let cot = rng.vec(k.forward(x).len(), -1.0, 1.0);
    let grad = k.adjoint(x, &cot);
    const H: f64 = 1e-4;
    k.groups()
        .into_iter()
        .map(|(name, range)| {
            let mut d = vec![0.0; x.len()];
            for i in range {
                d[i] = rng.uniform(-1.0, 1.0) * scale[i];
            }
            let at = |h: f64| k.forward(&axpy(x, h, &d));
            let (p1, m1, p2, m2) = (at(H), at(-H), at(2.0 * H), at(-2.0 * H));
            let fd = (0..cot.len()).map(|i| cot[i] * (8.0 * (p1[i] - m1[i]) - (p2[i] - m2[i]))).sum::<f64>() / (12.0 * H);
            let ad = dot(&grad, &d);
            let err = if fd == ad { 0.0 } else { (fd - ad).abs() / fd.abs().max(ad.abs()) };
            (name, err)
        })
        .collect()
}

/// Log-log slope of the Taylor remainder `|f(x + h d) - f(x) - h <grad f, d>|` over
/// h = 1e-3 .. 1e-5 along a random direction (scaled per input), over the remainders above
/// rounding: 2 when the adjoint is right; None when too few are (the map is linear there).
pub fn taylor_slope(k: &impl Flat, x: &[f64], scale: &[f64], rng: &mut Rng) -> Option<f64> {
    let cot = rng.vec(k.forward(x).len(), -1.0, 1.0);
    let grad = k.adjoint(x, &cot);
    let d: Vec<f64> = scale.iter().map(|s| rng.uniform(-1.0, 1.0) * s).collect();
    let loss = |x: &[f64]| dot(&cot, &k.forward(x));
    let (f0, slope) = (loss(x), dot(&grad, &d));
    // remainders within 1e-12 of the loss are rounding, not Taylor: left out of the fit
    let floor = 1e-12 * f0.abs().max(1e-300);
    let pts: Vec<(f64, f64)> = (0..=8)
        .map(|i| {
            let h = 10f64.powf(-3.0 - 0.25 * i as f64);
            (h.ln(), (loss(&axpy(x, h, &d)) - f0 - h * slope).abs())
        })
        .filter(|p| p.1 > floor)
        .map(|(lh, r)| (lh, r.ln()))
        .collect();
    if pts.len() < 3 {
        // linear along the direction to rounding: no second-order remainder to measure
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    Some(sxy / sxx)
}

fn m3(x: &[f64]) -> M3 {
    M3::from_cols_array(&std::array::from_fn(|i| x[i] as Real))
}

/// A material's `update` as a [`Flat`] map: inputs `[L (9, column-major), J, state_in, params]`,
/// outputs `[stress (9), state_out]`. `make` builds the material from parameter values in the
/// order of `param_names`.
struct MaterialUpdate<'a, M: Material, F: Fn(&[f64]) -> M> {
    make: &'a F,
    n_state: usize,
    n_params: usize,
    dt: f64,
}

impl<M: Material, F: Fn(&[f64]) -> M> Flat for MaterialUpdate<'_, M, F> {
    fn forward(&self, x: &[f64]) -> Vec<f64> {
        let mat = (self.make)(&x[10 + self.n_state..]);
        let mut state: Vec<Real> = x[10..10 + self.n_state].iter().map(|&v| v as Real).collect();
        let s = mat.update(&m3(x), x[9] as Real, self.dt as Real, &mut state);
        let mut out: Vec<f64> = s.to_cols_array().iter().map(|&v| v as f64).collect();
        out.extend(state.iter().map(|&v| v as f64));
        out
    }
    fn adjoint(&self, x: &[f64], cot: &[f64]) -> Vec<f64> {
        let mat = (self.make)(&x[10 + self.n_state..]);
        let state: Vec<Real> = x[10..10 + self.n_state].iter().map(|&v| v as Real).collect();
        let state_out_bar: Vec<Real> = cot[9..].iter().map(|&v| v as Real).collect();
        let (mut gv, mut jb) = (M3::ZERO, 0.0 as Real);
        let mut sb = vec![0.0 as Real; self.n_state];
        let mut pb = vec![0.0 as Real; self.n_params];
        let mut out = UpdateAdjoint { grad_v_bar: &mut gv, j_bar: &mut jb, state_bar: &mut sb, params_bar: &mut pb };
        mat.update_adjoint(&m3(x), x[9] as Real, self.dt as Real, &state, &m3(cot), &state_out_bar, &mut out);
        let mut g: Vec<f64> = gv.to_cols_array().iter().map(|&v| v as f64).collect();
        g.push(jb as f64);
        g.extend(sb.iter().map(|&v| v as f64));
        g.extend(pb.iter().map(|&v| v as f64));
        g
    }
    fn groups(&self) -> Vec<(String, std::ops::Range<usize>)> {
        let mut g = vec![("grad_v".to_string(), 0..9), ("J".to_string(), 9..10)];
        if self.n_state > 0 {
            g.push(("state".to_string(), 10..10 + self.n_state));
        }
        let names = (self.make)(&vec![1.0; self.n_params]).param_names();
        for (k, name) in names.iter().enumerate() {
            let i = 10 + self.n_state + k;
            g.push((name.to_string(), i..i + 1));
        }
        g
    }
}

/// The velocity gradients of the multi-step tests, `scale` times: a slow compression of z
/// with a little shear and volume change, wavering from step to step.
pub fn slow_loading(steps: usize, scale: Real) -> Vec<M3> {
    (0..steps)
        .map(|k| {
            let s = (k as f64 * 0.3).sin() as Real;
            M3::from_cols(V3::new(2e-4, 1e-4 * s, 0.0), V3::new(3e-4, 2e-4, 0.0), V3::new(0.0, 5e-5, -4e-4 - 1e-5 * s)) * scale
        })
        .collect()
}

/// A run of steps of a material from a new particle's state (`init_state`), as a [`Flat`] map
/// from the parameters (in `param_names` order) to the last step's stress and the final state;
/// its adjoint runs the steps' adjoints backwards, then `init_state_adjoint`. The groups are the
/// parameters, one each.
pub struct MaterialRun<M: Material, F: Fn(&[f64]) -> M> {
    pub make: F,
    /// (L, J) of each step.
    pub steps: Vec<(M3, Real)>,
    pub dt: Real,
    names: Vec<String>,
}

impl<M: Material, F: Fn(&[f64]) -> M> MaterialRun<M, F> {
    /// The run, its parameter names those of the material at `x`.
    pub fn new(make: F, steps: Vec<(M3, Real)>, dt: Real, x: &[f64]) -> Self {
        let names = make(x).param_names().iter().map(|n| n.to_string()).collect();
        MaterialRun { make, steps, dt, names }
    }

    /// The state before each step and after the last, and the last step's stress.
    pub fn states(&self, x: &[f64]) -> (Vec<Vec<Real>>, M3) {
        let m = (self.make)(x);
        let mut st = vec![0.0 as Real; m.state_names().len()];
        m.init_state(&mut st);
        let mut before = Vec::new();
        let mut sigma = M3::ZERO;
        for (l, j) in &self.steps {
            before.push(st.clone());
            sigma = m.update(l, *j, self.dt, &mut st);
        }
        before.push(st);
        (before, sigma)
    }
}

impl<M: Material, F: Fn(&[f64]) -> M> Flat for MaterialRun<M, F> {
    fn forward(&self, x: &[f64]) -> Vec<f64> {
        let (states, sigma) = self.states(x);
        let mut out: Vec<f64> = sigma.to_cols_array().iter().map(|&v| v as f64).collect();
        out.extend(states.last().unwrap().iter().map(|&v| v as f64));
        out
    }
    fn adjoint(&self, x: &[f64], cot: &[f64]) -> Vec<f64> {
        let m = (self.make)(x);
        let (states, _) = self.states(x);
        let n_state = states[0].len();
        let mut state_bar: Vec<Real> = cot[9..].iter().map(|&v| v as Real).collect();
        let mut params_bar = vec![0.0 as Real; x.len()];
        for (k, (l, j)) in self.steps.iter().enumerate().rev() {
            let stress_bar = if k + 1 == self.steps.len() { m3(cot) } else { M3::ZERO };
            let (mut gv, mut jb, mut sb) = (M3::ZERO, 0.0 as Real, vec![0.0 as Real; n_state]);
            let mut out = UpdateAdjoint { grad_v_bar: &mut gv, j_bar: &mut jb, state_bar: &mut sb, params_bar: &mut params_bar };
            m.update_adjoint(l, *j, self.dt, &states[k], &stress_bar, &state_bar, &mut out);
            state_bar = sb;
        }
        m.init_state_adjoint(&state_bar, &mut params_bar);
        params_bar.iter().map(|&v| v as f64).collect()
    }
    fn groups(&self) -> Vec<(String, std::ops::Range<usize>)> {
        self.names.iter().enumerate().map(|(i, n)| (n.clone(), i..i + 1)).collect()
    }
}

/// Check a material's `update_adjoint` at one point against fourth-order central differences,
/// per input group (L, J, the state before the update, each parameter), and the Taylor remainder
/// slope over all inputs at once. Panics with the per-group errors when any exceeds `tol` or the
/// slope is below 1.9 (a wrong gradient leaves a first-order remainder, slope 1; a slope above 2
/// only means little curvature along the direction); returns the worst error.
///
/// * `make` builds the material from parameter values, in the order of `param_names()`;
/// * `state_scale`, `param_scale` are the perturbation sizes per state entry and parameter
///   (roughly the magnitude of each, so a relative step is taken); L is perturbed by
///   `l_scale`, J by 1e-2.
#[allow(clippy::too_many_arguments)]
pub fn check_update_adjoint<M: Material, F: Fn(&[f64]) -> M>(
    label: &str,
    make: F,
    params: &[f64],
    grad_v: M3,
    j: f64,
    dt: f64,
    state_in: &[f64],
    l_scale: f64,
    state_scale: &[f64],
    param_scale: &[f64],
    tol: f64,
    seed: u64,
) -> f64 {
    let n_state = state_in.len();
    assert_eq!(state_scale.len(), n_state, "{label}: one scale per state entry");
    assert_eq!(param_scale.len(), params.len(), "{label}: one scale per parameter");
    assert_eq!(make(params).param_names().len(), params.len(), "{label}: one value per param_names() entry");
    let k = MaterialUpdate { make: &make, n_state, n_params: params.len(), dt };
    let mut x: Vec<f64> = grad_v.to_cols_array().iter().map(|&v| v as f64).collect();
    x.push(j);
    x.extend_from_slice(state_in);
    x.extend_from_slice(params);
    let mut scale = vec![l_scale; 9];
    scale.push(1e-2);
    scale.extend_from_slice(state_scale);
    scale.extend_from_slice(param_scale);
    checked(label, &k, &x, &scale, tol, seed)
}

/// Both checks of `k` at `x` (inputs perturbed by `scale`): the per-group errors against central
/// differences, which must be at most `tol`, and the Taylor slope, at least 1.9; printed under
/// `label`. Returns the worst error.
fn checked(label: &str, k: &impl Flat, x: &[f64], scale: &[f64], tol: f64, seed: u64) -> f64 {
    let mut rng = Rng(seed);
    let errs = group_errors(k, x, scale, &mut rng);
    let worst = errs.iter().map(|e| e.1).fold(0.0, f64::max);
    let report: Vec<String> = errs.iter().map(|(n, e)| format!("{n} {e:.1e}")).collect();
    println!("{label}: max relative error per input group: {}", report.join(", "));
    assert!(worst <= tol, "{label}: adjoint against central differences: {}", report.join(", "));
    match taylor_slope(k, x, scale, &mut rng) {
        Some(slope) => {
            println!("{label}: Taylor remainder slope {slope:.3}");
            assert!(slope >= 1.9, "{label}: Taylor remainder slope {slope:.3}, expected 2");
        }
        None => println!("{label}: linear along the Taylor direction (remainders at rounding level)"),
    }
    worst
}

/// A sleeping particle's wake as a [`Flat`] map: inputs `[J, state before, params]`, outputs
/// `[stress at rest (9), state after]` of `rest_for_at` over `duration` then `stress_at_rest`.
struct MaterialWake<'a, M: Material, F: Fn(&[f64]) -> M> {
    make: &'a F,
    n_state: usize,
    n_params: usize,
    duration: f64,
}

impl<M: Material, F: Fn(&[f64]) -> M> MaterialWake<'_, M, F> {
    fn woken(&self, x: &[f64]) -> (M, Vec<Real>, M3) {
        let mat = (self.make)(&x[1 + self.n_state..]);
        let mut state: Vec<Real> = x[1..1 + self.n_state].iter().map(|&v| v as Real).collect();
        mat.rest_for_at(&mut state, self.duration as Real, x[0] as Real);
        let stress = mat.stress_at_rest(&state, x[0] as Real);
        (mat, state, stress)
    }
}

impl<M: Material, F: Fn(&[f64]) -> M> Flat for MaterialWake<'_, M, F> {
    fn forward(&self, x: &[f64]) -> Vec<f64> {
        let (_, state, stress) = self.woken(x);
        let mut out: Vec<f64> = stress.to_cols_array().iter().map(|&v| v as f64).collect();
        out.extend(state.iter().map(|&v| v as f64));
        out
    }
    fn adjoint(&self, x: &[f64], cot: &[f64]) -> Vec<f64> {
        let (mat, state, _) = self.woken(x);
        let mut state_bar: Vec<Real> = cot[9..].iter().map(|&v| v as Real).collect();
        let (mut j_bar, mut params_bar) = (0.0 as Real, vec![0.0 as Real; self.n_params]);
        let done = mat.wake_adjoint(&state, self.duration as Real, x[0] as Real, &m3(cot), &mut state_bar, &mut j_bar, &mut params_bar);
        assert!(done, "{}: wake_adjoint refused", mat.name());
        let mut g = vec![j_bar as f64];
        g.extend(state_bar.iter().map(|&v| v as f64));
        g.extend(params_bar.iter().map(|&v| v as f64));
        g
    }
    fn groups(&self) -> Vec<(String, std::ops::Range<usize>)> {
        let mut g = vec![("J".to_string(), 0..1)];
        if self.n_state > 0 {
            g.push(("state".to_string(), 1..1 + self.n_state));
        }
        let names = (self.make)(&vec![1.0; self.n_params]).param_names();
        for (k, name) in names.iter().enumerate() {
            let i = 1 + self.n_state + k;
            g.push((name.to_string(), i..i + 1));
        }
        g
    }
}

/// Check a material's `wake_adjoint` (a sleeping particle of volume ratio `j` woken after
/// `duration` at rest from `state_before`) against fourth-order central differences, per input
/// group (J, the state before, each parameter), and the Taylor remainder slope; panics as
/// [`check_update_adjoint`] does and returns the worst error. `make`, the scales and `tol` as
/// there; J is perturbed by 1e-2.
#[allow(clippy::too_many_arguments)]
pub fn check_wake_adjoint<M: Material, F: Fn(&[f64]) -> M>(
    label: &str,
    make: F,
    params: &[f64],
    j: f64,
    duration: f64,
    state_before: &[f64],
    state_scale: &[f64],
    param_scale: &[f64],
    tol: f64,
    seed: u64,
) -> f64 {
    let n_state = state_before.len();
    assert_eq!(state_scale.len(), n_state, "{label}: one scale per state entry");
    assert_eq!(param_scale.len(), params.len(), "{label}: one scale per parameter");
    let k = MaterialWake { make: &make, n_state, n_params: params.len(), duration };
    let mut x = vec![j];
    x.extend_from_slice(state_before);
    x.extend_from_slice(params);
    let mut scale = vec![1e-2];
    scale.extend_from_slice(state_scale);
    scale.extend_from_slice(param_scale);
    checked(&format!("{label}, wake"), &k, &x, &scale, tol, seed)
}
