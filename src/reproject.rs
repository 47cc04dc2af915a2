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
