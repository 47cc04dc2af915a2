//! Steps 1 and 3 of the temporal stage on groups of pixels in SIMD lanes: the
//! arithmetic of the per-pixel code in [`super`], in the same order, so that
//! both give the same bits (`tests/temporal.rs` holds them to it). A group
//! that does not qualify (a tap outside the frame, taps at different offsets,
//! NaN/Inf light or motion) returns `None` and its pixels run one by one.
//!
//! The kernels are written once over [`Lane`]: `wide`'s lanes (4 in a build
//! without AVX, whose 8-lane type is two registers and would not hold a
//! group's state; 8 with AVX; 4 NEON lanes on aarch64), chosen at run time by
//! [`Isa`] in an x86-64 build without AVX2 + FMA, 8 AVX2 lanes ([`avx2`]),
//! and with [`Isa::Avx512`], in every x86-64 build, 16 AVX-512F lanes
//! ([`avx512`]). A 16-pixel group that does not qualify tries its first 8
//! pixels in the 8-lane kernel before running them one by one.

use super::{Reprojection, ResolveRow, Row, COUNT, LIGHT, OUTPUT};
use crate::isa::Isa;
use crate::kernels::LUMA;
use crate::reproject::floor;
use core::ops::{Add, AddAssign, BitAnd, BitAndAssign, BitOr, Div, Mul, Neg, Not, Sub};

/// What each intrinsics lane type (`avx2`, `avx512`) writes the same way: the
/// two entries that compile the runs of groups for its instruction set
/// (`$features`), and the assigning operators over its `+` and `&`.
#[cfg(target_arch = "x86_64")]
macro_rules! intrinsics_entries {
    ($t:ident, $features:literal) => {
        /// Step 1 on at most `max` groups ([`super::accumulate_run`]).
        ///
        /// # Safety
        #[doc = concat!("The CPU must support ", $features, ".")]
        #[target_feature(enable = $features)]
        pub(super) unsafe fn accumulate(
            st: &Reprojection,
            r: &Row<'_>,
            x: usize,
            out_row: &mut [f32],
            px_row: &mut [f32],
            max: usize,
        ) -> (usize, u64) {
            super::accumulate_run::<$t>(st, r, x, out_row, px_row, max)
        }

        /// Step 3 on at most `max` groups ([`super::resolve_run`]).
        ///
        /// # Safety
        #[doc = concat!("The CPU must support ", $features, ".")]
        #[target_feature(enable = $features)]
        pub(super) unsafe fn resolve(
            st: &Reprojection,
            r: &ResolveRow<'_>,
            x: usize,
            wrow: &mut [f32],
            out_row: &mut [f32],
            max: usize,
        ) -> usize {
            super::resolve_run::<$t>(st, r, x, wrow, out_row, max)
        }

        impl core::ops::AddAssign for $t {
            #[inline(always)]
            fn add_assign(&mut self, o: $t) {
                *self = *self + o;
            }
        }
        impl core::ops::BitAndAssign for $t {
            #[inline(always)]
            fn bitand_assign(&mut self, o: $t) {
                *self = *self & o;
            }
        }
    };
}

/// The [`Lane`] comparisons and NaN tests of an intrinsics lane type, over
/// its `cmp::<PREDICATE>` (the `_CMP_*` predicates of `core::arch`), `abs`
/// and `splat`.
#[cfg(target_arch = "x86_64")]
macro_rules! intrinsics_compares {
    () => {
        #[inline(always)]
        fn le(self, o: Self) -> Self {
            self.cmp::<_CMP_LE_OQ>(o)
        }
        #[inline(always)]
        fn lt(self, o: Self) -> Self {
            self.cmp::<_CMP_LT_OQ>(o)
        }
        #[inline(always)]
        fn ge(self, o: Self) -> Self {
            self.cmp::<_CMP_GE_OQ>(o)
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            self.cmp::<_CMP_GT_OQ>(o)
        }
        #[inline(always)]
        fn eq(self, o: Self) -> Self {
            self.cmp::<_CMP_EQ_OQ>(o)
        }
        #[inline(always)]
        fn is_nan(self) -> Self {
            self.cmp::<_CMP_UNORD_Q>(self)
        }
        #[inline(always)]
        fn is_finite(self) -> Self {
            self.abs().lt(Self::splat(f32::INFINITY))
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

/// Pixels ahead of a group whose history records it prefetches.
const PREFETCH_AHEAD: usize = 64;

/// Pixels run one by one where no group qualifies from a pixel.
pub(super) const PER_PIXEL_RUN: usize = 8;

/// A group of `N` f32 lanes; comparisons give masks (all bits set or clear
/// per lane) that the bit operations combine.
pub(super) trait Lane:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Not<Output = Self>
    + AddAssign
    + BitAndAssign
{
    const N: usize;
    fn splat(v: f32) -> Self;
    /// `[0, 1, …, N − 1]`.
    fn iota() -> Self;
    /// `s[i..i + N]`.
    fn load(s: &[f32], i: usize) -> Option<Self>;
    /// The `N` values from `p` (unaligned).
    ///
    /// # Safety
    /// `p..p + N` must be in one readable slice of `f32`.
    unsafe fn load_ptr(p: *const f32) -> Self;
    /// `s[i..i + N] = self`.
    fn store(self, s: &mut [f32], i: usize) -> Option<()>;
    fn first(self) -> f32;
    fn le(self, o: Self) -> Self;
    fn lt(self, o: Self) -> Self;
    fn ge(self, o: Self) -> Self;
    fn gt(self, o: Self) -> Self;
    fn eq(self, o: Self) -> Self;
    /// `t` where the mask `self` is set, `f` elsewhere.
    fn select(self, t: Self, f: Self) -> Self;
    fn abs(self) -> Self;
    fn sqrt(self) -> Self;
    fn is_nan(self) -> Self;
    fn is_finite(self) -> Self;
    /// `self` where `o` is NaN, else the larger (step 1 takes it where the
    /// two are never equal zeros of different signs).
    fn max(self, o: Self) -> Self;
    /// `self` where `o` is NaN, else the smaller (as [`Lane::max`]).
    fn min(self, o: Self) -> Self;
    /// Bit `l` set where lane `l` of the mask is.
    fn bitmask(self) -> u32;
    #[inline(always)]
    fn all(self) -> bool {
        self.bitmask() == (1 << Self::N) - 1
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.bitmask() != 0
    }
}

/// `wide`'s lanes in this build: 8 with AVX, 4 otherwise.
#[cfg(target_feature = "avx")]
type Portable = wide::f32x8;
#[cfg(not(target_feature = "avx"))]
type Portable = wide::f32x4;

impl Lane for Portable {
    const N: usize = core::mem::size_of::<Portable>() / 4;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Portable::splat(v)
    }
    #[inline(always)]
    fn iota() -> Self {
        Portable::from(core::array::from_fn(|l| l as f32))
    }
    #[inline(always)]
    fn load(s: &[f32], i: usize) -> Option<Self> {
        Some(Portable::from(<[f32; Self::N]>::try_from(s.get(i..i + Self::N)?).ok()?))
    }
    #[inline(always)]
    unsafe fn load_ptr(p: *const f32) -> Self {
        // SAFETY: the caller's contract; `Portable` is `N` f32 with no invalid bit patterns
        unsafe { core::ptr::read_unaligned(p as *const Portable) }
    }
    #[inline(always)]
    fn store(self, s: &mut [f32], i: usize) -> Option<()> {
        s.get_mut(i..i + Self::N)?.copy_from_slice(&self.to_array());
        Some(())
    }
    #[inline(always)]
    fn first(self) -> f32 {
        self.to_array()[0]
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        self.simd_le(o)
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        self.simd_lt(o)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self {
        self.simd_ge(o)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        self.simd_gt(o)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        self.simd_eq(o)
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        Portable::select(self, t, f)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Portable::abs(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Portable::sqrt(self)
    }
    #[inline(always)]
    fn is_nan(self) -> Self {
        Portable::is_nan(self)
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        Portable::is_finite(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Portable::max(self, o)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        Portable::min(self, o)
    }
    #[inline(always)]
    fn bitmask(self) -> u32 {
        self.to_bitmask()
    }
}

/// Whether `isa` takes the 16-lane AVX-512F kernels on this CPU.
#[cfg(target_arch = "x86_64")]
#[inline]
fn wide16(isa: Isa) -> bool {
    isa == Isa::Avx512 && isa.available()
}

/// Step 1 on groups of pixels from `x`, while they qualify: the first pixel
/// not done (`x` if no group qualified there) and the pixels done without
/// history. With AVX-512, a 16-pixel group that does not qualify is tried as
/// one 8-pixel group before the call returns.
#[inline]
pub(super) fn accumulate(st: &Reprojection, isa: Isa, r: &Row<'_>, x: usize, out_row: &mut [f32], px_row: &mut [f32]) -> (usize, u64) {
    #[cfg(target_arch = "x86_64")]
    if wide16(isa) {
        // SAFETY: the CPU has AVX-512F, AVX2 and FMA (`wide16`: `Isa::Avx512.available()`).
        let (x, n) = unsafe { avx512::accumulate(st, r, x, out_row, px_row, usize::MAX) };
        // SAFETY: as above (AVX2 and FMA).
        let (x, n8) = unsafe { avx2::accumulate(st, r, x, out_row, px_row, 1) };
        return (x, n + n8);
    }
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::accumulate(st, r, x, out_row, px_row, usize::MAX) };
    }
    let _ = isa;
    accumulate_run::<Portable>(st, r, x, out_row, px_row, usize::MAX)
}

/// Step 3 on groups of pixels from `x`, while they qualify: the first pixel
/// not done (`x` if no group qualified there). With AVX-512 as [`accumulate`].
#[inline]
pub(super) fn resolve(st: &Reprojection, isa: Isa, r: &ResolveRow<'_>, x: usize, wrow: &mut [f32], out_row: &mut [f32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if wide16(isa) {
        // SAFETY: the CPU has AVX-512F, AVX2 and FMA (`wide16`: `Isa::Avx512.available()`).
        let x = unsafe { avx512::resolve(st, r, x, wrow, out_row, usize::MAX) };
        // SAFETY: as above (AVX2 and FMA).
        return unsafe { avx2::resolve(st, r, x, wrow, out_row, 1) };
    }
    #[cfg(target_arch = "x86_64")]
    if isa.intrinsics() {
        // SAFETY: the CPU has AVX2 and FMA (`Isa::intrinsics`).
        return unsafe { avx2::resolve(st, r, x, wrow, out_row, usize::MAX) };
    }
    let _ = isa;
    resolve_run::<Portable>(st, r, x, wrow, out_row, usize::MAX)
}

/// At most `max` groups of [`accumulate_with`] from `x`, while they qualify:
/// the first pixel not done and the pixels done without history. The loop
/// sits in the caller's instruction set, so the groups' set-up inlines into it.
#[inline(always)]
pub(super) fn accumulate_run<L: Lane>(
    st: &Reprojection,
    r: &Row<'_>,
    mut x: usize,
    out_row: &mut [f32],
    px_row: &mut [f32],
    max: usize,
) -> (usize, u64) {
    let mut rejected = 0;
    for _ in 0..max {
        let Some(n) = accumulate_with::<L>(st, r, x, out_row, px_row) else { break };
        rejected += n;
        x += L::N;
    }
    (x, rejected)
}

/// At most `max` groups of [`resolve_with`] from `x`, while they qualify: the
/// first pixel not done.
#[inline(always)]
pub(super) fn resolve_run<L: Lane>(
    st: &Reprojection,
    r: &ResolveRow<'_>,
    mut x: usize,
    wrow: &mut [f32],
    out_row: &mut [f32],
    max: usize,
) -> usize {
    for _ in 0..max {
        if resolve_with::<L>(st, r, x, wrow, out_row).is_none() {
            break;
        }
        x += L::N;
    }
    x
}

/// The lanes where every value of `v` is finite: `0 · v` is ±0 for a finite
/// value and NaN for NaN/±Inf, and a sum with a NaN is NaN.
#[inline(always)]
fn finite<L: Lane, const K: usize>(v: [L; K]) -> L {
    let zero = L::splat(0.0);
    let mut s = zero;
    for x in v {
        s += x * zero;
    }
    s.eq(zero)
}

/// `super::footprint2` of the pixels `x..x + N` (their positions `p`), for
/// groups with both neighbours in the row (`None` otherwise: the per-pixel
/// code takes the row's ends).
#[inline(always)]
fn footprint2<L: Lane>(row: &[f32], p_at: usize, w: usize, x: usize, p: [L; 3]) -> Option<L> {
    if x == 0 || x + L::N + 1 > w {
        return None;
    }
    let m = distance2(load3(row, x - 1, p_at, w)?, p).min(distance2(load3(row, x + 1, p_at, w)?, p));
    Some(m.is_finite().select(m, L::splat(0.0)))
}

/// `|a − b|²`, +Inf where that is not finite.
#[inline(always)]
fn distance2<L: Lane>(a: [L; 3], b: [L; 3]) -> L {
    let e = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let d = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
    d.is_finite().select(d, L::splat(f32::INFINITY))
}

/// Lanes where all 3 values are 0.
#[inline(always)]
fn empty<L: Lane>(v: [L; 3]) -> L {
    let zero = L::splat(0.0);
    v[0].eq(zero) & v[1].eq(zero) & v[2].eq(zero)
}

/// Fields `f, f + 1, f + 2` (planes `w` apart) of the records at `s[i..]`.
#[inline(always)]
fn load3<L: Lane>(s: &[f32], i: usize, f: usize, w: usize) -> Option<[L; 3]> {
    Some([L::load(s, i + f * w)?, L::load(s, i + (f + 1) * w)?, L::load(s, i + (f + 2) * w)?])
}

/// `s[i..i + N]` without a bounds check.
///
/// # Safety
/// `i + N ≤ s.len()`.
#[inline(always)]
unsafe fn tap<L: Lane>(s: &[f32], i: usize) -> L {
    debug_assert!(i + L::N <= s.len());
    // SAFETY: the caller's contract
    unsafe { L::load_ptr(s.as_ptr().add(i)) }
}

/// [`tap`] of the fields at `i`, `i + w`, `i + 2w`.
///
/// # Safety
/// `i + 2w + N ≤ s.len()`.
#[inline(always)]
unsafe fn tap3<L: Lane>(s: &[f32], i: usize, w: usize) -> [L; 3] {
    // SAFETY: the caller's contract
    unsafe { [tap(s, i), tap(s, i + w), tap(s, i + 2 * w)] }
}

/// `v` where `mask` is set, +0 elsewhere (a `select` against zero in one instruction).
#[inline(always)]
fn keep<L: Lane>(mask: L, v: L) -> L {
    v & mask
}

/// Step 1 ([`Reprojection::accumulate_pixel`]) for pixels `x..x + L::N` of a
/// row whose 4 taps per pixel lie inside the frame at one common offset (so
/// each tap's fields are consecutive values of the previous records).
/// Returns the count of pixels without history.
#[inline(always)]
pub(super) fn accumulate_with<L: Lane>(st: &Reprojection, r: &Row<'_>, x: usize, out_row: &mut [f32], px_row: &mut [f32]) -> Option<u64> {
    let (w, h, rec, cfg) = (st.width, st.height, st.record(), &st.cfg);
    if !r.has_history || x + L::N > w {
        return None;
    }
    let (mx, my) = (L::load(r.mv, x)?, L::load(r.mv, w + x)?);
    let lim = L::splat(st.max_motion());
    if !(mx.abs().le(lim) & my.abs().le(lim)).all() {
        return None;
    }
    let (raw, cur) = (load3::<L>(r.raw, x, 0, w)?, load3::<L>(r.cur, x, 0, w)?);
    if !(finite(raw) & finite(cur)).all() {
        return None;
    }
    // the taps: (ix, iy) of lane l at (x + l + dx, iy)
    let xs = L::splat(x as f32) + L::iota();
    let (px, py) = (xs + mx, L::splat(r.y as f32) + my);
    // lane 0's taps; every lane's floor is lane 0's plus its lane index when
    // `fx ≤ px < fx + 1` (so `px − fx` is the fraction the per-pixel code takes)
    let (fx0, fy) = (floor(px.first()), floor(py.first()));
    let lanes = L::iota();
    let (fx, fyv) = (L::splat(fx0) + lanes, L::splat(fy));
    let one = L::splat(1.0);
    if !(px.ge(fx) & px.lt(fx + one) & py.ge(fyv) & py.lt(fyv + one)).all() {
        return None;
    }
    let (bx, iy) = (fx0 as i64, fy as i64);
    if bx < 0 || bx + L::N as i64 >= w as i64 || iy < 0 || iy + 1 >= h as i64 {
        return None;
    }
    let (bx, iy) = (bx as usize, iy as usize);
    let (ax, ay) = (px - fx, py - fyv);
    // (column, row below iy, weight) of the 4 taps
    let taps = [(bx, 0, (one - ax) * (one - ay)), (bx + 1, 0, ax * (one - ay)), (bx, 1, (one - ax) * ay), (bx + 1, 1, ax * ay)];
    // the previous records of rows iy and iy + 1, which every tap reads
    let records = r.read.get(iy * w * rec..(iy + 2) * w * rec)?;
    // row iy + 1 is new to this output row (row iy was the previous row's
    // second): its fields some groups ahead, a stream each
    let gather = st.accumulates_output();
    if bx % 16 < L::N {
        for f in 0..rec {
            // (the previous output's fields only where they are read)
            if gather || !(OUTPUT..OUTPUT + 3).contains(&f) {
                crate::image::prefetch(records, (rec + f) * w + bx + PREFETCH_AHEAD);
            }
        }
    }
    // SAFETY (each `tap`, `tap3` below): the fields read are fields of the
    // record (`f + 2 < rec` for `tap3`: the guide fields are read only where
    // the plan has them) and `tx + N ≤ bx + 1 + N ≤ w` (checked above), so
    // `(dy · rec + f) · w + tx + N ≤ 2 · w · rec`, the length of `records`.
    let (n_at, p_at, d_at) = st.guide_fields();
    let zero = L::splat(0.0);
    let normal = if st.normal { load3(out_row, x, n_at, w)? } else { [zero; 3] };
    let position = if st.position { load3(out_row, x, p_at, w)? } else { [zero; 3] };
    let d = if st.depth { L::load(out_row, d_at * w + x)? } else { zero };
    // the square of the largest position distance of a tap (as `Reprojection::accumulate_pixel`)
    let plim2 = if st.depth {
        let plim = L::splat(cfg.position_limit) * d.abs();
        plim * plim
    } else if st.position {
        L::splat(st.footprint_limit2()) * footprint2(out_row, p_at, w, x, position)?
    } else {
        zero
    };
    let (mut tw, mut n, mut prev) = (zero, zero, [zero; 3]);
    let (mut ow, mut out) = (zero, [zero; 3]);
    for (tx, dy, wt) in taps {
        let mut ok = wt.gt(zero);
        if st.normal {
            let b = unsafe { tap3::<L>(records, (dy * rec + n_at) * w + tx, w) };
            let dot = normal[0] * b[0] + normal[1] * b[1] + normal[2] * b[2];
            ok &= dot.ge(L::splat(cfg.normal_limit)) | (empty(normal) & empty(b));
        }
        if st.position {
            let p = unsafe { tap3::<L>(records, (dy * rec + p_at) * w + tx, w) };
            let e = [p[0] - position[0], p[1] - position[1], p[2] - position[2]];
            ok &= (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).le(plim2);
        } else if st.depth {
            ok &= (unsafe { tap::<L>(records, (dy * rec + d_at) * w + tx) } - d).abs().le(L::splat(cfg.depth_limit) * d.abs());
        }
        let (pl, pn) = unsafe { (tap3::<L>(records, (dy * rec + LIGHT) * w + tx, w), tap::<L>(records, (dy * rec + COUNT) * w + tx)) };
        // (NaN/Inf in the history are not tested per tap: an accepted one makes its sums
        // NaN/Inf, and such a group is left to the per-pixel code below)
        ok &= pn.ge(zero);
        // a rejected tap adds +0, which leaves these sums (never -0) as they are
        tw += keep(ok, wt);
        n += keep(ok, wt * pn);
        for ch in 0..3 {
            prev[ch] += keep(ok, wt * pl[ch]);
        }
        if gather {
            let po = unsafe { tap3::<L>(records, (dy * rec + OUTPUT) * w + tx, w) };
            ow += keep(ok, wt);
            for ch in 0..3 {
                out[ch] += keep(ok, wt * po[ch]);
            }
        }
    }
    // every accepted tap was finite (the per-pixel code skips the others, taking the
    // history's light and output separately): otherwise a sum is NaN/Inf
    if !finite([n, prev[0], prev[1], prev[2], out[0], out[1], out[2]]).all() {
        return None;
    }
    let kept = if r.clamped { kept(raw, cur) } else { one };
    let max_history = L::splat(cfg.max_history);
    let has = tw.gt(zero);
    let (nn, inv) = (n / tw, one / tw);
    let count = (nn + kept).min(max_history);
    let a = count.gt(zero).select((kept / count).max(kept / max_history), one);
    let count = has.select(count, kept.max(L::splat(1e-3)));
    for ch in 0..3 {
        let old = prev[ch] * inv;
        has.select(old + a * (cur[ch] - old), cur[ch]).store(out_row, (LIGHT + ch) * w + x)?;
    }
    count.store(out_row, COUNT * w + x)?;
    if gather {
        let (seen, inv) = (ow.gt(zero), one / ow);
        for (ch, o) in out.into_iter().enumerate() {
            seen.select(o * inv, L::splat(f32::NAN)).store(px_row, ch * w + x)?;
        }
    }
    Some((!has.bitmask() & ((1 << L::N) - 1)).count_ones() as u64)
}

/// [`LUMA`]·p, in the order of [`crate::fireflies::kept`].
#[inline(always)]
fn luma<L: Lane>(p: [L; 3]) -> L {
    L::splat(LUMA[0]) * p[0] + L::splat(LUMA[1]) * p[1] + L::splat(LUMA[2]) * p[2]
}

/// [`crate::fireflies::kept`] of finite samples.
#[inline(always)]
fn kept<L: Lane>(raw: [L; 3], clamped: [L; 3]) -> L {
    let (lr, lc) = (luma(raw), luma(clamped));
    let lowered = lr.gt(lc) & lr.abs().le(L::splat(f32::MAX)) & lc.ge(L::splat(0.0));
    // lr > lc ≥ 0: the ratio is in [0, 1] already (the scalar code's clamp keeps it)
    lowered.select(lc / lr, L::splat(1.0))
}

/// Horizontal 3-sums of `v` and of its squares (0 beyond the ends), in the
/// order `(a + b) + c`.
pub(super) fn three_sums(v: &[f32], s1: &mut [f32], s2: &mut [f32]) {
    three_sums_with::<Portable>(v, s1, s2)
}

/// [`three_sums`] with lanes `L`.
#[inline(always)]
pub(super) fn three_sums_with<L: Lane>(v: &[f32], s1: &mut [f32], s2: &mut [f32]) {
    let w = v.len().min(s1.len()).min(s2.len());
    let one = |x: usize, s1: &mut [f32], s2: &mut [f32]| {
        let (a, b, c) = (if x > 0 { v[x - 1] } else { 0.0 }, v[x], if x + 1 < w { v[x + 1] } else { 0.0 });
        s1[x] = a + b + c;
        s2[x] = a * a + b * b + c * c;
    };
    if w == 0 {
        return;
    }
    one(0, s1, s2);
    let mut x = 1;
    while x + L::N < w {
        if let (Some(a), Some(b), Some(c)) = (L::load(v, x - 1), L::load(v, x), L::load(v, x + 1)) {
            (a + b + c).store(s1, x);
            (a * a + b * b + c * c).store(s2, x);
        }
        x += L::N;
    }
    for x in x..w {
        one(x, s1, s2);
    }
}

/// RGB → YCoCg ([`crate::reproject::ycocg`]).
#[inline(always)]
fn ycocg<L: Lane>(c: [L; 3]) -> [L; 3] {
    let two = L::splat(2.0);
    [c[0] + two * c[1] + c[2], two * c[0] - two * c[2], -c[0] + two * c[1] - c[2]]
}

/// YCoCg → RGB ([`crate::reproject::rgb`]).
#[inline(always)]
fn rgb<L: Lane>(c: [L; 3]) -> [L; 3] {
    let q = L::splat(0.25);
    [q * (c[0] + c[1] - c[2]), q * (c[0] + c[2]), q * (c[0] - c[1] - c[2])]
}

/// Step 3 ([`Reprojection::resolve_pixel`]) for pixels `x..x + L::N` of a row,
/// none of them in the first or last column (their clip windows are 3 wide).
#[inline(always)]
pub(super) fn resolve_with<L: Lane>(st: &Reprojection, r: &ResolveRow<'_>, x: usize, wrow: &mut [f32], out_row: &mut [f32]) -> Option<()> {
    let (w, cfg) = (st.width, &st.cfg);
    if x == 0 || x + L::N >= w {
        return None;
    }
    let cur = load3::<L>(r.ring, r.cur + x, 0, w)?;
    let mut res = cur;
    let zero = L::splat(0.0);
    if r.blend {
        let pv = load3::<L>(r.prev, x, 0, w)?;
        let blends = !pv[0].is_nan();
        if blends.any() {
            let (mut s1, mut s2) = ([zero; 3], [zero; 3]);
            for &slot in r.slots.get(..r.rows)? {
                for ch in 0..3 {
                    s1[ch] += L::load(r.ring, slot + (3 + ch) * w + x)?;
                    s2[ch] += L::load(r.ring, slot + (6 + ch) * w + x)?;
                }
            }
            let p = ycocg(pv);
            // NaN/Inf in the statistics: the pixels one by one
            if (blends & !(finite(s1) & finite(s2) & finite(p))).any() {
                return None;
            }
            let inv = L::splat(1.0 / (r.rows * 3) as f32);
            let gamma = L::splat(cfg.clip_gamma);
            let mut clipped = [zero; 3];
            for ch in 0..3 {
                let mu = s1[ch] * inv;
                let var = s2[ch] * inv - mu * mu;
                let sd = var.gt(zero).select(var, zero).sqrt();
                let (lo, hi) = (mu - gamma * sd, mu + gamma * sd);
                let c = p[ch].ge(lo).select(p[ch], lo);
                clipped[ch] = c.le(hi).select(c, hi);
            }
            let n = L::load(wrow, COUNT * w + x)?;
            let one = L::splat(1.0);
            let a = n.gt(zero).select((one / n).max(L::splat(cfg.output_alpha)).min(one), one);
            let old = rgb(clipped);
            for ch in 0..3 {
                res[ch] = blends.select(old[ch] + a * (cur[ch] - old[ch]), cur[ch]);
            }
        }
    }
    for (ch, v) in res.into_iter().enumerate() {
        let v = if r.clamp_negative { v.gt(zero).select(v, zero) } else { v };
        let v = v.is_finite().select(v, zero);
        v.store(wrow, (OUTPUT + ch) * w + x)?;
        v.store(out_row, ch * w + x)?;
    }
    Some(())
}
