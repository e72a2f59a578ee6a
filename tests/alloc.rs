//! The step loop allocates nothing on the heap. Its own test binary with a single test, because
//! the counting allocator sees every thread of the process.

#[path = "suite/common.rs"]
mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Counts heap allocations on every thread while `COUNTING` is set.
struct CountingAlloc;
static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        System.realloc(p, l, n)
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

use strand::scenario::Scenario;
use strand::solver::Simulation;

#[test]
fn a_step_allocates_nothing() {
    // the counter must see allocations, or this test could not fail
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    let v: Vec<u64> = std::hint::black_box(vec![1, 2, 3]);
    COUNTING.store(false, Ordering::SeqCst);
    assert!(ALLOCS.load(Ordering::SeqCst) >= 1 && v.len() == 3);

    for (threads, kind) in [(1, "newtonian"), (2, "newtonian"), (2, "evp"), (2, "solids")] {
        let mut text = common::dam_break(threads, "256 MiB", "");
        if kind == "evp" {
            text = text.replace("kind = \"newtonian\"", "kind = \"evp_bingham\"\nyield_stress = 10.0\npoisson_ratio = 0.3");
        }
        if kind == "solids" {
            // issue 30: a rebar, a sloped wall and a gate that opens during the counted steps
            text = text.replace("[memory]", "[[solid]]\nshape = \"cylinder\"\nfrom = [0.3, -1.0, 0.05]\nto = [0.3, 1.0, 0.05]\nradius = 0.01\ncontact = { friction = { mu = 0.4 } }\n\
                [[solid]]\nshape = \"union\"\nparts = [{ shape = \"half_space\", point = [0.0, 0.0, 0.01], normal = [-0.1, 0.0, 1.0] }]\ncontact = \"free_slip\"\n\
                [[solid]]\nshape = \"box\"\nmin = [0.2, -1.0, -1.0]\nmax = [0.22, 1.0, 1.0]\nopen_at = 0.005\n[memory]");
        }
        let mut s = Simulation::new(&Scenario::parse(&text).unwrap()).unwrap();
        s.step_until(1.0).unwrap(); // first step outside the count: lazily initialised statics
        ALLOCS.store(0, Ordering::SeqCst);
        COUNTING.store(true, Ordering::SeqCst);
        for _ in 0..20 {
            s.step_until(1.0).unwrap();
        }
        COUNTING.store(false, Ordering::SeqCst);
        let n = ALLOCS.load(Ordering::SeqCst);
        assert_eq!(n, 0, "{n} heap allocations in 20 steps ({kind}, {threads} threads)");
        assert_eq!(s.step, 21);
    }

    // printing: the emitter thread recycles its slab buffers, and sleeping moves particles in
    // place; 0.3 s of the second layer cover emission, sleeping, waking and reordering
    let mut s = Simulation::new(&Scenario::parse(&common::tiny_print(2, 2, true, "256 MiB")).unwrap()).unwrap();
    while s.time < 1.4 {
        s.step_until(1.4).unwrap();
    }
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    let n0 = s.particles.n;
    while s.time < 1.7 {
        s.step_until(1.7).unwrap();
    }
    COUNTING.store(false, Ordering::SeqCst);
    let n = ALLOCS.load(Ordering::SeqCst);
    assert!(s.particles.n > n0, "no emission during the counted steps");
    assert!(s.particles.n_sleep > 0, "nothing asleep during the counted steps");
    assert_eq!(n, 0, "{n} heap allocations in 0.3 s of printing");
}
