//! `avx2_f64x4!()` defines `F64x4`, four f64 lanes in one AVX register, as
//! a private type of the module that invokes it, for the generic f64 code of
//! the four-cell kernels ([`F64Lanes`](super::cholesky::F64Lanes),
//! [`Lanes4`](super::cholesky::Lanes4)) run inside that module's
//! `#[target_feature(enable = "avx2")]` entries. Every operation is the
//! IEEE one per lane (no fused multiply-adds), so the lanes give the
//! portable lanes' bits.
//!
//! A macro rather than a shared type: its safe methods run AVX instructions,
//! which is sound only because no value of it can exist outside a call of
//! the invoking module's `unsafe` AVX2 entries, whose contract is that the
//! CPU has AVX2: the type is private to that module, and the entries return
//! plain arrays. Each file that invokes the macro keeps to that.

/// Defines the private `F64x4` lane type in the invoking module (see the module).
macro_rules! avx2_f64x4 {
    () => {
        /// Four f64 lanes in one AVX register. Private to this module; a
        /// value exists only during a call of its `unsafe`
        /// `#[target_feature(enable = "avx2")]` entries, whose contract is
        /// that the CPU has AVX2 (they return plain arrays): that is what
        /// makes its safe methods (AVX instructions) sound. They are
        /// `#[inline(always)]`, so they compile into those entries.
        #[derive(Clone, Copy)]
        struct F64x4(core::arch::x86_64::__m256d);

        impl core::ops::Add for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn add(self, o: F64x4) -> F64x4 {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_add_pd(self.0, o.0) })
            }
        }
        impl core::ops::Sub for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn sub(self, o: F64x4) -> F64x4 {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_sub_pd(self.0, o.0) })
            }
        }
        impl core::ops::Mul for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn mul(self, o: F64x4) -> F64x4 {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_mul_pd(self.0, o.0) })
            }
        }
        impl core::ops::Div for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn div(self, o: F64x4) -> F64x4 {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_div_pd(self.0, o.0) })
            }
        }

        impl $crate::kernels::cholesky::F64Lanes for F64x4 {
            const LANES: usize = 4;
            #[inline(always)]
            fn splat(v: f64) -> Self {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_set1_pd(v) })
            }
            #[inline(always)]
            fn abs_(self) -> Self {
                use core::arch::x86_64::{_mm256_andnot_pd, _mm256_set1_pd};
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0) })
            }
            #[inline(always)]
            fn max_(self, o: Self) -> Self {
                use core::arch::x86_64::{_mm256_blendv_pd, _mm256_cmp_pd, _CMP_GT_OQ};
                // `self` where `self > o` (ordered: NaN → `o`), as the portable lanes
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { _mm256_blendv_pd(o.0, self.0, _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, o.0)) })
            }
            #[inline(always)]
            fn sqrt_(self) -> Self {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { core::arch::x86_64::_mm256_sqrt_pd(self.0) })
            }
            #[inline(always)]
            fn not_above(self, floor: Self) -> u32 {
                use core::arch::x86_64::{_mm256_and_pd, _mm256_cmp_pd, _mm256_movemask_pd, _mm256_set1_pd, _CMP_GT_OQ, _CMP_LE_OQ};
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                unsafe {
                    let gt = _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, floor.0);
                    let finite = _mm256_cmp_pd::<_CMP_LE_OQ>(self.abs_().0, _mm256_set1_pd(f64::MAX));
                    !(_mm256_movemask_pd(_mm256_and_pd(gt, finite)) as u32) & 0xF
                }
            }
            #[inline(always)]
            fn set_where(self, mask: u32, v: f64) -> Self {
                use core::arch::x86_64::{_mm256_blendv_pd, _mm256_set1_pd, _mm256_setr_pd};
                if mask == 0 {
                    return self;
                }
                let m = |l: u32| if mask >> l & 1 != 0 { f64::from_bits(u64::MAX) } else { 0.0 };
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type).
                F64x4(unsafe { _mm256_blendv_pd(self.0, _mm256_set1_pd(v), _mm256_setr_pd(m(0), m(1), m(2), m(3))) })
            }
        }

        impl $crate::kernels::cholesky::Lanes4 for F64x4 {
            #[inline(always)]
            fn from_array(a: [f64; 4]) -> Self {
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type); reads 4 f64.
                F64x4(unsafe { core::arch::x86_64::_mm256_loadu_pd(a.as_ptr()) })
            }
            #[inline(always)]
            fn from_f32(a: [f32; 4]) -> Self {
                use core::arch::x86_64::{_mm256_cvtps_pd, _mm_loadu_ps};
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type); reads 4 f32.
                F64x4(unsafe { _mm256_cvtps_pd(_mm_loadu_ps(a.as_ptr())) })
            }
            #[inline(always)]
            fn to_array(self) -> [f64; 4] {
                let mut a = [0f64; 4];
                // SAFETY: a value exists only while the CPU is known to have AVX2 (see the type); writes 4 f64.
                unsafe { core::arch::x86_64::_mm256_storeu_pd(a.as_mut_ptr(), self.0) };
                a
            }
        }
    };
}
pub(crate) use avx2_f64x4;
