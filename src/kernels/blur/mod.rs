//! Kernel 2: separable blur of the moment grid (paper §3.2: one Gaussian pass
//! with σ/B on the B-times downsampled moments; box = guided filter window).
//!
//! The grid is `cells_x × cells_y` cells of `k` f64 values, row-major.
//! Outside the grid is zero (moments simply do not include pixels that do not
//! exist). Both passes work on whole cell rows, so each output row (or band)
//! is independent: the caller may run bands in any order or in parallel.

#[cfg(target_arch = "x86_64")]
mod avx2;

use crate::isa::Isa;
use core::ops::Range;
use wide::f64x4;

/// Largest blur radius on the cell grid, in cells.
pub const MAX_RADIUS_CELLS: usize = 64;

/// A Gaussian window is truncated at this many σ (unless given a radius).
pub const GAUSSIAN_TRUNCATION: f32 = 3.0;

/// ⌈radius / block⌉ cells (a hair under a whole number of cells stays it);
/// `usize::MAX` for a radius that is not finite and non-negative.
pub fn radius_to_cells(radius: f32, block: usize) -> usize {
    let cells = libm::ceilf(radius / block as f32 - 1e-4);
    if cells.is_finite() && cells >= 0.0 {
        cells as usize
    } else {
        usize::MAX
    }
}

/// Gaussian taps `w[0..=r]` for offsets `0..=r` (symmetric), normalised so the
/// full 1-D kernel sums to 1.
#[derive(Clone, Copy, Debug)]
pub struct Taps {
    /// Radius r in cells.
    pub radius: usize,
    /// Weights for offsets `0..=radius`, zero beyond.
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
    blur_row_on(Isa::detect(), taps, k, src, dst)
}

/// [`blur_row`] on the given instruction set (its Gaussian interior in
/// [`avx2`] where [`Isa::intrinsics`]).
fn blur_row_on(isa: Isa, taps: &Taps, k: usize, src: &[f64], dst: &mut [f64]) {
    let cx = src.len() / k;
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
    // Gaussian. Interior cells (all 2r + 1 taps inside the row) form one flat
    // range: out[x] = w0·src[x] + Σ_o w_o (src[x − o·k] + src[x + o·k]),
    // accumulated in registers `LANES` values at a time and stored once.
    let r = taps.radius;
    let (i0, i1) = if cx > 2 * r { (r, cx - r) } else { (cx, cx) };
    let mut x = i0 * k;
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`); x = r·k and the
        // interior ends r cells before the row's end (slices bounds-checked).
        x = unsafe { avx2::row_interior(&taps.w, r, k, src, dst, x, i1 * k) };
    }
    let _ = isa;
    x = row_pairs::<f64x4>(&taps.w, r, k, x, i1 * k, |i| load::<2>(&src[i..]), |i, v| store(&v, &mut dst[i..]));
    // An odd interior cell left over: LANES values at a time, then value by value.
    let cell = |x: usize, o: isize| (x as isize + o * k as isize) as usize;
    while x + LANES <= i1 * k {
        let acc = tap_chunk::<f64x4>(&taps.w, r, ALL, 0, |o| load::<VECS>(&src[cell(x, o)..]));
        store(&acc, &mut dst[x..]);
        x += LANES;
    }
    for x in x..i1 * k {
        dst[x] = tap_value(&taps.w, r, ALL, 0, |o| src[cell(x, o)]);
    }
    // Border cells (taps beyond the row are zero), a whole cell at a time so
    // the k values vectorise; same operations in the same order per value.
    for i in (0..i0.min(cx)).chain(i1.max(i0)..cx) {
        let out = &mut dst[i * k..(i + 1) * k];
        for (d, s) in out.iter_mut().zip(&src[i * k..(i + 1) * k]) {
            *d = s * taps.w[0];
        }
        for o in 1..=r {
            if o <= i {
                axpy(out, taps.w[o], &src[(i - o) * k..(i - o + 1) * k]);
            }
            if i + o < cx {
                axpy(out, taps.w[o], &src[(i + o) * k..(i + o + 1) * k]);
            }
        }
    }
}

/// Values accumulated in registers at once by the Gaussian passes (4 f64x4,
/// fused multiply-adds where the target has them).
const LANES: usize = 16;
const VECS: usize = LANES / 4;
/// Column strip of the vertical pass: the band's source rows of one strip stay in L1.
const STRIP: usize = 256;

#[inline(always)]
fn load<const V: usize>(s: &[f64]) -> [f64x4; V] {
    let mut a = [f64x4::ZERO; V];
    bytemuck::cast_slice_mut::<f64x4, f64>(&mut a).copy_from_slice(&s[..4 * V]);
    a
}

#[inline(always)]
fn store<const V: usize>(a: &[f64x4; V], d: &mut [f64]) {
    d[..4 * V].copy_from_slice(bytemuck::cast_slice::<f64x4, f64>(a));
}

/// Vertical pass for output rows `row0..row0 + dst.len() / row_len` of a grid
/// with `cells_y` rows: `src` is the whole grid, `dst` the band.
pub fn blur_cols_band(taps: &Taps, row_len: usize, cells_y: usize, row0: usize, src: &[f64], dst: &mut [f64]) {
    blur_cols_band_on(Isa::detect(), taps, row_len, cells_y, row0, src, dst)
}

/// [`blur_cols_band`] on the given instruction set (its Gaussian chunks in
/// [`avx2`] where [`Isa::intrinsics`]).
fn blur_cols_band_on(isa: Isa, taps: &Taps, row_len: usize, cells_y: usize, row0: usize, src: &[f64], dst: &mut [f64]) {
    let _ = isa;
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
    // Gaussian, in the row pass's form: out = w0·row(j) + Σ_o w_o (row(j − o)
    // + row(j + o)), rows outside the grid left out. Strips of STRIP values;
    // output rows two at a time, which read the same input rows (2r + 2 loads
    // for two outputs instead of 2(2r + 1)), each output chunk accumulated in
    // registers and stored once. (One row at a time with a multiply-add per
    // tap measured slower: bound by its loads and multiply-adds.)
    let r = taps.radius;
    let mut s0 = 0;
    while s0 < row_len {
        let s1 = (s0 + STRIP).min(row_len);
        let mut b = 0;
        while b < rows {
            let two = b + 1 < rows;
            let j = (row0 + b) as isize;
            let (out, next) = dst[b * row_len..].split_at_mut(row_len);
            let next = if two { &mut next[..row_len] } else { &mut next[..0] };
            let mut c = s0;
            #[cfg(target_arch = "x86_64")]
            if isa.intrinsics() {
                // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`); slices are bounds-checked.
                c = unsafe { avx2::cols_strip(&taps.w, r, src, row_len, cells_y, j, out, next, c, s1) };
            }
            while c + LANES <= s1 {
                let acc = tap_chunk::<f64x4>(&taps.w, r, 0..cells_y as isize, j, |jj| load::<VECS>(&row(jj)[c..]));
                store(&acc, &mut out[c..]);
                if two {
                    let acc = tap_chunk::<f64x4>(&taps.w, r, 0..cells_y as isize, j + 1, |jj| load::<VECS>(&row(jj)[c..]));
                    store(&acc, &mut next[c..]);
                }
                c += LANES;
            }
            for cc in c..s1 {
                out[cc] = tap_value(&taps.w, r, 0..cells_y as isize, j, |jj| row(jj)[cc]);
                if two {
                    next[cc] = tap_value(&taps.w, r, 0..cells_y as isize, j + 1, |jj| row(jj)[cc]);
                }
            }
            b += if two { 2 } else { 1 };
        }
        s0 = s1;
    }
}

/// Interior cells of the horizontal pass two at a time, from `x` (a cell's
/// first value) while both end by `end`, 8 values of each per step (the last
/// step of a cell overlaps the one before when `k` is not a multiple of 8;
/// it writes the same values again). Cells `i` and `i + 1` read the same
/// input cells but two, so each input chunk is loaded once for both: 2r + 2
/// loads per two outputs instead of 2(2r + 1). `load(i)` reads `src[i..i + 8]`,
/// `store(i, v)` writes `dst[i..i + 8]`. Returns the first value not done.
#[inline(always)]
pub(super) fn row_pairs<T: ColLanes>(
    w: &[f64],
    r: usize,
    k: usize,
    mut x: usize,
    end: usize,
    load: impl Fn(usize) -> [T; 2],
    mut store: impl FnMut(usize, [T; 2]),
) -> usize {
    if k < 8 {
        return x;
    }
    while x + 2 * k <= end {
        let mut c = 0;
        while c < k {
            let at = x + c.min(k - 8);
            // out(i) = w0·L(0) + Σ_o w_o (L(−o) + L(o)) for cell i, and the
            // same about cell i + 1; L(o) is input cell i + o's chunk.
            let (l0, l1) = (load(at), load(at + k));
            let (mut a, mut b) = (l0.map(|v| v.scale(w[0])), l1.map(|v| v.scale(w[0])));
            // L(o) for cell i's next right tap, L(1 − o) for cell i + 1's next left tap
            let (mut right, mut left) = (l1, l0);
            for o in 1..=r {
                let (l, n) = (load(at - o * k), load(at + (o + 1) * k));
                for v in 0..2 {
                    a[v] = l[v].pair_add(right[v], w[o], a[v]);
                    b[v] = left[v].pair_add(n[v], w[o], b[v]);
                }
                (left, right) = (l, n);
            }
            store(at, a);
            store(at + k, b);
            c += 8;
        }
        x += 2 * k;
    }
    x
}

/// Lanes the Gaussian loops shared by both instruction sets ([`row_pairs`],
/// [`tap_chunk`]) accumulate in: `f64x4` here, AVX registers in [`avx2`].
pub(super) trait ColLanes: Copy {
    fn scale(self, w: f64) -> Self;
    /// `(self + other)·w + acc`, fused where the target has it.
    fn pair_add(self, other: Self, w: f64, acc: Self) -> Self;
    /// `self·w + acc`, fused where the target has it.
    fn one_add(self, w: f64, acc: Self) -> Self;
}

impl ColLanes for f64x4 {
    #[inline(always)]
    fn scale(self, w: f64) -> Self {
        self * f64x4::splat(w)
    }
    #[inline(always)]
    fn pair_add(self, other: Self, w: f64, acc: Self) -> Self {
        (self + other).mul_add(f64x4::splat(w), acc)
    }
    #[inline(always)]
    fn one_add(self, w: f64, acc: Self) -> Self {
        self.mul_add(f64x4::splat(w), acc)
    }
}

/// Positions every tap of a row's interior may read (no border).
const ALL: Range<isize> = isize::MIN..isize::MAX;

/// One output chunk of a Gaussian pass about position `j`: `w0·x_j + Σ_o w_o
/// (x_{j−o} + x_{j+o})`, positions outside `valid` left out, `at(p)` loading
/// position `p`'s chunk (a row of the grid for the vertical pass; for the
/// horizontal pass's interior, `valid` is [`ALL`] and `p` an offset in cells).
/// The same operations in the same order in every lane type.
#[inline(always)]
pub(super) fn tap_chunk<T: ColLanes>(w: &[f64], r: usize, valid: Range<isize>, j: isize, at: impl Fn(isize) -> [T; VECS]) -> [T; VECS] {
    let mut acc = at(j).map(|v| v.scale(w[0]));
    for o in 1..=r {
        let (up, down) = (j - o as isize, j + o as isize);
        match (valid.contains(&up), valid.contains(&down)) {
            (true, true) => {
                let (a, b) = (at(up), at(down));
                for l in 0..VECS {
                    acc[l] = a[l].pair_add(b[l], w[o], acc[l]);
                }
            }
            (true, false) | (false, true) => {
                let a = at(if valid.contains(&up) { up } else { down });
                for l in 0..VECS {
                    acc[l] = a[l].one_add(w[o], acc[l]);
                }
            }
            (false, false) => {}
        }
    }
    acc
}

/// [`tap_chunk`] of one value (a strip's or an interior's tail), unfused.
#[inline(always)]
fn tap_value(w: &[f64], r: usize, valid: Range<isize>, j: isize, at: impl Fn(isize) -> f64) -> f64 {
    let mut acc = at(j) * w[0];
    for o in 1..=r {
        let (up, down) = (j - o as isize, j + o as isize);
        let pair = match (valid.contains(&up), valid.contains(&down)) {
            (true, true) => at(up) + at(down),
            (true, false) => at(up),
            (false, true) => at(down),
            (false, false) => continue,
        };
        acc += pair * w[o];
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both Gaussian passes equal the direct weighted sums `Σ_o w_|o| x[i + o]`
    /// over the cells that exist, to rounding: borders, grids narrower or
    /// shorter than the window, strip tails and odd row counts (the vertical
    /// pass does rows in pairs) on the instruction set this CPU picks.
    #[test]
    fn gaussian_passes_equal_direct_sums() {
        let mut seed = 97u32;
        let src: [f64; 4096] = core::array::from_fn(|_| 3.0 * crate::hash::uniform(&mut seed) - 1.0);
        let close = |got: f64, want: f64, what: (&str, usize, usize, isize, usize)| {
            assert!((got - want).abs() <= 1e-13 * (1.0 + want.abs()), "{what:?}: {got} vs {want}")
        };
        for radius in [1usize, 2, 3, 5] {
            let taps = Taps::gaussian(radius as f64 / 2.0, radius);
            let w = |o: isize| taps.w[o.unsigned_abs()];
            for (k, cx) in [(1usize, 1usize), (3, 2), (40, 9), (41, 20)] {
                let n = k * cx;
                let mut out = [0f64; 4096];
                blur_row(&taps, k, &src[..n], &mut out[..n]);
                for i in 0..cx as isize {
                    for m in 0..k {
                        let want: f64 = (-(radius as isize)..=radius as isize)
                            .filter(|o| (0..cx as isize).contains(&(i + o)))
                            .map(|o| w(o) * src[(i + o) as usize * k + m])
                            .sum();
                        close(out[i as usize * k + m], want, ("row: radius, k, cell, moment", radius, k, i, m));
                    }
                }
            }
            for (row_len, cells_y, row0, rows) in
                [(1usize, 1usize, 0usize, 1usize), (17, 3, 1, 2), (40, 9, 2, 5), (300, 12, 0, 12), (517, 7, 3, 3)]
            {
                let mut out = [0f64; 4096];
                blur_cols_band(&taps, row_len, cells_y, row0, &src[..row_len * cells_y], &mut out[..rows * row_len]);
                for b in 0..rows {
                    let j = (row0 + b) as isize;
                    for c in 0..row_len {
                        let want: f64 = (-(radius as isize)..=radius as isize)
                            .filter(|o| (0..cells_y as isize).contains(&(j + o)))
                            .map(|o| w(o) * src[(j + o) as usize * row_len + c])
                            .sum();
                        close(out[b * row_len + c], want, ("cols: radius, row_len, row, value", radius, row_len, j, c));
                    }
                }
            }
        }
    }

    /// The AVX2 + FMA Gaussian interiors (where this CPU has them) agree with
    /// the portable lanes to the rounding of fused against separate products,
    /// for rows and bands of awkward lengths (interior tails, borders, radii 1
    /// to 6). (Where `wide` is AVX2 + FMA, [`Isa::intrinsics`] keeps its lanes
    /// for both calls, which must then agree bit for bit.)
    #[test]
    fn avx2_blurs_match_portable() {
        if !Isa::Avx2Fma.available() {
            return;
        }
        let mut seed = 31u32;
        let src: [f64; 4096] = core::array::from_fn(|_| 1.0 + 2.0 * crate::hash::uniform(&mut seed));
        let fused = cfg!(all(target_feature = "avx2", target_feature = "fma"));
        let same = |p: &[f64], a: &[f64], what: (&str, usize, usize, usize)| {
            for (i, (p, a)) in p.iter().zip(a).enumerate() {
                if fused {
                    assert_eq!(p.to_bits(), a.to_bits(), "{what:?} value {i}: {p} vs {a}");
                } else {
                    assert!((p - a).abs() <= 1e-13 * (1.0 + p.abs()), "{what:?} value {i}: {p} vs {a}");
                }
            }
        };
        for radius in [1usize, 2, 4, 6] {
            let taps = Taps::gaussian(radius as f64 / 2.0, radius);
            for (k, cx) in [(1usize, 7usize), (5, 13), (40, 9), (41, 20), (131, 3)] {
                let n = k * cx;
                let (mut p, mut a) = ([0f64; 4096], [0f64; 4096]);
                blur_row_on(Isa::Portable, &taps, k, &src[..n], &mut p[..n]);
                blur_row_on(Isa::Avx2Fma, &taps, k, &src[..n], &mut a[..n]);
                same(&p[..n], &a[..n], ("row: radius, k, cells", radius, k, cx));
            }
            for (row_len, cells_y, row0, rows) in [(16usize, 5usize, 0usize, 5usize), (40, 9, 2, 4), (300, 12, 3, 6), (517, 7, 0, 7)] {
                let (mut p, mut a) = ([0f64; 4096], [0f64; 4096]);
                let n = rows * row_len;
                blur_cols_band_on(Isa::Portable, &taps, row_len, cells_y, row0, &src[..row_len * cells_y], &mut p[..n]);
                blur_cols_band_on(Isa::Avx2Fma, &taps, row_len, cells_y, row0, &src[..row_len * cells_y], &mut a[..n]);
                same(&p[..n], &a[..n], ("cols: radius, row_len, rows", radius, row_len, cells_y));
            }
        }
    }
}
