//! Kernel 2: separable blur of the moment grid (paper §3.2: one Gaussian pass
//! with σ/B on the B-times downsampled moments; box = guided filter window).
//!
//! The grid is `cells_x × cells_y` cells of `k` f64 values, row-major.
//! Outside the grid is zero (moments simply do not include pixels that do not
//! exist). Both passes work on whole cell rows, so each output row (or band)
//! is independent: the caller may run bands in any order or in parallel.

use crate::config::MAX_RADIUS_CELLS;

/// Gaussian taps `w[0..=r]` for offsets `0..=r` (symmetric), normalised so the
/// full 1-D kernel sums to 1.
#[derive(Clone, Copy, Debug)]
pub struct Taps {
    pub radius: usize,
    pub w: [f64; MAX_RADIUS_CELLS + 1],
    /// Box filter (all weights 1, sliding window) instead of explicit taps.
    pub is_box: bool,
}

impl Taps {
    /// Gaussian of std-dev `sigma` cells truncated at `radius` cells.
    pub fn gaussian(sigma: f64, radius: usize) -> Self {
        let radius = radius.min(MAX_RADIUS_CELLS);
        let mut w = [0f64; MAX_RADIUS_CELLS + 1];
        let mut sum = 0.0;
        for (i, wi) in w.iter_mut().enumerate().take(radius + 1) {
            let x = i as f64;
            *wi = libm::exp(-x * x / (2.0 * sigma * sigma));
            sum += if i == 0 { *wi } else { 2.0 * *wi };
        }
        for wi in w.iter_mut().take(radius + 1) {
            *wi /= sum;
        }
        Taps { radius, w, is_box: false }
    }
    /// Box of half-width `radius` cells; weights 1 (not normalised).
    pub fn boxed(radius: usize) -> Self {
        let radius = radius.min(MAX_RADIUS_CELLS);
        let mut w = [0f64; MAX_RADIUS_CELLS + 1];
        w[..=radius].fill(1.0);
        Taps { radius, w, is_box: true }
    }
    /// Sum of the 1-D kernel.
    pub fn sum(&self) -> f64 {
        self.w[0] + 2.0 * self.w[1..=self.radius].iter().sum::<f64>()
    }
}

#[inline]
fn axpy(dst: &mut [f64], a: f64, src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d += a * s;
    }
}

/// Horizontal pass over one cell row: `src` and `dst` are rows of `cells_x * k`.
pub fn blur_row(taps: &Taps, k: usize, src: &[f64], dst: &mut [f64]) {
    let cx = src.len() / k;
    dst.fill(0.0);
    if taps.is_box {
        // O(1) per cell: running window sum.
        let r = taps.radius;
        let mut acc = [0f64; super::moment_count(crate::MAX_GUIDES)];
        let acc = &mut acc[..k];
        for i in 0..r.min(cx) {
            axpy(acc, 1.0, &src[i * k..(i + 1) * k]);
        }
        for i in 0..cx {
            if i + r < cx {
                axpy(acc, 1.0, &src[(i + r) * k..(i + r + 1) * k]);
            }
            if i > r {
                axpy(acc, -1.0, &src[(i - r - 1) * k..(i - r) * k]);
            }
            dst[i * k..(i + 1) * k].copy_from_slice(acc);
        }
        return;
    }
    for off in -(taps.radius as isize)..=(taps.radius as isize) {
        let wk = taps.w[off.unsigned_abs()];
        // Output cells i with 0 <= i + off < cx.
        let lo = (-off).max(0) as usize;
        let hi = ((cx as isize) - off).min(cx as isize);
        if hi <= lo as isize {
            continue;
        }
        let hi = hi as usize;
        let s0 = (lo as isize + off) as usize;
        axpy(&mut dst[lo * k..hi * k], wk, &src[s0 * k..(s0 + hi - lo) * k]);
    }
}

/// Vertical pass for output rows `row0..row0 + dst.len() / row_len` of a grid
/// with `cells_y` rows: `src` is the whole grid, `dst` the band.
pub fn blur_cols_band(taps: &Taps, row_len: usize, cells_y: usize, row0: usize, src: &[f64], dst: &mut [f64]) {
    let rows = dst.len() / row_len;
    let r = taps.radius as isize;
    let row = |j: isize| &src[j as usize * row_len..(j as usize + 1) * row_len];
    if taps.is_box {
        // Sliding window down the band, initialised at the band start.
        let (first, rest) = dst.split_at_mut(row_len.min(dst.len()));
        first.fill(0.0);
        let j0 = row0 as isize;
        for j in (j0 - r).max(0)..=(j0 + r).min(cells_y as isize - 1) {
            axpy(first, 1.0, row(j));
        }
        let mut prev: &[f64] = first;
        for (b, out) in rest.chunks_exact_mut(row_len).enumerate() {
            let j = j0 + 1 + b as isize;
            out.copy_from_slice(prev);
            if j + r < cells_y as isize {
                axpy(out, 1.0, row(j + r));
            }
            if j - r > 0 {
                axpy(out, -1.0, row(j - r - 1));
            }
            prev = out;
        }
        return;
    }
    for (b, out) in dst.chunks_exact_mut(row_len).take(rows).enumerate() {
        let j = (row0 + b) as isize;
        out.fill(0.0);
        for off in -r..=r {
            let jj = j + off;
            if jj < 0 || jj >= cells_y as isize {
                continue;
            }
            axpy(out, taps.w[off.unsigned_abs()], row(jj));
        }
    }
}
