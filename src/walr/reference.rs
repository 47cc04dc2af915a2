//! REFWLR (§6): the slow, exact per-pixel weighted regression WALR
//! approximates, and the oracle of its tests. Same features, edge-stopping
//! function and pivot floor, but every pixel of the `(3^T)²` window is
//! weighted directly — by the minimum of the edge-stopping function along
//! the digital line from the centre (every pixel visited, no SDF, no
//! replacement, no à-trous) — and sums are in f64. With
//! [`WalrConfig::previous_weight`](super::WalrConfig::previous_weight) `w > 0`
//! the fit of the `(3^(T−1))²` window is blended in as WALR does:
//! `(1 − w)·fit_T + w·fit_{T−1}`. O(pixels × window × line length): for
//! small frames only.

use super::store::Store;
use super::{Parts, Report, Storage, Walr, GEO_FIXED, G_INV_SCALE, G_N, G_P, G_VALID, MAX_FEATURES};
use crate::error::Error;
use crate::guides::Frame;
use crate::image::ImageViewMut;

impl Walr {
    /// REFWLR on one frame (slow). Same scratch as [`Walr::denoise`].
    pub fn reference(&self, frame: &Frame<'_>, index: u32, scratch: &mut [f32], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let f = self.check_frame(frame)?;
        self.check_out(out, self.height)?;
        let prep = self.prepare(&f, index);
        let Parts { geo, z: [z0, z1], .. } = self.parts(scratch)?;
        let mut rep = self.features_rows(&f, &prep, 0, geo, z0)?;
        let r = match self.cfg.storage {
            Storage::F32 => self.reference_impl::<f32>(geo, z0, z1, prep.light_scale, out),
            Storage::F16 => self.reference_impl::<u16>(geo, bytemuck::cast_slice(z0), bytemuck::cast_slice_mut(z1), prep.light_scale, out),
        }?;
        rep.fallback_pixels = r;
        if self.blends_adaptively() {
            // the per-pixel fits and statistics are in z1, as `Walr::fit_rows` leaves them
            self.blend_rows(&prep, 0, z1, z0, out)?;
        }
        Ok(rep)
    }

    /// The exact fits at every pixel, blended into `out` — or, with the
    /// adaptive blend, stored into `stats` as [`Walr::fit_rows`] stores them.
    fn reference_impl<S: Store>(
        &self,
        geo: &[f32],
        z0: &[S],
        stats: &mut [S],
        scale: f32,
        out: &mut ImageViewMut<'_>,
    ) -> Result<u64, Error> {
        let (w, h, m) = (self.width as i64, self.height as i64, self.m);
        let (gp, kp, zl, ps) = (self.geo_planes(), self.planes(), self.z_row_values(), self.plane_stride());
        let t = self.cfg.iterations as u32;
        let radius = (3i64.pow(t) - 1) / 2;
        let adaptive = self.blends_adaptively();
        let wp = if t >= 2 { self.cfg.previous_weight as f64 } else { 0.0 };
        // the previous iteration's window (radius −1: none)
        let radius_prev = if wp > 0.0 || adaptive { (3i64.pow(t - 1) - 1) / 2 } else { -1 };
        let g = |c: usize, x: i64, y: i64| geo[(y as usize * gp + c) * ps + x as usize] as f64;
        let (far, range) = (self.cfg.far as f64, (self.cfg.far - self.cfg.near) as f64);
        let weight = |cx: i64, cy: i64, x: i64, y: i64| -> f64 {
            if g(G_VALID, x, y) != g(G_VALID, cx, cy).abs() {
                return 0.0;
            }
            let d: f64 = (0..3).map(|a| g(G_N + a, cx, cy) * (g(G_P + a, x, y) - g(G_P + a, cx, cy))).sum();
            ((far - d.abs() * g(G_INV_SCALE, cx, cy)) / range).clamp(0.0, 1.0)
        };
        let mut fallback = 0;
        for cy in 0..h {
            for cx in 0..w {
                // moments of the stored Z_0 (products, W) with weights w
                let mut sum = [0f64; 64];
                let mut sum_prev = [0f64; 64];
                for y in (cy - radius).max(0)..=(cy + radius).min(h - 1) {
                    for x in (cx - radius).max(0)..=(cx + radius).min(w - 1) {
                        let (dx, dy) = (x - cx, y - cy);
                        let n = dx.abs().max(dy.abs());
                        let mut wt = 1f64;
                        if self.cfg.tracing {
                            for k in 1..=n {
                                let px = cx + round_div(k * dx, n);
                                let py = cy + round_div(k * dy, n);
                                wt = wt.min(weight(cx, cy, px, py));
                                if wt == 0.0 {
                                    break;
                                }
                            }
                        } else if n > 0 {
                            wt = weight(cx, cy, x, y);
                        }
                        if wt == 0.0 {
                            continue;
                        }
                        let base = y as usize * zl + x as usize;
                        let wz = S::get(z0, base + (kp - 1) * ps) as f64;
                        let inner = n <= radius_prev;
                        for k in 0..kp - 1 {
                            let v = wt * wz * S::get(z0, base + k * ps) as f64;
                            sum[k] += v;
                            if inner {
                                sum_prev[k] += v;
                            }
                        }
                        sum[kp - 1] += wt * wz;
                        if inner {
                            sum_prev[kp - 1] += wt * wz;
                        }
                    }
                }
                let mut x = [1f64; MAX_FEATURES];
                for q in 1..m {
                    x[q] = g(GEO_FIXED + q - 1, cx, cy);
                }
                let fit = |sum: &[f64; 64]| {
                    if sum[kp - 1] > 0.0 {
                        let inv = 1.0 / sum[kp - 1];
                        let zz: [f64; 64] = core::array::from_fn(|k| sum[k] * inv);
                        Some(solve_f64(&zz[..kp - 1], &x[..m], self.cfg.epsilon as f64))
                    } else {
                        None
                    }
                };
                if adaptive {
                    let (fl, fs, st) = stats_f64(&sum, &sum_prev, kp, &x[..m], self.cfg.epsilon as f64);
                    fallback += (sum[kp - 1] <= 0.0) as u64;
                    let at = cy as usize * zl + cx as usize;
                    for (k, v) in fl.iter().chain(&fs).chain(&st).enumerate() {
                        S::set(stats, at + k * ps, *v as f32);
                    }
                    continue;
                }
                let mut y = fit(&sum).unwrap_or_else(|| {
                    fallback += 1;
                    [0.0; 3]
                });
                if wp > 0.0 {
                    let yp = fit(&sum_prev).unwrap_or([0.0; 3]);
                    y = core::array::from_fn(|c| (1.0 - wp) * y[c] + wp * yp[c]);
                }
                let v = y.map(|c| {
                    let c = c * scale as f64;
                    let c = if self.cfg.clamp_negative { c.max(0.0) } else { c };
                    if c.is_finite() {
                        c as f32
                    } else {
                        0.0
                    }
                });
                out.write_row_n(cy as usize, cx as usize, [&v[0..1], &v[1..2], &v[2..3]])
                    .ok_or(Error::InvalidTile { index: cy as usize, count: h as usize })?;
            }
        }
        Ok(fallback)
    }
}

/// `round(a / b)` for `b > 0` (halves away from zero).
fn round_div(a: i64, b: i64) -> i64 {
    if a >= 0 {
        (2 * a + b) / (2 * b)
    } else {
        -((-2 * a + b) / (2 * b))
    }
}

/// Runs `$body` with `$xa`, the features `$x` as an array of its length
/// `$m` (a constant: 3..=8), for the const-generic solves.
macro_rules! with_features {
    ($x:expr, $xa:ident, $m:ident, $body:expr) => {{
        macro_rules! arm {
            ($n:literal) => {{
                const $m: usize = $n;
                let mut $xa = [1f64; $m];
                $xa.copy_from_slice($x);
                $body
            }};
        }
        match $x.len() {
            3 => arm!(3),
            4 => arm!(4),
            5 => arm!(5),
            6 => arm!(6),
            7 => arm!(7),
            _ => arm!(8),
        }
    }};
}

/// Both windows' fits in f64 (0 for an empty window) and the statistics of
/// the adaptive blend, from the weighted sums (W last; true sample counts).
fn stats_f64(large: &[f64; 64], small: &[f64; 64], kp: usize, x: &[f64], eps: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
    use super::blend::window_stats;
    use super::regress::fit_stats;
    let avg = |s: &[f64; 64]| -> [f64; 64] {
        let inv = if s[kp - 1] > 0.0 { 1.0 / s[kp - 1] } else { 0.0 };
        core::array::from_fn(|k| s[k] * inv)
    };
    let (zl, zs) = (avg(large), avg(small));
    with_features!(x, xa, M, {
        let mut l = fit_stats::<f64, M>(&zl[..kp], &xa, eps);
        let mut s = fit_stats::<f64, M>(&zs[..kp], &xa, eps);
        if !(large[kp - 1] > 0.0) {
            l.y = [0.0; 3];
        }
        if !(small[kp - 1] > 0.0) {
            s.y = [0.0; 3];
        }
        (l.y, s.y, window_stats(&l, &s, large[kp - 1], small[kp - 1], M as f32))
    })
}

/// The regression of one pixel in f64 with the same floor (Algorithms 1–2).
fn solve_f64(z: &[f64], x: &[f64], eps: f64) -> [f64; 3] {
    with_features!(x, xa, M, super::regress::solve_pixel::<f64, M>(z, &xa, eps))
}
