//! Stage 3 with [`WalrConfig::adaptive_blend`](super::WalrConfig::adaptive_blend):
//! the fits of the last two windows (`3^T` and `3^(T−1)` wide) blended per
//! pixel by their estimated errors, in two passes.
//!
//! 1. [`Walr::fit_rows`] fits both windows at every pixel and keeps, in the
//!    small window's sums buffer (pixel by pixel, in place: each pixel's sums
//!    are read before its results are written, in the same storage),
//!    the planes `[fit_L (3), fit_S (3), d², var_S, var_L]`: `d` the
//!    luminance difference of the two fits (large − small), the variances
//!    `var = σ² · lev / W` (W: each window's true sample count, `lev` =
//!    `xᵀ A⁻¹ x` the pixel's leverage), the noise `σ² = rss_S · W_S / (W_S −
//!    m)` from the small window's residual (the large one's also holds its
//!    bias).
//! 2. [`Walr::blend_rows`] averages `d², var_S, var_L` over a box as wide as
//!    the small window (clipped to the frame; vertical averages go to the
//!    large window's buffer, free by then, as f32), turns them into the small
//!    window's weight and writes `fit_L + w·(fit_S − fit_L)`. Weights are
//!    `1 / (bias² + variance)`: the large window's bias² `= max(d² −
//!    K·(var_S − var_L), 0)` (`d`'s own variance is about `var_S − var_L`),
//!    the small one's taken as 0, so `w = (var_L + bias²) / (var_S + var_L +
//!    bias²)` in [0, 1] (0, the large window, where undefined).
//!
//! Per pixel the estimates are too noisy to choose by (a per-pixel weight
//! scored no better than the fixed blend on the training frames); averaged
//! over the small window they choose well (`docs/METHODS.md`, WALR).
//! Both passes work on bands of rows; pass 2 reads pass 1's results of the
//! rows around its band, so all of pass 1 must be done first.

use super::regress::{output_value, WindowFit};
use super::store::Store;
use super::{Prepared, Report, Storage, Walr};
use crate::error::{Arg, Error};
use crate::image::ImageViewMut;
use crate::kernels::cholesky::Lane;
use wide::f32x8;

/// Planes pass 1 leaves per pixel: two fits, then the three statistics.
const P_STATS: usize = 6;

/// Discount `K` of the variance difference in the large window's bias
/// estimate (module doc). Chosen on the training frames, where 0.5 and 2
/// scored lower.
pub const BLEND_BIAS_DISCOUNT: f32 = 1.0;
/// Cap of the stored statistics (f16 holds them; see [`window_stats`]).
const STAT_MAX: f32 = 60000.0;

/// What the adaptive blend needs of one pixel, from its two windows' fits:
/// `[d², var_S, var_L]` with
/// * noise `σ² = rss_S · W_S / (W_S − m)` (the small window's residual: the
///   large one's also holds its bias),
/// * variances `var = σ² · lev / W` (W: each window's true sample count),
/// * `d` the luminance difference of the two fits (large − small),
///
/// each capped at 60000 (so that f16 storage holds it).
#[inline(always)]
pub(crate) fn window_stats<T: Lane>(large: &WindowFit<T>, small: &WindowFit<T>, w_large: T, w_small: T, m: f32) -> [T; 3] {
    let (zero, one, tiny) = (T::splat(0.0), T::splat(1.0), T::splat(1e-30));
    // min(v, cap) as −max(−v, −cap): exact (NaN becomes the cap)
    let cap = |v: T| zero - (zero - v).max_(T::splat(-STAT_MAX));
    let sigma2 = small.rss.max_(zero) * w_small / (w_small - T::splat(m)).max_(one);
    let var_s = sigma2 * small.lev / w_small.max_(tiny);
    let var_l = sigma2 * large.lev / w_large.max_(tiny);
    let luma = crate::kernels::LUMA.map(T::splat);
    let lum = |y: &[T; 3]| luma[0] * y[0] + luma[1] * y[1] + luma[2] * y[2];
    let d = lum(&large.y) - lum(&small.y);
    [cap(d * d), cap(var_s), cap(var_l)]
}

/// The small window's weight `w` from the statistics of [`window_stats`]
/// averaged around the pixel, weights `1 / (bias² + variance)`: the large
/// window's bias² `= max(d² − K·(var_S − var_L), 0)` (`d`'s own variance is
/// about `var_S − var_L`; K = [`BLEND_BIAS_DISCOUNT`]), the small one's taken
/// as 0, so `w = (var_L + bias²) / (var_S + var_L + bias²)`, in [0, 1]
/// (0, the large window, where undefined).
#[inline(always)]
pub(crate) fn blend_weight<T: Lane>([d2, var_s, var_l]: [T; 3]) -> T {
    let (zero, tiny) = (T::splat(0.0), T::splat(1e-30));
    let bias2 = (d2 - T::splat(BLEND_BIAS_DISCOUNT) * (var_s - var_l).max_(zero)).max_(zero);
    let num = var_l + bias2;
    let w = (num / (var_s + num).max_(tiny)).max_(zero);
    // min(w, 1), exactly
    zero - (zero - w).max_(T::splat(-1.0))
}

impl Walr {
    /// Whether stage 3 is the two-pass adaptive blend ([`Walr::fit_rows`],
    /// [`Walr::blend_rows`]) rather than [`Walr::solve_rows`]: the
    /// configuration asks for it and there are two windows (T ≥ 2).
    pub fn blends_adaptively(&self) -> bool {
        self.cfg.adaptive_blend && self.cfg.iterations >= 2
    }

    /// Half-width of the box the statistics are averaged over: the small
    /// window's, `(3^(T−1) − 1) / 2`.
    pub fn blend_radius(&self) -> usize {
        (3usize.pow(self.cfg.iterations.saturating_sub(1) as u32) - 1) / 2
    }

    /// Adaptive stage 3, pass 1, on rows `y0..`: reads the sums of both
    /// windows (`last_rows`: those rows of `z[buffer_of(T)]`, `prev_rows`:
    /// of `z[buffer_of(T − 1)]`) and overwrites `prev_rows` with each pixel's
    /// two fits and statistics. Returns the fallback count (as
    /// [`Walr::solve_rows`]).
    pub fn fit_rows(&self, y0: usize, geo: &[f32], last_rows: &[f32], prev_rows: &mut [f32]) -> Result<Report, Error> {
        let (w, h, zl) = (self.width, self.height, self.z_row_len());
        if !self.blends_adaptively() {
            return Err(Error::Unsupported("fit_rows: the configuration has no adaptive blend (use solve_rows)"));
        }
        let rows = self.check_band(y0, prev_rows.len(), zl)?;
        if last_rows.len() != prev_rows.len() || geo.len() < h * self.geo_row_len() {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        macro_rules! go {
            ($s:ty, $last:expr, $prev:expr) => {{
                match self.m {
                    3 => self.fit_impl::<$s, 3>(y0, rows, w, geo, $last, $prev),
                    4 => self.fit_impl::<$s, 4>(y0, rows, w, geo, $last, $prev),
                    5 => self.fit_impl::<$s, 5>(y0, rows, w, geo, $last, $prev),
                    6 => self.fit_impl::<$s, 6>(y0, rows, w, geo, $last, $prev),
                    7 => self.fit_impl::<$s, 7>(y0, rows, w, geo, $last, $prev),
                    8 => self.fit_impl::<$s, 8>(y0, rows, w, geo, $last, $prev),
                    _ => Err(Error::InvalidConfig("feature count")),
                }
            }};
        }
        match self.cfg.storage {
            Storage::F32 => go!(f32, last_rows, prev_rows),
            Storage::F16 => go!(u16, bytemuck::cast_slice(last_rows), bytemuck::cast_slice_mut(prev_rows)),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn fit_impl<S: Store, const M: usize>(
        &self,
        y0: usize,
        rows: usize,
        w: usize,
        geo: &[f32],
        last: &[S],
        prev: &mut [S],
    ) -> Result<Report, Error> {
        let (zl, ps) = (self.z_row_values(), self.plane_stride());
        let gl = self.geo_row_len();
        let simd = self.cfg.kernel == crate::isa::Kernel::Simd;
        // true sample counts from the stored W (f16 stores 9^−t W_t)
        let t = self.cfg.iterations as u32;
        let true_w = |t: u32| (0..t).fold(1f32, |a, _| a / S::STEP);
        let (scale_l, scale_s) = (f32x8::splat(true_w(t)), f32x8::splat(true_w(t - 1)));
        let mut rep = Report::default();
        for r in 0..rows {
            let grow = &geo[(y0 + r) * gl..(y0 + r + 1) * gl];
            let lrow = &last[r * zl..(r + 1) * zl];
            let prow = &mut prev[r * zl..(r + 1) * zl];
            let mut x0 = 0;
            while x0 < w {
                let n = if simd && x0 + 8 <= w { 8 } else { 1 };
                let (large, wl, fallback) = self.fit_group::<S, M>(lrow, grow, x0, n, true);
                let (small, ws, _) = self.fit_group::<S, M>(prow, grow, x0, n, true);
                rep.fallback_pixels += fallback;
                let stats = window_stats(&large, &small, wl * scale_l, ws * scale_s, M as f32);
                // (plane by plane from registers: a chained iterator over the
                // three arrays went through a stack copy, whose reloads
                // stalled on store forwarding: a third of this pass)
                for c in 0..3 {
                    put(prow, c * ps + x0, n, large.y[c]);
                    put(prow, (3 + c) * ps + x0, n, small.y[c]);
                    put(prow, (6 + c) * ps + x0, n, stats[c]);
                }
                x0 += n;
            }
        }
        Ok(rep)
    }

    /// Adaptive stage 3, pass 2, on rows `y0..y0 + out.height()`: `prev` is
    /// the whole frame's `z[buffer_of(T − 1)]` after [`Walr::fit_rows`] ran
    /// on every row, `last_rows` those rows of `z[buffer_of(T)]` (overwritten:
    /// working space). Writes the blended light to `out` (those rows).
    pub fn blend_rows(
        &self,
        p: &Prepared,
        y0: usize,
        prev: &[f32],
        last_rows: &mut [f32],
        out: &mut ImageViewMut<'_>,
    ) -> Result<(), Error> {
        let (w, h, zl) = (self.width, self.height, self.z_row_len());
        let rows = out.height();
        if out.width() != w || out.channel_count() < 3 || y0 + rows > h {
            return Err(Error::SizeMismatch { arg: Arg::Output, expected: (w, h - y0.min(h)), got: (out.width(), rows) });
        }
        if !self.blends_adaptively() {
            return Err(Error::Unsupported("blend_rows: the configuration has no adaptive blend (use solve_rows)"));
        }
        if prev.len() < h * zl || last_rows.len() != rows * zl {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        match self.cfg.storage {
            Storage::F32 => self.blend_impl::<f32>(p, y0, prev, last_rows, out),
            Storage::F16 => self.blend_impl::<u16>(p, y0, bytemuck::cast_slice(prev), last_rows, out),
        }
    }

    /// Pass 2 for storage `S`; `tmp` (f32 whatever the storage: a band of
    /// rows of the other sums buffer) holds each row's vertical averages.
    fn blend_impl<S: Store>(&self, p: &Prepared, y0: usize, prev: &[S], tmp: &mut [f32], out: &mut ImageViewMut<'_>) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        let (zl, ps, tl) = (self.z_row_values(), self.plane_stride(), self.z_row_len());
        let rad = self.blend_radius();
        let simd = self.cfg.kernel == crate::isa::Kernel::Simd;
        let (scale, clamp) = (p.light_scale, self.cfg.clamp_negative);
        let fix = |v: f32| output_value(v, scale, clamp);
        for r in 0..out.height() {
            let y = y0 + r;
            // Vertical averages of the statistics over rows ya..=yb into
            // planes 0..3 of `trow` (f32), a whole row at a time, rows in
            // threes from ya: `acc += (a + b) + c`. The rows are read as
            // streams, and every pixel's sum is the same additions in the same
            // order on every path and for any band. (Summing up to 8 output
            // rows' windows in one sweep, each input row fetched once, was
            // slower: 27 passes over the accumulators instead of 9.)
            let trow = &mut tmp[r * tl..(r + 1) * tl];
            let (ya, yb) = (y.saturating_sub(rad), (y + rad).min(h - 1));
            let inv_v = 1.0 / (yb - ya + 1) as f32;
            for k in 0..3 {
                let acc = &mut trow[k * ps..k * ps + w];
                acc.fill(0.0);
                let mut yy = ya;
                while yy <= yb {
                    let row = |i: usize| {
                        let o = (yy + i).min(yb) * zl + (P_STATS + k) * ps;
                        &prev[o..o + w]
                    };
                    let take = (yb + 1 - yy).min(3);
                    let (a, b, c) = (row(0), row(1), row(2));
                    let mut x = 0;
                    if simd {
                        while x + 8 <= w {
                            let mut v = S::load8(a, x);
                            if take > 1 {
                                v += S::load8(b, x);
                            }
                            if take > 2 {
                                v += S::load8(c, x);
                            }
                            let sum = <f32 as Store>::load8(acc, x) + v;
                            <f32 as Store>::store8(acc, x, sum);
                            x += 8;
                        }
                    }
                    for x in x..w {
                        let mut v = S::get(a, x);
                        if take > 1 {
                            v += S::get(b, x);
                        }
                        if take > 2 {
                            v += S::get(c, x);
                        }
                        acc[x] += v;
                    }
                    yy += take;
                }
                for v in acc.iter_mut() {
                    *v *= inv_v;
                }
            }
            let trow = &*trow;
            // horizontal averages of those, the weight, the blend
            let prow = &prev[y * zl..(y + 1) * zl];
            let mut x0 = 0;
            while x0 < w {
                let n = if simd && x0 + 8 <= w && x0 >= rad && x0 + 8 + rad <= w { 8 } else { 1 };
                let (xa, xb) = (x0.saturating_sub(rad), (x0 + rad).min(w - 1));
                let inv_h = f32x8::splat(1.0 / (xb - xa + 1) as f32);
                let mut stats = [f32x8::ZERO; 3];
                if n == 8 {
                    let planes: [&[f32]; 3] = core::array::from_fn(|k| &trow[k * ps + xa..k * ps + xb + 8]);
                    for o in 0..xb + 1 - xa {
                        for k in 0..3 {
                            stats[k] += <f32 as Store>::load8(planes[k], o);
                        }
                    }
                } else {
                    for xx in xa..xb + 1 {
                        for k in 0..3 {
                            stats[k] += f32x8::from([trow[k * ps + xx], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
                        }
                    }
                }
                let stats = stats.map(|v| v * inv_h);
                let wt = blend_weight(stats);
                let planes: [[f32; 8]; 3] = core::array::from_fn(|c| {
                    let (fl, fs) = (get(prow, c * ps + x0, n), get(prow, (3 + c) * ps + x0, n));
                    (fl + wt * (fs - fl)).to_array().map(fix)
                });
                out.write_row_n(r, x0, [&planes[0][..n], &planes[1][..n], &planes[2][..n]])
                    .ok_or(Error::InvalidTile { index: y, count: h })?;
                x0 += n;
            }
        }
        Ok(())
    }
}

/// `n` = 8 values from `s[i..]` in lanes, or (`n` = 1) `s[i]` in lane 0.
#[inline(always)]
fn get<S: Store>(s: &[S], i: usize, n: usize) -> f32x8 {
    if n == 8 {
        S::load8(s, i)
    } else {
        f32x8::from([S::get(s, i), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    }
}

/// Stores lanes `..n` (8 or 1) of `v` at `s[i..]`.
#[inline(always)]
fn put<S: Store>(s: &mut [S], i: usize, n: usize, v: f32x8) {
    if n == 8 {
        S::store8(s, i, v);
    } else {
        S::set(s, i, v.to_array()[0]);
    }
}
