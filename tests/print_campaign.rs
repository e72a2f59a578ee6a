//! The measurement loop on printed layers (issue 26): the process effects' toolpath keys against
//! central differences, and print campaigns with a hidden effect, synthesised at finer cells than
//! the model runs at, diagnosed from a base model started away from the truth.

use strand::grad::check::check;
use strand::grad::{gradient, GradOptions, Objective};
use strand::scenario::Scenario;

/// A short Newtonian print at 5 mm (tests/grad.rs's), its flow 5 % short of the commanded and
/// its nozzle 0.5 mm high: the process effects' keys away from their nulls.
fn tiny_print() -> String {
    r#"
name = "process-keys"
[simulation]
dx = 0.005
end_time = 0.45
dt = 2e-4
j_bar = false
[domain]
min = [-0.02, -0.04, 0.0]
max = [0.07, 0.04, 0.04]
[boundary]
z_min = "no_slip"
[material]
kind = "newtonian"
density = 2100.0
bulk_modulus = 2.0e5
viscosity = 20.0
[print]
nozzle = { shape = "circle", diameter = 0.012 }
start = [0.0, 0.0, 0.006]
extrusion_factor = 0.95
z_offset = 0.0005
path = [
  { kind = "print", to = [0.05, 0.0, 0.006], speed = 0.0817, extrusion = 0.0503 },
  { kind = "pause", duration = 0.1 },
]
[memory]
budget = "64 MiB"
"#
    .to_string()
}

#[test]
fn the_extrusion_factor_and_the_z_offset_gradients_match_central_differences() {
    let sc = Scenario::parse(&tiny_print()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = GradOptions { ram_bytes: 1 << 30, disk_bytes: 0, disk_dir: dir.path().to_path_buf(), threads: None, schedule: None, until_rest: None };
    let wrt: Vec<String> = ["print.extrusion_factor", "print.z_offset"].iter().map(|s| s.to_string()).collect();
    for name in ["area@0.01", "height@0.01", "width@0.01"] {
        let obj: Objective = name.parse().unwrap();
        let r = gradient(&sc, &obj, &wrt, &opts).unwrap();
        let c = check(&sc, &obj, &r, None, &[1e-2, 1e-3]).unwrap();
        for p in &c.params {
            println!("d {name} / d {} = {:.6e}, central differences {:?}", p.param, p.adjoint, p.central);
            let best = p.central.iter().map(|x| x.2).fold(f64::INFINITY, f64::min);
            assert!(best <= 1e-3, "{name}: {p:?}");
        }
    }
}
