//! AVX2 + FMA version of the Gaussian blurs' interior loops
//! ([`super::blur_row`], [`super::blur_cols_band`]), for builds whose `wide`
//! is SSE2 (an `f64x4` of two SSE2 halves, multiply and add unfused): the same
//! loops with `core::arch` intrinsics, chosen at run time by
//! [`crate::isa::Isa`]. The same operations in the same order as the portable
//! version in an `x86-64-v3` build (bit-identical there); `blur::tests`
//! compares the two.

use super::{row_pairs, tap_chunk, ColLanes, ALL, LANES, VECS};
use core::arch::x86_64::{
    __m256d, _mm256_add_pd, _mm256_fmadd_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd,
};

/// `VECS` vectors from `s[..LANES]` (bounds-checked).
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn load(s: &[f64]) -> [__m256d; VECS] {
    let s = &s[..LANES];
    // SAFETY: AVX is guaranteed by the caller.
    let mut a = unsafe { [_mm256_setzero_pd(); VECS] };
    for (l, v) in a.iter_mut().enumerate() {
        // SAFETY: `s` holds LANES = 4·VECS values; AVX is guaranteed by the caller.
        *v = unsafe { _mm256_loadu_pd(s[4 * l..4 * l + 4].as_ptr()) };
    }
    a
}

/// Stores `a` into `d[..LANES]` (bounds-checked).
///
/// # Safety
/// The CPU must support AVX.
#[inline(always)]
unsafe fn store(a: &[__m256d; VECS], d: &mut [f64]) {
    let d = &mut d[..LANES];
    for (l, v) in a.iter().enumerate() {
        // SAFETY: `d` holds LANES = 4·VECS values; AVX is guaranteed by the caller.
        unsafe { _mm256_storeu_pd(d[4 * l..4 * l + 4].as_mut_ptr(), *v) };
    }
}

/// The horizontal pass's interior, values `x..` while `x + LANES ≤ end`:
/// `dst[x] = w0·src[x] + Σ_o w_o (src[x − o·k] + src[x + o·k])`, two cells at a
/// time ([`row_pairs`]), then `LANES` values at a time ([`tap_chunk`]).
/// Returns the first value not done.
///
/// # Safety
/// The CPU must support AVX2 and FMA; `x ≥ r·k` and `end + r·k ≤ src.len()`
/// (the slices are bounds-checked regardless).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn row_interior(w: &[f64], r: usize, k: usize, src: &[f64], dst: &mut [f64], mut x: usize, end: usize) -> usize {
    // SAFETY (every load and store): AVX2 and FMA are enabled in this function;
    // the slices are bounds-checked.
    let load2 = |i: usize| {
        let s = &src[i..i + 8];
        unsafe { [Lanes(_mm256_loadu_pd(s.as_ptr())), Lanes(_mm256_loadu_pd(s[4..].as_ptr()))] }
    };
    x = row_pairs::<Lanes>(w, r, k, x, end, load2, |i, v: [Lanes; 2]| {
        let d = &mut dst[i..i + 8];
        unsafe {
            _mm256_storeu_pd(d.as_mut_ptr(), v[0].0);
            _mm256_storeu_pd(d[4..].as_mut_ptr(), v[1].0);
        }
    });
    while x + LANES <= end {
        let acc = tap_chunk::<Lanes>(w, r, ALL, 0, |o| unsafe { load(&src[(x as isize + o * k as isize) as usize..]) }.map(Lanes));
        unsafe { store(&acc.map(|v| v.0), &mut dst[x..]) };
        x += LANES;
    }
    x
}

/// Four f64 lanes in one AVX register for [`tap_chunk`] and [`row_pairs`].
/// Made only inside [`cols_strip`] and [`row_interior`],
/// `#[target_feature(enable = "avx2,fma")]` functions that run only where the
/// CPU has them: that is what makes its safe methods (AVX and FMA
/// instructions, `#[inline(always)]` into those functions) sound.
#[derive(Clone, Copy)]
struct Lanes(__m256d);

impl ColLanes for Lanes {
    #[inline(always)]
    fn scale(self, w: f64) -> Self {
        // SAFETY: only inside `cols_strip` and `row_interior`, where AVX2 and FMA are enabled (see the type).
        Lanes(unsafe { _mm256_mul_pd(self.0, _mm256_set1_pd(w)) })
    }
    #[inline(always)]
    fn pair_add(self, other: Self, w: f64, acc: Self) -> Self {
        // SAFETY: as above.
        Lanes(unsafe { _mm256_fmadd_pd(_mm256_add_pd(self.0, other.0), _mm256_set1_pd(w), acc.0) })
    }
    #[inline(always)]
    fn one_add(self, w: f64, acc: Self) -> Self {
        // SAFETY: as above.
        Lanes(unsafe { _mm256_fmadd_pd(self.0, _mm256_set1_pd(w), acc.0) })
    }
}

/// The vertical pass's chunks `c..` in steps of `LANES` while `c + LANES ≤
/// end`, of output row `j` into `out` and, unless `next` is empty, of row
/// `j + 1` into `next` ([`tap_chunk`]); `src` holds the grid's `cells_y`
/// rows. Returns the first value not done.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn cols_strip(
    w: &[f64],
    r: usize,
    src: &[f64],
    row_len: usize,
    cells_y: usize,
    j: isize,
    out: &mut [f64],
    next: &mut [f64],
    mut c: usize,
    end: usize,
) -> usize {
    // SAFETY (every `load`/`store`): AVX2 and FMA are enabled in this function.
    let row = |jj: isize, c: usize| unsafe { load(&src[jj as usize * row_len + c..]) }.map(Lanes);
    while c + LANES <= end {
        let acc = tap_chunk::<Lanes>(w, r, 0..cells_y as isize, j, |jj| row(jj, c));
        unsafe { store(&acc.map(|v| v.0), &mut out[c..]) };
        if !next.is_empty() {
            let acc = tap_chunk::<Lanes>(w, r, 0..cells_y as isize, j + 1, |jj| row(jj, c));
            unsafe { store(&acc.map(|v| v.0), &mut next[c..]) };
        }
        c += LANES;
    }
    c
}
