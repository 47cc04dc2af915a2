//! Kernel 3: the per-cell solve. Blurred moments → affine model.
//!
//! * Normalized (default): the normalized-correlation regularized inverse,
//!   appendix eqs. 12–23, on per-frame standardised guides.
//! * Tikhonov: eq. 11 on the guides exactly as given.
//!
//! Model layout (f32, [`super::model_len`]): intercept `c0[3]`, coefficients
//! `c[q][3]` applied to `d = g − m` (guide minus frame reference), and the
//! local mean `μ_y[3]` (used where a pixel's guides are not finite).

#[cfg(target_arch = "x86_64")]
mod avx2;

use super::cholesky::{self, F64Lanes};
use super::CellLayout;
use crate::guides::MAX_GUIDES;
use crate::isa::Isa;
use wide::f64x4;

/// How the per-cell normal equations are regularised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Regularization {
    /// The normalized-correlation regularized inverse (appendix eqs. 12–23):
    /// `eps_mul` is ε (multiplicative, eq. 18), `eps_add` is ϵ (additive,
    /// eqs. 18 and 22). Guides are standardised per frame first, so the result
    /// does not depend on the world origin or the units of any guide.
    Normalized {
        /// ε, multiplicative (eq. 18).
        eps_mul: f64,
        /// ϵ, additive (eqs. 18 and 22).
        eps_add: f64,
    },
    /// Textbook Tikhonov (eq. 11): `(XᵀWX + ε I)⁻¹ XᵀWY` on the guides exactly
    /// as given, weights normalised to sum 1.
    Tikhonov {
        /// ε, added to the diagonal.
        eps: f64,
    },
}

const N1: usize = MAX_GUIDES + 1;

/// Per-frame constants of the solve.
#[derive(Clone, Copy, Debug)]
pub struct SolveParams {
    /// Frame reference `m` (absolute guide values; moments are relative to it).
    pub reference: [f64; MAX_GUIDES],
    /// Frame mean of each guide, relative to `m`.
    pub mean: [f64; MAX_GUIDES],
    /// Frame standard deviation of each guide (≥ a tiny floor, 1 for constants).
    pub scale: [f64; MAX_GUIDES],
    /// The regulariser.
    pub regularization: Regularization,
    /// 1 / (total window weight): turns sums into weighted averages (Tikhonov).
    pub weight_norm: f64,
    /// A cell whose window weight is at most this is empty (no valid pixel).
    pub min_weight: f64,
}

/// Outcome of one cell's solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CellOutcome {
    /// The cell is empty (window weight at most `min_weight`); its model is 0.
    pub empty: bool,
    /// Variables dropped by the pivot floor.
    pub dropped: u32,
}

/// Solves one cell. `cell` has `CellLayout::new(Q).k` values, `model` has `model_len(Q)`.
pub fn solve_cell<const Q: usize>(cell: &[f64], p: &SolveParams, model: &mut [f32]) -> CellOutcome {
    solve_cell_at::<Q, false>(cell, p, 0, model)
}

/// [`solve_cell`] that also fits the cell without guide `drop` (< `Q`):
/// `model` holds two models of `model_len(Q)` values, the full fit and then
/// the fit without `drop`, whose coefficients on it are 0 (its `μ_y` is the
/// same). Both come from one factorization: with `drop` ordered last, the
/// system without it is the full system's leading principal block, whose
/// Cholesky factor is the leading block of the full factor (every entry of
/// the normalized and the Tikhonov systems depends only on its two guides).
/// The full model is bit-identical to [`solve_cell`]'s when `drop` is the
/// last guide; otherwise the system is factored in that order, which rounds
/// differently (and, for a singular system, may drop other pivots).
pub fn solve_cell_without<const Q: usize>(cell: &[f64], p: &SolveParams, drop: usize, model: &mut [f32]) -> CellOutcome {
    solve_cell_at::<Q, true>(cell, p, drop, model)
}

fn solve_cell_at<const Q: usize, const SUB: bool>(cell: &[f64], p: &SolveParams, drop: usize, model: &mut [f32]) -> CellOutcome {
    let lay = CellLayout::new(Q);
    let ml = super::model_len(Q);
    let model = &mut model[..if SUB { 2 * ml } else { ml }];
    if is_empty(cell[0], p) {
        model.fill(0.0);
        return CellOutcome { empty: true, dropped: 0 };
    }
    let (full, dropped, sub) = match p.regularization {
        Regularization::Normalized { eps_mul, eps_add } => {
            let (full, dropped, sub) = normalized::<f64, Q, SUB>(|m| cell[m], p, eps_mul, eps_add, drop);
            (full, dropped[0], sub)
        }
        Regularization::Tikhonov { eps } => tikhonov::<Q, SUB>(cell, &lay, p, eps, drop),
    };
    let (a, b) = model.split_at_mut(ml);
    write_model::<Q>(&full.c0, &full.coef, &full.muy, a);
    if SUB {
        write_model::<Q>(&sub.c0, &sub.coef, &sub.muy, b);
    }
    CellOutcome { empty: false, dropped }
}

/// Solves four consecutive cells (`cells` holds 4·k values, `models` 4·`model_len(Q)`)
/// with one cell per f64x4 lane: bit-identical to four [`solve_cell`] calls.
/// On x86-64 the lanes are AVX2 registers where the CPU has them
/// (`avx2::normalized4`; same result), which matters in a default build,
/// whose `f64x4` is two SSE2 halves.
pub fn solve_cells4<const Q: usize>(cells: &[f64], p: &SolveParams, models: &mut [f32]) -> [CellOutcome; 4] {
    solve_cells4_on::<Q, false>(Isa::detect(), cells, p, 0, models)
}

/// [`solve_cells4`] with each cell's fit without guide `drop` too, as in
/// [`solve_cell_without`]: `models` holds 4 × 2·`model_len(Q)` values (per
/// cell the full model, then the one without `drop`); bit-identical to four
/// [`solve_cell_without`] calls.
pub fn solve_cells4_without<const Q: usize>(cells: &[f64], p: &SolveParams, drop: usize, models: &mut [f32]) -> [CellOutcome; 4] {
    solve_cells4_on::<Q, true>(Isa::detect(), cells, p, drop, models)
}

/// [`solve_cells4`] (with `SUB`, [`solve_cells4_without`]) on the given
/// instruction set (the intrinsics file where [`Isa::intrinsics`], otherwise
/// the portable lanes).
fn solve_cells4_on<const Q: usize, const SUB: bool>(
    isa: Isa,
    cells: &[f64],
    p: &SolveParams,
    drop: usize,
    models: &mut [f32],
) -> [CellOutcome; 4] {
    let lay = CellLayout::new(Q);
    let k = lay.k;
    let stride = super::model_len(Q) * if SUB { 2 } else { 1 };
    let Regularization::Normalized { eps_mul, eps_add } = p.regularization else {
        return core::array::from_fn(|l| {
            solve_cell_at::<Q, SUB>(&cells[l * k..(l + 1) * k], p, drop, &mut models[l * stride..(l + 1) * stride])
        });
    };
    let cells = &cells[..4 * k];
    let (full, dropped, sub) = normalized4_on::<Q, SUB>(isa, cells, p, eps_mul, eps_add, drop);
    write_models4::<Q>(&full, stride, models);
    if SUB {
        write_models4::<Q>(&sub, stride, &mut models[super::model_len(Q)..]);
    }
    core::array::from_fn(|l| {
        if is_empty(cells[l * k], p) {
            models[l * stride..(l + 1) * stride].fill(0.0);
            return CellOutcome { empty: true, dropped: 0 };
        }
        CellOutcome { empty: false, dropped: dropped[l] }
    })
}

/// One fit of one cell (`T = f64`) or four (`f64x4`): the intercepts, the
/// coefficients on `d = g − m` and the local means of y.
#[derive(Clone, Copy, Debug)]
struct Fit<T, const Q: usize> {
    c0: [T; 3],
    coef: [[T; 3]; Q],
    muy: [T; 3],
}

impl<T: Copy, const Q: usize> Fit<T, Q> {
    fn map<U>(self, f: impl Fn(T) -> U + Copy) -> Fit<U, Q> {
        Fit { c0: self.c0.map(f), coef: self.coef.map(|c| c.map(f)), muy: self.muy.map(f) }
    }
}

/// What [`normalized`] returns: the fit, each lane's number of dropped
/// pivots, and (with `SUB`) the fit without the dropped guide.
type Solved<T, const Q: usize> = (Fit<T, Q>, [u32; 4], Fit<T, Q>);

/// The four cells' normalized solve in `f64` lanes (`cells`: four cell
/// layouts back to back) on the given instruction set.
#[inline(always)]
fn normalized4_on<const Q: usize, const SUB: bool>(
    isa: Isa,
    cells: &[f64],
    p: &SolveParams,
    eps_mul: f64,
    eps_add: f64,
    drop: usize,
) -> Solved<f64x4, Q> {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe {
            if SUB {
                avx2::normalized4_without::<Q>(cells, p, eps_mul, eps_add, drop)
            } else {
                let (full, dropped) = avx2::normalized4::<Q>(cells, p, eps_mul, eps_add);
                (full, dropped, full)
            }
        };
    }
    let _ = isa;
    let k = CellLayout::new(Q).k;
    let get = |m: usize| f64x4::from([cells[m], cells[k + m], cells[2 * k + m], cells[3 * k + m]]);
    normalized::<f64x4, Q, SUB>(get, p, eps_mul, eps_add, drop)
}

/// [`write_model`] for four cells at once, cell `l`'s model at `models[l *
/// stride..]`: finiteness tested in lanes, each value transposed straight
/// into its cell's model; the rare lane with a non-finite value is redone by
/// [`write_model`] (same result).
#[inline(always)]
fn write_models4<const Q: usize>(fit: &Fit<f64x4, Q>, stride: usize, models: &mut [f32]) {
    let ml = super::model_len(Q);
    // (one bounds check here instead of one per value)
    let models = &mut models[..3 * stride + ml];
    let limit = f64x4::splat(f32::MAX as f64);
    let mut ok = f64x4::splat(f64::from_bits(u64::MAX));
    let mut put = |j: usize, v: f64x4, ok: &mut f64x4| {
        *ok &= v.abs().simd_lt(limit);
        for (l, x) in v.to_array().into_iter().enumerate() {
            models[l * stride + j] = x as f32;
        }
    };
    for c in 0..3 {
        put(c, fit.c0[c], &mut ok);
        put(3 + 3 * Q + c, fit.muy[c], &mut ok);
    }
    for a in 0..Q {
        for c in 0..3 {
            put(3 + 3 * a + c, fit.coef[a][c], &mut ok);
        }
    }
    let ok = ok.to_bitmask();
    for l in 0..4 {
        if ok & (1 << l) == 0 {
            let one = fit.map(|v: f64x4| v.to_array()[l]);
            write_model::<Q>(&one.c0, &one.coef, &one.muy, &mut models[l * stride..l * stride + ml]);
        }
    }
}

#[inline(always)]
fn is_empty(n: f64, p: &SolveParams) -> bool {
    !(n > p.min_weight) || !n.is_finite()
}

/// Position of guide `a` in a system that orders guide `drop` last (the
/// others keep their order): `a` itself unless `SUB`.
#[inline(always)]
const fn moved<const Q: usize, const SUB: bool>(a: usize, drop: usize) -> usize {
    if !SUB || a < drop {
        a
    } else if a == drop {
        Q - 1
    } else {
        a - 1
    }
}

/// The normalized-correlation regularized solve (appendix eqs. 12–23) of one
/// cell (`f64`) or four (`f64x4`); `get(m)` reads moment `m`. Returns the
/// fit (intercept, coefficients on `d = g − m`, local mean of y), the number
/// of dropped pivots per lane and, with `SUB`, the fit without guide `drop`
/// from the same factor ([`solve_cell_without`]; else a copy of the fit).
#[inline(always)]
fn normalized<T: F64Lanes, const Q: usize, const SUB: bool>(
    get: impl Fn(usize) -> T,
    p: &SolveParams,
    eps_mul: f64,
    eps_add: f64,
    drop: usize,
) -> Solved<T, Q> {
    let lay = CellLayout::new(Q);
    let s = T::splat;
    let inv_n = s(1.0) / get(0);
    let muy = [get(lay.t) * inv_n, get(lay.t + 1) * inv_n, get(lay.t + 2) * inv_n];
    let mut mu = [s(0.0); Q];
    let mut muz = [s(0.0); Q];
    let mut inv_scale = [0f64; Q];
    for a in 0..Q {
        inv_scale[a] = 1.0 / p.scale[a];
    }
    for a in 0..Q {
        mu[a] = get(lay.s + a) * inv_n;
        muz[a] = (mu[a] - s(p.mean[a])) * s(inv_scale[a]);
    }
    // Ŵ (eq. 18) on standardised guides; W = S/n − μμᵀ in f64. With `SUB`,
    // guide `a` sits at row and column `moved(a)` (`drop` last).
    let at = |a: usize| moved::<Q, SUB>(a, drop);
    let mut wh = [[s(0.0); Q]; Q];
    let mut idx = lay.ss;
    for a in 0..Q {
        for b in a..Q {
            let w = (get(idx) * inv_n - mu[a] * mu[b]) * s(inv_scale[a] * inv_scale[b]);
            let mut v = w + s(eps_mul) * muz[a] * muz[b];
            if a == b {
                v = v + s(eps_mul) * muz[a] * muz[a] + s(eps_add);
            }
            wh[at(a)][at(b)] = v;
            wh[at(b)][at(a)] = v;
            idx += 1;
        }
    }
    // σ̂ (eq. 19), Ĉ + ϵI (eqs. 20, 22), B̂ (eq. 21).
    let mut isig = [s(0.0); Q];
    for a in 0..Q {
        isig[a] = s(1.0) / wh[at(a)][at(a)].max_(s(1e-300)).sqrt_();
    }
    let mut bh = [[s(0.0); 3]; Q];
    for a in 0..Q {
        for b in 0..Q {
            wh[at(a)][at(b)] = wh[at(a)][at(b)] * isig[a] * isig[b];
        }
        wh[at(a)][at(a)] = wh[at(a)][at(a)] + s(eps_add);
        for c in 0..3 {
            let cxy = get(lay.p + 3 * a + c) * inv_n - mu[a] * muy[c];
            bh[at(a)][c] = cxy * isig[a] * s(inv_scale[a]);
        }
    }
    let mut inv_diag = [s(0.0); Q];
    let dropped = cholesky::factor_n(&mut wh, 1e-12, &mut inv_diag);
    let mut sub = bh;
    cholesky::solve_n(&wh, &inv_diag, &mut bh);
    if SUB && Q > 0 {
        cholesky::solve_lead_n(&wh, &inv_diag, &mut sub, Q - 1);
        sub[Q - 1] = [s(0.0); 3];
    }
    let back = Standardised { isig, inv_scale, mu, muy, drop };
    let full = back.raw::<SUB>(&bh);
    (full, dropped, if SUB { back.raw::<SUB>(&sub) } else { full })
}

/// What [`normalized`] needs to take a solution on standardised guides back to
/// raw ones.
struct Standardised<T, const Q: usize> {
    isig: [T; Q],
    inv_scale: [f64; Q],
    mu: [T; Q],
    muy: [T; 3],
    drop: usize,
}

impl<T: F64Lanes, const Q: usize> Standardised<T, Q> {
    /// Back to raw guides (eq. 23): y = μ_y + Σ β (d − μ). A function rather
    /// than a closure: a closure called twice was not inlined into the AVX2
    /// solve's `#[target_feature]` function, so it compiled without AVX and
    /// called each `_mm256_mul_pd` as a function (~6 % of a default build's
    /// frame with the AO-free candidate, measured).
    #[inline(always)]
    fn raw<const SUB: bool>(&self, x: &[[T; 3]; Q]) -> Fit<T, Q> {
        let s = T::splat;
        let mut fit = Fit { c0: self.muy, coef: [[s(0.0); 3]; Q], muy: self.muy };
        for a in 0..Q {
            for c in 0..3 {
                let beta = x[moved::<Q, SUB>(a, self.drop)][c] * self.isig[a] * s(self.inv_scale[a]);
                fit.coef[a][c] = beta;
                fit.c0[c] = fit.c0[c] - beta * self.mu[a];
            }
        }
        fit
    }
}

/// Textbook Tikhonov (eq. 11) on the guides exactly as given: the fit, its
/// number of dropped pivots and, with `SUB`, the fit without guide `drop`
/// from the same factor (as in [`normalized`]; else a copy of the fit).
fn tikhonov<const Q: usize, const SUB: bool>(
    cell: &[f64],
    lay: &CellLayout,
    p: &SolveParams,
    eps: f64,
    drop: usize,
) -> (Fit<f64, Q>, u32, Fit<f64, Q>) {
    let n = cell[0];
    let inv_n = 1.0 / n;
    let muy = [cell[lay.t] * inv_n, cell[lay.t + 1] * inv_n, cell[lay.t + 2] * inv_n];
    let wn = p.weight_norm;
    let m = &p.reference;
    // unknowns: the intercept, then guide `a` at `1 + moved(a)` (`drop` last with `SUB`)
    let at = |a: usize| 1 + moved::<Q, SUB>(a, drop);
    let mut xx = [0f64; N1 * N1];
    let mut xy = [0f64; N1 * 3];
    xx[0] = n * wn + eps;
    let mut idx = lay.ss;
    for a in 0..Q {
        let s_a = cell[lay.s + a];
        let s_raw = s_a + n * m[a];
        xx[at(a)] = s_raw * wn;
        xx[at(a) * N1] = s_raw * wn;
        for b in a..Q {
            let s_b = cell[lay.s + b];
            let raw = cell[idx] + m[a] * s_b + s_a * m[b] + n * m[a] * m[b];
            let mut v = raw * wn;
            if a == b {
                v += eps;
            }
            xx[at(a) * N1 + at(b)] = v;
            xx[at(b) * N1 + at(a)] = v;
            idx += 1;
        }
    }
    for c in 0..3 {
        let t = cell[lay.t + c];
        xy[c] = t * wn;
        for a in 0..Q {
            xy[at(a) * 3 + c] = (cell[lay.p + 3 * a + c] + m[a] * t) * wn;
        }
    }
    let dropped = cholesky::factor(&mut xx, Q + 1, N1, 1e-15);
    let mut sub = xy;
    cholesky::solve(&xx, Q + 1, N1, &mut xy, 3);
    let raw = |x: &[f64; N1 * 3], without: Option<usize>| {
        let mut fit = Fit { c0: [0.0; 3], coef: [[0.0; 3]; Q], muy };
        for c in 0..3 {
            fit.c0[c] = x[c];
            for a in (0..Q).filter(|&a| Some(a) != without) {
                let v = x[at(a) * 3 + c];
                fit.coef[a][c] = v;
                fit.c0[c] += v * m[a];
            }
        }
        fit
    };
    let full = raw(&xy, None);
    if !SUB {
        return (full, dropped.count_ones(), full);
    }
    // the leading Q × Q block: the intercept and every guide but `drop`
    cholesky::solve(&xx, Q, N1, &mut sub, 3);
    (full, dropped.count_ones(), raw(&sub, Some(drop)))
}

fn write_model<const Q: usize>(c0: &[f64; 3], coef: &[[f64; 3]], muy: &[f64; 3], model: &mut [f32]) {
    let finite = |v: f64| v.is_finite() && v.abs() < f32::MAX as f64;
    let ok = c0.iter().chain(coef[..Q].iter().flatten()).chain(muy).all(|&v| finite(v));
    let muy_f = if muy.iter().all(|&v| finite(v)) { [muy[0] as f32, muy[1] as f32, muy[2] as f32] } else { [0.0; 3] };
    if !ok {
        // Degenerate beyond repair: fall back to the local mean.
        model.fill(0.0);
        model[..3].copy_from_slice(&muy_f);
    } else {
        for c in 0..3 {
            model[c] = c0[c] as f32;
        }
        for a in 0..Q {
            for c in 0..3 {
                model[3 + 3 * a + c] = coef[a][c] as f32;
            }
        }
    }
    model[3 + 3 * Q..3 + 3 * Q + 3].copy_from_slice(&muy_f);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Moments of `n` pixels (guides from `g(i, q)`, light from `y(i, c)`) in
    /// the cell layout, summed in f64.
    fn cell_of<const Q: usize>(n: usize, g: impl Fn(usize, usize) -> f64, y: impl Fn(usize, usize) -> f64) -> [f64; 160] {
        let lay = CellLayout::new(Q);
        let mut cell = [0f64; 160];
        for i in 0..n {
            cell[0] += 1.0;
            let mut p = lay.ss;
            for a in 0..Q {
                cell[lay.s + a] += g(i, a);
                for b in a..Q {
                    cell[p] += g(i, a) * g(i, b);
                    p += 1;
                }
                for c in 0..3 {
                    cell[lay.p + 3 * a + c] += g(i, a) * y(i, c);
                }
            }
            for c in 0..3 {
                cell[lay.t + c] += y(i, c);
            }
        }
        cell
    }

    /// The four-cell solve gives the same bits on either instruction set and
    /// as four single-cell solves, on ordinary, duplicated-guide, empty and
    /// non-finite cells.
    #[test]
    fn cells4_match_on_every_isa() {
        let mut seed = 99u32;
        let mut rnd = move || crate::hash::uniform(&mut seed);
        fn check<const Q: usize>(rnd: &mut impl FnMut() -> f64) {
            let lay = CellLayout::new(Q);
            let (k, ml) = (lay.k, crate::kernels::model_len(Q));
            let p = SolveParams {
                reference: [0.0; MAX_GUIDES],
                mean: [0.1; MAX_GUIDES],
                scale: [0.7; MAX_GUIDES],
                regularization: Regularization::Normalized { eps_mul: 1e-3, eps_add: 1e-2 },
                weight_norm: 1.0,
                min_weight: 0.5,
            };
            let vals: [f64; 64 * 16] = core::array::from_fn(|_| rnd());
            let plain = cell_of::<Q>(64, |i, q| vals[i * 16 + q], |i, c| 2.0 + vals[i * 16 + 12 + c]);
            // guide 1 duplicates guide 0
            let dup = cell_of::<Q>(64, |i, q| vals[i * 16 + if q == 1 { 0 } else { q }], |i, c| vals[i * 16 + 12 + c]);
            let mut nan = plain;
            nan[lay.t] = f64::NAN;
            let empty = [0f64; 160];
            let mut cells = [0f64; 4 * 160];
            for (l, c) in [plain, dup, empty, nan].iter().enumerate() {
                cells[l * k..(l + 1) * k].copy_from_slice(&c[..k]);
            }
            let run = |isa: Isa| {
                let mut m = [0f32; 4 * 48];
                let o = solve_cells4_on::<Q, false>(isa, &cells[..4 * k], &p, 0, &mut m[..4 * ml]);
                (o, m)
            };
            let (po, pm) = run(Isa::Portable);
            let (ao, am) = run(Isa::Avx2Fma);
            assert_eq!(po, ao, "Q {Q}");
            for j in 0..4 * ml {
                assert_eq!(pm[j].to_bits(), am[j].to_bits(), "Q {Q} value {j}: {} vs {}", pm[j], am[j]);
            }
            for l in 0..4 {
                let mut one = [0f32; 48];
                let o = solve_cell::<Q>(&cells[l * k..(l + 1) * k], &p, &mut one[..ml]);
                assert_eq!(o, po[l], "Q {Q} cell {l}");
                for j in 0..ml {
                    assert_eq!(one[j].to_bits(), pm[l * ml + j].to_bits(), "Q {Q} cell {l} value {j}");
                }
            }
        }
        check::<0>(&mut rnd);
        check::<1>(&mut rnd);
        check::<3>(&mut rnd);
        check::<5>(&mut rnd);
        check::<8>(&mut rnd);
        check::<MAX_GUIDES>(&mut rnd);
    }

    /// The fit without one guide from the full factor ([`solve_cell_without`])
    /// equals a solve of that guide's moments left out, for every dropped
    /// guide position (last, first, middle), both regularizations; the four-
    /// cell version is bit-identical on either instruction set and to four
    /// single cells, and the full fit beside it equals [`solve_cell`]'s (bit
    /// for bit when the dropped guide is last; on these well-conditioned
    /// cells the reordered factor's rounding does not reach the f32 model).
    #[test]
    fn fit_without_a_guide_matches_a_smaller_solve() {
        let mut seed = 7u32;
        let mut rnd = move || crate::hash::uniform(&mut seed);
        fn check<const Q: usize, const Q1: usize>(rnd: &mut impl FnMut() -> f64, reg: Regularization) {
            let (k, ml, k1, ml1) =
                (CellLayout::new(Q).k, crate::kernels::model_len(Q), CellLayout::new(Q1).k, crate::kernels::model_len(Q1));
            let vals: [f64; 64 * 16] = core::array::from_fn(|_| rnd());
            // guides: a smooth mix plus noise; light depends on all of them
            let g = |i: usize, q: usize| vals[i * 16 + q] + 0.3 * (q as f64) + 0.1 * vals[i * 16 + (q + 1) % 8];
            let y = |i: usize, c: usize| 1.0 + vals[i * 16 + 12 + c] + (0..Q).map(|q| 0.2 * (q as f64 + 1.0) * g(i, q)).sum::<f64>();
            for drop in [Q - 1, 0, Q / 2] {
                let p = SolveParams {
                    reference: core::array::from_fn(|q| 0.05 * q as f64),
                    mean: core::array::from_fn(|q| 0.5 + 0.3 * q as f64),
                    scale: core::array::from_fn(|q| 0.3 + 0.01 * q as f64),
                    regularization: reg,
                    weight_norm: 1.0 / 64.0,
                    min_weight: 0.5,
                };
                let keep = |q1: usize| if q1 < drop { q1 } else { q1 + 1 };
                let cell = cell_of::<Q>(64, g, y);
                let small = cell_of::<Q1>(64, |i, q1| g(i, keep(q1)), y);
                let mut p1 = p;
                for q1 in 0..Q1 {
                    p1.reference[q1] = p.reference[keep(q1)];
                    p1.mean[q1] = p.mean[keep(q1)];
                    p1.scale[q1] = p.scale[keep(q1)];
                }
                let mut want = [0f32; 48];
                solve_cell::<Q1>(&small[..k1], &p1, &mut want[..ml1]);
                let mut both = [0f32; 96];
                solve_cell_without::<Q>(&cell[..k], &p, drop, &mut both[..2 * ml]);
                let mut full = [0f32; 48];
                solve_cell::<Q>(&cell[..k], &p, &mut full[..ml]);
                for j in 0..ml {
                    assert_eq!(both[j].to_bits(), full[j].to_bits(), "Q {Q} drop {drop} full value {j}");
                }
                let sub = &both[ml..2 * ml];
                let close = |a: f32, b: f32| (a - b).abs() <= 2e-4 * (1.0 + b.abs());
                for c in 0..3 {
                    assert!(close(sub[c], want[c]), "Q {Q} drop {drop} c0 {c}: {} vs {}", sub[c], want[c]);
                    assert_eq!(sub[3 + 3 * Q + c], full[3 + 3 * Q + c], "μ_y");
                    assert_eq!(sub[3 + 3 * drop + c], 0.0, "no coefficient on the dropped guide");
                    for q1 in 0..Q1 {
                        let (a, b) = (sub[3 + 3 * keep(q1) + c], want[3 + 3 * q1 + c]);
                        assert!(close(a, b), "Q {Q} drop {drop} guide {} c {c}: {a} vs {b}", keep(q1));
                    }
                }
                // the full fit does use the dropped guide: the two fits differ
                assert!((0..3).any(|c| full[3 + 3 * drop + c] != 0.0));
                if let Regularization::Normalized { .. } = reg {
                    let mut cells = [0f64; 4 * 160];
                    for l in 0..4 {
                        cells[l * k..(l + 1) * k].copy_from_slice(&cell[..k]);
                        cells[l * k + lay_t::<Q>()] += l as f64; // four different cells
                    }
                    cells[3 * k + lay_t::<Q>() + 1] = f64::NAN;
                    let run = |isa: Isa| {
                        let mut m = [0f32; 4 * 96];
                        let o = solve_cells4_on::<Q, true>(isa, &cells[..4 * k], &p, drop, &mut m[..8 * ml]);
                        (o, m)
                    };
                    let ((po, pm), (ao, am)) = (run(Isa::Portable), run(Isa::Avx2Fma));
                    assert_eq!(po, ao);
                    for l in 0..4 {
                        let mut one = [0f32; 96];
                        assert_eq!(solve_cell_without::<Q>(&cells[l * k..(l + 1) * k], &p, drop, &mut one[..2 * ml]), po[l]);
                        for j in 0..2 * ml {
                            let (a, b, c) = (pm[l * 2 * ml + j], am[l * 2 * ml + j], one[j]);
                            assert_eq!(a.to_bits(), b.to_bits(), "Q {Q} drop {drop} cell {l} value {j}");
                            assert_eq!(a.to_bits(), c.to_bits(), "Q {Q} drop {drop} cell {l} value {j}");
                        }
                    }
                }
            }
        }
        fn lay_t<const Q: usize>() -> usize {
            CellLayout::new(Q).t
        }
        for reg in [Regularization::Normalized { eps_mul: 1e-3, eps_add: 1e-2 }, Regularization::Tikhonov { eps: 1e-4 }] {
            check::<1, 0>(&mut rnd, reg);
            check::<3, 2>(&mut rnd, reg);
            check::<5, 4>(&mut rnd, reg);
            check::<8, 7>(&mut rnd, reg);
        }
    }
}
