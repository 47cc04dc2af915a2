//! Stage 3: the per-pixel solve from the final averages (§3.1, Algorithms 1
//! and 2) and the model applied to the pixel's own features.

use super::store::Store;
use super::{Prepared, Report, Storage, Walr, GEO_FIXED, G_VALID};
use crate::config::Kernel;
use crate::error::Error;
use crate::image::ImageViewMut;
use crate::kernels::cholesky::{factor_floor, substitute, Lane};
use wide::f32x8;

/// Solves one pixel (or 8 in lanes): `z` are the averages (sums over W; W last),
/// `x` the pixel's features; returns the light (still divided by the scale).
#[inline(always)]
pub(crate) fn solve_pixel<T: Lane, const M: usize>(z: &[T], x: &[T; M], eps: T) -> [T; 3] {
    let one = T::splat(1.0);
    let mut a = [[one; M]; M];
    let mut k = 0;
    for q in 1..M {
        a[q][0] = z[k];
        a[0][q] = z[k];
        k += 1;
    }
    for p in 1..M {
        for q in p..M {
            a[q][p] = z[k];
            a[p][q] = z[k];
            k += 1;
        }
    }
    let mut b = [[one; 3]; M];
    for c in 0..3 {
        for p in 0..M {
            b[p][c] = z[k];
            k += 1;
        }
    }
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

impl Walr {
    /// Stage 3 on rows `y0..y0 + out.height()`: solves every pixel from the
    /// final sums `z` (divided by their W here) (buffer [`Walr::buffer_of`]`(iterations)`, whole
    /// frame) and writes the light to `out` (those rows only).
    pub fn solve_rows(&self, p: &Prepared, y0: usize, geo: &[f32], z: &[f32], out: &mut ImageViewMut<'_>) -> Result<Report, Error> {
        let (w, h) = (self.width, self.height);
        let rows = out.height();
        if out.width() != w || out.channel_count() < 3 || y0 + rows > h {
            return Err(Error::SizeMismatch { arg: crate::error::Arg::Output, expected: (w, h - y0.min(h)), got: (out.width(), rows) });
        }
        if geo.len() < h * self.geo_row_len() || z.len() < h * self.z_row_len() {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        macro_rules! go {
            ($s:ty, $z:expr) => {
                match self.m {
                    3 => self.solve_impl::<$s, 3>(p, y0, rows, geo, $z, out),
                    4 => self.solve_impl::<$s, 4>(p, y0, rows, geo, $z, out),
                    5 => self.solve_impl::<$s, 5>(p, y0, rows, geo, $z, out),
                    6 => self.solve_impl::<$s, 6>(p, y0, rows, geo, $z, out),
                    7 => self.solve_impl::<$s, 7>(p, y0, rows, geo, $z, out),
                    8 => self.solve_impl::<$s, 8>(p, y0, rows, geo, $z, out),
                    _ => Err(Error::InvalidConfig("feature count")),
                }
            };
        }
        match self.cfg.storage {
            Storage::F32 => go!(f32, z),
            Storage::F16 => go!(u16, bytemuck::cast_slice(z)),
        }
    }

    fn solve_impl<S: Store, const M: usize>(
        &self,
        p: &Prepared,
        y0: usize,
        rows: usize,
        geo: &[f32],
        z: &[S],
        out: &mut ImageViewMut<'_>,
    ) -> Result<Report, Error> {
        let w = self.width;
        let (gp, kp, zl, ps) = (self.geo_planes(), self.planes(), self.z_row_values(), self.plane_stride());
        let mut rep = Report::default();
        let scale = p.light_scale;
        let clamp = self.cfg.clamp_negative;
        let simd = self.cfg.kernel == Kernel::Simd;
        let fix = |v: f32| {
            let v = v * scale;
            let v = if clamp { v.max(0.0) } else { v };
            if v.is_finite() {
                v
            } else {
                0.0
            }
        };
        for r in 0..rows {
            let y = y0 + r;
            let zrow = &z[y * zl..(y + 1) * zl];
            let grow = &geo[y * gp * ps..(y + 1) * gp * ps];
            let mut x0 = 0;
            while x0 < w {
                let n = if simd && x0 + 8 <= w { 8 } else { 1 };
                let mut res = [[0f32; 8]; 3];
                if n == 8 {
                    let mut zv = [f32x8::ZERO; 64];
                    for k in 0..kp {
                        zv[k] = S::load8(zrow, k * ps + x0);
                    }
                    // sums → averages (eq. 6: XX̄ = Σ w X Xᵀ / Σ w)
                    let wsum = zv[kp - 1];
                    let inv = wsum.simd_gt(f32x8::ZERO).select(f32x8::ONE / wsum, f32x8::ZERO);
                    for k in 0..kp - 1 {
                        zv[k] *= inv;
                    }
                    let mut xv = [f32x8::ONE; M];
                    // unknown geometry (NaN/Inf guides, code −1): evaluate at the
                    // window's mean features, i.e. output the weighted mean light
                    let unknown = <f32 as Store>::load8(grow, G_VALID * ps + x0).simd_lt(f32x8::ZERO);
                    for q in 1..M {
                        xv[q] = unknown.select(zv[q - 1], <f32 as Store>::load8(grow, (GEO_FIXED + q - 1) * ps + x0));
                    }
                    rep.fallback_pixels += unknown.to_bitmask().count_ones() as u64;
                    let yv = solve_pixel::<f32x8, M>(&zv[..kp], &xv, f32x8::splat(self.cfg.epsilon));
                    let empty = zv[kp - 1].simd_le(f32x8::ZERO);
                    rep.fallback_pixels += empty.to_bitmask().count_ones() as u64;
                    for c in 0..3 {
                        res[c] = empty.select(f32x8::ZERO, yv[c]).to_array();
                    }
                } else {
                    let mut zs = [0f32; 64];
                    for k in 0..kp {
                        zs[k] = S::get(zrow, k * ps + x0);
                    }
                    let inv = if zs[kp - 1] > 0.0 { 1.0 / zs[kp - 1] } else { 0.0 };
                    for k in 0..kp - 1 {
                        zs[k] *= inv;
                    }
                    let mut xs = [1f32; M];
                    let unknown = grow[G_VALID * ps + x0] < 0.0;
                    for q in 1..M {
                        xs[q] = if unknown { zs[q - 1] } else { grow[(GEO_FIXED + q - 1) * ps + x0] };
                    }
                    rep.fallback_pixels += unknown as u64;
                    let ys = solve_pixel::<f32, M>(&zs[..kp], &xs, self.cfg.epsilon);
                    let empty = !(zs[kp - 1] > 0.0);
                    rep.fallback_pixels += empty as u64;
                    for c in 0..3 {
                        res[c][0] = if empty { 0.0 } else { ys[c] };
                    }
                }
                let planes = res.map(|c| c.map(fix));
                out.write_row_n(r, x0, [&planes[0][..n], &planes[1][..n], &planes[2][..n]])
                    .ok_or(Error::InvalidTile { index: y, count: rows })?;
                x0 += n;
            }
        }
        Ok(rep)
    }
}
