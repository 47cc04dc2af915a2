//! The two storage formats of the averages: f32, or f16 bits in `u16`.

use half::f16;
use wide::f32x8;

/// A stored sample type (f32 or f16 bits).
pub(crate) trait Store: bytemuck::Pod {
    fn get(s: &[Self], i: usize) -> f32;
    fn set(s: &mut [Self], i: usize, v: f32);
    #[inline(always)]
    fn load8(s: &[Self], i: usize) -> f32x8 {
        let mut a = [0f32; 8];
        let src = &s[i..i + 8];
        for (d, v) in a.iter_mut().zip(src) {
            *d = Self::get(core::slice::from_ref(v), 0);
        }
        f32x8::from(a)
    }
    #[inline(always)]
    fn store8(s: &mut [Self], i: usize, v: f32x8) {
        let a = v.to_array();
        for (k, x) in a.into_iter().enumerate() {
            Self::set(s, i + k, x);
        }
    }
}

impl Store for f32 {
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
        // SAFETY: `c` holds exactly 8 f32 (the slice above is bounds-checked);
        // an unaligned read of them is a valid f32x8.
        unsafe { core::ptr::read_unaligned(c.as_ptr() as *const f32x8) }
    }
    #[inline(always)]
    fn store8(s: &mut [Self], i: usize, v: f32x8) {
        let c = &mut s[i..i + 8];
        // SAFETY: as in `load8`, 8 writable f32.
        unsafe { core::ptr::write_unaligned(c.as_mut_ptr() as *mut f32x8, v) }
    }
}

impl Store for u16 {
    #[inline(always)]
    fn get(s: &[Self], i: usize) -> f32 {
        f16::from_bits(s[i]).to_f32()
    }
    #[inline(always)]
    fn set(s: &mut [Self], i: usize, v: f32) {
        s[i] = f16::from_f32(v).to_bits();
    }
}
