//! The firefly clamp: a sample of the noisy light far brighter than the
//! brightest samples around it is scaled down before any method reads it.
//!
//! **Rule.** The frame is cut into bands of [`CELL`] rows and each band into
//! cells of [`CELL`] × [`CELL`] pixels. Each sample has a luminance
//! ℓ = [`LUMA`]·y (negative counts as 0); each cell keeps the largest ℓ of its
//! finite samples, their sum and their count. Cell `i`'s neighbourhood is the
//! cells `i − REACH ..= i + REACH` of its band (104 × 8 pixels). Its reference
//! is the larger of
//! - the *third largest* cell maximum of the neighbourhood, and
//! - the neighbourhood's mean ℓ leaving out the cell with the largest sum.
//!
//! A sample with ℓ > `k · reference` has its three channels scaled by
//! `k · reference / ℓ`, keeping its colour. `k` is the clamp's threshold
//! factor (`fireflies: Some(k)` in the config, [`DEFAULT_STRENGTH`]).
//! Non-finite samples are left for the method to exclude and count; a
//! neighbourhood without finite samples outside its brightest cell clamps
//! nothing.
//!
//! **Why this rule.** An outlier is a sample the light around it does not
//! predict. Comparing with the third brightest cell, rather than with a mean,
//! tells rare outliers (one or two in a neighbourhood, which set at most the
//! two largest cell maxima) from the heavy but common tail of 1-spp light in
//! dimly lit regions, where many cells have a bright sample and so nothing is
//! clamped. On the training scenes a mean-relative threshold cost up to 5 dB
//! on dim rooms at the strength that removed the injected outliers; this rule
//! costs nothing measurable on clean frames (docs/RESULTS.md). The band is
//! what FLR's moments hold in cache as they read the light (at block size 8,
//! the default), so the clamp costs no extra pass over memory there, and a
//! band depends on nothing outside its rows: tiled output stays bit-identical
//! to whole-frame output.
//!
//! **Bias.** The clamp removes the energy above the threshold; nothing is
//! redistributed, since an outlier's energy spread over the window is exactly
//! the blotch the clamp prevents (redistributing it within the cell was
//! measured: it gave back most of the injected outliers' damage and did not
//! help clean frames). On clean frames only samples brighter than every cell
//! but two of their neighbourhood, by the factor `k`, lose energy.

use crate::kernels::LUMA;
use wide::f32x8;

/// Cell side and band height in pixels.
pub const CELL: usize = 8;
/// Cells on each side of a cell in its neighbourhood.
pub const REACH: usize = 6;
/// The default threshold factor `k`, chosen on the training scenes
/// (1.25–2 measured within 0.1 dB of each other there).
pub const DEFAULT_STRENGTH: f32 = 1.5;
/// Largest luminance a sample contributes to its cell's sum, so that sums of
/// finite samples stay finite.
const LUMA_CAP: f32 = 1e30;

/// Checks a threshold factor: finite and at least 1.
pub fn valid_strength(k: f32) -> bool {
    k.is_finite() && k >= 1.0
}

/// Cells of a band of width `width`.
pub const fn cells(width: usize) -> usize {
    width.div_ceil(CELL)
}

/// Padding on each side of the per-cell arrays [`Thresholds::finish`] reads
/// eight cells at a time, plus the last vector's overrun.
const PAD: usize = REACH + CELL;

/// f32 values [`Thresholds`] needs for a band of width `width`: per-lane sums
/// and maxima, then padded per-cell sums, maxima and counts, then the thresholds.
pub const fn work_len(width: usize) -> usize {
    let n = cells(width);
    2 * CELL * n + 3 * (n + 2 * PAD) + n
}

/// The thresholds of one band, built row by row. Each cell accumulates its
/// sums and maxima per lane (the pixel's column within the cell) and reduces
/// them in [`Thresholds::finish`], so a band's rows are read eight pixels at a
/// time (`wide`) and a partial cell at the right edge, lane by lane, with the
/// same arithmetic.
#[derive(Debug)]
pub struct Thresholds<'a> {
    /// Per cell, eight lanes.
    sums: &'a mut [f32],
    maxima: &'a mut [f32],
    /// Per cell with [`PAD`] zeros on each side: the reduced sums and maxima
    /// (filled by `finish`) and the finite samples' counts.
    cell_sums: &'a mut [f32],
    cell_maxima: &'a mut [f32],
    counts: &'a mut [f32],
    thresholds: &'a mut [f32],
}

/// Eight lanes from a slice of at most eight (missing lanes 0).
#[inline(always)]
fn lanes(v: &[f32]) -> f32x8 {
    let mut a = [0f32; CELL];
    let n = v.len().min(CELL);
    a[..n].copy_from_slice(&v[..n]);
    f32x8::from(a)
}

/// Eight lanes from a slice of exactly eight.
#[inline(always)]
fn load(v: &[f32]) -> f32x8 {
    f32x8::from(<[f32; CELL]>::try_from(v).unwrap_or_default())
}

/// Eight pixels added to a cell's lane sums and maxima; returns them and the
/// mask of finite lanes (as bits; a count for a whole cell).
#[inline(always)]
fn add8(r: f32x8, g: f32x8, b: f32x8, sum: f32x8, max: f32x8) -> (f32x8, f32x8, u32) {
    let l = luma8(r, g, b);
    let finite = l.abs().simd_le(f32x8::splat(f32::MAX));
    let v = finite.select(l.fast_max(f32x8::ZERO).fast_min(f32x8::splat(LUMA_CAP)), f32x8::ZERO);
    (sum + v, max.fast_max(v), finite.to_bitmask())
}

/// Luminance of eight pixels (the scalar expression on each lane).
#[inline(always)]
fn luma8(r: f32x8, g: f32x8, b: f32x8) -> f32x8 {
    f32x8::splat(LUMA[0]) * r + f32x8::splat(LUMA[1]) * g + f32x8::splat(LUMA[2]) * b
}

impl<'a> Thresholds<'a> {
    /// Empty sums for a band of width `width` in `work` ([`work_len`] values).
    /// `None` if `work` is too short.
    pub fn new(work: &'a mut [f32], width: usize) -> Option<Self> {
        let n = cells(width);
        let (sums, rest) = work.get_mut(..work_len(width))?.split_at_mut(CELL * n);
        let (maxima, rest) = rest.split_at_mut(CELL * n);
        let (cell_sums, rest) = rest.split_at_mut(n + 2 * PAD);
        let (cell_maxima, rest) = rest.split_at_mut(n + 2 * PAD);
        let (counts, thresholds) = rest.split_at_mut(n + 2 * PAD);
        sums.fill(0.0);
        maxima.fill(0.0);
        cell_sums.fill(0.0);
        cell_maxima.fill(0.0);
        counts.fill(0.0);
        Some(Thresholds { sums, maxima, cell_sums, cell_maxima, counts, thresholds })
    }

    /// Adds one whole row of the band (planar channels, pixels `0..width`).
    pub fn add_row(&mut self, rgb: [&[f32]; 3]) {
        let [r, g, b] = rgb;
        let n = r.len().min(g.len()).min(b.len()).min(CELL * self.thresholds.len());
        let whole = n / CELL;
        let counts = &mut self.counts[PAD..];
        let cells = self.sums.chunks_exact_mut(CELL).zip(self.maxima.chunks_exact_mut(CELL)).zip(counts.iter_mut());
        let pixels =
            r[..whole * CELL].chunks_exact(CELL).zip(g[..whole * CELL].chunks_exact(CELL)).zip(b[..whole * CELL].chunks_exact(CELL));
        for (((r, g), b), ((s, m), c)) in pixels.zip(cells) {
            let (sum, top, finite) = add8(load(r), load(g), load(b), load(s), load(m));
            s.copy_from_slice(&sum.to_array());
            m.copy_from_slice(&top.to_array());
            *c += finite.count_ones() as f32;
        }
        if whole * CELL < n {
            // the partial cell at the right edge: its lanes past the row's end stay empty
            let (o, i) = (whole * CELL, whole);
            let (Some(s), Some(m), Some(c)) =
                (self.sums.get_mut(CELL * i..CELL * (i + 1)), self.maxima.get_mut(CELL * i..CELL * (i + 1)), self.counts.get_mut(PAD + i))
            else {
                return;
            };
            let (sum, top, count) = add8(lanes(&r[o..n]), lanes(&g[o..n]), lanes(&b[o..n]), load(s), load(m));
            s.copy_from_slice(&sum.to_array());
            m.copy_from_slice(&top.to_array());
            *c += (count & ((1u32 << (n - o)) - 1)).count_ones() as f32;
        }
    }

    /// Turns the sums into thresholds for the factor `k`. Eight cells at a
    /// time, each lane over its window in the same order as one cell alone:
    /// the padding's zeros add nothing (where every cell of a window sums to
    /// 0 a padding cell may be taken as the largest; the cell's threshold is
    /// then 0 and its samples, none above 0, clamp nothing).
    pub fn finish(self, k: f32) -> &'a [f32] {
        self.finish_capped(k, &[], &[], &mut [], &mut [])
    }

    /// [`Thresholds::finish`] with the third largest cell maximum of cell
    /// `i`'s neighbourhood lowered to `caps[i] · max(1, mean / prev_means[i])`
    /// where that is smaller, `mean` being the neighbourhood's mean term (not
    /// capped itself; cells past the end of `caps` are not capped). A
    /// temporal pipeline caps it with what the previous frame's clamped light
    /// held around the cell, raised by as much as the light around it
    /// brightened. Each cell's mean term goes to `means` and the largest
    /// luminance the clamp leaves in it to `kept` (as far as each reaches):
    /// the next frame's `prev_means` and, over the neighbourhood, `caps`.
    pub fn finish_capped(self, k: f32, caps: &[f32], prev_means: &[f32], means: &mut [f32], kept: &mut [f32]) -> &'a [f32] {
        let n = self.thresholds.len();
        for (i, (s, m)) in self.sums.chunks_exact(CELL).zip(self.maxima.chunks_exact(CELL)).enumerate() {
            self.cell_sums[PAD + i] = s.iter().sum();
            self.cell_maxima[PAD + i] = m.iter().fold(0f32, |a, &b| a.max(b));
        }
        let (sums, maxima, counts) = (&*self.cell_sums, &*self.cell_maxima, &*self.counts);
        let zero = f32x8::ZERO;
        for i in (0..n).step_by(CELL) {
            // lane l is cell i + l; its window is padded cells i + l + PAD − REACH + d
            // the sums of the cells other than the largest, kept apart so that
            // an outlier's sum does not swamp theirs in f32
            let (mut rest_sum, mut rest_count, mut top, mut top_count) = (zero, zero, f32x8::splat(-1.0), zero);
            let mut best = [zero; 3];
            for d in 0..=2 * REACH {
                let at = i + PAD - REACH + d;
                let (s, c, mut m) = (load(&sums[at..at + CELL]), load(&counts[at..at + CELL]), load(&maxima[at..at + CELL]));
                let above = s.simd_gt(top);
                // a new largest sum sends the old one (none at first: −1) to the rest
                rest_sum = above.select(rest_sum + top.fast_max(zero), rest_sum + s);
                rest_count = above.select(rest_count + top_count, rest_count + c);
                top = above.select(s, top);
                top_count = above.select(c, top_count);
                for b in best.iter_mut() {
                    let hi = b.fast_max(m);
                    m = b.fast_min(m);
                    *b = hi;
                }
            }
            // no finite sample outside the brightest cell: nothing to compare with
            let mean = rest_count.simd_gt(zero).select(rest_sum / rest_count, f32x8::splat(f32::INFINITY));
            let (mut cap, mut before) = ([f32::INFINITY; CELL], [f32::INFINITY; CELL]);
            for ((c, b), (&v, &m)) in cap.iter_mut().zip(before.iter_mut()).zip(caps.iter().zip(prev_means).skip(i)) {
                (*c, *b) = (v, m);
            }
            // the cap, raised by mean / before where the light around brightened;
            // none where it was black and is lit now. Selects, not NaN
            // propagation, decide every lane (`fast_min`/`fast_max` treat NaN
            // differently on each ISA).
            let (cap, before, inf) = (f32x8::from(cap), f32x8::from(before), f32x8::splat(f32::INFINITY));
            let brighter = mean.simd_gt(before);
            let limit = brighter.select(cap * (mean / before), cap);
            let limit = (brighter & before.simd_le(zero)).select(inf, limit);
            let limit = limit.simd_eq(limit).select(limit, inf);
            let t = f32x8::splat(k) * best[2].fast_min(limit).fast_max(mean);
            for (d, v) in means.iter_mut().skip(i).zip(mean.to_array()) {
                *d = v;
            }
            // a cell whose brightest sample is below its threshold clamps nothing:
            // +Inf lets `clamp_row` skip it without reading its samples
            let own = load(&maxima[PAD + i..PAD + i + CELL]);
            // a sample above the threshold is scaled to it
            for (d, v) in kept.iter_mut().skip(i).zip(own.fast_min(t).to_array()) {
                *d = v;
            }
            let none = own.simd_le(t) & own.simd_lt(f32x8::splat(LUMA_CAP));
            let t = none.select(f32x8::splat(f32::INFINITY), t).to_array();
            let end = (i + CELL).min(n);
            self.thresholds[i..end].copy_from_slice(&t[..end - i]);
        }
        self.thresholds
    }
}

/// The thresholds [`Thresholds::finish`] left in `work` for a band of width `width`.
pub fn finished(work: &[f32], width: usize) -> &[f32] {
    let n = cells(width);
    &work[2 * CELL * n + 3 * (n + 2 * PAD)..work_len(width)]
}

/// Clamps one row segment whose first pixel is at column `x0`, with its band's
/// `thresholds`. Returns the number of samples clamped.
pub fn clamp_row(rgb: [&mut [f32]; 3], x0: usize, thresholds: &[f32]) -> usize {
    let [r, g, b] = rgb;
    let mut clamped = 0;
    let mut one = |i: usize, r: &mut f32, g: &mut f32, b: &mut f32| {
        let l = LUMA[0] * *r + LUMA[1] * *g + LUMA[2] * *b;
        let t = thresholds.get((x0 + i) / CELL).copied().unwrap_or(f32::INFINITY);
        // false for NaN: non-finite samples are left to the method
        if l > t && l.abs() <= f32::MAX {
            let f = t / l;
            *r *= f;
            *g *= f;
            *b *= f;
            clamped += 1;
        }
    };
    // whole cells eight at a time: a cell is usually below its threshold
    let whole = if x0.is_multiple_of(CELL) { r.len().min(g.len()).min(b.len()) / CELL * CELL } else { 0 };
    let max = f32x8::splat(f32::MAX);
    for c in 0..whole / CELL {
        let o = CELL * c;
        let t = thresholds.get((x0 + o) / CELL).copied().unwrap_or(f32::INFINITY);
        if t == f32::INFINITY {
            continue;
        }
        let l = luma8(load(&r[o..o + CELL]), load(&g[o..o + CELL]), load(&b[o..o + CELL]));
        if (l.simd_gt(f32x8::splat(t)) & l.abs().simd_le(max)).any() {
            for i in o..o + CELL {
                one(i, &mut r[i], &mut g[i], &mut b[i]);
            }
        }
    }
    for (i, ((r, g), b)) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()).enumerate().skip(whole) {
        one(i, r, g, b);
    }
    clamped
}

/// The fraction of a sample the clamp kept: the clamped luminance over the
/// raw one (1 where the clamp left the sample alone or the raw luminance is
/// not positive and finite). The temporal pipelines weigh a sample entering
/// their history by it.
pub fn kept(raw: [f32; 3], clamped: [f32; 3]) -> f32 {
    let l = |p: [f32; 3]| LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2];
    let (lr, lc) = (l(raw), l(clamped));
    if lr > lc && lr.abs() <= f32::MAX && lc >= 0.0 {
        (lc / lr).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// f64 oracle: the rule as written in the module doc, pixel by pixel.
    fn oracle(rgb: &[[f32; 3]], w: usize, h: usize, k: f64) -> std::vec::Vec<[f64; 3]> {
        let luma = |p: [f32; 3]| LUMA[0] as f64 * p[0] as f64 + LUMA[1] as f64 * p[1] as f64 + LUMA[2] as f64 * p[2] as f64;
        let n = cells(w);
        let mut out = std::vec::Vec::new();
        for y in 0..h {
            let band = y / CELL;
            let rows = band * CELL..((band + 1) * CELL).min(h);
            // (sum, count, max) of cell i
            let cell = |i: usize| {
                let (mut s, mut c, mut m) = (0f64, 0f64, 0f64);
                for yy in rows.clone() {
                    for x in i * CELL..((i + 1) * CELL).min(w) {
                        let l = luma(rgb[yy * w + x]);
                        if l.is_finite() {
                            s += l.max(0.0);
                            c += 1.0;
                            m = m.max(l);
                        }
                    }
                }
                (s, c, m)
            };
            for x in 0..w {
                let i = x / CELL;
                let cs: std::vec::Vec<_> = (i.saturating_sub(REACH)..(i + REACH + 1).min(n)).map(cell).collect();
                let top = cs.iter().copied().fold((-1.0, 0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
                let (s, c) = cs.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
                let mean = if c - top.1 > 0.0 { (s - top.0) / (c - top.1) } else { f64::INFINITY };
                let mut maxima: std::vec::Vec<f64> = cs.iter().map(|c| c.2).collect();
                maxima.sort_by(|a, b| b.total_cmp(a));
                let third = maxima.get(2).copied().unwrap_or(0.0);
                let t = k * third.max(mean);
                let p = rgb[y * w + x];
                let l = luma(p);
                let f = if l.is_finite() && l > t { t / l } else { 1.0 };
                out.push([p[0] as f64 * f, p[1] as f64 * f, p[2] as f64 * f]);
            }
        }
        out
    }

    fn run(rgb: &[[f32; 3]], w: usize, h: usize, k: f32) -> (std::vec::Vec<[f32; 3]>, usize) {
        let mut planes = [std::vec![0f32; w * h], std::vec![0f32; w * h], std::vec![0f32; w * h]];
        for (i, p) in rgb.iter().enumerate() {
            for c in 0..3 {
                planes[c][i] = p[c];
            }
        }
        let mut work = std::vec![0f32; work_len(w)];
        let mut clamped = 0;
        for band in 0..h.div_ceil(CELL) {
            let rows = band * CELL..((band + 1) * CELL).min(h);
            let mut t = Thresholds::new(&mut work, w).unwrap();
            for y in rows.clone() {
                t.add_row([&planes[0][y * w..][..w], &planes[1][y * w..][..w], &planes[2][y * w..][..w]]);
            }
            let th = t.finish(k);
            for y in rows {
                let [a, b, c] = &mut planes;
                clamped += clamp_row([&mut a[y * w..][..w], &mut b[y * w..][..w], &mut c[y * w..][..w]], 0, th);
            }
        }
        ((0..w * h).map(|i| [planes[0][i], planes[1][i], planes[2][i]]).collect(), clamped)
    }

    /// A deterministic noisy frame with outliers and non-finite samples.
    fn frame(w: usize, h: usize, seed: u64) -> std::vec::Vec<[f32; 3]> {
        let mut s = seed | 1;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..w * h)
            .map(|_| {
                let u = next();
                let base = [next() * 2.0, next(), next() * 0.5];
                match (u * 1000.0) as u32 {
                    0..=4 => base.map(|v| v * 1e4),
                    5 => [f32::NAN, 1.0, 1.0],
                    6 => [f32::INFINITY, 0.0, 0.0],
                    7 => [65504.0, 65504.0, 65504.0],
                    8 => base.map(|v| -v),
                    _ => base,
                }
            })
            .collect()
    }

    #[test]
    fn matches_the_f64_oracle_on_awkward_sizes() {
        for (w, h) in [(1, 1), (7, 3), (255, 9), (256, 17), (257, 8), (80, 40)] {
            let rgb = frame(w, h, (w * 31 + h) as u64);
            let (got, clamped) = run(&rgb, w, h, 8.0);
            let want = oracle(&rgb, w, h, 8.0);
            let mut changed = 0;
            for (i, (g, o)) in got.iter().zip(&want).enumerate() {
                for c in 0..3 {
                    let (g, o) = (g[c] as f64, o[c]);
                    if g.is_nan() || o.is_nan() {
                        assert!(g.is_nan() && o.is_nan(), "{w}x{h} pixel {i}");
                        continue;
                    }
                    assert!(g == o || (g - o).abs() <= 1e-4 * o.abs().max(1.0), "{w}x{h} pixel {i} ch {c}: {g} vs {o}");
                }
                changed += (rgb[i].map(f32::to_bits) != g.map(f32::to_bits)) as usize;
            }
            assert_eq!(changed, clamped, "{w}x{h}");
        }
    }

    #[test]
    fn clamps_isolated_outliers_and_leaves_a_smooth_frame_alone() {
        let (w, h) = (64, 16);
        let mut rgb = std::vec![[1.0f32, 0.5, 0.25]; w * h];
        let (out, clamped) = run(&rgb, w, h, 4.0);
        assert_eq!((out, clamped), (rgb.clone(), 0));
        rgb[3 * w + 20] = [1e4, 5e3, 2.5e3];
        rgb[12 * w + 63] = [65504.0; 3];
        let (out, clamped) = run(&rgb, w, h, 4.0);
        assert_eq!(clamped, 2);
        let l = |p: [f32; 3]| LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2];
        let clean = l([1.0, 0.5, 0.25]);
        assert!((l(out[3 * w + 20]) - 4.0 * clean).abs() < 1e-4);
        assert!((out[3 * w + 20][0] / out[3 * w + 20][1] - 2.0).abs() < 1e-5, "colour kept");
        assert!((l(out[12 * w + 63]) - 4.0 * clean).abs() < 1e-4);
        // a dim region where many cells have a bright sample keeps them all
        let mut dim = std::vec![[0.01f32; 3]; w * h];
        for i in (0..w * h).step_by(37) {
            dim[i] = [5.0; 3];
        }
        let (out, clamped) = run(&dim, w, h, 1.5);
        assert_eq!((out, clamped), (dim, 0));
    }

    #[test]
    fn extreme_values_give_finite_thresholds() {
        let w = 24;
        let mut work = std::vec![0f32; work_len(w)];
        let mut t = Thresholds::new(&mut work, w).unwrap();
        let row = std::vec![f32::MAX; w];
        t.add_row([&row, &row, &row]);
        assert!(t.finish(1e6).iter().all(|v| !v.is_nan()));
    }
}
