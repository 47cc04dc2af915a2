//! Steps 1 and 3 of the temporal stage on groups of pixels in SIMD lanes: the arithmetic
//! of the per-pixel code in [`super`], in the same order, so that both give
//! the same bits (`tests/temporal.rs` holds them to it). A group that does
//! not qualify (a tap outside the frame, taps at different offsets, NaN/Inf
//! light or motion) returns `None` and its pixels run one by one.

use super::{Reprojection, ResolveRow, Row, COUNT, LIGHT, OUTPUT};
use crate::kernels::LUMA;
use crate::reproject::floor;

/// A group of pixels in SIMD lanes: 8 where the build has AVX, 4 otherwise
/// (`wide`'s 8 lanes are two SSE registers there, and the group's state would
/// not fit in the register file).
#[cfg(target_feature = "avx")]
type V = wide::f32x8;
#[cfg(not(target_feature = "avx"))]
type V = wide::f32x4;

/// Pixels per group.
#[cfg(target_feature = "avx")]
pub(super) const LANES: usize = 8;
/// Pixels per group.
#[cfg(not(target_feature = "avx"))]
pub(super) const LANES: usize = 4;

/// `s[i..i + 8]`.
#[inline(always)]
fn load(s: &[f32], i: usize) -> Option<V> {
    let a: [f32; LANES] = s.get(i..i + LANES)?.try_into().ok()?;
    Some(V::from(a))
}

/// `s[i..i + 8] = v`.
#[inline(always)]
fn store(s: &mut [f32], i: usize, v: V) -> Option<()> {
    s.get_mut(i..i + LANES)?.copy_from_slice(&v.to_array());
    Some(())
}

/// The lanes where every value of `v` is finite: `0 · v` is ±0 for a finite
/// value and NaN for NaN/±Inf, and a sum with a NaN is NaN.
#[inline(always)]
fn finite(v: &[V]) -> V {
    v.iter().fold(V::ZERO, |s, v| s + *v * V::ZERO).simd_eq(V::ZERO)
}

/// `v` where `mask` is set, +0 elsewhere (a `select` against zero in one instruction).
#[inline(always)]
fn keep(mask: V, v: V) -> V {
    v & mask
}

/// Step 1 ([`Reprojection::accumulate_pixel`]) for pixels `x..x + LANES` of a
/// row whose 4 taps per pixel lie inside the frame at one common offset (so
/// each tap's fields are consecutive values of the previous records).
/// Returns the count of pixels without history.
#[inline]
pub(super) fn accumulate(st: &Reprojection, r: &Row<'_>, x: usize, out_row: &mut [f32], px_row: &mut [f32]) -> Option<u64> {
    let (w, h, rec, cfg) = (st.width, st.height, st.record(), &st.cfg);
    if !r.has_history || x + LANES > w {
        return None;
    }
    let (mx, my) = (load(r.mv, x)?, load(r.mv, w + x)?);
    let lim = V::splat(st.max_motion());
    if !(mx.abs().simd_le(lim) & my.abs().simd_le(lim)).all() {
        return None;
    }
    let raw = [load(r.raw, x)?, load(r.raw, w + x)?, load(r.raw, 2 * w + x)?];
    let cur = [load(r.cur, x)?, load(r.cur, w + x)?, load(r.cur, 2 * w + x)?];
    if !(finite(&raw) & finite(&cur)).all() {
        return None;
    }
    // the taps: (ix, iy) of lane l at (x + l + dx, iy)
    let xs = V::from(core::array::from_fn::<f32, LANES, _>(|l| (x + l) as f32));
    let (px, py) = (xs + mx, V::splat(r.y as f32) + my);
    // lane 0's taps; every lane's floor is lane 0's plus its lane index when
    // `fx ≤ px < fx + 1` (so `px − fx` is the fraction the per-pixel code takes)
    let (fx0, fy) = (floor(px.to_array()[0]), floor(py.to_array()[0]));
    let lanes = V::from(core::array::from_fn::<f32, LANES, _>(|l| l as f32));
    let (fx, fyv) = (V::splat(fx0) + lanes, V::splat(fy));
    let one = V::ONE;
    if !(px.simd_ge(fx) & px.simd_lt(fx + one) & py.simd_ge(fyv) & py.simd_lt(fyv + one)).all() {
        return None;
    }
    let (bx, iy) = (fx0 as i64, fy as i64);
    if bx < 0 || bx + LANES as i64 >= w as i64 || iy < 0 || iy + 1 >= h as i64 {
        return None;
    }
    let (bx, iy) = (bx as usize, iy as usize);
    let (ax, ay) = (px - fx, py - fyv);
    let taps = [(bx, iy, (one - ax) * (one - ay)), (bx + 1, iy, ax * (one - ay)), (bx, iy + 1, (one - ax) * ay), (bx + 1, iy + 1, ax * ay)];
    let (n_at, p_at, d_at) = st.guide_fields();
    let g = |f: usize| load(out_row, f * w + x);
    let zero = V::ZERO;
    let empty = |v: &[V; 3]| v[0].simd_eq(zero) & v[1].simd_eq(zero) & v[2].simd_eq(zero);
    let normal = if st.normal { [g(n_at)?, g(n_at + 1)?, g(n_at + 2)?] } else { [zero; 3] };
    let position = if st.position { [g(p_at)?, g(p_at + 1)?, g(p_at + 2)?] } else { [zero; 3] };
    let d = if st.depth { g(d_at)? } else { zero };
    let depth = if st.depth { d.abs() } else { one };
    let plim = V::splat(cfg.position_limit) * depth;
    let (mut tw, mut n, mut prev) = (zero, zero, [zero; 3]);
    let (mut ow, mut out) = (zero, [zero; 3]);
    for (tx, ty, wt) in taps {
        let j = ty * w * rec + tx;
        let t = |f: usize| load(r.read, j + f * w);
        let mut ok = wt.simd_gt(zero);
        if st.normal {
            let b = [t(n_at)?, t(n_at + 1)?, t(n_at + 2)?];
            let dot = normal[0] * b[0] + normal[1] * b[1] + normal[2] * b[2];
            ok &= dot.simd_ge(V::splat(cfg.normal_limit)) | (empty(&normal) & empty(&b));
        }
        if st.position {
            let e = [t(p_at)? - position[0], t(p_at + 1)? - position[1], t(p_at + 2)? - position[2]];
            ok &= (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).simd_le(plim * plim);
        } else if st.depth {
            ok &= (t(d_at)? - d).abs().simd_le(V::splat(cfg.depth_limit) * d.abs());
        }
        let (pl, pn) = ([t(LIGHT)?, t(LIGHT + 1)?, t(LIGHT + 2)?], t(COUNT)?);
        ok &= finite(&[pl[0], pl[1], pl[2], pn]) & pn.simd_ge(zero);
        // a rejected tap adds +0, which leaves these sums (never -0) as they are
        tw += keep(ok, wt);
        n += keep(ok, wt * pn);
        for ch in 0..3 {
            prev[ch] += keep(ok, wt * pl[ch]);
        }
        let po = [t(OUTPUT)?, t(OUTPUT + 1)?, t(OUTPUT + 2)?];
        let ok = ok & finite(&po);
        ow += keep(ok, wt);
        for ch in 0..3 {
            out[ch] += keep(ok, wt * po[ch]);
        }
    }
    let kept = if r.clamped { kept(raw, cur) } else { one };
    let max_history = V::splat(cfg.max_history);
    let has = tw.simd_gt(zero);
    let (nn, inv) = (n / tw, one / tw);
    let count = (nn + kept).min(max_history);
    let a = count.simd_gt(zero).select((kept / count).max(kept / max_history), one);
    let count = has.select(count, kept.max(V::splat(1e-3)));
    for ch in 0..3 {
        let old = prev[ch] * inv;
        store(out_row, (LIGHT + ch) * w + x, has.select(old + a * (cur[ch] - old), cur[ch]))?;
    }
    store(out_row, COUNT * w + x, count)?;
    let (seen, inv) = (ow.simd_gt(zero), one / ow);
    for (ch, o) in out.into_iter().enumerate() {
        store(px_row, ch * w + x, seen.select(o * inv, V::splat(f32::NAN)))?;
    }
    Some((!has.to_bitmask() & ((1 << LANES) - 1)).count_ones() as u64)
}

/// [`crate::fireflies::kept`] of finite samples.
#[inline(always)]
fn kept(raw: [V; 3], clamped: [V; 3]) -> V {
    let l = |p: [V; 3]| V::splat(LUMA[0]) * p[0] + V::splat(LUMA[1]) * p[1] + V::splat(LUMA[2]) * p[2];
    let (lr, lc) = (l(raw), l(clamped));
    let lowered = lr.simd_gt(lc) & lr.abs().simd_le(V::splat(f32::MAX)) & lc.simd_ge(V::ZERO);
    // lr > lc ≥ 0: the ratio is in [0, 1] already (the scalar code's clamp keeps it)
    lowered.select(lc / lr, V::ONE)
}

/// Horizontal 3-sums of `v` and of its squares (0 beyond the ends), in the
/// order `(a + b) + c`.
pub(super) fn three_sums(v: &[f32], s1: &mut [f32], s2: &mut [f32]) {
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
    while x + LANES < w {
        if let (Some(a), Some(b), Some(c)) = (load(v, x - 1), load(v, x), load(v, x + 1)) {
            store(s1, x, a + b + c);
            store(s2, x, a * a + b * b + c * c);
        }
        x += LANES;
    }
    for x in x..w {
        one(x, s1, s2);
    }
}

/// RGB → YCoCg ([`crate::reproject::ycocg`]).
#[inline(always)]
fn ycocg(c: [V; 3]) -> [V; 3] {
    let two = V::splat(2.0);
    [c[0] + two * c[1] + c[2], two * c[0] - two * c[2], -c[0] + two * c[1] - c[2]]
}

/// YCoCg → RGB ([`crate::reproject::rgb`]).
#[inline(always)]
fn rgb(c: [V; 3]) -> [V; 3] {
    let q = V::splat(0.25);
    [q * (c[0] + c[1] - c[2]), q * (c[0] + c[2]), q * (c[0] - c[1] - c[2])]
}

/// Step 3 ([`Reprojection::resolve_pixel`]) for pixels `x..x + LANES` of a row,
/// none of them in the first or last column (their clip windows are 3 wide).
#[inline]
pub(super) fn resolve(st: &Reprojection, r: &ResolveRow<'_>, x: usize, wrow: &mut [f32], out_row: &mut [f32]) -> Option<()> {
    let (w, cfg) = (st.width, &st.cfg);
    if x == 0 || x + LANES >= w {
        return None;
    }
    let plane = |base: usize, p: usize| load(r.ring, base + p * w + x);
    let cur = [plane(r.cur, 0)?, plane(r.cur, 1)?, plane(r.cur, 2)?];
    let mut res = cur;
    let zero = V::ZERO;
    if r.blend {
        let pv = [load(r.prev, x)?, load(r.prev, w + x)?, load(r.prev, 2 * w + x)?];
        let blends = !pv[0].is_nan();
        if blends.any() {
            let (mut s1, mut s2) = ([zero; 3], [zero; 3]);
            for &slot in r.slots.get(..r.rows)? {
                for ch in 0..3 {
                    s1[ch] += plane(slot, 3 + ch)?;
                    s2[ch] += plane(slot, 6 + ch)?;
                }
            }
            let p = ycocg(pv);
            // NaN/Inf in the statistics: the pixels one by one (f32::max and
            // min treat NaN as this crate's SIMD does not)
            if (blends & !(finite(&s1) & finite(&s2) & finite(&p))).any() {
                return None;
            }
            let inv = V::splat(1.0 / (r.rows * 3) as f32);
            let gamma = V::splat(cfg.clip_gamma);
            let mut clipped = [zero; 3];
            for ch in 0..3 {
                let mu = s1[ch] * inv;
                let sd = (s2[ch] * inv - mu * mu).max(zero).sqrt();
                clipped[ch] = p[ch].max(mu - gamma * sd).min(mu + gamma * sd);
            }
            let n = load(wrow, COUNT * w + x)?;
            let one = V::ONE;
            let a = n.simd_gt(zero).select((one / n).max(V::splat(cfg.output_alpha)).min(one), one);
            let old = rgb(clipped);
            for ch in 0..3 {
                res[ch] = blends.select(old[ch] + a * (cur[ch] - old[ch]), cur[ch]);
            }
        }
    }
    for (ch, v) in res.into_iter().enumerate() {
        let v = if r.clamp_negative { v.max(zero) } else { v };
        let v = v.is_finite().select(v, zero);
        store(wrow, (OUTPUT + ch) * w + x, v)?;
        store(out_row, ch * w + x, v)?;
    }
    Some(())
}
