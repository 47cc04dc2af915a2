//! One edge-aware à-trous iteration with edge tracing (§3.2, §3.3, §5.2).
//!
//! `Z_{t+1}(x) = Σ_u f(x,u) W_t(x+u) Z_t(x+u) / Σ_u f(x,u) W_t(x+u)`,
//! `W_{t+1}(x) = Σ_u f(x,u) W_t(x+u)` over the 3×3 taps `u ∈ 3^t·{−1,0,1}²`
//! (the box kernel with `3^t − 1` zeros between taps: every sample is counted
//! once). `f` is the edge-stopping weight: the distance of the tap's position
//! from the plane through the centre position with the centre normal, over
//! the centre's camera distance, mapped to 1 below `near` and 0 beyond `far`;
//! with tracing, its minimum over the pixels of the segment centre → tap.
//!
//! Tracing steps along the segment by `max(1, ⌊sdf_step · sdf_t⌋)` pixels,
//! where `sdf_t(q)` is the distance from `q` to the nearest pixel whose weight
//! (seen from `q`) was below 1 on one of `q`'s segments of the previous
//! iteration (the segment length if none). This iteration writes `sdf_{t+1}`
//! the same way. A tap whose trace meets a zero weight at distance `k` is
//! replaced by the average at a hashed distance in `[⌈k/2⌉, k − 1]` on the
//! same segment, weighted by its own edge-stopping value.
//!
//! Validity codes: a tap counts only if its code equals the centre's
//! *absolute* code. Geometry (1) sees geometry, sky (0) sees sky, and a pixel
//! with NaN/Inf guides (−1) is seen by nobody but sees all geometry (its
//! normal is 0, so every plane distance is 0): it gets its neighbourhood's fit.
//!
//! 8 neighbouring pixels run in `f32x8` lanes when every tap of the group is
//! inside the row; the rest (borders, replacements) runs per pixel.

use super::store::Store;
use super::{Prepared, Storage, Walr, G_INV_SCALE, G_N, G_P, G_VALID};
use crate::config::Kernel;
use crate::error::Error;
use wide::f32x8;

/// The 8 non-centre tap directions, in accumulation order.
const DIRS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Read-only inputs of one iteration.
struct Ctx<'a, S> {
    w: usize,
    h: usize,
    gp: usize,
    ps: usize,
    zl: usize,
    geo: &'a [f32],
    sdf: &'a [f32],
    z: &'a [S],
    inv_range: f32,
    far: f32,
    tracing: bool,
    replace: bool,
    sdf_step: f32,
    seed: u32,
    t: u8,
}

/// The centre pixel of a trace.
#[derive(Clone, Copy)]
struct Centre {
    p: [f32; 3],
    n: [f32; 3],
    inv_scale: f32,
    valid: f32,
}

impl<S: Store> Ctx<'_, S> {
    #[inline(always)]
    fn g(&self, c: usize, x: usize, y: usize) -> f32 {
        self.geo[(y * self.gp + c) * self.ps + x]
    }
    #[inline(always)]
    fn g8(&self, c: usize, x: usize, y: usize) -> f32x8 {
        let i = (y * self.gp + c) * self.ps + x;
        debug_assert!(c < self.gp && x + 8 <= self.w && y < self.h && self.geo.len() >= self.h * self.gp * self.ps);
        // SAFETY: `iterate_rows` checked `geo.len() ≥ h · gp · ps` (ps ≥ w);
        // callers pass y < h, c < gp and x + 8 ≤ w (a group's taps are checked
        // in-row), so i + 8 ≤ geo.len(). An unaligned read of 8 f32 is a valid f32x8.
        unsafe { core::ptr::read_unaligned(self.geo.as_ptr().add(i) as *const f32x8) }
    }
    fn centre(&self, x: usize, y: usize) -> Centre {
        Centre {
            p: [self.g(G_P, x, y), self.g(G_P + 1, x, y), self.g(G_P + 2, x, y)],
            n: [self.g(G_N, x, y), self.g(G_N + 1, x, y), self.g(G_N + 2, x, y)],
            inv_scale: self.g(G_INV_SCALE, x, y),
            valid: self.g(G_VALID, x, y).abs(),
        }
    }
    /// Edge-stopping weight of pixel `(x, y)` seen from `c`.
    #[inline(always)]
    fn weight(&self, c: &Centre, x: usize, y: usize) -> f32 {
        if self.g(G_VALID, x, y) != c.valid {
            return 0.0;
        }
        let d =
            c.n[0] * (self.g(G_P, x, y) - c.p[0]) + c.n[1] * (self.g(G_P + 1, x, y) - c.p[1]) + c.n[2] * (self.g(G_P + 2, x, y) - c.p[2]);
        // the same operations as `weight8`, for bit-identical lanes
        let v = self.far * self.inv_range - d.abs() * (c.inv_scale * self.inv_range);
        // NaN-safe clamp to [0, 1]
        if v >= 1.0 {
            1.0
        } else if v > 0.0 {
            v
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn weight8(&self, c: &[f32x8; 9], x: usize, y: usize) -> f32x8 {
        // c: p (3), n (3), inv_scale / (far − near), |valid|, far / (far − near)
        let d = c[3] * (self.g8(G_P, x, y) - c[0]) + c[4] * (self.g8(G_P + 1, x, y) - c[1]) + c[5] * (self.g8(G_P + 2, x, y) - c[2]);
        let v = (c[8] - d.abs() * c[6]).fast_max(f32x8::ZERO).fast_min(f32x8::ONE);
        self.g8(G_VALID, x, y).simd_eq(c[7]).select(v, f32x8::ZERO)
    }
    /// The most careful SDF step of the 8 pixels `x..x + 8` of row `y`.
    #[inline(always)]
    fn step8(&self, x: usize, y: usize) -> usize {
        let i = y * self.w + x;
        debug_assert!(x + 8 <= self.w && y < self.h && self.sdf.len() >= self.h * self.w);
        // SAFETY: `iterate_rows` checked `sdf.len() ≥ h · w`; y < h, x + 8 ≤ w.
        let v = unsafe { core::ptr::read_unaligned(self.sdf.as_ptr().add(i) as *const f32x8) };
        let m = v.to_array().into_iter().fold(f32::INFINITY, f32::min) * self.sdf_step;
        if m >= 2.0 {
            m as usize
        } else {
            1
        }
    }
    #[inline(always)]
    fn step(&self, x: usize, y: usize) -> usize {
        let s = self.sdf_step * self.sdf[y * self.w + x];
        if s >= 2.0 {
            s as usize
        } else {
            1
        }
    }
    /// The hashed replacement distance for an edge met at distance `k ≥ 1`.
    fn replacement(&self, x: usize, y: usize, dir: usize, k: usize) -> usize {
        let lo = k.div_ceil(2);
        let len = k - lo;
        if len == 0 {
            return 0;
        }
        let key = ((y * self.w + x) as u32).wrapping_mul(8).wrapping_add(dir as u32) ^ ((self.t as u32) << 28);
        lo + (crate::hash::lowbias32(key ^ self.seed) as usize) % len
    }

    /// Traces one tap of pixel `(x, y)` on its own: returns the weight, the
    /// sample's distance along the segment (s, or a replacement, or None) and
    /// the distance of the first weight below 1 (s if none).
    fn trace_pixel(&self, c: &Centre, x: usize, y: usize, dir: usize, s: usize) -> (f32, Option<usize>, usize) {
        let (i, j) = DIRS[dir];
        let (tx, ty) = (x as i64 + i * s as i64, y as i64 + j * s as i64);
        if tx < 0 || ty < 0 || tx >= self.w as i64 || ty >= self.h as i64 {
            return (0.0, None, s);
        }
        let at = |k: usize| ((x as i64 + i * k as i64) as usize, (y as i64 + j * k as i64) as usize);
        let (mut wmin, mut first_lt1, mut zero_at) = (1f32, s, 0usize);
        if self.tracing {
            let mut k = 1;
            loop {
                let (qx, qy) = at(k);
                let wq = self.weight(c, qx, qy);
                if wq < 1.0 && first_lt1 == s {
                    first_lt1 = k;
                }
                if wq <= 0.0 {
                    (wmin, zero_at) = (0.0, k);
                    break;
                }
                wmin = wmin.min(wq);
                if k == s {
                    break;
                }
                k = (k + self.step(qx, qy)).min(s);
            }
        } else {
            wmin = self.weight(c, tx as usize, ty as usize);
            if wmin <= 0.0 {
                zero_at = s;
            }
        }
        if wmin > 0.0 {
            return (wmin, Some(s), first_lt1);
        }
        if !self.replace || zero_at == 0 {
            return (0.0, None, first_lt1);
        }
        let r = self.replacement(x, y, dir, zero_at);
        let (qx, qy) = at(r);
        (self.weight(c, qx, qy), Some(r), first_lt1)
    }

    /// Adds `f · W · Z` of the sample at `(qx, qy)` to lane `l` of `acc`.
    #[inline(always)]
    fn add_lane<const KP: usize>(&self, acc: &mut [f32x8; KP], l: usize, f: f32, qx: usize, qy: usize) {
        let base = qy * self.zl + qx;
        let fw = f * S::get(self.z, base + (KP - 1) * self.ps);
        for k in 0..KP - 1 {
            acc[k].as_mut_array()[l] += fw * S::get(self.z, base + k * self.ps);
        }
        acc[KP - 1].as_mut_array()[l] += fw;
    }
}

impl Walr {
    /// Stage 2: à-trous iteration `t` (0-based) for rows `y0..`, reading the
    /// whole-frame `geo`, `sdf_in` and `z_in` (buffer [`Walr::buffer_of`]`(t)`)
    /// and writing the same rows of the other buffers: `sdf_out` and `z_out`
    /// hold exactly those rows.
    #[allow(clippy::too_many_arguments)]
    pub fn iterate_rows(
        &self,
        t: u8,
        p: &Prepared,
        y0: usize,
        geo: &[f32],
        sdf_in: &[f32],
        z_in: &[f32],
        sdf_out: &mut [f32],
        z_out: &mut [f32],
    ) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        if t >= self.cfg.iterations || geo.len() < h * self.geo_row_len() || sdf_in.len() < h * w || z_in.len() < h * self.z_row_len() {
            return Err(Error::InvalidTile { index: t as usize, count: self.cfg.iterations as usize });
        }
        let rows = self.check_band(y0, sdf_out.len(), w)?;
        if z_out.len() != rows * self.z_row_len() {
            return Err(Error::InvalidTile { index: y0, count: h });
        }
        match self.cfg.storage {
            Storage::F32 => self.iterate_impl::<f32>(t, p, y0, rows, geo, sdf_in, z_in, sdf_out, z_out),
            Storage::F16 => {
                self.iterate_impl::<u16>(t, p, y0, rows, geo, sdf_in, bytemuck::cast_slice(z_in), sdf_out, bytemuck::cast_slice_mut(z_out))
            }
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn iterate_impl<S: Store>(
        &self,
        t: u8,
        p: &Prepared,
        y0: usize,
        rows: usize,
        geo: &[f32],
        sdf_in: &[f32],
        z_in: &[S],
        sdf_out: &mut [f32],
        z_out: &mut [S],
    ) {
        let cfg = &self.cfg;
        let ctx = Ctx {
            w: self.width,
            h: self.height,
            gp: self.geo_planes(),
            ps: self.plane_stride(),
            zl: self.z_row_values(),
            geo,
            sdf: sdf_in,
            z: z_in,
            inv_range: 1.0 / (cfg.far - cfg.near),
            far: cfg.far,
            tracing: cfg.tracing,
            replace: cfg.replace,
            // The previous field only exists from the second iteration on.
            sdf_step: if t == 0 { 0.0 } else { cfg.sdf_step },
            seed: p.seed,
            t,
        };
        let s = 3usize.pow(t as u32);
        let w = self.width;
        let simd = cfg.kernel == Kernel::Simd;
        // the accumulators stay in registers only for a compile-time plane count
        type Group<S> = fn(&Ctx<'_, S>, usize, usize, usize, &mut [S], &mut [f32]);
        let (group, one): (Group<S>, Group<S>) = match self.m {
            3 => (group8::<S, 15>, pixel::<S, 15>),
            4 => (group8::<S, 22>, pixel::<S, 22>),
            5 => (group8::<S, 30>, pixel::<S, 30>),
            6 => (group8::<S, 39>, pixel::<S, 39>),
            7 => (group8::<S, 49>, pixel::<S, 49>),
            _ => (group8::<S, 60>, pixel::<S, 60>),
        };
        for r in 0..rows {
            let y = y0 + r;
            let zo = &mut z_out[r * ctx.zl..(r + 1) * ctx.zl];
            let so = &mut sdf_out[r * w..(r + 1) * w];
            let mut x0 = 0;
            while x0 < w {
                if simd && x0 + 8 <= w {
                    group(&ctx, x0, y, s, zo, so);
                    x0 += 8;
                } else {
                    one(&ctx, x0, y, s, zo, so);
                    x0 += 1;
                }
            }
        }
    }
}

/// Writes the normalised averages of lane `l` (or pixel `x` for a one-lane call).
#[inline(always)]
fn finish<S: Store, const KP: usize>(ctx: &Ctx<'_, S>, acc: &[f32x8; KP], lanes: usize, x0: usize, zo: &mut [S]) {
    let kp = KP;
    let wsum = acc[kp - 1];
    let ok = wsum.simd_gt(f32x8::ZERO);
    let inv = ok.select(f32x8::ONE / wsum, f32x8::ZERO);
    if lanes == 8 {
        for k in 0..kp - 1 {
            S::store8(zo, k * ctx.ps + x0, acc[k] * inv);
        }
        S::store8(zo, (kp - 1) * ctx.ps + x0, wsum);
    } else {
        let inv = inv.to_array();
        for k in 0..kp - 1 {
            let a = acc[k].to_array();
            for l in 0..lanes {
                S::set(zo, k * ctx.ps + x0 + l, a[l] * inv[l]);
            }
        }
        let a = wsum.to_array();
        for l in 0..lanes {
            S::set(zo, (kp - 1) * ctx.ps + x0 + l, a[l]);
        }
    }
}

/// One pixel on its own (borders, the scalar kernel).
fn pixel<S: Store, const KP: usize>(ctx: &Ctx<'_, S>, x: usize, y: usize, s: usize, zo: &mut [S], so: &mut [f32]) {
    let mut acc = [f32x8::ZERO; KP];
    let c = ctx.centre(x, y);
    ctx.add_lane(&mut acc, 0, 1.0, x, y);
    let mut sdf = s;
    for dir in 0..8 {
        let (f, r, lt1) = ctx.trace_pixel(&c, x, y, dir, s);
        sdf = sdf.min(lt1);
        if let Some(r) = r {
            let (i, j) = DIRS[dir];
            ctx.add_lane(&mut acc, 0, f, (x as i64 + i * r as i64) as usize, (y as i64 + j * r as i64) as usize);
        }
    }
    finish(ctx, &acc, 1, x, zo);
    so[x] = sdf as f32;
}

/// 8 pixels `x0..x0 + 8` of row `y` in lanes.
fn group8<S: Store, const KP: usize>(ctx: &Ctx<'_, S>, x0: usize, y: usize, s: usize, zo: &mut [S], so: &mut [f32]) {
    let (w, kp, ps) = (ctx.w, KP, ctx.ps);
    let mut acc = [f32x8::ZERO; KP];
    let cv: [f32x8; 9] = [
        ctx.g8(G_P, x0, y),
        ctx.g8(G_P + 1, x0, y),
        ctx.g8(G_P + 2, x0, y),
        ctx.g8(G_N, x0, y),
        ctx.g8(G_N + 1, x0, y),
        ctx.g8(G_N + 2, x0, y),
        ctx.g8(G_INV_SCALE, x0, y) * f32x8::splat(ctx.inv_range),
        ctx.g8(G_VALID, x0, y).abs(),
        f32x8::splat(ctx.far * ctx.inv_range),
    ];
    // centre: weight 1
    {
        let base = y * ctx.zl + x0;
        let wv = S::load8(ctx.z, base + (kp - 1) * ps);
        for k in 0..kp - 1 {
            acc[k] += wv * S::load8(ctx.z, base + k * ps);
        }
        acc[kp - 1] += wv;
    }
    let sv = f32x8::splat(s as f32);
    let mut sdf = sv;
    for (dir, &(i, j)) in DIRS.iter().enumerate() {
        let ty = y as i64 + j * s as i64;
        if ty < 0 || ty >= ctx.h as i64 {
            continue;
        }
        let tx0 = x0 as i64 + i * s as i64;
        if tx0 < 0 || tx0 + 8 > w as i64 {
            // Part of the group leaves the row: per pixel.
            for l in 0..8 {
                let x = x0 + l;
                let c = ctx.centre(x, y);
                let (f, r, lt1) = ctx.trace_pixel(&c, x, y, dir, s);
                sdf.as_mut_array()[l] = sdf.as_array()[l].min(lt1 as f32);
                if let Some(r) = r {
                    ctx.add_lane(&mut acc, l, f, (x as i64 + i * r as i64) as usize, (y as i64 + j * r as i64) as usize);
                }
            }
            continue;
        }
        let at = |k: usize| ((x0 as i64 + i * k as i64) as usize, (y as i64 + j * k as i64) as usize);
        let (mut wmin, mut lt1, mut zero_at) = (f32x8::ONE, sv, f32x8::ZERO);
        if ctx.tracing {
            let mut k = 1;
            loop {
                let (qx, qy) = at(k);
                let wq = ctx.weight8(&cv, qx, qy);
                let kf = f32x8::splat(k as f32);
                lt1 = (wq.simd_lt(f32x8::ONE) & lt1.simd_eq(sv)).select(kf, lt1);
                zero_at = (wq.simd_le(f32x8::ZERO) & wmin.simd_gt(f32x8::ZERO)).select(kf, zero_at);
                wmin = wmin.fast_min(wq);
                if k == s || wmin.simd_gt(f32x8::ZERO).none() {
                    break;
                }
                k = (k + ctx.step8(qx, qy)).min(s);
            }
        } else {
            let (qx, qy) = at(s);
            wmin = ctx.weight8(&cv, qx, qy);
            zero_at = wmin.simd_le(f32x8::ZERO).select(sv, f32x8::ZERO);
        }
        sdf = sdf.fast_min(lt1);
        let live = wmin.simd_gt(f32x8::ZERO);
        if live.any() {
            let (qx, qy) = at(s);
            let base = qy * ctx.zl + qx;
            let fw = wmin * S::load8(ctx.z, base + (kp - 1) * ps);
            for k in 0..kp - 1 {
                acc[k] += fw * S::load8(ctx.z, base + k * ps);
            }
            acc[kp - 1] += fw;
        }
        if ctx.replace && !live.all() {
            let za = zero_at.to_array();
            for l in 0..8 {
                let k = za[l] as usize;
                if k == 0 {
                    continue;
                }
                let x = x0 + l;
                let r = ctx.replacement(x, y, dir, k);
                let (qx, qy) = ((x as i64 + i * r as i64) as usize, (y as i64 + j * r as i64) as usize);
                let c = ctx.centre(x, y);
                let f = ctx.weight(&c, qx, qy);
                ctx.add_lane(&mut acc, l, f, qx, qy);
            }
        }
    }
    finish(ctx, &acc, 8, x0, zo);
    so[x0..x0 + 8].copy_from_slice(&sdf.to_array());
}
