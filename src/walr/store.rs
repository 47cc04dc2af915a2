//! The two storage formats of the sums: f32, or f16 bits in `u16`.

use half::f16;
use half::slice::HalfBitsSliceExt;
use wide::f32x8;

/// A stored sample type (f32 or f16 bits).
pub(crate) trait Store: bytemuck::Pod {
    /// Factor applied to an iteration's sums before they are stored: 1 for
    /// f32; 1/9 for f16, so that `9^{−t} S_t` stays within f16's range (a
    /// 3×3 step multiplies a sum by at most 9).
    const STEP: f32;
    fn get(s: &[Self], i: usize) -> f32;
    fn set(s: &mut [Self], i: usize, v: f32);
    /// Values `i..i + 8` (bounds-checked).
    fn load8(s: &[Self], i: usize) -> f32x8;
    /// Values `i..i + 8`, unchecked.
    ///
    /// # Safety
    /// `i + 8 ≤ s.len()`.
    unsafe fn load8_unchecked(s: &[Self], i: usize) -> f32x8;
    fn store8(s: &mut [Self], i: usize, v: f32x8);
}

impl Store for f32 {
    const STEP: f32 = 1.0;
    #[inline(always)]
    fn get(s: &[Self], i: usize) -> f32 {
        s[i]
    }
    #[inline(always)]
    fn set(s: &mut [Self], i: usize, v: f32) {
        s[i] = v;
    }
    #[inline(always)]
    fn load8(s: &[Self], i: usize) -> f32x8 {
        let c = &s[i..i + 8];
        // SAFETY: `c` holds exactly 8 f32 (the slice above is bounds-checked).
        unsafe { Self::load8_unchecked(c, 0) }
    }
    #[inline(always)]
    unsafe fn load8_unchecked(s: &[Self], i: usize) -> f32x8 {
        debug_assert!(i + 8 <= s.len());
        // SAFETY: the caller guarantees i + 8 ≤ s.len(); an unaligned read of
        // 8 f32 is a valid f32x8.
        unsafe { core::ptr::read_unaligned(s.as_ptr().add(i) as *const f32x8) }
    }
    #[inline(always)]
    fn store8(s: &mut [Self], i: usize, v: f32x8) {
        let c = &mut s[i..i + 8];
        // SAFETY: as in `load8`, 8 writable f32.
        unsafe { core::ptr::write_unaligned(c.as_mut_ptr() as *mut f32x8, v) }
    }
}

impl Store for u16 {
    const STEP: f32 = 1.0 / 9.0;
    #[inline(always)]
    fn get(s: &[Self], i: usize) -> f32 {
        f16::from_bits(s[i]).to_f32()
    }
    #[inline(always)]
    fn set(s: &mut [Self], i: usize, v: f32) {
        s[i] = f16::from_f32(v).to_bits();
    }
    #[inline(always)]
    fn load8(s: &[Self], i: usize) -> f32x8 {
        let mut a = [0f32; 8];
        // F16C where the CPU has it (`convert`)
        crate::convert::f16_to_f32(s[i..i + 8].reinterpret_cast::<f16>(), &mut a);
        f32x8::from(a)
    }
    #[inline(always)]
    unsafe fn load8_unchecked(s: &[Self], i: usize) -> f32x8 {
        debug_assert!(i + 8 <= s.len());
        // SAFETY: the caller guarantees i + 8 ≤ s.len().
        let c = unsafe { s.get_unchecked(i..i + 8) };
        let mut a = [0f32; 8];
        crate::convert::f16_to_f32(c.reinterpret_cast::<f16>(), &mut a);
        f32x8::from(a)
    }
    #[inline(always)]
    fn store8(s: &mut [Self], i: usize, v: f32x8) {
        crate::convert::f32_to_f16(v.as_array(), s[i..i + 8].reinterpret_cast_mut::<f16>());
    }
}
