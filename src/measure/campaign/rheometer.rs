//! A virtual rheometer: one material point under a prescribed simple-shear history, through the
//! solver's own constitutive code (`Material::update`, the call every particle gets after G2P), so
//! rheometer data calibrate the same model a print or slump simulation uses, in milliseconds.
//!
//! The point is sheared as v_x = gamma_dot y: L = gamma_dot e_x e_y^T, J = 1 (the flow is
//! isochoric). A protocol is a list of phases: rest (gamma_dot = 0, the structure builds up),
//! shear at a constant rate, and a sweep of rates each held for a while (a flow curve). A
//! reading is the shear stress sigma_xy at the end of a recorded hold, as a rheometer's torque
//! gives it once the transient has passed.
//!
//! Gradients: [`Rheometer::gradient`] runs the point forward keeping its internal state at every
//! step (a few reals per step), then back through `Material::update_adjoint` and
//! `init_state_adjoint`, giving d(sum_k w_k tau_k)/d(parameter) for every parameter the material
//! names.

use crate::measure::error::{io_error, toml_error, MeasureError};
use crate::kernels::material::{Material, UpdateAdjoint};
use crate::kernels::{Real, M3, V3};
use serde::Deserialize;

/// A `[rheometer]` protocol.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Protocol {
    /// Step of the constitutive update [s]; a phase may set its own.
    #[serde(default = "default_dt")]
    pub dt: f64,
    pub phase: Vec<Phase>,
}

fn default_dt() -> f64 {
    1e-3
}
fn yes() -> bool {
    true
}

#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Phase {
    /// No shear for `duration` seconds.
    Rest {
        duration: f64,
        #[serde(default)]
        dt: Option<f64>,
    },
    /// Shear at `rate` [1/s] for `duration` seconds; the stress at the end is a reading unless
    /// `record = false`.
    Shear {
        rate: f64,
        duration: f64,
        #[serde(default = "yes")]
        record: bool,
        #[serde(default)]
        dt: Option<f64>,
    },
    /// Each rate of `rates` [1/s] held for `hold` seconds, in order, with a reading at the end
    /// of each hold.
    Sweep {
        rates: Vec<f64>,
        hold: f64,
        #[serde(default)]
        dt: Option<f64>,
    },
}

/// The shear stress at the end of a recorded hold.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Reading {
    /// Time since the start of the protocol [s].
    pub time: f64,
    /// Shear rate of the hold [1/s].
    pub rate: f64,
    /// sigma_xy [Pa].
    pub stress: f64,
}

/// The most constitutive steps a protocol may take: 1e8 run in tens of seconds, and the
/// adjoint keeps the state of every step (a few hundred MB at 1e8 steps of two reals).
pub const MAX_STEPS: usize = 100_000_000;

/// One hold of constant rate, as steps.
#[derive(Clone, Copy, Debug)]
struct Hold {
    rate: f64,
    dt: f64,
    steps: usize,
    record: bool,
}

pub struct Rheometer<'a> {
    material: &'a dyn Material,
    holds: Vec<Hold>,
}

/// L of simple shear v_x = g y (glam is column-major: column 1 holds d v / d y).
fn shear(g: f64) -> M3 {
    M3::from_cols(V3::ZERO, V3::new(g as Real, 0.0, 0.0), V3::ZERO)
}

impl<'a> Rheometer<'a> {
    /// Check the protocol (every phase named by its index on error) and lay out its steps.
    pub fn new(material: &'a dyn Material, protocol: &Protocol) -> Result<Rheometer<'a>, MeasureError> {
        let positive = |what: String, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(MeasureError::Rheometer(format!("{what} must be > 0, got {v}")))
            }
        };
        positive("rheometer.dt".into(), protocol.dt)?;
        if protocol.phase.is_empty() {
            return Err(MeasureError::Rheometer("rheometer: the protocol has no phase".into()));
        }
        let mut holds = Vec::new();
        for (i, ph) in protocol.phase.iter().enumerate() {
            let key = |k: &str| format!("rheometer.phase.{i}.{k}");
            let step = |dt: &Option<f64>| positive(key("dt"), dt.unwrap_or(protocol.dt));
            let steps = |duration: f64, dt: f64| -> Result<usize, MeasureError> {
                positive(key("duration"), duration)?;
                let n = (duration / dt).round().max(1.0);
                if n > MAX_STEPS as f64 {
                    return Err(MeasureError::Rheometer(format!(
                        "rheometer.phase.{i}: {duration} s at dt = {dt} s is {n:.3e} steps, more than the {MAX_STEPS} \
                            a protocol may take; raise its dt"
                    )));
                }
                Ok(n as usize)
            };
            match ph {
                Phase::Rest { duration, dt } => {
                    let dt = step(dt)?;
                    holds.push(Hold { rate: 0.0, dt, steps: steps(*duration, dt)?, record: false });
                }
                Phase::Shear { rate, duration, record, dt } => {
                    if !rate.is_finite() {
                        return Err(MeasureError::Rheometer(format!("{} must be finite, got {rate}", key("rate"))));
                    }
                    let dt = step(dt)?;
                    holds.push(Hold { rate: *rate, dt, steps: steps(*duration, dt)?, record: *record });
                }
                Phase::Sweep { rates, hold, dt } => {
                    if rates.is_empty() {
                        return Err(MeasureError::Rheometer(format!("{} is empty", key("rates"))));
                    }
                    let dt = step(dt)?;
                    positive(key("hold"), *hold)?;
                    for (k, &rate) in rates.iter().enumerate() {
                        if !rate.is_finite() {
                            return Err(MeasureError::Rheometer(format!(
                                "{}[{k}] must be finite, got {rate}",
                                key("rates")
                            )));
                        }
                        holds.push(Hold { rate, dt, steps: steps(*hold, dt)?, record: true });
                    }
                }
            }
        }
        let total: usize = holds.iter().map(|h| h.steps).sum();
        if total > MAX_STEPS {
            return Err(MeasureError::Rheometer(format!(
                "rheometer: the protocol takes {total} steps, more than the {MAX_STEPS} it may take; raise dt"
            )));
        }
        Ok(Rheometer { material, holds })
    }

    /// Constitutive updates the protocol takes.
    pub fn steps(&self) -> usize {
        self.holds.iter().map(|h| h.steps).sum()
    }

    /// Readings at the end of every recorded hold.
    pub fn run(&self) -> Vec<Reading> {
        self.forward(None)
    }

    /// The readings, and d(sum_k weights_k stress_k)/d(parameter) for the material's
    /// `param_names`, in that order. `weights` has one entry per reading.
    pub fn gradient(&self, weights: &[f64]) -> Result<(Vec<Reading>, Vec<f64>), MeasureError> {
        let sl = self.material.state_names().len();
        let mut history = Vec::with_capacity(self.steps() * sl);
        let readings = self.forward(Some(&mut history));
        if weights.len() != readings.len() {
            return Err(MeasureError::Rheometer(format!(
                "rheometer: {} weights for {} readings",
                weights.len(),
                readings.len()
            )));
        }
        let np = self.material.param_names().len();
        let mut params_bar = vec![0.0 as Real; np];
        let mut state_bar = vec![0.0 as Real; sl];
        let mut state_in_bar = vec![0.0 as Real; sl];
        let mut k = readings.len();
        let mut s = self.steps();
        for h in self.holds.iter().rev() {
            let l = shear(h.rate);
            for step in (0..h.steps).rev() {
                s -= 1;
                let mut stress_bar = M3::ZERO;
                if h.record && step + 1 == h.steps {
                    k -= 1;
                    stress_bar.y_axis.x = weights[k] as Real;
                }
                state_in_bar.fill(0.0);
                let (mut l_bar, mut j_bar) = (M3::ZERO, 0.0 as Real);
                let mut out = UpdateAdjoint {
                    grad_v_bar: &mut l_bar,
                    j_bar: &mut j_bar,
                    state_bar: &mut state_in_bar,
                    params_bar: &mut params_bar,
                };
                self.material.update_adjoint(
                    &l,
                    1.0,
                    h.dt as Real,
                    &history[s * sl..(s + 1) * sl],
                    &stress_bar,
                    &state_bar,
                    &mut out,
                );
                std::mem::swap(&mut state_bar, &mut state_in_bar);
            }
        }
        self.material.init_state_adjoint(&state_bar, &mut params_bar);
        Ok((readings, params_bar.iter().map(|&v| v as f64).collect()))
    }

    /// Run the protocol; with `history`, keep the state before every step.
    fn forward(&self, mut history: Option<&mut Vec<Real>>) -> Vec<Reading> {
        let mut state = vec![0.0 as Real; self.material.state_names().len()];
        self.material.init_state(&mut state);
        let mut readings = Vec::new();
        let mut t = 0.0;
        for h in &self.holds {
            let l = shear(h.rate);
            let mut stress = M3::ZERO;
            for _ in 0..h.steps {
                if let Some(hist) = history.as_deref_mut() {
                    hist.extend_from_slice(&state);
                }
                stress = self.material.update(&l, 1.0, h.dt as Real, &mut state);
            }
            t += h.dt * h.steps as f64;
            if h.record {
                readings.push(Reading { time: t, rate: h.rate, stress: stress.y_axis.x as f64 });
            }
        }
        readings
    }
}

/// `strand rheometer`: the `[material]` of the TOML file `model` under the `[rheometer]` protocol
/// (its own table, or the file `protocol`); with `sensitivity`, each reading's derivative with
/// respect to every material parameter. Returns the report (a table, or JSON).
pub fn run_cli(
    model: &std::path::Path,
    protocol: Option<&std::path::Path>,
    sensitivity: bool,
    json: bool,
) -> Result<String, MeasureError> {
    use std::fmt::Write as _;
    let read = |p: &std::path::Path| -> Result<toml::Table, MeasureError> {
        let text = std::fs::read_to_string(p).map_err(io_error(p))?;
        text.parse::<toml::Table>().map_err(toml_error(p))
    };
    let table = read(model)?;
    let mat = match table.get("material") {
        Some(toml::Value::Table(t)) => {
            crate::materials::build_material(t).map_err(|e| MeasureError::from(e).within(model.display()))?
        }
        _ => return Err(MeasureError::Rheometer(format!("{}: no [material] table", model.display()))),
    };
    let (source, proto) = match protocol {
        Some(p) => (p.to_path_buf(), toml::Value::Table(read(p)?)),
        None => match table.get("rheometer") {
            Some(v) => (model.to_path_buf(), v.clone()),
            None => {
                return Err(MeasureError::Rheometer(format!(
                    "{}: no [rheometer] table; give one or --protocol FILE",
                    model.display()
                )))
            }
        },
    };
    let proto: Protocol = proto.try_into().map_err(|e: toml::de::Error| {
        MeasureError::Rheometer(format!("{}: rheometer: {}", source.display(), e.message()))
    })?;
    let rh = Rheometer::new(&*mat, &proto).map_err(|e| e.within(source.display()))?;
    let readings = rh.run();
    let names = mat.param_names();
    let mut sens = Vec::new();
    if sensitivity {
        for k in 0..readings.len() {
            let mut w = vec![0.0; readings.len()];
            w[k] = 1.0;
            sens.push(rh.gradient(&w)?.1);
        }
    }
    if json {
        let rows: Vec<_> = readings
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let mut o = serde_json::json!({ "time": r.time, "rate": r.rate, "stress": r.stress });
                if sensitivity {
                    o["d_stress"] = names
                        .iter()
                        .zip(&sens[k])
                        .map(|(n, v)| (n.to_string(), serde_json::json!(v)))
                        .collect::<serde_json::Map<_, _>>()
                        .into();
                }
                o
            })
            .collect();
        return Ok(format!(
            "{:#}\n",
            serde_json::json!({ "material": mat.name(), "steps": rh.steps(), "readings": rows })
        ));
    }
    let mut s = String::new();
    let _ = writeln!(s, "{} under {} constitutive steps:", mat.name(), rh.steps());
    let _ = write!(s, "{:>10} {:>12} {:>14}", "time [s]", "rate [1/s]", "stress [Pa]");
    if sensitivity {
        for n in names {
            let _ = write!(s, " {:>16}", format!("d/d {n}"));
        }
    }
    let _ = writeln!(s);
    for (k, r) in readings.iter().enumerate() {
        let _ = write!(s, "{:>10.3} {:>12.4} {:>14.6}", r.time, r.rate, r.stress);
        if sensitivity {
            for v in &sens[k] {
                let _ = write!(s, " {v:>16.6e}");
            }
        }
        let _ = writeln!(s);
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materials::build_material;

    fn material(text: &str) -> Box<dyn Material> {
        build_material(&text.parse::<toml::Table>().unwrap()).unwrap()
    }

    fn protocol(text: &str) -> Protocol {
        toml::from_str(text).unwrap()
    }

    const BINGHAM: &str =
        "kind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = 630.0\n";

    #[test]
    fn a_bingham_flow_curve_is_tau0_plus_eta_gamma_dot() {
        let m = material(BINGHAM);
        let p = protocol("[[phase]]\nkind = \"sweep\"\nrates = [50.0, 20.0, 10.0, 5.0]\nhold = 0.5\n");
        let r = Rheometer::new(&*m, &p).unwrap().run();
        assert_eq!(r.len(), 4);
        for x in &r {
            let expect = 630.0 + 7.5 * x.rate;
            assert!((x.stress / expect - 1.0).abs() < 1e-3, "rate {}: {} vs {expect}", x.rate, x.stress);
        }
    }

    #[test]
    fn a_herschel_bulkley_flow_curve_is_tau0_plus_k_gamma_dot_n() {
        // steady state in each hold: the EVP solid's start-up (k g^(n-1) / G <= 2e-3 s) and the
        // regularisations (gamma_c = 0.01 /s; exp(-m g) with m g >= 20) are far below the
        // readings' 1e-3
        let cases = [
            "kind = \"bingham\"\ndensity = 2300.0\nbulk_modulus = 1e6\n",
            "kind = \"papanastasiou_roussel\"\ndensity = 2300.0\nbulk_modulus = 1e6\npapanastasiou_m = 200.0\n",
            // G large enough that the Jaumann spin's share (tau / G)^2 of elastic rate stays below 1e-4
            "kind = \"evp_bingham\"\ndensity = 2300.0\nbulk_modulus = 1e7\nshear_modulus = 1e6\n",
        ];
        let p = protocol("[[phase]]\nkind = \"sweep\"\nrates = [50.0, 20.0, 5.0, 1.0, 0.3, 0.1]\nhold = 0.5\n");
        for base in cases {
            for n in [0.6, 0.35, 1.3] {
                let m = material(&format!("{base}viscosity = 25.0\nyield_stress = 80.0\nflow_index = {n}\n"));
                let r = Rheometer::new(&*m, &p).unwrap().run();
                assert_eq!(r.len(), 6);
                for x in &r {
                    let expect = 80.0 + 25.0 * x.rate.powf(n);
                    assert!(
                        (x.stress / expect - 1.0).abs() < 1e-3,
                        "{} n = {n}, rate {}: {} vs {expect}",
                        m.name(),
                        x.rate,
                        x.stress
                    );
                }
            }
        }
    }

    #[test]
    fn thixotropic_build_up_raises_the_stress_after_rest() {
        let evp = "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 1e5\nviscosity = \
            19.5\nyield_stress = 92.0\na_thix = 0.39\nalpha = 0.15\n";
        let m = material(evp);
        let after = |rest: f64| {
            let p = protocol(&format!("[[phase]]\nkind = \"rest\"\nduration = {rest}\ndt = 0.01\n[[phase]]\nkind = \
                \"shear\"\nrate = 1.0\nduration = 0.05\n"));
            Rheometer::new(&*m, &p).unwrap().run()[0].stress
        };
        let (t0, t240) = (after(0.01), after(240.0));
        assert!(t240 > 1.5 * t0, "stress after 240 s of rest {t240} Pa, after none {t0} Pa");
    }

    #[test]
    fn a_maxwell_branch_adds_eta_m_gamma_dot_to_the_flow_curve() {
        let evp = "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 1e5\nviscosity = \
            19.5\nyield_stress = 92.0\n";
        // eta_M = G_M t_M = 10 Pa s; each hold lasts 10 t_M, so the branch is at its steady state
        let (g_m, t_m) = (200.0, 0.05);
        let p = protocol("[[phase]]\nkind = \"sweep\"\nrates = [4.0, 1.0, 0.25]\nhold = 0.5\n");
        let without = Rheometer::new(&*material(evp), &p).unwrap().run();
        let with = Rheometer::new(&*material(&format!("{evp}maxwell_modulus = {g_m}\nmaxwell_time = {t_m}\n")), &p)
            .unwrap()
            .run();
        for (a, b) in without.iter().zip(&with) {
            // the Jaumann Maxwell model's steady shear stress, eta_M gamma_dot / (1 + Wi^2) with
            // the Weissenberg number Wi = t_M gamma_dot (0.2 at the fastest rate)
            let wi = t_m * a.rate;
            let expect = g_m * t_m * a.rate / (1.0 + wi * wi);
            let added = b.stress - a.stress;
            assert!(
                (added / expect - 1.0).abs() < 1e-3,
                "rate {}: the branch adds {added} Pa, expected {expect}",
                a.rate
            );
        }
    }

    #[test]
    fn bad_protocols_name_the_phase_and_key() {
        let m = material(BINGHAM);
        let e = |text: &str| Rheometer::new(&*m, &protocol(text)).err().unwrap().to_string();
        assert!(e("[[phase]]\nkind = \"rest\"\nduration = -1.0\n").contains("rheometer.phase.0.duration"));
        assert!(e("[[phase]]\nkind = \"rest\"\nduration = 1.0\n[[phase]]\nkind = \"sweep\"\nrates = []\nhold = 1.0\n")
            .contains("rheometer.phase.1.rates"));
        assert!(e("dt = 0.0\n[[phase]]\nkind = \"rest\"\nduration = 1.0\n").contains("rheometer.dt"));
        // issue 27 finding 7: a rest of 1e12 s is refused at once, not run for ever
        let long = e("[[phase]]\nkind = \"rest\"\nduration = 1e12\n");
        assert!(long.contains("rheometer.phase.0") && long.contains("more than the 100000000"), "{long}");
        let many = e("dt = 1.0\n[[phase]]\nkind = \"sweep\"\nrates = [1.0, 2.0, 3.0]\nhold = 4e7\n");
        assert!(many.contains("the protocol takes 120000000 steps"), "{many}");
        assert!(toml::from_str::<Protocol>("[[phase]]\nkind = \"spin\"\n").is_err());
    }

    /// Every parameter's gradient of a weighted sum of readings against central differences, on
    /// a protocol that rests, shears and sweeps (so thixotropy, elasticity and flow all count).
    #[cfg(not(feature = "f32"))]
    #[test]
    fn gradients_match_central_differences() {
        let p = protocol(
            "dt = 0.002\n[[phase]]\nkind = \"rest\"\nduration = 20.0\ndt = 0.01\n[[phase]]\nkind = \"shear\"\nrate = \
                0.5\nduration = 0.4\n\
             [[phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0, 1.0]\nhold = 0.3\n",
        );
        let cases = [
            "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 2e4\nviscosity = 19.5\n\
                yield_stress = 92.0\na_thix = 0.39\nalpha = 0.15\nlambda0 = 0.2\n",
            BINGHAM,
            "kind = \"papanastasiou_roussel\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\nyield_stress = \
                630.0\n",
            // Herschel-Bulkley, thinning and thickening
            "kind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 25.0\nyield_stress = 80.0\n\
                flow_index = 0.6\n",
            "kind = \"papanastasiou_roussel\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 25.0\nyield_stress = \
                80.0\nflow_index = 1.3\n",
            "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 2e4\nviscosity = 19.5\n\
                yield_stress = 92.0\na_thix = 0.39\nalpha = 0.15\nlambda0 = 0.2\nflow_index = 0.6\n",
            // with the Maxwell branch, and at its null (G_M = 0, where d/d t_M is 0)
            "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 2e4\nviscosity = 19.5\n\
                yield_stress = 92.0\na_thix = 0.39\nalpha = 0.15\nlambda0 = 0.2\nmaxwell_modulus = 300.0\nmaxwell_time \
                = 0.2\n",
            "kind = \"evp_bingham\"\ndensity = 2400.0\nbulk_modulus = 1e6\nshear_modulus = 2e4\nviscosity = 19.5\n\
                yield_stress = 92.0\na_thix = 0.39\nalpha = 0.15\nlambda0 = 0.2\nmaxwell_modulus = 0.0\nmaxwell_time = \
                1.0\n",
        ];
        for text in cases {
            let table: toml::Table = text.parse().unwrap();
            let m = build_material(&table).unwrap();
            let rh = Rheometer::new(&*m, &p).unwrap();
            let weights = [1.0, 0.5, -0.25, 2.0];
            let (readings, grad) = rh.gradient(&weights).unwrap();
            assert_eq!(readings, rh.run(), "the gradient's forward is the run");
            let loss = |t: &toml::Table| -> f64 {
                let m = build_material(t).unwrap();
                Rheometer::new(&*m, &p).unwrap().run().iter().zip(weights).map(|(r, w)| w * r.stress).sum()
            };
            for (k, name) in m.param_names().iter().enumerate() {
                let Some(v) = table.get(*name).and_then(|v| v.as_float()) else { continue };
                let h = if v == 0.0 { 1e-3 } else { 1e-6 * v.abs().max(1e-3) };
                let at = |x: f64| {
                    let mut t = table.clone();
                    t.insert(name.to_string(), toml::Value::Float(x));
                    t
                };
                // at a parameter's lower bound (G_M = 0), the one-sided second-order difference
                let cd = if build_material(&at(v - h)).is_ok() {
                    (loss(&at(v + h)) - loss(&at(v - h))) / (2.0 * h)
                } else {
                    (4.0 * loss(&at(v + h)) - 3.0 * loss(&table) - loss(&at(v + 2.0 * h))) / (2.0 * h)
                };
                let scale = cd.abs().max(grad[k].abs()).max(1e-8);
                assert!(
                    (grad[k] - cd).abs() <= 1e-5 * scale,
                    "{}: {name}: adjoint {}, central difference {cd}",
                    m.name(),
                    grad[k]
                );
                // the branch counts, at its null too (its score)
                assert!(*name != "maxwell_modulus" || cd.abs() > 1e-2, "{name}: {cd}");
            }
        }
    }
}
