//! The adaptive window ([`crate::Blur::Adaptive`]): FLR fitted with three
//! Gaussian windows, blended per cell by the inverse of each fit's estimated
//! squared error at the cell (a bias–variance choice made from moments only).
//!
//! For window `s` with `N_s` effective samples (`4πσ_s²` pixels × the valid
//! fraction of the window) and a model with `Q + 1` coefficients, the variance
//! of its prediction is about `v_s = r_s (Q + 1) / N_s`, with `r_s` the
//! weighted residual variance of the light's luminance, `E[ℓ²] − E[ℓ]² − βᵀ
//! cov(g, ℓ)` (the energy moment `e` gives `E[ℓ²]`). The bias of a larger
//! window is measured against the smallest: `d_s² = E₀[(x·(β_s − β₀))²]`, the
//! mean squared difference of their predictions over the smallest window,
//! which also holds the variance difference, so `b_s² = max(d_s² − K·(v₀ −
//! v_s), 0)` with `K` = [`BIAS_DISCOUNT`]. Weights are `1 / (b_s² + v_s)`.
//!
//! Measured on the training scenes (256², 1 spp, σ = 6/12/20 px): +0.29 dB
//! over σ = 12 alone. Estimating `r_s` needs the energy moment, so this mode
//! costs three blurs and three solves instead of one.

use crate::isa::Isa;
use crate::kernels::cholesky::{quad, F64Lanes, Lanes4};
use crate::kernels::{model_len, CellLayout, LUMA};
use wide::{f32x4, f64x4};

#[cfg(target_arch = "x86_64")]
mod avx2;

/// `K`: the share of the variance difference `v₀ − v_s` that `d_s²` is taken
/// to contain (0.5 measured best of 0.25 / 0.5 / 1 on the training scenes;
/// flat within 0.1 dB).
pub const BIAS_DISCOUNT: f64 = 0.5;

/// A larger window (windows 1 and 2) whose σ is at least this many blocks is
/// fitted on the 2×2-pooled grid (cells of 2B × 2B pixels; σ ≥ 0.75 pooled
/// cells, so its Gaussian is still sampled finely enough) and its model and
/// variance are interpolated bilinearly back to the block grid for the blend.
/// Its blur and solve then cost about an eighth as much. At B = 8 that is
/// σ ≥ 12 px: on the training scenes (cell-level prototype, 256², σ = 6/12/20)
/// 32.96 dB pooled against 32.93 dB on the block grid.
pub const POOL_MIN_SIGMA: f32 = 1.5;

/// Whether a larger window of `sigma` pixels is fitted on the pooled grid at block size `block`.
pub fn pooled(sigma: f32, block: usize) -> bool {
    sigma >= POOL_MIN_SIGMA * block as f32
}

/// Block-grid row (or column) `i` lies at `i/2 − 1/4` on a pooled grid of `n`
/// rows (cell centres): its two pooled neighbours with weights ¼ and ¾ (the
/// weights sum to 1; at the border one neighbour with weight 1, the other 0).
pub fn pooled_taps(i: usize, n: usize) -> [(usize, f64); 2] {
    let c = (i / 2).min(n.saturating_sub(1));
    if i.is_multiple_of(2) {
        if c == 0 {
            [(0, 1.0), (0, 0.0)]
        } else {
            [(c - 1, 0.25), (c, 0.75)]
        }
    } else if c + 1 >= n {
        [(c, 1.0), (c, 0.0)]
    } else {
        [(c, 0.75), (c + 1, 0.25)]
    }
}

/// Most candidates a cell's blend weighs: the three windows and the AO-free
/// fit of window 0 ([`crate::FlrConfig::adaptive_without_ao`]).
pub const MAX_CANDIDATES: usize = 4;

/// Luminance weights in f64.
const L: [f64; 3] = [LUMA[0] as f64, LUMA[1] as f64, LUMA[2] as f64];

/// Estimated variance `v_s` of the prediction of `model` at a cell whose
/// blurred moments are `cell`: `r · coefficients / N` for a model fitted with
/// `coefficients` coefficients (`Q + 1`; `Q` for the AO-free fit, whose
/// coefficients on AO are 0); `norm` turns the window weight into its valid
/// fraction, `area` is `4πσ²` in input pixels. `+∞` for an empty window.
pub fn variance<const Q: usize>(cell: &[f64], model: &[f32], coefficients: usize, norm: f64, area: f64, min_weight: f64) -> f64 {
    let [v] = variance_lanes::<f64, Q, 1>(|m| cell[m], |_, j| model[j] as f64, [coefficients], norm, area, min_weight);
    v
}

/// [`variance`] of four cells at once, one per `f64x4` lane (`cells`: 4 ×
/// `k` moments), for `F` models of each cell (`models[l][f]`, with
/// `coefficients[f]`) from one pass over the moments: `[f][l]` is
/// bit-identical to `variance(cell l, models[l][f], coefficients[f], …)`.
pub fn variances4<const Q: usize, const F: usize>(
    cells: &[f64],
    models: [[&[f32]; F]; 4],
    coefficients: [usize; F],
    norm: f64,
    area: f64,
    min_weight: f64,
) -> [[f64; 4]; F] {
    variances4_on::<Q, F>(Isa::detect(), cells, models, coefficients, norm, area, min_weight)
}

/// [`variances4`] on the given instruction set (AVX2's lanes where
/// [`Isa::intrinsics`], otherwise `wide`'s; the same bits).
pub fn variances4_on<const Q: usize, const F: usize>(
    isa: Isa,
    cells: &[f64],
    models: [[&[f32]; F]; 4],
    coefficients: [usize; F],
    norm: f64,
    area: f64,
    min_weight: f64,
) -> [[f64; 4]; F] {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 (`Isa::intrinsics`).
        return unsafe { avx2::variances4::<Q, F>(cells, models, coefficients, norm, area, min_weight) };
    }
    let _ = isa;
    variances4_in::<f64x4, Q, F>(cells, models, coefficients, norm, area, min_weight)
}

/// [`variances4`] in `wide`'s lanes.
fn variances4_in<T: Lanes4, const Q: usize, const F: usize>(
    cells: &[f64],
    models: [[&[f32]; F]; 4],
    coefficients: [usize; F],
    norm: f64,
    area: f64,
    min_weight: f64,
) -> [[f64; 4]; F] {
    let k = CellLayout::new(Q).k;
    let lanes = model_lanes::<Q, F>(&models);
    let cell = |m: usize| quad::<T>(cells, k, m);
    to_arrays(variance_lanes::<T, Q, F>(cell, |f, j| T::from_f32(lanes[f][j]), coefficients, norm, area, min_weight))
}

/// The lanes of each of `v`.
#[inline(always)]
fn to_arrays<T: Lanes4, const F: usize>(v: [T; F]) -> [[f64; 4]; F] {
    let mut out = [[0f64; 4]; F];
    for f in 0..F {
        out[f] = v[f].to_array();
    }
    out
}

/// Each of the `F` models' values of the four cells, lane-major ([`transpose_values`]).
#[inline(always)]
fn model_lanes<const Q: usize, const F: usize>(models: &[[&[f32]; F]; 4]) -> [[[f32; 4]; GAP_VALUES]; F] {
    let mut lanes = [[[0f32; 4]; GAP_VALUES]; F];
    for (f, lanes) in lanes.iter_mut().enumerate() {
        transpose_values::<Q>([models[0][f], models[1][f], models[2][f], models[3][f]], lanes);
    }
    lanes
}

/// [`variance`] of one cell (`T = f64`) or four (`f64x4`) for `F` models at
/// once (sharing the moments' terms); `cell(m)` reads moment `m`, `model(f,
/// j)` value `j` of model `f`. Empty lanes and non-finite results are `+∞`.
#[inline(always)]
fn variance_lanes<T: F64Lanes, const Q: usize, const F: usize>(
    cell: impl Fn(usize) -> T,
    model: impl Fn(usize, usize) -> T,
    coefficients: [usize; F],
    norm: f64,
    area: f64,
    min_weight: f64,
) -> [T; F] {
    let lay = CellLayout::new(Q);
    let s = T::splat;
    let n = cell(0);
    let empty = n.not_above(s(min_weight));
    let inv = s(1.0) / n;
    let mean = luma(&cell, lay.t, inv);
    let mut explained = [s(0.0); F];
    for a in 0..Q {
        let cov = luma(&cell, lay.p + 3 * a, inv) - cell(lay.s + a) * inv * mean;
        let j = 3 + 3 * a;
        for (f, e) in explained.iter_mut().enumerate() {
            let beta = s(L[0]) * model(f, j) + s(L[1]) * model(f, j + 1) + s(L[2]) * model(f, j + 2);
            *e = *e + beta * cov;
        }
    }
    let spread = cell(lay.e) * inv - mean * mean;
    // min(n · norm, 1) as −max(−n · norm, −1) (exact; NaN → 1)
    let valid = s(0.0) - (s(0.0) - n * s(norm)).max_(s(-1.0));
    let samples = (s(area) * valid).max_(s(1.0));
    let mut out = [s(0.0); F];
    for f in 0..F {
        let residual = (spread - explained[f]).max_(s(0.0));
        let v = residual * s(coefficients[f] as f64) / samples;
        // v ≥ 0 where finite: "not above −1" means not finite
        out[f] = v.set_where(empty | v.not_above(s(-1.0)), f64::INFINITY);
    }
    out
}

/// The luminance of moments `at..at + 3`, times `inv`. A function, not a
/// closure: called Q + 1 times, the closure was not inlined (1.3 % of a 1080p
/// frame's samples in its own frame, each `f64x4` passed through memory).
#[inline(always)]
fn luma<T: F64Lanes>(cell: &impl Fn(usize) -> T, at: usize, inv: T) -> T {
    let s = T::splat;
    (s(L[0]) * cell(at) + s(L[1]) * cell(at + 1) + s(L[2]) * cell(at + 2)) * inv
}

/// `d_s²` for candidates `1..N` (windows 1 and 2, then the AO-free fit of
/// window 0 when there is one): the mean squared difference between the
/// luminance predictions of `models[s]` and `models[0]` (the smallest
/// window's) over the smallest window, whose blurred moments are `cell`:
/// `(Δc₀ + Δcᵀμ)² + Δcᵀ Σ Δc`. `gaps[0]` is 0.
pub fn prediction_gaps<const Q: usize, const N: usize>(cell: &[f64], models: [&[f32]; N], min_weight: f64) -> [f64; N] {
    gaps_lanes::<f64, Q, N>(|m| cell[m], |w, j| models[w][j] as f64, min_weight)
}

/// [`prediction_gaps`] of one cell (`T = f64`) or four (`f64x4`); `cell(m)`
/// reads moment `m`, `model(w, j)` value `j` of window `w`'s model. Empty
/// lanes get 0, non-finite gaps `+∞`.
#[inline(always)]
fn gaps_lanes<T: F64Lanes, const Q: usize, const N: usize>(
    cell: impl Fn(usize) -> T,
    model: impl Fn(usize, usize) -> T,
    min_weight: f64,
) -> [T; N] {
    let lay = CellLayout::new(Q);
    let s = T::splat;
    let n = cell(0);
    let empty = n.not_above(s(min_weight));
    let inv = s(1.0) / n;
    let mut mu = [s(0.0); crate::MAX_GUIDES];
    for (a, m) in mu.iter_mut().enumerate().take(Q) {
        *m = cell(lay.s + a) * inv;
    }
    // Candidates 1..N side by side (independent chains; the sums are the
    // same, in the same order, as one candidate at a time). Slot `w` is
    // candidate `w + 1`; slots past `N − 1` stay unused.
    let mut at_mean = [s(0.0); MAX_CANDIDATES - 1];
    for (w, a) in at_mean.iter_mut().enumerate().take(N - 1) {
        *a = luma_gap(&model, w + 1, 0);
    }
    let mut dc = [[s(0.0); crate::MAX_GUIDES]; MAX_CANDIDATES - 1];
    for a in 0..Q {
        for w in 0..N - 1 {
            dc[w][a] = luma_gap(&model, w + 1, 3 + 3 * a);
            at_mean[w] = at_mean[w] + dc[w][a] * mu[a];
        }
    }
    // Δcᵀ Σ Δc with Σ (packed upper triangle) formed on the fly.
    let mut spread = [s(0.0); MAX_CANDIDATES - 1];
    let mut p = 0;
    for a in 0..Q {
        for b in a..Q {
            let cov = cell(lay.ss + p) * inv - mu[a] * mu[b];
            for w in 0..N - 1 {
                let term = if a == b { dc[w][a] * dc[w][a] * cov } else { s(2.0) * dc[w][a] * dc[w][b] * cov };
                spread[w] = spread[w] + term;
            }
            p += 1;
        }
    }
    let mut gaps = [s(0.0); N];
    for w in 0..N - 1 {
        let d2 = at_mean[w] * at_mean[w] + spread[w].max_(s(0.0));
        // d2 ≥ 0 where finite
        gaps[w + 1] = d2.set_where(d2.not_above(s(-1.0)), f64::INFINITY).set_where(empty, 0.0);
    }
    gaps
}

/// The luminance of the difference between window `w`'s and window 0's
/// coefficient triple `j..j + 3`: `0 + L₀Δ₀ + L₁Δ₁ + L₂Δ₂`, in that order.
/// (Functions rather than closures: the compiler had left a closure as a
/// call per coefficient, and a closure made here would not compile with the
/// AVX2 entries' features.)
#[inline(always)]
fn luma_gap<T: F64Lanes>(model: &impl Fn(usize, usize) -> T, w: usize, j: usize) -> T {
    T::splat(0.0) + gap_term(model, w, j, 0) + gap_term(model, w, j, 1) + gap_term(model, w, j, 2)
}

/// `L_c · (model(w, j + c) − model(0, j + c))`.
#[inline(always)]
fn gap_term<T: F64Lanes>(model: &impl Fn(usize, usize) -> T, w: usize, j: usize, c: usize) -> T {
    T::splat(L[c]) * (model(w, j + c) - model(0, j + c))
}

/// The blend weights `1 / (b_s² + v_s)` of the `N` candidates from their
/// `variances` and `gaps` (`gaps[0]` unused), divided by their sum; lanes
/// whose sum is not positive and finite are flagged in the returned mask
/// (bit `l`: use the middle window's model).
#[inline(always)]
fn weights_lanes<T: F64Lanes, const N: usize>(variances: [T; N], gaps: [T; N]) -> ([T; N], u32) {
    let s = T::splat;
    let mut w = [s(0.0); N];
    for i in 0..N {
        let mse = if i == 0 {
            variances[0]
        } else {
            let seen = (variances[0] - variances[i]).max_(s(0.0));
            // seen ≥ 0 where finite; an infinite one (no variance to discount) counts no bias
            let bias = (gaps[i] - s(BIAS_DISCOUNT) * seen).max_(s(0.0)).set_where(seen.not_above(s(-1.0)), 0.0);
            bias + variances[i]
        };
        w[i] = (s(1.0) / mse.max_(s(1e-300))).set_where(mse.not_above(s(-1.0)), 0.0);
    }
    let mut total = w[0];
    for x in &w[1..] {
        total = total + *x;
    }
    let fallback = total.not_above(s(0.0));
    for x in w.iter_mut() {
        *x = *x / total;
    }
    (w, fallback)
}

/// Blends the `N` candidates' models of one cell (the three windows, then
/// the AO-free fit of window 0 when there is one) into `out`: weights
/// `1 / (b_s² + v_s)` from `variances` and the gaps `gaps[s]` (`gaps[0]` unused).
/// Falls back to the middle window's model where no weight is usable.
pub fn blend<const N: usize>(models: [&[f32]; N], variances: [f64; N], gaps: [f64; N], out: &mut [f32]) {
    let (w, fallback) = weights_lanes::<f64, N>(variances, gaps);
    blend_with(models, (fallback == 0).then_some(w), out);
}

/// Blends the candidates' models of one cell with the normalised weights `w`
/// (`None`: the middle window's model).
#[inline(always)]
fn blend_with<const N: usize>(models: [&[f32]; N], w: Option<[f64; N]>, out: &mut [f32]) {
    let Some(w) = w else {
        out.copy_from_slice(models[1]);
        return;
    };
    match N {
        // zipped (no bounds checks), so it vectorises
        3 => {
            for (((o, a), b), c) in out.iter_mut().zip(models[0]).zip(models[1]).zip(models[2]) {
                *o = (w[0] * *a as f64 + w[1] * *b as f64 + w[2] * *c as f64) as f32;
            }
        }
        4 => {
            let pairs = models[0].iter().zip(models[1]).zip(models[2].iter().zip(models[3]));
            for (o, ((a, b), (c, d))) in out.iter_mut().zip(pairs) {
                *o = (w[0] * *a as f64 + w[1] * *b as f64 + w[2] * *c as f64 + w[3] * *d as f64) as f32;
            }
        }
        _ => {
            for (j, o) in out.iter_mut().enumerate() {
                let mut v = w[0] * models[0][j] as f64;
                for i in 1..N {
                    v += w[i] * models[i][j] as f64;
                }
                *o = v as f32;
            }
        }
    }
}

/// Model values the prediction gaps read: the constant and guide coefficient
/// triples of the largest guide count, rounded up to whole 4-lane groups.
const GAP_VALUES: usize = (3 * (crate::MAX_GUIDES + 1)).div_ceil(4) * 4;

/// Working space of [`blend4`]: four cells' models lane-major, `[candidate][value][cell]`,
/// so that one value of the four cells is one `f64x4` conversion. Make one
/// and reuse it for every group of four cells.
#[derive(Clone, Debug)]
pub struct ModelLanes([[[f32; 4]; GAP_VALUES]; MAX_CANDIDATES]);

impl Default for ModelLanes {
    fn default() -> Self {
        ModelLanes([[[0.0; 4]; GAP_VALUES]; MAX_CANDIDATES])
    }
}

impl ModelLanes {
    /// The `N` candidates' [`transpose_values`].
    #[inline(always)]
    fn fill<const Q: usize, const N: usize>(&mut self, models: &[[&[f32]; N]; 4]) {
        for (w, lanes) in self.0.iter_mut().enumerate().take(N) {
            transpose_values::<Q>(models.map(|m| m[w]), lanes);
        }
    }
}

/// Transposes values `0..3(Q + 1)` (the constant and guide coefficients) of
/// four cells' models, 4 × 4 at a time, into `lanes[value][cell]`. (Read one
/// lane at a time from model-major storage, each of the ~50 model reads of
/// the gaps, or ~20 of a variance, would be 4 scalar loads, conversions and
/// inserts.)
#[inline(always)]
fn transpose_values<const Q: usize>(models: [&[f32]; 4], lanes: &mut [[f32; 4]; GAP_VALUES]) {
    // a model holds 3(Q + 1) + 3 values, so the 4-wide reads at j < 3(Q + 1) stay inside
    for j in (0..3 * (Q + 1)).step_by(4) {
        let rows: [f32x4; 4] = core::array::from_fn(|l| {
            let m = &models[l][j..j + 4];
            f32x4::from([m[0], m[1], m[2], m[3]])
        });
        for (c, v) in f32x4::transpose(rows).iter().enumerate() {
            lanes[j + c] = v.to_array();
        }
    }
}

/// [`prediction_gaps`] and [`blend`] of four cells at once, one per `f64x4`
/// lane: `cells` holds 4 × `k` moments, `models[l]` cell `l`'s `N` candidate
/// models, `variances[w]` candidate `w`'s four variances, `out` 4 ×
/// `model_len(Q)` values; `lanes` is working space. Bit-identical to four
/// scalar calls.
pub fn blend4<const Q: usize, const N: usize>(
    cells: &[f64],
    models: [[&[f32]; N]; 4],
    variances: [[f64; 4]; N],
    min_weight: f64,
    lanes: &mut ModelLanes,
    out: &mut [f32],
) {
    blend4_on::<Q, N>(Isa::detect(), cells, models, variances, min_weight, lanes, out)
}

/// [`blend4`] on the given instruction set (AVX2's lanes where
/// [`Isa::intrinsics`], otherwise `wide`'s; the same bits).
pub fn blend4_on<const Q: usize, const N: usize>(
    isa: Isa,
    cells: &[f64],
    models: [[&[f32]; N]; 4],
    variances: [[f64; 4]; N],
    min_weight: f64,
    lanes: &mut ModelLanes,
    out: &mut [f32],
) {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 (`Isa::intrinsics`).
        return unsafe { avx2::blend4::<Q, N>(cells, models, variances, min_weight, lanes, out) };
    }
    let _ = isa;
    blend4_in::<f64x4, Q, N>(cells, models, variances, min_weight, lanes, out)
}

/// [`blend4`] in `wide`'s lanes.
fn blend4_in<T: Lanes4, const Q: usize, const N: usize>(
    cells: &[f64],
    models: [[&[f32]; N]; 4],
    variances: [[f64; 4]; N],
    min_weight: f64,
    lanes: &mut ModelLanes,
    out: &mut [f32],
) {
    let k = CellLayout::new(Q).k;
    lanes.fill::<Q, N>(&models);
    let cell = |m: usize| quad::<T>(cells, k, m);
    let gaps = gaps_lanes::<T, Q, N>(cell, |w, j| T::from_f32(lanes.0[w][j]), min_weight);
    blend_weighted::<T, Q, N>(&models, variances, gaps, out);
}

/// The end of [`blend4`]: the candidates' weights from their variances and
/// gaps, and the four blended models. (Loops, not closures: this is inlined
/// into the AVX2 entries, and a closure would compile without their features.)
#[inline(always)]
fn blend_weighted<T: Lanes4, const Q: usize, const N: usize>(
    models: &[[&[f32]; N]; 4],
    variances: [[f64; 4]; N],
    gaps: [T; N],
    out: &mut [f32],
) {
    let mut v = [T::splat(0.0); N];
    for i in 0..N {
        v[i] = T::from_array(variances[i]);
    }
    let (w, fallback) = weights_lanes::<T, N>(v, gaps);
    let mut wa = [[0f64; 4]; N];
    for i in 0..N {
        wa[i] = w[i].to_array();
    }
    for (l, o) in out.chunks_exact_mut(model_len(Q)).take(4).enumerate() {
        let mut wl = [0f64; N];
        for i in 0..N {
            wl[i] = wa[i][l];
        }
        blend_with(models[l], (fallback >> l & 1 == 0).then_some(wl), o);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (no dependency in the core's tests).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64) / (1u64 << 53) as f64
        }
    }

    /// Four cells' moments and the models of the most candidates each, with
    /// the awkward lanes of real frames: an empty cell, a non-finite moment, a
    /// huge model value, negative energy (a residual clamped to 0).
    type Case = ([f64; 4 * K], [[[f32; ML]; MAX_CANDIDATES]; 4], [[f64; 4]; MAX_CANDIDATES]);
    /// Room for Q ≤ 12.
    const K: usize = CellLayout::new(crate::MAX_GUIDES).k;
    const ML: usize = model_len(crate::MAX_GUIDES);

    fn cases<const Q: usize>(seed: u64) -> Case {
        let k = CellLayout::new(Q).k;
        let mut r = Lcg(seed);
        let mut cells = [0f64; 4 * K];
        for (i, c) in cells[..4 * k].iter_mut().enumerate() {
            *c = if i % k == 0 { 1.0 + 100.0 * r.next() } else { 20.0 * r.next() - 5.0 };
        }
        let mut models = [[[0f32; ML]; MAX_CANDIDATES]; 4];
        for m in models.iter_mut().flatten() {
            for v in m.iter_mut() {
                *v = (4.0 * r.next() - 2.0) as f32;
            }
        }
        let mut var = [[0f64; 4]; MAX_CANDIDATES];
        for v in var.iter_mut().flatten() {
            *v = r.next() * 0.1;
        }
        match seed % 4 {
            0 => cells[k] = 0.0, // lane 1 empty
            1 => {
                // lane 2: a NaN moment; every window's variance infinite (the middle model)
                cells[2 * k + 3] = f64::NAN;
                for v in var.iter_mut() {
                    v[2] = f64::INFINITY;
                }
            }
            2 => models[3][2][4] = 3e38,    // lane 3: a huge slope
            _ => var[1][0] = f64::INFINITY, // lane 0: an empty larger window
        }
        (cells, models, var)
    }

    /// Every guide count the lanes' transposes see: 0 (a partial 4 × 4
    /// group only), 1, 2, 5 (the defaults), 7 and 12 (the most); three
    /// candidates (the windows) and four (with the AO-free fit).
    #[test]
    fn four_lanes_equal_four_cells() {
        check::<0, 3>();
        check::<1, 3>();
        check::<2, 3>();
        check::<5, 3>();
        check::<7, 3>();
        check::<12, 3>();
        check::<1, 4>();
        check::<5, 4>();
        check::<12, 4>();
    }

    fn check<const Q: usize, const N: usize>() {
        let (k, ml) = (CellLayout::new(Q).k, model_len(Q));
        let mut lanes = ModelLanes::default();
        // the portable lanes, and AVX2's where the CPU has them
        let isas = [Isa::Portable, Isa::detect()];
        for (seed, isa) in (0..128).map(|i| (i / 2, isas[i as usize % 2])) {
            let (cells, models, var) = cases::<Q>(seed);
            let flat: [f32; 4 * ML] = core::array::from_fn(|i| models[(i / ml) % 4][0][i % ml]);
            // one model per cell, and two (the second as the AO-free fit's, one coefficient fewer)
            let each: [[&[f32]; 1]; 4] = core::array::from_fn(|l| [&flat[l * ml..(l + 1) * ml]]);
            let [got] = variances4_on::<Q, 1>(isa, &cells, each, [Q + 1], 0.01, 1800.0, 1e-9);
            let pairs: [[&[f32]; 2]; 4] = core::array::from_fn(|l| [&models[l][0][..ml], &models[l][1][..ml]]);
            let two = variances4_on::<Q, 2>(isa, &cells, pairs, [Q + 1, Q], 0.01, 1800.0, 1e-9);
            for l in 0..4 {
                let cell = &cells[l * k..(l + 1) * k];
                let want = variance::<Q>(cell, each[l][0], Q + 1, 0.01, 1800.0, 1e-9);
                assert_eq!(got[l].to_bits(), want.to_bits(), "{isa:?} Q {Q} seed {seed} lane {l}");
                for f in 0..2 {
                    let want = variance::<Q>(cell, pairs[l][f], Q + 1 - f, 0.01, 1800.0, 1e-9);
                    assert_eq!(two[f][l].to_bits(), want.to_bits(), "{isa:?} Q {Q} seed {seed} lane {l} fit {f}");
                }
            }
            let m: [[&[f32]; N]; 4] = core::array::from_fn(|l| core::array::from_fn(|w| &models[l][w][..ml]));
            let var: [[f64; 4]; N] = core::array::from_fn(|w| var[w]);
            let mut out = [0f32; 4 * ML];
            // (`lanes` reused from the previous seed, as `Flr` does)
            blend4_on::<Q, N>(isa, &cells, m, var, 1e-9, &mut lanes, &mut out[..4 * ml]);
            for l in 0..4 {
                let cell = &cells[l * k..(l + 1) * k];
                let gaps = prediction_gaps::<Q, N>(cell, m[l], 1e-9);
                let mut want = [0f32; ML];
                blend::<N>(m[l], core::array::from_fn(|w| var[w][l]), gaps, &mut want[..ml]);
                for (a, b) in out[l * ml..(l + 1) * ml].iter().zip(&want[..ml]) {
                    assert_eq!(a.to_bits(), b.to_bits(), "{isa:?} Q {Q} N {N} seed {seed} lane {l}");
                }
            }
        }
    }
}
