//! AVX2 version of the four-cell normalized solve ([`super::solve_cells4`]),
//! for builds whose `wide` is SSE2 (where an `f64x4` is two SSE2 halves):
//! the generic solve `super::normalized` instantiated on [`F64x4`], a private
//! `__m256d` lane type, inside a `#[target_feature]` function chosen at run
//! time by [`crate::isa::Isa`]. [`F64Lanes`] promises IEEE operations per
//! lane (no fused multiply-adds), so the result is bit-identical to the
//! portable lanes and to the scalar path; `solve::tests` checks it.

use super::{F64Lanes, Fit, SolveParams, Solved};
use crate::kernels::CellLayout;
use core::arch::x86_64::{
    __m256d, _mm256_add_pd, _mm256_and_pd, _mm256_andnot_pd, _mm256_blendv_pd, _mm256_cmp_pd, _mm256_div_pd, _mm256_movemask_pd,
    _mm256_mul_pd, _mm256_set1_pd, _mm256_setr_pd, _mm256_sqrt_pd, _mm256_sub_pd, _CMP_GT_OQ, _CMP_LE_OQ,
};
use wide::f64x4;

/// Four f64 lanes in one AVX register. Private to this file and made only
/// inside [`normalized4`], a `#[target_feature(enable = "avx2")]` function
/// that runs only where the CPU has AVX2: that is what makes its safe methods
/// (AVX instructions) sound. They are `#[inline(always)]`, so they compile
/// into that function's AVX context.
#[derive(Clone, Copy)]
struct F64x4(__m256d);

macro_rules! op {
    ($tr:ident, $f:ident, $intr:ident) => {
        impl core::ops::$tr for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn $f(self, o: F64x4) -> F64x4 {
                // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
                F64x4(unsafe { $intr(self.0, o.0) })
            }
        }
    };
}
op!(Add, add, _mm256_add_pd);
op!(Sub, sub, _mm256_sub_pd);
op!(Mul, mul, _mm256_mul_pd);
op!(Div, div, _mm256_div_pd);

/// All bits set where `mask` has the lane's bit.
#[inline(always)]
fn lane_mask(mask: u32) -> __m256d {
    let m = |l: u32| if mask >> l & 1 != 0 { f64::from_bits(u64::MAX) } else { 0.0 };
    // SAFETY: only reached from F64x4's methods (see the type).
    unsafe { _mm256_setr_pd(m(0), m(1), m(2), m(3)) }
}

impl F64Lanes for F64x4 {
    const LANES: usize = 4;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        F64x4(unsafe { _mm256_set1_pd(v) })
    }
    #[inline(always)]
    fn abs_(self) -> Self {
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        F64x4(unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0) })
    }
    #[inline(always)]
    fn max_(self, o: Self) -> Self {
        // `self` where `self > o` (ordered: NaN → `o`), as the portable lanes
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        F64x4(unsafe { _mm256_blendv_pd(o.0, self.0, _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, o.0)) })
    }
    #[inline(always)]
    fn sqrt_(self) -> Self {
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        F64x4(unsafe { _mm256_sqrt_pd(self.0) })
    }
    #[inline(always)]
    fn not_above(self, floor: Self) -> u32 {
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        unsafe {
            let gt = _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, floor.0);
            let finite = _mm256_cmp_pd::<_CMP_LE_OQ>(self.abs_().0, _mm256_set1_pd(f64::MAX));
            !(_mm256_movemask_pd(_mm256_and_pd(gt, finite)) as u32) & 0xF
        }
    }
    #[inline(always)]
    fn set_where(self, mask: u32, v: f64) -> Self {
        if mask == 0 {
            return self;
        }
        // SAFETY: `F64x4` methods run only inside `normalized4`, where AVX2 is enabled (see the type).
        F64x4(unsafe { _mm256_blendv_pd(self.0, _mm256_set1_pd(v), lane_mask(mask)) })
    }
}

/// `super::normalized` on four cells (`cells`: 4 × `k` moments), one per
/// AVX lane; the results as `wide` lanes for [`super::write_models4`].
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn normalized4<const Q: usize>(cells: &[f64], p: &SolveParams, eps_mul: f64, eps_add: f64) -> (Fit<f64x4, Q>, [u32; 4]) {
    let (full, dropped, _) = super::normalized::<F64x4, Q, false>(lanes(cells, CellLayout::new(Q).k), p, eps_mul, eps_add, 0);
    (full.map(wide), dropped)
}

/// [`normalized4`] with the fit without guide `drop` too (a function of its
/// own, so that [`normalized4`] returns no second fit it would not use).
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn normalized4_without<const Q: usize>(
    cells: &[f64],
    p: &SolveParams,
    eps_mul: f64,
    eps_add: f64,
    drop: usize,
) -> Solved<f64x4, Q> {
    let (full, dropped, sub) = super::normalized::<F64x4, Q, true>(lanes(cells, CellLayout::new(Q).k), p, eps_mul, eps_add, drop);
    (full.map(wide), dropped, sub.map(wide))
}

/// Moment `m` of the four cells as one register.
#[inline(always)]
fn lanes(cells: &[f64], k: usize) -> impl Fn(usize) -> F64x4 + '_ {
    // SAFETY: only called inside `normalized4*`, where AVX2 is enabled (see the type).
    move |m: usize| F64x4(unsafe { _mm256_setr_pd(cells[m], cells[k + m], cells[2 * k + m], cells[3 * k + m]) })
}

/// `wide` lanes of the same four values (`f64x4` and `__m256d` are both 32
/// plain bytes: bytemuck checks it).
#[inline(always)]
fn wide(v: F64x4) -> f64x4 {
    bytemuck::cast(v.0)
}
