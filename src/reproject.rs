//! Helpers of the temporal stage ([`crate::temporal`]): bilinear
//! reprojection taps and the YCoCg colour space of its history clip.

/// The 4 bilinear taps `(x, y, weight)` around the continuous pixel
/// position `(px, py)` (pixel centres at integers).
#[inline(always)]
pub fn bilinear_taps(px: f32, py: f32) -> [(i64, i64, f32); 4] {
    let (fx, fy) = (floor(px), floor(py));
    let (ax, ay) = (px - fx, py - fy);
    // (a huge or infinite position saturates: its taps are outside any frame)
    let (ix, iy) = (fx as i64, fy as i64);
    let (jx, jy) = (ix.saturating_add(1), iy.saturating_add(1));
    [(ix, iy, (1.0 - ax) * (1.0 - ay)), (jx, iy, ax * (1.0 - ay)), (ix, jy, (1.0 - ax) * ay), (jx, jy, ax * ay)]
}

/// `⌊x⌋` (`libm::floorf` is a software routine; this is a conversion and a
/// compare). NaN, ±Inf and |x| ≥ 2²³ (already integers) come back unchanged.
#[inline(always)]
pub fn floor(x: f32) -> f32 {
    if x.is_nan() || x.abs() >= 8_388_608.0 {
        return x;
    }
    let t = x as i32 as f32; // truncation toward 0, exact here
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// RGB → YCoCg (unnormalised form, ×4, as in the BMFR authors' code).
#[inline(always)]
pub fn ycocg(c: [f32; 3]) -> [f32; 3] {
    [c[0] + 2.0 * c[1] + c[2], 2.0 * c[0] - 2.0 * c[2], -c[0] + 2.0 * c[1] - c[2]]
}

/// Inverse of [`ycocg`].
#[inline(always)]
pub fn rgb(c: [f32; 3]) -> [f32; 3] {
    [0.25 * (c[0] + c[1] - c[2]), 0.25 * (c[0] + c[2]), 0.25 * (c[0] - c[1] - c[2])]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_matches_libm() {
        for x in [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.999_999_8,
            -2.999_999_8,
            8_388_607.5,
            -8_388_607.5,
            1e9,
            -1e9,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            assert_eq!(floor(x), libm::floorf(x), "{x}");
        }
        assert!(floor(f32::NAN).is_nan());
    }

    #[test]
    fn bilinear_taps_of_huge_positions_do_not_overflow() {
        // (found by the walr fuzz target: 1e30 + 1 overflowed i64 in debug builds)
        for p in [1e30f32, f32::INFINITY, -1e30, f32::NEG_INFINITY, 9.3e18] {
            for (x, y, _) in bilinear_taps(p, p) {
                assert!(x.unsigned_abs() > 1 << 40 && y.unsigned_abs() > 1 << 40, "{p}: ({x}, {y})");
            }
        }
        let t = bilinear_taps(2.25, 3.5);
        assert_eq!((t[0].0, t[0].1, t[3].0, t[3].1), (2, 3, 3, 4));
        assert!((t.iter().map(|t| t.2).sum::<f32>() - 1.0).abs() < 1e-6);
    }
}
