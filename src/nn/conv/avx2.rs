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
use core::arch::x86_64::{__m256, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_set1_ps, _mm256_storeu_ps};

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
/// # Safety
/// The CPU must support AVX2 and FMA ([`super::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB]) -> usize {
    let (w, h, ew) = (g.w, g.h, g.w.div_ceil(2));
    let mut x = 0;
    let mut done = 0;
    let end = rows[0].len(); // the output row (≥ 8)
    while done < end {
        // the last group is shifted left to end at `end` (see the portable version)
        x = x.min(end - 8);
        let xi = x as isize;
        let mut acc = g.bias.map(|b| _mm256_set1_ps(b));
        for i in 0..g.cin {
            let src = &g.lanes[i * w * h..(i + 1) * w * h];
            for (ky, r) in g.src_rows.iter().enumerate() {
                let Some(sy) = *r else { continue };
                let srow = &src[sy * w..(sy + 1) * w];
                let t = (i * 3 + ky) * 3;
                let (v0, v1, v2) = if g.stride == 1 {
                    (load8(srow, xi - 1), load8(srow, xi), load8(srow, xi + 1))
                } else {
                    let (even, odd) = srow.split_at(ew);
                    (load8(odd, xi - 1), load8(even, xi), load8(odd, xi))
                };
                for (a, wb) in acc.iter_mut().zip(g.wts) {
                    let wb = &wb[t..t + 3];
                    *a = _mm256_fmadd_ps(_mm256_set1_ps(wb[0]), v0, *a);
                    *a = _mm256_fmadd_ps(_mm256_set1_ps(wb[1]), v1, *a);
                    *a = _mm256_fmadd_ps(_mm256_set1_ps(wb[2]), v2, *a);
                }
            }
        }
        for (a, r) in acc.iter().zip(rows.iter_mut()) {
            if let Some(dst) = r.get_mut(x..x + 8) {
                // SAFETY: `dst` holds exactly 8 f32, written unaligned (AVX guaranteed).
                unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), *a) };
            }
        }
        done = x + 8;
        x += 8;
    }
    done
}
