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
    pub rows: [&'a [f32]; MAX_GUIDES],
    pub reference: [f32; MAX_GUIDES],
    pub width: usize,
}

/// Evaluates one output row into `out` (3 planes of `width`). A pixel with a
/// non-finite guide gets the local mean; returns how many did. `row_slopes`
/// are the differences of consecutive cells' models ([`lerp_rows`]).
#[allow(clippy::too_many_arguments)]
pub fn apply_row<const Q: usize>(
    row_models: &[f32],
    row_slopes: &[f32],
    cells_x: usize,
    block: usize,
    guides: RowGuides<'_>,
    clamp: bool,
    simd: bool,
    out: &mut [f32],
) -> usize {
    let w = guides.width;
    let ml = super::model_len(Q);
    if guides.rows[..Q].iter().any(|r| r.len() < w)
        || out.len() < 3 * w
        || row_models.len() < cells_x * ml
        || row_slopes.len() < (cells_x - 1) * ml
    {
        return 0; // unreachable from the FLR driver, which sizes every buffer
    }
    let (o0, rest) = out.split_at_mut(w);
    let (o1, o2) = rest.split_at_mut(w);
    let mut outs = [o0, o1, &mut o2[..w]];
    let mut fallback = 0;

    let mut x = 0;
    if simd && block.is_multiple_of(8) && cells_x > 1 {
        // Left edge: pixels before the first centre use cell 0 alone (scalar below).
        let half = block / 2;
        while x < half.min(w) {
            fallback += scalar_px::<Q>(row_models, cells_x, block, ml, &guides, clamp, x, &mut outs);
            x += 1;
        }
        let span = Span { ml, block, half, cells_x };
        let (f, end) = if clamp {
            simd_spans_on::<Q, true>(Isa::detect(), row_models, row_slopes, &span, &guides, &mut outs)
        } else {
            simd_spans_on::<Q, false>(Isa::detect(), row_models, row_slopes, &span, &guides, &mut outs)
        };
        fallback += f;
        x = end;
    }
    while x < w {
        fallback += scalar_px::<Q>(row_models, cells_x, block, ml, &guides, clamp, x, &mut outs);
        x += 1;
    }
    fallback
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scalar_px<const Q: usize>(
    row_models: &[f32],
    cells_x: usize,
    block: usize,
    ml: usize,
    g: &RowGuides<'_>,
    clamp: bool,
    x: usize,
    outs: &mut [&mut [f32]; 3],
) -> usize {
    let (i, fx) = cell_pos(x, block, cells_x);
    let a = &row_models[i * ml..(i + 1) * ml];
    let b = if fx == 0.0 { a } else { &row_models[(i + 1) * ml..(i + 2) * ml] };
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
    row_models: &[f32],
    row_slopes: &[f32],
    sp: &Span,
    guides: &RowGuides<'_>,
    outs: &mut [&mut [f32]; 3],
) -> (usize, usize) {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::simd_spans::<Q, CLAMP>(row_models, row_slopes, sp, guides, outs) };
    }
    let _ = isa;
    simd_spans::<Q, CLAMP>(row_models, row_slopes, sp, guides, outs)
}

/// Every whole 8-pixel group between the first and last cell centres; returns
/// the fallback count and the first pixel not done.
#[inline(always)]
fn simd_spans<const Q: usize, const CLAMP: bool>(
    row_models: &[f32],
    row_slopes: &[f32],
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
            fallback += simd_group::<Q, CLAMP>(base, slope, fx0, &reference, guides, x0, outs);
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
            fallback += simd_group::<Q, CLAMP>(base, slope, fx, &reference, guides, x0, outs);
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
            let (base, slopes) = (&models[..cells_x * ml], &models[ml..(cells_x + 1) * ml]);
            let guides =
                RowGuides { rows: core::array::from_fn(|q| &rows[q][..]), reference: core::array::from_fn(|q| 0.25 * q as f32), width: W };
            let span = Span { ml, block, half: block / 2, cells_x };
            let run = |isa: Isa| {
                let mut out = [[0f32; W]; 3];
                let [a, b, c] = &mut out;
                let mut outs = [&mut a[..], &mut b[..], &mut c[..]];
                let r = match (isa, clamp) {
                    (Isa::Portable, true) => simd_spans::<Q, true>(base, slopes, &span, &guides, &mut outs),
                    (Isa::Portable, false) => simd_spans::<Q, false>(base, slopes, &span, &guides, &mut outs),
                    // SAFETY: the test returned early unless the CPU has AVX2 and FMA.
                    (Isa::Avx2Fma, true) => unsafe { avx2::simd_spans::<Q, true>(base, slopes, &span, &guides, &mut outs) },
                    // SAFETY: as above.
                    (Isa::Avx2Fma, false) => unsafe { avx2::simd_spans::<Q, false>(base, slopes, &span, &guides, &mut outs) },
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
