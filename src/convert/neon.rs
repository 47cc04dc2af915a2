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
            options(nostack),
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
            options(nostack),
        )
    };
}

/// Converts `min(src.len(), dst.len())` values eight at a time with `conv8`,
/// the tail through 8-value stack buffers.
///
/// # Safety
/// `conv8(s, d)` must read at most 8 values at `s` and write at most 8 at `d`.
#[inline]
unsafe fn by_eights<S: Copy + Default, D: Copy + Default>(src: &[S], dst: &mut [D], conv8: unsafe fn(*const S, *mut D)) {
    let n = src.len().min(dst.len());
    let mut i = 0;
    while i + 8 <= n {
        let (s, d) = (&src[i..i + 8], &mut dst[i..i + 8]);
        // SAFETY: `s` and `d` hold 8 values each, bounds-checked by the slicing; the caller's contract on `conv8`.
        unsafe { conv8(s.as_ptr(), d.as_mut_ptr()) };
        i += 8;
    }
    if i < n {
        let (mut s, mut d) = ([S::default(); 8], [D::default(); 8]);
        s[..n - i].copy_from_slice(&src[i..n]);
        // SAFETY: as above, on the two 8-value stack buffers.
        unsafe { conv8(s.as_ptr(), d.as_mut_ptr()) };
        dst[i..n].copy_from_slice(&d[..n - i]);
    }
}

/// [`super::f16_to_f32`] over `min(src.len(), dst.len())` values.
pub(super) fn f16_to_f32(src: &[f16], dst: &mut [f32]) {
    // SAFETY: `widen8` reads 8 halves and writes 8 floats.
    unsafe { by_eights(src, dst, widen8) }
}

/// [`super::f32_to_f16`] over `min(src.len(), dst.len())` values.
pub(super) fn f32_to_f16(src: &[f32], dst: &mut [f16]) {
    // SAFETY: `narrow8` reads 8 floats and writes 8 halves.
    unsafe { by_eights(src, dst, narrow8) }
}
