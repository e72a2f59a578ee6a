//! A parameter's key, parsed once: `TABLE.FIELD`, the table a scenario's (`material`,
//! `simulation`, `body`, `boundary`, `print`) or, in a measurement model, an effect's
//! (`thixotropy.a_thix`), the field the rest of the path, its parts naming tables and indexing
//! arrays (`boundary.z_min.friction.mu`, `print.path.3.speed`, `body.0.velocity.z`).
//!
//! The gradient driver (`grad/params.rs`) resolves a key to the simulation's parameter it names,
//! the measurement model (`measure/model.rs`) to a material number or an effect's parameter,
//! with its bounds and unit; both read the key through this one type.

use std::fmt;

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Key {
    text: String,
    /// Where the table's name ends.
    dot: usize,
}

impl Key {
    /// The key of `text`, which names a table and a field, each part non-empty.
    pub fn parse(text: &str) -> Result<Key, String> {
        match text.find('.') {
            Some(dot) if !text.split('.').any(str::is_empty) => Ok(Key { text: text.to_string(), dot }),
            _ => Err(format!("'{text}' is not a parameter key (TABLE.FIELD, as material.yield_stress)")),
        }
    }

    /// The table: a scenario's, or an effect's name.
    pub fn table(&self) -> &str {
        &self.text[..self.dot]
    }

    /// The path within the table (`yield_stress`, `z_min.friction.mu`).
    pub fn field(&self) -> &str {
        &self.text[self.dot + 1..]
    }

    /// Every part of the path, the table first.
    pub fn parts(&self) -> impl Iterator<Item = &str> {
        self.text.split('.')
    }

    pub fn as_str(&self) -> &str {
        &self.text
    }
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::Key;

    #[test]
    fn a_key_names_its_table_and_field_and_refuses_an_empty_part() {
        let k = Key::parse("boundary.z_min.friction.mu").unwrap();
        assert_eq!((k.table(), k.field()), ("boundary", "z_min.friction.mu"));
        assert_eq!(k.parts().collect::<Vec<_>>(), ["boundary", "z_min", "friction", "mu"]);
        for bad in ["yield_stress", "material.", ".mu", "a..b", ""] {
            assert!(Key::parse(bad).unwrap_err().contains("not a parameter key"), "{bad}");
        }
    }
}
