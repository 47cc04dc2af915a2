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

/// Arithmetic the WALR Cholesky runs on: `f32` (scalar path), `f64` (oracle) or
/// [`wide::f32x8`] (8 pixels per call, one per lane).
pub trait Lane:
    Copy + core::ops::Add<Output = Self> + core::ops::Sub<Output = Self> + core::ops::Mul<Output = Self> + core::ops::Div<Output = Self>
{
    fn splat(v: f32) -> Self;
    fn max_(self, o: Self) -> Self;
    fn sqrt_(self) -> Self;
}

impl Lane for f32 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn max_(self, o: Self) -> Self {
        // NaN-safe: a NaN pivot becomes the floor.
        if self > o {
            self
        } else {
            o
        }
    }
    #[inline(always)]
    fn sqrt_(self) -> Self {
        super::sqrt(self as f64) as f32
    }
}

impl Lane for f64 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        v as f64
    }
    #[inline(always)]
    fn max_(self, o: Self) -> Self {
        if self > o {
            self
        } else {
            o
        }
    }
    #[inline(always)]
    fn sqrt_(self) -> Self {
        super::sqrt(self)
    }
}

impl Lane for wide::f32x8 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        wide::f32x8::splat(v)
    }
    #[inline(always)]
    fn max_(self, o: Self) -> Self {
        // `o` (the floor) wherever `self > o` is false, NaN included.
        self.simd_gt(o).select(self, o)
    }
    #[inline(always)]
    fn sqrt_(self) -> Self {
        self.sqrt()
    }
}

/// WALR Algorithm 1: `C Cᵀ = A` for the symmetric `M×M` matrix `a` (lower
/// triangle read), with the per-pivot floor `C_ii = √max(C_ii, ε_i)` so a
/// singular or indefinite `A` still factors. `a`'s lower triangle becomes `C`;
/// returns `1 / C_ii`.
#[inline(always)]
pub fn factor_floor<T: Lane, const M: usize>(a: &mut [[T; M]; M], eps: &[T; M]) -> [T; M] {
    let one = T::splat(1.0);
    let mut inv = [one; M];
    for i in 0..M {
        let mut d = a[i][i];
        for j in 0..i {
            d = d - a[i][j] * a[i][j];
        }
        let c = d.max_(eps[i]).sqrt_();
        a[i][i] = c;
        inv[i] = one / c;
        for j in i + 1..M {
            let mut s = a[j][i];
            for k in 0..i {
                s = s - a[i][k] * a[j][k];
            }
            a[j][i] = s * inv[i];
        }
    }
    inv
}

/// WALR Algorithm 2: forward then backward substitution with the factor of
/// [`factor_floor`], for `R` right-hand sides at once (`b[i][r]`), in place.
#[inline(always)]
pub fn substitute<T: Lane, const M: usize, const R: usize>(c: &[[T; M]; M], inv: &[T; M], b: &mut [[T; R]; M]) {
    for i in 0..M {
        for j in 0..i {
            for r in 0..R {
                b[i][r] = b[i][r] - c[i][j] * b[j][r];
            }
        }
        for r in 0..R {
            b[i][r] = b[i][r] * inv[i];
        }
    }
    for j in (0..M).rev() {
        for i in j + 1..M {
            for r in 0..R {
                b[j][r] = b[j][r] - c[i][j] * b[i][r];
            }
        }
        for r in 0..R {
            b[j][r] = b[j][r] * inv[j];
        }
    }
}
