//! BMFR's per-block feature matrix: gathering (with mirrored borders and
//! NaN/Inf exclusion), per-block rescaling to `[0, 1]`, squared features, and
//! the stochastic regularisation noise.
//!
//! Column-major block matrices, `n = B²` rows (row `j·B + i` = pixel `(i, j)`
//! of the block):
//! * `valid`: 1 on rows the fit uses (noisy and guides finite), else 0;
//! * `guide_ok`: 1 where the pixel's own guides are finite;
//! * `a`: the fit matrix `[features + noise | noisy r, g, b]`, `n × (m + 3)`,
//!   overwritten by the QR.
//!
//! The features themselves are not stored: the fit matrix is built from the
//! tile's [`Band`] and the model is applied from it again
//! ([`apply_block`]), each in one pass over the block's rows in f32x8 lanes.

use super::CheckedFrame;
use crate::error::Error;
use crate::guides::{GuideSet, MAX_GUIDES};
use crate::image::ImageView;
#[cfg(doc)]
use crate::kernels::qr::lstsq_shrunk_ld;
use crate::kernels::qr::{padded_ld, MAX_FEATURES};
use wide::{f32x8, i32x8, u32x8};

/// Which guide channels become which features.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeatureSet {
    /// Guide channels Q (features `1..=Q`).
    pub q: usize,
    /// Channels rescaled to `[0, 1]` per block (depth, position, user);
    /// normals and AO are used as given (already bounded).
    pub scaled: [bool; MAX_GUIDES],
    /// Channels whose square is a feature (after rescaling).
    pub squares: [usize; 3],
    /// How many entries of `squares` are used (0, 1 or 3).
    pub n_squares: usize,
}

impl FeatureSet {
    /// The features of `set` (at most 4 user channels); with `quadratic`, the
    /// squares of the position channels, or of depth without position.
    pub fn new(set: &GuideSet, quadratic: bool) -> Self {
        let mut scaled = [false; MAX_GUIDES];
        let mut squares = [0; 3];
        let mut n_squares = 0;
        let mut q = 0;
        if set.normal {
            q += 3;
        }
        let depth = q;
        if set.depth {
            scaled[q] = true;
            q += 1;
        }
        let pos = q;
        if set.position {
            for s in &mut scaled[q..q + 3] {
                *s = true;
            }
            q += 3;
        }
        if set.ao {
            q += 1;
        }
        for _ in 0..set.user.min(4) {
            if q < MAX_GUIDES {
                scaled[q] = true;
            }
            q += 1;
        }
        if quadratic {
            if set.position {
                squares = [pos, pos + 1, pos + 2];
                n_squares = 3;
            } else if set.depth {
                squares[0] = depth;
                n_squares = 1;
            }
        }
        FeatureSet { q, scaled, squares, n_squares }
    }
    /// Number of features M (the constant included).
    pub const fn count(&self) -> usize {
        1 + self.q + self.n_squares
    }
}

/// f32 values of a worker for `b × b` blocks and `m` features.
pub const fn worker_len(b: usize, m: usize) -> usize {
    padded_ld(b * b) * (m + 3 + 3) + 4 * b * b
}

/// A worker buffer split into its regions.
#[derive(Debug)]
pub struct Worker<'w> {
    /// The fit matrix `[features + noise | noisy r, g, b]`, column-major,
    /// columns `ld` apart ([`padded_ld`]), overwritten by the QR.
    pub a: &'w mut [f32],
    /// The model's three channels, `ld` apart.
    pub model: &'w mut [f32],
    /// Distance between columns of `a` and of `model` ([`padded_ld`] of B²).
    pub ld: usize,
    /// 1 where the pixel's own guides are finite (it can use the model).
    pub guide_ok: &'w mut [f32],
    /// 1 where the row takes part in the fit.
    pub valid: &'w mut [f32],
    /// `2·B²` values of regularisation noise ([`noise_table`]).
    pub noise: &'w mut [f32],
}

impl<'w> Worker<'w> {
    /// Splits `buf` for `b × b` blocks and `m` features; `None` if it is
    /// shorter than [`worker_len`]`(b, m)`.
    pub fn split(buf: &'w mut [f32], b: usize, m: usize) -> Option<Self> {
        let n = b * b;
        if buf.len() < worker_len(b, m) {
            return None;
        }
        let ld = padded_ld(n);
        let (a, rest) = buf.split_at_mut(ld * (m + 3));
        let (model, rest) = rest.split_at_mut(3 * ld);
        let (guide_ok, rest) = rest.split_at_mut(n);
        let (valid, rest) = rest.split_at_mut(n);
        let noise = &mut rest[..2 * n];
        Some(Worker { a, model, ld, guide_ok, valid, noise })
    }
}

/// `i` reflected into `0..n` (… 1 0 | 0 1 … n−1 | n−1 n−2 …), for any `i`.
pub fn mirror(i: i64, n: usize) -> usize {
    let n = n as i64;
    let p = i.rem_euclid(2 * n);
    (if p < n { p } else { 2 * n - 1 - p }) as usize
}

/// Reads `len` pixels of channels `0..N` of row `y`, from column `x0` on, into
/// `dst` (one slice per channel), mirroring columns outside the image. The
/// span inside the image is read in one pass ([`ImageView::read_row_n`]).
fn read_span<const N: usize>(v: &ImageView<'_>, y: usize, x0: i64, dst: [&mut [f32]; N]) -> Option<()> {
    let w = v.width() as i64;
    let len = dst[0].len() as i64;
    let a = x0.clamp(0, w);
    let b = (x0 + len).clamp(0, w);
    let mut dst = dst;
    if b > a {
        let (s, e) = ((a - x0) as usize, (b - x0) as usize);
        let mut it = dst.iter_mut();
        let inner: [&mut [f32]; N] = core::array::from_fn(|_| match it.next() {
            Some(d) => &mut d[s..e],
            None => &mut [],
        });
        v.read_row_n(y, a as usize, inner)?;
    }
    // the mirrored margins: each is a run of the image read backwards (pixel
    // `−1 − k` is pixel `k`, pixel `w + k` is `w − 1 − k`), so read it forwards
    // and reverse it; pixel by pixel when a margin is wider than the image
    let left = (a - x0).clamp(0, len) as usize;
    let right = ((b - x0).max(0) as usize).max(left);
    let len = len as usize;
    if left > 0 && (left as i64) <= w && x0 + left as i64 == 0 {
        let mut it = dst.iter_mut();
        let part: [&mut [f32]; N] = core::array::from_fn(|_| match it.next() {
            Some(d) => &mut d[..left],
            None => &mut [],
        });
        v.read_row_n(y, 0, part)?;
        dst.iter_mut().for_each(|d| d[..left].reverse());
    } else {
        for i in 0..left {
            for (c, d) in dst.iter_mut().enumerate() {
                d[i] = v.get(mirror(x0 + i as i64, w as usize), y, c)?;
            }
        }
    }
    let n_right = len - right;
    if n_right > 0 && (n_right as i64) <= w && x0 + right as i64 == w {
        let mut it = dst.iter_mut();
        let part: [&mut [f32]; N] = core::array::from_fn(|_| match it.next() {
            Some(d) => &mut d[right..],
            None => &mut [],
        });
        v.read_row_n(y, (w as usize) - n_right, part)?;
        dst.iter_mut().for_each(|d| d[right..].reverse());
    } else {
        for i in right..len {
            for (c, d) in dst.iter_mut().enumerate() {
                d[i] = v.get(mirror(x0 + i as i64, w as usize), y, c)?;
            }
        }
    }
    Some(())
}

/// What gathering one block found.
#[derive(Clone, Copy, Debug, Default)]
pub struct Gathered {
    /// Rows used by the fit.
    pub valid: usize,
    /// Mean noisy colour of the valid rows (fallback output).
    pub mean: [f32; 3],
    /// NaN/Inf counts over the block's pixels inside the image (mirrored
    /// copies are not counted twice).
    pub nonfinite_noisy: u64,
    /// The same for the guides: pixels with a non-finite guide channel.
    pub nonfinite_guides: u64,
    /// Feature of guide channel `g`: `clamp((v − lo[g]) · inv[g], min[g], max[g])`
    /// (the per-block rescaling to `[0, 1]`; identity for normals and AO).
    pub scale: Scaling,
}

/// The per-block affine map of every guide channel onto its feature.
#[derive(Clone, Copy, Debug)]
pub struct Scaling {
    /// Per channel: subtracted first (the block's minimum for rescaled
    /// channels, else 0).
    pub lo: [f32; MAX_GUIDES],
    /// Per channel: the factor then applied (1 / the block's range for
    /// rescaled channels, 0 for a constant one, else 1).
    pub inv: [f32; MAX_GUIDES],
    /// Per channel: the lower clamp (0 for rescaled channels, else −∞).
    pub min: [f32; MAX_GUIDES],
    /// Per channel: the upper clamp (1 for rescaled channels, else +∞).
    pub max: [f32; MAX_GUIDES],
}

impl Default for Scaling {
    fn default() -> Self {
        Scaling { lo: [0.0; MAX_GUIDES], inv: [1.0; MAX_GUIDES], min: [f32::NEG_INFINITY; MAX_GUIDES], max: [f32::INFINITY; MAX_GUIDES] }
    }
}

impl Scaling {
    #[inline(always)]
    fn apply(&self, g: usize, v: f32) -> f32 {
        ((v - self.lo[g]) * self.inv[g]).max(self.min[g]).min(self.max[g])
    }
    #[inline(always)]
    fn apply8(&self, g: usize, v: f32x8) -> f32x8 {
        ((v - f32x8::splat(self.lo[g])) * f32x8::splat(self.inv[g])).fast_max(f32x8::splat(self.min[g])).fast_min(f32x8::splat(self.max[g]))
    }
}

#[inline]
fn finite(x: f32) -> bool {
    x.abs() <= f32::MAX
}

/// The pixels of one block (or, generally, `rows` rows of `stride` pixels),
/// one plane per channel (noisy r, g, b, then the guide channels), mirrored
/// outside the image. Filled per block so that it is still in L1/L2 when the
/// fit matrix is built and when the model is applied from it.
#[derive(Debug)]
pub struct Band<'b> {
    /// The channel planes, [`Band::plane`] apart, each `rows × stride` pixels.
    pub data: &'b mut [f32],
    /// Rows per plane.
    pub rows: usize,
    /// Pixels per row.
    pub stride: usize,
}

impl Band<'_> {
    /// f32 values of a band for `channels` channels.
    pub const fn len(channels: usize, rows: usize, stride: usize) -> usize {
        channels * padded_ld(rows * stride)
    }
    /// Distance between two channels' planes (padded off multiples of 4 KiB).
    pub const fn plane(&self) -> usize {
        padded_ld(self.rows * self.stride)
    }
    /// Reads the rows `y0..y0 + rows` (mirrored) of every channel, columns
    /// `x0..x0 + stride` (mirrored); three consecutive channels of one image
    /// are read in one pass.
    pub fn fill(&mut self, src: &Sources<'_>, (x0, y0): (i64, i64), h: usize) -> Result<(), Error> {
        let bad = Error::InvalidTile { index: 0, count: 0 };
        let (plane, stride) = (self.plane(), self.stride);
        for j in 0..self.rows {
            let y = mirror(y0 + j as i64, h);
            for &(v, first, channels) in src.iter() {
                let at = first * plane + j * stride;
                if channels == 3 {
                    let (p0, rest) = self.data[at..].split_at_mut(plane);
                    let (p1, p2) = rest.split_at_mut(plane);
                    read_span(&v, y, x0, [&mut p0[..stride], &mut p1[..stride], &mut p2[..stride]]).ok_or(bad)?;
                } else {
                    read_span(&v, y, x0, [&mut self.data[at..at + stride]]).ok_or(bad)?;
                }
            }
        }
        Ok(())
    }

    /// Hints that [`Band::fill`] will soon read rows `rows` of the band at
    /// `(x0, y0)` with `stride` pixels (mirrored rows as `fill` reads them; the
    /// mirrored columns, a few pixels at the image's borders, are left out).
    /// BMFR reads each block row of every input as its own short run, more
    /// runs than the hardware prefetchers follow: asked for while the previous
    /// chunk's blocks are fitted, they arrive before `fill` reads them.
    pub fn prefetch(src: &Sources<'_>, (x0, y0): (i64, i64), stride: usize, rows: core::ops::Range<usize>, h: usize) {
        for j in rows {
            let y = mirror(y0 + j as i64, h);
            for (v, _, _) in src.iter() {
                let w = v.width() as i64;
                let (a, b) = (x0.clamp(0, w) as usize, (x0 + stride as i64).clamp(0, w) as usize);
                v.prefetch_span(y, a, b - a);
            }
        }
    }
}

/// The images a [`Band`] is read from, each with the band plane of its first
/// channel and how many channels it gives (3, read in one pass, or 1): the
/// noisy colour, then the guides, where three consecutive channels of one
/// image (normal, position) are joined into one view. Built once per tile.
#[derive(Clone, Copy, Debug)]
pub struct Sources<'a> {
    views: [Option<(ImageView<'a>, usize, usize)>; 1 + MAX_GUIDES],
}

impl<'a> Sources<'a> {
    /// The noisy image and the first `q` guide channels of `frame`
    /// ([`Error::GuideMismatch`] where one is missing).
    pub fn new(frame: &CheckedFrame<'a>, q: usize) -> Result<Self, Error> {
        let view = |g: usize| frame.guides.get(g).copied().flatten().ok_or(Error::GuideMismatch);
        let mut views = [None; 1 + MAX_GUIDES];
        views[0] = Some((frame.noisy, 0, 3));
        let (mut n, mut g) = (1, 0);
        while g < q {
            let joined = if g + 3 <= q { ImageView::join3(&view(g)?, &view(g + 1)?, &view(g + 2)?) } else { None };
            let (v, channels) = match joined {
                Some(v) => (v, 3),
                None => (view(g)?, 1),
            };
            views[n] = Some((v, 3 + g, channels));
            (n, g) = (n + 1, g + channels);
        }
        Ok(Sources { views })
    }
    fn iter(&self) -> impl Iterator<Item = &(ImageView<'a>, usize, usize)> {
        self.views.iter().flatten()
    }
}

#[inline(always)]
fn load8(s: &[f32], i: usize) -> f32x8 {
    f32x8::from(<[f32; 8]>::try_from(&s[i..i + 8]).unwrap_or([0.0; 8]))
}
#[inline(always)]
fn store8(s: &mut [f32], i: usize, v: f32x8) {
    s[i..i + 8].copy_from_slice(&<[f32; 8]>::from(v));
}
#[inline(always)]
fn finite8(v: f32x8) -> f32x8 {
    v.abs().simd_le(f32x8::splat(f32::MAX))
}

/// Fills the masks `wb.guide_ok` and `wb.valid` of block `bx` of the band
/// and finds the block's rescaling of the guides (over the valid rows) and
/// the mean noisy colour. `origin` is the block's top-left pixel (only
/// pixels inside the image are counted as NaN/Inf).
#[allow(clippy::too_many_arguments)]
pub fn gather_block(
    fs: &FeatureSet,
    band: &Band<'_>,
    bx: usize,
    (w, h): (usize, usize),
    origin: (i64, i64),
    wb: &mut Worker<'_>,
) -> Result<Gathered, Error> {
    let b = band.rows;
    let n = b * b;
    let q = fs.q;
    let plane = band.plane();
    let at = |ch: usize, j: usize| ch * plane + j * band.stride + bx * b;
    let data = &*band.data;
    // Pass 1: masks, noisy sums and the scaled channels' ranges over valid rows.
    let mut lo = [f32x8::splat(f32::INFINITY); MAX_GUIDES];
    let mut hi = [f32x8::splat(f32::NEG_INFINITY); MAX_GUIDES];
    let (mut los, mut his) = ([f32::INFINITY; MAX_GUIDES], [f32::NEG_INFINITY; MAX_GUIDES]);
    let mut sum = [f32x8::ZERO; 3];
    let mut sums = [0f32; 3];
    let mut nvalid = 0usize;
    let mut all_ok = true;
    for j in 0..b {
        let mut i = 0;
        while i + 8 <= b {
            let mut ok = f32x8::splat(1.0).simd_eq(f32x8::splat(1.0));
            for g in 0..q {
                ok &= finite8(load8(data, at(3 + g, j) + i));
            }
            let mut valid = ok;
            for c in 0..3 {
                valid &= finite8(load8(data, at(c, j) + i));
            }
            for g in 0..q {
                if fs.scaled[g] {
                    let v = load8(data, at(3 + g, j) + i);
                    // (not `valid.select(lo.min(v), lo)`: LLVM turns that
                    // into a masked store, microcoded and slow on AMD)
                    lo[g] = lo[g].fast_min(valid.select(v, f32x8::splat(f32::INFINITY)));
                    hi[g] = hi[g].fast_max(valid.select(v, f32x8::splat(f32::NEG_INFINITY)));
                }
            }
            for (c, s) in sum.iter_mut().enumerate() {
                *s += valid.select(load8(data, at(c, j) + i), f32x8::ZERO);
            }
            let one = f32x8::splat(1.0);
            store8(wb.guide_ok, j * b + i, ok.select(one, f32x8::ZERO));
            store8(wb.valid, j * b + i, valid.select(one, f32x8::ZERO));
            let count = valid.to_bitmask().count_ones() as usize;
            nvalid += count;
            all_ok &= count == 8;
            i += 8;
        }
        while i < b {
            let ok = (0..q).all(|g| finite(data[at(3 + g, j) + i]));
            let valid = ok && (0..3).all(|c| finite(data[at(c, j) + i]));
            if valid {
                for g in 0..q {
                    let v = data[at(3 + g, j) + i];
                    los[g] = los[g].min(v);
                    his[g] = his[g].max(v);
                }
                for (c, s) in sums.iter_mut().enumerate() {
                    *s += data[at(c, j) + i];
                }
            }
            wb.guide_ok[j * b + i] = ok as u32 as f32;
            wb.valid[j * b + i] = valid as u32 as f32;
            nvalid += valid as usize;
            all_ok &= valid;
            i += 1;
        }
    }
    let mut g = Gathered { valid: nvalid, ..Default::default() };
    for f in 0..q {
        if !fs.scaled[f] {
            continue;
        }
        let l = lo[f].to_array().into_iter().fold(los[f], f32::min);
        let hv = hi[f].to_array().into_iter().fold(his[f], f32::max);
        let range = hv - l;
        let sc = &mut g.scale;
        if range > 0.0 && range.is_finite() {
            (sc.lo[f], sc.inv[f], sc.min[f], sc.max[f]) = (l, 1.0 / range, 0.0, 1.0);
        } else {
            // constant: collinear with the constant feature
            (sc.lo[f], sc.inv[f], sc.min[f], sc.max[f]) = (0.0, 0.0, 0.0, 0.0);
        }
    }
    if nvalid > 0 {
        for c in 0..3 {
            g.mean[c] = (sum[c].reduce_add() + sums[c]) / nvalid as f32;
        }
    }
    if !all_ok {
        // Rare: count what was not finite (inside the image only).
        for r in 0..n {
            if wb.valid[r] != 0.0 {
                continue;
            }
            let (i, j) = (r % b, r / b);
            let (x, y) = (origin.0 + i as i64, origin.1 + j as i64);
            if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
                g.nonfinite_noisy += (0..3).any(|c| !finite(data[at(c, j) + i])) as u64;
                g.nonfinite_guides += (wb.guide_ok[r] == 0.0) as u64;
            }
        }
    }
    Ok(g)
}

/// Fills `table` with the regularisation noise: `(hash(seed + i) >> 8)`
/// scaled onto `[−amp, amp)` (uniform; the same bits on every platform).
/// Filled once per tile: a block's features read windows of it ([`fit_matrix`]),
/// which costs one load per 8 values instead of a hash (~1 ms of the 1080p fit).
pub fn noise_table(table: &mut [f32], seed: u32, amp: f32) {
    let scale = 2.0 * amp / (1u32 << 24) as f32;
    let mut chunks = table.chunks_exact_mut(8);
    let mut i = 0u32;
    for c in &mut chunks {
        let x = u32x8::splat(seed.wrapping_add(i)) + u32x8::from([0, 1, 2, 3, 4, 5, 6, 7]);
        let u: i32x8 = bytemuck::cast(hash8(x) >> 8);
        c.copy_from_slice(&(f32x8::from_i32x8(u) * f32x8::splat(scale) - f32x8::splat(amp)).to_array());
        i = i.wrapping_add(8);
    }
    for v in chunks.into_remainder() {
        *v = (hash(seed.wrapping_add(i)) >> 8) as f32 * scale - amp;
        i = i.wrapping_add(1);
    }
}

/// Where feature `f`'s noise starts in the `2n`-value table for the block
/// whose seed is `seed`: its rows `0..n` read `table[o..o + n]`, `o < n`, a
/// window that differs per block and feature.
#[inline]
fn noise_offset(seed: u32, f: usize, n: usize) -> usize {
    hash(seed ^ ((f as u32) << 24)) as usize % n
}

/// Fills the block's fit matrix `wb.a` (row `j·B + i` = pixel `(i, j)`):
/// column 0 = 1, then every guide feature (rescaled with `g.scale`), then
/// the squares, each plus the regularisation noise (uniform in `[−amp, amp]`:
/// a window of `wb.noise`, [`noise_table`], picked by `seed`), then the noisy
/// colour; rows that are not valid are 0. Returns each column's sum, i.e.
/// its dot product with column 0 (the 0/1 row mask), which the QR's first
/// reflection needs ([`lstsq_shrunk_ld`]'s `dots0`): formed here from the values
/// as they are stored, not in another pass over the matrix. (Tried: feeding 128-row panels to a streamed TSQR that stays
/// in L1 — 12 % slower overall at 1080p; the QR is not bound by L2 here.)
pub fn fit_matrix(fs: &FeatureSet, band: &Band<'_>, bx: usize, g: &Gathered, seed: u32, wb: &mut Worker<'_>) -> [f32; MAX_FEATURES + 3] {
    let b = band.rows;
    let n = b * b;
    let m = fs.count();
    let q = fs.q;
    let plane = band.plane();
    let at = |ch: usize, j: usize| ch * plane + j * band.stride + bx * b;
    let data = &*band.data;
    let sc = g.scale;
    let mut off = [0usize; MAX_FEATURES];
    for (f, o) in off.iter_mut().enumerate().take(m).skip(1) {
        *o = noise_offset(seed, f, n);
    }
    let noise = &*wb.noise;
    let ld = wb.ld;
    let a = &mut *wb.a;
    a[..n].copy_from_slice(wb.valid);
    let mut sum8 = [f32x8::ZERO; MAX_FEATURES + 3];
    let mut sum = [0f32; MAX_FEATURES + 3];
    for j in 0..b {
        let mut i = 0;
        while i + 8 <= b {
            let r = j * b + i;
            let valid = load8(wb.valid, r).simd_ne(f32x8::ZERO);
            let mut feat = [f32x8::ZERO; MAX_GUIDES];
            for (f, x) in feat.iter_mut().enumerate().take(q) {
                *x = sc.apply8(f, load8(data, at(3 + f, j) + i));
                let v = valid.select(*x + load8(noise, off[1 + f] + r), f32x8::ZERO);
                sum8[1 + f] += v;
                store8(a, (1 + f) * ld + r, v);
            }
            for s in 0..fs.n_squares {
                let x = feat[fs.squares[s]];
                let f = 1 + q + s;
                let v = valid.select(x * x + load8(noise, off[f] + r), f32x8::ZERO);
                sum8[f] += v;
                store8(a, f * ld + r, v);
            }
            for c in 0..3 {
                let v = valid.select(load8(data, at(c, j) + i), f32x8::ZERO);
                sum8[m + c] += v;
                store8(a, (m + c) * ld + r, v);
            }
            i += 8;
        }
        while i < b {
            let r = j * b + i;
            let valid = wb.valid[r] != 0.0;
            let mut feat = [0f32; MAX_GUIDES];
            for f in 0..q {
                feat[f] = sc.apply(f, data[at(3 + f, j) + i]);
                a[(1 + f) * ld + r] = if valid { feat[f] + noise[off[1 + f] + r] } else { 0.0 };
            }
            for s in 0..fs.n_squares {
                let x = feat[fs.squares[s]];
                let f = 1 + q + s;
                a[f * ld + r] = if valid { x * x + noise[off[f] + r] } else { 0.0 };
            }
            for c in 0..3 {
                a[(m + c) * ld + r] = if valid { data[at(c, j) + i] } else { 0.0 };
            }
            for (c, s) in sum.iter_mut().enumerate().take(m + 3).skip(1) {
                *s += a[c * ld + r];
            }
            i += 1;
        }
    }
    sum[0] = g.valid as f32;
    for c in 1..m + 3 {
        sum[c] += sum8[c].reduce_add();
    }
    sum
}

/// Evaluates the fitted model `coef` (`m × 3`, row-major) on the block in
/// `band` into `model` (the three channels' `B²` values, `ld` apart):
/// features recomputed from the band with the block's scaling; pixels whose
/// own guides are not finite take `g.mean`; negative values clamped to 0 when
/// `clamp`; always finite.
#[allow(clippy::too_many_arguments)]
pub fn apply_block(
    fs: &FeatureSet,
    band: &Band<'_>,
    bx: usize,
    coef: &[f32],
    g: &Gathered,
    guide_ok: &[f32],
    clamp: bool,
    model: &mut [f32],
    ld: usize,
) {
    let b = band.rows;
    let n = ld;
    let (m, q) = (fs.count(), fs.q);
    let plane = band.plane();
    let at = |ch: usize, j: usize| ch * plane + j * band.stride + bx * b;
    let data = &*band.data;
    let sc = &g.scale;
    let lanes: [[f32x8; 3]; MAX_FEATURES] =
        core::array::from_fn(|f| core::array::from_fn(|c| f32x8::splat(if f < m { coef[f * 3 + c] } else { 0.0 })));
    let floor = if clamp { 0.0 } else { f32::NEG_INFINITY };
    for j in 0..b {
        let mut i = 0;
        while i + 8 <= b {
            let mut feat = [f32x8::ZERO; MAX_GUIDES];
            let mut o = lanes[0];
            for f in 0..q {
                feat[f] = sc.apply8(f, load8(data, at(3 + f, j) + i));
                for c in 0..3 {
                    o[c] = feat[f].mul_add(lanes[1 + f][c], o[c]);
                }
            }
            for s in 0..fs.n_squares {
                let v = feat[fs.squares[s]] * feat[fs.squares[s]];
                for c in 0..3 {
                    o[c] = v.mul_add(lanes[1 + q + s][c], o[c]);
                }
            }
            let ok = load8(guide_ok, j * b + i).simd_ne(f32x8::ZERO);
            for (c, oc) in o.iter().enumerate() {
                let v = ok.select(*oc, f32x8::splat(g.mean[c])).fast_max(f32x8::splat(floor));
                store8(model, c * n + j * b + i, finite8(v).select(v, f32x8::ZERO));
            }
            i += 8;
        }
        while i < b {
            let mut feat = [0f32; MAX_GUIDES];
            let mut o = [coef[0], coef[1], coef[2]];
            for f in 0..q {
                feat[f] = sc.apply(f, data[at(3 + f, j) + i]);
                for (c, oc) in o.iter_mut().enumerate() {
                    *oc += feat[f] * coef[(1 + f) * 3 + c];
                }
            }
            for s in 0..fs.n_squares {
                let v = feat[fs.squares[s]] * feat[fs.squares[s]];
                for (c, oc) in o.iter_mut().enumerate() {
                    *oc += v * coef[(1 + q + s) * 3 + c];
                }
            }
            let ok = guide_ok[j * b + i] != 0.0;
            for (c, oc) in o.iter().enumerate() {
                let v = if ok { *oc } else { g.mean[c] }.max(floor);
                model[c * n + j * b + i] = if finite(v) { v } else { 0.0 };
            }
            i += 1;
        }
    }
}

/// Per-(frame, block) seed of the regularisation noise.
pub fn seed(index: u32, block_id: u32) -> u32 {
    hash(index.wrapping_mul(0x9E37_79B9) ^ hash(block_id.wrapping_add(0x68E3_1DA4)))
}

use crate::hash::{lowbias32 as hash, lowbias32x8 as hash8};

#[cfg(test)]
mod tests {
    use super::*;

    /// The table's lanes and its scalar remainder give the same values, all in
    /// `[−amp, amp)` and centred (a biased noise would shift every feature).
    #[test]
    fn noise_table_is_uniform_in_range_and_lane_exact() {
        let amp = 0.01;
        for len in [0usize, 1, 7, 8, 2048, 2051] {
            let mut t = [0f32; 2051];
            let t = &mut t[..len];
            noise_table(t, 0xDEAD_BEEF, amp);
            let scale = 2.0 * amp / (1u32 << 24) as f32;
            for (i, v) in t.iter().enumerate() {
                let want = (hash(0xDEAD_BEEFu32.wrapping_add(i as u32)) >> 8) as f32 * scale - amp;
                assert_eq!(*v, want, "value {i} of {len}");
                assert!((-amp..amp).contains(v));
            }
            if len >= 2048 {
                let mean = t.iter().map(|&v| v as f64).sum::<f64>() / len as f64;
                assert!(mean.abs() < 0.05 * amp as f64, "mean {mean}");
                let var = t.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / len as f64;
                let uniform = (amp as f64).powi(2) / 3.0;
                assert!((var / uniform - 1.0).abs() < 0.1, "variance {var} vs {uniform}");
            }
        }
        let mut a = [0f32; 64];
        let mut b = [0f32; 64];
        noise_table(&mut a, 1, amp);
        noise_table(&mut b, 2, amp);
        assert_ne!(a, b, "the seed changes the noise");
    }

    /// Mirrored margins read as reversed runs equal the per-pixel mirror.
    #[test]
    fn read_span_mirrors_like_the_index_map() {
        let (w, h) = (9usize, 2usize);
        let data: [f32; 9 * 2 * 3] = core::array::from_fn(|i| i as f32);
        let v = ImageView::interleaved(&data, w, h, 3).unwrap();
        for x0 in -12i64..14 {
            for len in [1usize, 4, 9, 16, 30] {
                let mut p = [[0f32; 30]; 3];
                let [a, b, c] = &mut p;
                read_span(&v, 1, x0, [&mut a[..len], &mut b[..len], &mut c[..len]]).unwrap();
                for i in 0..len {
                    let x = mirror(x0 + i as i64, w);
                    for (ch, plane) in p.iter().enumerate() {
                        assert_eq!(plane[i], data[(w + x) * 3 + ch], "x0 {x0} len {len} i {i}");
                    }
                }
            }
        }
    }
}
