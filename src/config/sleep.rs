//! The `[sleep]` table: when material at rest sleeps and what wakes it (`sleep.rs` has the rules),
//! and whether a scenario that writes no `[sleep]` sleeps ([`sleep_by_default`], the default's
//! one rule).

use serde::Deserialize;
use crate::invalid::Invalid;
use crate::kernels::material::Material;
use crate::kernels::{Real, M3};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SleepConfig {
    /// `false`: all material stays awake, whatever the default ([`sleep_by_default`]) would do;
    /// the other keys are then not used. A written `[sleep]` table is on unless it says this.
    #[serde(default = "default_enabled")]
    pub enabled: bool,
    /// Particle speed below which material counts as at rest [m/s].
    #[serde(default = "default_speed")]
    pub speed: f64,
    /// Strain rate |sym(grad v)| below which material counts as at rest [1/s].
    #[serde(default = "default_rate")]
    pub strain_rate: f64,
    /// Time at rest before a unit sleeps [s].
    #[serde(default = "default_rest")]
    pub rest_time: f64,
    /// Speed of neighbouring material that wakes a sleeping unit [m/s].
    #[serde(default = "default_wake")]
    pub wake_speed: f64,
    /// Time a woken unit settles before its own speed can wake its neighbours [s].
    #[serde(default = "default_grace")]
    pub wake_grace: f64,
    /// Steps between checks for units to put to sleep.
    #[serde(default = "default_check")]
    pub check_interval: u64,
    /// Material above a sleeping unit wakes it by its load, not its speed: when the load can
    /// make the unit yield (module notes). Default: on for prints of two or more layers, where
    /// a layer asleep under a growing stack must wake before it yields (`Scenario` resolves it
    /// from the toolpath), off otherwise; off, the speed rule alone decides. It needs gravity
    /// along an axis (the test must know which way is down) and does nothing otherwise.
    #[serde(default)]
    pub wake_by_load: Option<bool>,
    /// Time over which the load on a sleeping unit is averaged [s] (with `wake_by_load`).
    #[serde(default = "default_load_time")]
    pub load_time: f64,
    /// Least amount [Pa] by which a load's share of tau must pass a sleeping unit's margin to
    /// yield to wake it (with `wake_by_load`): a load that adds less than this to tau never
    /// wakes a unit. Why: EVP material that stopped flowing rests on its yield surface (margins
    /// of -0.5 to +1 Pa were measured), so the averaged load's fluctuations of a few Pa would
    /// otherwise wake units that just fell asleep.
    #[serde(default = "default_load_floor")]
    pub load_floor: f64,
    /// Share of a sleeping unit's margin to yield that a load must pass to wake it (with
    /// `wake_by_load`), in (0, 1]: below 1, a safety factor that wakes units before their
    /// material would yield (at the price of more awake material). None: the default of the
    /// material's load test ([`SleepConfig::load_fraction_for`]).
    #[serde(default)]
    pub load_fraction: Option<f64>,
    /// Speed [m/s] above which material above a sleeping unit still wakes it (with
    /// `wake_by_load`), and keeps an awake one from falling asleep under it; `inf`, material
    /// above wakes by its load alone. Why: material arriving from the nozzle squeezes the layer
    /// below before its weight has built up a load (module notes).
    #[serde(default = "default_arrive_speed")]
    pub arrive_speed: f64,
    /// Carry the interior of sleeping material by one particle per cell (`coarsen.rs`): the
    /// layers below cost less when the next layer wakes them. Off by default.
    #[serde(default)]
    pub coarsen: bool,
}

fn default_enabled() -> bool {
    true
}
fn default_speed() -> f64 {
    // Each emitted slab sends an elastic pulse through deposited EVP material: block maxima of
    // 1e-4-5e-4 m/s pass every slab interval (measured on case 1), so a lower threshold never
    // lets a block rest while the nozzle runs. Material still creeping at 1 mm/s for the rest
    // time moves 0.05 mm: below 1 % of a layer.
    1e-3
}
fn default_rate() -> f64 {
    // Elastic waves from the nozzle keep deposited EVP material straining at ~1e-2 /s (speeds
    // ~3e-5 m/s over a 2.5 mm cell, measured on case 1) without changing its shape; 0.1 /s sits
    // above that noise and far below flow under the nozzle (~10 /s).
    0.1
}
fn default_rest() -> f64 {
    0.05
}
fn default_wake() -> f64 {
    // Slow enough to wake the flanks of a layer that the next layer spreads (1-2 mm/s); well
    // above the elastic pulses of emission (1e-4-5e-4 m/s). Measured on the three-layer print at
    // 2.5 mm (BENCHMARKS.md "Sleeping"): with 1e-2 the first layer's flanks slept through the
    // second layer's passage and the section came out 1.37 % narrower than all-awake; with
    // 4e-3, 1.02 %; with 2e-3, 0.26 %.
    2e-3
}
fn default_grace() -> f64 {
    // Many times the pulse's passage through a unit (5 mm at c ~ 28 m/s: 0.2 ms), leaving room
    // for the ringing after it; short enough that flow reaching a sleeping neighbour is held
    // back by at most 0.02 s x 2 mm/s = 0.04 mm. Measured, ten layers at 5 mm: 268 CPU s with
    // 0.02 s, 295 s with 0.1 s, 423 s without (BENCHMARKS.md "Sleeping").
    0.02
}
fn default_check() -> u64 {
    64
}
fn default_load_time() -> f64 {
    // Many times the elastic ringing of a layer (2 x 12.5 mm at c ~ 28 m/s: 0.9 ms) and the
    // impact of each arriving slab, which average out; short against the nozzle's passage over a
    // unit (~0.2 s), whose squeeze is the load that matters.
    0.02
}
fn default_column_load_fraction() -> f64 {
    // A quarter for a material whose units are tested against their whole column's added load
    // (`Material::column_loads`: `early_age_solid`), whose sleeping part is held rigid while the
    // awake part deforms. The printed cylinder of bench/cylinder.py (10 mm cells, mass scaling
    // 100, one run each, AMD EPYC) fails asleep in layers 19, 17 and 10 at the chosen cohesion,
    // two thirds and a third of it, against 24, 18 and 11 awake; with half (0.5) in 21, 14 and
    // 11. Neither is within a layer; a quarter is off by 5 at most, half by 4 but the other way
    // round at two thirds. The laid wall of early_age_wall.toml fails in layer 17 asleep with
    // either, 19 awake (docs/failure.md "Sleeping and failure").
    0.25
}
fn default_load_fraction() -> f64 {
    // Half: a unit wakes when the load added since it fell asleep approaches its margin to
    // yield, so sleeping never holds up a collapse. Measured on the tiny wall of tests/suite/print.rs
    // (6 mm layers, tau0 = 100 Pa, 5 mm cells), failure layer and time: all awake 5 at 7.06 s;
    // the speed rule alone 5 at 6.96 s; wake on load with the whole margin (1.0) 6 at 8.44 s, a
    // layer late; with half of it 5 at 6.96 s, and the fewest awake particle-steps of the four
    // (BENCHMARKS.md "Printing to failure"). Half was once the default while the layer below was
    // held still under the nozzle, where waking it sooner kept the new layer from spreading over
    // it (+0.37 % width against the speed rule on the dwell print at 2.5 mm); `arrive_speed` now
    // keeps that layer awake under the nozzle.
    0.5
}
fn default_arrive_speed() -> f64 {
    // Between the new layer's settling behind the nozzle (a few mm/s, falling) and material
    // leaving the nozzle (printing and extrusion speeds, 30-34 mm/s in paper 000's case 1).
    // Measured on the dwell print at 2.5 mm, two layers, against the speed rule: width -0.05 %
    // with 1e-2 and with 5e-3, +1.6 % without.
    1e-2
}
fn default_load_floor() -> f64 {
    // Several times the averaged load's fluctuations on a unit at rest (a few Pa, measured on
    // the ten-layer print at 5 mm; BENCHMARKS.md "Sleeping"), and small against a layer's
    // weight on the one below (~150 Pa for 12.5 mm).
    20.0
}

/// Whether a scenario that writes no `[sleep]` sleeps, and why, in a sentence for its log.
#[derive(Clone, Debug, PartialEq)]
pub struct SleepDefault {
    pub on: bool,
    pub why: String,
}

/// Materials whose sleeping is measured sound against all awake: `evp_bingham` (a printed
/// section within 1 % of all awake, `strand verify` case `print_sleep` and tests/suite/print.rs;
/// its wake has an adjoint, so gradient runs sleep too). Not listed: the rate-independent elastic-plastic solids
/// (`early_age_solid`, `drucker_prager`), whose failure layer moves asleep (docs/failure.md
/// "Sleeping and failure"), and the plain fluids (`newtonian`, `bingham`,
/// `papanastasiou_roussel`), which hold no margin to yield for the load test and whose sleeping
/// nobody has measured.
pub const SLEEPS_BY_DEFAULT: &[&str] = &["evp_bingham"];

/// The default for a scenario without `[sleep]`, the one rule: a print (`printed`: it has a
/// `[print]`) of a material in [`SLEEPS_BY_DEFAULT`] sleeps, unless it is printed to failure
/// (`to_failure`: two or more layers observed at a station, whose failure `failure.rs` detects)
/// or the material's configuration has no adjoint of waking (`evp_bingham` with an age law or a
/// Maxwell branch, so that a gradient run of the same scenario sleeps as its forward run does and
/// never stops on a wake); everything else stays awake. Why not to failure: a wall that builds up
/// strength at rest (the failure campaign's truth, A_thix = 40 Pa/s, at 10 mm) failed 0.45 s
/// (28 % of a layer period) later asleep, in the same layer, and the diagnosis from those walls
/// changed its verdict. A scenario opts out with `[sleep] enabled = false`, and into sleeping
/// anywhere by writing `[sleep]`.
pub fn sleep_by_default(printed: bool, to_failure: bool, material: &dyn Material) -> SleepDefault {
    let name = material.name();
    let (on, why) = if !printed {
        (false, "sleeping is on by default only in prints (a [print] table)".to_string())
    } else if to_failure {
        (false, "a print of two or more layers observed at a station is printed to failure, and sleeping can delay a failure".to_string())
    } else if !SLEEPS_BY_DEFAULT.contains(&name) {
        (false, format!("sleeping is on by default only for prints of {}, whose sleeping is measured against all awake; {name} is not", SLEEPS_BY_DEFAULT.join(", ")))
    } else if !wakes_in_gradients(material) {
        (false, format!("this {name} (an age law or a Maxwell branch) has no adjoint of waking, so gradient runs could not sleep with it"))
    } else {
        (true, format!("a print of {name}, not printed to failure, whose sleeping is measured against all awake (the section within 1 %)"))
    };
    SleepDefault { on, why }
}

/// Whether `material` has an adjoint of waking ([`Material::wake_adjoint`], which answers false
/// and touches nothing without one; with one it writes into these scratch buffers only).
fn wakes_in_gradients(material: &dyn Material) -> bool {
    let mut state = vec![0.0 as Real; material.state_names().len()];
    material.init_state(&mut state);
    let mut state_bar = vec![0.0 as Real; state.len()];
    let mut params_bar = vec![0.0 as Real; material.param_names().len()];
    let mut j_bar = 0.0 as Real;
    material.wake_adjoint(&state, 0.0, 1.0, &M3::ZERO, &mut state_bar, &mut j_bar, &mut params_bar)
}

impl SleepConfig {
    /// The load fraction in force: the one given, else half, or a quarter when the material's
    /// units are tested against their whole column's load (`column_loads`; reasons at the
    /// defaults).
    pub fn load_fraction_for(&self, column_loads: bool) -> f64 {
        self.load_fraction.unwrap_or_else(|| if column_loads { default_column_load_fraction() } else { default_load_fraction() })
    }

    /// Every key at its default (an empty `[sleep]` table).
    pub fn defaults() -> SleepConfig {
        toml::from_str("").expect("every [sleep] key has a default")
    }

    pub fn validate(&self) -> Result<(), Invalid> {
        for (k, v) in [
            ("sleep.speed", self.speed),
            ("sleep.strain_rate", self.strain_rate),
            ("sleep.rest_time", self.rest_time),
            ("sleep.wake_speed", self.wake_speed),
            ("sleep.wake_grace", self.wake_grace),
            ("sleep.load_time", self.load_time),
            ("sleep.load_floor", self.load_floor),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(Invalid(format!("{k} must be >= 0, got {v}")));
            }
        }
        if !(self.arrive_speed >= self.wake_speed) {
            return Err(Invalid(format!(
                "sleep.arrive_speed must be >= sleep.wake_speed ({}) (inf: material above wakes by its load alone), got {}",
                self.wake_speed, self.arrive_speed
            )));
        }
        if let Some(f) = self.load_fraction.filter(|f| !(*f > 0.0 && *f <= 1.0)) {
            return Err(Invalid(format!("sleep.load_fraction must be in (0, 1], got {f}")));
        }
        if self.wake_speed < self.speed {
            return Err(Invalid(format!(
                "sleep.wake_speed ({}) must be >= sleep.speed ({}), or blocks would wake at rest",
                self.wake_speed, self.speed
            )));
        }
        if self.check_interval == 0 {
            return Err(Invalid("sleep.check_interval must be >= 1".into()));
        }
        Ok(())
    }

    /// Whether loads wake sleeping units under `gravity`: `wake_by_load`, and gravity along an
    /// axis (the test needs to know which way is down).
    pub fn tests_loads(&self, gravity: [f64; 3]) -> bool {
        self.down(gravity).is_some()
    }

    /// Axis and sign of `gravity` when loads are tested under it.
    pub fn down(&self, gravity: [f64; 3]) -> Option<(usize, i32)> {
        let mut axes = (0..3).filter(|&a| gravity[a] != 0.0);
        match (axes.next(), axes.next()) {
            (Some(a), None) if self.wake_by_load.unwrap_or(true) => Some((a, gravity[a].signum() as i32)),
            _ => None,
        }
    }
}
