//! The model's value of every observation and, on request, its gradient with respect to named
//! model parameters — by the adjoints: the solver's reverse pass for a simulation (one forward
//! and one reverse sweep for all the observations of an experiment that its run passes, an
//! adjoint each: `strand grad`'s driver), the rheometer's for a rheometer test, then the model's
//! effects backwards ([`Model::keys_adjoint`]).
//!
//! An observable without an adjoint (a print's failure layer and time, a flow front's arrival
//! and stop times, a discharge's passing time: piecewise constant in the parameters, see
//! `failure.rs`, `front.rs` and `passing.rs`) gets
//! its values from forward runs as `strand compare` runs them,
//! and its Jacobian columns by central differences of forward runs ([`differenced`]).
//!
//! A simulation whose adjoint costs more than central differences (few parameters against the
//! experiment's observations: [`by_differences_is_cheaper`]) gets its Jacobian by central
//! differences of the same fixed-step runs that give its values ([`DIFFERENCE_STEP_SMOOTH`]).
//!
//! Simulations here run the way a gradient run does (fixed step, every particle awake, one sort
//! by block up front), values and gradients alike, so a fit compares like with like; their values
//! can differ from `strand compare`'s in the last bits. An observation at an earlier time is taken
//! after the step of the whole run that reaches it (to the step control's rounding of 1e-9 dt),
//! not from a run that ends there: the two differ by that rounding of the last step's length.

use crate::measure::error::MeasureError;
use super::experiments::{Experiment, Experiments};
use crate::measure::observables::{observable_plan, reading_index};
use crate::measure::observation::{Observable, Observation};
use super::runner::{find, group, job_threads, par_map_experiments, scenario_from_table, ungroup, Applied, Jobs};
use super::spare::Spare;
use crate::measure::effects::Keys;
use crate::measure::model::{set_path, Model, Parameter};
use super::rheometer::Rheometer;
use crate::grad::driver::Seeded;
use crate::grad::{driver, params, GradOptions};
use crate::observables::Objective;

/// Values (one per observation) and, when asked, d value / d parameter (a row per observation).
#[derive(Clone, Debug)]
pub struct Sensitivity {
    pub values: Vec<f64>,
    pub jacobian: Option<Vec<Vec<f64>>>,
    /// Each value's scatter: the standard deviation of its rough part in the parameters (a
    /// section sampled by particles), where the central differences of its Jacobian estimated
    /// it ([`central`]); 0 where nothing did (values alone, an adjoint, a rheometer's smooth
    /// readings).
    pub scatter: Vec<f64>,
    /// With the Jacobian, each of its entries' scatter (one standard deviation, the same shape):
    /// a central difference over a width w carries its values' scatter as s sqrt(2) / w; an
    /// adjoint's entry has none.
    pub jacobian_scatter: Option<Vec<Vec<f64>>>,
}

/// How a simulation's Jacobian columns that stand in for its adjoint are differenced
/// ([`DIFFERENCE_STEP_SMOOTH`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Differences {
    /// Both sides of each parameter, whose second differences also estimate each value's
    /// scatter ([`central`]).
    #[default]
    Central,
    /// One side (p + h, or p - h where p + h leaves the bounds): p runs against 2 p, first-order
    /// accurate, at a point whose values' scatter central differences there have estimated (one
    /// per observation, in the data's order): more columns at a fit's optimum, such as the
    /// effects' at the base fit's values. Not for a fit's own Jacobians: a scatter carried to
    /// another point can be several times that point's own (docs/gradient_cost.md).
    Forward(Vec<f64>),
}

/// The values at a model where they are known (in the data's order), and how a simulation's
/// Jacobian is differenced there ([`evaluate`]).
pub type Known<'a> = Option<(&'a [f64], &'a Differences)>;

/// Values of every observation under `model`, with their gradients in `names` when given;
/// experiments run as `jobs` says. `at`: the values at `model` where they are known (in the
/// data's order, as this gives them there: a calibration's accepted trial) and how a simulation's
/// Jacobian is differenced; an experiment whose Jacobian is all differences then takes them
/// instead of running the model again (one run of its 1 + 2 p, or 1 + p:
/// [`Differences::Forward`]). Without, the values are run and differences are central.
pub fn evaluate(
    model: &Model,
    data: &[Observation],
    exps: &Experiments,
    (names, jobs): (Option<&[String]>, Jobs),
    at: Known,
) -> Result<Sensitivity, MeasureError> {
    let (known, differences) = match at {
        Some((values, differences)) => (Some(values), differences),
        None => (None, &Differences::Central),
    };
    let wanted = group(data);
    let threads = job_threads(jobs.n, wanted.len());
    let known = known.map(|v| regroup(data, &wanted, v));
    let scatter = match differences {
        Differences::Central => None,
        Differences::Forward(s) => Some(regroup(data, &wanted, s)),
    };
    let per = par_map_experiments(&wanted, jobs.n, |k, spare| {
        let given = Given {
            values: known.as_ref().map(|v| &v[k][..]),
            scatter: scatter.as_ref().map(|s| &s[k][..]),
            spare: Some(spare),
        };
        let valued = one_given(model, exps, &wanted[k].0, &wanted[k].1, (names, threads), given);
        (jobs.done)();
        valued
    })?;
    Ok(assemble(data, &wanted, &per, names))
}

/// What the caller gives one experiment's evaluation: its values at the model where known (a
/// trial just run), its values' scatter, which makes its differences one-sided
/// ([`Differences::Forward`]), each in the experiment's order of observables; and the campaign's
/// idle workers, which its independent runs may use.
#[derive(Clone, Copy, Default)]
struct Given<'a> {
    values: Option<&'a [f64]>,
    scatter: Option<&'a [f64]>,
    spare: Option<&'a Spare>,
}

/// Values in the data's order grouped by experiment, as [`group`] orders them (the inverse of
/// [`ungroup`]).
pub fn regroup(data: &[Observation], wanted: &[(String, Vec<Observable>)], values: &[f64]) -> Vec<Vec<f64>> {
    let mut per = vec![Vec::new(); wanted.len()];
    for (o, v) in data.iter().zip(values) {
        per[wanted.iter().position(|(id, _)| *id == o.experiment).expect("grouped")].push(*v);
    }
    per
}

/// One experiment's values of `wanted` and, with `names`, their gradients (one-sided where
/// `scatter`, its values' known scatter, is given): the unit of work [`evaluate`] runs side
/// by side and a scheduler's job runs alone (`engine.rs`).
pub fn one(
    model: &Model,
    exps: &Experiments,
    id: &str,
    wanted: &[Observable],
    (names, threads): (Option<&[String]>, Option<usize>),
    scatter: Option<&[f64]>,
) -> Result<Vec<Valued>, MeasureError> {
    one_given(model, exps, id, wanted, (names, threads), Given { scatter, ..Given::default() })
}

fn one_given(
    model: &Model,
    exps: &Experiments,
    id: &str,
    wanted: &[Observable],
    (names, threads): (Option<&[String]>, Option<usize>),
    given: Given,
) -> Result<Vec<Valued>, MeasureError> {
    let x = find(exps, id)?;
    let params = names.map(|n| model.parameters(n)).transpose();
    params
        .and_then(|params| experiment(model, exps, x, wanted, (params.as_deref(), threads), given))
        .map_err(|e| e.within(format!("experiment '{id}'")))
}

/// The experiments' results ([`one`] each, in `wanted`'s order) in the data's order.
pub fn assemble(
    data: &[Observation],
    wanted: &[(String, Vec<Observable>)],
    per: &[Vec<Valued>],
    names: Option<&[String]>,
) -> Sensitivity {
    let flat = ungroup(data, wanted, per);
    Sensitivity {
        values: flat.iter().map(|v| v.value).collect(),
        scatter: flat.iter().map(|v| v.scatter).collect(),
        jacobian_scatter: names.map(|_| flat.iter().map(|v| v.gradient_scatter.clone().expect("asked")).collect()),
        jacobian: names.map(|_| flat.into_iter().map(|v| v.gradient.expect("asked")).collect()),
    }
}

/// An observation's value and, when asked, its gradient, with the scatter of each where the
/// gradient's differences estimated it ([`Sensitivity::scatter`],
/// [`Sensitivity::jacobian_scatter`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Valued {
    pub value: f64,
    pub gradient: Option<Vec<f64>>,
    pub scatter: f64,
    pub gradient_scatter: Option<Vec<f64>>,
}

impl Valued {
    /// A value and gradient without scatter (an adjoint's, a rheometer's).
    pub fn new(value: f64, gradient: Option<Vec<f64>>) -> Valued {
        let gradient_scatter = gradient.as_ref().map(|g| vec![0.0; g.len()]);
        Valued { value, gradient, scatter: 0.0, gradient_scatter }
    }
}

/// Whether an observable's gradient comes from an adjoint; the others are differenced.
pub fn has_adjoint(o: &Observable) -> bool {
    ![crate::failure::OBSERVABLES, crate::measure::front::OBSERVABLES, crate::measure::passing::OBSERVABLES]
        .concat()
        .contains(&o.name.as_str())
}

/// The relative step [`differenced`] starts from: a tenth of the parameter (its scale, the
/// typical magnitude a fit moves it by, for a parameter at 0: an effect at its null).
pub const DIFFERENCE_STEP: f64 = 0.1;

/// The relative step of the central differences that stand in for a simulation's adjoint
/// ([`simulated`]): 3 % of the parameter, or of its unit where that is larger ([`smooth_step`]). A
/// print's section is sampled by particles, so it is rough in the parameters below about 1 %:
/// on the print campaign's line, differences at 0.1 % and 0.03 % scatter by factors of several
/// and change sign, while those at 1, 3 and 10 % agree with each other and with the adjoint (test
/// `differences_stand_in_for_the_adjoint_on_a_print_line`).
pub const DIFFERENCE_STEP_SMOOTH: f64 = 0.03;

/// [`DIFFERENCE_STEP_SMOOTH`] of `name`'s value, or of its unit ([`Model::unit`]) where that is
/// larger: 3 % of a viscosity fitted to 1e-5 Pa s moves the model by less than its particle
/// noise, and a difference over it is that noise over a tiny step, a column 10^4 times the
/// others that a Gauss-Newton step follows and the model then refuses.
fn smooth_step(p: &Parameter) -> f64 {
    DIFFERENCE_STEP_SMOOTH * p.value.abs().max(p.unit)
}

/// What one experiment's adjoint costs, in forward runs of it: a share every observation's
/// adjoint reuses (the forward sweep with its recomputations, and each reversed step's
/// recomputation) and a share per observation (its materials, G2P and P2G adjoints). Measured on
/// a printed line (BENCHMARKS.md "Gradient cost per observation": 6.1 forward runs for one
/// observation, 48 % of it shared).
pub const ADJOINT_SHARED_RUNS: f64 = 2.9;
pub const ADJOINT_RUNS_PER_OBSERVATION: f64 = 3.2;

/// Whether differences that take `runs` forward runs beside the values' (two a parameter, one
/// for a parameter at a bound, which moves one way only) cost less than one adjoint of
/// `observations` (each a scalar's reverse pass), whose forward sweep gives the values.
pub fn by_differences_is_cheaper(runs: usize, observations: usize) -> bool {
    ((1 + runs) as f64) < ADJOINT_SHARED_RUNS + ADJOINT_RUNS_PER_OBSERVATION * observations as f64
}

/// One experiment's values of `wanted` and, with `names`, their gradients; `given`: what the
/// caller has of it ([`Given`]).
fn experiment(
    model: &Model,
    exps: &Experiments,
    x: &Experiment,
    wanted: &[Observable],
    (params, threads): (Option<&[Parameter]>, Option<usize>),
    given: Given,
) -> Result<Vec<Valued>, MeasureError> {
    let (adjoint, other): (Vec<usize>, Vec<usize>) = (0..wanted.len()).partition(|&k| has_adjoint(&wanted[k]));
    if other.is_empty() {
        return simulated(model, exps, x, wanted, (params, threads), given);
    }
    let pick = |ks: &[usize]| ks.iter().map(|&k| wanted[k].clone()).collect::<Vec<_>>();
    let part = |v: Option<&[f64]>, ks: &[usize]| v.map(|v| ks.iter().map(|&k| v[k]).collect::<Vec<f64>>());
    let mut out: Vec<Option<Valued>> = vec![None; wanted.len()];
    for (&k, v) in other.iter().zip(differenced(
        model,
        exps,
        x,
        &pick(&other),
        (params, threads),
        part(given.values, &other).as_deref(),
    )?) {
        out[k] = Some(v);
    }
    if !adjoint.is_empty() {
        let (values, scatter) = (part(given.values, &adjoint), part(given.scatter, &adjoint));
        for (&k, v) in adjoint.iter().zip(simulated(
            model,
            exps,
            x,
            &pick(&adjoint),
            (params, threads),
            Given { values: values.as_deref(), scatter: scatter.as_deref(), spare: given.spare },
        )?) {
            out[k] = Some(v);
        }
    }
    Ok(out.into_iter().map(|v| v.expect("every observation valued")).collect())
}

/// Observables with an adjoint: values from the fixed-step runs of a gradient, and their Jacobian
/// from the adjoint, or from central differences of those runs ([`DIFFERENCE_STEP_SMOOTH`]) for
/// a parameter that moves the toolpath (the adjoint holds fixed which step each slab of
/// material enters in, and a changed flow or speed changes that over a whole print: the
/// extrusion factor's adjoint gets the sign of a line's width wrong) and, for a simulation, for
/// every parameter when that costs less than the adjoint ([`by_differences_is_cheaper`]). With
/// the values' scatter known, each difference is one-sided ([`Differences::Forward`]).
fn simulated(
    model: &Model,
    exps: &Experiments,
    x: &Experiment,
    wanted: &[Observable],
    (params, threads): (Option<&[Parameter]>, Option<usize>),
    given: Given,
) -> Result<Vec<Valued>, MeasureError> {
    let applied = Applied::new(model, x)?;
    let (Some(params), Some(_)) = (params, &x.scenario) else {
        return by_adjoint(model, &applied, (exps, x), wanted, (params, threads));
    };
    let keys = &applied.keys;
    let sides = params.iter().map(|p| moves(model, x, keys, p, smooth_step(p))).collect::<Result<Vec<_>, _>>()?;
    let sides: Vec<Option<Sides>> = match given.scatter {
        Some(_) => sides.into_iter().map(|s| s.map(Sides::one_side)).collect(),
        None => sides,
    };
    // the toolpath's parameters are differenced either way
    let all =
        by_differences_is_cheaper(sides.iter().flatten().filter(|s| !s.toolpath).map(Sides::runs).sum(), wanted.len());
    let by_differences: Vec<bool> = sides.iter().map(|s| s.as_ref().is_some_and(|s| all || s.toolpath)).collect();
    // a parameter that leaves the experiment as it is has a zero column, from neither
    let from_the_adjoint: Vec<bool> = sides.iter().zip(&by_differences).map(|(s, &d)| s.is_some() && !d).collect();
    let adjoint: Vec<Parameter> =
        params.iter().zip(&from_the_adjoint).filter(|(_, a)| **a).map(|(p, _)| p.clone()).collect();
    let at_model = match given.values {
        Some(v) if adjoint.is_empty() => v.iter().map(|&v| Valued::new(v, None)).collect(),
        _ => {
            let asked = (!adjoint.is_empty()).then_some(&adjoint[..]);
            by_adjoint(model, &applied, (exps, x), wanted, (asked, threads))?
        }
    };
    let values: Vec<f64> = at_model.iter().map(|v| v.value).collect();
    let run = |m: &Model| {
        let values = by_adjoint(m, &Applied::new(m, x)?, (exps, x), wanted, (None, threads))?;
        Ok(values.into_iter().map(|v| v.value).collect())
    };
    let differenced: Vec<Option<Sides>> =
        sides.into_iter().zip(&by_differences).map(|(s, &d)| s.filter(|_| d)).collect();
    let Central { columns, scatter, column_scatter } =
        central(&values, run, differenced, (given.scatter, given.spare))?;
    let mut from_adjoint = 0..adjoint.len();
    let picks: Vec<Option<usize>> =
        from_the_adjoint.iter().map(|&a| if a { from_adjoint.next() } else { None }).collect();
    Ok(at_model
        .into_iter()
        .zip(columns.into_iter().zip(column_scatter).zip(scatter))
        .map(|(v, ((fd, fd_scatter), scatter))| {
            let row =
                picks.iter().zip(fd).map(|(k, d)| k.map_or(d, |k| v.gradient.as_ref().expect("asked")[k])).collect();
            let row_scatter = picks.iter().zip(fd_scatter).map(|(k, d)| if k.is_some() { 0.0 } else { d }).collect();
            Valued { value: v.value, gradient: Some(row), scatter, gradient_scatter: Some(row_scatter) }
        })
        .collect())
}

/// Values of `wanted` from a forward run ([`runner::evaluate`](super::runner::evaluate)) and,
/// with `names`, their gradients by central differences of forward runs over a step wide enough
/// to see them move. A failure layer and time are staircases in a parameter: whole layers, and
/// times resolved to the output interval, flat between stairs. A difference over a step that
/// crosses no stair is 0, one that crosses one is a stair over however short a step (a slope
/// without bound near a stair), and neither says how the failure moves with the parameter. So
/// the step starts at h = [`DIFFERENCE_STEP`] |p| (its scale where p = 0) and grows fourfold
/// while an observable has moved by less than twice the smallest move it made: the difference
/// then spans at least two of its stairs, within a factor 2 of the staircase's mean slope. Each
/// observable keeps the difference over the first step that resolved it; one that never does
/// keeps the widest. The step stops at 0.4 |p| (the parameter stays near itself: a yield stress
/// stays a yield stress), at 64 times its scale from 0 (a structuration rate of 0.5 Pa/s, its
/// scale, moves no failure layer of a print of a few layers of seconds each; 32 Pa/s does), and
/// at the last step whose runs run (a process offset wide enough to put the nozzle outside the
/// domain is refused). The difference is one-sided where p - h or p + h leaves the parameter's
/// bounds (an effect at its null on its lower bound). A parameter that leaves this experiment's
/// scenario keys as they are has a zero column without a run.
fn differenced(
    model: &Model,
    exps: &Experiments,
    x: &Experiment,
    wanted: &[Observable],
    (params, threads): (Option<&[Parameter]>, Option<usize>),
    known: Option<&[f64]>,
) -> Result<Vec<Valued>, MeasureError> {
    const WIDEST: f64 = 0.4;
    const WIDEST_AT_NULL: f64 = 64.0;
    const GROWTH: f64 = 4.0;
    let run = |m: &Model| super::runner::evaluate(m, exps, x, wanted, threads);
    let values = match known {
        Some(v) => v.to_vec(),
        None => run(model)?,
    };
    let Some(params) = params else { return Ok(values.into_iter().map(|v| Valued::new(v, None)).collect()) };
    let keys = Applied::new(model, x)?.keys;
    let mut rows = vec![vec![0.0; params.len()]; wanted.len()];
    for (j, param) in params.iter().enumerate() {
        let (p, b) = (param.value, param.bounds);
        let side = |m: Option<Model>| m.map_or(Ok(values.clone()), |m| run(&m));
        let (mut h, widest) =
            if p != 0.0 { (DIFFERENCE_STEP * p.abs(), WIDEST * p.abs()) } else { (b.scale, WIDEST_AT_NULL * b.scale) };
        // each observable's smallest move so far (its stair), and whether a difference spanned two
        let mut stair = vec![f64::INFINITY; wanted.len()];
        let mut resolved = vec![false; wanted.len()];
        for widened in 0.. {
            let Some(Sides { lo: (lo, m_lo), hi: (hi, m_hi), .. }) = moves(model, x, &keys, param, h)? else { break };
            let (v_lo, v_hi) = match (side(m_lo), side(m_hi)) {
                (Ok(a), Ok(c)) => (a, c),
                (Err(e), _) | (_, Err(e)) if widened == 0 => return Err(e),
                _ => break,
            };
            for (i, row) in rows.iter_mut().enumerate().filter(|(i, _)| !resolved[*i]) {
                let d = v_hi[i] - v_lo[i];
                if d != 0.0 {
                    stair[i] = stair[i].min(d.abs());
                }
                row[j] = d / (hi - lo);
            }
            for (i, r) in resolved.iter_mut().enumerate() {
                *r = *r || (v_hi[i] - v_lo[i]).abs() >= 2.0 * stair[i];
            }
            if resolved.iter().all(|&r| r) || h >= widest || (lo <= b.lower && hi >= b.upper) {
                break;
            }
            h = (GROWTH * h).min(widest);
        }
    }
    Ok(values.into_iter().zip(rows).map(|(v, g)| Valued::new(v, Some(g))).collect())
}

/// A parameter's two sides for a central difference ([`moves`]).
struct Sides {
    /// The parameter's value p.
    at: f64,
    lo: (f64, Option<Model>),
    hi: (f64, Option<Model>),
    /// Whether the parameter moves a toolpath key (`print.*`).
    toolpath: bool,
}

impl Sides {
    /// The forward runs its difference takes beside the values'.
    fn runs(&self) -> usize {
        usize::from(self.lo.1.is_some()) + usize::from(self.hi.1.is_some())
    }

    /// One side only: p + h, or p - h where p + h changes nothing (the upper bound).
    fn one_side(self) -> Sides {
        match self.hi.1 {
            Some(_) => Sides { lo: (self.at, None), ..self },
            None => self,
        }
    }
}

/// `name` moved to p +- h, each side held within the parameter's bounds, with the models there
/// (None for a side at p, or one that leaves this experiment's scenario keys as they are). None
/// when neither side changes the experiment: its column is 0 without a run.
fn moves(model: &Model, x: &Experiment, keys: &Keys, param: &Parameter, h: f64) -> Result<Option<Sides>, MeasureError> {
    let (p, b) = (param.value, param.bounds);
    let (lo, hi) = ((p - h).max(b.lower), (p + h).min(b.upper));
    let mut toolpath = false;
    let mut moved = |v: f64| -> Result<Option<Model>, MeasureError> {
        let m = model.edited(&[], &[(param, v)]);
        let there = Applied::new(&m, x)?.keys;
        toolpath |= there.iter().any(|(k, v)| k.starts_with("print.") && keys.get(k) != Some(v));
        Ok((v != p && there != *keys).then_some(m))
    };
    let (m_lo, m_hi) = (moved(lo)?, moved(hi)?);
    Ok((m_lo.is_some() || m_hi.is_some()).then_some(Sides { at: p, lo: (lo, m_lo), hi: (hi, m_hi), toolpath }))
}

/// Each parameter's column (a row per value): `run` at its two sides, one-sided where a side
/// stays at p (`values`, the run at the model) or fails to run (a printed line that breaks up
/// there); 0 without sides. With them, each value's scatter ([`Sensitivity::scatter`]): where a
/// parameter ran both sides a step h away, the second difference v(p + h) + v(p - h) - 2 v(p)
/// of values with independent scatter s has variance 6 s^2 (plus its curvature, h^2 v'', small
/// at 3 % steps, which only makes the estimate cautious); the mean square over the parameters
/// that ran both sides, over 6, estimates s^2. `known`, the values' scatter where the caller
/// knows it, is taken instead. A column's entry, a difference over a width w, scatters by
/// s sqrt(2) / w. The sides' runs, independent of each other, share the campaign's `spare`
/// workers.
fn central(
    values: &[f64],
    run: impl Fn(&Model) -> Result<Vec<f64>, MeasureError> + Sync,
    sides: Vec<Option<Sides>>,
    (known, spare): (Option<&[f64]>, Option<&Spare>),
) -> Result<Central, MeasureError> {
    // every side that moves, low before high, parameter by parameter
    let moved: Vec<&Model> =
        sides.iter().flatten().flat_map(|s| [s.lo.1.as_ref(), s.hi.1.as_ref()]).flatten().collect();
    let ran = match spare {
        Some(spare) => spare.map(moved.len(), |i| run(moved[i])),
        None => moved.iter().map(|m| run(m)).collect(),
    };
    let mut ran = ran.into_iter();
    let mut rows = vec![vec![0.0; sides.len()]; values.len()];
    let mut second = vec![0.0; values.len()];
    let mut both_sides = 0;
    let mut widths = vec![f64::INFINITY; sides.len()];
    for (j, s) in sides.into_iter().enumerate() {
        let Some(Sides { lo: (lo, m_lo), hi: (hi, m_hi), at, .. }) = s else { continue };
        let symmetric = m_lo.is_some() && m_hi.is_some() && hi - at == at - lo;
        let mut side = |m: Option<Model>| m.map_or(Ok(values.to_vec()), |_| ran.next().expect("every moved side ran"));
        let (v_lo, v_hi) = (side(m_lo), side(m_hi));
        let ((lo, v_lo), (hi, v_hi)) = match (v_lo, v_hi) {
            (Ok(a), Ok(b)) => {
                if symmetric {
                    both_sides += 1;
                    for (d2, ((a, b), v)) in second.iter_mut().zip(a.iter().zip(&b).zip(values)) {
                        *d2 += (a + b - 2.0 * v).powi(2);
                    }
                }
                ((lo, a), (hi, b))
            }
            (Err(_), Ok(b)) if hi != at => ((at, values.to_vec()), (hi, b)),
            (Ok(a), Err(_)) if lo != at => ((lo, a), (at, values.to_vec())),
            (Err(e), _) | (_, Err(e)) => return Err(e),
        };
        for (row, (a, b)) in rows.iter_mut().zip(v_lo.iter().zip(&v_hi)) {
            row[j] = (b - a) / (hi - lo);
        }
        widths[j] = hi - lo;
    }
    let scatter: Vec<f64> = match known {
        Some(s) => s.to_vec(),
        None => second
            .into_iter()
            .map(|d2| if both_sides == 0 { 0.0 } else { (d2 / (6 * both_sides) as f64).sqrt() })
            .collect(),
    };
    let column_scatter = scatter.iter().map(|s| widths.iter().map(|w| s * 2f64.sqrt() / w).collect()).collect();
    Ok(Central { columns: rows, scatter, column_scatter })
}

/// What [`central`] gives: the columns (a row per value), each value's scatter, and each
/// column entry's.
struct Central {
    columns: Vec<Vec<f64>>,
    scatter: Vec<f64>,
    column_scatter: Vec<Vec<f64>>,
}

/// Values of `wanted` from experiment `x`'s run under `model` (`applied` to it) and, with `names`,
/// their gradients by the adjoints: the simulation's or the rheometer's, then the model's effects.
fn by_adjoint(
    model: &Model,
    applied: &Applied,
    (exps, x): (&Experiments, &Experiment),
    wanted: &[Observable],
    (params, threads): (Option<&[Parameter]>, Option<usize>),
) -> Result<Vec<Valued>, MeasureError> {
    let keys = &applied.keys;
    // an override cuts the key from the model
    let chain = |mut keys_bar: Keys| -> Result<Vec<f64>, MeasureError> {
        for k in x.set.keys() {
            keys_bar.remove(k);
        }
        model.keys_adjoint(&x.covariates(), keys_bar, params.expect("gradients asked"))
    };
    match (&x.scenario, &x.protocol) {
        (Some(s), _) => {
            let path = exps.base_dir.join(s);
            let doc = applied.scenario_table(&path)?;
            let whole = scenario_from_table(doc.clone(), &path)?;
            let end = whole.simulation.end_time;
            // each model key with the scenario key it landed on (the floor's friction on the
            // platform or the z_min face)
            let (wrt, placed): (Vec<String>, Vec<String>) = match params {
                Some(_) => {
                    let known = params::known(&driver::prepare(&whole, threads)?);
                    keys.keys()
                        .filter(|k| !x.set.contains_key(*k))
                        .map(|k| (k.clone(), crate::measure::effects::placed(k, &doc)))
                        .filter(|(_, p)| known.contains(p))
                        .unzip()
                }
                None => (Vec::new(), Vec::new()),
            };
            // the observations the whole run passes share its forward and reverse sweeps (an
            // adjoint each); the others (between two of its steps, or at t = 0) run to their time
            let plans: Vec<(f64, Objective)> =
                wanted.iter().map(|o| observable_plan(o, end)).collect::<Result<_, _>>()?;
            let sim = driver::prepare(&whole, threads)?;
            let steps: Vec<Option<u64>> = plans.iter().map(|(t, _)| driver::step_at(&sim, *t)).collect();
            drop(sim);
            let shared: Vec<usize> = (0..plans.len()).filter(|&k| steps[k].is_some()).collect();
            let seeds: Vec<Seeded> =
                shared.iter().map(|&k| Seeded { objective: plans[k].1.clone(), step: steps[k] }).collect();
            let opts = GradOptions {
                ram_bytes: 2 << 30,
                disk_bytes: 0,
                disk_dir: std::env::temp_dir(),
                threads,
                schedule: None,
                until_rest: None,
            };
            let mut out: Vec<Option<Valued>> = vec![None; plans.len()];
            if params.is_none() {
                for (&k, v) in shared.iter().zip(driver::forward_values(&whole, &seeds, threads)?) {
                    out[k] = Some(Valued::new(v, None));
                }
            } else {
                for (&k, r) in shared.iter().zip(driver::gradients(&whole, &seeds, &placed, &opts)?) {
                    out[k] = Some(Valued::new(r.value, Some(chain(wrt.iter().cloned().zip(r.gradient).collect())?)));
                }
            }
            for (k, (t, obj)) in plans.iter().enumerate().filter(|(k, _)| steps[*k].is_none()) {
                let mut at_t = doc.clone();
                set_path(&mut at_t, "simulation.end_time", *t)?;
                let sc = scenario_from_table(at_t, &path)?;
                out[k] = Some(if params.is_none() {
                    let steps = driver::count_steps(&driver::prepare(&sc, threads)?);
                    Valued::new(driver::forward_value(&sc, obj, threads, steps)?, None)
                } else {
                    let r = driver::gradient(&sc, obj, &placed, &opts)?;
                    Valued::new(r.value, Some(chain(wrt.iter().cloned().zip(r.gradient).collect())?))
                });
            }
            Ok(out.into_iter().map(|v| v.expect("every observation valued")).collect())
        }
        (None, Some(p)) => {
            let (material, proto) = applied.rheometer_setup(&exps.base_dir, p)?;
            let rh = Rheometer::new(&*material, &proto)?;
            let readings = rh.run();
            wanted
                .iter()
                .map(|o| {
                    let k = reading_index(o, &readings)?;
                    if params.is_none() {
                        return Ok(Valued::new(readings[k].stress, None));
                    }
                    let mut w = vec![0.0; readings.len()];
                    w[k] = 1.0;
                    let (_, g) = rh.gradient(&w)?;
                    let kb: Keys = material.param_names().iter().map(|n| format!("material.{n}")).zip(g).collect();
                    Ok(Valued::new(readings[k].stress, Some(chain(kb)?)))
                })
                .collect()
        }
        (None, None) => Err(MeasureError::Run("neither scenario nor protocol".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: &str = "[material]\nkind = \"bingham\"\ndensity = 2100.0\nbulk_modulus = 1e6\nviscosity = 7.5\n\
        yield_stress = 630.0\n[effects.ageing]\nrate = 0.0\n";
    const EXPS: &str = "[[experiment]]\nid = \"flow\"\nobserve = [\"stress@20\", \"stress@5\"]\n[experiment.protocol]\n\
        [[experiment.protocol.phase]]\nkind = \"sweep\"\nrates = [20.0, 5.0]\nhold = 0.5\n";

    /// A simulation's difference steps 3 % of the parameter, or of its unit where the parameter
    /// has gone under it: the value the model was read with for a material number, the scale
    /// for an effect's.
    #[test]
    fn a_parameter_fitted_towards_0_is_differenced_over_its_unit() {
        let mut m = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let smooth_step = |m: &Model, name: &str| m.parameters(&[name.into()]).map(|p| smooth_step(&p[0]));
        assert_eq!(smooth_step(&m, "material.viscosity").unwrap(), 0.03 * 7.5);
        m.set("material.viscosity", 1e-5).unwrap();
        assert_eq!(smooth_step(&m, "material.viscosity").unwrap(), 0.03 * 7.5);
        m.set("material.viscosity", 30.0).unwrap();
        assert_eq!(smooth_step(&m, "material.viscosity").unwrap(), 0.03 * 30.0);
        let scale = m.bounds("ageing.rate").unwrap().scale;
        assert_eq!(smooth_step(&m, "ageing.rate").unwrap(), 0.03 * scale);
        m.set("ageing.rate", 1e-3 * scale).unwrap();
        assert_eq!(smooth_step(&m, "ageing.rate").unwrap(), 0.03 * scale);
    }

    /// The scatter the central differences estimate is the standard deviation of values' rough
    /// part (uniform noise of unit variance times s, independent from run to run), not their
    /// slope; a curved smooth value scatters by its second difference over sqrt(6).
    #[test]
    fn central_differences_estimate_the_values_scatter() {
        let m = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let (name, p, h, s) = ("material.viscosity", 7.5, 0.225, 0.01);
        let at = |v: f64| {
            let mut m = m.clone();
            m.set(name, v).unwrap();
            Some(m)
        };
        let sides = || vec![Some(Sides { at: p, lo: (p - h, at(p - h)), hi: (p + h, at(p + h)), toolpath: false })];
        // uniform on [-sqrt 3, sqrt 3] from a hash of the observation and the run
        let noise = |i: u64, v: f64| {
            let mut x = (i << 32) ^ v.to_bits();
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d049bb133111eb);
            x ^= x >> 31;
            3f64.sqrt() * (2.0 * (x >> 11) as f64 / (1u64 << 53) as f64 - 1.0)
        };
        let n = 4000;
        let rough = |m: &Model| -> Result<Vec<f64>, MeasureError> {
            let v = m.get(name)?;
            Ok((0..n).map(|i| (1.0 + i as f64) * v + s * noise(i, v)).collect())
        };
        let c = central(&rough(&m).unwrap(), rough, sides(), (None, None)).unwrap();
        let rms = (c.scatter.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
        assert!((rms / s - 1.0).abs() < 0.05, "rms scatter {rms} against {s}");
        // the slopes scatter about theirs by s / (sqrt(2) h), as each entry's scatter says
        let (miss, said): (f64, f64) = (0..n as usize)
            .map(|i| ((c.columns[i][0] - (1.0 + i as f64)).powi(2), c.column_scatter[i][0].powi(2)))
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let expected = s / (2f64.sqrt() * h);
        assert!(
            ((miss / n as f64).sqrt() / expected - 1.0).abs() < 0.05,
            "slopes miss by {} rms against {expected}",
            (miss / n as f64).sqrt()
        );
        assert!(
            ((said / n as f64).sqrt() / expected - 1.0).abs() < 0.1,
            "slopes said to scatter by {} rms against {expected}",
            (said / n as f64).sqrt()
        );
        let smooth =
            |m: &Model| -> Result<Vec<f64>, MeasureError> { Ok(vec![3.0 * m.get(name)?, m.get(name)?.powi(2)]) };
        let c = central(&smooth(&m).unwrap(), smooth, sides(), (None, None)).unwrap();
        assert!(c.scatter[0] < 1e-12, "a line has no scatter: {}", c.scatter[0]);
        assert!((c.scatter[1] - 2.0 * h * h / 6f64.sqrt()).abs() < 1e-9, "a parabola's: {}", c.scatter[1]);
        // one-sided (a side at a bound) says nothing of the scatter
        let one_sided = vec![Some(Sides { at: p, lo: (p, None), hi: (p + h, at(p + h)), toolpath: false })];
        let c = central(&rough(&m).unwrap(), rough, one_sided, (None, None)).unwrap();
        assert!(c.scatter.iter().all(|&x| x == 0.0) && c.column_scatter.iter().all(|r| r[0] == 0.0));
        // forward differences with the scatter known: the slopes scatter by s sqrt(2) / h, twice
        // the central ones' over the same h, as each entry's scatter says
        let forward = sides().into_iter().map(|s| s.map(Sides::one_side)).collect();
        let known = vec![s; n as usize];
        let c = central(&rough(&m).unwrap(), rough, forward, (Some(&known), None)).unwrap();
        assert_eq!(c.scatter, known);
        let (miss, said): (f64, f64) = (0..n as usize)
            .map(|i| ((c.columns[i][0] - (1.0 + i as f64)).powi(2), c.column_scatter[i][0].powi(2)))
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let expected = s * 2f64.sqrt() / h;
        assert!(
            ((miss / n as f64).sqrt() / expected - 1.0).abs() < 0.05,
            "forward slopes miss by {} rms against {expected}",
            (miss / n as f64).sqrt()
        );
        assert!(
            ((said / n as f64).sqrt() / expected - 1.0).abs() < 1e-9,
            "forward slopes said to scatter by {} rms against {expected}",
            (said / n as f64).sqrt()
        );
    }

    /// The differenced Jacobian is the adjoint's where the observable is linear in the
    /// parameters (a Bingham flow curve: tau0 + eta rate); a parameter that leaves the
    /// experiment's keys unchanged (ageing at age 0) has a zero column; an effect at its null on
    /// its lower bound is differenced one-sided.
    #[test]
    fn differences_agree_with_the_adjoint_on_a_linear_observable() {
        let m = Model::from_table(&MODEL.parse().unwrap()).unwrap();
        let e: Experiments = toml::from_str(EXPS).unwrap();
        e.validate().unwrap();
        let x = find(&e, "flow").unwrap();
        let wanted = [Observable::parse("stress@20").unwrap(), Observable::parse("stress@5").unwrap()];
        let names: Vec<String> =
            ["material.yield_stress", "material.viscosity", "ageing.rate"].map(String::from).to_vec();
        let params = m.parameters(&names).unwrap();
        let fd = differenced(&m, &e, x, &wanted, (Some(&params[..]), None), None).unwrap();
        let adj = by_adjoint(&m, &Applied::new(&m, x).unwrap(), (&e, x), &wanted, (Some(&params[..]), None)).unwrap();
        for (f, a) in fd.iter().zip(&adj) {
            let (v, va) = (f.value, a.value);
            assert!((v - va).abs() <= 1e-9 * va.abs(), "{v} against {va}");
            let (g, ga) = (f.gradient.as_ref().unwrap(), a.gradient.as_ref().unwrap());
            for (a, b) in g.iter().zip(ga) {
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{g:?} against the adjoint's {ga:?}");
            }
            assert_eq!(g[2], 0.0);
        }
        let values: Vec<f64> = fd.iter().map(|v| v.value).collect();
        assert_eq!(differenced(&m, &e, x, &wanted, (Some(&params[..]), None), Some(&values)).unwrap(), fd);
        // at age 100 s ageing moves the yield stress: d stress / d rate = tau0 age, one-sided
        let aged: Experiments = toml::from_str(&EXPS.replace("observe = ", "age = 100.0\nobserve = ")).unwrap();
        let x = find(&aged, "flow").unwrap();
        let fd = differenced(&m, &aged, x, &wanted, (Some(&params[..]), None), None).unwrap();
        let applied = Applied::new(&m, x).unwrap();
        let adj = by_adjoint(&m, &applied, (&aged, x), &wanted, (Some(&params[..]), None)).unwrap();
        for (f, a) in fd.iter().zip(&adj) {
            let (g, ga) = (f.gradient.as_ref().unwrap(), a.gradient.as_ref().unwrap());
            assert!(
                (g[2] / (630.0 * 100.0) - 1.0).abs() < 1e-6 && (g[2] / ga[2] - 1.0).abs() < 1e-6,
                "{g:?} against the adjoint's {ga:?}"
            );
        }
    }

    /// On a printed line (the print campaign's, at its 3 mm cells) the differences that stand in
    /// for the adjoint give a section's response to the material as the adjoint does, and its
    /// response to the pump as mass balance does: the area of a line is the delivered flow over
    /// the print speed, so d area / d factor = area / factor. The adjoint holds the number of
    /// particles the nozzle emits fixed, so it misses that response (printed beside).
    #[test]
    fn differences_stand_in_for_the_adjoint_on_a_print_line() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/measure/print");
        let mut m =
            Model::from_table(&std::fs::read_to_string(dir.join("base.toml")).unwrap().parse().unwrap()).unwrap();
        m = m.with_effect(crate::measure::effects::find("extrusion_factor").unwrap());
        m.set("extrusion_factor.factor", 0.95).unwrap();
        let e = Experiments::load(&dir.join("experiments.toml")).unwrap();
        let x = find(&e, "line_V60").unwrap();
        let wanted: Vec<Observable> = x.observe.iter().map(|o| Observable::parse(o).unwrap()).collect();
        let names: Vec<String> =
            ["material.yield_stress", "material.viscosity", "extrusion_factor.factor"].map(String::from).to_vec();
        let (params, applied) = (m.parameters(&names).unwrap(), Applied::new(&m, x).unwrap());
        // two material parameters; the extrusion factor's is differenced either way
        assert!(by_differences_is_cheaper(2 * 2, wanted.len()));
        let fd = experiment(&m, &e, x, &wanted, (Some(&params[..]), Some(1)), Given::default()).unwrap();
        let adj = by_adjoint(&m, &applied, (&e, x), &wanted, (Some(&params[..]), Some(1))).unwrap();
        // the values known (a calibration's accepted trial), the same Jacobian without their run
        let values: Vec<f64> = fd.iter().map(|v| v.value).collect();
        let given = Given { values: Some(&values), ..Given::default() };
        let known = experiment(&m, &e, x, &wanted, (Some(&params[..]), Some(1)), given).unwrap();
        assert_eq!(known, fd);
        let p: Vec<f64> = names.iter().map(|n| m.get(n).unwrap()).collect();
        let mut by_name = std::collections::BTreeMap::new();
        for (o, (f, a)) in wanted.iter().zip(fd.iter().zip(&adj)) {
            let v = f.value;
            assert_eq!(v, a.value, "{o:?}: the values come from the same runs");
            let (g, ga) = (f.gradient.as_ref().unwrap(), a.gradient.as_ref().unwrap());
            for j in 0..names.len() {
                let (name, differences, adjoint) = (&names[j], g[j] * p[j], ga[j] * p[j]);
                println!(
                    "{} {:?}: d / d ln {name}: differences {differences:.4e}, adjoint {adjoint:.4e}",
                    o.name, o.at2
                );
            }
            by_name.insert(o.name.clone(), (v, g.clone(), ga.clone()));
        }
        let (area, g, _) = &by_name["area"];
        let ratio = g[2] * p[2] / area;
        println!("d ln area / d ln factor = {ratio:.4}");
        assert!((ratio - 1.0).abs() < 0.05, "d ln area / d ln factor = {ratio} against mass balance's 1");
        for o in ["width", "height"] {
            let (_, g, ga) = &by_name[o];
            let big = (0..2).map(|j| (ga[j] * p[j]).abs()).fold(0.0, f64::max);
            for j in 0..2 {
                assert!(
                    (g[j] - ga[j]).abs() * p[j] <= 0.25 * big,
                    "{o}: d / d {}: differences {} against the adjoint's {}",
                    names[j],
                    g[j],
                    ga[j]
                );
            }
        }
        // one-sided with the values' scatter known: p runs, not 2 p, the columns the central
        // ones to first order, the scatter the one given
        let scatter: Vec<f64> = fd.iter().map(|v| v.scatter).collect();
        let given = Given { values: Some(&values), scatter: Some(&scatter), spare: None };
        let forward = experiment(&m, &e, x, &wanted, (Some(&params[..]), Some(1)), given).unwrap();
        for ((o, f), (c, s)) in wanted.iter().zip(&forward).zip(fd.iter().zip(&scatter)) {
            assert_eq!((f.value, f.scatter), (c.value, *s));
            let (gf, gc) = (f.gradient.as_ref().unwrap(), c.gradient.as_ref().unwrap());
            // within 3 standard deviations of the two differences' scatter, as each says it, and
            // the width, the best resolved, within a quarter of its largest entry
            let (sf, sc) = (f.gradient_scatter.as_ref().unwrap(), c.gradient_scatter.as_ref().unwrap());
            let big = (0..names.len()).map(|j| (gc[j] * p[j]).abs()).fold(0.0, f64::max);
            for j in 0..names.len() {
                let apart = 3.0 * sf[j].hypot(sc[j]);
                let (name, one_sided, central, sigma3) = (&names[j], gf[j] * p[j], gc[j] * p[j], apart * p[j]);
                println!(
                    "{} {:?}: d / d ln {name}: forward {one_sided:.4e}, central {central:.4e}, 3 sigma {sigma3:.4e}",
                    o.name, o.at2
                );
                assert!(
                    (gf[j] - gc[j]).abs() <= apart,
                    "{}: d / d {}: forward {} against central {}, 3 sigma {apart}",
                    o.name,
                    names[j],
                    gf[j],
                    gc[j]
                );
                assert!(
                    o.name != "width" || (gf[j] - gc[j]).abs() * p[j] <= 0.25 * big,
                    "width: d / d {}: forward {} against central {}",
                    names[j],
                    gf[j],
                    gc[j]
                );
            }
        }
        // with more parameters than differences pay for, the material's columns come from the
        // adjoint and the toolpath's from differences
        let more = ["material.bulk_modulus".to_string()].into_iter().chain(names.iter().cloned()).collect::<Vec<_>>();
        let more = m.parameters(&more).unwrap();
        assert!(!by_differences_is_cheaper(2 * 3, 1));
        let hybrid = experiment(&m, &e, x, &wanted[..1], (Some(&more[..]), Some(1)), Given::default()).unwrap();
        let adj = by_adjoint(&m, &applied, (&e, x), &wanted[..1], (Some(&more[..3]), Some(1))).unwrap();
        let (row, adj_row) = (hybrid[0].gradient.as_ref().unwrap(), adj[0].gradient.as_ref().unwrap());
        assert_eq!(&row[..3], &adj_row[..], "the material's columns from the adjoint");
        assert_eq!(row[3], fd[0].gradient.as_ref().unwrap()[2], "the extrusion factor's from differences");
    }
}
