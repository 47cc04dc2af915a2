//! AVX2 lanes of the adaptive window's four-cell kernels
//! ([`super::variances4`], [`super::blend4`]), for builds whose `wide` is
//! SSE2 (where an `f64x4` is two SSE2 halves): the same generic code
//! instantiated on `F64x4` (`kernels::f64x4_avx2`) inside `#[target_feature]`
//! functions chosen at run time by [`crate::isa::Isa`]. The lanes do the IEEE
//! operation per lane, so the bits equal the portable lanes'; `adaptive::tests`
//! checks both.

use super::ModelLanes;
use crate::kernels::cholesky::{quad, Lanes4};
use crate::kernels::f64x4_avx2::avx2_f64x4;
use crate::kernels::CellLayout;

avx2_f64x4!();

/// [`super::variances4`] in AVX2 lanes.
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn variances4<const Q: usize, const F: usize>(
    cells: &[f64],
    models: [[&[f32]; F]; 4],
    coefficients: [usize; F],
    norm: f64,
    area: f64,
    min_weight: f64,
) -> [[f64; 4]; F] {
    // (the closures are made here, so that they compile with AVX2 enabled)
    let k = CellLayout::new(Q).k;
    let lanes = super::model_lanes::<Q, F>(&models);
    let cell = |m: usize| quad::<F64x4>(cells, k, m);
    let model = |f: usize, j: usize| F64x4::from_f32(lanes[f][j]);
    super::to_arrays(super::variance_lanes::<F64x4, Q, F>(cell, model, coefficients, norm, area, min_weight))
}

/// [`super::blend4`] in AVX2 lanes.
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn blend4<const Q: usize, const N: usize>(
    cells: &[f64],
    models: [[&[f32]; N]; 4],
    variances: [[f64; 4]; N],
    min_weight: f64,
    lanes: &mut ModelLanes,
    out: &mut [f32],
) {
    // (the closures are made here, so that they compile with AVX2 enabled)
    let k = CellLayout::new(Q).k;
    lanes.fill::<Q, N>(&models);
    let cell = |m: usize| quad::<F64x4>(cells, k, m);
    let model = |w: usize, j: usize| F64x4::from_f32(lanes.0[w][j]);
    let gaps = super::gaps_lanes::<F64x4, Q, N>(cell, model, min_weight);
    super::blend_weighted::<F64x4, Q, N>(&models, variances, gaps, out)
}
