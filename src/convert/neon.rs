//! NEON version of [`super`]'s conversions (aarch64): eight values per pair of
//! `FCVTL`/`FCVTL2` (f16 → f32) or `FCVTN`/`FCVTN2` (f32 → f16), the tail
//! through an 8-value buffer.
//!
//! Half ↔ single conversion is part of every AArch64 CPU's Advanced SIMD (the
//! FP16 extension adds half arithmetic, not conversion), but `half` converts
//! in software unless the build enables `fp16`, and stable Rust has no
//! `float16x4_t` intrinsics: hence inline assembly. `FCVTN` rounds by FPCR's
//! mode, nearest-even unless the caller changed it, as `half` does.

use core::arch::asm;
use half::f16;

/// Eight halves at `s` to eight floats at `d`.
///
/// # Safety
/// `s` must be valid for reading 16 bytes and `d` for writing 32 bytes.
#[inline]
unsafe fn widen8(s: *const f16, d: *mut f32) {
    // SAFETY: the caller's contract; unaligned LDR/STP of q registers are allowed.
    unsafe {
        asm!(
            "ldr {h:q}, [{s}]",
            "fcvtl {lo:v}.4s, {h:v}.4h",
            "fcvtl2 {hi:v}.4s, {h:v}.8h",
            "stp {lo:q}, {hi:q}, [{d}]",
            s = in(reg) s,
            d = in(reg) d,
            h = out(vreg) _,
            lo = out(vreg) _,
            hi = out(vreg) _,
            options(nostack, preserves_flags),
        )
    };
}

/// Eight floats at `s` to eight halves at `d`.
///
/// # Safety
/// `s` must be valid for reading 32 bytes and `d` for writing 16 bytes.
#[inline]
unsafe fn narrow8(s: *const f32, d: *mut f16) {
    // SAFETY: the caller's contract; unaligned LDP/STR of q registers are allowed.
    unsafe {
        asm!(
            "ldp {lo:q}, {hi:q}, [{s}]",
            "fcvtn {h:v}.4h, {lo:v}.4s",
            "fcvtn2 {h:v}.8h, {hi:v}.4s",
            "str {h:q}, [{d}]",
            s = in(reg) s,
            d = in(reg) d,
            h = out(vreg) _,
            lo = out(vreg) _,
            hi = out(vreg) _,
            options(nostack, preserves_flags),
        )
    };
}

/// [`super::f16_to_f32`] over `min(src.len(), dst.len())` values.
pub(super) fn f16_to_f32(src: &[f16], dst: &mut [f32]) {
    let n = src.len().min(dst.len());
    let mut i = 0;
    while i + 8 <= n {
        let (s, d) = (&src[i..i + 8], &mut dst[i..i + 8]);
        // SAFETY: `s` holds 8 halves (16 bytes) and `d` 8 floats (32 bytes), bounds-checked above.
        unsafe { widen8(s.as_ptr(), d.as_mut_ptr()) };
        i += 8;
    }
    if i < n {
        let (mut h, mut f) = ([f16::ZERO; 8], [0f32; 8]);
        h[..n - i].copy_from_slice(&src[i..n]);
        // SAFETY: as above, on the two 8-value stack buffers.
        unsafe { widen8(h.as_ptr(), f.as_mut_ptr()) };
        dst[i..n].copy_from_slice(&f[..n - i]);
    }
}

/// [`super::f32_to_f16`] over `min(src.len(), dst.len())` values.
pub(super) fn f32_to_f16(src: &[f32], dst: &mut [f16]) {
    let n = src.len().min(dst.len());
    let mut i = 0;
    while i + 8 <= n {
        let (s, d) = (&src[i..i + 8], &mut dst[i..i + 8]);
        // SAFETY: `s` holds 8 floats (32 bytes) and `d` 8 halves (16 bytes), bounds-checked above.
        unsafe { narrow8(s.as_ptr(), d.as_mut_ptr()) };
        i += 8;
    }
    if i < n {
        let (mut f, mut h) = ([0f32; 8], [f16::ZERO; 8]);
        f[..n - i].copy_from_slice(&src[i..n]);
        // SAFETY: as above, on the two 8-value stack buffers.
        unsafe { narrow8(f.as_ptr(), h.as_mut_ptr()) };
        dst[i..n].copy_from_slice(&h[..n - i]);
    }
}
