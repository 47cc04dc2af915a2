//! Householder QR least squares for tall-skinny blocks (BMFR, Koskela et al.
//! 2019): `min ‖T α − z_c‖` for up to 3 right-hand sides at once, on the
//! augmented matrix `[T | z]` (rows × (m + k), column-major, overwritten).
//!
//! Each Householder reflection zeroes one column below the diagonal and is
//! applied to every later column, right-hand sides included, so `Qᵀz` is
//! formed without storing Q. Back-substitution on the m×m triangle drops a
//! coefficient (sets it to 0) when its pivot is not clearly non-zero relative to
//! the largest pivot, instead of dividing by ~0: rank-deficient blocks (flat
//! walls, empty sky) give finite, minimum-effort fits. The SIMD path makes one
//! pass over the matrix per reflection (the updates and the next reflection's
//! dot products together, `triangularize_fused`) in `f32x8` lanes with a
//! scalar remainder; the scalar path is the textbook two-pass form, its oracle.

#[cfg(target_arch = "x86_64")]
mod avx2;

use crate::isa::Isa;
use wide::f32x8;

/// Most features per block.
pub const MAX_FEATURES: usize = 16;
/// Most right-hand sides.
pub const MAX_RHS: usize = 3;

/// Outcome of one fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fit {
    /// Bit `i` set: feature `i` was dropped (zero pivot).
    pub dropped: u32,
}

/// `Σ a_i b_i`. Four independent accumulators hide the FMA latency (a single
/// chain made the whole factorisation latency-bound, ~4× slower).
#[inline]
fn dot(a: &[f32], b: &[f32], simd: bool) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut i = 0;
    let mut s = 0.0;
    if simd {
        let mut acc = [f32x8::ZERO; 4];
        for (x, y) in a.chunks_exact(32).zip(b.chunks_exact(32)) {
            for l in 0..4 {
                let xv: [f32; 8] = x[8 * l..8 * l + 8].try_into().unwrap_or([0.0; 8]);
                let yv: [f32; 8] = y[8 * l..8 * l + 8].try_into().unwrap_or([0.0; 8]);
                acc[l] = f32x8::from(xv).mul_add(f32x8::from(yv), acc[l]);
            }
        }
        i = n / 32 * 32;
        while i + 8 <= n {
            let xv: [f32; 8] = a[i..i + 8].try_into().unwrap_or([0.0; 8]);
            let yv: [f32; 8] = b[i..i + 8].try_into().unwrap_or([0.0; 8]);
            acc[0] = f32x8::from(xv).mul_add(f32x8::from(yv), acc[0]);
            i += 8;
        }
        s = ((acc[0] + acc[1]) + (acc[2] + acc[3])).reduce_add();
    }
    while i < n {
        s += a[i] * b[i];
        i += 1;
    }
    s
}

#[inline]
fn axpy(y: &mut [f32], alpha: f32, x: &[f32], simd: bool) {
    let n = y.len().min(x.len());
    let mut i = 0;
    if simd {
        let av = f32x8::splat(alpha);
        while i + 8 <= n {
            let xv: [f32; 8] = x[i..i + 8].try_into().unwrap_or([0.0; 8]);
            let yv: [f32; 8] = y[i..i + 8].try_into().unwrap_or([0.0; 8]);
            let r: [f32; 8] = f32x8::from(xv).mul_add(av, f32x8::from(yv)).into();
            y[i..i + 8].copy_from_slice(&r);
            i += 8;
        }
    }
    while i < n {
        y[i] += alpha * x[i];
        i += 1;
    }
}

/// Householder-triangularises the first `m` columns of the `rows × cols`
/// column-major matrix with leading dimension `ld` (column `c` is
/// `a[c * ld..c * ld + rows]`), applying every reflection to all later
/// columns. R ends up on and above the diagonal (its diagonal also in
/// `diag`), the reflection vectors' tails below it. The textbook two passes
/// per reflection (the dot products `vᵀa_c`, then the updates): the scalar
/// oracle of [`triangularize_fused`].
fn triangularize(a: &mut [f32], ld: usize, rows: usize, cols: usize, m: usize, diag: &mut [f32; MAX_FEATURES]) {
    for j in 0..m.min(rows) {
        let (head, tail) = a.split_at_mut((j + 1) * ld);
        let v = &mut head[j * ld + j..j * ld + rows];
        let norm = libm::sqrtf(dot(v, v, false));
        if !(norm > 0.0) || !norm.is_finite() {
            diag[j] = 0.0;
            continue;
        }
        let alpha = if v[0] > 0.0 { -norm } else { norm };
        v[0] -= alpha; // v = x − α e1
        let vv = dot(v, v, false); // = 2 ‖x‖ (‖x‖ + |x0|) > 0
        for c in 0..(cols - j - 1) {
            let col = &mut tail[c * ld + j..c * ld + rows];
            let s = -2.0 * dot(v, col, false) / vv;
            axpy(col, s, v, false);
        }
        v[0] = alpha; // column j now holds R's column j on and above the diagonal
        diag[j] = alpha;
    }
}

/// Columns updated together in one pass of [`update_and_dot`] (4 updates and
/// 4 dot accumulators fit the 16 vector registers with room to spare).
const GROUP: usize = 4;

/// One pass over rows `lo..` of `G` ≤ [`GROUP`] columns: `col_c += s_c v`
/// (the reflection), then `dots_c += x · col_c` on the updated values, where
/// `x` is the first column of the group after its update (`x = None`, the
/// group that holds the next pivot column) or the given, already updated,
/// next pivot column. Each value is loaded and stored once per reflection.
fn update_and_dot<const G: usize>(v: &[f32], s: &[f32], cols: [&mut [f32]; G], x: Option<&[f32]>, lo: usize, dots: &mut [f32]) {
    let rows = v.len();
    let mut cols = cols.map(|c| &mut c[..rows]);
    let x = x.map(|x| &x[..rows]);
    // two accumulators per column (even and odd chunks): one FMA chain per
    // column made the pass latency-bound
    let mut acc = [[f32x8::ZERO; 2]; G];
    let sv: [f32x8; G] = core::array::from_fn(|c| f32x8::splat(s[c]));
    let load = |sl: &[f32], i: usize| f32x8::from(<[f32; 8]>::try_from(&sl[i..i + 8]).unwrap_or([0.0; 8]));
    let mut i = lo;
    while i + 16 <= rows {
        let vi = [load(v, i), load(v, i + 8)];
        let mut xi = match x {
            Some(x) => [load(x, i), load(x, i + 8)],
            None => [f32x8::ZERO; 2],
        };
        for c in 0..G {
            for h in 0..2 {
                let o = i + 8 * h;
                let u = vi[h].mul_add(sv[c], load(cols[c], o));
                cols[c][o..o + 8].copy_from_slice(&<[f32; 8]>::from(u));
                if c == 0 && x.is_none() {
                    xi[h] = u;
                }
                acc[c][h] = xi[h].mul_add(u, acc[c][h]);
            }
        }
        i += 16;
    }
    let mut acc = acc.map(|[a, b]| a + b);
    while i + 8 <= rows {
        let vi = load(v, i);
        let mut xi = match x {
            Some(x) => load(x, i),
            None => f32x8::ZERO,
        };
        for c in 0..G {
            let u = vi.mul_add(sv[c], load(cols[c], i));
            cols[c][i..i + 8].copy_from_slice(&<[f32; 8]>::from(u));
            if c == 0 && x.is_none() {
                xi = u;
            }
            acc[c] = xi.mul_add(u, acc[c]);
        }
        i += 8;
    }
    let tail = update_and_dot_rows(v, s, &mut cols, x, i);
    for c in 0..G {
        dots[c] = acc[c].reduce_add() + tail[c];
    }
}

/// Rows `from..` of [`update_and_dot`] one at a time (those no 8-row lane
/// group covers); returns their part of each dot product. Shared by every
/// instruction set's version.
#[inline(always)]
fn update_and_dot_rows<const G: usize>(v: &[f32], s: &[f32], cols: &mut [&mut [f32]; G], x: Option<&[f32]>, from: usize) -> [f32; G] {
    let mut tail = [0f32; G];
    for i in from..v.len() {
        let mut xi = x.map_or(0.0, |x| x[i]);
        for c in 0..G {
            cols[c][i] += s[c] * v[i];
            if c == 0 && x.is_none() {
                xi = cols[c][i];
            }
            tail[c] += xi * cols[c][i];
        }
    }
    tail
}

/// [`update_and_dot`] on the first `g` ≤ [`GROUP`] columns of `cols`, in
/// AVX2 + FMA intrinsics when the build's `wide` lacks them and the CPU has
/// them ([`Isa`]).
fn update_and_dot_group(v: &[f32], s: &[f32], cols: &mut [&mut [f32]; GROUP], g: usize, x: Option<&[f32]>, lo: usize, dots: &mut [f32]) {
    update_and_dot_group_with(Isa::detect(), v, s, cols, g, x, lo, dots)
}

/// [`update_and_dot_group`] on the given instruction set (`Avx2Fma` only
/// where it is available; otherwise the portable lanes).
#[allow(clippy::too_many_arguments)]
fn update_and_dot_group_with(
    isa: Isa,
    v: &[f32],
    s: &[f32],
    cols: &mut [&mut [f32]; GROUP],
    g: usize,
    x: Option<&[f32]>,
    lo: usize,
    dots: &mut [f32],
) {
    let [c0, c1, c2, c3] = cols;
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        unsafe {
            match g {
                1 => avx2::update_and_dot::<1>(v, s, [&mut **c0], x, lo, dots),
                2 => avx2::update_and_dot::<2>(v, s, [&mut **c0, &mut **c1], x, lo, dots),
                3 => avx2::update_and_dot::<3>(v, s, [&mut **c0, &mut **c1, &mut **c2], x, lo, dots),
                _ => avx2::update_and_dot::<4>(v, s, [&mut **c0, &mut **c1, &mut **c2, &mut **c3], x, lo, dots),
            }
        }
        return;
    }
    let _ = isa;
    match g {
        1 => update_and_dot::<1>(v, s, [&mut **c0], x, lo, dots),
        2 => update_and_dot::<2>(v, s, [&mut **c0, &mut **c1], x, lo, dots),
        3 => update_and_dot::<3>(v, s, [&mut **c0, &mut **c1, &mut **c2], x, lo, dots),
        _ => update_and_dot::<4>(v, s, [&mut **c0, &mut **c1, &mut **c2, &mut **c3], x, lo, dots),
    }
}

/// [`triangularize`] with one pass over the matrix per reflection: while
/// reflection `j` updates the later columns, the dot products the next
/// reflection needs (`x_{j+1} · a_c` over rows `j + 1..`, with `x_{j+1}` the
/// updated column `j + 1`) are accumulated from the values just written. With
/// `x` the pivot column and `v = x − α e₁`, `vᵀa_c = xᵀa_c − α a_c[j]` and
/// `vᵀv = 2(‖x‖² − α x₀)`, so the reflection needs only those dot products.
/// Halves the loads and stores of the two-pass form (the matrix, 53 KB for a
/// 1024 × 13 block, lives in L2).
fn triangularize_fused(
    a: &mut [f32],
    ld: usize,
    rows: usize,
    cols: usize,
    m: usize,
    diag: &mut [f32; MAX_FEATURES],
    dots0: Option<&[f32]>,
) {
    let mut d = [0f32; MAX_FEATURES + MAX_RHS];
    let pivots = m.min(rows);
    if pivots == 0 {
        return;
    }
    // dots of column 0 with every column, over all rows (given, or one pass)
    match dots0 {
        Some(d0) => d[..cols].copy_from_slice(&d0[..cols]),
        None => {
            for c in 0..cols {
                d[c] = dot(&a[..rows], &a[c * ld..c * ld + rows], true);
            }
        }
    }
    for j in 0..pivots {
        let (head, tail) = a.split_at_mut((j + 1) * ld);
        let v = &mut head[j * ld..j * ld + rows];
        let later = cols - j - 1;
        let x0 = v[j];
        let norm = libm::sqrtf(d[j]);
        let mut s = [0f32; MAX_FEATURES + MAX_RHS];
        let reflect = norm > 0.0 && norm.is_finite();
        let alpha = if x0 > 0.0 { -norm } else { norm };
        if reflect {
            let vv = 2.0 * (d[j] - alpha * x0);
            let f = -2.0 / vv; // one division per reflection, not one per column
            for c in 0..later {
                s[c] = (d[j + 1 + c] - alpha * tail[c * ld + j]) * f;
            }
            // row j: v_j = x0 − α
            for c in 0..later {
                tail[c * ld + j] += s[c] * (x0 - alpha);
            }
            v[j] = alpha;
            diag[j] = alpha;
        } else {
            diag[j] = 0.0;
        }
        if later == 0 {
            break;
        }
        let mut next = [0f32; MAX_FEATURES + MAX_RHS];
        if !reflect {
            // column j is left as it is (zero or not finite): only the next dots
            let x = &tail[j + 1..rows];
            for (c, n) in next[..later].iter_mut().enumerate() {
                *n = dot(x, &tail[c * ld + j + 1..c * ld + rows], true);
            }
            d = [0f32; MAX_FEATURES + MAX_RHS];
            d[j + 1..j + 1 + later].copy_from_slice(&next[..later]);
            continue;
        }
        // rows j + 1..: update every later column and form the next dots
        let (first, rest) = tail.split_at_mut(ld.min(tail.len()));
        let (first, rest_cols) = (&mut first[..rows], rest);
        let mut done = 0;
        {
            let mut it = rest_cols.chunks_mut(ld);
            let mut group: [&mut [f32]; GROUP] = [&mut [], &mut [], &mut [], &mut []];
            group[0] = first;
            let mut g = 1;
            while g < GROUP && done + g < later {
                if let Some(c) = it.next() {
                    group[g] = &mut c[..rows];
                }
                g += 1;
            }
            update_and_dot_group(&v[..rows], &s[..g], &mut group, g, None, j + 1, &mut next[..g]);
            done += g;
            // the remaining groups dot with the (now final) column j + 1
        }
        while done < later {
            let (firstc, others) = tail.split_at_mut(ld);
            let xcol = &firstc[..rows];
            let mut it = others.chunks_mut(ld).skip(done - 1);
            let mut group: [&mut [f32]; GROUP] = [&mut [], &mut [], &mut [], &mut []];
            let mut g = 0;
            while g < GROUP && done + g < later {
                if let Some(c) = it.next() {
                    group[g] = &mut c[..rows];
                }
                g += 1;
            }
            update_and_dot_group(&v[..rows], &s[done..done + g], &mut group, g, Some(xcol), j + 1, &mut next[done..done + g]);
            done += g;
        }
        d = [0f32; MAX_FEATURES + MAX_RHS];
        d[j + 1..j + 1 + later].copy_from_slice(&next[..later]);
    }
}

/// Factors the first `m` columns of the column-major `rows × (m + k)` matrix
/// `a` in place and solves for `x` (`m × k`, row-major: `x[i * k + c]`).
/// Afterwards R is on and above the diagonal of the top `m` rows and `Qᵀz` in
/// the top `m` rows of the last `k` columns (the rest is workspace).
/// (Tried and not kept, for 1024-row blocks on AMD EPYC: a TSQR over 256-row
/// panels, 30 % slower; streaming 128-row panels through an L1-resident
/// triangle, 12 % slower for the whole BMFR frame; two reflections per pass
/// in compact-WY form, halving the stores, no faster.) Pivots below
/// `rel_tol × max|R_jj|` drop their feature.
/// Returns `None` for inconsistent sizes (`rows < 1`, `m > 16`, `k > 3`, short slices).
pub fn lstsq(a: &mut [f32], rows: usize, m: usize, k: usize, rel_tol: f32, simd: bool, x: &mut [f32]) -> Option<Fit> {
    lstsq_ld(a, rows, rows, m, k, rel_tol, simd, x)
}

/// The leading dimension [`lstsq_ld`] works best with for `rows` rows: a
/// whole number of f32x8 lanes, and not a multiple of 4 KiB, whose columns
/// alias in the load/store unit's address check (measured on AMD EPYC
/// Zen 3: the 1024-row QR 11.6 → 10.1 µs with 16 floats of padding).
pub const fn padded_ld(rows: usize) -> usize {
    let ld = rows.div_ceil(8) * 8;
    if ld % 1024 < 16 || ld % 1024 > 1024 - 16 {
        ld + 16
    } else {
        ld
    }
}

/// [`lstsq`] on columns `ld ≥ rows` apart (column `c` is `a[c * ld..c * ld + rows]`).
#[allow(clippy::too_many_arguments)]
pub fn lstsq_ld(a: &mut [f32], ld: usize, rows: usize, m: usize, k: usize, rel_tol: f32, simd: bool, x: &mut [f32]) -> Option<Fit> {
    lstsq_shrunk_ld(a, ld, rows, m, k, rel_tol, simd, Shrinkage::NONE, None, x)
}

/// Wiener shrinkage of a least-squares fit in the orthogonal basis of its QR
/// factorisation ([`lstsq_shrunk_ld`]).
///
/// With `A = Q R`, the fitted values are `Q₁ q`, `q = (Qᵀz)_top`: coordinate
/// `q_l` is the data's component along Q's column `l`, the signal there plus
/// noise of the residual variance `σ̂² = ‖(Qᵀz)_{m..}‖² / (samples − m)`
/// (white noise keeps its variance in any orthonormal basis). Each `q_l`,
/// `l ≥ 1`, is scaled by `q_l² / (q_l² + κ σ̂²)` before back-substitution:
/// components that stand well above the noise are kept, those at its level
/// are damped. Column 0 (BMFR's constant feature: the block mean) is kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shrinkage {
    /// κ ≥ 0 (0: plain least squares).
    pub kappa: f32,
    /// Rows that hold data (the rest are zero rows), for σ̂²'s degrees of freedom.
    pub samples: usize,
}

impl Shrinkage {
    /// No shrinkage: plain least squares.
    pub const NONE: Shrinkage = Shrinkage { kappa: 0.0, samples: 0 };
}

/// [`lstsq_ld`] with [`Shrinkage`] of the fit: factors, scales `Qᵀz`'s
/// components (right-hand side by right-hand side, each with its own σ̂²),
/// then back-substitutes. `Shrinkage::NONE`, or no more samples than
/// features, is plain least squares.
///
/// `dots0`: the dot products of column 0 with every column (`a₀ · a_c`,
/// `m + k` values), which the first reflection needs, when the caller already
/// has them; `None` computes them in a pass over the matrix. BMFR, whose
/// column 0 is the 0/1 row mask, sums the columns while it fills them. (The
/// scalar path, `simd = false`, always computes them itself.)
#[allow(clippy::too_many_arguments)]
pub fn lstsq_shrunk_ld(
    a: &mut [f32],
    ld: usize,
    rows: usize,
    m: usize,
    k: usize,
    rel_tol: f32,
    simd: bool,
    shrink: Shrinkage,
    dots0: Option<&[f32]>,
    x: &mut [f32],
) -> Option<Fit> {
    if dots0.is_some_and(|d| d.len() < m + k) {
        return None;
    }
    if rows == 0 || m + k == 0 || ld < rows || m > MAX_FEATURES || k > MAX_RHS || a.len() < ld * (m + k - 1) + rows || x.len() < m * k {
        return None;
    }
    let cols = m + k;
    let mut diag = [0f32; MAX_FEATURES];
    if simd {
        triangularize_fused(a, ld, rows, cols, m, &mut diag, dots0);
    } else {
        triangularize(a, ld, rows, cols, m, &mut diag);
    }
    for d in diag.iter_mut().skip(rows) {
        *d = 0.0;
    }
    if shrink.kappa > 0.0 && shrink.samples > m && rows > m {
        for c in 0..k {
            shrink_components(&mut a[(m + c) * ld..(m + c) * ld + rows], m, shrink, simd);
        }
    }
    Some(back_substitute(a, ld, m, k, &diag, rel_tol, x))
}

/// Scales `qtz[1..m]` (one right-hand side's `Qᵀz`, whose rows `m..` are the
/// residual) by `q² / (q² + κσ̂²)` ([`Shrinkage`]). A non-finite σ̂² leaves
/// it as is. The residual's sum of squares is an f32 [`dot`] (in lanes with
/// `simd`; its rounding, ~1e-6 relative, is far below what a shrinkage factor
/// needs); the factors are formed in f64.
fn shrink_components(qtz: &mut [f32], m: usize, shrink: Shrinkage, simd: bool) {
    let rss = dot(&qtz[m..], &qtz[m..], simd) as f64;
    let noise = shrink.kappa as f64 * rss / (shrink.samples - m) as f64;
    if !noise.is_finite() {
        return;
    }
    for q in &mut qtz[1..m] {
        let q2 = *q as f64 * *q as f64;
        let f = q2 / (q2 + noise);
        // 0/0 (a zero component, no noise): nothing to scale
        *q = if f.is_finite() { (*q as f64 * f) as f32 } else { *q };
    }
}

/// Solves `R x = (Qᵀz)_top` (R: the top `m` rows of the first `m` columns,
/// `Qᵀz`: of the last `k`), dropping (zeroing) every coefficient whose pivot
/// `diag[i]` is not above `rel_tol` × the largest.
fn back_substitute(a: &[f32], ld: usize, m: usize, k: usize, diag: &[f32; MAX_FEATURES], rel_tol: f32, x: &mut [f32]) -> Fit {
    let rmax = diag[..m].iter().fold(0f32, |acc, d| acc.max(d.abs()));
    let floor = rmax * rel_tol;
    let mut fit = Fit::default();
    for i in (0..m).rev() {
        let r = diag[i];
        let drop = !(r.abs() > floor);
        for c in 0..k {
            if drop {
                x[i * k + c] = 0.0;
                continue;
            }
            let mut s = a[(m + c) * ld + i];
            for j in i + 1..m {
                s -= a[j * ld + i] * x[j * k + c];
            }
            let v = s / r;
            x[i * k + c] = if v.is_finite() { v } else { 0.0 };
        }
        if drop {
            fit.dropped |= 1 << i;
        }
    }
    fit
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 + FMA column update (where this CPU has it) agrees with the
    /// portable lanes to the rounding of fused against separate products, for
    /// every group size, with and without a given pivot column, across the
    /// 16-, 8- and 1-row parts of the loop.
    #[test]
    fn avx2_update_matches_portable() {
        if !Isa::Avx2Fma.available() {
            return;
        }
        let mut seed = 12345u32;
        let mut rnd = || crate::hash::uniform(&mut seed) as f32;
        for rows in [1usize, 7, 8, 15, 16, 17, 33, 1024] {
            for lo in [0usize, 1, 5] {
                let lo = lo.min(rows);
                let v: [f32; 1024] = core::array::from_fn(|_| rnd());
                let xcol: [f32; 1024] = core::array::from_fn(|_| rnd());
                let cols0: [[f32; 1024]; GROUP] = core::array::from_fn(|_| core::array::from_fn(|_| rnd()));
                let s = [0.3f32, -1.2, 0.7, 2.0];
                for g in 1..=GROUP {
                    for given in [false, true] {
                        let x = given.then_some(&xcol[..rows]);
                        let run = |isa: Isa| {
                            let mut c = cols0;
                            let mut dots = [0f32; GROUP];
                            {
                                let [a, b, cc, d] = &mut c;
                                let mut group: [&mut [f32]; GROUP] = [&mut a[..rows], &mut b[..rows], &mut cc[..rows], &mut d[..rows]];
                                update_and_dot_group_with(isa, &v[..rows], &s[..g], &mut group, g, x, lo, &mut dots[..g]);
                            }
                            (c, dots)
                        };
                        let (pc, pd) = run(Isa::Portable);
                        let (ac, ad) = run(Isa::Avx2Fma);
                        for c in 0..g {
                            for i in 0..rows {
                                assert!((pc[c][i] - ac[c][i]).abs() <= 1e-6 * (1.0 + pc[c][i].abs()), "rows {rows} g {g} col {c} row {i}");
                            }
                            assert!(
                                (pd[c] - ad[c]).abs() <= 1e-5 * (1.0 + pd[c].abs()) * rows as f32,
                                "rows {rows} g {g} dot {c}: {} vs {}",
                                pd[c],
                                ad[c]
                            );
                            if lo < rows {
                                assert_ne!(pd[c], 0.0, "the dots were formed");
                            }
                        }
                        for c in g..GROUP {
                            assert_eq!(ac[c], cols0[c], "column {c} outside the group is untouched");
                        }
                    }
                }
            }
        }
    }
}
