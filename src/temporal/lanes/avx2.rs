//! 8 AVX2 lanes for the temporal stage's groups ([`super::Lane`]), chosen at
//! run time in x86-64 builds without AVX2 + FMA: the entries compile the
//! kernels of [`super`] with AVX2 enabled, so the `Avx` operations inline
//! as single instructions. Each operation is the one `wide` does in an AVX
//! build (`max`/`min` included), so both give the same bits.

use super::{Lane, Reprojection, ResolveRow, Row};
use core::arch::x86_64::*;
use core::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Pixels per group.
const WIDTH: usize = 8;

/// 8 f32 lanes in an AVX register. Private to this file: only the entries
/// (`intrinsics_entries!`), which the caller runs on a CPU with AVX2 and FMA, make one.
#[derive(Clone, Copy)]
struct Avx(__m256);

intrinsics_entries!(Avx, "avx2,fma");

// SAFETY (every `unsafe` block below): an `Avx` exists only inside the
// entries above, which run on a CPU with AVX2 (their callers check
// `Isa::intrinsics`); loads and stores are bounds-checked before the pointer
// access.
macro_rules! binary {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for Avx {
            type Output = Avx;
            #[inline(always)]
            fn $f(self, o: Avx) -> Avx {
                Avx(unsafe { $op(self.0, o.0) })
            }
        }
    };
}
binary!(Add, add, _mm256_add_ps);
binary!(Sub, sub, _mm256_sub_ps);
binary!(Mul, mul, _mm256_mul_ps);
binary!(Div, div, _mm256_div_ps);
binary!(BitAnd, bitand, _mm256_and_ps);
binary!(BitOr, bitor, _mm256_or_ps);

impl Neg for Avx {
    type Output = Avx;
    #[inline(always)]
    fn neg(self) -> Avx {
        Avx(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
    }
}
impl Not for Avx {
    type Output = Avx;
    #[inline(always)]
    fn not(self) -> Avx {
        Avx(unsafe { _mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) })
    }
}

impl Avx {
    #[inline(always)]
    fn cmp<const P: i32>(self, o: Avx) -> Avx {
        Avx(unsafe { _mm256_cmp_ps::<P>(self.0, o.0) })
    }
}

impl Lane for Avx {
    const N: usize = WIDTH;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Avx(unsafe { _mm256_set1_ps(v) })
    }
    #[inline(always)]
    fn iota() -> Self {
        Avx(unsafe { _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0) })
    }
    #[inline(always)]
    fn load(s: &[f32], i: usize) -> Option<Self> {
        let s = s.get(i..i + 8)?;
        Some(Avx(unsafe { _mm256_loadu_ps(s.as_ptr()) }))
    }
    #[inline(always)]
    unsafe fn load_ptr(p: *const f32) -> Self {
        // SAFETY: the caller's contract (8 readable f32 from `p`); unaligned load
        Avx(unsafe { _mm256_loadu_ps(p) })
    }
    #[inline(always)]
    fn store(self, s: &mut [f32], i: usize) -> Option<()> {
        let s = s.get_mut(i..i + 8)?;
        unsafe { _mm256_storeu_ps(s.as_mut_ptr(), self.0) };
        Some(())
    }
    #[inline(always)]
    fn first(self) -> f32 {
        unsafe { _mm256_cvtss_f32(self.0) }
    }
    intrinsics_compares!();
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        Avx(unsafe { _mm256_blendv_ps(f.0, t.0, self.0) })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Avx(unsafe { _mm256_and_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX))) })
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Avx(unsafe { _mm256_sqrt_ps(self.0) })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        o.is_nan().select(self, Avx(unsafe { _mm256_max_ps(self.0, o.0) }))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        o.is_nan().select(self, Avx(unsafe { _mm256_min_ps(self.0, o.0) }))
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }
}
