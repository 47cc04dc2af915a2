//! The integer hash behind every reproducible "random" choice (BMFR's
//! regularisation noise, WALR's replacement averages): same inputs, same bits,
//! on every platform and in any tile order.

/// C. Wellons' "lowbias32": cheap, well mixed, vectorises.
#[inline(always)]
pub fn lowbias32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// A uniform value in [−1, 1) from the sequence `seed` walks (unit tests'
/// random inputs: reproducible, no dependency).
#[cfg(test)]
pub(crate) fn uniform(seed: &mut u32) -> f64 {
    *seed = lowbias32(*seed);
    (*seed >> 8) as f64 / (1u64 << 24) as f64 * 2.0 - 1.0
}

/// [`lowbias32`] on eight lanes (bit-identical per lane).
#[cfg(feature = "bmfr")]
#[inline(always)]
pub fn lowbias32x8(mut x: wide::u32x8) -> wide::u32x8 {
    use wide::u32x8;
    x ^= x >> 16;
    x *= u32x8::splat(0x7feb_352d);
    x ^= x >> 15;
    x *= u32x8::splat(0x846c_a68b);
    x ^ (x >> 16)
}

#[cfg(all(test, feature = "bmfr"))]
mod tests {
    #[test]
    fn lanes_equal_scalar() {
        for base in [0u32, 1, 0x9E37_79B9, u32::MAX - 3] {
            let x = wide::u32x8::from(core::array::from_fn::<u32, 8, _>(|i| base.wrapping_add(i as u32 * 977)));
            let got = super::lowbias32x8(x).to_array();
            for (i, g) in got.iter().enumerate() {
                assert_eq!(*g, super::lowbias32(base.wrapping_add(i as u32 * 977)));
            }
        }
    }
}
