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

/// f64 arithmetic of FLR's per-cell solve: `f64` (one cell) or [`wide::f64x4`]
/// (four cells, one per lane). Every operation is the IEEE one per lane, so a
/// lane's result is bit-identical to the scalar path's.
pub trait F64Lanes:
    Copy + core::ops::Add<Output = Self> + core::ops::Sub<Output = Self> + core::ops::Mul<Output = Self> + core::ops::Div<Output = Self>
{
    /// Cells per value: 1 or 4.
    const LANES: usize;
    /// `v` in every lane.
    fn splat(v: f64) -> Self;
    /// Absolute value per lane.
    fn abs_(self) -> Self;
    /// `self` where `self > o`, else `o` (NaN → `o`).
    fn max_(self, o: Self) -> Self;
    /// Square root per lane.
    fn sqrt_(self) -> Self;
    /// Bit `l` set where lane `l` is not (`self > floor` and finite).
    fn not_above(self, floor: Self) -> u32;
    /// Lanes whose bit is set in `mask` become `v`.
    fn set_where(self, mask: u32, v: f64) -> Self;
}

impl F64Lanes for f64 {
    const LANES: usize = 1;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn abs_(self) -> Self {
        self.abs()
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
    #[inline(always)]
    fn not_above(self, floor: Self) -> u32 {
        (!(self > floor) || !self.is_finite()) as u32
    }
    #[inline(always)]
    fn set_where(self, mask: u32, v: f64) -> Self {
        if mask & 1 != 0 {
            v
        } else {
            self
        }
    }
}

impl F64Lanes for wide::f64x4 {
    const LANES: usize = 4;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        wide::f64x4::splat(v)
    }
    #[inline(always)]
    fn abs_(self) -> Self {
        self.abs()
    }
    #[inline(always)]
    fn max_(self, o: Self) -> Self {
        self.simd_gt(o).bitselect(self, o)
    }
    #[inline(always)]
    fn sqrt_(self) -> Self {
        self.sqrt()
    }
    #[inline(always)]
    fn not_above(self, floor: Self) -> u32 {
        let ok = self.simd_gt(floor) & self.abs().simd_le(wide::f64x4::splat(f64::MAX));
        (!ok.to_bitmask()) & 0xF
    }
    #[inline(always)]
    fn set_where(self, mask: u32, v: f64) -> Self {
        if mask == 0 {
            return self;
        }
        let m: [f64; 4] = core::array::from_fn(|l| if mask >> l & 1 != 0 { f64::from_bits(u64::MAX) } else { 0.0 });
        wide::f64x4::from(m).bitselect(wide::f64x4::splat(v), self)
    }
}

/// Four [`F64Lanes`] lanes read from and written to memory: the lane types
/// of the four-cell kernels (`wide::f64x4`, and the AVX2 lanes of
/// `kernels::f64x4_avx2`). Conversions are exact.
pub trait Lanes4: F64Lanes {
    /// The four values, lane `l` from `a[l]`.
    fn from_array(a: [f64; 4]) -> Self;
    /// The four f32 values widened to f64.
    fn from_f32(a: [f32; 4]) -> Self;
    /// The four lanes.
    fn to_array(self) -> [f64; 4];
}

/// Value `m` of four cells stored back to back, `k` values each: cell `l`'s in lane `l`.
#[inline(always)]
pub fn quad<T: Lanes4>(cells: &[f64], k: usize, m: usize) -> T {
    T::from_array([cells[m], cells[k + m], cells[2 * k + m], cells[3 * k + m]])
}

impl Lanes4 for wide::f64x4 {
    #[inline(always)]
    fn from_array(a: [f64; 4]) -> Self {
        wide::f64x4::from(a)
    }
    #[inline(always)]
    fn from_f32(a: [f32; 4]) -> Self {
        wide::f64x4::from(a.map(f64::from))
    }
    #[inline(always)]
    fn to_array(self) -> [f64; 4] {
        wide::f64x4::to_array(self)
    }
}

/// [`factor`] for a compile-time size, on one cell (`f64`) or four (`f64x4`):
/// fully unrollable, no zeroed scratch. `inv_diag[j]` = 1 / L_jj (0 for dropped
/// pivots), so the substitutions multiply instead of dividing (divisions are
/// long-latency and sit on the dependency chain). Returns the number of dropped
/// pivots of each lane.
#[inline(always)]
pub fn factor_n<T: F64Lanes, const N: usize>(a: &mut [[T; N]; N], rel_floor: f64, inv_diag: &mut [T; N]) -> [u32; 4] {
    let mut dropped = [0u32; 4];
    let mut maxdiag = T::splat(0.0);
    for (i, row) in a.iter().enumerate() {
        maxdiag = row[i].abs_().max_(maxdiag);
    }
    let floor = (maxdiag * T::splat(rel_floor)).max_(T::splat(f64::MIN_POSITIVE));
    for j in 0..N {
        let mut d = a[j][j];
        for p in 0..j {
            d = d - a[j][p] * a[j][p];
        }
        let drop = d.not_above(floor);
        for (l, c) in dropped.iter_mut().enumerate().take(T::LANES) {
            *c += drop >> l & 1;
        }
        let l = d.set_where(drop, 1.0).sqrt_();
        let inv = (T::splat(1.0) / l).set_where(drop, 0.0);
        a[j][j] = l.set_where(drop, 0.0);
        inv_diag[j] = inv;
        for i in j + 1..N {
            let mut s = a[i][j];
            for p in 0..j {
                s = s - a[i][p] * a[j][p];
            }
            a[i][j] = (s * inv).set_where(drop, 0.0);
        }
    }
    dropped
}

/// [`solve`] for a compile-time size and 3 right-hand sides, with the
/// reciprocal diagonal from [`factor_n`] (0 for dropped variables → 0).
#[inline(always)]
pub fn solve_n<T: F64Lanes, const N: usize>(l: &[[T; N]; N], inv_diag: &[T; N], b: &mut [[T; 3]; N]) {
    solve_lead_n(l, inv_diag, b, N);
}

/// [`solve_n`] on the leading `m × m` block (`m ≤ N`): the factor of a
/// matrix's leading principal block is the leading block of its factor, so
/// this solves the system of the first `m` variables alone (the rest of `b`
/// is left as it was). FLR's fit without its last guide ([`crate::flr`]).
#[inline(always)]
pub fn solve_lead_n<T: F64Lanes, const N: usize>(l: &[[T; N]; N], inv_diag: &[T; N], b: &mut [[T; 3]; N], m: usize) {
    let m = m.min(N);
    for i in 0..m {
        let mut s = b[i];
        for p in 0..i {
            for c in 0..3 {
                s[c] = s[c] - l[i][p] * b[p][c];
            }
        }
        for c in 0..3 {
            b[i][c] = s[c] * inv_diag[i];
        }
    }
    for i in (0..m).rev() {
        let mut s = b[i];
        for p in i + 1..m {
            for c in 0..3 {
                s[c] = s[c] - l[p][i] * b[p][c];
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
    /// `v` in every lane.
    fn splat(v: f32) -> Self;
    /// `self` where `self > o`, else `o` (NaN → `o`).
    fn max_(self, o: Self) -> Self;
    /// Square root per lane.
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

/// The forward half of [`substitute`]: `C u = b` for `R` right-hand sides,
/// in place.
#[inline(always)]
pub fn forward<T: Lane, const M: usize, const R: usize>(c: &[[T; M]; M], inv: &[T; M], b: &mut [[T; R]; M]) {
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
}

/// WALR Algorithm 2: forward then backward substitution with the factor of
/// [`factor_floor`], for `R` right-hand sides at once (`b[i][r]`), in place.
#[inline(always)]
pub fn substitute<T: Lane, const M: usize, const R: usize>(c: &[[T; M]; M], inv: &[T; M], b: &mut [[T; R]; M]) {
    forward(c, inv, b);
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
