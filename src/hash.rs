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
