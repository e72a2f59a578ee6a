// Shared scenario text for the integration tests.
#![allow(dead_code)]

/// A small quasi-2D dam break: `threads` workers, `budget` memory.
pub fn dam_break(threads: usize, budget: &str, extra_memory: &str) -> String {
    format!(
        r#"
name = "test-dam-break"
[simulation]
dx = 0.02
end_time = 0.2
threads = {threads}
reorder_interval = 5
[domain]
min = [0.0, 0.0, 0.0]
max = [0.6, 0.16, 0.4]
periodic = [false, true, false]
[material]
kind = "newtonian"
density = 1000.0
bulk_modulus = 2.0e5
viscosity = 1.0
[[body]]
shape = "box"
min = [0.0, 0.0, 0.0]
max = [0.2, 0.16, 0.3]
[memory]
budget = "{budget}"
{extra_memory}
"#
    )
}
