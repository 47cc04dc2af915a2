//! AVX2 + FMA version of the 3×3 layers' 8-pixel lanes ([`super::conv3_lanes`]),
//! for builds whose `wide` is SSE2: the same loop with `core::arch` intrinsics,
//! chosen at run time by [`super::Isa`]. (Written out twice on purpose, one
//! file per instruction set as in fast_image_resize: a loop generic over the
//! vector type would need `wide`'s compile-time choice or trait methods inlined
//! into this `#[target_feature]` function, which Rust does not promise.)
//! Same operations in the same order as
//! the portable version in an `x86-64-v3` build (fused multiply-adds), so
//! their outputs are identical there; against an SSE2 build they differ by
//! the rounding of the unfused products (tests/nn.rs compares both with f64).

use super::{Lanes, LEAKY_SLOPE, OB};
use core::arch::x86_64::{
    __m256, _mm256_blendv_ps, _mm256_broadcast_ss, _mm256_cmp_ps, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_set1_ps,
    _mm256_setzero_ps, _mm256_storeu_ps, _mm_prefetch, _CMP_LT_OQ, _MM_HINT_T0,
};

/// The 8 values `s[x..x + 8]`, zeros for those outside `s` (see [`super::load8`]).
#[inline(always)]
fn load8(s: &[f32], x: isize) -> __m256 {
    match usize::try_from(x).ok().and_then(|x| s.get(x..x + 8)) {
        // SAFETY: `c` holds exactly 8 f32, read unaligned; the caller of
        // `conv3_lanes` guaranteed AVX.
        Some(c) => unsafe { _mm256_loadu_ps(c.as_ptr()) },
        None => {
            let a = super::padded8(s, x);
            // SAFETY: as above.
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        }
    }
}

/// `8 · G` output pixels per pass: with `OB` channels, `G · OB` independent
/// accumulators.
const G: usize = 2;

/// [`super::conv3_lanes`] with AVX2 + FMA over output pixels `x0..x1`;
/// returns `x1`.
///
/// # Safety
/// The CPU must support AVX2 and FMA ([`super::Isa::Avx2Fma`] available),
/// and `g.fits()` must hold.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB], x0: usize, x1: usize) -> usize {
    let ow = rows[0].len(); // ≥ 8, and x1 ≥ min(x0 + STRIP, ow)
    let mut x = x0;
    while x < x1 {
        // the last pass is shifted left to end at `x1` (it recomputes a few
        // pixels, bit-identically: every group starts from the bias)
        if ow >= 8 * G && x1 >= 8 * G {
            let xs = x.min(x1 - 8 * G);
            // SAFETY: AVX2, FMA and `g.fits()` are guaranteed by this function's caller.
            unsafe { groups::<G>(g, rows, xs) };
            x = xs + 8 * G;
        } else {
            let xs = x.min(x1.max(8) - 8);
            // SAFETY: as above.
            unsafe { groups::<1>(g, rows, xs) };
            x = xs + 8;
        }
    }
    x1
}

/// `N` consecutive 8-pixel groups from pixel `x0` of [`conv3_lanes`].
///
/// # Safety
/// The CPU must support AVX2 and FMA, and `g.fits()` must hold.
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn groups<const N: usize>(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB], x0: usize) {
    let (w, plane, ew) = (g.w, g.plane, g.w.div_ceil(2));
    let mut acc = [[_mm256_setzero_ps(); OB]; N];
    for ak in acc.iter_mut() {
        for (a, &b) in ak.iter_mut().zip(&g.bias) {
            *a = _mm256_set1_ps(b);
        }
    }
    // every tap of the N groups inside the row (else the zero padding is
    // loaded lane by lane); stride 2 reads odd[x − 1..], even[x..], odd[x..]
    let interior = x0 >= 1 && if g.stride == 1 { x0 + 8 * N < w } else { x0 + 8 * N <= w / 2 };
    if interior {
        // where the three taps' 8·N values start in a row
        let offs = if g.stride == 1 { [x0 - 1, x0, x0 + 1] } else { [ew + x0 - 1, x0, ew + x0] };
        // the rows inside the input: (ky, offset of row sy)
        let (valid, n) = super::rows_inside(&g.src_rows, w);
        let (base, wbase) = (g.lanes.as_ptr(), g.wts.as_ptr());
        for i in 0..g.cin {
            for &(ky, ro) in &valid[..n] {
                // SAFETY: `g.fits()`: row sy of plane i (i < cin) lies inside
                // `lanes`; `interior`: offs[kx] + 8·N ≤ w (stride 2:
                // ew + x0 + 8·N ≤ ew + w/2 = w).
                let row = unsafe { base.add(i * plane + ro) };
                // the next pass's values of the first two taps' parts of the
                // row: a pass reads 3 · cin rows, more streams than the
                // hardware prefetcher follows
                for o in [offs[0], offs[1]] {
                    _mm_prefetch::<_MM_HINT_T0>(row.wrapping_add(o + 8 * N + 16).cast());
                }
                let t = (i * 3 + ky) * 3;
                for (kx, &off) in offs.iter().enumerate() {
                    let mut v = [_mm256_setzero_ps(); N];
                    for (k, vk) in v.iter_mut().enumerate() {
                        // SAFETY: see `row`; AVX is guaranteed by the caller.
                        *vk = unsafe { _mm256_loadu_ps(row.add(off + 8 * k)) };
                    }
                    for b in 0..OB {
                        // SAFETY: `g.fits()`: wts holds cin · 9 · OB values, and
                        // (t + kx) · OB + b < that.
                        let s = unsafe { _mm256_broadcast_ss(&*wbase.add((t + kx) * OB + b)) };
                        for (ak, vk) in acc.iter_mut().zip(&v) {
                            ak[b] = _mm256_fmadd_ps(s, *vk, ak[b]);
                        }
                    }
                }
            }
        }
    } else {
        for i in 0..g.cin {
            let src = &g.lanes[i * plane..];
            for (ky, r) in g.src_rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                let srow = &src[sy * w..(sy + 1) * w];
                let t = (i * 3 + ky) * 3;
                // (loops, not `array::from_fn`: its closure would not inherit
                // this function's target features, and the loads would be calls)
                let mut v = [[_mm256_setzero_ps(); 3]; N];
                for (k, vk) in v.iter_mut().enumerate() {
                    let xi = (x0 + 8 * k) as isize;
                    *vk = if g.stride == 1 {
                        [load8(srow, xi - 1), load8(srow, xi), load8(srow, xi + 1)]
                    } else {
                        let (even, odd) = srow.split_at(ew);
                        [load8(odd, xi - 1), load8(even, xi), load8(odd, xi)]
                    };
                }
                for kx in 0..3 {
                    let wk = &g.wts[(t + kx) * OB..(t + kx + 1) * OB];
                    for (b, &wt) in wk.iter().enumerate() {
                        let s = _mm256_set1_ps(wt);
                        for (ak, vk) in acc.iter_mut().zip(&v) {
                            ak[b] = _mm256_fmadd_ps(s, vk[kx], ak[b]);
                        }
                    }
                }
            }
        }
    }
    let slope = _mm256_set1_ps(LEAKY_SLOPE);
    for (k, ak) in acc.iter().enumerate() {
        let x = x0 + 8 * k;
        for (a, r) in ak.iter().zip(rows.iter_mut()) {
            let a = if g.leaky {
                _mm256_blendv_ps(*a, _mm256_mul_ps(*a, slope), _mm256_cmp_ps::<_CMP_LT_OQ>(*a, _mm256_setzero_ps()))
            } else {
                *a
            };
            if let Some(dst) = r.get_mut(x..x + 8) {
                // SAFETY: `dst` holds exactly 8 f32, written unaligned (AVX guaranteed).
                unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), a) };
            }
        }
    }
}
