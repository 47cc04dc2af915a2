//! Stage 3: the per-pixel solve from the final averages (§3.1, Algorithms 1
//! and 2) and the model applied to the pixel's own features.

use super::store::Store;
use super::{Prepared, Report, Storage, Walr, GEO_FIXED, G_VALID};
use crate::error::Error;
use crate::image::ImageViewMut;
use crate::isa::Kernel;
use crate::kernels::cholesky::{factor_floor, forward, substitute, Lane};
use wide::f32x8;

/// The moment matrix `A` (`A₀₀ = 1`, the rest from the averages `z`) and the
/// colours' right-hand sides `E[x y_c]` (the first 3 of `R` columns of `b`,
/// the others 0); returns them and the index in `z` of the next stored value.
#[inline(always)]
fn system<T: Lane, const M: usize, const R: usize>(z: &impl Fn(usize) -> T) -> ([[T; M]; M], [[T; R]; M], usize) {
    let mut a = [[T::splat(1.0); M]; M];
    let mut k = 0;
    for q in 1..M {
        let v = z(k);
        a[q][0] = v;
        a[0][q] = v;
        k += 1;
    }
    for p in 1..M {
        for q in p..M {
            let v = z(k);
            a[q][p] = v;
            a[p][q] = v;
            k += 1;
        }
    }
    let mut b = [[T::splat(0.0); R]; M];
    for c in 0..3 {
        for p in 0..M {
            b[p][c] = z(k);
            k += 1;
        }
    }
    (a, b, k)
}

/// Solves one pixel (or 8 in lanes): `z` are the averages (sums over W; W last),
/// `x` the pixel's features; returns the light (still divided by the scale).
#[inline(always)]
pub(crate) fn solve_pixel<T: Lane, const M: usize>(z: &[T], x: &[T; M], eps: T) -> [T; 3] {
    solve_pixel_with::<T, M>(&|k| z[k], x, eps)
}

/// [`solve_pixel`] with average `k` read by `z(k)` (the lanes' path: loaded
/// and divided by W where used, no copy of the averages).
#[inline(always)]
fn solve_pixel_with<T: Lane, const M: usize>(z: &impl Fn(usize) -> T, x: &[T; M], eps: T) -> [T; 3] {
    let one = T::splat(1.0);
    let (mut a, mut b, _) = system::<T, M, 3>(z);
    let mut eps_v = [eps; M];
    eps_v[0] = one;
    let inv = factor_floor(&mut a, &eps_v);
    substitute(&a, &inv, &mut b);
    let mut y = [T::splat(0.0); 3];
    for c in 0..3 {
        for p in 0..M {
            y[c] = y[c] + x[p] * b[p][c];
        }
    }
    y
}

/// One window's fit at a pixel and what [`blend_adaptive`] needs from it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WindowFit<T> {
    /// The light (still divided by the scale).
    pub y: [T; 3],
    /// Residual luminance variance in the window, `E[ℓ²] − |C⁻¹ E[xℓ]|²`.
    pub rss: T,
    /// Leverage `xᵀ A⁻¹ x = |C⁻¹ x|²` of the pixel's features (≥ 1 with the
    /// constant feature): the fit's variance is `σ² · lev / W`.
    pub lev: T,
}

/// [`solve_pixel`] through the factor's forward substitution alone, with the
/// window's residual variance and the pixel's leverage: `u = C⁻¹ E[xy]`,
/// `v = C⁻¹ x`, `ŷ = v·u` (the same fit: `xᵀ C⁻ᵀ C⁻¹ E[xy]`). `z` are the
/// averages (sums over W; energy at `z[planes − 2]` = `z[k_energy]`).
#[inline(always)]
pub(crate) fn fit_stats<T: Lane, const M: usize>(z: &[T], x: &[T; M], eps: T) -> WindowFit<T> {
    fit_stats_with::<T, M>(&|k| z[k], x, eps)
}

/// [`fit_stats`] with average `k` read by `z(k)` (as [`solve_pixel_with`]).
#[inline(always)]
fn fit_stats_with<T: Lane, const M: usize>(z: &impl Fn(usize) -> T, x: &[T; M], eps: T) -> WindowFit<T> {
    let one = T::splat(1.0);
    let zero = T::splat(0.0);
    // right-hand sides: the three colours, then the features themselves
    let (mut a, mut b, k) = system::<T, M, 4>(z);
    for p in 0..M {
        b[p][3] = x[p];
    }
    let energy = z(k) * T::splat(1.0 / super::features::ENERGY_SCALE);
    let mut eps_v = [eps; M];
    eps_v[0] = one;
    let inv = factor_floor(&mut a, &eps_v);
    forward(&a, &inv, &mut b);
    let luma = crate::kernels::LUMA.map(T::splat);
    let (mut y, mut explained, mut lev) = ([zero; 3], zero, zero);
    for row in &b {
        for c in 0..3 {
            y[c] = y[c] + row[3] * row[c];
        }
        let ul = luma[0] * row[0] + luma[1] * row[1] + luma[2] * row[2];
        explained = explained + ul * ul;
        lev = lev + row[3] * row[3];
    }
    WindowFit { y, rss: energy - explained, lev }
}

/// A pixel's output from its fitted light `v` (divided by the frame's light
/// `scale`): scaled back, clamped at 0 with `clamp`, 0 if not finite.
#[inline(always)]
pub(crate) fn output_value(v: f32, scale: f32, clamp: bool) -> f32 {
    let v = v * scale;
    let v = if clamp { v.max(0.0) } else { v };
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

impl Walr {
    /// Stage 3 on rows `y0..y0 + out.height()`: solves every pixel from the
    /// final sums (divided by their W here) and writes the light to `out`
    /// (those rows only). `z` is the pair of sum buffers of [`Walr::parts`]
    /// (whole frame): the final sums are `z[buffer_of(iterations)]`; with
    /// [`WalrConfig::previous_weight`](super::WalrConfig::previous_weight) `w > 0` (and T ≥ 2) the
    /// fit of the previous iteration's sums, `z[buffer_of(iterations − 1)]`,
    /// is blended in: `(1 − w)·fit_T + w·fit_{T−1}`.
    pub fn solve_rows(&self, p: &Prepared, y0: usize, geo: &[f32], z: [&[f32]; 2], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let (w, h) = (self.width, self.height);
        let rows = out.height();
        if out.width() != w || out.channel_count() < 3 || y0 + rows > h {
            return Err(Error::SizeMismatch { arg: crate::error::Arg::Output, expected: (w, h - y0.min(h)), got: (out.width(), rows) });
        }
        if geo.len() < h * self.geo_row_len() || z.iter().any(|z| z.len() < h * self.z_row_len()) {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        if self.blends_adaptively() {
            return Err(Error::Unsupported("solve_rows: the configuration blends adaptively (use fit_rows, then blend_rows)"));
        }
        let t = self.cfg.iterations;
        let last = z[Self::buffer_of(t)];
        let wp = self.cfg.previous_weight;
        let prev = (t >= 2 && wp > 0.0).then(|| (z[Self::buffer_of(t - 1)], wp));
        macro_rules! go {
            ($s:ty, $cast:expr) => {{
                let prev = prev.map(|(z, w)| ($cast(z), w));
                match self.m {
                    3 => self.solve_impl::<$s, 3>(p, y0, rows, geo, $cast(last), prev, out),
                    4 => self.solve_impl::<$s, 4>(p, y0, rows, geo, $cast(last), prev, out),
                    5 => self.solve_impl::<$s, 5>(p, y0, rows, geo, $cast(last), prev, out),
                    6 => self.solve_impl::<$s, 6>(p, y0, rows, geo, $cast(last), prev, out),
                    7 => self.solve_impl::<$s, 7>(p, y0, rows, geo, $cast(last), prev, out),
                    8 => self.solve_impl::<$s, 8>(p, y0, rows, geo, $cast(last), prev, out),
                    _ => Err(Error::InvalidConfig("feature count")),
                }
            }};
        }
        fn as_f32(z: &[f32]) -> &[f32] {
            z
        }
        fn as_f16_bits(z: &[f32]) -> &[u16] {
            bytemuck::cast_slice(z)
        }
        match self.cfg.storage {
            Storage::F32 => go!(f32, as_f32),
            Storage::F16 => go!(u16, as_f16_bits),
        }
    }

    /// [`Walr::solve_rows`] for storage `S` and `M` features: the fit of
    /// `z` at every pixel of the rows, blended with the fit of `prev`'s sums
    /// (weight `w`) when given.
    #[allow(clippy::too_many_arguments)]
    fn solve_impl<S: Store, const M: usize>(
        &self,
        p: &Prepared,
        y0: usize,
        rows: usize,
        geo: &[f32],
        z: &[S],
        prev: Option<(&[S], f32)>,
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        let w = self.width;
        let zl = self.z_row_values();
        let mut rep = Report::default();
        let scale = p.light_scale;
        let clamp = self.cfg.clamp_negative;
        let simd = self.cfg.kernel == Kernel::Simd;
        let fix = |v: f32| output_value(v, scale, clamp);
        for r in 0..rows {
            let y = y0 + r;
            let grow = &geo[y * self.geo_planes() * self.plane_stride()..(y + 1) * self.geo_planes() * self.plane_stride()];
            let mut x0 = 0;
            while x0 < w {
                let n = if simd && x0 + 8 <= w { 8 } else { 1 };
                let (large, _, fallback) = self.fit_group::<S, M>(&z[y * zl..(y + 1) * zl], grow, x0, n, false);
                rep.fallback_pixels += fallback;
                let mut res = large.y;
                if let Some((zp, wp)) = prev {
                    // the previous window's fit (its fallbacks are the same pixels' or fewer)
                    let (small, _, _) = self.fit_group::<S, M>(&zp[y * zl..(y + 1) * zl], grow, x0, n, false);
                    let (a, b) = (f32x8::splat(1.0 - wp), f32x8::splat(wp));
                    for c in 0..3 {
                        res[c] = a * large.y[c] + b * small.y[c];
                    }
                }
                let res = res.map(|c| c.to_array());
                let planes = res.map(|c| c.map(fix));
                out.write_row_n(r, x0, [&planes[0][..n], &planes[1][..n], &planes[2][..n]])
                    .ok_or(Error::InvalidTile { index: y, count: rows })?;
                x0 += n;
            }
        }
        Ok(rep)
    }

    /// The fit at pixels `x0..x0 + n` (n = 8: in lanes; n = 1: scalar, in
    /// lane 0) of one row from its sums `zrow` and geometry row `grow`, the
    /// stored sample count W, and how many of them fell back (unknown
    /// geometry: the window's mean light; an empty window: 0). With `stats`
    /// the fit goes through [`fit_stats`] (residual variance and leverage for
    /// [`blend_adaptive`]), else through [`solve_pixel`] (`rss`, `lev` = 0).
    #[inline(always)]
    pub(crate) fn fit_group<S: Store, const M: usize>(
        &self,
        zrow: &[S],
        grow: &[f32],
        x0: usize,
        n: usize,
        stats: bool,
    ) -> (WindowFit<f32x8>, f32x8, u64) {
        let (kp, ps) = (self.planes(), self.plane_stride());
        let eps = self.cfg.epsilon;
        let mut fallback = 0u64;
        if n == 8 {
            // sums → averages (eq. 6: XX̄ = Σ w X Xᵀ / Σ w), each loaded and
            // divided where the solve uses it (no copy: zeroing a copy cost
            // a third of this stage)
            let wsum = S::load8(zrow, (kp - 1) * ps + x0);
            let inv = wsum.simd_gt(f32x8::ZERO).select(f32x8::ONE / wsum, f32x8::ZERO);
            let z = |k: usize| S::load8(zrow, k * ps + x0) * inv;
            let mut xv = [f32x8::ONE; M];
            // unknown geometry (NaN/Inf guides, code −1): evaluate at the
            // window's mean features, i.e. output the weighted mean light
            let unknown = <f32 as Store>::load8(grow, G_VALID * ps + x0).simd_lt(f32x8::ZERO);
            for q in 1..M {
                xv[q] = unknown.select(z(q - 1), <f32 as Store>::load8(grow, (GEO_FIXED + q - 1) * ps + x0));
            }
            fallback += unknown.to_bitmask().count_ones() as u64;
            let mut fit = if stats {
                fit_stats_with::<f32x8, M>(&z, &xv, f32x8::splat(eps))
            } else {
                WindowFit { y: solve_pixel_with::<f32x8, M>(&z, &xv, f32x8::splat(eps)), rss: f32x8::ZERO, lev: f32x8::ZERO }
            };
            let empty = wsum.simd_le(f32x8::ZERO);
            fallback += empty.to_bitmask().count_ones() as u64;
            fit.y = fit.y.map(|c| empty.select(f32x8::ZERO, c));
            (fit, wsum, fallback)
        } else {
            let wsum = S::get(zrow, (kp - 1) * ps + x0);
            let inv = if wsum > 0.0 { 1.0 / wsum } else { 0.0 };
            let z = |k: usize| S::get(zrow, k * ps + x0) * inv;
            let mut xs = [1f32; M];
            let unknown = grow[G_VALID * ps + x0] < 0.0;
            for q in 1..M {
                xs[q] = if unknown { z(q - 1) } else { grow[(GEO_FIXED + q - 1) * ps + x0] };
            }
            fallback += unknown as u64;
            let fit = if stats {
                fit_stats_with::<f32, M>(&z, &xs, eps)
            } else {
                WindowFit { y: solve_pixel_with::<f32, M>(&z, &xs, eps), rss: 0.0, lev: 0.0 }
            };
            let empty = !(wsum > 0.0);
            fallback += empty as u64;
            let lane0 = |v: f32| f32x8::from([v, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
            let y = fit.y.map(|c| lane0(if empty { 0.0 } else { c }));
            (WindowFit { y, rss: lane0(fit.rss), lev: lane0(fit.lev) }, lane0(wsum), fallback)
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// `fit_stats` against the textbook f64 least squares on samples: the fit,
    /// the residual variance `E[ℓ²] − β_ℓ·E[xℓ]` and the leverage `xᵀA⁻¹x`.
    #[test]
    fn fit_stats_matches_f64_least_squares() {
        let mut seed = 7u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f64 / (1u32 << 24) as f64
        };
        for case in 0..20 {
            const M: usize = 4;
            let n = 30 + case * 7;
            // samples: features in [0, 1], light affine in them plus noise
            let xs: std::vec::Vec<[f64; M]> = (0..n).map(|_| [1.0, rnd(), rnd(), rnd()]).collect();
            let ys: std::vec::Vec<[f64; 3]> =
                xs.iter().map(|x| core::array::from_fn(|c| 0.5 + x[1] * (c as f64 + 1.0) - x[2] + 0.3 * rnd())).collect();
            let luma = crate::kernels::LUMA.map(|v| v as f64);
            let lum = |y: &[f64; 3]| luma[0] * y[0] + luma[1] * y[1] + luma[2] * y[2];
            // averages in the stored order (as the features stage writes them, / W)
            let nf = n as f64;
            let mut z = std::vec::Vec::new();
            for q in 1..M {
                z.push(xs.iter().map(|x| x[q]).sum::<f64>() / nf);
            }
            for p in 1..M {
                for q in p..M {
                    z.push(xs.iter().map(|x| x[p] * x[q]).sum::<f64>() / nf);
                }
            }
            for c in 0..3 {
                for p in 0..M {
                    z.push(xs.iter().zip(&ys).map(|(x, y)| x[p] * y[c]).sum::<f64>() / nf);
                }
            }
            let e: f64 = ys.iter().map(|y| lum(y) * lum(y)).sum::<f64>() / nf;
            z.push(e * super::super::features::ENERGY_SCALE as f64);
            // textbook: A β = b by Gaussian elimination
            let mut a = [[0f64; M]; M];
            let mut b = [[0f64; 3]; M];
            for (x, y) in xs.iter().zip(&ys) {
                for p in 0..M {
                    for q in 0..M {
                        a[p][q] += x[p] * x[q] / nf;
                    }
                    for c in 0..3 {
                        b[p][c] += x[p] * y[c] / nf;
                    }
                }
            }
            let solve = |rhs: [f64; M]| -> [f64; M] {
                let (mut m, mut v) = (a, rhs);
                for i in 0..M {
                    for r in i + 1..M {
                        let f = m[r][i] / m[i][i];
                        for k in i..M {
                            m[r][k] -= f * m[i][k];
                        }
                        v[r] -= f * v[i];
                    }
                }
                let mut out = [0f64; M];
                for i in (0..M).rev() {
                    out[i] = (v[i] - (i + 1..M).map(|k| m[i][k] * out[k]).sum::<f64>()) / m[i][i];
                }
                out
            };
            let x0 = [1.0, rnd(), rnd(), rnd()];
            let beta: [[f64; M]; 3] = core::array::from_fn(|c| solve(core::array::from_fn(|p| b[p][c])));
            let want_y: [f64; 3] = core::array::from_fn(|c| (0..M).map(|p| x0[p] * beta[c][p]).sum());
            let bl: [f64; M] = core::array::from_fn(|p| (0..3).map(|c| luma[c] * beta[c][p]).sum());
            let el: [f64; M] = core::array::from_fn(|p| (0..3).map(|c| luma[c] * b[p][c]).sum());
            let want_rss = e - (0..M).map(|p| bl[p] * el[p]).sum::<f64>();
            let ainv_x = solve(x0);
            let want_lev: f64 = (0..M).map(|p| x0[p] * ainv_x[p]).sum();
            // f64 lanes (tiny floor: not engaged) and f32
            let got = fit_stats::<f64, M>(&z, &x0, 1e-12);
            let z32: std::vec::Vec<f32> = z.iter().map(|&v| v as f32).collect();
            let got32 = fit_stats::<f32, M>(&z32, &x0.map(|v| v as f32), 1e-7);
            for c in 0..3 {
                assert!((got.y[c] - want_y[c]).abs() < 1e-9, "case {case}: y {c}");
                assert!((got32.y[c] as f64 - want_y[c]).abs() < 2e-3, "case {case}: f32 y {c}");
            }
            assert!((got.rss - want_rss).abs() < 1e-9 * e, "case {case}: rss {} vs {want_rss}", got.rss);
            assert!(want_rss > 0.0 && (got32.rss as f64 - want_rss).abs() < 0.05 * want_rss, "case {case}: f32 rss");
            assert!((got.lev - want_lev).abs() < 1e-9 * want_lev && want_lev >= 1.0 - 1e-9, "case {case}: lev");
        }
    }
}
