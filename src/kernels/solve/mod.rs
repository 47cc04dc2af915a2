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
use crate::config::Regularization;
use crate::guides::MAX_GUIDES;
use crate::isa::Isa;
use wide::f64x4;

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
    pub regularization: Regularization,
    /// 1 / (total window weight): turns sums into weighted averages (Tikhonov).
    pub weight_norm: f64,
    /// A cell whose window weight is at most this is empty (no valid pixel).
    pub min_weight: f64,
}

/// Outcome of one cell's solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CellOutcome {
    pub empty: bool,
    /// Variables dropped by the pivot floor.
    pub dropped: u32,
}

/// Solves one cell. `cell` has `CellLayout::new(Q).k` values, `model` has `model_len(Q)`.
pub fn solve_cell<const Q: usize>(cell: &[f64], p: &SolveParams, model: &mut [f32]) -> CellOutcome {
    let lay = CellLayout::new(Q);
    let n = cell[0];
    if is_empty(n, p) {
        model.fill(0.0);
        return CellOutcome { empty: true, dropped: 0 };
    }
    let (c0, coef, muy, dropped) = match p.regularization {
        Regularization::Normalized { eps_mul, eps_add } => {
            let (c0, c, muy, dropped) = normalized::<f64, Q>(|m| cell[m], p, eps_mul, eps_add);
            let mut coef = [[0f64; 3]; MAX_GUIDES];
            coef[..Q].copy_from_slice(&c);
            (c0, coef, muy, dropped[0])
        }
        Regularization::Tikhonov { eps } => tikhonov::<Q>(cell, &lay, p, eps),
    };
    write_model::<Q>(&c0, &coef[..Q], &muy, model);
    CellOutcome { empty: false, dropped }
}

/// Solves four consecutive cells (`cells` holds 4·k values, `models` 4·`model_len(Q)`)
/// with one cell per f64x4 lane: bit-identical to four [`solve_cell`] calls.
/// On x86-64 the lanes are AVX2 registers where the CPU has them
/// (`avx2::normalized4`; same result), which matters in a default build,
/// whose `f64x4` is two SSE2 halves.
pub fn solve_cells4<const Q: usize>(cells: &[f64], p: &SolveParams, models: &mut [f32]) -> [CellOutcome; 4] {
    solve_cells4_on::<Q>(Isa::detect(), cells, p, models)
}

/// [`solve_cells4`] on the given instruction set (the intrinsics file where
/// [`Isa::intrinsics`], otherwise the portable lanes).
fn solve_cells4_on<const Q: usize>(isa: Isa, cells: &[f64], p: &SolveParams, models: &mut [f32]) -> [CellOutcome; 4] {
    let lay = CellLayout::new(Q);
    let (k, ml) = (lay.k, super::model_len(Q));
    let Regularization::Normalized { eps_mul, eps_add } = p.regularization else {
        return core::array::from_fn(|l| solve_cell::<Q>(&cells[l * k..(l + 1) * k], p, &mut models[l * ml..(l + 1) * ml]));
    };
    let cells = &cells[..4 * k];
    let (c0, coef, muy, dropped) = normalized4_on::<Q>(isa, cells, p, eps_mul, eps_add);
    write_models4::<Q>(&c0, &coef, &muy, models);
    core::array::from_fn(|l| {
        if is_empty(cells[l * k], p) {
            models[l * ml..(l + 1) * ml].fill(0.0);
            return CellOutcome { empty: true, dropped: 0 };
        }
        CellOutcome { empty: false, dropped: dropped[l] }
    })
}

/// Four cells' fits in `f64` lanes, as [`normalized`] returns them: the
/// intercepts, the coefficients on `d = g − m`, the local means of y and
/// each lane's number of dropped pivots.
type Lanes4<const Q: usize> = ([f64x4; 3], [[f64x4; 3]; Q], [f64x4; 3], [u32; 4]);

/// The four cells' normalized solve in `f64` lanes (`cells`: four cell
/// layouts back to back) on the given instruction set.
#[inline(always)]
fn normalized4_on<const Q: usize>(isa: Isa, cells: &[f64], p: &SolveParams, eps_mul: f64, eps_add: f64) -> Lanes4<Q> {
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::normalized4::<Q>(cells, p, eps_mul, eps_add) };
    }
    let _ = isa;
    let k = CellLayout::new(Q).k;
    let get = |m: usize| f64x4::from([cells[m], cells[k + m], cells[2 * k + m], cells[3 * k + m]]);
    normalized::<f64x4, Q>(get, p, eps_mul, eps_add)
}

/// [`write_model`] for four cells at once: finiteness tested in lanes, each
/// value transposed straight into its cell's model; the rare lane with a
/// non-finite value is redone by [`write_model`] (same result).
#[inline(always)]
fn write_models4<const Q: usize>(c0: &[f64x4; 3], coef: &[[f64x4; 3]; Q], muy: &[f64x4; 3], models: &mut [f32]) {
    let ml = super::model_len(Q);
    let limit = f64x4::splat(f32::MAX as f64);
    let mut ok = f64x4::splat(f64::from_bits(u64::MAX));
    let mut put = |j: usize, v: f64x4, ok: &mut f64x4| {
        *ok &= v.abs().simd_lt(limit);
        for (l, x) in v.to_array().into_iter().enumerate() {
            models[l * ml + j] = x as f32;
        }
    };
    for c in 0..3 {
        put(c, c0[c], &mut ok);
        put(3 + 3 * Q + c, muy[c], &mut ok);
    }
    for a in 0..Q {
        for c in 0..3 {
            put(3 + 3 * a + c, coef[a][c], &mut ok);
        }
    }
    let ok = ok.to_bitmask();
    for l in 0..4 {
        if ok & (1 << l) == 0 {
            let lane = |v: f64x4| v.to_array()[l];
            let mut coefl = [[0f64; 3]; MAX_GUIDES];
            for a in 0..Q {
                coefl[a] = coef[a].map(lane);
            }
            write_model::<Q>(&c0.map(lane), &coefl[..Q], &muy.map(lane), &mut models[l * ml..(l + 1) * ml]);
        }
    }
}

#[inline(always)]
fn is_empty(n: f64, p: &SolveParams) -> bool {
    !(n > p.min_weight) || !n.is_finite()
}

/// The normalized-correlation regularized solve (appendix eqs. 12–23) of one
/// cell (`f64`) or four (`f64x4`); `get(m)` reads moment `m`. Returns the
/// intercept, coefficients on `d = g − m`, the local mean of y and the number
/// of dropped pivots per lane.
#[allow(clippy::type_complexity)]
#[inline(always)]
fn normalized<T: F64Lanes, const Q: usize>(
    get: impl Fn(usize) -> T,
    p: &SolveParams,
    eps_mul: f64,
    eps_add: f64,
) -> ([T; 3], [[T; 3]; Q], [T; 3], [u32; 4]) {
    let lay = CellLayout::new(Q);
    let s = T::splat;
    let inv_n = s(1.0) / get(0);
    let muy = [get(lay.t) * inv_n, get(lay.t + 1) * inv_n, get(lay.t + 2) * inv_n];
    let mut c0 = muy;
    let mut coef = [[s(0.0); 3]; Q];
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
    // Ŵ (eq. 18) on standardised guides; W = S/n − μμᵀ in f64.
    let mut wh = [[s(0.0); Q]; Q];
    let mut idx = lay.ss;
    for a in 0..Q {
        for b in a..Q {
            let w = (get(idx) * inv_n - mu[a] * mu[b]) * s(inv_scale[a] * inv_scale[b]);
            let mut v = w + s(eps_mul) * muz[a] * muz[b];
            if a == b {
                v = v + s(eps_mul) * muz[a] * muz[a] + s(eps_add);
            }
            wh[a][b] = v;
            wh[b][a] = v;
            idx += 1;
        }
    }
    // σ̂ (eq. 19), Ĉ + ϵI (eqs. 20, 22), B̂ (eq. 21).
    let mut isig = [s(0.0); Q];
    for a in 0..Q {
        isig[a] = s(1.0) / wh[a][a].max_(s(1e-300)).sqrt_();
    }
    let mut bh = [[s(0.0); 3]; Q];
    for a in 0..Q {
        for b in 0..Q {
            wh[a][b] = wh[a][b] * isig[a] * isig[b];
        }
        wh[a][a] = wh[a][a] + s(eps_add);
        for c in 0..3 {
            let cxy = get(lay.p + 3 * a + c) * inv_n - mu[a] * muy[c];
            bh[a][c] = cxy * isig[a] * s(inv_scale[a]);
        }
    }
    let mut inv_diag = [s(0.0); Q];
    let dropped = cholesky::factor_n(&mut wh, 1e-12, &mut inv_diag);
    cholesky::solve_n(&wh, &inv_diag, &mut bh);
    // Back to raw guides (eq. 23): y = μ_y + Σ β (d − μ).
    for a in 0..Q {
        for c in 0..3 {
            let beta = bh[a][c] * isig[a] * s(inv_scale[a]);
            coef[a][c] = beta;
            c0[c] = c0[c] - beta * mu[a];
        }
    }
    (c0, coef, muy, dropped)
}

/// Textbook Tikhonov (eq. 11) on the guides exactly as given.
#[allow(clippy::type_complexity)]
fn tikhonov<const Q: usize>(
    cell: &[f64],
    lay: &CellLayout,
    p: &SolveParams,
    eps: f64,
) -> ([f64; 3], [[f64; 3]; MAX_GUIDES], [f64; 3], u32) {
    let n = cell[0];
    let inv_n = 1.0 / n;
    let muy = [cell[lay.t] * inv_n, cell[lay.t + 1] * inv_n, cell[lay.t + 2] * inv_n];
    let mut c0 = [0f64; 3];
    let mut coef = [[0f64; 3]; MAX_GUIDES];
    let wn = p.weight_norm;
    let m = &p.reference;
    let mut xx = [0f64; N1 * N1];
    let mut xy = [0f64; N1 * 3];
    xx[0] = n * wn + eps;
    let mut idx = lay.ss;
    for a in 0..Q {
        let s_a = cell[lay.s + a];
        let s_raw = s_a + n * m[a];
        xx[a + 1] = s_raw * wn;
        xx[(a + 1) * N1] = s_raw * wn;
        for b in a..Q {
            let s_b = cell[lay.s + b];
            let raw = cell[idx] + m[a] * s_b + s_a * m[b] + n * m[a] * m[b];
            let mut v = raw * wn;
            if a == b {
                v += eps;
            }
            xx[(a + 1) * N1 + b + 1] = v;
            xx[(b + 1) * N1 + a + 1] = v;
            idx += 1;
        }
    }
    for c in 0..3 {
        let t = cell[lay.t + c];
        xy[c] = t * wn;
        for a in 0..Q {
            xy[(a + 1) * 3 + c] = (cell[lay.p + 3 * a + c] + m[a] * t) * wn;
        }
    }
    let dropped = cholesky::factor(&mut xx, Q + 1, N1, 1e-15);
    cholesky::solve(&xx, Q + 1, N1, &mut xy, 3);
    for c in 0..3 {
        c0[c] = xy[c];
        for a in 0..Q {
            let v = xy[(a + 1) * 3 + c];
            coef[a][c] = v;
            c0[c] += v * m[a];
        }
    }
    (c0, coef, muy, dropped.count_ones())
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
                let o = solve_cells4_on::<Q>(isa, &cells[..4 * k], &p, &mut m[..4 * ml]);
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
}
