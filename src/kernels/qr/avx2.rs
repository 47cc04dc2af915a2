//! AVX2 + FMA version of the QR's fused column update ([`super::update_and_dot`]),
//! for builds whose `wide` is SSE2: the same loop with `core::arch`
//! intrinsics, chosen at run time by [`crate::isa::Isa`]. (One file per
//! instruction set, as in `nn::conv` and fast_image_resize: `wide`'s methods
//! are not promised to inline into a `#[target_feature]` function.) The
//! same multiply-adds in the same order as the portable version in an
//! `x86-64-v3` build, whose `mul_add` is fused (only the final lane sums may
//! associate differently); against an SSE2 build the products round
//! separately. `qr::tests` compares the two versions; the QR and BMFR tests
//! check whichever the CPU runs against f64.

use core::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_castps256_ps128, _mm256_extractf128_ps, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_set1_ps,
    _mm256_setzero_ps, _mm256_storeu_ps, _mm_add_ps, _mm_add_ss, _mm_cvtss_f32, _mm_movehl_ps, _mm_shuffle_ps,
};

/// `s[i..i + 8]` (a bounds-checked slice, read unaligned).
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn load(s: &[f32], i: usize) -> __m256 {
    let c = &s[i..i + 8];
    // SAFETY: `c` holds exactly 8 f32; AVX is guaranteed by the caller.
    unsafe { _mm256_loadu_ps(c.as_ptr()) }
}

/// Stores `v` into `s[i..i + 8]`.
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn store(s: &mut [f32], i: usize, v: __m256) {
    let c = &mut s[i..i + 8];
    // SAFETY: `c` holds exactly 8 f32; AVX is guaranteed by the caller.
    unsafe { _mm256_storeu_ps(c.as_mut_ptr(), v) }
}

/// The sum of the 8 lanes.
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn reduce_add(v: __m256) -> f32 {
    // SAFETY: AVX (and the SSE it implies) is guaranteed by the caller.
    unsafe {
        let s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let s = _mm_add_ps(s, _mm_movehl_ps(s, s));
        _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps::<0b01>(s, s)))
    }
}

/// [`super::update_and_dot`] with AVX2 + FMA.
///
/// # Safety
/// The CPU must support AVX2 and FMA ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn update_and_dot<const G: usize>(
    v: &[f32],
    s: &[f32],
    cols: [&mut [f32]; G],
    x: Option<&[f32]>,
    lo: usize,
    dots: &mut [f32],
) {
    let rows = v.len();
    let mut cols = cols.map(|c| &mut c[..rows]);
    let x = x.map(|x| &x[..rows]);
    // (loops, not `array::from_fn` or `map`: their closures would not inherit
    // this function's target features)
    let mut acc = [[_mm256_setzero_ps(); 2]; G];
    let mut sv = [_mm256_setzero_ps(); G];
    for c in 0..G {
        sv[c] = _mm256_set1_ps(s[c]);
    }
    let mut i = lo;
    // SAFETY (every `load`/`store` below): AVX2 and FMA are guaranteed by this
    // function's caller; the slices are bounds-checked.
    while i + 16 <= rows {
        let vi = unsafe { [load(v, i), load(v, i + 8)] };
        let mut xi = match x {
            Some(x) => unsafe { [load(x, i), load(x, i + 8)] },
            None => [_mm256_setzero_ps(); 2],
        };
        for c in 0..G {
            for h in 0..2 {
                let o = i + 8 * h;
                let u = _mm256_fmadd_ps(vi[h], sv[c], unsafe { load(cols[c], o) });
                unsafe { store(cols[c], o, u) };
                if c == 0 && x.is_none() {
                    xi[h] = u;
                }
                acc[c][h] = _mm256_fmadd_ps(xi[h], u, acc[c][h]);
            }
        }
        i += 16;
    }
    let mut acc1 = [_mm256_setzero_ps(); G];
    for c in 0..G {
        acc1[c] = _mm256_add_ps(acc[c][0], acc[c][1]);
    }
    while i + 8 <= rows {
        let vi = unsafe { load(v, i) };
        let mut xi = match x {
            Some(x) => unsafe { load(x, i) },
            None => _mm256_setzero_ps(),
        };
        for c in 0..G {
            let u = _mm256_fmadd_ps(vi, sv[c], unsafe { load(cols[c], i) });
            unsafe { store(cols[c], i, u) };
            if c == 0 && x.is_none() {
                xi = u;
            }
            acc1[c] = _mm256_fmadd_ps(xi, u, acc1[c]);
        }
        i += 8;
    }
    let tail = super::update_and_dot_rows(v, s, &mut cols, x, i);
    for c in 0..G {
        dots[c] = unsafe { reduce_add(acc1[c]) } + tail[c];
    }
}
