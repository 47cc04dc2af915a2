//! Dense Cholesky LLᵀ for small SPD systems in f64, in place, with a pivot
//! floor: a pivot that is not clearly positive (relative to the matrix's
//! diagonal) drops its variable (row/column zeroed, coefficient 0) instead
//! of dividing by ~0.

/// Factors the `n×n` row-major matrix `a` (leading dimension `ld`) in place
/// (lower triangle = L). Entries of dropped pivots are set so that the solve
/// returns 0 for that variable. Returns a bit mask of dropped pivots.
pub fn factor(a: &mut [f64], n: usize, ld: usize, rel_floor: f64) -> u32 {
    let mut dropped = 0u32;
    let mut maxdiag = 0f64;
    for i in 0..n {
        maxdiag = maxdiag.max(a[i * ld + i].abs());
    }
    let floor = (maxdiag * rel_floor).max(f64::MIN_POSITIVE);
    for j in 0..n {
        let mut d = a[j * ld + j];
        for p in 0..j {
            d -= a[j * ld + p] * a[j * ld + p];
        }
        if !(d > floor) || !d.is_finite() {
            dropped |= 1 << j;
            a[j * ld + j] = 0.0;
            for i in j + 1..n {
                a[i * ld + j] = 0.0;
            }
            continue;
        }
        let l = super::sqrt(d);
        a[j * ld + j] = l;
        for i in j + 1..n {
            let mut s = a[i * ld + j];
            for p in 0..j {
                s -= a[i * ld + p] * a[j * ld + p];
            }
            a[i * ld + j] = s / l;
        }
    }
    dropped
}

/// Solves `L Lᵀ x = b` for `nrhs` right-hand sides stored row-major in `b`
/// (`n × nrhs`), in place. Dropped variables (zero pivot) get 0.
pub fn solve(l: &[f64], n: usize, ld: usize, b: &mut [f64], nrhs: usize) {
    for c in 0..nrhs {
        for i in 0..n {
            let d = l[i * ld + i];
            if d == 0.0 {
                b[i * nrhs + c] = 0.0;
                continue;
            }
            let mut s = b[i * nrhs + c];
            for p in 0..i {
                s -= l[i * ld + p] * b[p * nrhs + c];
            }
            b[i * nrhs + c] = s / d;
        }
        for i in (0..n).rev() {
            let d = l[i * ld + i];
            if d == 0.0 {
                b[i * nrhs + c] = 0.0;
                continue;
            }
            let mut s = b[i * nrhs + c];
            for p in i + 1..n {
                s -= l[p * ld + i] * b[p * nrhs + c];
            }
            b[i * nrhs + c] = s / d;
        }
    }
}

/// [`factor`] for a compile-time size: fully unrollable, no zeroed scratch.
/// Returns the dropped-pivot mask; `inv_diag[j]` = 1 / L_jj (0 for dropped pivots),
/// so the substitutions multiply instead of dividing (divisions are long-latency
/// and sit on the dependency chain).
#[inline(always)]
pub fn factor_n<const N: usize>(a: &mut [[f64; N]; N], rel_floor: f64, inv_diag: &mut [f64; N]) -> u32 {
    let mut dropped = 0u32;
    let mut maxdiag = 0f64;
    for (i, row) in a.iter().enumerate() {
        maxdiag = maxdiag.max(row[i].abs());
    }
    let floor = (maxdiag * rel_floor).max(f64::MIN_POSITIVE);
    for j in 0..N {
        let mut d = a[j][j];
        for p in 0..j {
            d -= a[j][p] * a[j][p];
        }
        if !(d > floor) || !d.is_finite() {
            dropped |= 1 << j;
            a[j][j] = 0.0;
            inv_diag[j] = 0.0;
            for row in a.iter_mut().skip(j + 1) {
                row[j] = 0.0;
            }
            continue;
        }
        let l = super::sqrt(d);
        let inv = 1.0 / l;
        a[j][j] = l;
        inv_diag[j] = inv;
        for i in j + 1..N {
            let mut s = a[i][j];
            for p in 0..j {
                s -= a[i][p] * a[j][p];
            }
            a[i][j] = s * inv;
        }
    }
    dropped
}

/// [`solve`] for a compile-time size and 3 right-hand sides, with the
/// reciprocal diagonal from [`factor_n`] (0 for dropped variables → 0).
#[inline(always)]
pub fn solve_n<const N: usize>(l: &[[f64; N]; N], inv_diag: &[f64; N], b: &mut [[f64; 3]; N]) {
    for i in 0..N {
        let mut s = b[i];
        for p in 0..i {
            for c in 0..3 {
                s[c] -= l[i][p] * b[p][c];
            }
        }
        for c in 0..3 {
            b[i][c] = s[c] * inv_diag[i];
        }
    }
    for i in (0..N).rev() {
        let mut s = b[i];
        for p in i + 1..N {
            for c in 0..3 {
                s[c] -= l[p][i] * b[p][c];
            }
        }
        for c in 0..3 {
            b[i][c] = s[c] * inv_diag[i];
        }
    }
}
