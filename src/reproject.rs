//! Helpers shared by the temporal pipelines (FLR's stage, BMFR, WALR):
//! bilinear reprojection taps and the YCoCg colour space used for history clamping.

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

/// The bilinear reprojection of a 3-plane history (`planes`: 3 planes of
/// `w × h`, plane stride `np`) at `(px, py)`: the weighted mean of the taps
/// whose bit is set in `mask` (bit k = tap k of [`bilinear_taps`]), that lie
/// in the image and hold finite values; `None` if no tap qualifies.
#[cfg(any(feature = "bmfr", feature = "walr"))]
pub fn reproject3(planes: &[f32], np: usize, (w, h): (usize, usize), (px, py): (f32, f32), mask: u32) -> Option<[f32; 3]> {
    let (mut tw, mut sum) = (0f32, [0f32; 3]);
    for (k, (tx, ty, wt)) in bilinear_taps(px, py).into_iter().enumerate() {
        if mask & (1 << k) == 0 || tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 || wt.is_nan() || wt <= 0.0 {
            continue;
        }
        let j = ty as usize * w + tx as usize;
        let v = [planes[j], planes[np + j], planes[2 * np + j]];
        if v.iter().all(|v| v.is_finite()) {
            tw += wt;
            for c in 0..3 {
                sum[c] += wt * v[c];
            }
        }
    }
    (tw > 0.0).then(|| sum.map(|v| v / tw))
}

#[cfg(feature = "bmfr")]
/// The YCoCg clamp box of one row of pixels, from the rows above, at and
/// below (`None` outside the image), each 3 planes of `w` in YCoCg: per
/// channel, the mean of the 3×3 box's and the 5-pixel cross's minimum (and
/// maximum), as in the BMFR authors' TAA. `lo`, `hi`: 3 planes of `w`.
pub fn clamp_box_row(above: Option<&[f32]>, row: &[f32], below: Option<&[f32]>, w: usize, lo: &mut [f32], hi: &mut [f32]) {
    for c in 0..3 {
        let cur = &row[c * w..(c + 1) * w];
        let (lo, hi) = (&mut lo[c * w..(c + 1) * w], &mut hi[c * w..(c + 1) * w]);
        // vertical extremes of the column (the cross's vertical arm and the box's columns)
        for x in 0..w {
            let (mut a, mut b) = (cur[x], cur[x]);
            for r in [above, below].into_iter().flatten() {
                a = a.min(r[c * w + x]);
                b = b.max(r[c * w + x]);
            }
            lo[x] = a;
            hi[x] = b;
        }
        // box = horizontal extremes of the column extremes; cross = column
        // extremes of the centre column with the centre row's neighbours
        let (mut pl, mut ph) = (f32::INFINITY, f32::NEG_INFINITY); // column x − 1
        let (mut pcl, mut pch) = (f32::INFINITY, f32::NEG_INFINITY); // pixel x − 1 of the row
        for x in 0..w {
            let (cl, ch) = (lo[x], hi[x]);
            let (nl, nh) = if x + 1 < w { (lo[x + 1], hi[x + 1]) } else { (f32::INFINITY, f32::NEG_INFINITY) };
            let (ncl, nch) = if x + 1 < w { (cur[x + 1], cur[x + 1]) } else { (f32::INFINITY, f32::NEG_INFINITY) };
            let box_lo = pl.min(cl).min(nl);
            let box_hi = ph.max(ch).max(nh);
            let cross_lo = cl.min(pcl).min(ncl);
            let cross_hi = ch.max(pch).max(nch);
            (pl, ph, pcl, pch) = (cl, ch, cur[x], cur[x]);
            lo[x] = 0.5 * (box_lo + cross_lo);
            hi[x] = 0.5 * (box_hi + cross_hi);
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::{vec, vec::Vec};

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

    /// The row-wise clamp box equals the per-pixel 3×3 box / cross extremes.
    #[cfg(feature = "bmfr")]
    #[test]
    fn clamp_box_matches_per_pixel() {
        for (w, h) in [(1, 1), (1, 4), (5, 1), (7, 3), (9, 6)] {
            let v: Vec<f32> = (0..3 * w * h).map(|i| ((i * 7919) % 101) as f32 - 50.0).collect();
            let row =
                |y: usize| -> Vec<f32> { (0..3).flat_map(|c| (0..w).map(move |x| (c, x))).map(|(c, x)| v[(y * w + x) * 3 + c]).collect() };
            for y in 0..h {
                let (above, cur, below) = ((y > 0).then(|| row(y - 1)), row(y), (y + 1 < h).then(|| row(y + 1)));
                let (mut lo, mut hi) = (vec![0.0; 3 * w], vec![0.0; 3 * w]);
                clamp_box_row(above.as_deref(), &cur, below.as_deref(), w, &mut lo, &mut hi);
                for x in 0..w {
                    for c in 0..3 {
                        let (mut b, mut cr) = ((f32::INFINITY, f32::NEG_INFINITY), (f32::INFINITY, f32::NEG_INFINITY));
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                let (sx, sy) = (x as i64 + dx, y as i64 + dy);
                                if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
                                    continue;
                                }
                                let s = v[(sy as usize * w + sx as usize) * 3 + c];
                                b = (b.0.min(s), b.1.max(s));
                                if dx == 0 || dy == 0 {
                                    cr = (cr.0.min(s), cr.1.max(s));
                                }
                            }
                        }
                        assert_eq!((lo[c * w + x], hi[c * w + x]), (0.5 * (b.0 + cr.0), 0.5 * (b.1 + cr.1)), "{w}x{h} ({x},{y}) c{c}");
                    }
                }
            }
        }
    }
}
