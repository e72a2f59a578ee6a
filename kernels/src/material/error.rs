//! Why a material's parameters are refused. Every message names the scenario key, the rule and
//! the value found, so the caller can pass it to the user unchanged.

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// A value outside its range; `range` is the rule in words ("> 0", "in (-1, 0.5)").
    #[error("{key} must be {range}, got {value}")]
    OutOfRange { key: String, range: String, value: f64 },
    /// A value out of its range only when another key has a given value.
    #[error("{key} must be {range} when {when} ({reason})")]
    OutOfRangeWhen { key: &'static str, range: &'static str, when: &'static str, reason: &'static str },
    /// A key required only when another key has a given value.
    #[error("{key} is required when {when}: {reason}")]
    RequiredWhen { key: &'static str, when: &'static str, reason: &'static str },
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

#[cfg(test)]
mod tests {
    use super::MaterialError;

    /// The messages are the ones users have always read, word for word.
    #[test]
    fn messages_name_the_key_the_rule_and_the_value() {
        assert_eq!(MaterialError::out_of_range("material.density", "> 0", -1.0).to_string(), "material.density must be > 0, got -1");
        let yield_stress = MaterialError::OutOfRangeWhen { key: "material.yield_stress", range: "> 0", when: "material.a_thix > 0", reason: "eq. 22 divides by it" };
        assert_eq!(yield_stress.to_string(), "material.yield_stress must be > 0 when material.a_thix > 0 (eq. 22 divides by it)");
        let both = MaterialError::BothGiven { table: "material".into(), first: "shear_modulus", second: "poisson_ratio" };
        assert_eq!(both.to_string(), "material: give either shear_modulus or poisson_ratio, not both");
        let neither = MaterialError::NeitherGiven { table: "material".into(), first: "shear_modulus", second: "poisson_ratio" };
        assert_eq!(neither.to_string(), "material: one of shear_modulus or poisson_ratio is required");
    }
}
