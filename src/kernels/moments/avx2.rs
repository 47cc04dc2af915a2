//! AVX2 + FMA version of the block accumulation ([`super::accumulate`]) and
//! of building an in-place block's group vectors ([`super::groups_plain`]), for
//! builds whose `wide` is SSE2: the same loop with `core::arch` intrinsics,
//! chosen at run time by [`crate::isa::Isa`] (one file per instruction set, as
//! in `kernels::qr` and `nn::conv`: `wide`'s methods are not promised to
//! inline into a `#[target_feature]` function). The same operations in the
//! same order as the portable version in an `x86-64-v3` build, whose `mul_add`
//! is fused and whose 8-lane reduction is the same tree, so there the two are
//! bit-identical; against an SSE2 build the products round separately.
//! `moments::tests` compares the two; the FLR tests check whichever the CPU
//! runs against f64.

use super::{eight_at, store_eight, BandRows, MAX_GROUPS, MAX_K, PREFETCH_AHEAD, PREFETCH_L2_AHEAD, VW};
use crate::guides::MAX_GUIDES;
use crate::image::{prefetch, prefetch_l2};
use crate::kernels::{CellLayout, LUMA};
use core::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_andnot_ps, _mm256_blendv_ps, _mm256_cmp_ps, _mm256_div_ps, _mm256_fmadd_ps, _mm256_hadd_ps,
    _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps, _mm256_mul_ps, _mm256_permute2f128_ps, _mm256_set1_ps,
    _mm256_setzero_ps, _mm256_sqrt_ps, _mm256_storeu_ps, _mm256_sub_ps, _CMP_LE_OQ,
};
use wide::f32x8;

/// The 8 lane sums of `v[0..8]`, as `[Σv0, …, Σv7]`, each summed as
/// `((x0 + x1) + (x2 + x3)) + ((x4 + x5) + (x6 + x7))`: the tree of the
/// portable version's transpose and adds.
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn lane_sums(v: &[__m256; 8]) -> __m256 {
    // SAFETY: AVX is guaranteed by the caller.
    unsafe {
        let t0 = _mm256_hadd_ps(v[0], v[1]);
        let t1 = _mm256_hadd_ps(v[2], v[3]);
        let t2 = _mm256_hadd_ps(v[4], v[5]);
        let t3 = _mm256_hadd_ps(v[6], v[7]);
        // per 128-bit half: [v0, v1, v2, v3] (low half: lanes 0-3 summed, high half: 4-7)
        let u0 = _mm256_hadd_ps(t0, t1);
        let u1 = _mm256_hadd_ps(t2, t3);
        _mm256_add_ps(_mm256_permute2f128_ps::<0x20>(u0, u1), _mm256_permute2f128_ps::<0x31>(u0, u1))
    }
}

/// Whether every lane of `v` is finite (`|v| ≤ f32::MAX`; NaN fails).
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn all_finite(v: __m256) -> bool {
    // SAFETY: AVX is guaranteed by the caller.
    unsafe {
        let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(abs, _mm256_set1_ps(f32::MAX))) == 0xff
    }
}

/// [`super::accumulate`] with AVX2 + FMA: the block sums of the group vectors
/// into `acc` (plain sums weighted by `weights` where given); with `check`,
/// `false` as soon as a plain sum is not finite.
///
/// # Safety
/// The CPU must support AVX2 and FMA ([`crate::isa::Isa::Avx2Fma`] available).
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn accumulate<const Q: usize>(
    groups: &[[f32x8; VW]],
    weights: Option<&[f32x8]>,
    sums: &mut [f32x8; MAX_K],
    wsum: f32x8,
    lay: &CellLayout,
    acc: &mut [f32; MAX_K],
    check: bool,
) -> bool {
    // (f32x8 and __m256 are both 32 plain bytes: bytemuck checks size and alignment)
    let groups: &[__m256] = bytemuck::cast_slice(groups.as_flattened());
    let sums: &mut [__m256] = bytemuck::cast_slice_mut(&mut sums[..]);
    let wsum: __m256 = bytemuck::cast(wsum);
    let (zero, luma) = (_mm256_setzero_ps(), LUMA.map(|l| _mm256_set1_ps(l)));
    sums[0] = wsum;
    let mut plain = [zero; VW];
    let mut energy = zero;
    let weights: Option<&[__m256]> = weights.map(bytemuck::cast_slice);
    for (i, vg) in groups.chunks_exact(VW).enumerate() {
        match weights {
            Some(s) => {
                for j in 0..Q + 3 {
                    plain[j] = _mm256_fmadd_ps(s[i], vg[j], plain[j]);
                }
            }
            None => {
                for j in 0..Q + 3 {
                    plain[j] = _mm256_add_ps(plain[j], vg[j]);
                }
            }
        }
        let l = _mm256_fmadd_ps(vg[Q], luma[0], _mm256_fmadd_ps(vg[Q + 1], luma[1], _mm256_mul_ps(vg[Q + 2], luma[2])));
        energy = _mm256_fmadd_ps(l, l, energy);
    }
    if check {
        let mut ok = true;
        for p in &plain[..Q + 3] {
            // SAFETY: AVX is enabled in this function.
            ok &= unsafe { all_finite(*p) };
        }
        if !ok {
            return false;
        }
    }
    sums[lay.s..lay.s + Q].copy_from_slice(&plain[..Q]);
    sums[lay.t..lay.t + 3].copy_from_slice(&plain[Q..Q + 3]);
    sums[lay.e] = energy;
    // S (upper triangle) and P, as in the portable version: per guide `a`,
    // up to ROW products `v_a v_b` (b ≥ a) in registers over the groups.
    const ROW: usize = 8;
    let mut p = lay.ss;
    for a in 0..Q {
        let mut b0 = a;
        while b0 < Q + 3 {
            let nb = (Q + 3 - b0).min(ROW);
            let mut r = [zero; ROW];
            for vg in groups.chunks_exact(VW) {
                let va = vg[a];
                for j in 0..nb {
                    r[j] = _mm256_fmadd_ps(va, vg[b0 + j], r[j]);
                }
            }
            for j in 0..nb {
                let b = b0 + j;
                if b < Q {
                    sums[p] = r[j];
                    p += 1;
                } else {
                    sums[lay.p + 3 * a + (b - Q)] = r[j];
                }
            }
            b0 += nb;
        }
    }
    // (as the portable version: whole runs of eight, no run-time length copies)
    for i in (0..lay.k).step_by(8) {
        let eight = eight_at(sums, i, zero);
        let mut total = [0f32; 8];
        // SAFETY: AVX is enabled in this function; `total` holds 8 f32.
        unsafe { _mm256_storeu_ps(total.as_mut_ptr(), lane_sums(&eight)) };
        store_eight(acc, i, lay.k, &total);
    }
    true
}

/// [`super::groups_plain`] with AVX2: the group vectors of a block read in
/// place, every pixel taken as valid (`e = (g − m) − r`, and the colour,
/// divided by `s(ao)` when the band demodulates). Only subtractions, one
/// division, one square root and min/max, each exactly rounded and in the
/// portable version's order, so the two are bit-identical in every build.
/// Measured in a default (SSE2) build: `wide`'s two-half lanes made building
/// the groups twice the work of the AVX2 accumulation that follows.
///
/// # Safety
/// The CPU must support AVX2. Every row slice of `band` holds `band.width`
/// values, `x0 + block ≤ band.width`, `block % 8 == 0` and `band.rows · block
/// / 8 ≤ MAX_GROUPS` (what `moments_rows` checks before calling).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn groups_plain<const Q: usize>(
    band: &BandRows<'_>,
    x0: usize,
    block: usize,
    r: &[f32; MAX_GUIDES],
    v: &mut [[f32x8; VW]; MAX_GROUPS],
) -> usize {
    // SAFETY (every load below): `x + 8 ≤ band.width ≤ row.len()` by the caller's
    // contract, for x in x0..x0 + block.
    let load = |s: &[f32], x: usize| unsafe { _mm256_loadu_ps(s.as_ptr().add(x)) };
    let (mut mv, mut rv) = ([_mm256_setzero_ps(); MAX_GUIDES], [_mm256_setzero_ps(); MAX_GUIDES]);
    for q in 0..Q {
        mv[q] = _mm256_set1_ps(band.reference[q]);
        rv[q] = _mm256_set1_ps(r[q]);
    }
    let demod = band.demod.filter(|&(a, _)| a < Q).map(|(a, c)| (a, _mm256_set1_ps(c)));
    let (zero, one, max) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0), _mm256_set1_ps(f32::MAX));
    let neg_max = _mm256_sub_ps(zero, max);
    let mut ng = 0;
    for row in &band.planes[..band.rows] {
        for q in 0..Q {
            prefetch(row[3 + q], x0 + PREFETCH_AHEAD);
            prefetch_l2(row[3 + q], x0 + PREFETCH_L2_AHEAD);
        }
        for x in (x0..x0 + block).step_by(8) {
            let vg: &mut [__m256] = bytemuck::cast_slice_mut(&mut v[ng][..]);
            for q in 0..Q {
                vg[q] = _mm256_sub_ps(_mm256_sub_ps(load(row[3 + q], x), mv[q]), rv[q]);
            }
            if let Some((a, c)) = demod {
                // demodulation::inverse8: 1 / √(clamp(finite ? ao : 1, 0, 1) + c)
                let ao = load(row[3 + a], x);
                let finite = _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_andnot_ps(_mm256_set1_ps(-0.0), ao), max);
                let clamped = _mm256_min_ps(_mm256_max_ps(_mm256_blendv_ps(one, ao, finite), zero), one);
                let f = _mm256_div_ps(one, _mm256_sqrt_ps(_mm256_add_ps(clamped, c)));
                for ch in 0..3 {
                    // demodulation::demodulate8: (y · f) clamped to ±MAX, + (y − y)
                    let y = load(row[ch], x);
                    let d = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(y, f), max), neg_max);
                    vg[Q + ch] = _mm256_add_ps(d, _mm256_sub_ps(y, y));
                }
            } else {
                for ch in 0..3 {
                    vg[Q + ch] = load(row[ch], x);
                }
            }
            ng += 1;
        }
    }
    ng
}
