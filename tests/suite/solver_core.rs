//! Solver-core properties: bit-identical results for any thread count, clean failures for budgets and pools that are too small, and blow-up reports.

use crate::common;

use strand::scenario::Scenario;
use strand::solver::Simulation;

fn sim(threads: usize) -> Simulation {
    let sc = Scenario::parse(&common::dam_break(threads, "256 MiB", "")).unwrap();
    Simulation::new(&sc).unwrap()
}

fn state_bytes(s: &Simulation) -> Vec<u8> {
    let p = &s.particles;
    let n = p.n;
    let mut out = Vec::new();
    out.extend_from_slice(bytemuck::cast_slice(&p.xg.as_slice()[..n]));
    out.extend_from_slice(bytemuck::cast_slice(&p.v.as_slice()[..n]));
    out.extend_from_slice(bytemuck::cast_slice(&p.c.as_slice()[..n]));
    out.extend_from_slice(bytemuck::cast_slice(&p.stress.as_slice()[..n]));
    out.extend_from_slice(bytemuck::cast_slice(&p.j.as_slice()[..n]));
    out.extend_from_slice(bytemuck::cast_slice(&p.id.as_slice()[..n]));
    out
}

#[test]
fn one_and_two_threads_are_bit_identical() {
    let mut a = sim(1);
    let mut b = sim(2);
    assert_eq!(b.threads(), 2);
    for _ in 0..60 {
        a.step_until(1.0).unwrap();
        b.step_until(1.0).unwrap();
    }
    assert!(a.vmax > 0.1, "the column must be moving: vmax {}", a.vmax);
    assert_eq!(a.time.to_bits(), b.time.to_bits());
    assert!(state_bytes(&a) == state_bytes(&b), "1- and 2-thread states differ");
    // and a three-thread team too
    let mut c = {
        let sc = Scenario::parse(&common::dam_break(3, "256 MiB", "")).unwrap();
        Simulation::new(&sc).unwrap()
    };
    for _ in 0..60 {
        c.step_until(1.0).unwrap();
    }
    assert!(state_bytes(&a) == state_bytes(&c), "1- and 3-thread states differ");
}

#[test]
fn budget_too_small_fails_at_start_listing_pools() {
    let sc = Scenario::parse(&common::dam_break(1, "1 MiB", "")).unwrap();
    // refused by the plan's lower bound (solver::preflight: the particles and the grid) before
    // anything is counted or allocated
    let e = Simulation::new(&sc).err().expect("must not fit").to_string();
    for pool in ["particles.x", "particles.stress", "grid.nodes", "grid.table", "budget"] {
        assert!(e.contains(pool), "message lacks {pool}: {e}");
    }
}

#[test]
fn particle_pool_too_small_names_the_pool() {
    let sc = Scenario::parse(&common::dam_break(1, "256 MiB", "max_particles = 100")).unwrap();
    let e = Simulation::new(&sc).err().expect("pool too small").to_string();
    assert!(e.contains("particles") && e.contains("max_particles") && e.contains("100"), "{e}");
}

#[test]
fn running_out_of_blocks_mid_run_is_an_error_naming_the_pool() {
    // enough blocks for the column at rest, not for the spreading flow
    let sc = Scenario::parse(&common::dam_break(1, "256 MiB", "max_blocks = 60")).unwrap();
    let mut s = Simulation::new(&sc).unwrap();
    let mut err = None;
    for _ in 0..2000 {
        if let Err(e) = s.step_until(1.0) {
            err = Some(e.to_string());
            break;
        }
    }
    let e = err.expect("the flow must outgrow 60 blocks");
    assert!(e.contains("grid blocks") && e.contains("max_blocks"), "{e}");
}

#[test]
fn blow_up_names_step_particle_and_field() {
    let text = common::dam_break(1, "256 MiB", "").replace("reorder_interval = 5", "reorder_interval = 5\ndt = 0.05");
    let sc = Scenario::parse(&text).unwrap();
    let mut s = Simulation::new(&sc).unwrap();
    let mut err = None;
    for _ in 0..200 {
        if let Err(e) = s.step_until(100.0) {
            err = Some(e.to_string());
            break;
        }
    }
    let e = err.expect("a step 100x the CFL bound must blow up");
    assert!(e.contains("blow-up at step") && e.contains("particle") && (e.contains("velocity") || e.contains("stress") || e.contains("J")), "{e}");
}

#[test]
fn scenario_errors_name_the_key() {
    let bad_key = common::dam_break(1, "256 MiB", "").replace("viscosity = 1.0", "viscosty = 1.0");
    // unknown material keys are caught when the material is built
    let msg = match Scenario::parse(&bad_key) {
        Err(e) => e.to_string(),
        Ok(sc) => Simulation::new(&sc).err().expect("unknown key must fail").to_string(),
    };
    assert!(msg.contains("viscosty"), "{msg}");

    let unknown_top = common::dam_break(1, "256 MiB", "").replace("[simulation]", "[simulation]\nfoo = 1");
    let msg = Scenario::parse(&unknown_top).expect_err("unknown key").to_string();
    assert!(msg.contains("foo"), "{msg}");

    let bad_dx = common::dam_break(1, "256 MiB", "").replace("dx = 0.02", "dx = -0.02");
    let msg = Scenario::parse(&bad_dx).expect_err("negative dx").to_string();
    assert!(msg.contains("simulation.dx"), "{msg}");

    let bad_budget = common::dam_break(1, "lots", "");
    let msg = Scenario::parse(&bad_budget).expect_err("bad budget").to_string();
    assert!(msg.contains("memory.budget"), "{msg}");

    let bad_mat = common::dam_break(1, "256 MiB", "").replace("viscosity = 1.0", "viscosity = -1.0");
    let sc = Scenario::parse(&bad_mat).unwrap();
    let msg = Simulation::new(&sc).err().expect("negative viscosity").to_string();
    assert!(msg.contains("viscosity"), "{msg}");
}

#[test]
fn file_backed_pools_give_the_same_result() {
    let dir = tempfile::tempdir().unwrap();
    let extra = format!("dir = {:?}", dir.path().to_str().unwrap());
    let sc = Scenario::parse(&common::dam_break(2, "256 MiB", &extra)).unwrap();
    let mut f = Simulation::new(&sc).unwrap();
    let mut a = sim(2);
    for _ in 0..20 {
        a.step_until(1.0).unwrap();
        f.step_until(1.0).unwrap();
    }
    assert!(state_bytes(&a) == state_bytes(&f));
    assert!(dir.path().join("particles_x.pool").exists());
}

#[test]
fn material_dropped_on_a_platform_rests_on_it() {
    // a block falls onto a raised platform of the given kind and must come to rest on its top
    for kind in ["\"no_slip\"", "\"free_slip\"", "{ friction = { mu = 0.5 } }"] {
        let text = common::dam_break(2, "256 MiB", "")
            .replace("max = [0.2, 0.16, 0.3]", "max = [0.2, 0.16, 0.35]")
            .replace("min = [0.0, 0.0, 0.0]\nmax = [0.2", "min = [0.0, 0.0, 0.2]\nmax = [0.2")
            .replace("[material]", &format!("[boundary.platform]\nz = 0.1\nxy_min = [0.0, 0.0]\nxy_max = [0.6, 0.16]\nkind = {kind}\n\n[material]"));
        let mut s = Simulation::new(&Scenario::parse(&text).unwrap()).unwrap();
        while s.time < 0.3 {
            s.step_until(0.3).unwrap();
        }
        let zmin = (0..s.particles.n).map(|i| s.position(i)[2]).fold(f64::INFINITY, f64::min);
        assert!((0.1 - 1e-9..0.12).contains(&zmin), "{kind}: lowest particle at {zmin}, platform at 0.1");
    }
}
