//! AVX2 + FMA version of the model application's 8-pixel groups
//! ([`super::simd_spans`]), for builds whose `wide` is SSE2: the same loops
//! with `core::arch` intrinsics, chosen at run time by [`crate::isa::Isa`]
//! (one file per instruction set, as in `kernels::moments` and `kernels::qr`).
//! The same operations in the same order as the portable version in an
//! `x86-64-v3` build (bit-identical there); against an SSE2 build the
//! products round separately. `apply::tests` compares the two.

use super::{RowGuides, Sink, Span};
use crate::guides::MAX_GUIDES;
use core::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_and_ps, _mm256_andnot_ps, _mm256_blendv_ps, _mm256_castsi256_ps, _mm256_cmp_ps, _mm256_fmadd_ps,
    _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps, _mm256_mul_ps, _mm256_set1_epi32, _mm256_set1_ps, _mm256_setr_ps,
    _mm256_setzero_ps, _mm256_sqrt_ps, _mm256_sub_ps, _CMP_LE_OQ,
};
use wide::f32x8;

/// [`super::simd_spans`] with AVX2 + FMA: every whole 8-pixel group between
/// the first and last cell centres; returns the fallback count and the first
/// pixel not done.
///
/// # Safety
/// The CPU must support AVX2 and FMA ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn simd_spans<const Q: usize, const CLAMP: bool, S: Sink>(
    row_models: &[f32],
    row_slopes: &[f32],
    sp: &Span,
    guides: &RowGuides<'_>,
    demod: Option<(usize, f32)>,
    out: &mut S,
) -> (usize, usize) {
    let (ml, w) = (sp.ml, guides.width);
    let inv_b = _mm256_set1_ps(1.0 / sp.block as f32);
    let fx0 = _mm256_mul_ps(_mm256_setr_ps(0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5), inv_b);
    let mut reference = [_mm256_setzero_ps(); MAX_GUIDES];
    for q in 0..Q {
        reference[q] = _mm256_set1_ps(guides.reference[q]);
    }
    let (mut fallback, mut x) = (0, sp.half.min(w));
    // (the portable version's two loops, for the same reason: see there)
    if sp.block == 8 {
        for i in 0..sp.cells_x - 1 {
            let x0 = i * 8 + sp.half;
            if x0 + 8 > w {
                break;
            }
            let (base, slope) = (&row_models[i * ml..(i + 1) * ml], &row_slopes[i * ml..(i + 1) * ml]);
            // SAFETY: AVX2 and FMA are enabled in this function; x0 + 8 ≤ w.
            fallback += unsafe { group::<Q, CLAMP, S>(base, slope, fx0, &reference, guides, demod, x0, out) };
            x = x0 + 8;
        }
        return (fallback, x);
    }
    for i in 0..sp.cells_x - 1 {
        let start = i * sp.block + sp.half;
        let base = &row_models[i * ml..(i + 1) * ml];
        let slope = &row_slopes[i * ml..(i + 1) * ml];
        for g in 0..sp.block / 8 {
            let x0 = start + 8 * g;
            if x0 + 8 > w {
                return (fallback, x);
            }
            let fx = if g == 0 { fx0 } else { _mm256_add_ps(fx0, _mm256_mul_ps(_mm256_set1_ps((8 * g) as f32), inv_b)) };
            // SAFETY: AVX2 and FMA are enabled in this function; x0 + 8 ≤ w.
            fallback += unsafe { group::<Q, CLAMP, S>(base, slope, fx, &reference, guides, demod, x0, out) };
            x = x0 + 8;
        }
    }
    (fallback, x)
}

/// [`super::simd_group`] with AVX2 + FMA: pixels `x0..x0 + 8`.
///
/// # Safety
/// The CPU must support AVX2 and FMA; `x0 + 8 ≤ guides.width`, and every
/// guide row and output plane holds `width` values (`apply_row` checked).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn group<const Q: usize, const CLAMP: bool, S: Sink>(
    base: &[f32],
    slope: &[f32],
    fx: __m256,
    reference: &[__m256; MAX_GUIDES],
    g: &RowGuides<'_>,
    demod: Option<(usize, f32)>,
    x0: usize,
    out: &mut S,
) -> usize {
    // SAFETY: AVX2 and FMA are guaranteed by the caller; every load and store
    // is of a bounds-checked 8-value slice.
    unsafe {
        let load = |s: &[f32]| _mm256_loadu_ps(s[x0..x0 + 8].as_ptr());
        let lerp = |j: usize| _mm256_fmadd_ps(_mm256_set1_ps(slope[j]), fx, _mm256_set1_ps(base[j]));
        let sign = _mm256_set1_ps(-0.0);
        let max = _mm256_set1_ps(f32::MAX);
        let finite = |v: __m256| _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_andnot_ps(sign, v), max);
        let mut d = [_mm256_setzero_ps(); MAX_GUIDES];
        for q in 0..Q {
            d[q] = _mm256_sub_ps(load(g.rows[q]), reference[q]);
        }
        let mut all_ok = true;
        let mut rgb = [_mm256_setzero_ps(); 3];
        for (c, o) in rgb.iter_mut().enumerate() {
            let mut y = lerp(c);
            for q in 0..Q {
                y = _mm256_fmadd_ps(lerp(3 + 3 * q + c), d[q], y);
            }
            let ok = finite(y);
            let mut r = if _mm256_movemask_ps(ok) == 0xff {
                y
            } else {
                all_ok = false;
                _mm256_blendv_ps(lerp(3 + 3 * Q + c), y, ok)
            };
            if CLAMP {
                r = _mm256_max_ps(r, _mm256_setzero_ps());
            }
            *o = r;
        }
        if let Some((a, c)) = demod {
            // `demodulation::scale8` and `remodulate8`, in the same order
            let ao = load(g.rows[a]);
            let finite = finite(ao);
            let one = _mm256_set1_ps(1.0);
            let clamped = _mm256_min_ps(_mm256_max_ps(_mm256_blendv_ps(one, ao, finite), _mm256_setzero_ps()), one);
            let s = _mm256_sqrt_ps(_mm256_add_ps(clamped, _mm256_set1_ps(c)));
            for v in rgb.iter_mut() {
                *v = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(*v, s), max), _mm256_sub_ps(_mm256_setzero_ps(), max));
            }
        }
        out.put8(x0, rgb.map(bytemuck::cast::<__m256, f32x8>));
        if all_ok {
            return 0;
        }
        let mut ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        for q in 0..Q {
            ok = _mm256_and_ps(ok, finite(load(g.rows[q])));
        }
        8 - (_mm256_movemask_ps(ok) as u32).count_ones() as usize
    }
}
