//! AO demodulation ([`crate::FlrConfig::ao_demodulation`]): the noisy light
//! is divided by `s(ao) = √(clamp(ao, 0, 1) + c)` before its moments are
//! taken and the applied model multiplied by `s` again, so FLR fits
//! `y ≈ s · (c₀ + β·g)` by least squares weighted `1 / s²`.
//!
//! Why: the quality protocol (`docs/DATA.md`) scores tone-mapped light, in
//! which an error in a dark, occluded region weighs more than the same error
//! in an open one, while plain least squares let the bright pixels of a window
//! dominate its fit. Occlusion also scales the light rather than adding to it,
//! which the model `s · (c₀ + β·g)` expresses with the same coefficients.
//! The square root and the offset `c` were chosen on the training scenes
//! (`docs/METHODS.md`, FLR); `s ∈ [√c, √(1 + c)]`, never 0 or NaN: a
//! non-finite AO value counts as 1 (open), out-of-range values are clamped.
//!
//! The moments' in-place path demodulates its colour vectors as it builds
//! them ([`inverse8`], [`demodulate8`]: no pass of its own), and the apply
//! re-modulates each group of eight pixels before it stores them
//! ([`scale8`], [`remodulate8`]); only the gathering moments path runs over
//! rows ([`divide_rows`]).
//! Both run eight pixels at a time (`wide`), the row's tail one by one;
//! square root and division are correctly rounded, so the lanes and the tail
//! give the same values. Cost at 1080p (x86-64-v3, Zen 4, one thread):
//! +1.0–2.2 ms (~6 %), mostly the square root and the one division per pixel.
//! The GPU shaders (`src/flr/flr.wgsl`, `demod_*`) do the same arithmetic.

use wide::f32x8;

/// `s(ao)` for the offset `c` (`c > 0`, checked by `FlrConfig::validate`).
#[inline]
pub fn scale(ao: f32, c: f32) -> f32 {
    // `a.abs() <= MAX` is false for NaN and ±Inf
    let a = if ao.abs() <= f32::MAX { ao } else { 1.0 };
    libm::sqrtf(a.clamp(0.0, 1.0) + c)
}

/// `1 / s(ao)` on eight lanes (the square root and the division are correctly
/// rounded, so each lane is `1.0 / scale(ao, c)` exactly).
#[inline(always)]
pub fn inverse8(ao: f32x8, c: f32x8) -> f32x8 {
    f32x8::ONE / scale8(ao, c)
}

/// [`scale`] on eight lanes (correctly rounded: each lane is `scale(ao, c)`).
#[inline(always)]
pub fn scale8(ao: f32x8, c: f32x8) -> f32x8 {
    let finite = ao.abs().simd_le(f32x8::splat(f32::MAX));
    let a = finite.select(ao, f32x8::ONE);
    (a.fast_max(f32x8::ZERO).fast_min(f32x8::ONE) + c).sqrt()
}

/// `x · f` clamped to ±`f32::MAX`, so that a finite value stays finite; a
/// non-finite `x` becomes NaN (`+ (x − x)`), still non-finite for the moments'
/// check to exclude and count. Min, max and add rather than a select: a
/// select against a loaded value compiles to masked stores, which cost ~10 ms
/// per 1080p frame on Zen 4 (measured).
#[inline(always)]
#[allow(clippy::eq_op)] // `x − x` is 0 or NaN on purpose
pub fn demodulate8(x: f32x8, f: f32x8) -> f32x8 {
    let max = f32x8::splat(f32::MAX);
    (x * f).fast_min(max).fast_max(-max) + (x - x)
}

/// [`demodulate8`] on one value.
#[inline(always)]
#[allow(clippy::eq_op)] // as in `demodulate8`
fn demodulate1(x: f32, f: f32) -> f32 {
    (x * f).clamp(-f32::MAX, f32::MAX) + (x - x)
}

/// `y · s` clamped to ±`f32::MAX` (the applied model re-modulated; the
/// output stays finite).
#[inline(always)]
pub fn remodulate8(y: f32x8, s: f32x8) -> f32x8 {
    let max = f32x8::splat(f32::MAX);
    (y * s).fast_min(max).fast_max(-max)
}

/// [`remodulate8`] on one value (the same rounding: one product, then the clamp).
#[inline(always)]
pub fn remodulate1(y: f32, s: f32) -> f32 {
    (y * s).clamp(-f32::MAX, f32::MAX)
}

/// Divides three colour rows by `s(ao)` per pixel (before the moments), `s`
/// once per pixel for all three ([`demodulate8`]). A finite value that the
/// division would make infinite (beyond ~0.3 × `f32::MAX` for a small `c`) is
/// clamped to ±`f32::MAX`: still finite, so the moments' finiteness check sees
/// what the caller gave; NaN and ±Inf become NaN.
#[inline]
pub fn divide_rows(rgb: [&mut [f32]; 3], ao: &[f32], c: f32) {
    let c8 = f32x8::splat(c);
    let [r, g, b] = rgb;
    let n = ao.len().min(r.len()).min(g.len()).min(b.len());
    let whole = n - n % 8;
    let lanes = |v: &[f32]| f32x8::from(<[f32; 8]>::try_from(v).unwrap_or_default());
    let one = |v: &mut [f32], f: f32x8| v.copy_from_slice(&demodulate8(lanes(v), f).to_array());
    let chunks = r[..whole].chunks_exact_mut(8).zip(g[..whole].chunks_exact_mut(8)).zip(b[..whole].chunks_exact_mut(8));
    for (((r, g), b), a) in chunks.zip(ao[..whole].chunks_exact(8)) {
        let f = inverse8(lanes(a), c8);
        one(r, f);
        one(g, f);
        one(b, f);
    }
    for i in whole..n {
        let f = 1.0 / scale(ao[i], c);
        for v in [&mut r[i], &mut g[i], &mut b[i]] {
            *v = demodulate1(*v, f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_is_bounded_and_finite() {
        let c = 0.1;
        for a in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -5.0, 0.0, 0.3, 1.0, 7.0, f32::MAX] {
            let s = scale(a, c);
            assert!(s.is_finite() && s >= c.sqrt() && s <= (1.0 + c).sqrt(), "{a}: {s}");
        }
        assert_eq!(scale(f32::NAN, c), scale(1.0, c));
        assert_eq!(scale(0.25, 0.75), 1.0);
    }

    #[test]
    fn divide_then_multiply_round_trips_and_stays_finite() {
        let ao = [0.0, 0.5, 1.0, f32::NAN, 0.2];
        let mut r = [1.0, 2.0, 3.0, 4.0, f32::MAX];
        let (mut g, mut b) = ([0.5; 5], [f32::NAN, 1.0, f32::INFINITY, 0.0, -2.0]);
        divide_rows([&mut r, &mut g, &mut b], &ao, 0.1);
        assert_eq!(r[0], 1.0 * (1.0 / 0.1f32.sqrt()));
        assert_eq!(r[4], f32::MAX, "an overflowing quotient is clamped");
        assert!(b[0].is_nan() && b[2].is_nan(), "non-finite input stays non-finite (the moments count it)");
        assert_eq!(b[4], -2.0 * (1.0 / 0.3f32.sqrt()));
        for (i, (x, want)) in r.iter().zip([1.0, 2.0, 3.0, 4.0]).enumerate() {
            let y = remodulate1(*x, scale(ao[i], 0.1));
            assert!((y - want).abs() <= 1e-6 * want, "{y} vs {want}");
        }
        assert_eq!(remodulate1(f32::MAX, 2.0), f32::MAX, "the product is clamped");
        let lanes = remodulate8(f32x8::from([1.0, -f32::MAX, 3.0, 0.5, 0.0, -1.0, 7.0, f32::MAX]), f32x8::splat(1.5)).to_array();
        for (x, y) in [1.0, -f32::MAX, 3.0, 0.5, 0.0, -1.0, 7.0, f32::MAX].iter().zip(lanes) {
            assert_eq!(remodulate1(*x, 1.5).to_bits(), y.to_bits(), "lanes and one value agree");
        }
    }
}
