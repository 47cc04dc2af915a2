//! F16C version of [`super`]'s conversions (x86-64, chosen at run time): eight
//! values per instruction, the tail through an 8-value buffer.

use core::arch::x86_64::{
    __m128i, _mm256_cvtph_ps, _mm256_cvtps_ph, _mm256_loadu_ps, _mm256_storeu_ps, _mm_loadu_si128, _mm_storeu_si128,
    _MM_FROUND_TO_NEAREST_INT,
};
use half::f16;

/// [`super::f16_to_f32`] over `min(src.len(), dst.len())` values.
///
/// # Safety
/// The CPU must have F16C and the OS must save the AVX state
/// ([`crate::isa::f16c_available`]).
#[target_feature(enable = "avx,f16c")]
pub(super) unsafe fn f16_to_f32(src: &[f16], dst: &mut [f32]) {
    let n = src.len().min(dst.len());
    let mut i = 0;
    while i + 8 <= n {
        let (s, d) = (&src[i..i + 8], &mut dst[i..i + 8]);
        // SAFETY: `s` holds 8 halves (16 bytes) and `d` 8 floats (bounds-checked
        // slices above); both accesses are unaligned loads and stores.
        unsafe { _mm256_storeu_ps(d.as_mut_ptr(), _mm256_cvtph_ps(_mm_loadu_si128(s.as_ptr() as *const __m128i))) };
        i += 8;
    }
    if i < n {
        let (mut h, mut f) = ([f16::ZERO; 8], [0f32; 8]);
        h[..n - i].copy_from_slice(&src[i..n]);
        // SAFETY: as above, on the two 8-value stack buffers.
        unsafe { _mm256_storeu_ps(f.as_mut_ptr(), _mm256_cvtph_ps(_mm_loadu_si128(h.as_ptr() as *const __m128i))) };
        dst[i..n].copy_from_slice(&f[..n - i]);
    }
}

/// [`super::f32_to_f16`] over `min(src.len(), dst.len())` values.
///
/// # Safety
/// As [`f16_to_f32`].
#[target_feature(enable = "avx,f16c")]
pub(super) unsafe fn f32_to_f16(src: &[f32], dst: &mut [f16]) {
    let n = src.len().min(dst.len());
    let mut i = 0;
    while i + 8 <= n {
        let (s, d) = (&src[i..i + 8], &mut dst[i..i + 8]);
        // SAFETY: `s` holds 8 floats and `d` 8 halves (16 bytes), bounds-checked above.
        unsafe {
            _mm_storeu_si128(d.as_mut_ptr() as *mut __m128i, _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(s.as_ptr())))
        };
        i += 8;
    }
    if i < n {
        let (mut f, mut h) = ([0f32; 8], [f16::ZERO; 8]);
        f[..n - i].copy_from_slice(&src[i..n]);
        // SAFETY: as above, on the two 8-value stack buffers.
        unsafe {
            _mm_storeu_si128(h.as_mut_ptr() as *mut __m128i, _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(f.as_ptr())))
        };
        dst[i..n].copy_from_slice(&h[..n - i]);
    }
}
