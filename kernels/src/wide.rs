//! The 256-bit register of the AVX2 copies: one quantity of W particles (4 in f64, 8 in f32),
//! with lane-by-lane operations that are the same IEEE operations as the scalars' (add, subtract,
//! multiply, divide, square root, floor, max; no FMA), so a lane computes what the one-particle
//! code computes, to the bit. Only ever built inside functions compiled for AVX2 (which is where
//! its intrinsics inline), so every `unsafe` in it runs on a CPU with AVX2. The transfers'
//! lanes (`transfer_lanes.rs`, `p2g_lanes.rs`, `transfer_adjoint_lanes.rs`) and the materials'
//! (`material/lanes.rs`, `drucker_prager_lanes.rs`, `evp_bingham_lanes.rs`) use it.

/// The register `R`, from its intrinsics. `gather3` is each precision's own.
macro_rules! wide_register {
    ($w:expr, $reg:ty, $all:expr, $set1:ident, $loadu:ident, $storeu:ident, $floor:ident, $max:ident, $andnot:ident, $cmp:ident, $movemask:ident, $add:ident, $sub:ident, $mul:ident, $div:ident, $sqrt:ident, |$x:ident, $a:ident| $to_i32:expr) => {
        use crate::real::Real;
        use std::arch::x86_64::*;

        pub const W: usize = $w;
        #[derive(Clone, Copy)]
        pub struct R($reg);

        impl R {
            #[inline(always)]
            pub fn splat(x: Real) -> R {
                R(unsafe { $set1(x) })
            }
            #[inline(always)]
            pub fn from_array(a: [Real; W]) -> R {
                R(unsafe { $loadu(a.as_ptr()) })
            }
            #[inline(always)]
            pub fn to_array(self) -> [Real; W] {
                let mut a = [0.0; W];
                unsafe { $storeu(a.as_mut_ptr(), self.0) };
                a
            }
            #[inline(always)]
            pub fn floor(self) -> R {
                R(unsafe { $floor(self.0) })
            }
            /// Lane by lane the larger of the two, `other` where `self` is NaN.
            #[inline(always)]
            pub fn max_or(self, other: R) -> R {
                R(unsafe { $max(self.0, other.0) })
            }
            /// Whether every lane's magnitude is below `bound` (false for NaN).
            #[inline(always)]
            pub fn all_abs_below(self, bound: Real) -> bool {
                unsafe {
                    let abs = $andnot($set1(-0.0), self.0);
                    $movemask($cmp::<_CMP_LT_OQ>(abs, $set1(bound))) == $all
                }
            }
            /// The correctly rounded square root, lane by lane.
            #[inline(always)]
            pub fn sqrt(self) -> R {
                R(unsafe { $sqrt(self.0) })
            }
            /// Bit l set where lane l is below `o` (false for NaN, as `<` is).
            #[inline(always)]
            pub fn lt_mask(self, o: R) -> u32 {
                unsafe { $movemask($cmp::<_CMP_LT_OQ>(self.0, o.0)) as u32 }
            }
            /// Bit l set where lane l is at most `o` (false for NaN, as `<=` is).
            #[inline(always)]
            pub fn le_mask(self, o: R) -> u32 {
                unsafe { $movemask($cmp::<_CMP_LE_OQ>(self.0, o.0)) as u32 }
            }
            /// Lane l of `if_set` where bit l of `mask` is set, else lane l of `otherwise`.
            #[inline(always)]
            pub fn select(mask: u32, if_set: R, otherwise: R) -> R {
                let (a, mut c) = (if_set.to_array(), otherwise.to_array());
                for l in 0..W {
                    if mask & (1 << l) != 0 {
                        c[l] = a[l];
                    }
                }
                R::from_array(c)
            }
            /// The lanes as integers; exact for integral lanes below 2^31.
            #[inline(always)]
            pub fn to_i32(self) -> [i32; W] {
                let mut $a = [0i32; W];
                let $x = self.0;
                unsafe { $to_i32 };
                $a
            }
        }

        impl std::ops::Add for R {
            type Output = R;
            #[inline(always)]
            fn add(self, o: R) -> R {
                R(unsafe { $add(self.0, o.0) })
            }
        }
        impl std::ops::Sub for R {
            type Output = R;
            #[inline(always)]
            fn sub(self, o: R) -> R {
                R(unsafe { $sub(self.0, o.0) })
            }
        }
        impl std::ops::Mul for R {
            type Output = R;
            #[inline(always)]
            fn mul(self, o: R) -> R {
                R(unsafe { $mul(self.0, o.0) })
            }
        }
        impl std::ops::Div for R {
            type Output = R;
            #[inline(always)]
            fn div(self, o: R) -> R {
                R(unsafe { $div(self.0, o.0) })
            }
        }
    };
}

#[cfg(not(feature = "f32"))]
pub(crate) mod imp {
    wide_register!(4, __m256d, 0b1111, _mm256_set1_pd, _mm256_loadu_pd, _mm256_storeu_pd, _mm256_floor_pd, _mm256_max_pd, _mm256_andnot_pd, _mm256_cmp_pd, _mm256_movemask_pd, _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd, _mm256_sqrt_pd, |x, a| _mm_storeu_si128(a.as_mut_ptr().cast(), _mm256_cvtpd_epi32(x)));

    impl R {
        /// `[x, y, z]`: lane l of each holds `p[l][0]`, `p[l][1]`, `p[l][2]`.
        ///
        /// # Safety
        /// `p[l] - 1 ..= p[l] + 2` are readable for every lane (this copy reads `p[l][0..3]`).
        #[inline(always)]
        pub unsafe fn gather3(p: [*const Real; W]) -> [R; 3] {
            // [x0 y0 | x2 y2], [x1 y1 | x3 y3], [y0 z0 | y2 z2], [y1 z1 | y3 z3]
            let xy02 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(_mm_loadu_pd(p[0])), _mm_loadu_pd(p[2]));
            let xy13 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(_mm_loadu_pd(p[1])), _mm_loadu_pd(p[3]));
            let yz02 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(_mm_loadu_pd(p[0].add(1))), _mm_loadu_pd(p[2].add(1)));
            let yz13 = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(_mm_loadu_pd(p[1].add(1))), _mm_loadu_pd(p[3].add(1)));
            [R(_mm256_unpacklo_pd(xy02, xy13)), R(_mm256_unpackhi_pd(xy02, xy13)), R(_mm256_unpackhi_pd(yz02, yz13))]
        }
    }
}

#[cfg(feature = "f32")]
pub(crate) mod imp {
    wide_register!(8, __m256, 0xff, _mm256_set1_ps, _mm256_loadu_ps, _mm256_storeu_ps, _mm256_floor_ps, _mm256_max_ps, _mm256_andnot_ps, _mm256_cmp_ps, _mm256_movemask_ps, _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_div_ps, _mm256_sqrt_ps, |x, a| _mm256_storeu_si256(a.as_mut_ptr().cast(), _mm256_cvtps_epi32(x)));

    impl R {
        /// `[x, y, z]`: lane l of each holds `p[l][0]`, `p[l][1]`, `p[l][2]`.
        ///
        /// # Safety
        /// `p[l] - 1 ..= p[l] + 2` are readable for every lane.
        #[inline(always)]
        pub unsafe fn gather3(p: [*const Real; W]) -> [R; 3] {
            // lanes k and k + 4 of a register hold particles k and k + 4: [_ x y z | _ x y z]
            let r0 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(p[0].sub(1))), _mm_loadu_ps(p[4].sub(1)));
            let r1 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(p[1].sub(1))), _mm_loadu_ps(p[5].sub(1)));
            let r2 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(p[2].sub(1))), _mm_loadu_ps(p[6].sub(1)));
            let r3 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(p[3].sub(1))), _mm_loadu_ps(p[7].sub(1)));
            // [_0 _1 x0 x1], [y0 y1 z0 z1], [_2 _3 x2 x3], [y2 y3 z2 z3] in each half
            let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
            let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
            [R(_mm256_shuffle_ps::<0xee>(t0, t2)), R(_mm256_shuffle_ps::<0x44>(t1, t3)), R(_mm256_shuffle_ps::<0xee>(t1, t3))]
        }
    }
}

pub(crate) use imp::{R, W};
