//! 16 AVX-512F lanes for the temporal stage's groups ([`super::Lane`]), chosen
//! at run time by [`crate::isa::Isa::Avx512`]: the entries compile the kernels
//! of [`super`] with AVX-512F enabled. Twice the pixels of the AVX2 lanes per
//! instruction, and 32 registers: step 1's kernel keeps a group's sums and
//! guides in them (12 vector loads and stores on the stack in the generated
//! code, against 66 in the AVX2 kernel's). Each operation is the IEEE
//! operation of the AVX2 lanes (`max`/`min` with the same NaN rule), so both
//! give the per-pixel bits.
//!
//! Masks are lanes with every bit set or clear, as the trait asks; the
//! compiler turns a comparison feeding a `select` into an opmask.

use super::{Lane, Reprojection, ResolveRow, Row};
use core::arch::x86_64::*;
use core::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Pixels per group.
const WIDTH: usize = 16;

/// 16 f32 lanes in a ZMM register. Private to this file: only the entries
/// (`intrinsics_entries!`), which the caller runs on a CPU with AVX-512F, make one.
#[derive(Clone, Copy)]
struct Zmm(__m512);

intrinsics_entries!(Zmm, "avx512f,avx2,fma");

// SAFETY (every `unsafe` block below): a `Zmm` exists only inside the
// entries above, which run on a CPU with AVX-512F (their callers check
// `Isa::Avx512.available()`); loads and stores are bounds-checked before the
// pointer access.
macro_rules! binary {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for Zmm {
            type Output = Zmm;
            #[inline(always)]
            fn $f(self, o: Zmm) -> Zmm {
                Zmm(unsafe { $op(self.0, o.0) })
            }
        }
    };
}
binary!(Add, add, _mm512_add_ps);
binary!(Sub, sub, _mm512_sub_ps);
binary!(Mul, mul, _mm512_mul_ps);
binary!(Div, div, _mm512_div_ps);

/// A bit operation on the lanes as 32-bit integers (AVX-512F has no `and_ps`).
macro_rules! bits {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for Zmm {
            type Output = Zmm;
            #[inline(always)]
            fn $f(self, o: Zmm) -> Zmm {
                Zmm(unsafe { _mm512_castsi512_ps($op(_mm512_castps_si512(self.0), _mm512_castps_si512(o.0))) })
            }
        }
    };
}
bits!(BitAnd, bitand, _mm512_and_si512);
bits!(BitOr, bitor, _mm512_or_si512);

impl Neg for Zmm {
    type Output = Zmm;
    #[inline(always)]
    fn neg(self) -> Zmm {
        Zmm(unsafe { _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(self.0), _mm512_set1_epi32(i32::MIN))) })
    }
}
impl Not for Zmm {
    type Output = Zmm;
    #[inline(always)]
    fn not(self) -> Zmm {
        Zmm(unsafe { _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(self.0), _mm512_set1_epi32(-1))) })
    }
}

impl Zmm {
    /// The lanes of the opmask `k` as a mask of every bit set or clear.
    #[inline(always)]
    fn from_mask(k: __mmask16) -> Zmm {
        Zmm(unsafe { _mm512_castsi512_ps(_mm512_maskz_mov_epi32(k, _mm512_set1_epi32(-1))) })
    }
    /// The lanes of the mask `self` as an opmask.
    #[inline(always)]
    fn mask(self) -> __mmask16 {
        let v = unsafe { _mm512_castps_si512(self.0) };
        unsafe { _mm512_test_epi32_mask(v, v) }
    }
    #[inline(always)]
    fn cmp<const P: i32>(self, o: Zmm) -> Zmm {
        Zmm::from_mask(unsafe { _mm512_cmp_ps_mask::<P>(self.0, o.0) })
    }
}

impl Lane for Zmm {
    const N: usize = WIDTH;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Zmm(unsafe { _mm512_set1_ps(v) })
    }
    #[inline(always)]
    fn iota() -> Self {
        Zmm(unsafe { _mm512_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0) })
    }
    #[inline(always)]
    fn load(s: &[f32], i: usize) -> Option<Self> {
        let s = s.get(i..i + WIDTH)?;
        Some(Zmm(unsafe { _mm512_loadu_ps(s.as_ptr()) }))
    }
    #[inline(always)]
    unsafe fn load_ptr(p: *const f32) -> Self {
        // SAFETY: the caller's contract (16 readable f32 from `p`); unaligned load
        Zmm(unsafe { _mm512_loadu_ps(p) })
    }
    #[inline(always)]
    fn store(self, s: &mut [f32], i: usize) -> Option<()> {
        let s = s.get_mut(i..i + WIDTH)?;
        unsafe { _mm512_storeu_ps(s.as_mut_ptr(), self.0) };
        Some(())
    }
    #[inline(always)]
    fn first(self) -> f32 {
        unsafe { _mm512_cvtss_f32(self.0) }
    }
    intrinsics_compares!();
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        Zmm(unsafe { _mm512_mask_blend_ps(self.mask(), f.0, t.0) })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Zmm(unsafe { _mm512_abs_ps(self.0) })
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Zmm(unsafe { _mm512_sqrt_ps(self.0) })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        o.is_nan().select(self, Zmm(unsafe { _mm512_max_ps(self.0, o.0) }))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        o.is_nan().select(self, Zmm(unsafe { _mm512_min_ps(self.0, o.0) }))
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        self.mask() as u32
    }
}
