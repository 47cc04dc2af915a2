//! AVX-512F versions of the 3×3 layers' lanes, 16-pixel vectors with 32
//! registers:
//! * [`conv3_lanes`] (the stride-2 layers): [`super::conv3_lanes`] with `N`
//!   groups per pass (`N · OB` accumulators), the same fused multiply-adds in
//!   the same order as the AVX2 version, so their outputs are identical;
//! * [`winograd_row`] (the stride-1 layers): Winograd's F(2, 3) along the
//!   row, four products per pair of outputs and kernel row instead of six.
//!
//! Masked loads read the zero padding at either end of a row and masked
//! stores end a pass at the row's or the strip's end, so every pass takes
//! the same path.

use super::{Lanes, Planes, LEAKY_SLOPE, OB};
use core::arch::x86_64::{
    __m512, _mm512_add_ps, _mm512_alignr_epi32, _mm512_castps_si512, _mm512_castsi512_ps, _mm512_cmp_ps_mask, _mm512_fmadd_ps,
    _mm512_loadu_si512, _mm512_mask_mul_ps, _mm512_mask_storeu_ps, _mm512_maskz_loadu_ps, _mm512_permutex2var_ps, _mm512_set1_ps,
    _mm512_setzero_ps, _mm512_sub_ps, _mm_prefetch, _CMP_LT_OQ, _MM_HINT_T0,
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
    let (valid, n) = super::rows_inside(&g.src_rows, w);
    let (base, wbase) = (g.lanes.as_ptr(), g.wts.as_ptr());
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
                // the next pass's values of the first two taps' parts of the
                // row (stride 2: odd and even; stride 1: the same part)
                for o in [off[0][0], off[1][0]] {
                    _mm_prefetch::<_MM_HINT_T0>(row.wrapping_offset(o + 16 * N as isize).cast());
                    _mm_prefetch::<_MM_HINT_T0>(row.wrapping_offset(o + 16 * N as isize + 16).cast());
                }
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
        let slope = _mm512_set1_ps(LEAKY_SLOPE);
        for (k, ak) in acc.iter().enumerate() {
            let px = x + 16 * k;
            for (a, r) in ak.iter().zip(rows.iter_mut()) {
                let keep = mask(px as isize, x1.min(r.len()));
                let a =
                    if g.leaky { _mm512_mask_mul_ps(*a, _mm512_cmp_ps_mask::<_CMP_LT_OQ>(*a, _mm512_setzero_ps()), *a, slope) } else { *a };
                // SAFETY: the mask keeps the lanes written inside `r` (px + j <
                // r.len()); AVX-512F is guaranteed by the caller.
                unsafe { _mm512_mask_storeu_ps(r.as_mut_ptr().wrapping_add(px), keep, a) };
            }
        }
        x += 16 * N;
    }
    x1
}

/// One output row of a stride-1 layer's blocks in Winograd's F(2, 3) along
/// the row: per input channel and kernel row, output pixels 2m and 2m + 1
/// take the input values d0..d3 at 2m − 1..2m + 2 and four products instead
/// of six,
///
/// ```text
/// m1 = (d0 − d2)·g0   m2 = (d1 + d2)·(g0 + g1 + g2)/2
/// m3 = (d2 − d1)·(g0 − g1 + g2)/2   m4 = (d1 − d3)·g2
/// y(2m) = m1 + m2 + m3   y(2m + 1) = m2 − m3 − m4
/// ```
///
/// each product summed over the input channels and kernel rows before the
/// two outputs are formed (the bias starts m2's sum). 32 output pixels (16
/// pairs) per pass: the four transformed inputs (d0 − d2, ...) of up to
/// `CH` input channels are computed once into a buffer that every block of
/// output channels reads; with more input channels, each further `CH` adds
/// its outputs to the row. The rounding differs from the direct products'
/// (both are within tests/nn.rs's f64 bound). Pairs start at column 0, so a
/// tile gives the frame's bits only where its columns start even (FLNR's
/// tiles do). Uses 24 KiB of stack for the buffer.
///
/// # Safety
/// The CPU must support AVX-512F, `g.fits()` must hold, and no other live
/// slice covers row `y` of `out`'s planes.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn winograd_row(g: &WinogradRow<'_>, out: &Planes<'_>, y: usize) {
    let (w, plane, cin) = (g.w, g.plane, g.cin);
    let (valid, n) = super::rows_inside(&g.src_rows, w);
    // SAFETY: plain loads of index tables (AVX-512F guaranteed by the caller).
    let (even_i, odd_i, lo_i, hi_i) = unsafe {
        (
            _mm512_loadu_si512(EVEN.as_ptr().cast()),
            _mm512_loadu_si512(ODD.as_ptr().cast()),
            _mm512_loadu_si512(LO.as_ptr().cast()),
            _mm512_loadu_si512(HI.as_ptr().cast()),
        )
    };
    let (base, wbase) = (g.lanes.as_ptr(), g.wino.as_ptr());
    let slope = _mm512_set1_ps(LEAKY_SLOPE);
    let wn = OB * cin * 12; // one block's transformed weights
                            // [input channel − c0][valid row][4]
    let mut ubuf = [_mm512_setzero_ps(); CH * 3 * 4];
    let mut x = 0;
    while x < w {
        // the values at x.. and x + 16.. (the zero padding masked off), and
        // the single values at x − 1 and x + 32 where they lie inside the row
        let xi = x as isize;
        let m = [mask(xi, w), mask(xi + 16, w)];
        let (has_before, has_after) = (x >= 1, x + 32 < w);
        for c0 in (0..cin).step_by(CH) {
            let c1 = (c0 + CH).min(cin);
            for i in c0..c1 {
                for (v, &(_, ro)) in valid[..n].iter().enumerate() {
                    let row = base.wrapping_add(i * plane + ro).wrapping_offset(xi);
                    // SAFETY: `g.fits()`: row sy of plane i lies inside `lanes`,
                    // and the masks keep the lanes read inside it; x − 1 and
                    // x + 32 are read only inside the row. (Loads with only
                    // one lane unmasked ran many times slower on Zen 4.)
                    let [before, l0, l1, after] = unsafe {
                        [
                            _mm512_set1_ps(if has_before { *row.wrapping_sub(1) } else { 0.0 }),
                            _mm512_maskz_loadu_ps(m[0], row),
                            _mm512_maskz_loadu_ps(m[1], row.wrapping_add(16)),
                            _mm512_set1_ps(if has_after { *row.wrapping_add(32) } else { 0.0 }),
                        ]
                    };
                    // the next pass's values: a pass reads 3 · cin rows, more
                    // streams than the hardware prefetcher follows
                    _mm_prefetch::<_MM_HINT_T0>(row.wrapping_add(AHEAD).cast());
                    _mm_prefetch::<_MM_HINT_T0>(row.wrapping_add(AHEAD + 16).cast());
                    let d1 = _mm512_permutex2var_ps(l0, even_i, l1); // d(x + 2j)
                    let d2 = _mm512_permutex2var_ps(l0, odd_i, l1); // d(x + 2j + 1)
                                                                    // d(x + 2j − 1): d(x − 1), then d2 shifted up one lane
                    let d0 = _mm512_castsi512_ps(_mm512_alignr_epi32::<15>(_mm512_castps_si512(d2), _mm512_castps_si512(before)));
                    // d(x + 2j + 2): d1 shifted down one lane, then d(x + 32)
                    let d3 = _mm512_castsi512_ps(_mm512_alignr_epi32::<1>(_mm512_castps_si512(after), _mm512_castps_si512(d1)));
                    let at = ((i - c0) * 3 + v) * 4;
                    ubuf[at] = _mm512_sub_ps(d0, d2);
                    ubuf[at + 1] = _mm512_add_ps(d1, d2);
                    ubuf[at + 2] = _mm512_sub_ps(d2, d1);
                    ubuf[at + 3] = _mm512_sub_ps(d1, d3);
                }
            }
            for k in 0..g.blocks {
                for b0 in (0..OB).step_by(HB) {
                    let mut acc = [[_mm512_setzero_ps(); HB]; 4];
                    if c0 == 0 {
                        for (a, &b) in acc[1].iter_mut().zip(&g.bias[k * OB + b0..]) {
                            *a = _mm512_set1_ps(b);
                        }
                    }
                    for i in c0..c1 {
                        for (v, &(ky, _)) in valid[..n].iter().enumerate() {
                            let u = &ubuf[((i - c0) * 3 + v) * 4..][..4];
                            let t = k * wn + (i * 3 + ky) * 4 * OB + b0;
                            for (j, (aj, uj)) in acc.iter_mut().zip(u).enumerate() {
                                for (b, a) in aj.iter_mut().enumerate() {
                                    // SAFETY: `g.fits()`: wino holds blocks · OB ·
                                    // cin · 12 values, and t + j · OB + b < that.
                                    let s = _mm512_set1_ps(unsafe { *wbase.add(t + j * OB + b) });
                                    *a = _mm512_fmadd_ps(*uj, s, *a);
                                }
                            }
                        }
                    }
                    let [a1, a2, a3, a4] = acc;
                    for (b, (((m1, m2), m3), m4)) in a1.into_iter().zip(a2).zip(a3).zip(a4).enumerate() {
                        let y0 = _mm512_add_ps(_mm512_add_ps(m1, m2), m3);
                        let y1 = _mm512_sub_ps(_mm512_sub_ps(m2, m3), m4);
                        // SAFETY: the caller keeps row y to this call.
                        let r = unsafe { out.row(k * OB + b0 + b, y) };
                        let end = r.len().min(w);
                        for (h, idx) in [lo_i, hi_i].into_iter().enumerate() {
                            let px = x + 16 * h;
                            let keep = mask(px as isize, end);
                            let p = r.as_mut_ptr().wrapping_add(px);
                            let mut a = _mm512_permutex2var_ps(y0, idx, y1);
                            if c0 > 0 {
                                // SAFETY: the mask keeps the lanes read inside `r`.
                                a = _mm512_add_ps(a, unsafe { _mm512_maskz_loadu_ps(keep, p) });
                            }
                            if c1 == cin && g.leaky {
                                a = _mm512_mask_mul_ps(a, _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, _mm512_setzero_ps()), a, slope);
                            }
                            // SAFETY: the mask keeps the lanes written inside `r`
                            // (px + j < end ≤ r.len()); AVX-512F is guaranteed by the caller.
                            unsafe { _mm512_mask_storeu_ps(p, keep, a) };
                        }
                    }
                }
            }
        }
        x += 32;
    }
}

/// How far ahead (in values) [`winograd_row`] prefetches its input rows.
const AHEAD: usize = 64;

/// Input channels transformed at once by [`winograd_row`]: a 24 KiB buffer.
const CH: usize = 32;

/// What [`winograd_row`] reads for one output row of a stride-1 layer.
pub(super) struct WinogradRow<'a> {
    /// The transformed weights of every block, `[block][i · 3 + ky][4][OB]`.
    pub wino: &'a [f32],
    /// Biases of the blocks' channels.
    pub bias: &'a [f32],
    pub blocks: usize,
    pub cin: usize,
    pub lanes: &'a [f32],
    pub w: usize,
    pub plane: usize,
    pub src_rows: [Option<usize>; 3],
    pub leaky: bool,
}

impl WinogradRow<'_> {
    /// Whether every value read lies inside `lanes`, `wino` and `bias`.
    pub fn fits(&self) -> bool {
        self.src_rows.iter().flatten().all(|&sy| (sy + 1) * self.w <= self.plane)
            && self.lanes.len() >= self.cin * self.plane
            && self.wino.len() >= self.blocks * OB * self.cin * 12
            && self.bias.len() >= self.blocks * OB
    }
}

/// Channels of a block accumulated together by [`winograd_row`].
const HB: usize = 3;

/// `_mm512_permutex2var_ps` indices: the even and odd values of two vectors
/// (0..16 the first, 16..32 the second), and the two halves of the
/// interleaving of two vectors.
const EVEN: [i32; 16] = [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30];
const ODD: [i32; 16] = [1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31];
const LO: [i32; 16] = [0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23];
const HI: [i32; 16] = [8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31];
