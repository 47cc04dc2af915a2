//! Householder QR least squares for tall-skinny blocks (BMFR, Koskela et al.
//! 2019): `min ‖T α − z_c‖` for up to 3 right-hand sides at once, on the
//! augmented matrix `[T | z]` (rows × (m + k), column-major, overwritten).
//!
//! Each Householder reflection zeroes one column below the diagonal and is
//! applied to every later column, right-hand sides included, so `Qᵀz` is
//! formed without storing Q. Back-substitution on the m×m triangle drops a
//! coefficient (sets it to 0) when its pivot is not clearly non-zero relative to
//! the largest pivot, instead of dividing by ~0: rank-deficient blocks (flat
//! walls, empty sky) give finite, minimum-effort fits. Dot products and updates
//! run over the rows in `f32x8` lanes, with a scalar remainder.

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
/// `diag`), the reflection vectors' tails below it.
fn triangularize(a: &mut [f32], ld: usize, rows: usize, cols: usize, m: usize, simd: bool, diag: &mut [f32; MAX_FEATURES]) {
    for j in 0..m.min(rows) {
        let (head, tail) = a.split_at_mut((j + 1) * ld);
        let v = &mut head[j * ld + j..j * ld + rows];
        let norm = libm::sqrtf(dot(v, v, simd));
        if !(norm > 0.0) || !norm.is_finite() {
            diag[j] = 0.0;
            continue;
        }
        let alpha = if v[0] > 0.0 { -norm } else { norm };
        v[0] -= alpha; // v = x − α e1
        let vv = dot(v, v, simd); // = 2 ‖x‖ (‖x‖ + |x0|) > 0
        for c in 0..(cols - j - 1) {
            let col = &mut tail[c * ld + j..c * ld + rows];
            let s = -2.0 * dot(v, col, simd) / vv;
            axpy(col, s, v, simd);
        }
        v[0] = alpha; // column j now holds R's column j on and above the diagonal
        diag[j] = alpha;
    }
}

/// Factors the first `m` columns of the column-major `rows × (m + k)` matrix
/// `a` in place and solves for `x` (`m × k`, row-major: `x[i * k + c]`).
/// Afterwards R is on and above the diagonal of the top `m` rows and `Qᵀz` in
/// the top `m` rows of the last `k` columns (the rest is workspace).
/// (A blocked TSQR variant — 256-row panels, then the stacked R's — was
/// measured 30% slower for 1024-row blocks on AMD EPYC; not kept.) Pivots below `rel_tol × max|R_jj|` drop their feature.
/// Returns `None` for inconsistent sizes (`rows < 1`, `m > 16`, `k > 3`, short slices).
pub fn lstsq(a: &mut [f32], rows: usize, m: usize, k: usize, rel_tol: f32, simd: bool, x: &mut [f32]) -> Option<Fit> {
    if rows == 0 || m > MAX_FEATURES || k > MAX_RHS || a.len() < rows * (m + k) || x.len() < m * k {
        return None;
    }
    let cols = m + k;
    let mut diag = [0f32; MAX_FEATURES];
    triangularize(a, rows, rows, cols, m, simd, &mut diag);
    // Back-substitution with pivot dropping.
    let rmax = diag[..m].iter().fold(0f32, |acc, d| acc.max(d.abs()));
    let floor = rmax * rel_tol;
    let mut fit = Fit::default();
    for i in (0..m).rev() {
        let r = if i < rows { diag[i] } else { 0.0 };
        let drop = !(r.abs() > floor) || i >= rows;
        for c in 0..k {
            if drop {
                x[i * k + c] = 0.0;
                continue;
            }
            let mut s = a[(m + c) * rows + i];
            for j in i + 1..m {
                s -= a[j * rows + i] * x[j * k + c];
            }
            let v = s / r;
            x[i * k + c] = if v.is_finite() { v } else { 0.0 };
        }
        if drop {
            fit.dropped |= 1 << i;
        }
    }
    Some(fit)
}
