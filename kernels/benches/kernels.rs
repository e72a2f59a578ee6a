//! Criterion benchmarks of the pure compute kernels on one particle block as the solver sees it:
//! a 4^3-cell block at 8 particles per cell (512 particles) and its 6^3-node neighbourhood.
//!
//! Scales are those of the default scenario (paper 000's case 1 at dx = 2.5 mm, dt near its CFL
//! step, printing speeds of a few cm/s); inputs are deterministic, from a small LCG. Every bench
//! reports time per call and particles per second (`Throughput::Elements`). Groups carry the
//! working precision (`f64/...` or `f32/...`), so criterion compares a run against the previous
//! run of the same precision only.
//!
//! Run: `cargo bench -p strand-kernels --bench kernels [--features f32]`.

use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{black_box, criterion_group, criterion_main, BatchSize, BenchmarkGroup, Criterion, Throughput};
use strand_kernels::material::eos::Eos;
use strand_kernels::material::evp_bingham::EvpBingham;
use strand_kernels::material::newtonian::Newtonian;
use strand_kernels::material::bingham::Bingham;
use strand_kernels::material::papanastasiou_roussel::PapanastasiouRoussel;
use strand_kernels::material::{Material, UpdateAdjoint};
use strand_kernels::real::{ddot, dev, r, sym, sym_to_array, Real, M3, NAME, V3};
use strand_kernels::transfer::{g2p_block, p2g_block, G2pOutput, Node, P2gInput, TransferParams, BLOCK_EDGE, NEIGHBOURHOOD_NODES};
use strand_kernels::transfer_adjoint::{g2p_block_adjoint, p2g_block_adjoint, G2pAdjointIn, G2pAdjointOut, P2gAdjoint};

/// First node of the block (any interior block; the kernels only see local offsets).
const ORIGIN: [i32; 3] = [8, 4, 12];
/// Particles per cell, as the solver seeds them.
const PPC: usize = 8;
/// Particles in the block.
const N: usize = BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE * PPC;
/// Grid spacing [m] and step [s] of the default scenario (its CFL step is about 2.7e-5 s).
const DX: f64 = 0.0025;
const DT: f64 = 2.5e-5;
/// Density [kg/m3] of the default scenario's material.
const RHO: f64 = 2100.0;
/// FLIP share of the FLIP variants (the value the adjoint tests use).
const FLIP: f64 = 0.95;

fn tp() -> TransferParams {
    TransferParams { dx: r(DX), dt: r(DT) }
}

/// Knuth's MMIX linear congruential generator; the top 53 bits as a uniform number.
struct Lcg(u64);

impl Lcg {
    fn uniform(&mut self, lo: f64, hi: f64) -> Real {
        self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        r(lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64))
    }

    fn v3(&mut self, a: f64) -> V3 {
        V3::new(self.uniform(-a, a), self.uniform(-a, a), self.uniform(-a, a))
    }

    fn m3(&mut self, a: f64) -> M3 {
        M3::from_cols(self.v3(a), self.v3(a), self.v3(a))
    }
}

/// The particles of one block, in the solver's layout (parallel slices, visited through `order`).
#[derive(Clone)]
struct Block {
    xg: Vec<V3>,
    v: Vec<V3>,
    c: Vec<M3>,
    stress: Vec<M3>,
    mass: Vec<Real>,
    vol0: Vec<Real>,
    j: Vec<Real>,
    order: Vec<u32>,
}

impl Block {
    /// PPC particles per cell at jittered positions whose stencil base is the cell, so all of them
    /// belong to this particle block; stored cell by cell, as after the solver's reorder. Velocity:
    /// a 3 cm/s print speed along x with +-1 cm/s of noise; velocity gradient of +-5 1/s per entry;
    /// stress of a few hundred Pa (the yield stress is 630 Pa) plus the EOS pressure at J.
    fn new(rng: &mut Lcg) -> Self {
        let vol = DX * DX * DX / PPC as f64;
        let mut b = Block { xg: vec![], v: vec![], c: vec![], stress: vec![], mass: vec![], vol0: vec![], j: vec![], order: vec![] };
        for cell in 0..BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE {
            let (ci, cj, ck) = (cell / (BLOCK_EDGE * BLOCK_EDGE), cell / BLOCK_EDGE % BLOCK_EDGE, cell % BLOCK_EDGE);
            let corner = V3::new(
                r((ORIGIN[0] + ci as i32) as f64 + 0.5),
                r((ORIGIN[1] + cj as i32) as f64 + 0.5),
                r((ORIGIN[2] + ck as i32) as f64 + 0.5),
            );
            for _ in 0..PPC {
                // clear of the cell faces, so rounding in f32 cannot move a particle to the next base
                let jitter = V3::new(rng.uniform(0.01, 0.99), rng.uniform(0.01, 0.99), rng.uniform(0.01, 0.99));
                b.xg.push(corner + jitter);
                b.v.push(V3::new(r(0.03), r(0.0), r(0.0)) + rng.v3(0.01));
                b.c.push(rng.m3(5.0));
                let j = rng.uniform(0.99, 1.01);
                let p = r(1.0e6) * (r(1.0) / j - r(1.0));
                b.stress.push(sym(&rng.m3(300.0)) - M3::from_diagonal(V3::splat(p)));
                b.mass.push(r(RHO * vol));
                b.vol0.push(r(vol));
                b.j.push(j);
            }
        }
        b.order = (0..N as u32).collect();
        b
    }

    fn p2g_input(&self) -> P2gInput<'_> {
        P2gInput { xg: &self.xg, v: &self.v, c: &self.c, stress: &self.stress, mass: &self.mass, vol0: &self.vol0, j: &self.j }
    }
}

/// The block neighbourhood after the grid update, as G2P reads it: split P2G of the block, then
/// the solver's node update `[m, old + impulse / m + g dt, old]` with `old` = momentum / m.
fn updated_grid(b: &Block) -> [Node; NEIGHBOURHOOD_NODES] {
    let mut local = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
    p2g_block::<true>(ORIGIN, &b.order, &b.p2g_input(), &tp(), &mut local);
    let gravity = V3::new(r(0.0), r(0.0), r(-9.81));
    for node in local.iter_mut() {
        let m = node[0];
        if m <= r(0.0) {
            *node = [r(0.0); 7];
            continue;
        }
        let old = V3::new(node[1], node[2], node[3]) / m;
        let v = old + V3::new(node[4], node[5], node[6]) / m + gravity * r(DT);
        *node = [m, v.x, v.y, v.z, old.x, old.y, old.z];
    }
    local
}

/// The particle state G2P overwrites in place.
#[derive(Clone)]
struct G2pState {
    xg: Vec<V3>,
    v: Vec<V3>,
    c: Vec<M3>,
    j: Vec<Real>,
}

impl G2pState {
    fn of(b: &Block) -> Self {
        G2pState { xg: b.xg.clone(), v: b.v.clone(), c: b.c.clone(), j: b.j.clone() }
    }

    fn run(&mut self, b: &Block, local: &[Node; NEIGHBOURHOOD_NODES], flip: Real, j_bar: bool) -> Real {
        let mut out = G2pOutput { xg: &mut self.xg, v: &mut self.v, c: &mut self.c, j: &mut self.j };
        g2p_block(ORIGIN, &b.order, local, flip, j_bar.then_some(&b.vol0[..]), &tp(), &mut out)
    }
}

/// The G2P variants: (name, FLIP share, J-bar). The solver's default is APIC with J-bar.
fn g2p_variants() -> [(&'static str, Real, bool); 4] {
    [("apic", r(0.0), false), ("apic_jbar", r(0.0), true), ("flip", r(FLIP), false), ("flip_jbar", r(FLIP), true)]
}

fn group<'a>(c: &'a mut Criterion, name: &str) -> BenchmarkGroup<'a, WallTime> {
    let mut g = c.benchmark_group(format!("{NAME}/{name}"));
    g.throughput(Throughput::Elements(N as u64));
    g
}

fn bench_p2g(c: &mut Criterion) {
    let b = Block::new(&mut Lcg(1));
    let input = b.p2g_input();
    let mut g = group(c, "p2g");
    let mut local = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
    // the solver clears the neighbourhood buffer before each block; so does the benchmark
    g.bench_function("folded", |bench| {
        bench.iter(|| {
            local.iter_mut().for_each(|n| *n = [r(0.0); 7]);
            p2g_block::<false>(black_box(ORIGIN), black_box(&b.order), black_box(&input), black_box(&tp()), &mut local);
            black_box(&local);
        })
    });
    g.bench_function("split", |bench| {
        bench.iter(|| {
            local.iter_mut().for_each(|n| *n = [r(0.0); 7]);
            p2g_block::<true>(black_box(ORIGIN), black_box(&b.order), black_box(&input), black_box(&tp()), &mut local);
            black_box(&local);
        })
    });
    g.finish();
}

fn bench_g2p(c: &mut Criterion) {
    let b = Block::new(&mut Lcg(2));
    let local = updated_grid(&b);
    let start = G2pState::of(&b);
    let mut g = group(c, "g2p");
    for (name, flip, j_bar) in g2p_variants() {
        // G2P moves the particles in place: each call starts from a fresh copy (not timed)
        g.bench_function(name, |bench| {
            bench.iter_batched_ref(
                || start.clone(),
                |s| black_box(s.run(black_box(&b), black_box(&local), flip, j_bar)),
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
}

/// Zeroed adjoint accumulators of P2G's inputs.
struct P2gBars {
    xg: Vec<V3>,
    v: Vec<V3>,
    c: Vec<M3>,
    stress: Vec<M3>,
    mass: Vec<Real>,
    vol0: Vec<Real>,
    jac: Vec<Real>,
    dt: Real,
    dx: Real,
}

impl P2gBars {
    fn new() -> Self {
        P2gBars {
            xg: vec![V3::ZERO; N],
            v: vec![V3::ZERO; N],
            c: vec![M3::ZERO; N],
            stress: vec![M3::ZERO; N],
            mass: vec![r(0.0); N],
            vol0: vec![r(0.0); N],
            jac: vec![r(0.0); N],
            dt: r(0.0),
            dx: r(0.0),
        }
    }

    fn out(&mut self) -> P2gAdjoint<'_> {
        P2gAdjoint {
            xg_bar: &mut self.xg,
            v_bar: &mut self.v,
            c_bar: &mut self.c,
            stress_bar: &mut self.stress,
            mass_bar: &mut self.mass,
            vol0_bar: &mut self.vol0,
            jac_bar: &mut self.jac,
            dt_bar: &mut self.dt,
            dx_bar: &mut self.dx,
        }
    }
}

fn bench_p2g_adjoint(c: &mut Criterion) {
    let mut rng = Lcg(3);
    let b = Block::new(&mut rng);
    let input = b.p2g_input();
    let mut local_bar = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
    for node in local_bar.iter_mut() {
        node.iter_mut().for_each(|x| *x = rng.uniform(-1.0, 1.0));
    }
    // adjoints accumulate (+=) and P2G's adjoint reads only the forward's inputs, so repeated
    // calls need no reset
    let mut bars = P2gBars::new();
    let mut g = group(c, "p2g_adjoint");
    g.bench_function("folded", |bench| {
        bench.iter(|| {
            let (order, p, t) = (black_box(&b.order), black_box(&input), black_box(tp()));
            p2g_block_adjoint::<false>(black_box(ORIGIN), order, p, &t, black_box(&local_bar), &mut bars.out());
        })
    });
    g.bench_function("split", |bench| {
        bench.iter(|| {
            let (order, p, t) = (black_box(&b.order), black_box(&input), black_box(tp()));
            p2g_block_adjoint::<true>(black_box(ORIGIN), order, p, &t, black_box(&local_bar), &mut bars.out());
        })
    });
    black_box((&bars.xg, bars.dt, bars.dx));
    g.finish();
}

fn bench_g2p_adjoint(c: &mut Criterion) {
    let mut rng = Lcg(4);
    let b = Block::new(&mut rng);
    let local = updated_grid(&b);
    // cotangents of G2P's outputs
    let xg_bar: Vec<V3> = (0..N).map(|_| rng.v3(1.0)).collect();
    let v_bar: Vec<V3> = (0..N).map(|_| rng.v3(1.0)).collect();
    let c_bar: Vec<M3> = (0..N).map(|_| rng.m3(1.0)).collect();
    let jac_bar: Vec<Real> = (0..N).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let mut g = group(c, "g2p_adjoint");
    for (name, flip, j_bar) in g2p_variants() {
        // the solver hands the adjoint the forward's v and C when it ran without FLIP
        let mut after = G2pState::of(&b);
        after.run(&b, &local, flip, j_bar);
        let inp = G2pAdjointIn {
            local: &local,
            xg: &b.xg,
            v: &b.v,
            j: &b.j,
            forward: (flip == r(0.0)).then_some((&after.v[..], &after.c[..])),
            xg_bar: &xg_bar,
            v_bar: &v_bar,
            c_bar: &c_bar,
            jac_bar: &jac_bar,
        };
        let mut local_out = [[r(0.0); 7]; NEIGHBOURHOOD_NODES];
        let (mut xg_out, mut v_out) = (vec![V3::ZERO; N], vec![V3::ZERO; N]);
        let (mut jac_out, mut vol0_out) = (vec![r(0.0); N], vec![r(0.0); N]);
        let (mut dt_out, mut dx_out) = (r(0.0), r(0.0));
        g.bench_function(name, |bench| {
            bench.iter(|| {
                let mut out = G2pAdjointOut {
                    local_bar: &mut local_out,
                    xg_bar: &mut xg_out,
                    v_bar: &mut v_out,
                    jac_bar: &mut jac_out,
                    vol0_bar: &mut vol0_out,
                    dt_bar: &mut dt_out,
                    dx_bar: &mut dx_out,
                };
                let vol0 = j_bar.then_some(&b.vol0[..]);
                g2p_block_adjoint(black_box(ORIGIN), black_box(&b.order), flip, vol0, black_box(&tp()), black_box(&inp), &mut out);
            })
        });
        black_box((&local_out, &xg_out, dt_out, dx_out));
    }
    g.finish();
}

/// The default scenario's material (paper 000 case 1): tau0 630 Pa, eta 7.5 Pa s, K 1 MPa,
/// nu 0.3, no thixotropy, linear EOS.
fn evp_bingham(n: f64) -> EvpBingham {
    EvpBingham {
        density: RHO,
        bulk_modulus: 1.0e6,
        shear_modulus: None,
        poisson_ratio: Some(0.3),
        viscosity: 7.5,
        yield_stress: 630.0,
        a_thix: 0.0,
        alpha: 0.0,
        lambda0: 0.0,
        maxwell_modulus: None,
        maxwell_time: 1.0,
        flow_index: n,
        eos: Eos::Linear,
        bulk_modulus_rate: None,
        bulk_modulus_late_rate: None,
        bulk_modulus_transition_age: None,
        age_at_start: None,
        max_age: None,
    }
}

/// 000's material as the bi-viscous Bingham fluid (gamma_c = 0.01 /s), and as the
/// Papanastasiou-Roussel fluid (m = 10 s, no thixotropy), with flow index n.
fn bingham(n: f64) -> Bingham {
    Bingham { density: RHO, bulk_modulus: 1.0e6, viscosity: 7.5, yield_stress: 630.0, critical_shear_rate: 0.01, flow_index: n, eos: Eos::Linear }
}

fn papanastasiou_roussel(n: f64) -> PapanastasiouRoussel {
    PapanastasiouRoussel {
        density: RHO, bulk_modulus: 1.0e6, viscosity: 7.5, yield_stress: 630.0, papanastasiou_m: 10.0,
        a_thix: 0.0, alpha: 0.0, lambda0: 0.0, lambda_max: None, flow_index: n, eos: Eos::Linear,
    }
}

/// The peer scene's J-fluid: inviscid, linear EOS with K = E = 400.
fn j_fluid() -> Newtonian {
    Newtonian { density: 1000.0, bulk_modulus: 400.0, viscosity: 0.0, eos: Eos::Linear }
}

/// Per-particle input of a material update: velocity gradient, J, and the state before it. The
/// EVP state is a deviatoric stress with tau = sqrt(J2) between 0.5 and 1.2 tau0, so with the
/// +-5 1/s gradients some particles stay elastic and the others take the return map.
struct MaterialInput {
    grad_v: Vec<M3>,
    j: Vec<Real>,
    state: Vec<Real>,
}

fn material_input(m: &dyn Material, rng: &mut Lcg) -> MaterialInput {
    let sl = m.state_names().len();
    let b = Block::new(rng);
    let mut state = vec![r(0.0); N * sl];
    for p in 0..N {
        let st = &mut state[p * sl..(p + 1) * sl];
        m.init_state(st);
        if sl == 8 {
            let s = dev(&sym(&rng.m3(1.0)));
            let tau = (r(0.5) * ddot(&s, &s)).sqrt();
            let s = s * (rng.uniform(0.5, 1.2) * r(630.0) / tau);
            st[..6].copy_from_slice(&sym_to_array(&s));
            st[7] = rng.uniform(0.0, 1.0);
        }
    }
    MaterialInput { grad_v: b.c, j: b.j, state }
}

fn bench_material(c: &mut Criterion, label: &str, m: &dyn Material, seed: u64) {
    let mut rng = Lcg(seed);
    let inp = material_input(m, &mut rng);
    let (sl, np) = (m.state_names().len(), m.param_names().len());
    let dt = r(DT);
    let mut stress = vec![M3::ZERO; N];
    if sl == 8 {
        let mut st = inp.state.clone();
        m.update_batch(&inp.grad_v, &inp.j, dt, &mut st, &mut stress);
        let plastic = (0..N).filter(|&p| st[p * sl + 7] > inp.state[p * sl + 7]).count();
        eprintln!("{label}: {plastic} of {N} particles take the plastic branch");
    }
    let mut g = group(c, "material");
    // the update overwrites the state: each call starts from a fresh copy (not timed)
    g.bench_function(format!("{label}_update"), |bench| {
        bench.iter_batched_ref(
            || inp.state.clone(),
            |st| {
                m.update_batch(black_box(&inp.grad_v), black_box(&inp.j), black_box(dt), st, &mut stress);
                black_box(&stress);
            },
            BatchSize::SmallInput,
        )
    });
    // the solver's loop of the backward pass: one dynamic call per particle, parameter adjoints
    // into a per-particle array summed in f64
    let stress_bar: Vec<M3> = (0..N).map(|_| rng.m3(1.0)).collect();
    let state_out_bar: Vec<Real> = (0..N * sl).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let mut grad_v_bar = vec![M3::ZERO; N];
    let mut j_bar = vec![r(0.0); N];
    let mut state_bar = vec![r(0.0); N * sl];
    let mut params_total = [0.0f64; 8];
    g.bench_function(format!("{label}_adjoint"), |bench| {
        bench.iter(|| {
            for p in 0..N {
                let mut params = [r(0.0); 8];
                let mut adj = UpdateAdjoint {
                    grad_v_bar: &mut grad_v_bar[p],
                    j_bar: &mut j_bar[p],
                    state_bar: &mut state_bar[p * sl..(p + 1) * sl],
                    params_bar: &mut params[..np],
                };
                m.update_adjoint(
                    black_box(&inp.grad_v[p]),
                    inp.j[p],
                    dt,
                    &inp.state[p * sl..(p + 1) * sl],
                    &stress_bar[p],
                    &state_out_bar[p * sl..(p + 1) * sl],
                    &mut adj,
                );
                // a no-op cast in f64, a widening one in f32
                #[allow(clippy::unnecessary_cast)]
                for (a, v) in params_total.iter_mut().zip(&params[..np]) {
                    *a += *v as f64;
                }
            }
        })
    });
    black_box((&grad_v_bar, &j_bar, &state_bar, params_total));
    g.finish();
}

fn bench_materials(c: &mut Criterion) {
    bench_material(c, "evp_bingham", &evp_bingham(1.0), 5);
    bench_material(c, "bingham", &bingham(1.0), 7);
    bench_material(c, "papanastasiou_roussel", &papanastasiou_roussel(1.0), 8);
    // Herschel-Bulkley, n = 0.6: a powf per update, and the EVP's Newton return map
    bench_material(c, "evp_bingham_hb", &evp_bingham(0.6), 5);
    bench_material(c, "bingham_hb", &bingham(0.6), 7);
    bench_material(c, "papanastasiou_roussel_hb", &papanastasiou_roussel(0.6), 8);
    bench_material(c, "newtonian_jfluid", &j_fluid(), 6);
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500));
    targets = bench_p2g, bench_g2p, bench_p2g_adjoint, bench_g2p_adjoint, bench_materials
}
criterion_main!(benches);
