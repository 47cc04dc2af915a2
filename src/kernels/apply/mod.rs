//! Kernel 4: bilinear interpolation of the per-cell affine models between
//! cell centres and application to the full-resolution guides (paper §3.2).
//!
//! Cell `i` covers pixels `i·B .. i·B + B`; its centre is at `i·B + B/2 − ½`.
//! [`model_rows`] picks the two model rows an output row lies between;
//! [`apply_row`] interpolates each cell's model vertically to the row as it
//! reaches it, then horizontally per pixel, and evaluates `ŷ = c0 + Σ c_q d_q`
//! (eq. 23 in raw coordinates). With B a multiple of 8 each span between two
//! centres is whole `f32x8` groups with fixed lane weights.

#[cfg(target_arch = "x86_64")]
mod avx2;

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

/// The two rows of the model grid output row `y` interpolates between: cell
/// row `a`, and `b` with weight `fy` ([`model_rows`]). Each holds `cells_x ·
/// model_len(Q)` values.
#[derive(Clone, Copy, Debug)]
pub struct ModelRows<'a> {
    pub a: &'a [f32],
    pub b: &'a [f32],
    pub fy: f32,
}

/// The model rows output row `y` interpolates between, in a grid of `cells_y`
/// rows of `cells_x · ml` values.
pub fn model_rows(models: &[f32], cells_x: usize, cells_y: usize, ml: usize, block: usize, y: usize) -> ModelRows<'_> {
    let (j, fy) = cell_pos(y, block, cells_y);
    let row = cells_x * ml;
    let a = &models[j * row..(j + 1) * row];
    let b = if fy == 0.0 { a } else { &models[(j + 1) * row..(j + 2) * row] };
    ModelRows { a, b, fy }
}

impl ModelRows<'_> {
    /// Cell `i`'s model at this output row, `a + (b − a)·fy`, into `out[..ml]`.
    #[inline(always)]
    fn cell(&self, i: usize, ml: usize, out: &mut [f32]) {
        self.cells(i, 1, ml, out);
    }
    /// The models of cells `i..i + n` at this output row into `out[..n · ml]`.
    #[inline(always)]
    fn cells(&self, i: usize, n: usize, ml: usize, out: &mut [f32]) {
        let r = i * ml..(i + n) * ml;
        let (a, out) = (&self.a[r.clone()], &mut out[..n * ml]);
        if self.fy == 0.0 {
            out.copy_from_slice(a);
            return;
        }
        for ((o, a), b) in out.iter_mut().zip(a).zip(&self.b[r]) {
            *o = a + (b - a) * self.fy;
        }
    }
}

/// Most model values (`model_len(MAX_GUIDES)`).
const MAX_ML: usize = super::model_len(MAX_GUIDES);

/// Spans whose models [`Spans`] interpolates at once.
const CHUNK: usize = 16;

/// The spans between consecutive cell centres of one output row, `CHUNK` at
/// a time: [`Spans::fill`] interpolates the models of spans `i0..` to the row
/// into buffers that stay in L1 (a few KB), then [`Spans::span`] gives span
/// `i0 + c`'s model `c_i` (its left cell's) and slope `c_{i+1} − c_i`, which
/// the groups splat. (Before session 30 a whole row of models and slopes was
/// interpolated first: two ~20 KB arrays per row at 1080p, ~1 ms per frame
/// more. Filling inside the group loop, one span or one chunk at a time, was
/// slower still: the compiler then kept the group's constants on the stack.)
pub(super) struct Spans<'r> {
    rows: ModelRows<'r>,
    ml: usize,
    cells_x: usize,
    models: [f32; (CHUNK + 1) * MAX_ML],
    slopes: [f32; CHUNK * MAX_ML],
}

impl<'r> Spans<'r> {
    #[inline(always)]
    pub(super) fn new(rows: ModelRows<'r>, ml: usize, cells_x: usize) -> Self {
        Spans { rows, ml, cells_x, models: [0.0; (CHUNK + 1) * MAX_ML], slopes: [0.0; CHUNK * MAX_ML] }
    }
    /// Interpolates spans `i0..i0 + n` (`i0 < cells_x − 1`) and returns `n`,
    /// at most `CHUNK`.
    #[inline(always)]
    pub(super) fn fill(&mut self, i0: usize) -> usize {
        let ml = self.ml;
        let n = CHUNK.min(self.cells_x - 1 - i0);
        // cells i0..=i0 + n, one flat run of values
        self.rows.cells(i0, n + 1, ml, &mut self.models);
        let (m, next) = (&self.models[..n * ml], &self.models[ml..(n + 1) * ml]);
        for ((s, a), b) in self.slopes[..n * ml].iter_mut().zip(m).zip(next) {
            *s = b - a;
        }
        n
    }
    /// Model and slope of the filled chunk's span `c`.
    #[inline(always)]
    pub(super) fn span(&self, c: usize) -> (&[f32], &[f32]) {
        let ml = self.ml;
        (&self.models[c * ml..(c + 1) * ml], &self.slopes[c * ml..(c + 1) * ml])
    }
}

/// Guide rows of one output row: `Q` slices of `width` raw guide values (from
/// the caller's image when it is planar f32, else gathered), and the frame
/// reference `m` each is measured from (`d = g − m`).
#[derive(Clone, Copy, Debug)]
pub struct RowGuides<'a> {
    pub rows: [&'a [f32]; MAX_GUIDES],
    pub reference: [f32; MAX_GUIDES],
    pub width: usize,
}

/// Evaluates one output row into `out` (3 planes of `width`), interpolating
/// the models of `rows` ([`model_rows`]). A pixel with a non-finite guide gets
/// the local mean; returns how many did.
#[allow(clippy::too_many_arguments)]
pub fn apply_row<const Q: usize>(
    rows: ModelRows<'_>,
    cells_x: usize,
    block: usize,
    guides: RowGuides<'_>,
    clamp: bool,
    simd: bool,
    out: &mut [f32],
) -> usize {
    let w = guides.width;
    let ml = super::model_len(Q);
    if guides.rows[..Q].iter().any(|r| r.len() < w) || out.len() < 3 * w || rows.a.len() < cells_x * ml || rows.b.len() < cells_x * ml {
        return 0; // unreachable from the FLR driver, which sizes every buffer
    }
    let (o0, rest) = out.split_at_mut(w);
    let (o1, o2) = rest.split_at_mut(w);
    let mut outs = [o0, o1, &mut o2[..w]];
    let mut fallback = 0;
    let mut pair = CellPair::new();

    let mut x = 0;
    if simd && block.is_multiple_of(8) && cells_x > 1 {
        // Left edge: pixels before the first centre use cell 0 alone (scalar below).
        let half = block / 2;
        while x < half.min(w) {
            fallback += scalar_px::<Q>(&rows, &mut pair, cells_x, block, ml, &guides, clamp, x, &mut outs);
            x += 1;
        }
        let span = Span { ml, block, half, cells_x };
        let (f, end) = if clamp {
            simd_spans_on::<Q, true>(Isa::detect(), rows, &span, &guides, &mut outs)
        } else {
            simd_spans_on::<Q, false>(Isa::detect(), rows, &span, &guides, &mut outs)
        };
        fallback += f;
        x = end;
    }
    while x < w {
        fallback += scalar_px::<Q>(&rows, &mut pair, cells_x, block, ml, &guides, clamp, x, &mut outs);
        x += 1;
    }
    fallback
}

/// The models of cells `i` and `i + 1` at one output row, for the pixels
/// done one at a time: kept while consecutive pixels lie in the same span.
struct CellPair {
    i: usize,
    m: [[f32; MAX_ML]; 2],
}

impl CellPair {
    fn new() -> Self {
        CellPair { i: usize::MAX, m: [[0.0; MAX_ML]; 2] }
    }
    /// Cell `i`'s model and, if `i + 1 < cells_x`, cell `i + 1`'s.
    #[inline(always)]
    fn get(&mut self, rows: &ModelRows<'_>, i: usize, cells_x: usize, ml: usize) -> &[[f32; MAX_ML]; 2] {
        if self.i != i {
            self.i = i;
            rows.cell(i, ml, &mut self.m[0]);
            if i + 1 < cells_x {
                rows.cell(i + 1, ml, &mut self.m[1]);
            }
        }
        &self.m
    }
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scalar_px<const Q: usize>(
    rows: &ModelRows<'_>,
    pair: &mut CellPair,
    cells_x: usize,
    block: usize,
    ml: usize,
    g: &RowGuides<'_>,
    clamp: bool,
    x: usize,
    outs: &mut [&mut [f32]; 3],
) -> usize {
    let (i, fx) = cell_pos(x, block, cells_x);
    // (fx > 0 only where cell i + 1 exists)
    let m = pair.get(rows, i, cells_x, ml);
    let a = &m[0][..ml];
    let b = if fx == 0.0 { a } else { &m[1][..ml] };
    let lerp = |j: usize| a[j] + (b[j] - a[j]) * fx;
    let mut d = [0f32; MAX_GUIDES];
    let mut valid = true;
    for q in 0..Q {
        let v = g.rows[q][x];
        valid &= v.is_finite();
        d[q] = v - g.reference[q];
    }
    for c in 0..3 {
        let mut y = lerp(c);
        for q in 0..Q {
            y += lerp(3 + 3 * q + c) * d[q];
        }
        let muy = lerp(3 + 3 * Q + c);
        let y = if valid && y.is_finite() { y } else { muy };
        outs[c][x] = if clamp { y.max(0.0) } else { y };
    }
    !valid as usize
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
fn simd_spans_on<const Q: usize, const CLAMP: bool>(
    isa: Isa,
    rows: ModelRows<'_>,
    sp: &Span,
    guides: &RowGuides<'_>,
    outs: &mut [&mut [f32]; 3],
) -> (usize, usize) {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::simd_spans::<Q, CLAMP>(rows, sp, guides, outs) };
    }
    let _ = isa;
    simd_spans::<Q, CLAMP>(rows, sp, guides, outs)
}

/// Every whole 8-pixel group between the first and last cell centres; returns
/// the fallback count and the first pixel not done.
#[inline(always)]
fn simd_spans<const Q: usize, const CLAMP: bool>(
    rows: ModelRows<'_>,
    sp: &Span,
    guides: &RowGuides<'_>,
    outs: &mut [&mut [f32]; 3],
) -> (usize, usize) {
    let (ml, w) = (sp.ml, guides.width);
    let inv_b = f32x8::splat(1.0 / sp.block as f32);
    let fx0 = f32x8::from([0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5]) * inv_b;
    let mut reference = [f32x8::ZERO; MAX_GUIDES];
    for q in 0..Q {
        reference[q] = f32x8::splat(guides.reference[q]);
    }
    let (mut fallback, mut x) = (0, sp.half.min(w));
    let mut spans = Spans::new(rows, ml, sp.cells_x);
    let mut i0 = 0;
    if sp.block == 8 {
        // One group per span. Kept apart from the general loop: there the
        // compiler hoists the span's 2·ml splats out of the group loop and,
        // with too few registers, spills them: ~2× the instructions per group.
        while i0 < sp.cells_x - 1 {
            let n = spans.fill(i0);
            for c in 0..n {
                let x0 = (i0 + c) * 8 + sp.half;
                if x0 + 8 > w {
                    return (fallback, x);
                }
                let (base, slope) = spans.span(c);
                fallback += simd_group::<Q, CLAMP>(base, slope, fx0, &reference, guides, x0, outs);
                x = x0 + 8;
            }
            i0 += n;
        }
        return (fallback, x);
    }
    while i0 < sp.cells_x - 1 {
        let n = spans.fill(i0);
        for c in 0..n {
            let start = (i0 + c) * sp.block + sp.half;
            // The span's model is `a + fx·(b − a)`: both splatted from memory per group.
            let (base, slope) = spans.span(c);
            for g in 0..sp.block / 8 {
                let x0 = start + 8 * g;
                if x0 + 8 > w {
                    return (fallback, x);
                }
                let fx = if g == 0 { fx0 } else { fx0 + f32x8::splat((8 * g) as f32) * inv_b };
                fallback += simd_group::<Q, CLAMP>(base, slope, fx, &reference, guides, x0, outs);
                x = x0 + 8;
            }
        }
        i0 += n;
    }
    (fallback, x)
}

/// One group of 8 pixels, channels one after the other (interleaving their
/// chains measured slower: it spills). A non-finite guide makes every
/// channel's `y` non-finite (`c·d` is NaN or ±Inf for any `c`, 0·Inf
/// included), so one finiteness test of `y` covers the guides too; the guides
/// are looked at again only to count fallbacks when some lane failed.
#[inline(always)]
fn simd_group<const Q: usize, const CLAMP: bool>(
    base: &[f32],
    slope: &[f32],
    fx: f32x8,
    reference: &[f32x8; MAX_GUIDES],
    g: &RowGuides<'_>,
    x0: usize,
    outs: &mut [&mut [f32]; 3],
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
    for c in 0..3 {
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
        let arr: [f32; 8] = r.into();
        outs[c][x0..x0 + 8].copy_from_slice(&arr);
    }
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
            let mrows = ModelRows { a: &models[..cells_x * ml], b: &models[ml..(cells_x + 1) * ml], fy: 0.375 };
            let guides =
                RowGuides { rows: core::array::from_fn(|q| &rows[q][..]), reference: core::array::from_fn(|q| 0.25 * q as f32), width: W };
            let span = Span { ml, block, half: block / 2, cells_x };
            let run = |isa: Isa| {
                let mut out = [[0f32; W]; 3];
                let [a, b, c] = &mut out;
                let mut outs = [&mut a[..], &mut b[..], &mut c[..]];
                let r = match (isa, clamp) {
                    (Isa::Portable, true) => simd_spans::<Q, true>(mrows, &span, &guides, &mut outs),
                    (Isa::Portable, false) => simd_spans::<Q, false>(mrows, &span, &guides, &mut outs),
                    // SAFETY: the test returned early unless the CPU has AVX2 and FMA.
                    (Isa::Avx2Fma, true) => unsafe { avx2::simd_spans::<Q, true>(mrows, &span, &guides, &mut outs) },
                    // SAFETY: as above.
                    (Isa::Avx2Fma, false) => unsafe { avx2::simd_spans::<Q, false>(mrows, &span, &guides, &mut outs) },
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

    const fn model_len_max() -> usize {
        crate::kernels::model_len(MAX_GUIDES)
    }
}
