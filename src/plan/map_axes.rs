//! The printability map's axes (`strand plan --map X,Y`): a setting (speed, extrusion,
//! standoff) or a dimensionless group, V/U (the nozzle's travel speed over the extrusion speed)
//! or H/D (the standoff over the nozzle's diameter), the groups in which Comminal et al. and
//! paper 000 report layer shapes.
//!
//! In: the spec (`v/u,h/d`, each name optionally with its range, `v/u=0.8:1.5`), the counts
//! (`5x5`), the targets' bounds; after the plan, its point and the nozzle's diameter.
//! Out: two [`Axis`], and each grid point's settings. A group is varied through one setting, the
//! rest held at the plan's point: H/D through the standoff (D the outlet's narrowest width); V/U
//! through the speed at the plan's extrusion speed, or, when the speed has no bounds or is the
//! other axis, through the extrusion speed at the plan's speed. A group's range defaults to what
//! its setting's bounds allow at the plan's point; a grid point whose setting falls outside its
//! bounds is refused, naming it. An axis given a range may vary a setting the targets hold (no
//! bounds): the map then leaves the plan's own search space.

use super::error::PlanError;
use super::line::Point;
use super::targets::{Setting, Targets};

/// What an axis spans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quantity {
    Setting(Setting),
    /// V/U, varied through `through` (the speed or the extrusion speed), the other held.
    SpeedRatio { through: Setting },
    /// H/D, varied through the standoff, with D the nozzle's narrowest width [m].
    StandoffRatio { diameter: f64 },
}

impl Quantity {
    /// The setting the quantity is varied through.
    pub fn varied(self) -> Setting {
        match self {
            Quantity::Setting(s) | Quantity::SpeedRatio { through: s } => s,
            Quantity::StandoffRatio { .. } => Setting::Standoff,
        }
    }

    /// The quantity's value at settings `x` (a setting in SI units).
    pub fn of(self, x: &Point) -> f64 {
        match self {
            Quantity::Setting(s) => x[s.index()],
            Quantity::SpeedRatio { .. } => x[0] / x[1],
            Quantity::StandoffRatio { diameter } => x[2] / diameter,
        }
    }

    /// `x` with the quantity at `q`, through its setting, the others held.
    fn set(self, q: f64, x: &mut Point) {
        match self {
            Quantity::Setting(s) => x[s.index()] = q,
            Quantity::SpeedRatio { through: Setting::Speed } => x[0] = q * x[1],
            Quantity::SpeedRatio { .. } => x[1] = x[0] / q,
            Quantity::StandoffRatio { diameter } => x[2] = q * diameter,
        }
    }

    /// Its short name: a setting's, `V/U` or `H/D`.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::Setting(s) => s.name(),
            Quantity::SpeedRatio { .. } => "V/U",
            Quantity::StandoffRatio { .. } => "H/D",
        }
    }

    /// The factor from its value to what plots and tables show (mm, mm/s, or 1).
    pub fn shown(self) -> f64 {
        match self {
            Quantity::Setting(s) => s.unit().1,
            _ => 1.0,
        }
    }

    /// An axis's description: the name, its unit, and for a group how it is varied.
    pub fn label(self, at: &Point) -> String {
        match self {
            Quantity::Setting(s) => format!("{} [{}]", s.name(), s.unit().0),
            Quantity::SpeedRatio { through: Setting::Speed } => format!("V/U (speed varied, U = {:.1} mm/s)", at[1] * 1e3),
            Quantity::SpeedRatio { .. } => format!("V/U (extrusion varied, V = {:.1} mm/s)", at[0] * 1e3),
            Quantity::StandoffRatio { diameter } => format!("H/D (standoff varied, D = {:.1} mm)", diameter * 1e3),
        }
    }
}

/// An axis as asked, before the plan's point gives a group's range.
#[derive(Clone, Copy, Debug)]
pub struct AxisSpec {
    /// The name as given, lower case.
    name: Named,
    range: Option<[f64; 2]>,
    n: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Named {
    Setting(Setting),
    SpeedRatio,
    StandoffRatio,
}

/// A map's axis: `n` values of `quantity` from `bounds[0]` to `bounds[1]`.
#[derive(Clone, Copy, Debug)]
pub struct Axis {
    pub quantity: Quantity,
    pub bounds: [f64; 2],
    pub n: usize,
}

impl Axis {
    /// An axis over a setting.
    pub fn setting(s: Setting, bounds: [f64; 2], n: usize) -> Axis {
        Axis { quantity: Quantity::Setting(s), bounds, n }
    }

    pub fn values(&self) -> Vec<f64> {
        let [lo, hi] = self.bounds;
        (0..self.n).map(|k| if self.n == 1 { lo } else { lo + (hi - lo) * k as f64 / (self.n - 1) as f64 }).collect()
    }
}

/// The axes `spec` names ("speed,extrusion", "v/u,h/d", "v/u=0.8:1.5,standoff"), `size` ("3x3")
/// points, checked against the targets: each axis's setting must have bounds.
pub fn parse(spec: &str, size: &str, targets: &Targets) -> Result<[AxisSpec; 2], PlanError> {
    let bad = |why: String| PlanError::Targets(why);
    let parts: Vec<&str> = spec.split(',').map(str::trim).collect();
    let counts: Vec<usize> = size.split('x').map(|s| s.trim().parse::<usize>()).collect::<Result<_, _>>().map_err(|_| bad(format!("--map-size {size}: give the points along each axis as NxM, for example 3x3")))?;
    if parts.len() != 2 || counts.len() != 2 {
        return Err(bad(format!("--map {spec} --map-size {size}: a map has two axes and two counts (speed,extrusion or v/u,h/d, and 3x3)")));
    }
    let mut out = Vec::new();
    for (part, n) in parts.iter().zip(counts) {
        let (name, range) = match part.split_once('=') {
            Some((a, r)) => (a.trim().to_ascii_lowercase(), Some(range_of(r.trim()).ok_or_else(|| bad(format!("--map {part}: give the range as LO:HI with LO < HI, for example v/u=0.8:1.5")))?)),
            None => (part.to_ascii_lowercase(), None),
        };
        let named = match name.as_str() {
            "v/u" => Named::SpeedRatio,
            "h/d" => Named::StandoffRatio,
            s => Named::Setting(Setting::parse(s).ok_or_else(|| bad(format!("--map: unknown axis '{name}'; an axis is speed, extrusion, standoff, v/u or h/d")))?),
        };
        // a range given spans the axis; else the setting's bounds do
        let needs = |s: Setting| match (range, targets.settings.of(s)) {
            (None, None) => Err(bad(format!("--map {name}: settings.{} has no bounds in the targets; the map spans them (or give the axis a range, {name}=LO:HI)", s.name()))),
            _ => Ok(()),
        };
        match named {
            Named::Setting(s) => needs(s)?,
            Named::StandoffRatio => needs(Setting::Standoff)?,
            Named::SpeedRatio if range.is_some() => {}
            Named::SpeedRatio => {
                if targets.settings.speed.is_none() && targets.settings.extrusion.is_none() {
                    return Err(bad("--map v/u: neither settings.speed nor settings.extrusion has bounds in the targets; V/U is varied through one of them within its bounds".into()));
                }
            }
        }
        if n < 2 {
            return Err(bad(format!("--map-size {size}: at least 2 points along each axis")));
        }
        out.push(AxisSpec { name: named, range, n });
    }
    if out[0].name == out[1].name {
        return Err(bad(format!("--map {spec}: the two axes are the same")));
    }
    Ok([out[0], out[1]])
}

/// `LO:HI` with LO < HI, both finite and above 0.
fn range_of(s: &str) -> Option<[f64; 2]> {
    let (a, b) = s.split_once(':')?;
    let (a, b) = (a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?);
    (a.is_finite() && b.is_finite() && 0.0 < a && a < b).then_some([a, b])
}

/// The axes of `specs` around the plan's point `at`, for a nozzle `diameter` [m]: each group
/// through its setting, its range what the bounds allow unless given.
pub fn resolve(specs: [AxisSpec; 2], targets: &Targets, at: &Point, diameter: f64) -> Result<[Axis; 2], PlanError> {
    let bounds = |s: Setting| targets.settings.of(s).expect("parse checked the bounds of an axis without a range");
    let other = |k: usize| specs[1 - k].name;
    let mut axes = Vec::new();
    for (k, spec) in specs.iter().enumerate() {
        let quantity = match spec.name {
            Named::Setting(s) => Quantity::Setting(s),
            Named::StandoffRatio => Quantity::StandoffRatio { diameter },
            Named::SpeedRatio => {
                // the speed with bounds, or without when a range is given and the extrusion has none
                let free = |s: Setting| (targets.settings.of(s).is_some() || spec.range.is_some()) && other(k) != Named::Setting(s);
                let through = if free(Setting::Speed) && (targets.settings.speed.is_some() || targets.settings.extrusion.is_none()) {
                    Setting::Speed
                } else if free(Setting::Extrusion) {
                    Setting::Extrusion
                } else if free(Setting::Speed) {
                    Setting::Speed
                } else {
                    return Err(PlanError::Targets("--map v/u: V/U is varied through the speed or the extrusion speed, and the other axis varies the one with bounds".into()));
                };
                Quantity::SpeedRatio { through }
            }
        };
        let range = match (spec.range, quantity) {
            (Some(r), _) => r,
            (None, Quantity::Setting(s)) => bounds(s),
            (None, Quantity::StandoffRatio { diameter }) => bounds(Setting::Standoff).map(|h| h / diameter),
            (None, Quantity::SpeedRatio { through: Setting::Speed }) => bounds(Setting::Speed).map(|v| v / at[1]),
            (None, Quantity::SpeedRatio { .. }) => {
                let [lo, hi] = bounds(Setting::Extrusion);
                [at[0] / hi, at[0] / lo]
            }
        };
        axes.push(Axis { quantity, bounds: range, n: spec.n });
    }
    if axes[0].quantity.varied() == axes[1].quantity.varied() {
        return Err(PlanError::Targets(format!("--map: {} and {} both vary the {}; a map's axes vary two different settings", axes[0].quantity.name(), axes[1].quantity.name(), axes[0].quantity.varied().name())));
    }
    Ok([axes[0], axes[1]])
}

/// The grid's settings, the first axis fastest, the rest at `at`; refused when a point's varied
/// setting leaves its bounds (a group's range given, or V/U against an extrusion axis).
pub fn points(axes: &[Axis; 2], targets: &Targets, at: &Point) -> Result<Vec<Point>, PlanError> {
    // a setting first, then a group of it: V/U through the speed reads the point's own U
    let order: [usize; 2] = if matches!(axes[1].quantity, Quantity::Setting(_)) { [1, 0] } else { [0, 1] };
    let mut xs = Vec::new();
    for b in axes[1].values() {
        for a in axes[0].values() {
            let q = [a, b];
            let mut x = *at;
            for k in order {
                axes[k].quantity.set(q[k], &mut x);
            }
            for axis in axes {
                let s = axis.quantity.varied();
                // a setting the targets hold has no bounds: a range given spans it freely
                let Some([lo, hi]) = targets.settings.of(s) else { continue };
                let v = x[s.index()];
                let slack = 1e-9 * hi.abs();
                if v < lo - slack || v > hi + slack {
                    let (u, f) = s.unit();
                    return Err(PlanError::Targets(format!(
                        "--map: {} = {:.4} at the point's {} needs a {} of {:.2} {u}, outside settings.{} [{:.2}, {:.2}] {u}; give the axis a range within them ({}=LO:HI)",
                        axis.quantity.name(),
                        axis.quantity.of(&x),
                        held(axis.quantity, &x),
                        s.name(),
                        v * f,
                        s.name(),
                        lo * f,
                        hi * f,
                        axis.quantity.name().to_ascii_lowercase()
                    )));
                }
            }
            xs.push(x);
        }
    }
    Ok(xs)
}

/// What a group holds, for messages.
fn held(q: Quantity, x: &Point) -> String {
    match q {
        Quantity::SpeedRatio { through: Setting::Speed } => format!("extrusion speed {:.2} mm/s", x[1] * 1e3),
        Quantity::SpeedRatio { .. } => format!("speed {:.2} mm/s", x[0] * 1e3),
        Quantity::StandoffRatio { diameter } => format!("nozzle diameter {:.2} mm", diameter * 1e3),
        Quantity::Setting(_) => "settings".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn targets(settings: &str) -> Targets {
        Targets::parse(&format!("[layer]\nwidth = 0.017\nwidth_tolerance = 0.001\nheight = 0.006\nheight_tolerance = 0.0005\n[settings]\n{settings}")).unwrap()
    }

    #[test]
    fn groups_are_varied_through_one_setting_within_its_bounds() {
        let t = targets("speed = [0.05, 0.12]\nextrusion = [0.03, 0.08]\nstandoff = [0.004, 0.008]\n");
        let at = [0.08, 0.05, 0.006];
        let axes = resolve(parse("v/u,H/D", "3x2", &t).unwrap(), &t, &at, 0.012).unwrap();
        assert_eq!(axes[0].quantity, Quantity::SpeedRatio { through: Setting::Speed });
        assert!((axes[0].bounds[0] - 1.0).abs() < 1e-12 && (axes[0].bounds[1] - 2.4).abs() < 1e-12, "{:?}", axes[0].bounds);
        assert!((axes[1].bounds[0] - 1.0 / 3.0).abs() < 1e-12 && (axes[1].bounds[1] - 2.0 / 3.0).abs() < 1e-12);
        let xs = points(&axes, &t, &at).unwrap();
        assert_eq!(xs.len(), 6);
        for (k, x) in xs.iter().enumerate() {
            // U held at the plan's, V = (V/U) U, H = (H/D) D
            let (r, h) = (axes[0].values()[k % 3], axes[1].values()[k / 3]);
            assert_eq!(x[1], 0.05);
            assert!((x[0] / x[1] - r).abs() < 1e-12 && (x[2] / 0.012 - h).abs() < 1e-12, "{x:?}");
            assert!((axes[0].quantity.of(x) - r).abs() < 1e-12);
        }
        // against a speed axis, V/U goes through the extrusion speed, at the point's speed
        let axes = resolve(parse("speed,v/u", "2x2", &t).unwrap(), &t, &at, 0.012).unwrap();
        assert_eq!(axes[1].quantity, Quantity::SpeedRatio { through: Setting::Extrusion });
        let e = points(&axes, &t, &at).unwrap_err().to_string();
        assert!(e.contains("outside settings.extrusion") && e.contains("v/u=LO:HI"), "{e}");
        // a range the bounds forbid is named
        let axes = resolve(parse("v/u=0.5:1.5,standoff", "2x2", &t).unwrap(), &t, &at, 0.012).unwrap();
        let e = points(&axes, &t, &at).unwrap_err().to_string();
        assert!(e.contains("V/U = 0.5000 at the point's extrusion speed 50.00 mm/s needs a speed of 25.00 mm/s, outside settings.speed [50.00, 120.00] mm/s"), "{e}");
    }

    #[test]
    fn an_axis_without_bounds_or_a_setting_twice_is_refused() {
        let t = targets("extrusion = [0.03, 0.08]\n");
        let e = parse("h/d,extrusion", "2x2", &t).unwrap_err().to_string();
        assert!(e.contains("settings.standoff has no bounds") && e.contains("h/d=LO:HI"), "{e}");
        // with a range, a held setting is spanned freely
        let a = resolve(parse("h/d=0.4:0.6,extrusion", "2x2", &t).unwrap(), &t, &[0.08, 0.05, 0.006], 0.012).unwrap();
        let xs = points(&a, &t, &[0.08, 0.05, 0.006]).unwrap();
        assert!((xs[3][2] - 0.0072).abs() < 1e-12 && xs[3][1] == 0.08, "{xs:?}");
        // V/U through the extrusion speed when the speed is held
        let s = parse("v/u,standoff", "2x2", &targets("extrusion = [0.03, 0.08]\nstandoff = [0.004, 0.008]\n")).unwrap();
        let a = resolve(s, &targets("extrusion = [0.03, 0.08]\nstandoff = [0.004, 0.008]\n"), &[0.08, 0.05, 0.006], 0.012).unwrap();
        assert_eq!(a[0].quantity, Quantity::SpeedRatio { through: Setting::Extrusion });
        let e = resolve(parse("v/u,extrusion", "2x2", &t).unwrap(), &t, &[0.08, 0.05, 0.006], 0.012).unwrap_err().to_string();
        assert!(e.contains("V/U is varied through the speed or the extrusion speed"), "{e}");
        let t = targets("standoff = [0.004, 0.008]\nspeed = [0.05, 0.12]\n");
        let e = resolve(parse("h/d,standoff", "2x2", &t).unwrap(), &t, &[0.08, 0.05, 0.006], 0.012).unwrap_err().to_string();
        assert!(e.contains("both vary the standoff"), "{e}");
        for (spec, why) in [("v/u", "two axes"), ("speed,speed", "the same"), ("q,speed", "unknown axis 'q'"), ("v/u=2:1,speed", "LO:HI")] {
            let e = parse(spec, "2x2", &t).unwrap_err().to_string();
            assert!(e.contains(why), "{spec}: {e}");
        }
    }
}
