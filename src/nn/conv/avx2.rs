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

use super::{Lanes, OB};
use core::arch::x86_64::{__m256, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_set1_ps, _mm256_setzero_ps, _mm256_storeu_ps};

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

/// [`super::conv3_lanes`] with AVX2 + FMA; returns the end of the pixels filled.
///
/// Two 8-pixel groups per pass where the row has room: 2 × `OB` independent
/// accumulators. With `OB` alone, each accumulator's chain of dependent
/// multiply-adds (4 cycles each) left half of the FMA throughput idle.
///
/// # Safety
/// The CPU must support AVX2 and FMA ([`super::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB]) -> usize {
    let end = rows[0].len(); // the output row (≥ 8)
    let mut x = 0;
    while x + 16 <= end {
        // SAFETY: AVX2 and FMA are guaranteed by this function's caller.
        unsafe { groups::<2>(g, rows, x) };
        x += 16;
    }
    while x < end {
        // the last group is shifted left to end at `end` (it recomputes a few
        // pixels, bit-identically: every group starts from the bias)
        // SAFETY: as above.
        unsafe { groups::<1>(g, rows, x.min(end - 8)) };
        x += 8;
    }
    end
}

/// `G` consecutive 8-pixel groups from pixel `x0` of [`conv3_lanes`].
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn groups<const G: usize>(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB], x0: usize) {
    let (w, plane, ew) = (g.w, g.plane, g.w.div_ceil(2));
    let mut acc = [g.bias.map(|b| _mm256_set1_ps(b)); G];
    // every tap of the G groups inside the row (else the zero padding is
    // loaded lane by lane); stride 2 reads odd[x − 1..], even[x..], odd[x..]
    let interior = x0 >= 1 && if g.stride == 1 { x0 + 8 * G < w } else { x0 + 8 * G <= w / 2 };
    for i in 0..g.cin {
        let src = &g.lanes[i * plane..];
        for (ky, r) in g.src_rows.iter().enumerate() {
            let Some(sy) = *r else { continue };
            let srow = &src[sy * w..(sy + 1) * w];
            let t = (i * 3 + ky) * 3;
            // (loops, not `array::from_fn`: its closure would not inherit
            // this function's target features, and the loads would be calls)
            let mut v = [[_mm256_setzero_ps(); 3]; G];
            if interior {
                // the taps' 8·G values each, inside the row
                let n = 8 * G;
                let taps: [&[f32]; 3] = if g.stride == 1 {
                    [&srow[x0 - 1..x0 - 1 + n], &srow[x0..x0 + n], &srow[x0 + 1..x0 + 1 + n]]
                } else {
                    let (even, odd) = srow.split_at(ew);
                    [&odd[x0 - 1..x0 - 1 + n], &even[x0..x0 + n], &odd[x0..x0 + n]]
                };
                for (k, vk) in v.iter_mut().enumerate() {
                    for (vj, tj) in vk.iter_mut().zip(taps) {
                        // SAFETY: `tj` holds 8·G values and k < G, so the 8 read
                        // are inside it; AVX is guaranteed by the caller.
                        *vj = unsafe { _mm256_loadu_ps(tj.as_ptr().add(8 * k)) };
                    }
                }
            } else {
                for (k, vk) in v.iter_mut().enumerate() {
                    let xi = (x0 + 8 * k) as isize;
                    *vk = if g.stride == 1 {
                        [load8(srow, xi - 1), load8(srow, xi), load8(srow, xi + 1)]
                    } else {
                        let (even, odd) = srow.split_at(ew);
                        [load8(odd, xi - 1), load8(even, xi), load8(odd, xi)]
                    };
                }
            }
            for (b, wb) in g.wts.iter().enumerate() {
                let wb = &wb[t..t + 3];
                for (j, &wt) in wb.iter().enumerate() {
                    let s = _mm256_set1_ps(wt);
                    for (a, vk) in acc.iter_mut().zip(&v) {
                        a[b] = _mm256_fmadd_ps(s, vk[j], a[b]);
                    }
                }
            }
        }
    }
    for (k, ak) in acc.iter().enumerate() {
        let x = x0 + 8 * k;
        for (a, r) in ak.iter().zip(rows.iter_mut()) {
            if let Some(dst) = r.get_mut(x..x + 8) {
                // SAFETY: `dst` holds exactly 8 f32, written unaligned (AVX guaranteed).
                unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), *a) };
            }
        }
    }
}
