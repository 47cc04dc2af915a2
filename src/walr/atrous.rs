//! One edge-aware à-trous iteration with edge tracing (§3.2, §3.3, §5.2).
//!
//! `S_{t+1}(x) = Σ_u f(x,u) S_t(x+u)`, `W_{t+1}(x) = Σ_u f(x,u) W_t(x+u)`
//! over the 3×3 taps `u ∈ 3^t·{−1,0,1}²` (the box kernel with `3^t − 1` zeros
//! between taps: every sample is counted once). `S_t = W_t Z_t` are the
//! weighted **sums** whose ratios are the paper's averages `Z_t` (§3.2:
//! `Z_{t+1} = Σ f W_t Z_t / Σ f W_t`): storing sums instead of averages makes
//! an iteration 9 multiply-adds per value and no division; [`Walr::solve_rows`]
//! divides once. (f16 storage keeps them in range by storing `9^{−t} S_t`,
//! `9^{−t} W_t`; the solve's ratios are unchanged.) `f` is the edge-stopping
//! weight: the distance of the tap's position from the plane through the
//! centre position with the centre normal, over the centre's camera distance,
//! mapped to 1 below `near` and 0 beyond `far`; with tracing, its minimum
//! over the pixels of the segment centre → tap.
//!
//! Tracing steps along the segment by `max(1, ⌊sdf_step · sdf_t⌋)` pixels,
//! where `sdf_t(q)` is the distance from `q` to the nearest pixel whose weight
//! (seen from `q`) was below 1 on one of `q`'s segments of the previous
//! iteration (the segment length if none), or rather its minimum over `q` and
//! the 7 pixels to its right, so that 8 lanes stepping together read one value
//! (see `min_of_next_8`). This iteration writes `sdf_{t+1}` the same way, as
//! the step itself in a byte per pixel: a trace is a chain of dependent loads
//! (each step needs the field at the last point), and the bytes of the rows
//! a trace visits stay in L2 where f32 distances would not. A tap whose trace meets a zero weight at distance `k` is
//! replaced by the sample at a hashed distance in `[⌈k/2⌉, k − 1]` on the
//! same segment, weighted by its own edge-stopping value.
//!
//! Validity codes: a tap counts only if its code equals the centre's
//! *absolute* code. Geometry (1) sees geometry, sky (0) sees sky, and a pixel
//! with NaN/Inf guides (−1) is seen by nobody but sees all geometry (its
//! normal is 0, so every plane distance is 0): it gets its neighbourhood's fit.
//!
//! Each group of 8 neighbouring pixels runs in two phases: first the 9 taps'
//! weights (tracing), then, plane by plane, the 9 multiply-adds of the sums
//! with the weights held in registers. Groups whose taps all lie inside the
//! row load each tap as 8 consecutive values; the others (borders, and every
//! pixel of the scalar kernel) gather per lane, with the same operations in
//! the same order. Replacement samples belong to one lane; they are added
//! after the 9 taps, in direction order, in every path.

use super::store::Store;
use super::{Prepared, Storage, Walr, G_INV_SCALE, G_N, G_P, G_VALID};
use crate::error::Error;
use crate::isa::Kernel;
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
    sdf: &'a [u8],
    z: &'a [S],
    inv_range: f32,
    far: f32,
    tracing: bool,
    replace: bool,
    /// `sdf_step` of the configuration, for the field this iteration writes.
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
        debug_assert!(c < self.gp && x + 8 <= self.w && y < self.h);
        self.g8_at((y * self.gp + c) * self.ps + x)
    }
    /// Values `i..i + 8` of the geometry: `i = (y·gp + c)·ps + x` for a plane
    /// `c < gp` of a point with `y < h` and `x + 8 ≤ w` (a group's taps are
    /// checked in-row, and a trace's points lie between its centre and tap).
    #[inline(always)]
    fn g8_at(&self, i: usize) -> f32x8 {
        debug_assert!(i + 8 <= self.geo.len());
        // SAFETY: `iterate_rows` checked `geo.len() ≥ h · gp · ps` (ps ≥ w),
        // and an index of the form above has i + 8 ≤ geo.len(). An unaligned
        // read of 8 f32 is a valid f32x8.
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
        debug_assert!(x + 8 <= self.w && y < self.h);
        self.weight8_at(c, y * self.gp * self.ps + x)
    }
    /// [`Ctx::weight8`] of the point whose plane-0 geometry index is `i`
    /// (`y·gp·ps + x`): a trace's points advance by a fixed stride of it.
    #[inline(always)]
    fn weight8_at(&self, c: &[f32x8; 9], i: usize) -> f32x8 {
        // c: p (3), n (3), inv_scale / (far − near), |valid|, far / (far − near)
        let ps = self.ps;
        let g = |plane: usize| self.g8_at(i + plane * ps);
        let d = c[3] * (g(G_P) - c[0]) + c[4] * (g(G_P + 1) - c[1]) + c[5] * (g(G_P + 2) - c[2]);
        let v = (c[8] - d.abs() * c[6]).fast_max(f32x8::ZERO).fast_min(f32x8::ONE);
        g(G_VALID).simd_eq(c[7]).select(v, f32x8::ZERO)
    }
    /// The trace step at field index `i` (`y·w + x`). Only a point short of
    /// the tap steps (k < s = 3^t), so t ≥ 1 and the previous iteration wrote
    /// the field; ≥ 1 even for a caller's field of zeros, so a trace always
    /// advances.
    #[inline(always)]
    fn step_at(&self, i: usize) -> usize {
        self.sdf[i].max(1) as usize
    }
    /// The step stored for an edge distance `e`: `max(1, ⌊sdf_step · e⌋)`.
    #[inline(always)]
    fn step_of(&self, e: f32) -> u8 {
        let v = self.sdf_step * e;
        // e ≤ 3^(MAX_ITERATIONS − 1) = 81, so the step fits a byte
        if v >= 2.0 {
            (v as usize).min(255) as u8
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

    /// Traces one tap of pixel `(x, y)` on its own. `None`: the tap lies
    /// outside the frame. Else `(wmin, zero_at, lt1)`: the edge-stopping
    /// weight (with tracing its minimum over the segment; 0 once cut), the
    /// distance of the first zero weight (0 if none) and that of the first
    /// weight below 1 (`s` if none).
    fn trace_pixel(&self, c: &Centre, x: usize, y: usize, dir: usize, s: usize) -> Option<(f32, usize, usize)> {
        let (i, j) = DIRS[dir];
        let (tx, ty) = (x as i64 + i * s as i64, y as i64 + j * s as i64);
        if tx < 0 || ty < 0 || tx >= self.w as i64 || ty >= self.h as i64 {
            return None;
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
                k = (k + self.step_at(qy * self.w + qx)).min(s);
            }
        } else {
            wmin = self.weight(c, tx as usize, ty as usize);
            if wmin <= 0.0 {
                (wmin, zero_at) = (0.0, s);
            }
        }
        Some((wmin, zero_at, first_lt1))
    }

    /// The replacement sample of lane `lane` (pixel `(x, y)`) for its tap
    /// `dir`, cut by an edge at distance `zero_at ≥ 1`.
    fn replace_sample(&self, lane: usize, x: usize, y: usize, dir: usize, zero_at: usize) -> Extra {
        let (i, j) = DIRS[dir];
        let r = self.replacement(x, y, dir, zero_at) as i64;
        let (qx, qy) = ((x as i64 + i * r) as usize, (y as i64 + j * r) as usize);
        Extra { lane, at: qy * self.zl + qx, f: self.weight(&self.centre(x, y), qx, qy) }
    }

    /// Tap `dir` of lane `lane` (pixel `(x, y)`) traced on its own: the
    /// per-lane path of [`gather_lanes`] and of [`weights8`]'s directions that
    /// leave the row. `None`: the tap lies outside the frame.
    fn trace_lane(&self, lane: usize, x: usize, y: usize, dir: usize, s: usize) -> Option<LaneTap> {
        let (wmin, zero_at, lt1) = self.trace_pixel(&self.centre(x, y), x, y, dir, s)?;
        let (i, j) = DIRS[dir];
        let at = (y as i64 + j * s as i64) as usize * self.zl + (x as i64 + i * s as i64) as usize;
        let extra = (self.replace && zero_at > 0).then(|| self.replace_sample(lane, x, y, dir, zero_at));
        Some(LaneTap { f: wmin, at, lt1: lt1 as f32, extra })
    }
}

/// One lane's traced tap ([`Ctx::trace_lane`]): its weight, the z index of
/// its sample's first plane, the distance of its first weight below 1, and
/// its replacement sample if an edge cut it.
struct LaneTap {
    f: f32,
    at: usize,
    lt1: f32,
    extra: Option<Extra>,
}

/// Most replacement samples of one group: one per lane and direction.
const MAX_EXTRA: usize = 64;

/// A sample of one lane only (a replacement): its lane, the z index of its
/// first plane, its weight.
#[derive(Clone, Copy, Default)]
struct Extra {
    lane: usize,
    at: usize,
    f: f32,
}

/// The replacement samples of one group (per-lane path).
type Extras = [Extra; MAX_EXTRA];

/// Adds the lane-only samples to `acc`, plane offset `o` (after the 9 taps,
/// in direction order per lane, in every path alike).
#[inline(always)]
fn add_extra<S: Store>(z: &[S], extra: &[Extra], o: usize, acc: f32x8) -> f32x8 {
    let mut a = acc.to_array();
    for e in extra {
        a[e.lane] += e.f * S::get(z, e.at + o);
    }
    f32x8::from(a)
}

/// The 9 taps of one plane: the centre `c` plus `Σ f_d z_d`, as two chains
/// of multiply-adds (centre and taps 0–3; taps 4–7) added at the end.
#[inline(always)]
fn taps9(c: f32x8, f: &[f32x8; 8], z: impl Fn(usize) -> f32x8) -> f32x8 {
    let mut a = c;
    let mut b = f[4] * z(4);
    for d in 0..4 {
        a = f[d].mul_add(z(d), a);
    }
    for d in 5..8 {
        b = f[d].mul_add(z(d), b);
    }
    a + b
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
        sdf_in: &[u8],
        z_in: &[f32],
        sdf_out: &mut [u8],
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
        sdf_in: &[u8],
        z_in: &[S],
        sdf_out: &mut [u8],
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
            sdf_step: cfg.sdf_step,
            seed: p.seed,
            t,
        };
        let s = 3usize.pow(t as u32);
        let w = self.width;
        let simd = cfg.kernel == Kernel::Simd;
        // the plane count is a compile-time constant, so the plane loop unrolls
        type Row<S> = fn(&Ctx<'_, S>, usize, usize, &mut [S], &mut [u8], &mut Chunk, &mut Extras);
        type Lanes<S> = fn(&Ctx<'_, S>, usize, usize, usize, usize, &mut [S], &mut [u8], &mut Extras);
        let (row, lanes): (Row<S>, Lanes<S>) = match self.planes() {
            15 => (row8::<S, 15>, gather_lanes::<S, 15>),
            16 => (row8::<S, 16>, gather_lanes::<S, 16>),
            22 => (row8::<S, 22>, gather_lanes::<S, 22>),
            23 => (row8::<S, 23>, gather_lanes::<S, 23>),
            30 => (row8::<S, 30>, gather_lanes::<S, 30>),
            31 => (row8::<S, 31>, gather_lanes::<S, 31>),
            39 => (row8::<S, 39>, gather_lanes::<S, 39>),
            40 => (row8::<S, 40>, gather_lanes::<S, 40>),
            49 => (row8::<S, 49>, gather_lanes::<S, 49>),
            50 => (row8::<S, 50>, gather_lanes::<S, 50>),
            60 => (row8::<S, 60>, gather_lanes::<S, 60>),
            _ => (row8::<S, 61>, gather_lanes::<S, 61>),
        };
        // (allocated once per band: fresh ones per group would be memsets)
        let mut chunk =
            Chunk { x0: 0, n: 0, f: [[f32x8::ZERO; 8]; CHUNK], extra: [Extra::default(); CHUNK_EXTRA], ne: 0, ex_end: [0; CHUNK] };
        let mut extra = [Extra::default(); MAX_EXTRA];
        for r in 0..rows {
            let y = y0 + r;
            let zo = &mut z_out[r * ctx.zl..(r + 1) * ctx.zl];
            let so = &mut sdf_out[r * w..(r + 1) * w];
            if simd {
                row(&ctx, y, s, zo, so, &mut chunk, &mut extra);
            } else {
                for x in 0..w {
                    lanes(&ctx, x, 1, y, s, zo, so, &mut extra);
                }
            }
            min_of_next_8(so);
        }
    }
}

/// Groups of 8 pixels per chunk of a row: phase 1 computes their weights,
/// phase 2 then runs plane by plane over all of them.
const CHUNK: usize = 64;
/// Replacement samples a chunk holds (one group adds at most [`MAX_EXTRA`]).
const CHUNK_EXTRA: usize = 4 * MAX_EXTRA;

/// Phase 1's results for a run of interior groups of one row (~23 KiB, on
/// the stack of [`Walr::iterate_rows`] once per call).
struct Chunk {
    /// First pixel of the first group.
    x0: usize,
    /// Groups.
    n: usize,
    /// Weights of the 8 outer taps of each group.
    f: [[f32x8; 8]; CHUNK],
    extra: [Extra; CHUNK_EXTRA],
    ne: usize,
    /// End of each group's replacements in `extra`.
    ex_end: [usize; CHUNK],
}

/// Replaces each step `e[x]` by `min(e[x..x + 8])` (fewer at the row's end),
/// in place: the field the next iteration steps by. 8 lanes at `x` step
/// together by the field at `x` alone, and a pixel on its own by the same
/// value, so no reduction over 8 lanes sits on the trace's critical path.
fn min_of_next_8(e: &mut [u8]) {
    // forward and in place, e[x + sh] is still this pass's input: windows 2, 4, 8
    for sh in [1, 2, 4] {
        for x in 0..e.len().saturating_sub(sh) {
            e[x] = e[x].min(e[x + sh]);
        }
    }
}

/// Writes lanes `..n` of plane offset `o` at pixel `x0` (scaled for storage).
#[inline(always)]
fn put<S: Store>(zo: &mut [S], o: usize, x0: usize, n: usize, acc: f32x8) {
    let v = if S::STEP != 1.0 { acc * f32x8::splat(S::STEP) } else { acc };
    if n == 8 {
        S::store8(zo, o + x0, v);
    } else {
        let a = v.to_array();
        for l in 0..n {
            S::set(zo, o + x0 + l, a[l]);
        }
    }
}

/// Phase 2 for one group of `n` lanes at pixel `x0`, every plane: the centre
/// `centre(o)` plus the taps `tap(d, o)` weighted by `f` ([`taps9`]), then the
/// lane-only samples `extra`; `o` is the plane offset. The per-lane and
/// border paths; [`sums8`] is the same per plane over a chunk of groups.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sums_group<S: Store, const KP: usize>(
    ctx: &Ctx<'_, S>,
    x0: usize,
    n: usize,
    f: &[f32x8; 8],
    centre: impl Fn(usize) -> f32x8,
    tap: impl Fn(usize, usize) -> f32x8,
    extra: &[Extra],
    zo: &mut [S],
) {
    for k in 0..KP {
        let o = k * ctx.ps;
        let acc = taps9(centre(o), f, |d| tap(d, o));
        let acc = add_extra(ctx.z, extra, o, acc);
        put(zo, o, x0, n, acc);
    }
}

/// Pixels `x0..x0 + n` (n ≤ 8) of row `y` traced and summed per lane: the
/// last `w mod 8` pixels of a row, and every pixel of the scalar kernel
/// (n = 1). Same operations, in the same order, as [`weights8`] and
/// [`sums8`] (bit-identical without tracing).
#[allow(clippy::too_many_arguments)]
fn gather_lanes<S: Store, const KP: usize>(
    ctx: &Ctx<'_, S>,
    x0: usize,
    n: usize,
    y: usize,
    s: usize,
    zo: &mut [S],
    so: &mut [u8],
    extra: &mut Extras,
) {
    let mut f = [[0f32; 8]; 8];
    let mut at = [[0usize; 8]; 9];
    let mut sdf = [s as f32; 8];
    let mut ne = 0;
    for l in 0..n {
        let x = x0 + l;
        let centre = y * ctx.zl + x;
        at[0][l] = centre;
        for dir in 0..8 {
            at[dir + 1][l] = centre;
            let Some(t) = ctx.trace_lane(l, x, y, dir, s) else { continue };
            sdf[l] = sdf[l].min(t.lt1);
            (at[dir + 1][l], f[dir][l]) = (t.at, t.f);
            if let Some(e) = t.extra {
                extra[ne] = e;
                ne += 1;
            }
        }
    }
    // per lane, the extras are in direction order (lanes were visited in turn)
    let gather = |k: usize, o: usize| {
        let mut a = [0f32; 8];
        for l in 0..n {
            a[l] = S::get(ctx.z, at[k][l] + o);
        }
        f32x8::from(a)
    };
    sums_group::<S, KP>(ctx, x0, n, &f.map(f32x8::from), |o| gather(0, o), |d, o| gather(d + 1, o), &extra[..ne], zo);
    for l in 0..n {
        so[x0 + l] = ctx.step_of(sdf[l]);
    }
}

/// Row `y` in groups of 8 pixels: groups whose taps all lie inside the row
/// go through [`weights8`] into a [`Chunk`], then [`sums8`]; the others
/// (and the last `w mod 8` pixels) through [`gather_lanes`].
fn row8<S: Store, const KP: usize>(ctx: &Ctx<'_, S>, y: usize, s: usize, zo: &mut [S], so: &mut [u8], ch: &mut Chunk, extra: &mut Extras) {
    let w = ctx.w;
    // tap offsets in z (0 for a row outside the frame: weight 0 at the centre)
    let mut off = [0isize; 8];
    for (d, &(i, j)) in DIRS.iter().enumerate() {
        let ty = y as i64 + j * s as i64;
        if ty >= 0 && ty < ctx.h as i64 {
            off[d] = (j * s as i64 * ctx.zl as i64 + i * s as i64) as isize;
        }
    }
    ch.n = 0;
    ch.ne = 0;
    // per-lane sample indices of a border group (once per row, not a memset per group)
    let mut at = [[0usize; 8]; 8];
    let mut x0 = 0;
    while x0 < w {
        if x0 + 8 > w {
            gather_lanes::<S, KP>(ctx, x0, w - x0, y, s, zo, so, extra);
            break;
        }
        if x0 < s || x0 + 8 + s > w {
            // some taps leave the row: those directions per lane, the others in lanes
            let (mut f, mut ne, mut lanewise) = ([f32x8::ZERO; 8], 0, 0u32);
            let sdf = weights8(ctx, x0, y, s, &mut f, extra, &mut ne, &mut lanewise, &mut at).to_array();
            for l in 0..8 {
                so[x0 + l] = ctx.step_of(sdf[l]);
            }
            let c = y * ctx.zl + x0;
            let tap = |d: usize, o: usize| {
                if lanewise & (1 << d) != 0 {
                    f32x8::from(at[d].map(|i| S::get(ctx.z, i + o)))
                } else {
                    S::load8(ctx.z, c.wrapping_add_signed(off[d]) + o)
                }
            };
            sums_group::<S, KP>(ctx, x0, 8, &f, |o| S::load8(ctx.z, c + o), tap, &extra[..ne], zo);
        } else {
            if ch.n == 0 {
                ch.x0 = x0;
            }
            let g = ch.n;
            let mut lanewise = 0u32;
            let sdf = weights8(ctx, x0, y, s, &mut ch.f[g], &mut ch.extra, &mut ch.ne, &mut lanewise, &mut at);
            debug_assert_eq!(lanewise, 0);
            let sdf = sdf.to_array();
            for l in 0..8 {
                so[x0 + l] = ctx.step_of(sdf[l]);
            }
            ch.ex_end[g] = ch.ne;
            ch.n += 1;
            if ch.n == CHUNK || ch.ne + MAX_EXTRA > CHUNK_EXTRA {
                sums8::<S, KP>(ctx, y, s, &off, ch, zo, extra);
                ch.n = 0;
                ch.ne = 0;
            }
        }
        x0 += 8;
    }
    if ch.n > 0 {
        sums8::<S, KP>(ctx, y, s, &off, ch, zo, extra);
    }
}

/// Phase 1 for the 8 pixels `x0..x0 + 8` of row `y` (every tap inside the
/// row): the weights of the 8 outer taps into `f` (0 for a tap above or below
/// the frame, and for a lane whose trace was cut), the replacements appended
/// to `extra`; returns the new edge distances.
/// A direction whose 8 taps do not all lie inside the row is traced per lane
/// and its bit set in `*lanewise`, with each lane's sample index in `at`.
#[allow(clippy::too_many_arguments)]
fn weights8<S: Store>(
    ctx: &Ctx<'_, S>,
    x0: usize,
    y: usize,
    s: usize,
    f: &mut [f32x8; 8],
    extra: &mut [Extra],
    ne: &mut usize,
    lanewise: &mut u32,
    at: &mut [[usize; 8]; 8],
) -> f32x8 {
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
    let sv = f32x8::splat(s as f32);
    let mut sdf = sv;
    for (dir, &(i, j)) in DIRS.iter().enumerate() {
        f[dir] = f32x8::ZERO;
        let ty = y as i64 + j * s as i64;
        if ty < 0 || ty >= ctx.h as i64 {
            continue;
        }
        let tx0 = x0 as i64 + i * s as i64;
        if tx0 < 0 || tx0 + 8 > ctx.w as i64 {
            // part of the group leaves the row: per lane, as `gather_lanes`
            *lanewise |= 1 << dir;
            let (mut fl, mut sl) = ([0f32; 8], sdf.to_array());
            for l in 0..8 {
                let x = x0 + l;
                at[dir][l] = y * ctx.zl + x;
                let Some(t) = ctx.trace_lane(l, x, y, dir, s) else { continue };
                sl[l] = sl[l].min(t.lt1);
                (at[dir][l], fl[l]) = (t.at, t.f);
                if let Some(e) = t.extra {
                    extra[*ne] = e;
                    *ne += 1;
                }
            }
            f[dir] = f32x8::from(fl);
            sdf = f32x8::from(sl);
            continue;
        }
        let pos = |k: usize| ((x0 as i64 + i * k as i64) as usize, (y as i64 + j * k as i64) as usize);
        let (mut wmin, mut lt1, mut zero_at) = (f32x8::ONE, sv, f32x8::ZERO);
        if ctx.tracing {
            // point k's indices are the centre's plus k strides (no
            // multiplication per plane on the chain of dependent steps);
            // every point lies between the centre and the tap, so in the frame
            let (g0, gs) = ((y * ctx.gp * ctx.ps + x0) as isize, j as isize * (ctx.gp * ctx.ps) as isize + i as isize);
            let (f0, fs) = ((y * ctx.w + x0) as isize, j as isize * ctx.w as isize + i as isize);
            let mut k = 1;
            loop {
                let wq = ctx.weight8_at(&cv, (g0 + k as isize * gs) as usize);
                let below1 = wq.simd_lt(f32x8::ONE);
                if below1.any() {
                    // (on flat ground every weight is 1: nothing to record)
                    let kf = f32x8::splat(k as f32);
                    lt1 = (below1 & lt1.simd_eq(sv)).select(kf, lt1);
                    zero_at = (wq.simd_le(f32x8::ZERO) & wmin.simd_gt(f32x8::ZERO)).select(kf, zero_at);
                    wmin = wmin.fast_min(wq);
                    if wmin.simd_gt(f32x8::ZERO).none() {
                        break;
                    }
                }
                if k == s {
                    break;
                }
                k = (k + ctx.step_at((f0 + k as isize * fs) as usize)).min(s);
            }
        } else {
            let (qx, qy) = pos(s);
            wmin = ctx.weight8(&cv, qx, qy);
            zero_at = wmin.simd_le(f32x8::ZERO).select(sv, f32x8::ZERO);
        }
        sdf = sdf.fast_min(lt1);
        // the weights are in [0, 1] (a cut lane is 0): the values of the per-lane path
        f[dir] = wmin;
        if ctx.replace && zero_at.simd_gt(f32x8::ZERO).any() {
            let za = zero_at.to_array();
            for l in 0..8 {
                let k = za[l] as usize;
                if k > 0 {
                    extra[*ne] = ctx.replace_sample(l, x0 + l, y, dir, k);
                    *ne += 1;
                }
            }
        }
    }
    sdf
}

/// Phase 2 for a chunk: per plane, per group, the centre plus 8
/// multiply-adds with the tap weights, then the group's replacements.
/// (Plane by plane over the chunk, the loads stream through 3 rows of one
/// plane at a time; group by group, with the weights in registers, they
/// would stream through 3 × 15 planes at once: 1.7× slower at 1080p.)
fn sums8<S: Store, const KP: usize>(ctx: &Ctx<'_, S>, y: usize, s: usize, off: &[isize; 8], ch: &Chunk, zo: &mut [S], extra: &mut Extras) {
    let base = y * ctx.zl + ch.x0;
    let hi = off.iter().fold(0, |m, &o| m.max(o)) as usize;
    let lo = off.iter().fold(0, |m, &o| m.min(o)).unsigned_abs();
    if base < lo || base + 8 * ch.n + hi + (KP - 1) * ctx.ps > ctx.z.len() {
        // cannot happen (every tap lies inside the frame); keeps the loads below sound
        for g in 0..ch.n {
            let mut sdf = [0u8; 8];
            gather_lanes::<S, KP>(ctx, ch.x0 + 8 * g, 8, y, s, zo, &mut sdf, extra);
        }
        return;
    }
    for k in 0..KP {
        let o = k * ctx.ps;
        // SAFETY: every index read is in `base − lo ..= base + 8(n − 1) + hi + o`
        // and o ≤ (KP − 1)·ps, so it and the 7 values after it lie in z (checked above).
        let ld = |c: usize, d: isize| unsafe { S::load8_unchecked(ctx.z, c.wrapping_add_signed(d)) };
        let mut e0 = 0;
        for g in 0..ch.n {
            let c = base + 8 * g + o;
            if k + 1 < KP {
                // the next plane's three tap rows: one stream per plane
                // would end at each chunk's end, and 3 × KP streams are
                // more than the hardware prefetchers follow
                let n = c + ctx.ps;
                crate::image::prefetch(ctx.z, n.wrapping_add_signed(off[1]));
                crate::image::prefetch(ctx.z, n);
                crate::image::prefetch(ctx.z, n.wrapping_add_signed(off[6]));
                crate::image::prefetch(zo, o + ctx.ps + ch.x0 + 8 * g);
            }
            let mut acc = taps9(ld(c, 0), &ch.f[g], |d| ld(c, off[d]));
            let e1 = ch.ex_end[g];
            if e1 > e0 {
                acc = add_extra(ctx.z, &ch.extra[e0..e1], o, acc);
                e0 = e1;
            }
            put(zo, o, ch.x0 + 8 * g, 8, acc);
        }
    }
}
