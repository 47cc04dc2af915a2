//! AVX2 version of the four-cell normalized solve ([`super::solve_cells4`]),
//! for builds whose `wide` is SSE2 (where an `f64x4` is two SSE2 halves):
//! the generic solve `super::normalized` instantiated on `F64x4`, a private
//! `__m256d` lane type (`kernels::f64x4_avx2`), inside a `#[target_feature]` function chosen at run
//! time by [`crate::isa::Isa`]. [`F64Lanes`](crate::kernels::cholesky::F64Lanes) promises IEEE operations per
//! lane (no fused multiply-adds), so the result is bit-identical to the
//! portable lanes and to the scalar path; `solve::tests` checks it.

use super::{Fit, SolveParams, Solved};
use crate::kernels::cholesky::quad;
use crate::kernels::f64x4_avx2::avx2_f64x4;
use crate::kernels::CellLayout;
use wide::f64x4;

avx2_f64x4!();

/// `super::normalized` on four cells (`cells`: 4 × `k` moments), one per
/// AVX lane; the results as `wide` lanes for [`super::write_models4`].
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn normalized4<const Q: usize>(cells: &[f64], p: &SolveParams, eps_mul: f64, eps_add: f64) -> (Fit<f64x4, Q>, [u32; 4]) {
    let (full, dropped, _) =
        super::normalized::<F64x4, Q, false>(|m| quad::<F64x4>(cells, CellLayout::new(Q).k, m), p, eps_mul, eps_add, 0);
    (full.map(wide), dropped)
}

/// [`normalized4`] with the fit without guide `drop` too (a function of its
/// own, so that [`normalized4`] returns no second fit it would not use).
///
/// # Safety
/// The CPU must support AVX2 ([`crate::isa::Isa::Avx2Fma`] available).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn normalized4_without<const Q: usize>(
    cells: &[f64],
    p: &SolveParams,
    eps_mul: f64,
    eps_add: f64,
    drop: usize,
) -> Solved<f64x4, Q> {
    let (full, dropped, sub) =
        super::normalized::<F64x4, Q, true>(|m| quad::<F64x4>(cells, CellLayout::new(Q).k, m), p, eps_mul, eps_add, drop);
    (full.map(wide), dropped, sub.map(wide))
}

/// `wide` lanes of the same four values (`f64x4` and `__m256d` are both 32
/// plain bytes: bytemuck checks it).
#[inline(always)]
fn wide(v: F64x4) -> f64x4 {
    bytemuck::cast(v.0)
}
