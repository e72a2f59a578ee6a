//! Runtime CPU-feature dispatch of the hot kernels: one binary, built for the baseline x86-64
//! (SSE2), runs P2G, G2P, their adjoints and the hottest material updates through copies compiled
//! for AVX2 where the CPU has it.
//!
//! The rule that keeps results bit-identical whichever copy runs: only features that change the
//! instructions, never the arithmetic. AVX2 (with the VEX encodings and SSE4.1's `roundsd` it
//! implies) performs the same IEEE-754 operations in the same order; FMA is not enabled, and Rust
//! never contracts a multiply and an add on its own, so no rounding moves. The tests of
//! `transfer.rs`, `transfer_adjoint_lanes.rs` and the materials compare the copies bit for bit.

/// Whether this CPU runs the AVX2 copies (std caches the CPUID answer after the first call).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// The node register of the AVX2 copies of P2G and G2P: f64 has no SIMD vector of three in glam,
/// so one 256-bit register holds a node's mass and momentum (P2G) or three velocity channels and
/// a padding lane (G2P); see [`crate::transfer::NodeLanes`]. Only ever built inside the AVX2
/// copies, which is where its intrinsics inline.
#[cfg(all(target_arch = "x86_64", not(feature = "f32")))]
#[derive(Clone, Copy)]
pub struct AvxLanes(std::arch::x86_64::__m256d);

/// The node register of P2G in f32: glam's `Vec3A` is one SSE register too, but P2G adds its mass
/// and momentum to a node as four scalars; this register adds channels 0..4 at once. SSE is part
/// of the baseline x86-64, so every copy can use it; see [`crate::transfer::NodeLanes`].
#[cfg(all(target_arch = "x86_64", feature = "f32"))]
#[derive(Clone, Copy)]
pub struct SseLanes(std::arch::x86_64::__m128);

/// A node register wrapping one SIMD value of four lanes, from its intrinsics: the
/// [`NodeLanes`](crate::transfer::NodeLanes) impl (a node's channels `CH..CH + 4` in one load, the
/// last three by `$rotate`-ing the four that end there down one lane; P2G's mass in lane 0, so a
/// node's channels 0..4 take one add) and the lane-by-lane add, subtract and multiply by a
/// broadcast scalar, the same IEEE operations as glam's vectors.
#[cfg(target_arch = "x86_64")]
macro_rules! node_register {
    ($lanes:ident, $zero:ident, $load:ident, $store:ident, $setr:ident, $add:ident, $sub:ident, $mul:ident, $splat:ident, |$x:ident| $rotate:expr) => {
        use super::$lanes;
        use crate::real::{Real, V3};
        use crate::transfer::{Node, NodeLanes};
        use std::arch::x86_64::*;

        // SAFETY (every intrinsic below): the register exists only in copies compiled for, and
        // run on, CPUs with its instructions; the loads and stores stay inside the node.
        impl NodeLanes for $lanes {
            #[inline(always)]
            fn zero() -> Self {
                $lanes(unsafe { $zero() })
            }
            #[inline(always)]
            fn node<const CH: usize>(n: &Node) -> Self {
                if CH + 4 <= n.len() {
                    $lanes(unsafe { $load(n.as_ptr().add(CH)) })
                } else {
                    let $x = unsafe { $load(n.as_ptr().add(n.len() - 4)) };
                    $lanes(unsafe { $rotate })
                }
            }
            #[inline(always)]
            fn v3(self) -> V3 {
                let mut a = [0.0; 4];
                unsafe { $store(a.as_mut_ptr(), self.0) };
                V3::new(a[0], a[1], a[2])
            }
            #[inline(always)]
            fn mass_momentum(m: Real, q: V3) -> Self {
                $lanes(unsafe { $setr(m, q.x, q.y, q.z) })
            }
            #[inline(always)]
            fn slope(col: V3) -> Self {
                $lanes(unsafe { $setr(0.0, col.x, col.y, col.z) })
            }
            #[inline(always)]
            fn scatter(self, node: &mut Node, weight: Real, _: Real) {
                let add = self * weight;
                unsafe { $store(node.as_mut_ptr(), $add($load(node.as_ptr()), add.0)) };
            }
        }

        impl std::ops::Add for $lanes {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                $lanes(unsafe { $add(self.0, o.0) })
            }
        }
        impl std::ops::Sub for $lanes {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                $lanes(unsafe { $sub(self.0, o.0) })
            }
        }
        impl std::ops::Mul<Real> for $lanes {
            type Output = Self;
            #[inline(always)]
            fn mul(self, s: Real) -> Self {
                $lanes(unsafe { $mul(self.0, $splat(s)) })
            }
        }
        impl std::ops::AddAssign for $lanes {
            #[inline(always)]
            fn add_assign(&mut self, o: Self) {
                *self = *self + o;
            }
        }
        impl std::ops::SubAssign for $lanes {
            #[inline(always)]
            fn sub_assign(&mut self, o: Self) {
                *self = *self - o;
            }
        }
    };
}

#[cfg(all(target_arch = "x86_64", not(feature = "f32")))]
mod avx_lanes {
    node_register!(AvxLanes, _mm256_setzero_pd, _mm256_loadu_pd, _mm256_storeu_pd, _mm256_setr_pd, _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_set1_pd, |x| _mm256_permute4x64_pd::<0b00_11_10_01>(x));
}

#[cfg(all(target_arch = "x86_64", feature = "f32"))]
mod sse_lanes {
    node_register!(SseLanes, _mm_setzero_ps, _mm_loadu_ps, _mm_storeu_ps, _mm_setr_ps, _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_set1_ps, |x| _mm_shuffle_ps::<0b00_11_10_01>(x, x));
}
