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
//! over σ = 12 alone; the prototype (`tools/flr_scales_proto.py`) found the
//! same per pixel. Estimating `r_s` needs the energy moment, so this mode
//! costs three blurs and three solves instead of one.

use crate::kernels::{CellLayout, LUMA};

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
    if i % 2 == 0 {
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

/// Luminance weights in f64.
const L: [f64; 3] = [LUMA[0] as f64, LUMA[1] as f64, LUMA[2] as f64];

/// Estimated variance `v_s` of the prediction of `model` at a cell whose
/// blurred moments are `cell`; `norm` turns the window weight into its valid
/// fraction, `area` is `4πσ²` in input pixels. `+∞` for an empty window.
pub fn variance<const Q: usize>(cell: &[f64], model: &[f32], norm: f64, area: f64, min_weight: f64) -> f64 {
    let lay = CellLayout::new(Q);
    let n = cell[0];
    if !(n > min_weight && n.is_finite()) {
        return f64::INFINITY;
    }
    let inv = 1.0 / n;
    let luma = |at: usize| (L[0] * cell[at] + L[1] * cell[at + 1] + L[2] * cell[at + 2]) * inv;
    let mean = luma(lay.t);
    let mut explained = 0.0;
    for a in 0..Q {
        let cov = luma(lay.p + 3 * a) - cell[lay.s + a] * inv * mean;
        let j = 3 + 3 * a;
        let beta = L[0] * model[j] as f64 + L[1] * model[j + 1] as f64 + L[2] * model[j + 2] as f64;
        explained += beta * cov;
    }
    let residual = (cell[lay.e] * inv - mean * mean - explained).max(0.0);
    let samples = (area * (n * norm).min(1.0)).max(1.0);
    let v = residual * (Q + 1) as f64 / samples;
    if v.is_finite() {
        v
    } else {
        f64::INFINITY
    }
}

/// `d_s²` for windows 1 and 2: the mean squared difference between the
/// luminance predictions of `models[s]` and `models[0]` (the smallest
/// window's) over the smallest window, whose blurred moments are `cell`:
/// `(Δc₀ + Δcᵀμ)² + Δcᵀ Σ Δc`. `gaps[0]` is 0.
pub fn prediction_gaps<const Q: usize>(cell: &[f64], models: [&[f32]; 3], min_weight: f64) -> [f64; 3] {
    let lay = CellLayout::new(Q);
    let n = cell[0];
    if !(n > min_weight && n.is_finite()) {
        return [0.0; 3];
    }
    let inv = 1.0 / n;
    let mut mu = [0f64; crate::MAX_GUIDES];
    for a in 0..Q {
        mu[a] = cell[lay.s + a] * inv;
    }
    // Windows 1 and 2 side by side (two independent chains; the sums are
    // the same, in the same order, as one window at a time).
    let first = models[0];
    let dl = |model: &[f32], j: usize| {
        let d = |c: usize| L[c] * (model[j + c] as f64 - first[j + c] as f64);
        0.0 + d(0) + d(1) + d(2)
    };
    let mut at_mean = [dl(models[1], 0), dl(models[2], 0)];
    let mut dc = [[0f64; crate::MAX_GUIDES]; 2];
    for a in 0..Q {
        for w in 0..2 {
            dc[w][a] = dl(models[w + 1], 3 + 3 * a);
            at_mean[w] += dc[w][a] * mu[a];
        }
    }
    // Δcᵀ Σ Δc with Σ (packed upper triangle) formed on the fly.
    let mut spread = [0f64; 2];
    let mut p = 0;
    for a in 0..Q {
        for b in a..Q {
            let cov = cell[lay.ss + p] * inv - mu[a] * mu[b];
            for w in 0..2 {
                spread[w] += if a == b { dc[w][a] * dc[w][a] * cov } else { 2.0 * dc[w][a] * dc[w][b] * cov };
            }
            p += 1;
        }
    }
    let mut gaps = [0f64; 3];
    for w in 0..2 {
        let d2 = at_mean[w] * at_mean[w] + spread[w].max(0.0);
        gaps[w + 1] = if d2.is_finite() { d2 } else { f64::INFINITY };
    }
    gaps
}

/// Blends the three windows' models of one cell into `out`: weights
/// `1 / (b_s² + v_s)` from `variances` and the gaps `gaps[s]` (`gaps[0]` unused).
/// Falls back to the middle window's model where no weight is usable.
pub fn blend(models: [&[f32]; 3], variances: [f64; 3], gaps: [f64; 3], out: &mut [f32]) {
    let mut w = [0f64; 3];
    for s in 0..3 {
        let mse = if s == 0 {
            variances[0]
        } else {
            let seen = (variances[0] - variances[s]).max(0.0);
            let bias = if seen.is_finite() { (gaps[s] - BIAS_DISCOUNT * seen).max(0.0) } else { 0.0 };
            bias + variances[s]
        };
        w[s] = if mse.is_finite() { 1.0 / mse.max(1e-300) } else { 0.0 };
    }
    let total = w[0] + w[1] + w[2];
    if !(total > 0.0 && total.is_finite()) {
        out.copy_from_slice(models[1]);
        return;
    }
    // zipped (no bounds checks), so it vectorises
    for (((o, a), b), c) in out.iter_mut().zip(models[0]).zip(models[1]).zip(models[2]) {
        *o = ((w[0] * *a as f64 + w[1] * *b as f64 + w[2] * *c as f64) / total) as f32;
    }
}
