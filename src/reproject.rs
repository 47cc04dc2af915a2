//! Helpers shared by the temporal pipelines (BMFR, WALR): bilinear
//! reprojection taps and the YCoCg colour space used for history clamping.

/// The 4 bilinear taps `(x, y, weight)` around the continuous pixel
/// position `(px, py)` (pixel centres at integers).
#[inline]
pub fn bilinear_taps(px: f32, py: f32) -> [(i64, i64, f32); 4] {
    let (fx, fy) = (libm::floorf(px), libm::floorf(py));
    let (ax, ay) = (px - fx, py - fy);
    let (ix, iy) = (fx as i64, fy as i64);
    [(ix, iy, (1.0 - ax) * (1.0 - ay)), (ix + 1, iy, ax * (1.0 - ay)), (ix, iy + 1, (1.0 - ax) * ay), (ix + 1, iy + 1, ax * ay)]
}

/// RGB → YCoCg (unnormalised form, ×4, as in the BMFR authors' code).
#[inline]
pub fn ycocg(c: [f32; 3]) -> [f32; 3] {
    [c[0] + 2.0 * c[1] + c[2], 2.0 * c[0] - 2.0 * c[2], -c[0] + 2.0 * c[1] - c[2]]
}

/// Inverse of [`ycocg`].
#[inline]
pub fn rgb(c: [f32; 3]) -> [f32; 3] {
    [0.25 * (c[0] + c[1] - c[2]), 0.25 * (c[0] + c[2]), 0.25 * (c[0] - c[1] - c[2])]
}

/// The bilinear reprojection of a 3-plane history (`planes`: 3 planes of
/// `w × h`, plane stride `np`) at `(px, py)`: the weighted mean of the taps
/// whose bit is set in `mask` (bit k = tap k of [`bilinear_taps`]), that lie
/// in the image and hold finite values; `None` if no tap qualifies.
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
