//! Why a material's parameters are refused. Every message names the scenario key, the rule and
//! the value found, so the caller can pass it to the user unchanged.

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// A value outside its range; `range` is the rule in words ("> 0", "in (-1, 0.5)").
    #[error("{key} must be {range}, got {value}")]
    OutOfRange { key: String, range: String, value: f64 },
    /// A rule that holds only when another key has a given value.
    #[error("{key} {rule} when {when}: {why}")]
    Conditional { key: &'static str, rule: &'static str, when: &'static str, why: &'static str },
    /// Two keys that say the same thing, both given.
    #[error("{table}: give either {first} or {second}, not both")]
    BothGiven { table: String, first: &'static str, second: &'static str },
    /// Two keys of which one is required, neither given.
    #[error("{table}: one of {first} or {second} is required")]
    NeitherGiven { table: String, first: &'static str, second: &'static str },
    /// A frictional material with neither friction nor cohesion: it cannot carry any shear.
    #[error("material: friction_angle_deg and cohesion are both 0, so the material has no shear strength")]
    NoShearStrength,
}

impl MaterialError {
    pub fn out_of_range(key: impl Into<String>, range: impl Into<String>, value: f64) -> Self {
        MaterialError::OutOfRange { key: key.into(), range: range.into(), value }
    }
}
