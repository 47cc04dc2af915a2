//! AVX-512F version of the 3×3 layers' lanes ([`super::conv3_lanes`]):
//! 16-pixel vectors, and with 32 registers `N` groups of them per pass (`N ·
//! OB` accumulators). Masked loads read the zero padding at either end of a
//! row and masked stores end a pass at the strip's end, so every pass takes
//! the same path. Same operations in the same order as the AVX2 version
//! (fused multiply-adds over input channel, kernel row, kernel column), so
//! their outputs are identical.

use super::{Lanes, LEAKY_SLOPE, OB};
use core::arch::x86_64::{
    __m512, _mm512_cmp_ps_mask, _mm512_fmadd_ps, _mm512_mask_mul_ps, _mm512_mask_storeu_ps, _mm512_maskz_loadu_ps, _mm512_set1_ps,
    _mm512_setzero_ps, _CMP_LT_OQ,
};

/// 16-pixel groups per pass.
const N: usize = 2;

/// Bits `j` of a 16-lane mask where `0 ≤ p + j < len`.
#[inline(always)]
fn mask(p: isize, len: usize) -> u16 {
    let lo = (-p).clamp(0, 16) as u32; // lanes before index 0
    let hi = (len as isize - p).clamp(0, 16) as u32; // lanes before index len
    let below_hi = if hi >= 16 { u16::MAX } else { (1u16 << hi) - 1 };
    let below_lo = if lo >= 16 { u16::MAX } else { (1u16 << lo) - 1 };
    below_hi & !below_lo
}

/// [`super::conv3_lanes`] with AVX-512F over output pixels `x0..x1`;
/// returns `x1`.
///
/// # Safety
/// The CPU must support AVX-512F ([`super::Isa::Avx512`] available), and
/// `g.fits()` must hold.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn conv3_lanes(g: &Lanes<'_>, rows: &mut [&mut [f32]; OB], x0: usize, x1: usize) -> usize {
    let (w, plane, ew) = (g.w, g.plane, g.w.div_ceil(2));
    // each tap's values within an input row: (start, length, offset from
    // output pixel x); stride 2 reads odd[x − 1], even[x], odd[x] of the
    // split row [even (ew) | odd (w / 2)]
    let taps: [(usize, usize, isize); 3] =
        if g.stride == 1 { [(0, w, -1), (0, w, 0), (0, w, 1)] } else { [(ew, w / 2, -1), (0, ew, 0), (ew, w / 2, 0)] };
    let mut valid = [(0, 0); 3];
    let mut n = 0;
    for (ky, r) in g.src_rows.iter().enumerate() {
        if let Some(sy) = *r {
            valid[n] = (ky, sy * w);
            n += 1;
        }
    }
    let (base, wbase) = (g.lanes.as_ptr(), g.wts.as_ptr());
    let ow = rows[0].len();
    let mut x = x0;
    while x < x1 {
        // per tap and group: where its 16 values start in a row, and which
        // of them lie inside it (the rest are the zero padding, not read)
        let mut off = [[0isize; N]; 3];
        let mut m = [[0u16; N]; 3];
        for (kx, &(start, len, d)) in taps.iter().enumerate() {
            for k in 0..N {
                let p = (x + 16 * k) as isize + d;
                off[kx][k] = start as isize + p;
                m[kx][k] = mask(p, len);
            }
        }
        let mut acc = [[_mm512_setzero_ps(); OB]; N];
        for ak in acc.iter_mut() {
            for (a, &b) in ak.iter_mut().zip(&g.bias) {
                *a = _mm512_set1_ps(b);
            }
        }
        for i in 0..g.cin {
            for &(ky, ro) in &valid[..n] {
                // (wrapping: a group's first lanes may lie before the row,
                // masked off and not read)
                let row = base.wrapping_add(i * plane + ro);
                let t = (i * 3 + ky) * 3;
                for kx in 0..3 {
                    let mut v: [__m512; N] = [_mm512_setzero_ps(); N];
                    for (k, vk) in v.iter_mut().enumerate() {
                        // SAFETY: `g.fits()`: row sy of plane i lies inside
                        // `lanes`, and the mask keeps the lanes read inside the
                        // tap's part of that row; AVX-512F is guaranteed by the caller.
                        *vk = unsafe { _mm512_maskz_loadu_ps(m[kx][k], row.wrapping_offset(off[kx][k])) };
                    }
                    for b in 0..OB {
                        // SAFETY: `g.fits()`: wts holds cin · 9 · OB values, and
                        // (t + kx) · OB + b < that.
                        let s = _mm512_set1_ps(unsafe { *wbase.add((t + kx) * OB + b) });
                        for (ak, vk) in acc.iter_mut().zip(&v) {
                            ak[b] = _mm512_fmadd_ps(s, *vk, ak[b]);
                        }
                    }
                }
            }
        }
        let end = x1.min(ow);
        let slope = _mm512_set1_ps(LEAKY_SLOPE);
        for (k, ak) in acc.iter().enumerate() {
            let px = x + 16 * k;
            let keep = mask(px as isize, end);
            for (a, r) in ak.iter().zip(rows.iter_mut()) {
                let a = if g.leaky { _mm512_mask_mul_ps(*a, _mm512_cmp_ps_mask::<_CMP_LT_OQ>(*a, _mm512_setzero_ps()), *a, slope) } else { *a };
                // SAFETY: the mask keeps the lanes written inside `r` (px + j <
                // end ≤ r.len()); AVX-512F is guaranteed by the caller.
                unsafe { _mm512_mask_storeu_ps(r.as_mut_ptr().wrapping_add(px), keep, a) };
            }
        }
        x += 16 * N;
    }
    x1
}
