//! Half-precision conversion of contiguous runs: F16C chosen at run time on
//! x86-64, NEON's conversions on aarch64, `half`'s software elsewhere.
//!
//! `half`'s slice conversions use the F16C instructions only where the build
//! enables them (`-C target-cpu=x86-64-v3`) or, with `half`'s `std` feature,
//! after run-time detection. This crate's core is `no_std`, so a plain build
//! (the C library, a Rust crate on the default features) would convert every
//! half in software, which measured about 2.4× FLR's time on 1080p f16 inputs
//! (x86-64 baseline build, one thread). Here F16C is
//! taken whenever the CPU has it ([`crate::isa::f16c_available`]); both
//! directions give the same bits as `half` (f16 → f32 is exact; f32 → f16
//! rounds to nearest even and keeps NaNs quiet NaNs), which the tests check.
//! On aarch64 `half` would convert in software too (it takes the hardware
//! only in builds with the `fp16` feature), so the `neon` file runs on every
//! little-endian aarch64 target with NEON (all the common ones): every
//! AArch64 CPU converts in hardware.

#[cfg(target_arch = "x86_64")]
mod f16c;
#[cfg(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little"))]
mod neon;

use half::f16;
#[cfg(not(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little")))]
use half::slice::HalfFloatSliceExt;

/// Whether this build must take the F16C file (it lacks F16C at compile time,
/// where `half` would use it itself) and the CPU has it.
#[cfg(target_arch = "x86_64")]
#[inline]
fn use_f16c() -> bool {
    !cfg!(target_feature = "f16c") && crate::isa::f16c_available()
}

/// `dst[i] = src[i]` as f32 for `i < min(src.len(), dst.len())` (exact).
#[inline]
pub fn f16_to_f32(src: &[f16], dst: &mut [f32]) {
    let n = src.len().min(dst.len());
    let (src, dst) = (&src[..n], &mut dst[..n]);
    #[cfg(target_arch = "x86_64")]
    if use_f16c() {
        // SAFETY: the CPU has F16C and the OS saves the AVX state (`f16c_available`).
        unsafe { f16c::f16_to_f32(src, dst) };
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little"))]
    neon::f16_to_f32(src, dst);
    #[cfg(not(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little")))]
    src.convert_to_f32_slice(dst);
}

/// `dst[i] = src[i]` rounded to f16 (nearest, ties to even; out of range → ±∞,
/// NaN → a quiet NaN) for `i < min(src.len(), dst.len())`.
#[inline]
pub fn f32_to_f16(src: &[f32], dst: &mut [f16]) {
    let n = src.len().min(dst.len());
    let (src, dst) = (&src[..n], &mut dst[..n]);
    #[cfg(target_arch = "x86_64")]
    if use_f16c() {
        // SAFETY: as in `f16_to_f32`.
        unsafe { f16c::f32_to_f16(src, dst) };
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little"))]
    neon::f32_to_f16(src, dst);
    #[cfg(not(all(target_arch = "aarch64", target_feature = "neon", target_endian = "little")))]
    dst.convert_from_f32_slice(src);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every f16 bit pattern converts to the bits `half`'s software routine gives
    /// (NaNs: to a NaN), through the dispatching function and, where the CPU
    /// has F16C, through the F16C file itself, at every run length 0..=19.
    #[test]
    fn f16_to_f32_matches_half_for_every_half() {
        let all: [f16; 65536] = core::array::from_fn(|b| f16::from_bits(b as u16));
        let mut out = [0f32; 65536];
        let check = |out: &[f32]| {
            for (h, v) in all.iter().zip(out) {
                let want = h.to_f32_const(); // `half`'s software routine
                assert!(v.to_bits() == want.to_bits() || (v.is_nan() && want.is_nan()), "{:#06x}: {v} vs {want}", h.to_bits());
            }
        };
        f16_to_f32(&all, &mut out);
        check(&out);
        #[cfg(target_arch = "x86_64")]
        if crate::isa::f16c_available() {
            out.fill(0.0);
            // SAFETY: the CPU has F16C (checked).
            unsafe { f16c::f16_to_f32(&all, &mut out) };
            check(&out);
        }
        for len in 0..20 {
            let mut o = [0f32; 19];
            f16_to_f32(&all[1000..1000 + len], &mut o[..len]);
            check_prefix(&all[1000..1000 + len], &o[..len]);
            assert!(o[len..].iter().all(|&v| v == 0.0), "len {len}: wrote past the run");
        }
    }

    fn check_prefix(h: &[f16], o: &[f32]) {
        for (h, v) in h.iter().zip(o) {
            assert_eq!(v.to_bits(), h.to_f32_const().to_bits());
        }
    }

    /// f32 → f16 gives `half`'s software bits (NaN: a NaN) for specials, every rounding
    /// boundary region, subnormals, overflow and a sweep of bit patterns.
    #[test]
    fn f32_to_f16_matches_half() {
        let mut vals = alloc_free_values();
        let n = vals.len();
        let mut out = [f16::ZERO; 4096];
        let check = |v: &[f32], out: &[f16]| {
            for (x, h) in v.iter().zip(out) {
                let want = f16::from_f32_const(*x); // `half`'s software routine
                assert!(
                    h.to_bits() == want.to_bits() || (h.is_nan() && want.is_nan()),
                    "{x:e} ({:#010x}): {:#06x} vs {:#06x}",
                    x.to_bits(),
                    h.to_bits(),
                    want.to_bits()
                );
            }
        };
        f32_to_f16(&vals[..n], &mut out[..n]);
        check(&vals[..n], &out[..n]);
        #[cfg(target_arch = "x86_64")]
        if crate::isa::f16c_available() {
            out.fill(f16::ZERO);
            // SAFETY: the CPU has F16C (checked).
            unsafe { f16c::f32_to_f16(&vals[..n], &mut out[..n]) };
            check(&vals[..n], &out[..n]);
        }
        for len in 0..20 {
            let mut o = [f16::ONE; 19];
            f32_to_f16(&vals[..len], &mut o[..len]);
            check(&vals[..len], &o[..len]);
            assert!(o[len..].iter().all(|&h| h == f16::ONE), "len {len}: wrote past the run");
        }
        vals.reverse();
        f32_to_f16(&vals[..n], &mut out[..n]);
        check(&vals[..n], &out[..n]);
    }

    /// 4096 test inputs: specials, values around f16's limits and rounding
    /// ties, and bit patterns spread over all of f32.
    fn alloc_free_values() -> [f32; 4096] {
        let mut v = [0f32; 4096];
        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7f80_0001),
            f32::from_bits(0xffc0_1234), // signalling and payload NaNs
            65504.0,
            65519.99,
            65520.0,
            -65520.0,
            1e6,
            -1e30,
            f32::MAX,
            f32::MIN_POSITIVE,
            6.103_515_6e-5,
            6.0e-5,
            5.960_464_5e-8,
            2.980_232_2e-8,
            2.980_233e-8,
            1e-10,
            -1e-10,
            1.000_488_3,
            1.000_976_6,
            1.001_464_8,
            2049.0,
            2051.0,
            0.333_333_34,
            1e-8,
            1e4 + 0.5,
        ];
        v[..specials.len()].copy_from_slice(&specials);
        let mut x: u32 = 0x9e37_79b9;
        for (i, s) in v.iter_mut().enumerate().skip(specials.len()) {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *s = if i % 2 == 0 {
                f32::from_bits(x) // anywhere in f32
            } else {
                // inside f16's range, often exactly on a tie: the low 13 mantissa bits 0x1000
                let e = 103 + (x >> 27) % 40; // 2^-24 .. 2^15
                f32::from_bits((x & 0x8000_0000) | (e << 23) | (x & 0x007f_e000) | if x & 4 == 0 { 0x1000 } else { x & 0x1fff })
            };
        }
        v
    }
}
