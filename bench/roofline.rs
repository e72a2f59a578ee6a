//! This machine's two roofline limits, for `make bench-roofline` (bench/roofline.sh):
//! memory bandwidth (a STREAM triad `a = b + s c` over arrays far larger than the caches, on
//! 1 and 2 threads) and peak arithmetic (independent chains of multiplies and adds, scalar and
//! 128/256/512-bit SIMD, f64 and f32, on one thread; FMA is left out because strand's kernels
//! never contract a multiply and an add, which keeps their IEEE bits).
//!
//! Built by rustc alone (no crate): `rustc -C opt-level=3 bench/roofline.rs`. Every figure is
//! the best of several repeats, since other work on a shared machine only ever slows a run.
//! Prints `key value` lines.
use std::arch::x86_64::*;
use std::hint::black_box;
use std::time::Instant;

const TRIAD_LEN: usize = 1 << 25; // 3 arrays of 256 MiB of f64: no cache holds them
const REPEATS: usize = 5;

/// Best seconds of `REPEATS` calls of `f`.
fn best(mut f: impl FnMut()) -> f64 {
    (0..REPEATS)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// STREAM triad bandwidth in bytes/s on `threads` threads, counting 24 bytes per element as
/// STREAM does (the write-allocate read of `a` is not counted).
fn triad(threads: usize) -> f64 {
    let mut a = vec![0.0f64; TRIAD_LEN];
    let b = vec![1.0f64; TRIAD_LEN];
    let c = vec![2.0f64; TRIAD_LEN];
    let s = black_box(3.0);
    let chunk = TRIAD_LEN / threads;
    let secs = best(|| {
        std::thread::scope(|sc| {
            for ((a, b), c) in a.chunks_mut(chunk).zip(b.chunks(chunk)).zip(c.chunks(chunk)) {
                sc.spawn(move || {
                    for i in 0..a.len() {
                        a[i] = b[i] + s * c[i];
                    }
                });
            }
        });
        black_box(&a);
    });
    24.0 * TRIAD_LEN as f64 / secs
}

const ITERS: usize = 20_000_000;

/// Peak of one SIMD width: 7 chains of multiplies and 7 of adds, independent, so latency never
/// binds; flops counted per lane. `$mul`/`$add`/`$set` are the width's intrinsics.
macro_rules! peak {
    ($name:ident, $feat:literal, $t:ty, $lanes:expr, $set:ident, $mul:ident, $add:ident, $x:ty) => {
        #[target_feature(enable = $feat)]
        unsafe fn $name() -> f64 {
            let m = $set(black_box(1.0 as $t));
            let z = $set(black_box(0.0 as $t));
            let secs = best(|| {
                let mut p: [$x; 7] = [$set(1.0 as $t); 7];
                let mut q: [$x; 7] = [$set(1.0 as $t); 7];
                for _ in 0..ITERS {
                    for k in 0..7 {
                        p[k] = $mul(p[k], m);
                        q[k] = $add(q[k], z);
                    }
                }
                black_box((p, q));
            });
            14.0 * $lanes as f64 * ITERS as f64 / secs
        }
    };
}
peak!(f64_scalar, "sse2", f64, 1, _mm_set1_pd, _mm_mul_sd, _mm_add_sd, __m128d);
peak!(f64_sse2, "sse2", f64, 2, _mm_set1_pd, _mm_mul_pd, _mm_add_pd, __m128d);
peak!(f64_avx2, "avx2", f64, 4, _mm256_set1_pd, _mm256_mul_pd, _mm256_add_pd, __m256d);
peak!(f64_avx512, "avx512f", f64, 8, _mm512_set1_pd, _mm512_mul_pd, _mm512_add_pd, __m512d);
peak!(f32_scalar, "sse2", f32, 1, _mm_set1_ps, _mm_mul_ss, _mm_add_ss, __m128);
peak!(f32_sse2, "sse2", f32, 4, _mm_set1_ps, _mm_mul_ps, _mm_add_ps, __m128);
peak!(f32_avx2, "avx2", f32, 8, _mm256_set1_ps, _mm256_mul_ps, _mm256_add_ps, __m256);
peak!(f32_avx512, "avx512f", f32, 16, _mm512_set1_ps, _mm512_mul_ps, _mm512_add_ps, __m512);

fn main() {
    for t in [1, 2] {
        println!("triad_bytes_per_s_t{t} {:.4e}", triad(t));
    }
    let avx2 = is_x86_feature_detected!("avx2");
    let avx512 = is_x86_feature_detected!("avx512f");
    type Peak = unsafe fn() -> f64;
    let runs: [(&str, bool, Peak); 8] = [
        ("f64_scalar", true, f64_scalar),
        ("f64_sse2", true, f64_sse2),
        ("f64_avx2", avx2, f64_avx2),
        ("f64_avx512", avx512, f64_avx512),
        ("f32_scalar", true, f32_scalar),
        ("f32_sse2", true, f32_sse2),
        ("f32_avx2", avx2, f32_avx2),
        ("f32_avx512", avx512, f32_avx512),
    ];
    for (name, present, f) in runs {
        if present {
            // SAFETY: the CPU has the feature the function is compiled for (checked above)
            println!("flops_per_s_{name} {:.4e}", unsafe { f() });
        } else {
            println!("flops_per_s_{name} absent");
        }
    }
}
