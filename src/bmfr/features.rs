//! BMFR's per-block feature matrix: gathering (with mirrored borders and
//! NaN/Inf exclusion), per-block rescaling to `[0, 1]`, squared features, and
//! the stochastic regularisation noise.
//!
//! Column-major block matrices, `n = B²` rows (row `j·B + i` = pixel `(i, j)`
//! of the block):
//! * `clean`: the `m` features as applied (column 0 = 1);
//! * `valid`: 1 on rows the fit uses (noisy and guides finite), else 0;
//! * `a`: the fit matrix `[features + noise | noisy r, g, b]`, `n × (m + 3)`,
//!   overwritten by the QR.

use super::CheckedFrame;
use crate::error::Error;
use crate::guides::{GuideSet, MAX_GUIDES};
use crate::image::ImageView;

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
    pub n_squares: usize,
}

impl FeatureSet {
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

/// f32 values of a worker for `n` rows and `m` features.
pub const fn worker_len(n: usize, m: usize) -> usize {
    n * (m + 3) + n * m + 2 * n
}

/// A worker buffer split into its regions.
#[derive(Debug)]
pub struct Worker<'w> {
    pub a: &'w mut [f32],
    pub clean: &'w mut [f32],
    /// 1 where the pixel's own guides are finite (it can use the model).
    pub guide_ok: &'w mut [f32],
    /// 1 where the row takes part in the fit.
    pub valid: &'w mut [f32],
}

impl<'w> Worker<'w> {
    pub fn split(buf: &'w mut [f32], n: usize, m: usize) -> Option<Self> {
        if buf.len() < worker_len(n, m) {
            return None;
        }
        let (a, rest) = buf.split_at_mut(n * (m + 3));
        let (clean, rest) = rest.split_at_mut(n * m);
        let (guide_ok, rest) = rest.split_at_mut(n);
        let valid = &mut rest[..n];
        Some(Worker { a, clean, guide_ok, valid })
    }
}

/// `i` reflected into `0..n` (… 1 0 | 0 1 … n−1 | n−1 n−2 …), for any `i`.
pub fn mirror(i: i64, n: usize) -> usize {
    let n = n as i64;
    let p = i.rem_euclid(2 * n);
    (if p < n { p } else { 2 * n - 1 - p }) as usize
}

/// Reads `dst.len()` pixels of channel `c`, row `y`, from column `x0` on,
/// mirroring columns outside the image.
fn read_span(v: &ImageView<'_>, c: usize, y: usize, x0: i64, dst: &mut [f32]) -> Option<()> {
    let w = v.width() as i64;
    let len = dst.len() as i64;
    let a = x0.clamp(0, w);
    let b = (x0 + len).clamp(0, w);
    if b > a {
        v.read_row(y, c, a as usize, &mut dst[(a - x0) as usize..(b - x0) as usize])?;
    }
    // the mirrored margins, pixel by pixel
    let (left, right) = ((a - x0).min(len) as usize, ((b - x0).max(0) as usize).max((a - x0).min(len) as usize));
    for i in (0..left).chain(right..dst.len()) {
        dst[i] = v.get(mirror(x0 + i as i64, w as usize), y, c)?;
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
    pub nonfinite_guides: u64,
}

#[inline]
fn finite(x: f32) -> bool {
    x.abs() <= f32::MAX
}

/// The frame rows of one tile (a row of blocks), one plane per channel
/// (noisy r, g, b, then the guide channels), `rows` rows of `stride` pixels
/// starting at the grid's left edge, with mirrored margins filled in.
#[derive(Debug)]
pub struct Band<'b> {
    pub data: &'b mut [f32],
    pub rows: usize,
    pub stride: usize,
}

impl Band<'_> {
    /// f32 values of a band for `channels` channels.
    pub const fn len(channels: usize, rows: usize, stride: usize) -> usize {
        channels * rows * stride
    }
    /// Reads the rows `y0..y0 + rows` (mirrored) of every channel, columns
    /// `x0..x0 + stride` (mirrored): each frame row is read once per channel.
    pub fn fill(&mut self, frame: &CheckedFrame<'_>, q: usize, (x0, y0): (i64, i64), h: usize) -> Result<(), Error> {
        let bad = Error::InvalidTile { index: 0, count: 0 };
        let plane = self.rows * self.stride;
        for j in 0..self.rows {
            let y = mirror(y0 + j as i64, h);
            for ch in 0..3 + q {
                let dst = &mut self.data[ch * plane + j * self.stride..ch * plane + (j + 1) * self.stride];
                if ch < 3 {
                    read_span(&frame.noisy, ch, y, x0, dst).ok_or(bad)?;
                } else {
                    let v = frame.guides[ch - 3].as_ref().ok_or(Error::GuideMismatch)?;
                    read_span(v, 0, y, x0, dst).ok_or(bad)?;
                }
            }
        }
        Ok(())
    }
}

/// Fills `wb.clean` (features, rescaled, squared) and the noisy columns of
/// `wb.a` for block `bx` of the band; `origin` is the block's top-left pixel
/// (for counting only pixels inside the image). Invalid rows are 0.
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
    let m = fs.count();
    let q = fs.q;
    let plane = band.rows * band.stride;
    for j in 0..b {
        let src = |ch: usize| &band.data[ch * plane + j * band.stride + bx * b..ch * plane + j * band.stride + (bx + 1) * b];
        for c in 0..3 {
            wb.a[(m + c) * n + j * b..(m + c) * n + (j + 1) * b].copy_from_slice(src(c));
        }
        for g in 0..q {
            wb.clean[(1 + g) * n + j * b..(1 + g) * n + (j + 1) * b].copy_from_slice(src(3 + g));
        }
    }
    // Validity masks: guide_ok (own guides finite), valid (guides and noisy).
    let (ones, feats) = wb.clean.split_at_mut(n);
    ones.fill(1.0);
    let valid = &mut *wb.valid;
    wb.guide_ok.fill(1.0);
    for g in 0..q {
        for (ok, &v) in wb.guide_ok.iter_mut().zip(&feats[g * n..(g + 1) * n]) {
            *ok = if finite(v) { *ok } else { 0.0 };
        }
    }
    valid.copy_from_slice(wb.guide_ok);
    for c in 0..3 {
        for (ok, &v) in valid.iter_mut().zip(&wb.a[(m + c) * n..(m + c + 1) * n]) {
            *ok = if finite(v) { *ok } else { 0.0 };
        }
    }
    let mut g = Gathered { valid: valid.iter().filter(|&&v| v != 0.0).count(), ..Default::default() };
    if g.valid < n {
        // Rare: count what was not finite (inside the image only) and zero it.
        for r in 0..n {
            if valid[r] != 0.0 {
                continue;
            }
            let (x, y) = (origin.0 + (r % b) as i64, origin.1 + (r / b) as i64);
            let inside = x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h;
            let noisy_bad = (0..3).any(|c| !finite(wb.a[(m + c) * n + r]));
            if inside {
                g.nonfinite_noisy += noisy_bad as u64;
                g.nonfinite_guides += (wb.guide_ok[r] == 0.0) as u64;
            }
            for c in 0..3 {
                wb.a[(m + c) * n + r] = 0.0;
            }
            if wb.guide_ok[r] == 0.0 {
                for f in 0..q {
                    feats[f * n + r] = 0.0;
                }
            }
        }
    }
    if wb.guide_ok.contains(&0.0) {
        // only needed as the fallback of pixels with non-finite guides
        for c in 0..3 {
            let s: f64 = wb.a[(m + c) * n..(m + c + 1) * n].iter().map(|&v| v as f64).sum();
            g.mean[c] = if g.valid > 0 { (s / g.valid as f64) as f32 } else { 0.0 };
        }
    }
    // Per-block rescaling to [0, 1] over the valid rows.
    for f in 0..q {
        if !fs.scaled[f] {
            continue;
        }
        let col = &mut feats[f * n..(f + 1) * n];
        let (lo, hi) = min_max(col, valid);
        let range = hi - lo;
        if range > 0.0 && range.is_finite() {
            let inv = 1.0 / range;
            // (rows excluded only for their noisy value keep a clamped feature)
            for (v, &ok) in col.iter_mut().zip(wb.guide_ok.iter()) {
                *v = ((*v - lo) * inv).clamp(0.0, 1.0) * ok;
            }
        } else {
            col.fill(0.0); // constant: collinear with the constant feature
        }
    }
    for s in 0..fs.n_squares {
        let src = fs.squares[s];
        let (head, tail) = feats.split_at_mut((q + s) * n);
        for (d, &v) in tail[..n].iter_mut().zip(&head[src * n..(src + 1) * n]) {
            *d = v * v;
        }
    }
    Ok(g)
}

/// Minimum and maximum of `v` over the rows where `mask != 0` (f32x8 lanes).
fn min_max(v: &[f32], mask: &[f32]) -> (f32, f32) {
    use wide::f32x8;
    let (mut lo, mut hi) = (f32x8::splat(f32::INFINITY), f32x8::splat(f32::NEG_INFINITY));
    let (vc, mc) = (v.chunks_exact(8), mask.chunks_exact(8));
    let (vr, mr) = (vc.remainder(), mc.remainder());
    for (x, m) in vc.zip(mc) {
        let x = f32x8::from(<[f32; 8]>::try_from(x).unwrap_or([0.0; 8]));
        let keep = f32x8::from(<[f32; 8]>::try_from(m).unwrap_or([0.0; 8])).simd_ne(f32x8::ZERO);
        lo = keep.select(lo.fast_min(x), lo);
        hi = keep.select(hi.fast_max(x), hi);
    }
    let (mut l, mut h) =
        (lo.to_array().into_iter().fold(f32::INFINITY, f32::min), hi.to_array().into_iter().fold(f32::NEG_INFINITY, f32::max));
    for (&x, &m) in vr.iter().zip(mr) {
        if m != 0.0 {
            l = l.min(x);
            h = h.max(x);
        }
    }
    (l, h)
}

/// Per-(frame, block) seed of the regularisation noise.
pub fn seed(index: u32, block_id: u32) -> u32 {
    hash(index.wrapping_mul(0x9E37_79B9) ^ hash(block_id.wrapping_add(0x68E3_1DA4)))
}

use crate::hash::lowbias32 as hash;

/// Fills the feature columns of `a`: `clean` on valid rows (0 elsewhere),
/// plus uniform noise in `[−amp, amp]` on every feature but the constant
/// (stochastic regularisation, for the fit only).
pub fn regularize(fs: &FeatureSet, wb: &mut Worker<'_>, n: usize, amp: f32, seed: u32) {
    let m = fs.count();
    let valid = &*wb.valid;
    wb.a[..n].copy_from_slice(valid);
    let scale = 2.0 * amp / (1u32 << 24) as f32;
    for f in 1..m {
        let base = seed ^ ((f as u32) << 24);
        let col = &mut wb.a[f * n..(f + 1) * n];
        let clean = &wb.clean[f * n..(f + 1) * n];
        for (r, ((v, &c), &ok)) in col.iter_mut().zip(clean).zip(valid).enumerate() {
            let u = (hash(base.wrapping_add(r as u32)) >> 8) as f32;
            *v = (c + (u * scale - amp)) * ok;
        }
    }
}
