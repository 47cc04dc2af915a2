//! Kernel 4: bilinear interpolation of the per-cell affine models between
//! cell centres and application to the full-resolution guides (paper §3.2).
//!
//! Cell `i` covers pixels `i·B .. i·B + B`; its centre is at `i·B + B/2 − ½`.
//! Rows are done in two steps: [`lerp_rows`] interpolates the model grid
//! vertically to the output row, [`apply_row`] interpolates horizontally and
//! evaluates `ŷ = c0 + Σ c_q d_q` (eq. 23 in raw coordinates). With B a
//! multiple of 8 each span between two centres is whole `f32x8` groups with
//! fixed lane weights.

#[cfg(target_arch = "x86_64")]
mod avx2;

use super::demodulation;
use crate::guides::MAX_GUIDES;
use crate::isa::Isa;
use wide::f32x8;

/// Interpolation position of pixel `x` (or row `y`): left cell and weight.
#[inline]
pub fn cell_pos(x: usize, block: usize, cells: usize) -> (usize, f32) {
    let c = (x as f32 + 0.5) / block as f32 - 0.5;
    if c <= 0.0 {
        return (0, 0.0);
    }
    let i = c as usize;
    if i + 1 >= cells {
        return (cells - 1, 0.0);
    }
    (i, c - i as f32)
}

/// Vertically interpolated model row for output row `y` into `out` (`cells_x * ml`),
/// and the horizontal differences `slopes[i] = out[i + 1] − out[i]` per cell
/// (`(cells_x − 1) * ml`), so the SIMD path splats both straight from memory.
#[allow(clippy::too_many_arguments)]
pub fn lerp_rows(models: &[f32], cells_x: usize, cells_y: usize, ml: usize, block: usize, y: usize, out: &mut [f32], slopes: &mut [f32]) {
    let (j, fy) = cell_pos(y, block, cells_y);
    let row = cells_x * ml;
    let a = &models[j * row..(j + 1) * row];
    if fy == 0.0 {
        out.copy_from_slice(a);
    } else {
        let b = &models[(j + 1) * row..(j + 2) * row];
        for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
            *o = a + (b - a) * fy;
        }
    }
    let n = (cells_x - 1) * ml;
    for ((s, a), b) in slopes[..n].iter_mut().zip(&out[..n]).zip(&out[ml..]) {
        *s = b - a;
    }
}

/// Guide rows of one output row: `Q` slices of `width` raw guide values (from
/// the caller's image when it is planar f32, else gathered), and the frame
/// reference `m` each is measured from (`d = g − m`).
#[derive(Clone, Copy, Debug)]
pub struct RowGuides<'a> {
    /// Per guide channel `q < Q`: its row's `width` raw values.
    pub rows: [&'a [f32]; MAX_GUIDES],
    /// Per guide channel: the frame reference `m`.
    pub reference: [f32; MAX_GUIDES],
    /// Pixels in the row.
    pub width: usize,
}

/// Where [`apply_row`] puts its row: `3 · width` values either way.
#[derive(Debug)]
pub enum RowOut<'a> {
    /// Three planes of `width` values: r, then g, then b.
    Planes(&'a mut [f32]),
    /// One interleaved RGB row, written as each group of pixels is done (no
    /// second pass over the row to interleave it).
    Rgb(&'a mut [f32]),
    /// As `Rgb`, with non-temporal stores for the 16-byte aligned groups
    /// (x86-64; elsewhere as `Rgb`) and a store fence at the end of the row:
    /// for outputs far larger than the caches ([`crate::image::STREAM_MIN_BYTES`]).
    /// Interleaved with the arithmetic, the stores drain while the next
    /// groups are computed; a separate pass over the row waited on them.
    RgbStreaming(&'a mut [f32]),
}

/// Evaluates one output row into `out`. A pixel with a non-finite guide gets
/// the local mean; returns how many did. `row_slopes` are the differences of
/// consecutive cells' models ([`lerp_rows`]). `demod`: the AO demodulation's
/// guide index and offset ([`crate::FlrConfig::ao_demodulation`]); the model's
/// value is multiplied by `s(ao)` ([`demodulation::scale8`]) before it is stored.
#[allow(clippy::too_many_arguments)]
pub fn apply_row<const Q: usize>(
    row_models: &[f32],
    row_slopes: &[f32],
    cells_x: usize,
    block: usize,
    guides: RowGuides<'_>,
    clamp: bool,
    demod: Option<(usize, f32)>,
    simd: bool,
    out: RowOut<'_>,
) -> usize {
    let w = guides.width;
    let ml = super::model_len(Q);
    let demod = demod.filter(|&(a, _)| a < Q);
    let out_len = match &out {
        RowOut::Planes(o) | RowOut::Rgb(o) | RowOut::RgbStreaming(o) => o.len(),
    };
    if guides.rows[..Q].iter().any(|r| r.len() < w)
        || out_len < 3 * w
        || row_models.len() < cells_x * ml
        || row_slopes.len() < (cells_x - 1) * ml
    {
        return 0; // unreachable from the FLR driver, which sizes every buffer
    }
    let row = Row { models: row_models, slopes: row_slopes, cells_x, block, guides, demod };
    match out {
        RowOut::Planes(o) => {
            let (o0, rest) = o.split_at_mut(w);
            let (o1, o2) = rest.split_at_mut(w);
            row.apply::<Q, _>(clamp, simd, &mut Planes([o0, o1, &mut o2[..w]]))
        }
        RowOut::Rgb(o) => row.apply::<Q, _>(clamp, simd, &mut Rgb::<false>(&mut o[..3 * w])),
        RowOut::RgbStreaming(o) => {
            let n = row.apply::<Q, _>(clamp, simd, &mut Rgb::<true>(&mut o[..3 * w]));
            #[cfg(target_arch = "x86_64")]
            // SAFETY: a store fence has no operands and no preconditions; it
            // orders the row's non-temporal stores before any later store.
            unsafe {
                core::arch::x86_64::_mm_sfence()
            };
            n
        }
    }
}

/// One output row's inputs ([`apply_row`]).
struct Row<'a> {
    models: &'a [f32],
    slopes: &'a [f32],
    cells_x: usize,
    block: usize,
    guides: RowGuides<'a>,
    demod: Option<(usize, f32)>,
}

impl Row<'_> {
    fn apply<const Q: usize, S: Sink>(&self, clamp: bool, simd: bool, out: &mut S) -> usize {
        let (w, block, cells_x) = (self.guides.width, self.block, self.cells_x);
        let ml = super::model_len(Q);
        let mut fallback = 0;
        let mut x = 0;
        if simd && block.is_multiple_of(8) && cells_x > 1 {
            // Left edge: pixels before the first centre use cell 0 alone (scalar below).
            let half = block / 2;
            while x < half.min(w) {
                fallback += self.scalar_px::<Q, S>(ml, clamp, x, out);
                x += 1;
            }
            let span = Span { ml, block, half, cells_x };
            let (f, end) = if clamp {
                simd_spans_on::<Q, true, S>(Isa::detect(), self.models, self.slopes, &span, &self.guides, self.demod, out)
            } else {
                simd_spans_on::<Q, false, S>(Isa::detect(), self.models, self.slopes, &span, &self.guides, self.demod, out)
            };
            fallback += f;
            x = end;
        }
        while x < w {
            fallback += self.scalar_px::<Q, S>(ml, clamp, x, out);
            x += 1;
        }
        fallback
    }

    #[inline(always)]
    fn scalar_px<const Q: usize, S: Sink>(&self, ml: usize, clamp: bool, x: usize, out: &mut S) -> usize {
        let (i, fx) = cell_pos(x, self.block, self.cells_x);
        let a = &self.models[i * ml..(i + 1) * ml];
        let b = if fx == 0.0 { a } else { &self.models[(i + 1) * ml..(i + 2) * ml] };
        let lerp = |j: usize| a[j] + (b[j] - a[j]) * fx;
        let g = &self.guides;
        let mut d = [0f32; MAX_GUIDES];
        let mut valid = true;
        for q in 0..Q {
            let v = g.rows[q][x];
            valid &= v.is_finite();
            d[q] = v - g.reference[q];
        }
        let s = self.demod.map(|(a, c)| demodulation::scale(g.rows[a][x], c));
        let mut rgb = [0f32; 3];
        for (c, o) in rgb.iter_mut().enumerate() {
            let mut y = lerp(c);
            for q in 0..Q {
                y += lerp(3 + 3 * q + c) * d[q];
            }
            let muy = lerp(3 + 3 * Q + c);
            let y = if valid && y.is_finite() { y } else { muy };
            let y = if clamp { y.max(0.0) } else { y };
            *o = s.map_or(y, |s| demodulation::remodulate1(y, s));
        }
        out.put1(x, rgb);
        !valid as usize
    }
}

/// Stores of one output row's pixels ([`RowOut`]).
trait Sink {
    /// Pixels `x0..x0 + 8` (`x0 + 8 ≤ width`), one vector per colour.
    fn put8(&mut self, x0: usize, rgb: [f32x8; 3]);
    /// Pixel `x` (`x < width`).
    fn put1(&mut self, x: usize, rgb: [f32; 3]);
}

/// Three planes.
struct Planes<'a>([&'a mut [f32]; 3]);

impl Sink for Planes<'_> {
    #[inline(always)]
    fn put8(&mut self, x0: usize, rgb: [f32x8; 3]) {
        for (o, v) in self.0.iter_mut().zip(rgb) {
            o[x0..x0 + 8].copy_from_slice(&v.to_array());
        }
    }
    #[inline(always)]
    fn put1(&mut self, x: usize, rgb: [f32; 3]) {
        for (o, v) in self.0.iter_mut().zip(rgb) {
            o[x] = v;
        }
    }
}

/// One interleaved RGB row; `STREAM`: non-temporal stores where aligned.
struct Rgb<'a, const STREAM: bool>(&'a mut [f32]);

impl<const STREAM: bool> Sink for Rgb<'_, STREAM> {
    #[inline(always)]
    fn put8(&mut self, x0: usize, rgb: [f32x8; 3]) {
        // (`x0 + 8 ≤ width` and the row holds `3 · width` values: always there)
        let Some(d) = self.0.get_mut(3 * x0..3 * x0 + 24).and_then(|d| <&mut [f32; 24]>::try_from(d).ok()) else {
            return;
        };
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{__m128, _mm_storeu_ps, _mm_stream_ps};
            let [r, g, b] = rgb.map(bytemuck::cast::<f32x8, [__m128; 2]>);
            let stream = STREAM && (d.as_ptr() as usize).is_multiple_of(16);
            for h in 0..2 {
                let o = crate::image::interleave4(r[h], g[h], b[h]);
                for (k, v) in o.into_iter().enumerate() {
                    let p = d[12 * h + 4 * k..12 * h + 4 * k + 4].as_mut_ptr();
                    // SAFETY: SSE is part of x86-64; `p` points at 4 values inside
                    // `d`; a non-temporal store only where `d` (so `p`, 16 bytes
                    // further each time) is 16-byte aligned.
                    unsafe {
                        if stream {
                            _mm_stream_ps(p, v)
                        } else {
                            _mm_storeu_ps(p, v)
                        }
                    }
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let [r, g, b] = rgb.map(|v| v.to_array());
            for (i, px) in d.chunks_exact_mut(3).enumerate() {
                px.copy_from_slice(&[r[i], g[i], b[i]]);
            }
        }
    }
    #[inline(always)]
    fn put1(&mut self, x: usize, rgb: [f32; 3]) {
        self.0[3 * x..3 * x + 3].copy_from_slice(&rgb);
    }
}

/// Geometry of the spans between cell centres of one row.
struct Span {
    ml: usize,
    block: usize,
    half: usize,
    cells_x: usize,
}

/// [`simd_spans`] on the given instruction set: in AVX2 + FMA intrinsics when
/// `isa` says so, the build's `wide` lacks them and the CPU has them (a
/// default x86-64 build's SSE2 lanes took ~1.5× as long), else the portable
/// lanes.
#[inline(always)]
fn simd_spans_on<const Q: usize, const CLAMP: bool, S: Sink>(
    isa: Isa,
    row_models: &[f32],
    row_slopes: &[f32],
    sp: &Span,
    guides: &RowGuides<'_>,
    demod: Option<(usize, f32)>,
    out: &mut S,
) -> (usize, usize) {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::simd_spans::<Q, CLAMP, S>(row_models, row_slopes, sp, guides, demod, out) };
    }
    let _ = isa;
    simd_spans::<Q, CLAMP, S>(row_models, row_slopes, sp, guides, demod, out)
}

/// Every whole 8-pixel group between the first and last cell centres; returns
/// the fallback count and the first pixel not done.
#[inline(always)]
fn simd_spans<const Q: usize, const CLAMP: bool, S: Sink>(
    row_models: &[f32],
    row_slopes: &[f32],
    sp: &Span,
    guides: &RowGuides<'_>,
    demod: Option<(usize, f32)>,
    out: &mut S,
) -> (usize, usize) {
    let demod = demod.map(|(a, c)| (a, f32x8::splat(c)));
    let (ml, w) = (sp.ml, guides.width);
    let inv_b = f32x8::splat(1.0 / sp.block as f32);
    let fx0 = f32x8::from([0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5]) * inv_b;
    let mut reference = [f32x8::ZERO; MAX_GUIDES];
    for q in 0..Q {
        reference[q] = f32x8::splat(guides.reference[q]);
    }
    let (mut fallback, mut x) = (0, sp.half.min(w));
    if sp.block == 8 {
        // One group per span. Kept apart from the general loop: there the
        // compiler hoists the span's 2·ml splats out of the group loop and,
        // with too few registers, spills them: ~2× the instructions per group.
        for i in 0..sp.cells_x - 1 {
            let x0 = i * 8 + sp.half;
            if x0 + 8 > w {
                break;
            }
            let (base, slope) = (&row_models[i * ml..(i + 1) * ml], &row_slopes[i * ml..(i + 1) * ml]);
            fallback += simd_group::<Q, CLAMP, S>(base, slope, fx0, &reference, guides, demod, x0, out);
            x = x0 + 8;
        }
        return (fallback, x);
    }
    for i in 0..sp.cells_x - 1 {
        let start = i * sp.block + sp.half;
        // The span's model is `a + fx·(b − a)`: both splatted from memory per group.
        let base = &row_models[i * ml..(i + 1) * ml];
        let slope = &row_slopes[i * ml..(i + 1) * ml];
        for g in 0..sp.block / 8 {
            let x0 = start + 8 * g;
            if x0 + 8 > w {
                return (fallback, x);
            }
            let fx = if g == 0 { fx0 } else { fx0 + f32x8::splat((8 * g) as f32) * inv_b };
            fallback += simd_group::<Q, CLAMP, S>(base, slope, fx, &reference, guides, demod, x0, out);
            x = x0 + 8;
        }
    }
    (fallback, x)
}

/// One group of 8 pixels, channels one after the other (interleaving their
/// chains measured slower: it spills). A non-finite guide makes every
/// channel's `y` non-finite (`c·d` is NaN or ±Inf for any `c`, 0·Inf
/// included), so one finiteness test of `y` covers the guides too; the guides
/// are looked at again only to count fallbacks when some lane failed.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn simd_group<const Q: usize, const CLAMP: bool, S: Sink>(
    base: &[f32],
    slope: &[f32],
    fx: f32x8,
    reference: &[f32x8; MAX_GUIDES],
    g: &RowGuides<'_>,
    demod: Option<(usize, f32x8)>,
    x0: usize,
    out: &mut S,
) -> usize {
    let load = |s: &[f32]| -> f32x8 {
        debug_assert!(x0 + 8 <= s.len());
        // SAFETY: `apply_row` only calls this for groups with `x0 + 8 <= width` and
        // checked that every guide row holds at least `width` values.
        unsafe { core::ptr::read_unaligned(s.as_ptr().add(x0) as *const f32x8) }
    };
    let lerp = |j: usize| f32x8::splat(slope[j]).mul_add(fx, f32x8::splat(base[j]));
    let max = f32x8::splat(f32::MAX);
    let mut d = [f32x8::ZERO; MAX_GUIDES];
    for q in 0..Q {
        d[q] = load(g.rows[q]) - reference[q];
    }
    let mut all_ok = true;
    let mut rgb = [f32x8::ZERO; 3];
    for (c, o) in rgb.iter_mut().enumerate() {
        let mut y = lerp(c);
        for q in 0..Q {
            y = lerp(3 + 3 * q + c).mul_add(d[q], y);
        }
        let finite = y.abs().simd_le(max);
        let mut r = if finite.all() {
            y
        } else {
            all_ok = false;
            finite.select(y, lerp(3 + 3 * Q + c))
        };
        if CLAMP {
            r = r.fast_max(f32x8::ZERO);
        }
        *o = r;
    }
    if let Some((a, c)) = demod {
        let s = demodulation::scale8(load(g.rows[a]), c);
        rgb = rgb.map(|v| demodulation::remodulate8(v, s));
    }
    out.put8(x0, rgb);
    if all_ok {
        return 0;
    }
    let mut ok = f32x8::splat(f32::from_bits(u32::MAX));
    for q in 0..Q {
        ok &= load(g.rows[q]).abs().simd_le(max);
    }
    8 - ok.to_bitmask().count_ones() as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 + FMA groups (where this CPU has them) agree with the
    /// portable lanes: bit for bit where `wide` is AVX2 + FMA, else to the
    /// rounding of fused against separate products; the same pixels are done
    /// and the same non-finite guides counted (B = 8 and 16, both clamps).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_spans_match_portable() {
        if !Isa::Avx2Fma.available() {
            return;
        }
        let mut seed = 4242u32;
        let mut rnd = || crate::hash::uniform(&mut seed) as f32;
        const W: usize = 263;
        let rows: [[f32; W]; MAX_GUIDES] =
            core::array::from_fn(|q| core::array::from_fn(|x| if (x * 7 + q) % 97 == 5 { f32::NAN } else { 3.0 * rnd() }));
        let models: [f32; 40 * model_len_max()] = core::array::from_fn(|_| rnd());
        fn case<const Q: usize>(rows: &[[f32; W]; MAX_GUIDES], models: &[f32], block: usize, clamp: bool) {
            let ml = crate::kernels::model_len(Q);
            let cells_x = W.div_ceil(block);
            let (base, slopes) = (&models[..cells_x * ml], &models[ml..(cells_x + 1) * ml]);
            let guides =
                RowGuides { rows: core::array::from_fn(|q| &rows[q][..]), reference: core::array::from_fn(|q| 0.25 * q as f32), width: W };
            let span = Span { ml, block, half: block / 2, cells_x };
            let demod = (Q > 1).then_some((1, 0.1));
            let run = |isa: Isa| {
                let mut out = [[0f32; W]; 3];
                let [a, b, c] = &mut out;
                let mut outs = Planes([&mut a[..], &mut b[..], &mut c[..]]);
                let r = match (isa, clamp) {
                    (Isa::Portable, true) => simd_spans::<Q, true, _>(base, slopes, &span, &guides, demod, &mut outs),
                    (Isa::Portable, false) => simd_spans::<Q, false, _>(base, slopes, &span, &guides, demod, &mut outs),
                    // SAFETY: the test returned early unless the CPU has AVX2 and FMA.
                    (Isa::Avx2Fma | Isa::Avx512, true) => unsafe {
                        avx2::simd_spans::<Q, true, _>(base, slopes, &span, &guides, demod, &mut outs)
                    },
                    // SAFETY: as above.
                    (Isa::Avx2Fma | Isa::Avx512, false) => unsafe {
                        avx2::simd_spans::<Q, false, _>(base, slopes, &span, &guides, demod, &mut outs)
                    },
                };
                (r, out)
            };
            let ((pf, px), p) = run(Isa::Portable);
            let ((af, ax), a) = run(Isa::Avx2Fma);
            assert_eq!((pf, px), (af, ax), "Q {Q} B {block}");
            assert!(px > W / 2, "the spans cover most of the row");
            assert!(Q == 0 || pf > 0, "some non-finite guides are counted");
            let fused = cfg!(all(target_feature = "avx2", target_feature = "fma"));
            for c in 0..3 {
                for x in 0..W {
                    let (p, a) = (p[c][x], a[c][x]);
                    if fused {
                        assert_eq!(p.to_bits(), a.to_bits(), "Q {Q} B {block} c {c} x {x}: {p} vs {a}");
                    } else {
                        assert!((p - a).abs() <= 1e-5 * (1.0 + p.abs()), "Q {Q} B {block} c {c} x {x}: {p} vs {a}");
                    }
                }
            }
        }
        for block in [8usize, 16] {
            for clamp in [false, true] {
                case::<0>(&rows, &models, block, clamp);
                case::<1>(&rows, &models, block, clamp);
                case::<3>(&rows, &models, block, clamp);
                case::<5>(&rows, &models, block, clamp);
                case::<MAX_GUIDES>(&rows, &models, block, clamp);
            }
        }
    }

    /// Every [`RowOut`] holds the same values for every pixel, interleaved or
    /// not, streamed (aligned or not) or not, and the AO re-modulation gives
    /// exactly `remodulate1(y, scale(ao, c))` of the value without it (what a
    /// separate pass over the row gave before it was fused): widths 1..263, B
    /// = 8 and 16, lanes and scalar, with non-finite guides and AO values.
    #[test]
    fn row_outputs_agree_and_remodulate_exactly() {
        #[repr(align(16))]
        struct Aligned([f32; 3 * W + 4]);
        const W: usize = 263;
        let mut seed = 77u32;
        let mut rnd = || crate::hash::uniform(&mut seed) as f32;
        let rows: [[f32; W]; MAX_GUIDES] = core::array::from_fn(|q| {
            core::array::from_fn(|x| match (x * 5 + q) % 89 {
                3 => f32::NAN,
                7 => f32::INFINITY,
                _ => 2.0 * rnd() - 0.5,
            })
        });
        let models: [f32; 40 * model_len_max()] = core::array::from_fn(|_| 2.0 * rnd() - 1.0);
        fn case<const Q: usize>(rows: &[[f32; W]; MAX_GUIDES], models: &[f32], w: usize, block: usize, simd: bool, clamp: bool) {
            let ml = crate::kernels::model_len(Q);
            let cells_x = w.div_ceil(block);
            let (m, sl) = (&models[..cells_x * ml], &models[ml..(cells_x.max(2) + 1) * ml]);
            let guides =
                RowGuides { rows: core::array::from_fn(|q| &rows[q][..w]), reference: core::array::from_fn(|q| 0.1 * q as f32), width: w };
            let demods = [None, Some((Q.saturating_sub(1), 0.1f32))];
            for demod in demods.into_iter().take(if Q > 0 { 2 } else { 1 }) {
                let run = |out: RowOut<'_>| apply_row::<Q>(m, sl, cells_x, block, guides, clamp, demod, simd, out);
                let mut planes = [0f32; 3 * W];
                let n_planes = run(RowOut::Planes(&mut planes[..3 * w]));
                let mut want = [0f32; 3 * W];
                for x in 0..w {
                    for c in 0..3 {
                        want[3 * x + c] = planes[c * w + x];
                    }
                }
                if let Some((a, c)) = demod {
                    let mut plain = [0f32; 3 * W];
                    apply_row::<Q>(m, sl, cells_x, block, guides, clamp, None, simd, RowOut::Planes(&mut plain[..3 * w]));
                    for x in 0..w {
                        for ch in 0..3 {
                            let y = demodulation::remodulate1(plain[ch * w + x], demodulation::scale(rows[a][x], c));
                            assert_eq!(
                                y.to_bits(),
                                planes[ch * w + x].to_bits(),
                                "Q {Q} w {w} B {block} x {x}: {y} vs {}",
                                planes[ch * w + x]
                            );
                        }
                    }
                }
                for shift in [0usize, 1] {
                    let mut buf = Aligned([0f32; 3 * W + 4]);
                    for streaming in [false, true] {
                        buf.0.fill(-7.0);
                        let dst = &mut buf.0[shift..shift + 3 * w];
                        let n = run(if streaming { RowOut::RgbStreaming(dst) } else { RowOut::Rgb(dst) });
                        assert_eq!(n, n_planes);
                        for (i, (a, b)) in buf.0[shift..shift + 3 * w].iter().zip(&want[..3 * w]).enumerate() {
                            assert_eq!(a.to_bits(), b.to_bits(), "Q {Q} w {w} B {block} simd {simd} value {i}: {a} vs {b}");
                            assert!(a.is_finite());
                        }
                        assert!(buf.0[shift + 3 * w..].iter().all(|v| *v == -7.0), "nothing written past the row");
                    }
                }
            }
        }
        for w in [1usize, 7, 8, 12, 37, 256, W] {
            for block in [8usize, 16] {
                for simd in [true, false] {
                    case::<0>(&rows, &models, w, block, simd, false);
                    case::<3>(&rows, &models, w, block, simd, true);
                    case::<5>(&rows, &models, w, block, simd, false);
                    case::<MAX_GUIDES>(&rows, &models, w, block, simd, true);
                }
            }
        }
    }

    const fn model_len_max() -> usize {
        crate::kernels::model_len(MAX_GUIDES)
    }
}
